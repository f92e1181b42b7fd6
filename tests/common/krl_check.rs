//! The KRL structure check of the generated `.src`/`.dat` (shared by `tests/ok_fixtures.rs` and
//! `tests/flow_run.rs`: `#[path = "common/krl_check.rs"] mod krl_check;`).
#![allow(dead_code)]

/// A KRL name: a letter or `_`, then letters, digits or `_`, at most 24 characters.
fn is_krl_name(s: &str) -> bool {
    let b = s.as_bytes();
    !b.is_empty()
        && b.len() <= 24
        && (b[0].is_ascii_alphabetic() || b[0] == b'_')
        && b.iter().all(|c| c.is_ascii_alphanumeric() || *c == b'_')
}

/// Splits `text` into lines, checking that it is ASCII without control characters (tabs
/// allowed) and that every line, the last included, ends in CRLF (or LF when `lf`).
fn split_lines<'t>(text: &'t str, lf: bool, what: &str) -> Result<Vec<&'t str>, String> {
    if text.is_empty() {
        return Err(format!("{what} is empty"));
    }
    let mut lines = Vec::new();
    let mut rest = text;
    let mut n = 0;
    while !rest.is_empty() {
        n += 1;
        let Some(i) = rest.find('\n') else {
            return Err(format!(
                "{what} line {n}: no line break at the end of the file"
            ));
        };
        let (line, ending) = match rest[..i].strip_suffix('\r') {
            Some(l) => (l, "CRLF"),
            None => (&rest[..i], "LF"),
        };
        let wanted = if lf { "LF" } else { "CRLF" };
        if ending != wanted {
            return Err(format!(
                "{what} line {n} ends in {ending}, expected {wanted} (mixed line endings)"
            ));
        }
        if let Some(c) = line.chars().find(|c| !c.is_ascii()) {
            return Err(format!("{what} line {n}: non-ASCII character `{c}`"));
        }
        if let Some(c) = line.chars().find(|c| c.is_ascii_control() && *c != '\t') {
            return Err(format!("{what} line {n}: control character {:?}", c));
        }
        lines.push(line);
        rest = &rest[i + 1..];
    }
    Ok(lines)
}

/// The code part of a KRL line: without a `;` comment (outside string literals); string
/// contents blanked so keywords inside them do not count.
fn code_of(line: &str) -> Result<String, String> {
    let mut out = String::with_capacity(line.len());
    let mut in_str = false;
    for c in line.chars() {
        match c {
            '"' => {
                in_str = !in_str;
                out.push('"');
            }
            ';' if !in_str => break,
            _ if in_str => out.push(' '),
            _ => out.push(c),
        }
    }
    if in_str {
        return Err("unterminated string literal".to_owned());
    }
    Ok(out.trim().to_owned())
}

/// The words of a code line (runs of letters, digits, `_`, `$`, `#`), upper-cased.
fn words_of(code: &str) -> Vec<String> {
    code.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '$' || c == '#'))
        .filter(|w| !w.is_empty())
        .map(str::to_ascii_uppercase)
        .collect()
}

/// The name declared by `DEF name(...)` (`rest` is the text after `DEF`).
fn def_name(rest: &str) -> Result<&str, String> {
    let rest = rest.trim_start();
    let Some(paren) = rest.find('(') else {
        return Err(format!("`DEF {rest}` has no parameter list"));
    };
    if !rest.trim_end().ends_with(')') {
        return Err(format!("`DEF {rest}`: parameter list not closed"));
    }
    let name = rest[..paren].trim();
    if !is_krl_name(name) {
        return Err(format!("DEF name `{name}` is not a valid KRL name"));
    }
    Ok(name)
}

/// Checks the timers a code line names: `$TIMER[k]`, `$TIMER_STOP[k]`, `$TIMER_FLAG[k]` with
/// `k` a number from 1 to 64.
fn timers_of(code: &str) -> Result<(), String> {
    let upper = code.to_ascii_uppercase();
    for (at, _) in upper.match_indices("$TIMER") {
        let rest = &upper[at + 6..];
        let rest = rest
            .strip_prefix("_STOP")
            .or_else(|| rest.strip_prefix("_FLAG"))
            .unwrap_or(rest);
        let k = rest
            .strip_prefix('[')
            .and_then(|r| r.split_once(']'))
            .map(|(k, _)| k.trim());
        match k.and_then(|k| k.parse::<u32>().ok()) {
            Some(1..=64) => {}
            _ => return Err("a timer is `$TIMER[k]` with k from 1 to 64".to_owned()),
        }
    }
    Ok(())
}

/// Checks the tools and bases a code line selects: `BAS(#TOOL, n)` with `n` from 1 to 16 and
/// `BAS(#BASE, n)` from 1 to 32 (a KSS 8 controller's `TOOL_DATA[16]` and `BASE_DATA[32]`).
fn tools_of(code: &str) -> Result<(), String> {
    let upper: String = code.to_ascii_uppercase().split_whitespace().collect();
    for (what, max) in [("#TOOL,", 16), ("#BASE,", 32)] {
        for (at, _) in upper.match_indices(&format!("BAS({what}")) {
            let rest = &upper[at + 4 + what.len()..];
            let n = rest.split_once(')').map(|(n, _)| n);
            match n.and_then(|n| n.parse::<u32>().ok()) {
                Some(n) if (1..=max).contains(&n) => {}
                _ => return Err(format!("`BAS({what} n)` selects n from 1 to {max}")),
            }
        }
    }
    Ok(())
}

/// Checks the structure of a generated `.src`/`.dat` pair for `program`: ASCII; CRLF (or LF)
/// line endings on every line; header lines (`&...`) only before the first `DEF`; `DEF name( )`
/// / `END` balanced and not nested, every statement inside one, the first `DEF` named like the
/// program; the timers `$TIMER[k]`, `$TIMER_STOP[k]`, `$TIMER_FLAG[k]` numbered 1 to 64 (KSS 8);
/// `IF`/`ENDIF` (with `THEN`, `ELSE` only inside), `FOR`/`ENDFOR`, `WHILE`/`ENDWHILE`,
/// `LOOP`/`ENDLOOP`, `SWITCH`/`ENDSWITCH`, `REPEAT`/`UNTIL` balanced inside each `DEF` (comments
/// and string contents ignored); `;FOLD`/`;ENDFOLD` balanced and closed before `DEF`/`END`; every
/// name a valid KRL name; the `.dat` one `DEFDAT <program>` ... `ENDDAT`.
pub fn check_krl(src: &str, dat: &str, program: &str, lf: bool) -> Result<(), String> {
    if !is_krl_name(program) {
        return Err(format!("program name `{program}` is not a valid KRL name"));
    }

    // .src
    let lines = split_lines(src, lf, ".src")?;
    let mut open_def: Option<(String, usize)> = None;
    let mut defs: Vec<String> = Vec::new();
    let mut blocks: Vec<(&str, usize)> = Vec::new();
    let mut folds: Vec<usize> = Vec::new();
    // The labels of the open DEF and the GOTOs to them, each with the blocks open there (by
    // their first line): a GOTO stays in its DEF and never enters a block, so the blocks open
    // at its label are open at the GOTO too.
    let mut labels: Vec<(String, Vec<usize>)> = Vec::new();
    let mut gotos: Vec<(String, usize, Vec<usize>)> = Vec::new();
    for (i, raw) in lines.iter().enumerate() {
        let n = i + 1;
        let err = |m: String| format!(".src line {n}: {m}: `{raw}`");
        let t = raw.trim();
        let upper = t.to_ascii_uppercase();
        if upper.starts_with(";FOLD") {
            folds.push(n);
            continue;
        }
        if upper.starts_with(";ENDFOLD") {
            if folds.pop().is_none() {
                return Err(err("`;ENDFOLD` without `;FOLD`".into()));
            }
            continue;
        }
        let code = code_of(t).map_err(&err)?;
        if code.is_empty() {
            continue;
        }
        if code.starts_with('&') {
            if !defs.is_empty() {
                return Err(err("header line after the first DEF".into()));
            }
            continue;
        }
        let words = words_of(&code);
        let mut first = words.first().map(String::as_str).unwrap_or("");
        let mut body = code.as_str();
        if first == "GLOBAL" && matches!(words.get(1).map(String::as_str), Some("DEF")) {
            first = "DEF";
            body = body.trim_start()[6..].trim_start();
        }
        match first {
            "DEF" => {
                if let Some((name, at)) = &open_def {
                    return Err(err(format!("DEF inside DEF `{name}` (line {at})")));
                }
                if let Some(f) = folds.last() {
                    return Err(err(format!("DEF inside the ;FOLD of line {f}")));
                }
                let name = def_name(&body[3..]).map_err(&err)?;
                if defs.is_empty() && name != program {
                    return Err(err(format!(
                        "the first DEF is `{name}`, not the program `{program}`"
                    )));
                }
                if defs.iter().any(|d| d.eq_ignore_ascii_case(name)) {
                    return Err(err(format!("DEF `{name}` defined twice")));
                }
                defs.push(name.to_owned());
                open_def = Some((name.to_owned(), n));
            }
            "END" => {
                if open_def.is_none() {
                    return Err(err("END without DEF".into()));
                }
                if let Some((kw, at)) = blocks.last() {
                    return Err(err(format!("END while {kw} of line {at} is open")));
                }
                if let Some(f) = folds.last() {
                    return Err(err(format!("END inside the ;FOLD of line {f}")));
                }
                if words.len() != 1 {
                    return Err(err("END followed by more".into()));
                }
                for (l, at, open) in &gotos {
                    let Some((_, where_)) = labels.iter().find(|(x, _)| x == l) else {
                        return Err(format!(
                            ".src line {at}: GOTO {l}: no such label in this DEF"
                        ));
                    };
                    if !open.starts_with(where_) {
                        return Err(format!(
                            ".src line {at}: GOTO {l} enters a block its label stands in"
                        ));
                    }
                }
                labels.clear();
                gotos.clear();
                open_def = None;
            }
            _ => {
                if open_def.is_none() {
                    return Err(err("statement outside a DEF".into()));
                }
                timers_of(&code).map_err(&err)?;
                tools_of(&code).map_err(&err)?;
                let close = |blocks: &mut Vec<(&str, usize)>, opener: &str| match blocks.pop() {
                    Some((kw, _)) if kw == opener => Ok(()),
                    Some((kw, at)) => Err(err(format!(
                        "{first} closes {kw} of line {at}, expected {opener}"
                    ))),
                    None => Err(err(format!("{first} without {opener}"))),
                };
                if words.len() == 1 && code.trim_end().ends_with(':') {
                    let name = first;
                    if !is_krl_name(name) {
                        return Err(err(format!("label `{name}` is not a valid KRL name")));
                    }
                    if labels.iter().any(|(l, _)| l == name) {
                        return Err(err(format!("label `{name}` defined twice")));
                    }
                    labels.push((name.to_owned(), blocks.iter().map(|b| b.1).collect()));
                    continue;
                }
                match first {
                    "GOTO" => {
                        if words.len() != 2 || !is_krl_name(&words[1]) {
                            return Err(err("GOTO needs one label".into()));
                        }
                        gotos.push((words[1].clone(), n, blocks.iter().map(|b| b.1).collect()));
                    }
                    "IF" => {
                        if words.last().map(String::as_str) != Some("THEN") {
                            return Err(err("IF without THEN".into()));
                        }
                        blocks.push(("IF", n));
                    }
                    "ELSE" if !matches!(blocks.last(), Some(("IF", _))) => {
                        return Err(err("ELSE outside IF".into()));
                    }
                    "FOR" | "WHILE" | "LOOP" | "SWITCH" | "REPEAT" => {
                        let kw = ["FOR", "WHILE", "LOOP", "SWITCH", "REPEAT"]
                            .into_iter()
                            .find(|k| *k == first)
                            .unwrap();
                        blocks.push((kw, n));
                    }
                    "CASE" | "DEFAULT" if !matches!(blocks.last(), Some(("SWITCH", _))) => {
                        return Err(err(format!("{first} outside SWITCH")));
                    }
                    "ENDIF" => close(&mut blocks, "IF")?,
                    "ENDFOR" => close(&mut blocks, "FOR")?,
                    "ENDWHILE" => close(&mut blocks, "WHILE")?,
                    "ENDLOOP" => close(&mut blocks, "LOOP")?,
                    "ENDSWITCH" => close(&mut blocks, "SWITCH")?,
                    "UNTIL" => close(&mut blocks, "REPEAT")?,
                    _ => {}
                }
            }
        }
    }
    if let Some((name, at)) = open_def {
        return Err(format!(".src: DEF `{name}` of line {at} has no END"));
    }
    if let Some(at) = folds.last() {
        return Err(format!(".src: ;FOLD of line {at} has no ;ENDFOLD"));
    }
    if defs.is_empty() {
        return Err(".src has no DEF".to_owned());
    }

    // .dat
    let lines = split_lines(dat, lf, ".dat")?;
    let mut state = 0; // 0 before DEFDAT, 1 inside, 2 after ENDDAT
    for (i, raw) in lines.iter().enumerate() {
        let n = i + 1;
        let code = code_of(raw.trim()).map_err(|m| format!(".dat line {n}: {m}"))?;
        if code.is_empty() {
            continue;
        }
        let words = words_of(&code);
        let first = words.first().map(String::as_str).unwrap_or("");
        match (state, first) {
            (0, _) if code.starts_with('&') => {}
            (0, "DEFDAT") => {
                let name = code.split_whitespace().nth(1).unwrap_or("");
                if !is_krl_name(name) {
                    return Err(format!(".dat line {n}: `{name}` is not a valid KRL name"));
                }
                if name != program {
                    return Err(format!(
                        ".dat line {n}: DEFDAT `{name}`, but the program is `{program}`"
                    ));
                }
                let rest: Vec<&String> = words.iter().skip(2).collect();
                if !(rest.is_empty() || rest == ["PUBLIC"]) {
                    return Err(format!(".dat line {n}: unexpected text after DEFDAT"));
                }
                state = 1;
            }
            (1, "ENDDAT") if words.len() == 1 => state = 2,
            (1, "DEFDAT") => return Err(format!(".dat line {n}: DEFDAT inside DEFDAT")),
            (1, _) => {}
            (0, _) => return Err(format!(".dat line {n}: `{raw}` before DEFDAT")),
            _ => return Err(format!(".dat line {n}: `{raw}` after ENDDAT")),
        }
    }
    match state {
        0 => return Err(".dat has no DEFDAT".to_owned()),
        1 => return Err(".dat: DEFDAT without ENDDAT".to_owned()),
        _ => {}
    }
    check_points(src, dat, lf)
}

/// The `.dat`'s declarations by upper-case name: the type and the value's text. Every `DECL`
/// is `DECL [GLOBAL] TYPE NAME=VALUE` (or without a value) with a KRL name, braces balanced in
/// the value, each name declared once.
fn dat_declarations(
    dat: &str,
    lf: bool,
) -> Result<std::collections::HashMap<String, (String, String)>, String> {
    let mut out = std::collections::HashMap::new();
    for (i, raw) in split_lines(dat, lf, ".dat")?.iter().enumerate() {
        let n = i + 1;
        let code = code_of(raw.trim()).map_err(|m| format!(".dat line {n}: {m}"))?;
        let Some(rest) = code.strip_prefix("DECL ") else {
            continue;
        };
        let rest = rest.trim_start();
        let rest = rest.strip_prefix("GLOBAL ").unwrap_or(rest).trim_start();
        let (ty, rest) = rest
            .split_once(' ')
            .ok_or_else(|| format!(".dat line {n}: `{code}` has no name"))?;
        let (name, value) = match rest.split_once('=') {
            Some((name, value)) => (name.trim(), value.trim()),
            None => (rest.trim(), ""),
        };
        let name = name.split('[').next().unwrap_or(name).trim();
        if !is_krl_name(name) {
            return Err(format!(".dat line {n}: `{name}` is not a valid KRL name"));
        }
        let opens = value.matches('{').count();
        if opens != value.matches('}').count() || (opens > 0 && !value.ends_with('}')) {
            return Err(format!(
                ".dat line {n}: the value of `{name}` is not one aggregate"
            ));
        }
        if out
            .insert(
                name.to_ascii_uppercase(),
                (ty.to_ascii_uppercase(), value.to_owned()),
            )
            .is_some()
        {
            return Err(format!(".dat line {n}: `{name}` declared twice"));
        }
    }
    Ok(out)
}

/// The named points of a `.src` (docs/LANGUAGES.md, "Points"): every point a motion goes to
/// (`PTP XName`, `LIN XName C_DIS`, `CIRC XAux, XTarget`) is declared in the `.dat` as an
/// `E6POS` (an `E6AXIS` for `PTP`), with only numbers in it; the data an inline form makes
/// active (`FDAT_ACT=FName`, `PDAT_ACT=PPDATn`, `LDAT_ACT=LCPDATn`) is declared as `FDAT`,
/// `PDAT`, `LDAT`; an inline form's fold names its point in its title and its `%P` list and
/// holds exactly `$BWDSTART`, the data, `BAS(…)` and the motion to `X` + that point.
fn check_points(src: &str, dat: &str, lf: bool) -> Result<(), String> {
    let decls = dat_declarations(dat, lf)?;
    let declared = |name: &str, types: &[&str], n: usize| -> Result<(), String> {
        match decls.get(&name.to_ascii_uppercase()) {
            Some((ty, value)) if types.contains(&ty.as_str()) => {
                if ty.starts_with("E6") {
                    let inner = value.trim_start_matches('{').trim_end_matches('}');
                    for item in inner.split(',') {
                        let mut w = item.split_whitespace();
                        let (Some(_), Some(v), None) = (w.next(), w.next(), w.next()) else {
                            return Err(format!("point `{name}`: `{item}` is not `KEY number`"));
                        };
                        if v.parse::<f64>().is_err() {
                            return Err(format!("point `{name}`: `{v}` is not a number"));
                        }
                    }
                }
                Ok(())
            }
            Some((ty, _)) => Err(format!(
                ".src line {n}: `{name}` is a {ty} in the .dat, expected {types:?}"
            )),
            None => Err(format!(
                ".src line {n}: `{name}` is not declared in the .dat"
            )),
        }
    };
    let lines = split_lines(src, lf, ".src")?;
    let mut i = 0;
    while i < lines.len() {
        let n = i + 1;
        let raw = lines[i].trim();
        i += 1;
        if raw.contains("%{PE}") && raw.contains("%CMOVE") {
            // An inline form: its title, then its six lines.
            let title = raw
                .strip_prefix(";FOLD ")
                .ok_or(format!(".src line {n}: an inline form outside a ;FOLD"))?;
            let mut words = title.split_whitespace();
            let verb = words.next().unwrap_or("");
            let point = if verb == "CIRC" {
                words.nth(1)
            } else {
                words.next()
            }
            .unwrap_or("");
            let params = title
                .split("%P ")
                .nth(1)
                .ok_or(format!(".src line {n}: no %P"))?;
            let slot = if verb == "CIRC" { "3:" } else { "2:" };
            if !params.split(", ").any(|p| p == format!("{slot}{point}")) {
                return Err(format!(
                    ".src line {n}: the form's %P does not name its point `{point}`"
                ));
            }
            let body: Vec<&str> = lines
                .get(i..i + 6)
                .ok_or(format!(".src line {n}: a short inline form"))?
                .iter()
                .map(|l| l.trim())
                .collect();
            let (data, bas) = if verb == "PTP" {
                ("PDAT_ACT=P", "BAS(#PTP_PARAMS,")
            } else {
                ("LDAT_ACT=L", "BAS(#CP_PARAMS,")
            };
            let ok = body[0] == "$BWDSTART=FALSE"
                && body[1].starts_with(data)
                && body[2] == format!("FDAT_ACT=F{point}")
                && body[3].starts_with(bas)
                && body[4].starts_with(&format!("{verb} "))
                && body[4].contains(&format!("X{point}"))
                && body[5] == ";ENDFOLD";
            if !ok {
                return Err(format!(
                    ".src line {n}: the inline form of `{point}` is not KUKA's: {body:?}"
                ));
            }
            declared(
                &body[1][9..],
                if verb == "PTP" { &["PDAT"] } else { &["LDAT"] },
                n + 2,
            )?;
            declared(&format!("F{point}"), &["FDAT"], n + 3)?;
            continue;
        }
        let code = code_of(raw).map_err(|m| format!(".src line {n}: {m}"))?;
        let mut w = code.split_whitespace();
        let verb = w.next().unwrap_or("").to_ascii_uppercase();
        if !matches!(verb.as_str(), "PTP" | "LIN" | "CIRC") {
            continue;
        }
        let targets = code[verb.len()..].trim_start();
        if targets.starts_with('{') || targets.starts_with('$') {
            continue;
        }
        let names: Vec<&str> = targets
            .split(',')
            .map(|t| t.split_whitespace().next().unwrap_or(""))
            .collect();
        for name in names {
            // KUKA's own points (`XHOME`, `XHOME1` …) are declared in `$config.dat`.
            let kuka = name
                .to_ascii_uppercase()
                .strip_prefix("XHOME")
                .is_some_and(|d| d.bytes().all(|b| b.is_ascii_digit()));
            if name.len() > 1 && name.starts_with(['X', 'x']) && !kuka {
                let types: &[&str] = if verb == "PTP" {
                    &["E6POS", "E6AXIS"]
                } else {
                    &["E6POS"]
                };
                declared(name, types, n)?;
            }
        }
    }
    Ok(())
}
