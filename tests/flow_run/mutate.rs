//! Programs of a cell broken on purpose, the way a handshake can be wrong (the mutation
//! checks of the co-simulation, `cosim.rs`): each mutation rewrites a generated program's text
//! in its language's forms (a watched wait is one unit: its timer, its wait with a time limit
//! and the block that shows its message).

use crate::Lang;

/// How a program may be broken on purpose (the mutation checks).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mutation {
    None,
    /// A handshake wait dropped: the first `WAIT FOR` on a wire of a hear.
    DroppedWait,
    /// A follower decides on its own: its first `IF skp_got == 0` reads the chart's input
    /// `Part_OK` instead.
    DecidesTwice,
    /// The advance run sets an output: a tell's acknowledgement wait dropped.
    AdvanceRun,
    /// No start barrier: its three waits dropped.
    NoBarrier,
    /// No restart guard: every wait on a partner waits for its message only, and never stops.
    NoGuard,
    /// A wait's message is never taken away from the pendant.
    MessageKept,
    /// A tell that a step is done moved after the teller's next step (right below it).
    TellLate,
}

/// The line that closes the block opened at line `i` (`ENDIF`, URScript's `end`, as deep).
fn block_end(lines: &[&str], i: usize, lang: Lang) -> usize {
    let close = if lang == Lang::UrScript {
        "end"
    } else {
        "ENDIF"
    };
    let depth = |l: &str| l.len() - l.trim_start().len();
    i + 1
        + lines[i + 1..]
            .iter()
            .position(|n| n.trim() == close && depth(n) == depth(lines[i]))
            .unwrap()
}

/// The end (the line after it) of a watched wait on a partner that begins at line `i`: its
/// timer's start, the wait with a time limit, and the block that shows the message, waits on
/// and takes the message away (`IF NOT (…)` … `ENDIF`, `IF skp_late THEN` … `ENDIF`,
/// `if not (…):` … `end`).
fn unit_end(lines: &[&str], i: usize, lang: Lang) -> usize {
    let opens = |l: &str| match lang {
        Lang::Krl => l.starts_with("IF NOT ("),
        Lang::Rapid => l == "IF skp_late THEN",
        Lang::UrScript => l.starts_with("if not ("),
    };
    let j = (i..lines.len())
        .find(|&j| opens(lines[j].trim()))
        .unwrap_or_else(|| panic!("no watched wait at line {}: {}", i + 1, lines[i]));
    block_end(lines, j, lang) + 1
}

/// `src` broken as `m` says.
pub fn mutate(src: &str, m: Mutation, lang: Lang) -> String {
    let lines: Vec<&str> = src.lines().collect();
    let barrier = |i: usize| i > 0 && lines[i - 1].contains("handshake: start barrier");
    let keep = |drop: &[std::ops::Range<usize>]| -> String {
        lines
            .iter()
            .enumerate()
            .filter(|(k, _)| !drop.iter().any(|r| r.contains(k)))
            .map(|(_, l)| *l)
            .collect::<Vec<_>>()
            .join("\n")
            + "\n"
    };
    match m {
        Mutation::NoBarrier => {
            let mut drop = Vec::new();
            for i in 0..lines.len() {
                if barrier(i) {
                    drop.push(i..unit_end(&lines, i, lang));
                }
                // The barrier's stop.
                if lines
                    .get(i + 1)
                    .is_some_and(|n| n.contains("during the start barrier: stop"))
                {
                    drop.push(i..block_end(&lines, i, lang) + 1);
                }
            }
            return keep(&drop);
        }
        Mutation::NoGuard => {
            // Every wait on a message waits for the message only: its guard (the partner's
            // run wire) becomes FALSE, and the stops go.
            let (or, never) = match lang {
                Lang::Krl => (" OR (", "(FALSE)"),
                Lang::Rapid => (" OR (", "(FALSE)"),
                Lang::UrScript => (" or (", "(False)"),
            };
            let unguard = |l: &str| -> String {
                let mut out = String::new();
                let mut rest = l;
                while let Some(at) = rest.find("skp_") {
                    let (head, tail) = rest.split_at(at);
                    out.push_str(head);
                    // `skp_rxN)` or `skp_txN)` and its guard ` OR (…)` after it.
                    let toggle = tail.len() > 6
                        && (tail.starts_with("skp_rx") || tail.starts_with("skp_tx"));
                    let digits = tail[6.min(tail.len())..]
                        .bytes()
                        .take_while(u8::is_ascii_digit)
                        .count();
                    let after = 6 + digits;
                    if toggle && digits > 0 && tail[after..].starts_with(&format!("){or}")) {
                        out.push_str(&tail[..after + 1 + or.len() - 1]);
                        let open = after + 1 + or.len() - 1;
                        // The guard's parentheses.
                        let mut depth = 0;
                        let close = tail[open..]
                            .char_indices()
                            .find_map(|(k, c)| {
                                match c {
                                    '(' => depth += 1,
                                    ')' => {
                                        depth -= 1;
                                        if depth == 0 {
                                            return Some(open + k);
                                        }
                                    }
                                    _ => {}
                                }
                                None
                            })
                            .unwrap();
                        out.push_str(never);
                        rest = &tail[close + 1..];
                    } else {
                        out.push_str(&tail[..4]);
                        rest = &tail[4..];
                    }
                }
                out.push_str(rest);
                out
            };
            let mut out: Vec<String> = Vec::new();
            let mut i = 0;
            while i < lines.len() {
                if lines[i]
                    .trim_start()
                    .to_ascii_uppercase()
                    .starts_with("IF ")
                    && lines
                        .get(i + 1)
                        .is_some_and(|n| n.contains("a partner was started again"))
                {
                    // The stop.
                    i = block_end(&lines, i, lang) + 1;
                    continue;
                }
                out.push(if barrier(i) {
                    lines[i].to_owned()
                } else {
                    unguard(lines[i])
                });
                i += 1;
            }
            return out.join("\n") + "\n";
        }
        Mutation::TellLate => {
            let indent = |l: &str| l.len() - l.trim_start().len();
            let comment = match lang {
                Lang::Krl => ";",
                Lang::Rapid => "!",
                Lang::UrScript => "#",
            };
            // The tell's last line puts the flipped toggle on the strobe.
            let strobe = |l: &str| {
                let t = l.trim().trim_end_matches([';', ')']);
                t.rsplit_once("skp_tx").is_some_and(|(head, n)| {
                    !n.is_empty()
                        && n.bytes().all(|b| b.is_ascii_digit())
                        && !["NOT ", "not ", "1 - ", "WAIT", "Wait", "while", "=="]
                            .iter()
                            .any(|w| head.contains(w))
                })
            };
            for i in 0..lines.len() {
                if !(lines[i].contains("handshake: tell ") && lines[i].contains(") is done")) {
                    continue;
                }
                let Some(e) = (i + 1..lines.len()).find(|&k| strobe(lines[k])) else {
                    continue;
                };
                let Some(next) = lines.get(e + 1) else {
                    continue;
                };
                let t = next.trim();
                let step = match lang {
                    Lang::Krl => t.starts_with(";FOLD "),
                    _ => t.starts_with(&format!("{comment} step ")),
                };
                if !step || indent(next) != indent(lines[i]) {
                    continue;
                }
                let d = indent(next);
                let end = match lang {
                    Lang::Krl => {
                        let mut depth = 0;
                        (e + 1..lines.len())
                            .find(|&k| {
                                let t = lines[k].trim();
                                if t.starts_with(";FOLD") {
                                    depth += 1;
                                } else if t.starts_with(";ENDFOLD") {
                                    depth -= 1;
                                }
                                depth == 0
                            })
                            .unwrap()
                            + 1
                    }
                    _ => (e + 2..lines.len())
                        .find(|&k| {
                            let l = lines[k];
                            !l.trim().is_empty()
                                && (indent(l) < d
                                    || (indent(l) == d && l.trim().starts_with(comment)))
                        })
                        .unwrap_or(lines.len()),
                };
                let order: Vec<&str> = lines[..i]
                    .iter()
                    .chain(&lines[e + 1..end])
                    .chain(&lines[i..e + 1])
                    .chain(&lines[end..])
                    .copied()
                    .collect();
                return order.join("\n") + "\n";
            }
            return src.to_owned();
        }
        Mutation::MessageKept => {
            let clears = |l: &str| match lang {
                Lang::Krl => l.starts_with("skp_hide("),
                Lang::Rapid => l == "TPErase;",
                Lang::UrScript => l.starts_with("textmsg(") && l.ends_with("the wait has ended\")"),
            };
            let drop: Vec<_> = (0..lines.len())
                .filter(|&i| clears(lines[i].trim()))
                .map(|i| i..i + 1)
                .collect();
            return keep(&drop);
        }
        _ => {}
    }
    let pick = |pred: &dyn Fn(usize, &str) -> bool| {
        lines
            .iter()
            .enumerate()
            .position(|(i, l)| pred(i, l.trim()))
    };
    // A hear toggles its `skp_rxN` right before its wait.
    let after_toggle = |i: usize| {
        i > 0 && {
            let t = lines[i - 1].trim();
            t.starts_with("skp_rx")
                && (t.contains("NOT skp_rx")
                    || t.contains("not skp_rx")
                    || t.contains("1 - skp_rx"))
        }
    };
    let tell = |i: usize| i > 0 && lines[i - 1].contains("handshake: tell");
    match m {
        Mutation::None
        | Mutation::NoBarrier
        | Mutation::NoGuard
        | Mutation::MessageKept
        | Mutation::TellLate => src.to_owned(),
        Mutation::DroppedWait => match pick(&|i, _| after_toggle(i) && !barrier(i)) {
            Some(i) => keep(std::slice::from_ref(&(i..unit_end(&lines, i, lang)))),
            None => src.to_owned(),
        },
        Mutation::AdvanceRun => match lang {
            Lang::Krl => match pick(&|i, _| tell(i)) {
                Some(i) => keep(std::slice::from_ref(&(i..unit_end(&lines, i, lang)))),
                None => src.to_owned(),
            },
            // RAPID: the tell's waits without `\InPos` (not a chart's wait, which stands too).
            Lang::Rapid => {
                let Some(i) = pick(&|i, _| tell(i)) else {
                    return src.to_owned();
                };
                let end = unit_end(&lines, i, lang);
                let mut out: Vec<String> = lines.iter().map(|l| (*l).to_owned()).collect();
                for l in &mut out[i..end] {
                    *l = l.replacen("WaitUntil \\InPos, ", "WaitUntil ", 1);
                }
                out.join("\n") + "\n"
            }
            // URScript has no advance run: its moves return at their target.
            Lang::UrScript => src.to_owned(),
        },
        Mutation::DecidesTwice => match lang {
            Lang::Krl => src.replacen("IF skp_got == 0 THEN", "IF $IN[1] THEN", 1),
            Lang::Rapid => src.replacen("IF skp_got = 0 THEN", "IF di_Part_OK = 1 THEN", 1),
            Lang::UrScript => src.replacen("if skp_got == 0:", "if get_standard_digital_in(1):", 1),
        },
    }
}
