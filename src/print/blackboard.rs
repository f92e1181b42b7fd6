//! `-pB`: the blackboard's resources (their languages, controllers, tooling, skills, functions
//! and signals) and wires, and what each wire a cell's handshakes use does.

use std::fmt::Write as _;

use crate::model::{Blackboard, Signal, SignalKind};

/// A resource's language and where it comes from: the compile's decision for a resource the
/// program uses (`languages`), else its `Language` attribute, else the default.
pub fn language_text(
    bb: &Blackboard,
    ri: usize,
    languages: &std::collections::HashMap<usize, crate::lang::Language>,
) -> String {
    let r = &bb.resources[ri];
    match (languages.get(&ri), &r.language) {
        (Some(l), Some((a, _))) if l == a => format!("{l} (Language attribute)"),
        (Some(l), None) => format!("{l} (IRL files, else the default)"),
        (Some(l), Some(_)) => l.to_string(),
        (None, Some((a, _))) => format!("{a} (Language attribute)"),
        (None, None) => "KRL unless its IRL files say otherwise (no Language attribute)".to_owned(),
    }
}

/// `-pB`: resources (with their language), their skills with the calls they map, and functions
/// with their IRL files.
/// The `-pB` controller line of resource `ri` (docs/CELLS.md), when there is anything to say: the
/// resource whose controller runs it and why, or the controller a `Controller` value describes.
fn controller_text(bb: &Blackboard, ri: usize) -> Option<String> {
    let r = &bb.resources[ri];
    let c = bb.controller_of(ri);
    if c != ri {
        let how = match (&r.controller_attr, r.parent) {
            (Some((v, _)), _) if crate::names::key(v) == bb.resources[c].name.key.as_ref() => {
                "its Controller attribute"
            }
            (_, Some(_)) => "mounted on it",
            _ => "its Controller attribute",
        };
        return Some(format!("runs on {} ({how})", bb.resources[c].name.text));
    }
    r.controller_attr
        .as_ref()
        .map(|(v, _)| format!("its own: {v}"))
}

pub fn blackboard(
    bb: &Blackboard,
    languages: &std::collections::HashMap<usize, crate::lang::Language>,
    uses: Option<&std::collections::HashMap<usize, String>>,
) -> String {
    let mut o = String::new();
    for (ri, r) in bb.resources.iter().enumerate() {
        let _ = writeln!(o, "{:<23} {}", r.name.text, r.id.as_deref().unwrap_or(""));
        let _ = writeln!(o, "        (Language) {}", language_text(bb, ri, languages));
        if let Some(line) = controller_text(bb, ri) {
            let _ = writeln!(o, "        (Controller) {line}");
        }
        for line in crate::read::tooling::listing(&r.tooling) {
            let _ = writeln!(o, "        {line}");
        }
        let mut skills: Vec<_> = r.skills.iter().collect();
        skills.sort_by(|a, b| a.name.key.cmp(&b.name.key));
        for s in skills {
            let _ = writeln!(
                o,
                "        (Skill) {:<41} {}",
                s.name.text,
                s.id.as_deref().unwrap_or("")
            );
            for m in &s.mappings {
                let args: Vec<&str> = m.args.iter().map(|a| a.skill_param.text.as_ref()).collect();
                let _ = writeln!(
                    o,
                    "                -> {} ({})   [order {}]",
                    m.function.text,
                    args.join(", "),
                    m.order
                );
            }
        }
        let mut funcs: Vec<_> = r.functions.iter().collect();
        funcs.sort_by(|a, b| a.name.key.cmp(&b.name.key));
        for f in funcs {
            let _ = writeln!(
                o,
                "        (Func)  {:<41} {}",
                f.name.text,
                f.id.as_deref().unwrap_or("")
            );
            let _ = writeln!(
                o,
                "                -> IRL-File:  {}   (command {})",
                f.irl.value, f.command.text
            );
        }
        for s in &r.signals {
            let _ = writeln!(o, "        (Signal) {:<40} {}", s.name.text, signal_text(s));
        }
    }
    for (k, w) in bb.wires.iter().enumerate() {
        let end = |(r, si): (usize, usize)| {
            format!(
                "{}: {}",
                bb.resources[r].name.text, bb.resources[r].signals[si].name.text
            )
        };
        let used = uses
            .and_then(|u| u.get(&k))
            .map(|u| format!(", handshake: {u}"))
            .unwrap_or_default();
        let _ = writeln!(
            o,
            "(Wire) {} -> {}   (InternalLink {}{used})",
            end(w.from),
            end(w.to),
            w.name
        );
    }
    o
}

/// What each wire a cell's handshakes use does (docs/CELLS.md): `strobe of A -> B`, `data bit 1 of
/// A -> B`, `acknowledgement of A -> B` (the channel from A to B), by wire index.
pub fn wire_uses(
    cell: &crate::plan::cell::Cell,
    bb: &Blackboard,
) -> std::collections::HashMap<usize, String> {
    let name = |c: usize| bb.resources[cell.controllers[c]].name.text.to_string();
    let mut out = std::collections::HashMap::new();
    for ch in &cell.channels {
        let of = format!("of {} -> {}", name(ch.from), name(ch.to));
        if let Some(w) = ch.strobe {
            out.insert(w, format!("strobe {of}"));
        }
        for (b, &w) in ch.data.iter().enumerate() {
            out.insert(w, format!("data bit {} {of}", b + 1));
        }
        if let Some(w) = ch.ack {
            out.insert(w, format!("acknowledgement {of}"));
        }
    }
    for l in &cell.links {
        let of = format!("of {} -> {}", name(l.from), name(l.to));
        if let Some(w) = l.run {
            out.insert(w, format!("run {of} (start barrier, restart check)"));
        }
        if let Some(w) = l.ready {
            out.insert(w, format!("ready {of} (start barrier)"));
        }
    }
    out
}

/// A signal in one line: direction, type and where it is (`input bit $IN[3]`).
pub fn signal_text(s: &Signal) -> String {
    let dir = if s.output { "output" } else { "input" };
    let io = if s.output { "$OUT" } else { "$IN" };
    match &s.kind {
        SignalKind::Bit(n) => format!("{dir} bit {io}[{n}]"),
        SignalKind::Group { number, length } => format!(
            "{dir} integer {io}[{number}] TO {io}[{}] ({length} bits)",
            number + length - 1
        ),
        SignalKind::Address { text, integer } => format!(
            "{dir} {} at {text}",
            if *integer { "integer" } else { "bit" }
        ),
    }
}
