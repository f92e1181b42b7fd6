//! The listings of the original's print options: `-pB` (blackboard), `-pS` (SFC objects), `-pF`
//! (flow with parallel branches and times), `-pO` (execution order), and `--info`.
//!
//! Each returns a `String`; the command line prints it. The layout follows the original's
//! console output (`../shared/spec/reference/original-sample/`), with localIds everywhere; [`json`]
//! gives the same listings as JSON objects for `--format json` (docs/JSON.md).

pub mod parts;

use std::fmt::Write as _;

use crate::model::{Blackboard, ElementKind, Sfc, Signal, SignalKind, Value};
use crate::plan::{Block, BranchEnd, Plan, condition_text as condition, one_line};

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

fn value_text(v: &Value) -> String {
    match v {
        Value::Scalar(s) => s.clone(),
        Value::List(items) => {
            let inner: Vec<String> = items.iter().map(value_text).collect();
            format!("[ {} ]", inner.join(", "))
        }
    }
}

/// `-pS`: the file header, then every SFC object with its connections.
pub fn sfc(sfc: &Sfc) -> String {
    let mut o = String::new();
    let h = &sfc.header;
    let parts: Vec<&str> = [
        &h.company_name,
        &h.product_name,
        &h.product_version,
        &h.creation_date_time,
    ]
    .iter()
    .map(|v| v.as_deref().unwrap_or("?"))
    .collect();
    let _ = writeln!(o, "{}", parts.join(", "));
    let _ = writeln!(o, "POU: {}", sfc.pou_name.as_deref().unwrap_or("?"));
    let mut succs: std::collections::HashMap<u64, Vec<u64>> = Default::default();
    for e in &sfc.elements {
        for (r, _) in &e.inputs {
            succs.entry(*r).or_default().push(e.local_id);
        }
    }
    let ids = |v: Option<&Vec<u64>>| match v {
        Some(v) if !v.is_empty() => v.iter().map(u64::to_string).collect::<Vec<_>>().join(", "),
        _ => "(?)".to_owned(),
    };
    for e in &sfc.elements {
        let ins: Vec<u64> = e.inputs.iter().map(|(r, _)| *r).collect();
        let conn = format!(
            "{} -> [ {} ] -> {}",
            ids(Some(&ins)),
            e.local_id,
            ids(succs.get(&e.local_id))
        );
        match &e.kind {
            ElementKind::Step(st) => {
                let _ = writeln!(
                    o,
                    "Step: {}     {}",
                    if st.initial { "*" } else { " " },
                    st.name
                );
                let _ = writeln!(o, "            {conn}");
                let _ = writeln!(
                    o,
                    "            Duration:   {}",
                    seconds(st.duration.unwrap_or(0.0))
                );
                if let Some(r) = &st.resource {
                    let _ = writeln!(o, "            Resource:   {}", r.text);
                }
                if let Some(s) = &st.skill {
                    let _ = writeln!(o, "            Skill:      {}", s.text);
                }
                for v in sfc.variables_of(st) {
                    let value = sfc.value_of(v);
                    let kind = match value {
                        Value::Scalar(_) => "(Value)",
                        Value::List(_) => "(List) ",
                    };
                    let _ = writeln!(
                        o,
                        "            {:<19} {kind}    = {}",
                        format!("{}:", v.name.text.to_uppercase()),
                        value_text(&value)
                    );
                }
            }
            k => {
                let _ = writeln!(o, "Transition  ({})", k.tag());
                let _ = writeln!(o, "            {conn}");
                match k {
                    ElementKind::Transition(Some(c)) => {
                        let _ = writeln!(
                            o,
                            "            Condition:  {}{}",
                            one_line(&c.text),
                            if c.reference { "   (reference)" } else { "" }
                        );
                    }
                    ElementKind::Transition(None) => {
                        let _ = writeln!(o, "            Condition:  TRUE");
                    }
                    ElementKind::JumpStep(Some(t)) => {
                        let _ = writeln!(o, "            Target:     {}", t.text);
                    }
                    _ => {}
                }
            }
        }
    }
    o
}

fn step_name(sfc: &Sfc, i: usize) -> &str {
    match &sfc.elements[i].kind {
        ElementKind::Step(s) => &s.name,
        _ => "",
    }
}

fn duration(sfc: &Sfc, i: usize) -> f64 {
    match &sfc.elements[i].kind {
        ElementKind::Step(s) => s.duration.unwrap_or(0.0),
        _ => 0.0,
    }
}

/// What the flow's total time means.
#[derive(Default)]
struct Totals {
    loops: bool,
    /// Flow in states ([`Block::Machine`]): each counted once.
    states: bool,
    endless: bool,
    choices: bool,
}

/// `-pF`: the flow as a pseudo-graphic: one line per step with its start time and duration;
/// simultaneous branches drawn as `{ | … + | … }` (so are the sequences of several initial
/// steps, with a title), selection branches as `< | ? cond … + … >`,
/// a loop as `[ loop … ]` with one round of its body. A block of branches ends when its longest
/// branch ends (simultaneous branches run in parallel in the plan, even though one robot runs
/// them in turn; of alternatives the longest is counted). A loop counts one round.
pub fn flow(sfc: &Sfc, plan: &Plan) -> String {
    fn walk(
        sfc: &Sfc,
        blocks: &[Block],
        t: f64,
        indent: &str,
        o: &mut String,
        tot: &mut Totals,
    ) -> f64 {
        let mut t = t;
        for b in blocks {
            match b {
                // Handshakes stand only in the programs of a cell, not in the chart's plan.
                Block::Tell(_) | Block::Hear(_) | Block::Follow { .. } => {}
                Block::Step(i) => {
                    let d = duration(sfc, *i);
                    let _ = writeln!(
                        o,
                        "{indent}id={:>4}, [@{:<6} + {:>6}], {}",
                        sfc.elements[*i].local_id,
                        fmt_num(t),
                        fmt_num(d),
                        step_name(sfc, *i)
                    );
                    t += d;
                }
                Block::Wait(tr) => {
                    let _ = writeln!(
                        o,
                        "{indent}wait for {} (transition id={})",
                        condition(sfc, *tr),
                        sfc.elements[*tr].local_id
                    );
                }
                Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                    if matches!(b, Block::Sequences(_)) {
                        let _ = writeln!(
                            o,
                            "{indent}{{ {} sequences at the same time, each from an initial step:",
                            branches.len()
                        );
                    } else {
                        let _ = writeln!(o, "{indent}{{");
                    }
                    let inner = format!("{indent} | ");
                    let mut end = t;
                    for (k, br) in branches.iter().enumerate() {
                        if k > 0 {
                            let _ = writeln!(o, "{indent} +");
                        }
                        end = end.max(walk(sfc, br, t, &inner, o, tot));
                    }
                    let _ = writeln!(o, "{indent}}}");
                    t = end;
                }
                Block::Choice {
                    divergence,
                    branches,
                    ..
                } => {
                    tot.choices = true;
                    let _ = writeln!(
                        o,
                        "{indent}< selection id={}, the longest branch counts",
                        sfc.elements[*divergence].local_id
                    );
                    let inner = format!("{indent} | ");
                    let mut end = t;
                    for (k, br) in branches.iter().enumerate() {
                        if k > 0 {
                            let _ = writeln!(o, "{indent} +");
                        }
                        let _ = writeln!(
                            o,
                            "{inner}? {} (transition id={})",
                            br.condition_text(sfc),
                            sfc.elements[br.transition].local_id
                        );
                        end = end.max(walk(sfc, &br.body, t, &inner, o, tot));
                        match br.end {
                            BranchEnd::Join => {}
                            BranchEnd::Repeat(j) => {
                                let how = match sfc.closed.iter().find(|c| c.jump == j) {
                                    Some(c) => format!(
                                        "connection back from id={}",
                                        sfc.elements[c.from].local_id
                                    ),
                                    None => format!("jump id={}", sfc.elements[j].local_id),
                                };
                                let _ = writeln!(o, "{inner}-> round again ({how})");
                            }
                            BranchEnd::Leave => {
                                let _ = writeln!(o, "{inner}-> leave the loop");
                            }
                        }
                    }
                    let _ = writeln!(o, "{indent}>");
                    t = end;
                }
                Block::Machine(states) => {
                    tot.states = true;
                    for (k, st) in states.iter().enumerate() {
                        let _ = writeln!(
                            o,
                            "{indent}[ state {} at id={}:",
                            k + 1,
                            sfc.elements[st.entry].local_id
                        );
                        let inner = format!("{indent} : ");
                        t = walk(sfc, &st.body, t, &inner, o, tot);
                        let _ = writeln!(o, "{indent}]");
                    }
                }
                Block::Goto { target, .. } => {
                    let _ = writeln!(
                        o,
                        "{indent}-> go on at id={}",
                        sfc.elements[*target].local_id
                    );
                }
                Block::Loop {
                    head,
                    body,
                    endless,
                    ..
                } => {
                    tot.loops = true;
                    tot.endless |= *endless;
                    let _ = writeln!(
                        o,
                        "{indent}[ loop back to id={}{}, one round:",
                        sfc.elements[*head].local_id,
                        if *endless { ", endless" } else { "" }
                    );
                    let inner = format!("{indent} : ");
                    t = walk(sfc, body, t, &inner, o, tot);
                    let _ = writeln!(o, "{indent}]");
                }
            }
        }
        t
    }
    let mut o = String::new();
    let mut tot = Totals::default();
    let total = walk(sfc, &plan.body, 0.0, "", &mut o, &mut tot);
    let what = if tot.endless {
        " per round (the program repeats without end)"
    } else if tot.states {
        " at least (loops and states counted once)"
    } else if tot.loops {
        " at least (loops counted once)"
    } else {
        ""
    };
    let longest = if tot.choices {
        ", the longest alternative counted"
    } else {
        ""
    };
    let _ = writeln!(o, "total: {}{what}{longest}", seconds(total));
    o
}

/// `1 second`, `0 seconds`, `1.5 seconds`.
fn seconds(x: f64) -> String {
    let n = fmt_num(x);
    if n == "1" {
        "1 second".to_owned()
    } else {
        format!("{n} seconds")
    }
}

fn fmt_num(x: f64) -> String {
    let s = format!("{x:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s.is_empty() {
        "0".to_owned()
    } else {
        s.to_owned()
    }
}

/// `-pO`: the execution order, one step per line with its number and localId; selections,
/// their branches' conditions and loops are shown around the steps they hold.
pub fn order(sfc: &Sfc, plan: &Plan) -> String {
    let mut o = String::new();
    order_lines(sfc, None, &plan.body, "", &mut 0, &mut o);
    o
}

/// The lines of `-pO` for `blocks`; with a cell's view, a program's handshakes too.
fn order_lines(
    sfc: &Sfc,
    view: Option<&CellView>,
    blocks: &[Block],
    indent: &str,
    n: &mut usize,
    o: &mut String,
) {
    for b in blocks {
        match b {
            Block::Step(i) => {
                *n += 1;
                // Aligned with spaces (no tabs): numbers to 999, localIds to 99999.
                let _ = writeln!(
                    o,
                    "{indent} {:<4} {:<10} {}",
                    format!("#{n}"),
                    format!("(id={})", sfc.elements[*i].local_id),
                    step_name(sfc, *i)
                );
            }
            Block::Wait(t) => {
                let _ = writeln!(o, "{indent} wait for {}", condition(sfc, *t));
            }
            // Handshakes stand only in the programs of a cell.
            Block::Tell(m) | Block::Hear(m) => {
                if let Some(v) = view {
                    let tell = matches!(b, Block::Tell(_));
                    let _ = writeln!(o, "{indent} {}", v.handshake(sfc, m, tell));
                }
            }
            Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                for br in branches {
                    order_lines(sfc, view, br, indent, n, o);
                }
            }
            Block::Machine(states) => {
                for (k, st) in states.iter().enumerate() {
                    let _ = writeln!(
                        o,
                        "{indent} state {} (id={}):",
                        k + 1,
                        sfc.elements[st.entry].local_id
                    );
                    order_lines(sfc, view, &st.body, &format!("{indent}    "), n, o);
                }
            }
            Block::Goto { target, .. } => {
                let _ = writeln!(o, "{indent} go on at id={}", sfc.elements[*target].local_id);
            }
            Block::Choice {
                divergence,
                branches,
                ..
            }
            | Block::Follow {
                divergence,
                branches,
                ..
            } => {
                let decided = match (b, view) {
                    (Block::Follow { heard, .. }, Some(v)) => format!(
                        "wait for {}: the branch it takes",
                        v.controller(v.cell.channels[heard.channel].from)
                    ),
                    _ => "the first branch whose condition holds".to_owned(),
                };
                let _ = writeln!(
                    o,
                    "{indent} selection (id={}): {decided}",
                    sfc.elements[*divergence].local_id
                );
                let inner = format!("{indent}    ");
                for (k, br) in branches.iter().enumerate() {
                    let _ = writeln!(o, "{indent}  {}. if {}", k + 1, br.condition_text(sfc));
                    order_lines(sfc, view, &br.body, &inner, n, o);
                    match br.end {
                        BranchEnd::Join => {}
                        BranchEnd::Repeat(_) => {
                            let _ = writeln!(o, "{inner} round again");
                        }
                        BranchEnd::Leave => {
                            let _ = writeln!(o, "{inner} leave the loop");
                        }
                    }
                }
            }
            Block::Loop {
                head,
                body,
                endless,
                ..
            } => {
                let _ = writeln!(
                    o,
                    "{indent} loop{} (back to id={}):",
                    if *endless { ", endless" } else { "" },
                    sfc.elements[*head].local_id
                );
                order_lines(sfc, view, body, &format!("{indent}  "), n, o);
            }
        }
    }
}

/// `--info`: version and build; with a blackboard, per resource the skills and the SFC
/// variables each needs (the original printed a fixed list of step types here).
pub fn info(bb: Option<&Blackboard>) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "skillpost v{}, build: {} {}",
        crate::VERSION,
        std::env::consts::OS,
        std::env::consts::ARCH
    );
    let _ = writeln!(
        o,
        "  Output profiles: KUKA KRL (.src/.dat), ABB RAPID (.mod), Universal Robots URScript (.script)"
    );
    let _ = writeln!(
        o,
        "  Step types: any; a step's variables come from its skill's SFC mapping"
    );
    if let Some(bb) = bb {
        for (ri, r) in bb.resources.iter().enumerate() {
            let _ = writeln!(o, "{}", r.name.text);
            let _ = writeln!(
                o,
                "  language {}",
                language_text(bb, ri, &Default::default())
            );
            if r.skills.is_empty() {
                let _ = writeln!(o, "  (no skills)");
            }
            for s in &r.signals {
                let _ = writeln!(o, "  signal {:<21} {}", s.name.text, signal_text(s));
            }
            for s in &r.skills {
                let vars = s.variables();
                let _ = writeln!(
                    o,
                    "  {:<28} variables: {}",
                    s.name.text,
                    if vars.is_empty() {
                        "none".to_owned()
                    } else {
                        vars.join(", ")
                    }
                );
            }
        }
    }
    o
}

/// The listings as JSON objects, for `--format json` (one object per listing, printed on one
/// line; docs/JSON.md). Each has `"listing"`: `blackboard`, `sfc`, `flow` or `order`.
pub mod json {
    use serde_json::{Value as Json, json};

    use super::{Totals, condition, duration, one_line, signal_text, step_name};
    use crate::model::{Blackboard, ElementKind, Sfc, SignalKind, Value};
    use crate::plan::{Block, BranchEnd, Plan};

    /// `-pB`: resources with their skills (and the calls each maps), functions and signals.
    pub fn blackboard(
        bb: &Blackboard,
        languages: &std::collections::HashMap<usize, crate::lang::Language>,
        uses: Option<&std::collections::HashMap<usize, String>>,
    ) -> Json {
        let resources: Vec<Json> = bb
            .resources
            .iter()
            .enumerate()
            .map(|(ri, r)| {
                let mut skills: Vec<_> = r.skills.iter().collect();
                skills.sort_by(|a, b| a.name.key.cmp(&b.name.key));
                let skills: Vec<Json> = skills
                    .iter()
                    .map(|s| {
                        let calls: Vec<Json> = s
                            .mappings
                            .iter()
                            .map(|m| {
                                json!({
                                    "function": &*m.function.text,
                                    "arguments": m.args.iter().map(|a| &*a.skill_param.text).collect::<Vec<_>>(),
                                    "order": m.order,
                                })
                            })
                            .collect();
                        json!({"name": &*s.name.text, "id": s.id, "calls": calls})
                    })
                    .collect();
                let mut funcs: Vec<_> = r.functions.iter().collect();
                funcs.sort_by(|a, b| a.name.key.cmp(&b.name.key));
                let functions: Vec<Json> = funcs
                    .iter()
                    .map(|f| {
                        json!({
                            "name": &*f.name.text,
                            "id": f.id,
                            "irl": f.irl.value,
                            "command": &*f.command.text,
                        })
                    })
                    .collect();
                let signals: Vec<Json> = r
                    .signals
                    .iter()
                    .map(|s| {
                        let mut o = json!({
                            "name": &*s.name.text,
                            "direction": if s.output { "output" } else { "input" },
                            "type": if s.is_integer() { "integer" } else { "bit" },
                        });
                        match &s.kind {
                            SignalKind::Bit(n) => o["number"] = json!(n),
                            SignalKind::Group { number, length } => {
                                o["number"] = json!(number);
                                o["length"] = json!(length);
                            }
                            SignalKind::Address { text, .. } => o["address"] = json!(text),
                        }
                        o["text"] = json!(signal_text(s));
                        o
                    })
                    .collect();
                let language = languages
                    .get(&ri)
                    .copied()
                    .or(r.language.as_ref().map(|(l, _)| *l));
                let controller = bb.controller_of(ri);
                json!({
                    "name": &*r.name.text,
                    "id": r.id,
                    "controller": &*bb.resources[controller].name.text,
                    "controller_description": r.controller_attr.as_ref()
                        .filter(|_| controller == ri)
                        .map(|(v, _)| v),
                    "language": language.map(|l| l.name()),
                    "language_from": match (languages.get(&ri), &r.language) {
                        (_, Some(_)) => "attribute",
                        (Some(_), None) => "irl-or-default",
                        (None, None) => "unknown",
                    },
                    "skills": skills,
                    "functions": functions,
                    "signals": signals,
                })
            })
            .collect();
        let wires: Vec<Json> = bb
            .wires
            .iter()
            .enumerate()
            .map(|(k, w)| {
                let end = |(r, si): (usize, usize)| {
                    json!({
                        "resource": &*bb.resources[r].name.text,
                        "controller": &*bb.resources[bb.controller_of(r)].name.text,
                        "signal": &*bb.resources[r].signals[si].name.text,
                    })
                };
                json!({
                    "name": w.name,
                    "from": end(w.from),
                    "to": end(w.to),
                    "handshake": uses.and_then(|u| u.get(&k)),
                })
            })
            .collect();
        json!({"listing": "blackboard", "resources": resources, "wires": wires})
    }

    fn value(v: &Value) -> Json {
        match v {
            Value::Scalar(s) => json!(s),
            Value::List(items) => Json::Array(items.iter().map(value).collect()),
        }
    }

    /// `-pS`: the file header, the POU, and every SFC object with its connections.
    pub fn sfc(sfc: &Sfc) -> Json {
        let h = &sfc.header;
        let mut succs: std::collections::HashMap<u64, Vec<u64>> = Default::default();
        for e in &sfc.elements {
            for (r, _) in &e.inputs {
                succs.entry(*r).or_default().push(e.local_id);
            }
        }
        let objects: Vec<Json> = sfc
            .elements
            .iter()
            .map(|e| {
                let mut o = json!({
                    "kind": e.kind.tag(),
                    "local_id": e.local_id,
                    "inputs": e.inputs.iter().map(|(r, _)| *r).collect::<Vec<_>>(),
                    "outputs": succs.get(&e.local_id).cloned().unwrap_or_default(),
                });
                match &e.kind {
                    ElementKind::Step(st) => {
                        o["name"] = json!(&*st.name);
                        o["initial"] = json!(st.initial);
                        o["duration"] = json!(st.duration.unwrap_or(0.0));
                        o["resource"] = json!(st.resource.as_ref().map(|r| &*r.text));
                        o["skill"] = json!(st.skill.as_ref().map(|s| &*s.text));
                        o["variables"] = Json::Array(
                            sfc.variables_of(st)
                                .iter()
                                .map(|v| json!({"name": &*v.name.text, "value": value(&sfc.value_of(v))}))
                                .collect(),
                        );
                    }
                    ElementKind::Transition(c) => {
                        o["condition"] = json!(
                            c.as_ref()
                                .map_or_else(|| "TRUE".to_owned(), |c| one_line(&c.text))
                        );
                        o["reference"] = json!(c.as_ref().is_some_and(|c| c.reference));
                    }
                    ElementKind::JumpStep(t) => {
                        o["target"] = json!(t.as_ref().map(|t| &*t.text));
                    }
                    _ => {}
                }
                o
            })
            .collect();
        json!({
            "listing": "sfc",
            "header": {
                "company_name": h.company_name,
                "product_name": h.product_name,
                "product_version": h.product_version,
                "creation_date_time": h.creation_date_time,
            },
            "pou": sfc.pou_name,
            "objects": objects,
        })
    }

    fn local_id(sfc: &Sfc, i: usize) -> u64 {
        sfc.elements[i].local_id
    }

    /// `-pF`: the flow as a tree of blocks with start times and durations (seconds), and the
    /// total. Times are counted as in the text listing.
    pub fn flow(sfc: &Sfc, plan: &Plan) -> Json {
        fn walk(sfc: &Sfc, blocks: &[Block], t: f64, tot: &mut Totals) -> (Vec<Json>, f64) {
            let mut t = t;
            let mut out = Vec::new();
            for b in blocks {
                match b {
                    // Handshakes stand only in the programs of a cell, not in the chart's plan.
                    Block::Tell(_) | Block::Hear(_) | Block::Follow { .. } => {}
                    Block::Step(i) => {
                        let d = duration(sfc, *i);
                        out.push(json!({
                            "kind": "step",
                            "local_id": local_id(sfc, *i),
                            "name": step_name(sfc, *i),
                            "start": t,
                            "duration": d,
                        }));
                        t += d;
                    }
                    Block::Wait(tr) => out.push(json!({
                        "kind": "wait",
                        "condition": condition(sfc, *tr),
                        "transition": local_id(sfc, *tr),
                    })),
                    Block::Machine(states) => {
                        tot.states = true;
                        let mut ss = Vec::new();
                        for st in states {
                            let (blocks, e) = walk(sfc, &st.body, t, tot);
                            t = e;
                            ss.push(json!({"entry": local_id(sfc, st.entry), "blocks": blocks}));
                        }
                        out.push(json!({"kind": "states", "states": ss}));
                    }
                    Block::Goto { target, .. } => out.push(json!({
                        "kind": "goto",
                        "target": local_id(sfc, *target),
                    })),
                    Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                        // All start together; the block ends with the longest.
                        let start = t;
                        let mut end = t;
                        let mut bs = Vec::new();
                        for br in branches {
                            let (blocks, e) = walk(sfc, br, start, tot);
                            end = end.max(e);
                            bs.push(json!({"blocks": blocks}));
                        }
                        out.push(match b {
                            Block::Parallel { divergence, .. } => json!({
                                "kind": "parallel",
                                "divergence": local_id(sfc, *divergence),
                                "start": start,
                                "end": end,
                                "branches": bs,
                            }),
                            _ => json!({
                                "kind": "sequences",
                                "start": start,
                                "end": end,
                                "sequences": bs,
                            }),
                        });
                        t = end;
                    }
                    Block::Choice {
                        divergence,
                        branches,
                        ..
                    } => {
                        tot.choices = true;
                        let start = t;
                        let mut end = t;
                        let mut bs = Vec::new();
                        for br in branches {
                            let (blocks, e) = walk(sfc, &br.body, start, tot);
                            end = end.max(e);
                            let mut o = json!({
                                "condition": br.condition_text(sfc),
                                "transition": local_id(sfc, br.transition),
                                "blocks": blocks,
                            });
                            match br.end {
                                BranchEnd::Join => o["then"] = json!("join"),
                                BranchEnd::Repeat(j) => {
                                    o["then"] = json!("repeat");
                                    o["jump"] = json!(local_id(sfc, j));
                                }
                                BranchEnd::Leave => o["then"] = json!("leave"),
                            }
                            bs.push(o);
                        }
                        out.push(json!({
                            "kind": "selection",
                            "divergence": local_id(sfc, *divergence),
                            "start": start,
                            "end": end,
                            "branches": bs,
                        }));
                        t = end;
                    }
                    Block::Loop {
                        head,
                        body,
                        endless,
                        ..
                    } => {
                        tot.loops = true;
                        tot.endless |= *endless;
                        let start = t;
                        let (blocks, e) = walk(sfc, body, t, tot);
                        out.push(json!({
                            "kind": "loop",
                            "head": local_id(sfc, *head),
                            "endless": endless,
                            "start": start,
                            "end": e,
                            "blocks": blocks,
                        }));
                        t = e;
                    }
                }
            }
            (out, t)
        }
        let mut tot = Totals::default();
        let (blocks, total) = walk(sfc, &plan.body, 0.0, &mut tot);
        json!({
            "listing": "flow",
            "blocks": blocks,
            "total": {
                "seconds": total,
                "at_least": (tot.loops || tot.states) && !tot.endless,
                "per_round": tot.endless,
                "longest_alternative": tot.choices,
            },
        })
    }

    /// `-pO`: the execution order as a tree of blocks.
    pub fn order(sfc: &Sfc, plan: &Plan) -> Json {
        let mut blocks = Vec::new();
        let mut n = 0;
        order_blocks(sfc, None, &plan.body, &mut n, &mut blocks);
        json!({"listing": "order", "steps": n, "blocks": blocks})
    }

    /// The blocks of `-pO`; with a cell's view, a program's handshakes too (`tell`, `hear`,
    /// and `decided_by` of a selection it follows).
    fn order_blocks(
        sfc: &Sfc,
        view: Option<&super::CellView>,
        blocks: &[Block],
        n: &mut usize,
        out: &mut Vec<Json>,
    ) {
        for b in blocks {
            match b {
                Block::Step(i) => {
                    *n += 1;
                    out.push(json!({
                        "kind": "step",
                        "number": *n,
                        "local_id": local_id(sfc, *i),
                        "name": step_name(sfc, *i),
                    }));
                }
                Block::Wait(t) => out.push(json!({
                    "kind": "wait",
                    "condition": condition(sfc, *t),
                    "transition": local_id(sfc, *t),
                })),
                Block::Machine(states) => {
                    let mut ss = Vec::new();
                    for st in states {
                        let mut blocks = Vec::new();
                        order_blocks(sfc, view, &st.body, n, &mut blocks);
                        ss.push(json!({"entry": local_id(sfc, st.entry), "blocks": blocks}));
                    }
                    out.push(json!({"kind": "states", "states": ss}));
                }
                Block::Goto { target, .. } => out.push(json!({
                    "kind": "goto",
                    "target": local_id(sfc, *target),
                })),
                Block::Tell(m) | Block::Hear(m) => {
                    let Some(view) = view else {
                        continue;
                    };
                    let tell = matches!(b, Block::Tell(_));
                    let ch = &view.cell.channels[m.channel];
                    let decision = m.kind == crate::plan::cell::Kind::Decision;
                    out.push(json!({
                        "kind": if tell { "tell" } else { "hear" },
                        "controller": view.controller(if tell { ch.to } else { ch.from }),
                        "about": local_id(sfc, m.about),
                        "decision": decision,
                        "branch": (tell && decision).then_some(m.value + 1),
                        "passed": match m.kind {
                            crate::plan::cell::Kind::Passed(c) => Some(c.name()),
                            _ => None,
                        },
                    }));
                }
                Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                    for br in branches {
                        order_blocks(sfc, view, br, n, out);
                    }
                }
                Block::Choice {
                    divergence,
                    branches,
                    ..
                }
                | Block::Follow {
                    divergence,
                    branches,
                    ..
                } => {
                    let bs: Vec<Json> = branches
                        .iter()
                        .map(|br| {
                            let mut blocks = Vec::new();
                            order_blocks(sfc, view, &br.body, n, &mut blocks);
                            json!({
                                "condition": br.condition_text(sfc),
                                "transition": local_id(sfc, br.transition),
                                "blocks": blocks,
                                "then": match br.end {
                                    BranchEnd::Join => "join",
                                    BranchEnd::Repeat(_) => "repeat",
                                    BranchEnd::Leave => "leave",
                                },
                            })
                        })
                        .collect();
                    let mut selection = json!({
                        "kind": "selection",
                        "divergence": local_id(sfc, *divergence),
                    });
                    if let Some(v) = view {
                        selection["decided_by"] = match b {
                            Block::Follow { heard, .. } => {
                                json!(v.controller(v.cell.channels[heard.channel].from))
                            }
                            _ => Json::Null,
                        };
                    }
                    selection["branches"] = Json::Array(bs);
                    out.push(selection);
                }
                Block::Loop {
                    head,
                    body,
                    endless,
                    ..
                } => {
                    let mut blocks = Vec::new();
                    order_blocks(sfc, view, body, n, &mut blocks);
                    out.push(json!({
                        "kind": "loop",
                        "head": local_id(sfc, *head),
                        "endless": endless,
                        "blocks": blocks,
                    }));
                }
            }
        }
    }

    /// A listing that cannot be printed (`-pF`/`-pO` when the flow has errors).
    pub fn unavailable(listing: &str, reason: &str) -> Json {
        json!({"listing": listing, "available": false, "reason": reason})
    }

    /// `-pO` of a cell: each program with its blocks, handshakes included (`tell`, `hear`, a
    /// selection it follows, `decided_by` its decider).
    pub fn cell_order(sfc: &Sfc, view: &super::CellView) -> Json {
        let mut total = 0;
        let programs: Vec<Json> = view
            .cell
            .programs
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let mut blocks = Vec::new();
                let mut n = 0;
                order_blocks(sfc, Some(view), &p.body, &mut n, &mut blocks);
                total += n;
                json!({
                    "program": view.names.get(k),
                    "controller": view.controller(k),
                    "steps": n,
                    "blocks": blocks,
                })
            })
            .collect();
        json!({"listing": "order", "steps": total, "programs": programs})
    }

    /// `-pF` of a cell: one lane per controller with its steps and its waits for others, and
    /// the cell's time.
    pub fn cell_flow(sfc: &Sfc, plan: &Plan, view: &super::CellView) -> Json {
        let (lanes, total) = super::cell_timeline(sfc, plan, view);
        let lanes: Vec<Json> = lanes
            .iter()
            .enumerate()
            .map(|(k, lane)| {
                let items: Vec<Json> = lane
                    .iter()
                    .map(|it| match it.waits_for {
                        Some(c) => json!({
                            "kind": "wait",
                            "start": it.start,
                            "end": it.end,
                            "for_controller": view.controller(c),
                            "for_step": local_id(sfc, it.element),
                        }),
                        None => json!({
                            "kind": "step",
                            "start": it.start,
                            "duration": it.end - it.start,
                            "local_id": local_id(sfc, it.element),
                            "name": step_name(sfc, it.element),
                        }),
                    })
                    .collect();
                json!({
                    "controller": view.controller(k),
                    "program": view.names.get(k),
                    "items": items,
                })
            })
            .collect();
        json!({"listing": "flow", "lanes": lanes, "total": total})
    }
}

// ---------------------------------------------------------------------------------------------
// Cells (docs/CELLS.md): `-pO` per program, `-pF` one lane per controller
// ---------------------------------------------------------------------------------------------

/// What the cell listings need besides the chart: the programs, the blackboard's names, the
/// programs' names (empty without a program name).
pub struct CellView<'a> {
    pub cell: &'a crate::plan::cell::Cell,
    pub bb: &'a Blackboard,
    pub names: &'a [String],
}

impl CellView<'_> {
    /// Controller `k`'s resource name.
    pub fn controller(&self, k: usize) -> &str {
        &self.bb.resources[self.cell.controllers[k]].name.text
    }

    /// Program `k`'s name (`the program of <controller>` without a program name).
    pub fn program(&self, k: usize) -> String {
        self.names
            .get(k)
            .cloned()
            .unwrap_or_else(|| format!("the program of {}", self.controller(k)))
    }

    /// A handshake as one line, for program `me`.
    fn handshake(&self, sfc: &Sfc, m: &crate::plan::cell::Message, tell: bool) -> String {
        use crate::plan::cell::Kind;
        let ch = &self.cell.channels[m.channel];
        let about = match &sfc.elements[m.about].kind {
            ElementKind::Step(s) => {
                format!("step {} (id={})", s.name, sfc.elements[m.about].local_id)
            }
            _ => format!("id={}", sfc.elements[m.about].local_id),
        };
        match (tell, m.kind) {
            (true, Kind::Done) => format!("tell {}: {about} done", self.controller(ch.to)),
            (true, Kind::Decision) => format!(
                "tell {}: branch {} taken at the selection {about}",
                self.controller(ch.to),
                m.value + 1
            ),
            (false, Kind::Done) => format!("wait for {}: {about} done", self.controller(ch.from)),
            (true, Kind::Passed(c)) => {
                format!("tell {}: it {} {about}", self.controller(ch.to), c.verb())
            }
            (false, Kind::Passed(c)) => {
                format!(
                    "wait for {}: it {} {about}",
                    self.controller(ch.from),
                    c.verb()
                )
            }
            (false, Kind::Decision) => format!(
                "wait for {}: its branch at the selection {about}",
                self.controller(ch.from)
            ),
        }
    }
}

/// `-pO` of a cell: each program's order, with its handshakes.
pub fn cell_order(sfc: &Sfc, view: &CellView) -> String {
    let mut o = String::new();
    for (k, p) in view.cell.programs.iter().enumerate() {
        let _ = writeln!(
            o,
            "program {} (controller {}):",
            view.program(k),
            view.controller(k)
        );
        order_lines(sfc, Some(view), &p.body, " ", &mut 0, &mut o);
    }
    o
}

/// One lane's entry of a cell's timeline: a step, or a wait for another controller.
#[derive(Debug, Clone, PartialEq)]
pub struct LaneItem {
    pub start: f64,
    pub end: f64,
    /// The step, or (for a wait) the step waited for.
    pub element: usize,
    /// For a wait: the controller waited for.
    pub waits_for: Option<usize>,
}

/// The cell's timeline (`-pF`): each controller's steps at the earliest times the chart
/// allows them (every step after the steps the chart puts before it, on any controller, and
/// after its controller's step before it in its program), its waits for other controllers, and
/// the cell's time. Simultaneous branches on different controllers overlap; a selection counts
/// its longest branch, a loop one round.
pub fn cell_timeline(sfc: &Sfc, plan: &Plan, view: &CellView) -> (Vec<Vec<LaneItem>>, f64) {
    let n = view.cell.controllers.len();
    // Each step's controller, from the programs.
    let mut of: std::collections::HashMap<usize, usize> = Default::default();
    for (k, p) in view.cell.programs.iter().enumerate() {
        crate::plan::visit(&p.body, &mut |b| {
            if let Block::Step(i) = b {
                of.insert(*i, k);
            }
        });
    }
    struct T<'s> {
        sfc: &'s Sfc,
        of: std::collections::HashMap<usize, usize>,
        lanes: Vec<Vec<LaneItem>>,
        free: Vec<f64>,
    }
    // A frontier: (time the steps before end, the last step ended then and its controller).
    type Front = (f64, Option<(usize, usize)>);
    fn walk(t: &mut T, blocks: &[Block], mut front: Front) -> Front {
        for b in blocks {
            match b {
                Block::Step(i) => {
                    let Some(&c) = t.of.get(i) else {
                        continue;
                    };
                    let d = duration(t.sfc, *i);
                    let start = front.0.max(t.free[c]);
                    if let Some((pc, pi)) = front.1
                        && pc != c
                        && front.0 > t.free[c]
                    {
                        t.lanes[c].push(LaneItem {
                            start: t.free[c],
                            end: front.0,
                            element: pi,
                            waits_for: Some(pc),
                        });
                    }
                    t.lanes[c].push(LaneItem {
                        start,
                        end: start + d,
                        element: *i,
                        waits_for: None,
                    });
                    t.free[c] = start + d;
                    front = (start + d, Some((c, *i)));
                }
                Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                    let mut end = front;
                    for br in branches {
                        let e = walk(t, br, front);
                        if e.0 >= end.0 {
                            end = e;
                        }
                    }
                    front = end;
                }
                Block::Choice { branches, .. } | Block::Follow { branches, .. } => {
                    // The longest branch counts: each tried from the same lanes; what a
                    // branch adds is taken off again (the lanes are not copied per branch).
                    let lens: Vec<usize> = t.lanes.iter().map(Vec::len).collect();
                    let free = t.free.clone();
                    let mut best: Option<(Front, Vec<Vec<LaneItem>>, Vec<f64>)> = None;
                    for br in branches {
                        t.free.clone_from(&free);
                        let e = walk(t, &br.body, front);
                        let added: Vec<Vec<LaneItem>> = t
                            .lanes
                            .iter_mut()
                            .zip(&lens)
                            .map(|(lane, &n)| lane.split_off(n))
                            .collect();
                        if best.as_ref().is_none_or(|b| e.0 > b.0.0) {
                            best = Some((e, added, t.free.clone()));
                        }
                    }
                    match best {
                        Some((e, added, f)) => {
                            front = e;
                            for (lane, mut more) in t.lanes.iter_mut().zip(added) {
                                lane.append(&mut more);
                            }
                            t.free = f;
                        }
                        None => t.free = free,
                    }
                }
                Block::Loop { body, .. } => front = walk(t, body, front),
                Block::Machine(states) => {
                    for st in states {
                        front = walk(t, &st.body, front);
                    }
                }
                Block::Goto { .. } => {}
                Block::Wait(_) | Block::Tell(_) | Block::Hear(_) => {}
            }
        }
        front
    }
    let mut t = T {
        sfc,
        of,
        lanes: vec![Vec::new(); n],
        free: vec![0.0; n],
    };
    let end = walk(&mut t, &plan.body, (0.0, None));
    let total = t.free.iter().copied().fold(end.0, f64::max);
    (t.lanes, total)
}

/// `-pF` of a cell: one column per controller, a row per moment something starts, the waits
/// between controllers, and the cell's time.
pub fn cell_flow(sfc: &Sfc, plan: &Plan, view: &CellView) -> String {
    let (lanes, total) = cell_timeline(sfc, plan, view);
    const W: usize = 30;
    let cut = |s: String| -> String {
        if s.chars().count() > W {
            s.chars().take(W - 1).collect::<String>() + "…"
        } else {
            s
        }
    };
    let mut o = String::new();
    let _ = write!(o, "{:<8}", "time");
    for k in 0..lanes.len() {
        let _ = write!(o, " | {:<W$}", cut(view.controller(k).to_owned()));
    }
    let _ = writeln!(o);
    let mut rows: Vec<(f64, usize, String)> = Vec::new();
    for (k, lane) in lanes.iter().enumerate() {
        for it in lane {
            let text = match it.waits_for {
                Some(c) => format!(
                    "waits for {} (id={})",
                    view.controller(c),
                    sfc.elements[it.element].local_id
                ),
                None => format!(
                    "{} (id={}) + {}",
                    step_name(sfc, it.element),
                    sfc.elements[it.element].local_id,
                    fmt_num(it.end - it.start)
                ),
            };
            rows.push((it.start, k, text));
        }
    }
    rows.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    for (time, k, text) in rows {
        let _ = write!(o, "{:<8}", fmt_num(time));
        for c in 0..lanes.len() {
            let cell = if c == k {
                cut(text.clone())
            } else {
                String::new()
            };
            let _ = write!(o, " | {cell:<W$}");
        }
        let _ = writeln!(o);
    }
    let _ = writeln!(
        o,
        "cell time: {} (simultaneous branches on different controllers overlap; the longest alternative counted, loops once)",
        seconds(total)
    );
    o
}
