//! The report of `skillpost simulate`: text for a person, JSON for a program (one document),
//! and the signals and wires of the first run as a Value Change Dump (IEEE 1364-2005, 18.2)
//! that GTKWave and Surfer open.

use std::fmt::Write as _;

use serde_json::{Value, json};

use super::ir::Val;
use super::{Report, engine::Outcome};

fn secs(t: f64) -> String {
    format!("{t:.2}")
}

/// The cycle time of a run: when every program had ended; `None` when they did not.
pub fn cycle(o: &Outcome) -> Option<f64> {
    o.ended.then_some(o.end_time)
}

/// The report as text.
pub fn human(r: &Report) -> String {
    let mut s = String::new();
    let names: Vec<String> = r
        .cell
        .controllers
        .iter()
        .map(|c| format!("{} ({})", c.name, c.file))
        .collect();
    let _ = writeln!(
        s,
        "simulate: {} run{} of {} controller{}: {}{}",
        r.runs.len(),
        if r.runs.len() == 1 { "" } else { "s" },
        names.len(),
        if names.len() == 1 { "" } else { "s" },
        names.join(", "),
        r.scenario
            .as_ref()
            .map(|f| format!("; scenario {f}"))
            .unwrap_or_else(|| "; random inputs and timing".to_owned())
    );
    let width = r
        .cell
        .controllers
        .iter()
        .map(|c| c.name.chars().count())
        .max()
        .unwrap_or(0);
    for (k, (seed, o)) in r.runs.iter().enumerate() {
        let head = match (cycle(o), o.repeats) {
            (Some(c), _) => format!("cycle time {} s", secs(c)),
            (None, true) => format!(
                "the chart repeats: stopped after {} steps at {} s",
                o.timeline.len(),
                secs(o.end_time)
            ),
            (None, false) => format!("did not end (stopped at {} s)", secs(o.end_time)),
        };
        let shown = k == 0 || !o.problems.is_empty();
        if !shown {
            continue;
        }
        let _ = writeln!(
            s,
            "\nrun {} (seed {seed}): {head}, {} problem{}",
            k + 1,
            o.problems.len(),
            if o.problems.len() == 1 { "" } else { "s" }
        );
        if !o.timeline.is_empty() {
            for st in &o.timeline {
                let c = &r.cell.controllers[st.controller];
                let _ = writeln!(
                    s,
                    "  {:>8} {:>8}  {:<width$}  {} (localId {}){}",
                    secs(st.start),
                    secs(st.end),
                    c.name,
                    st.name,
                    st.local_id,
                    if st.cut {
                        ", cut short by a restart"
                    } else {
                        ""
                    },
                );
            }
            for (c, t) in &o.restarts {
                let _ = writeln!(
                    s,
                    "  {:>8}           {:<width$}  started again",
                    secs(*t),
                    r.cell.controllers[*c].name
                );
            }
        }
        for p in &o.problems {
            let place = match (p.controller, p.line) {
                (Some(c), Some(l)) => format!(" [{}:{l}]", r.cell.controllers[c].file),
                _ => String::new(),
            };
            let element = p
                .local_id
                .map(|id| format!(" (chart element localId {id})"))
                .unwrap_or_default();
            let _ = writeln!(
                s,
                "  problem: {} at {} s: {}{element}{place}",
                p.kind.name(),
                secs(p.time),
                p.message
            );
        }
    }
    let quiet = r
        .runs
        .iter()
        .skip(1)
        .filter(|o| o.1.problems.is_empty())
        .count();
    if quiet > 0 {
        let cycles: Vec<f64> = r.runs.iter().filter_map(|o| cycle(&o.1)).collect();
        let range = if cycles.is_empty() {
            String::new()
        } else {
            let lo = cycles.iter().copied().fold(f64::MAX, f64::min);
            let hi = cycles.iter().copied().fold(f64::MIN, f64::max);
            format!("; cycle times {} to {} s", secs(lo), secs(hi))
        };
        let _ = writeln!(s, "\n{quiet} more run(s) without problems{range}");
    }
    if r.runs.len() > 1 {
        if r.never_steps.is_empty() && r.never_branches.is_empty() {
            let _ = writeln!(s, "\ncoverage: every step and branch was reached");
        } else {
            let _ = writeln!(s, "\ncoverage: never reached in {} runs:", r.runs.len());
            for (id, name) in &r.never_steps {
                let _ = writeln!(s, "  step {name} (localId {id})");
            }
            for (t, sel) in &r.never_branches {
                let _ = writeln!(
                    s,
                    "  the branch of transition localId {t}{}",
                    sel.map(|x| format!(" (selection localId {x})"))
                        .unwrap_or_default()
                );
            }
        }
    }
    if !r.not_simulated.is_empty() {
        let _ = writeln!(
            s,
            "\nnot simulated (they take no time of their own; their step's time covers them):"
        );
        for (c, line, text) in &r.not_simulated {
            let _ = writeln!(s, "  {}:{line}: {text}", r.cell.controllers[*c].file);
        }
    }
    let n = r.problems();
    let _ = writeln!(
        s,
        "\n{}",
        if n == 0 {
            "no problems".to_owned()
        } else {
            format!("{n} problem{}", if n == 1 { "" } else { "s" })
        }
    );
    s
}

/// The report as one JSON document.
pub fn json(r: &Report) -> Value {
    let ctl = |c: usize| r.cell.controllers[c].name.clone();
    let runs: Vec<Value> = r
        .runs
        .iter()
        .enumerate()
        .map(|(k, (seed, o))| {
            json!({
                "run": k + 1,
                "seed": seed,
                "ended": o.ended,
                "repeats": o.repeats,
                "cycle_s": cycle(o),
                "end_s": o.end_time,
                "timeline": o.timeline.iter().map(|s| json!({
                    "controller": ctl(s.controller),
                    "step": s.name,
                    "local_id": s.local_id,
                    "start_s": s.start,
                    "end_s": s.end,
                    "cut": s.cut,
                })).collect::<Vec<_>>(),
                "restarts": o.restarts.iter().map(|(c, t)| json!({"controller": ctl(*c), "at_s": t})).collect::<Vec<_>>(),
                "problems": o.problems.iter().map(|p| json!({
                    "kind": p.kind.name(),
                    "time_s": p.time,
                    "controller": p.controller.map(ctl),
                    "file": p.controller.map(|c| r.cell.controllers[c].file.clone()),
                    "line": p.line,
                    "local_id": p.local_id,
                    "message": p.message,
                })).collect::<Vec<_>>(),
            })
        })
        .collect();
    json!({
        "schema": "skillpost.simulation/1",
        "controllers": r.cell.controllers.iter().map(|c| json!({
            "name": c.name, "program": c.program, "file": c.file, "language": c.language.name(),
        })).collect::<Vec<_>>(),
        "scenario": r.scenario,
        "runs": runs,
        "problems": r.problems(),
        "coverage": {
            "steps_never_reached": r.never_steps.iter().map(|(id, n)| json!({"local_id": id, "step": n})).collect::<Vec<_>>(),
            "branches_never_reached": r.never_branches.iter().map(|(t, s)| json!({"transition": t, "selection": s})).collect::<Vec<_>>(),
        },
        "not_simulated": r.not_simulated.iter().map(|(c, l, t)| json!({
            "controller": ctl(*c), "file": r.cell.controllers[*c].file, "line": l, "statement": t,
        })).collect::<Vec<_>>(),
    })
}

/// A VCD identifier: printable ASCII from `!` on, base 94.
fn vcd_id(mut k: usize) -> String {
    let mut s = String::new();
    loop {
        s.push((b'!' + (k % 94) as u8) as char);
        k /= 94;
        if k == 0 {
            return s;
        }
    }
}

/// A name VCD readers take: letters, digits and `_` (others become `_`).
fn vcd_name(s: &str) -> String {
    let t: String = s
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if t.is_empty() { "_".into() } else { t }
}

/// The first run's signals and wires as a Value Change Dump: a scope per controller, a
/// variable per input, output and wire it has (wires by their link's name), time in ms.
pub fn vcd(r: &Report) -> String {
    let Some((_, o)) = r.runs.first() else {
        return String::new();
    };
    // Every (controller, key) that a change names, plus every wire's two ends and every input.
    let mut vars: Vec<(usize, String, String, bool)> = Vec::new();
    let mut add = |c: usize, key: &str, name: String, integer: bool| {
        if !vars.iter().any(|v| v.0 == c && v.1 == key) {
            vars.push((c, key.to_owned(), name, integer));
        }
    };
    for w in &r.cell.wires {
        add(w.from.0, &w.from.1, format!("{}_out", w.name), false);
        add(w.to.0, &w.to.1, format!("{}_in", w.name), false);
    }
    for i in &r.cell.inputs {
        if i.key.len() == 1 {
            add(i.controller, &i.key[0], i.name.clone(), i.integer);
        } else {
            for (b, k) in i.key.iter().enumerate() {
                add(i.controller, k, format!("{}_{b}", i.name), false);
            }
        }
    }
    for (_, c, k, v) in &o.changes {
        add(*c, k, k.clone(), matches!(v, Val::Num(_)));
    }
    let mut s = String::new();
    let _ = writeln!(s, "$date skillpost simulate $end");
    let _ = writeln!(s, "$version skillpost {} $end", crate::VERSION);
    let _ = writeln!(s, "$timescale 1 ms $end");
    for (c, ctl) in r.cell.controllers.iter().enumerate() {
        let _ = writeln!(s, "$scope module {} $end", vcd_name(&ctl.name));
        for (k, v) in vars.iter().enumerate().filter(|v| v.1.0 == c) {
            let (size, kind) = if v.3 { (32, "integer") } else { (1, "wire") };
            let _ = writeln!(
                s,
                "$var {kind} {size} {} {} $end",
                vcd_id(k),
                vcd_name(&v.2)
            );
        }
        let _ = writeln!(s, "$upscope $end");
    }
    let _ = writeln!(s, "$enddefinitions $end");
    let value = |v: &Val, integer: bool, id: &str| -> String {
        if integer {
            format!("b{:b} {id}", v.num().unwrap_or(0.0).max(0.0) as u64)
        } else {
            format!("{}{id}", u8::from(v.truth()))
        }
    };
    // Everything starts at 0 (a wire's output is FALSE until its program sets it).
    let _ = writeln!(s, "#0\n$dumpvars");
    for (k, v) in vars.iter().enumerate() {
        let _ = writeln!(
            s,
            "{}",
            value(
                &if v.3 { Val::Num(0.0) } else { Val::Bool(false) },
                v.3,
                &vcd_id(k)
            )
        );
    }
    let _ = writeln!(s, "$end");
    let mut changes: Vec<&(f64, usize, String, Val)> = o.changes.iter().collect();
    changes.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut now = 0u64;
    for (t, c, key, v) in changes {
        let ms = (t * 1000.0).round().max(0.0) as u64;
        // A wire's output is read at its input too: both change.
        let mut ids: Vec<usize> = vars
            .iter()
            .enumerate()
            .filter(|(_, x)| x.0 == *c && x.1 == *key)
            .map(|(k, _)| k)
            .collect();
        for w in &r.cell.wires {
            if w.from.0 == *c
                && w.from.1 == *key
                && let Some(k) = vars.iter().position(|x| x.0 == w.to.0 && x.1 == w.to.1)
            {
                ids.push(k);
            }
        }
        if ms != now {
            let _ = writeln!(s, "#{ms}");
            now = ms;
        }
        for k in ids {
            let _ = writeln!(s, "{}", value(v, vars[k].3, &vcd_id(k)));
        }
    }
    let end = (o.end_time * 1000.0).round().max(0.0) as u64;
    if end > now {
        let _ = writeln!(s, "#{end}");
    }
    s
}
