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
            (None, false) if o.capped => format!(
                "stopped after {} steps at {} s: the random inputs kept a loop going",
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
                "capped": o.capped,
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
                "messages": o.messages.iter().map(|(c, a, b)| json!({"controller": ctl(*c), "shown_s": a, "taken_s": b})).collect::<Vec<_>>(),
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

/// The first run as an SVG timeline, measured (`--svg`): one lane per controller, a box per step
/// from when it started to when its motion ended (its name and localId inside, or below it on
/// the first line where it meets no other text, tied to it by a thin line), the restarts
/// (orange), the problems (red, with their kind), a time axis in seconds and the cycle time.
/// Text is text; the same report gives the same bytes.
pub fn svg(r: &Report) -> String {
    use crate::picture::{esc, text_w, tick_step};
    const LEFT_MIN: f64 = 170.0;
    const BOX_H: f64 = 30.0;
    const LINE_H: f64 = 13.0;
    const LABEL: f64 = 9.0;
    const PAD: f64 = 10.0;
    let Some((_, o)) = r.runs.first() else {
        return String::new();
    };
    let end = o
        .timeline
        .iter()
        .map(|s| s.end)
        .chain(o.problems.iter().map(|p| p.time))
        .fold(o.end_time, f64::max)
        .max(0.001);
    let scale = (1100.0 / end).clamp(4.0, 160.0);
    let left = r
        .cell
        .controllers
        .iter()
        .map(|c| text_w(&c.name, 12.0, true) + 24.0)
        .fold(LEFT_MIN, f64::max);
    let x = |t: f64| left + t * scale;
    // Per lane: each step's box, and its label line (None: inside the box).
    let lanes = r.cell.controllers.len();
    let mut lines: Vec<Vec<Vec<(f64, f64)>>> = vec![Vec::new(); lanes];
    let mut placed: Vec<(usize, f64, f64, String, Option<usize>)> = Vec::new();
    for s in &o.timeline {
        let label = format!("{} (id={})", s.name, s.local_id);
        let (x0, w) = (x(s.start), ((s.end - s.start) * scale).max(3.0));
        let tw = text_w(&label, LABEL, false);
        if tw + 6.0 <= w {
            placed.push((s.controller, x0, w, label, None));
            continue;
        }
        let taken = &mut lines[s.controller];
        let k = (0..)
            .find(|&k| {
                taken.get(k).is_none_or(|l: &Vec<(f64, f64)>| {
                    l.iter().all(|&(a, b)| x0 + tw + 8.0 <= a || b + 8.0 <= x0)
                })
            })
            .unwrap_or(0);
        if taken.len() <= k {
            taken.resize(k + 1, Vec::new());
        }
        taken[k].push((x0, x0 + tw));
        placed.push((s.controller, x0, w, label, Some(k)));
    }
    let lane_h: Vec<f64> = lines
        .iter()
        .map(|l| BOX_H + 2.0 * PAD + l.len() as f64 * LINE_H)
        .collect();
    let top = 50.0;
    let mut lane_y = Vec::with_capacity(lanes);
    let mut y = top;
    for h in &lane_h {
        lane_y.push(y);
        y += h;
    }
    let axis_y = y + 6.0;
    let height = axis_y + 40.0 + 14.0 * o.problems.len().min(20) as f64;
    let width = x(end) + 40.0;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w:.0}\" height=\"{height:.0}\" viewBox=\"0 0 {w:.0} {height:.0}\" font-family=\"DejaVu Sans, Verdana, sans-serif\">",
        w = width
    );
    let _ = writeln!(s, "<rect width=\"100%\" height=\"100%\" fill=\"#ffffff\"/>");
    let programs: Vec<String> = r
        .cell
        .controllers
        .iter()
        .map(|c| format!("{} ({})", c.file, c.name))
        .collect();
    let head = match (cycle(o), o.repeats) {
        (Some(c), _) => format!("cycle time {} s", secs3(c)),
        (None, true) => "the chart repeats".to_owned(),
        (None, false) => "the programs did not end".to_owned(),
    };
    let _ = writeln!(
        s,
        "<text x=\"12\" y=\"20\" font-size=\"13\" font-weight=\"bold\">{}</text>",
        esc(&format!("Simulation, run 1: {}", programs.join(", ")))
    );
    let _ = writeln!(
        s,
        "<text x=\"12\" y=\"38\" font-size=\"12\">{}</text>",
        esc(&format!("{head}; {} problem(s)", o.problems.len()))
    );
    for (k, c) in r.cell.controllers.iter().enumerate() {
        let ly = lane_y[k];
        let _ = writeln!(
            s,
            "<rect x=\"4\" y=\"{ly:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"{}\"/>",
            width - 8.0,
            lane_h[k] - 2.0,
            if k % 2 == 0 { "#f5f7fa" } else { "#eef1f5" }
        );
        let _ = writeln!(
            s,
            "<text x=\"12\" y=\"{:.1}\" font-size=\"12\" font-weight=\"bold\">{}</text>",
            ly + PAD + BOX_H / 2.0 + 4.0,
            esc(&c.name)
        );
    }
    for (c, x0, w, label, line) in &placed {
        let by = lane_y[*c] + PAD;
        let _ = writeln!(
            s,
            "<rect x=\"{x0:.1}\" y=\"{by:.1}\" width=\"{w:.1}\" height=\"{BOX_H}\" fill=\"#90caf9\" stroke=\"#1565c0\"/>"
        );
        match line {
            None => {
                let _ = writeln!(
                    s,
                    "<text x=\"{:.1}\" y=\"{:.1}\" font-size=\"{LABEL}\">{}</text>",
                    x0 + 3.0,
                    by + BOX_H / 2.0 + 3.0,
                    esc(label)
                );
            }
            Some(j) => {
                let ty = by + BOX_H + LINE_H * (*j as f64 + 1.0);
                let _ = writeln!(
                    s,
                    "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#9e9e9e\" stroke-width=\"0.5\"/>",
                    x0 + 1.0,
                    by + BOX_H,
                    x0 + 1.0,
                    ty - LABEL + 1.0
                );
                let _ = writeln!(
                    s,
                    "<text x=\"{x0:.1}\" y=\"{ty:.1}\" font-size=\"{LABEL}\">{}</text>",
                    esc(label)
                );
            }
        }
    }
    for (c, t) in &o.restarts {
        let (ly, h) = (lane_y[*c], lane_h[*c]);
        let _ = writeln!(
            s,
            "<line x1=\"{x:.1}\" y1=\"{ly:.1}\" x2=\"{x:.1}\" y2=\"{:.1}\" stroke=\"#ef6c00\" stroke-width=\"2\" stroke-dasharray=\"4 2\"><title>started again at {} s</title></line>",
            ly + h,
            secs3(*t),
            x = x(*t)
        );
    }
    for (k, p) in o.problems.iter().take(20).enumerate() {
        let (y0, y1) = match p.controller {
            Some(c) => (lane_y[c], lane_y[c] + lane_h[c]),
            None => (top, y),
        };
        let _ = writeln!(
            s,
            "<line x1=\"{px:.1}\" y1=\"{y0:.1}\" x2=\"{px:.1}\" y2=\"{y1:.1}\" stroke=\"#c62828\" stroke-width=\"2\"/>",
            px = x(p.time)
        );
        let _ = writeln!(
            s,
            "<text x=\"12\" y=\"{:.1}\" font-size=\"{LABEL}\" fill=\"#c62828\">{}</text>",
            axis_y + 34.0 + 14.0 * k as f64,
            esc(&format!(
                "{} at {} s: {}",
                p.kind.name(),
                secs3(p.time),
                p.message
            ))
        );
    }
    // The axis.
    let _ = writeln!(
        s,
        "<line x1=\"{left:.1}\" y1=\"{axis_y:.1}\" x2=\"{:.1}\" y2=\"{axis_y:.1}\" stroke=\"#212121\"/>",
        x(end)
    );
    let step = tick_step(scale);
    let mut t = 0.0;
    while t <= end + 1e-9 {
        let _ = writeln!(
            s,
            "<line x1=\"{px:.1}\" y1=\"{axis_y:.1}\" x2=\"{px:.1}\" y2=\"{:.1}\" stroke=\"#212121\"/><text x=\"{px:.1}\" y=\"{:.1}\" font-size=\"{LABEL}\" text-anchor=\"middle\">{} s</text>",
            axis_y + 4.0,
            axis_y + 15.0,
            secs3(t),
            px = x(t)
        );
        t += step;
    }
    if let Some(c) = cycle(o) {
        let _ = writeln!(
            s,
            "<line x1=\"{px:.1}\" y1=\"{top:.1}\" x2=\"{px:.1}\" y2=\"{axis_y:.1}\" stroke=\"#212121\" stroke-dasharray=\"2 2\"/>",
            px = x(c)
        );
    }
    s.push_str("</svg>\n");
    s
}

/// Seconds with at most 3 decimals, no trailing zeros.
pub fn secs3(x: f64) -> String {
    let s = format!("{x:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}
