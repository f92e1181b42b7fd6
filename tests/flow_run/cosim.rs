//! The cell co-simulation (docs/CELLS.md): every program of a cell of several controllers runs
//! at the same time on the product's simulator (`skillpost::simulate`, docs/SIMULATE.md), the
//! blackboard's wires connecting one's outputs to the other's inputs, under random step
//! durations, motion speeds, statement times, start delays and inputs that change at random
//! times. The programs run are the files the binary wrote (a split program's parts followed),
//! read by the simulator's readers; the simulator's engine keeps each controller's clock,
//! KRL's and RAPID's advance run and URScript's blocking moves.
//!
//! A run passes when:
//! - the simulator found no problem but `stuck` (a wait for a chart condition whose inputs no
//!   longer change may stop a run early): no deadlock (a cycle of handshake waits, or one on
//!   a program that ended), no step before one the chart puts before it has ended, no wire set
//!   while a motion before it still ran, no selection decided twice, no wait's message shown
//!   early, twice or left on the pendant, no tell that a step is done after the teller's next
//!   step, no program left stopped;
//! - the controllers did what one run of the chart does (`Chart::explain`, the test's own chart
//!   player: one choice at every selection for all of them, each controller's steps in its
//!   order; when all programs ended, the chart ends there too), and no step started before a
//!   step the chart puts before it had ended or was cut short.

use std::collections::HashMap;

use skillpost::simulate::ir::{Ins, Program, Val};
use skillpost::simulate::{self, Cell as SimCell, Change, Restart, StepRun, Timing, When};

use crate::chart::{Chart, ChartGen};
pub use crate::mutate::{Mutation, mutate};
use crate::{Lang, Rng, SIGNALS, repo, sequences};

/// A step run: its name, the start and end of its motion (seconds).
pub type Step = (String, f64, f64);

/// How the operator starts the programs of a cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scenario {
    /// Each program once.
    Once,
    /// `n` cycles: each program started again after its END, in any order, with any delay.
    Cycles(usize),
    /// One program started again at a random time (mid-cycle, a fault), every other one later
    /// at a random time (whatever it does then); then one whole cycle.
    Fault,
}

/// The most steps a controller runs in one run (an endless chart, or inputs that keep a loop
/// going, stop there).
const CAP: usize = 25;

/// The flow base's blackboard with a robot `R1`, `R2`, … per language of `langs`, each on a
/// controller of its own with the base's signals and skills (readable in its language, its IRL
/// file `kr15-2-<language>.irl`), and `m` wires from each to each other
/// (`benches/common/cell.rs`): robot `k`'s output `To_R<p>_<j>` drives robot `p`'s input
/// `From_R<k>_<j>`. KRL: `$OUT[100 + 10 p + j]` and `$IN[200 + 10 k + j]`; RAPID: `Address`
/// `do_To_R<p>_<j>`, `di_From_R<k>_<j>`; URScript (one peer at most, `m` ≤ 7): standard digital
/// output `j`, input `j + 3`.
pub fn cell_blackboard(langs: &[Lang], m: usize) -> String {
    let n = langs.len();
    let raw = std::fs::read_to_string(repo().join("fixtures/base/flow/Blackboard.aml")).unwrap();
    assert!(
        !langs.contains(&Lang::UrScript) || n == 2,
        "a UR robot has one peer"
    );
    crate::cell::cell_blackboard(
        "KUKA KR15-2",
        n,
        m,
        &|k| langs[k - 1].blackboard(&raw),
        &|k, p, j| {
            let number = |v: usize| ("Number", v.to_string());
            match langs[k - 1] {
                Lang::Krl => (number(100 + 10 * p + j), number(200 + 10 * p + j)),
                Lang::Rapid => (
                    ("Address", format!("do_To_R{p}_{j}")),
                    ("Address", format!("di_From_R{p}_{j}")),
                ),
                // Standard digital inputs 4-7, then boolean input registers (a fieldbus).
                Lang::UrScript if j + 3 <= 7 => (number(j), number(j + 3)),
                Lang::UrScript => (
                    number(j),
                    ("Address", format!("read_input_boolean_register({j})")),
                ),
            }
        },
        &|k, text| {
            let mut text = text.replace(
                "<Value>kr15-2.irl</Value>",
                &format!("<Value>kr15-2-{}.irl</Value>", langs[k - 1].ext()),
            );
            // A wait on a partner shows on the pendant after 50 ms (steps here take 0.1 to
            // 500 ms: the default 10 s would never show).
            let at = text.find('\n').unwrap();
            text.insert_str(
                at,
                &format!("\n<Attribute Name=\"HandshakeTimeout\" AttributeDataType=\"xs:double\"><Value>{HANDSHAKE_TIMEOUT_S}</Value></Attribute>"),
            );
            text
        },
    )
}

/// The `HandshakeTimeout` of the robots of [`cell_blackboard`], in seconds.
pub const HANDSHAKE_TIMEOUT_S: f64 = 0.05;

/// Puts each skill step of a chart on one of `n` robots at random; returns the chart and each
/// step's robot (from 0), by step name.
pub fn spread(chart: &str, n: usize, rng: &mut Rng) -> (String, HashMap<String, usize>) {
    let mut out = String::new();
    let mut of = HashMap::new();
    let mut rest = chart;
    let mut step_name = String::new();
    let marker = "<ressource name=\"KUKA KR15-2\"/>";
    loop {
        let next_step = rest.find("<step ");
        let next_res = rest.find(marker);
        match (next_step, next_res) {
            (Some(s), r) if r.is_none_or(|r| s < r) => {
                let name_at = rest[s..].find("name=\"").unwrap() + s + 6;
                let name_end = rest[name_at..].find('"').unwrap() + name_at;
                step_name = rest[name_at..name_end].to_owned();
                out.push_str(&rest[..name_end]);
                rest = &rest[name_end..];
            }
            (_, Some(r)) => {
                let k = (rng.next() % n as u64) as usize;
                of.insert(step_name.clone(), k);
                out.push_str(&rest[..r]);
                out.push_str(&format!("<ressource name=\"R{}\"/>", k + 1));
                rest = &rest[r + marker.len()..];
            }
            _ => break,
        }
    }
    out.push_str(rest);
    (out, of)
}

/// A compiled cell: each robot's program as the binary wrote it (`None` for a robot without
/// steps: its main file, KRL's `.dat`, a split program's parts followed), its language, and
/// the cell as the simulator sees it (controllers in the same order, wires, inputs, chart).
pub struct CellPrograms {
    pub programs: Vec<Option<(String, String)>>,
    pub langs: Vec<Lang>,
    pub sim: SimCell,
    /// Per controller of [`CellPrograms::sim`]: its index in `programs`.
    pub to_test: Vec<usize>,
}

/// The cell of project `dir` (blackboard `bb`, program `program`, the compile's `args`) as the
/// simulator sees it, compiled in memory by the library, and for each of its controllers the
/// index of its name in `names` (every one of `names` is a controller).
fn sim_cell(
    dir: &std::path::Path,
    bb: &str,
    program: &str,
    args: &[String],
    names: &[String],
) -> (SimCell, Vec<usize>) {
    let mut max_lines = skillpost::emit::split::Limits::default();
    for w in args.windows(2) {
        if w[0] == "--max-lines" {
            max_lines.set(&w[1]).unwrap();
        }
    }
    let sim = crate::sim::compile_cell(dir, bb, program, max_lines);
    let to_test: Vec<usize> = sim
        .controllers
        .iter()
        .map(|c| {
            names
                .iter()
                .position(|n| *n == c.name)
                .unwrap_or_else(|| panic!("{}: controller {} unknown", dir.display(), c.name))
        })
        .collect();
    (sim, to_test)
}

/// Writes the project (robots in `langs`) and compiles it with the binary.
pub fn compile_cell(
    dir: &std::path::Path,
    chart: &str,
    langs: &[Lang],
    m: usize,
) -> Result<CellPrograms, String> {
    // A fresh project: no program of an earlier one left.
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("Blackboard.aml"), cell_blackboard(langs, m)).unwrap();
    let irl = std::fs::read_to_string(repo().join("fixtures/base/flow/kr15-2.irl")).unwrap();
    for lang in langs {
        std::fs::write(
            dir.join(format!("kr15-2-{}.irl", lang.ext())),
            lang.irl(&irl),
        )
        .unwrap();
    }
    std::fs::write(dir.join("sfc.xml"), chart).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["--lf", "Blackboard.aml", "Cell"])
        .current_dir(dir)
        .output()
        .unwrap();
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).into_owned());
    }
    product_simulator_agrees(dir);
    let programs = (1..=langs.len())
        .zip(langs)
        .map(|(k, lang)| {
            let read =
                |ext: &str| std::fs::read_to_string(dir.join(format!("Cell_R{k}.{ext}"))).ok();
            let main = read(lang.ext())?;
            let dat = if *lang == Lang::Krl {
                read("dat")?
            } else {
                String::new()
            };
            Some(crate::parts::follow(*lang, dir, main, dat))
        })
        .collect();
    let names: Vec<String> = (1..=langs.len()).map(|k| format!("R{k}")).collect();
    let (sim, to_test) = sim_cell(dir, "Blackboard.aml", "Cell", &[], &names);
    Ok(CellPrograms {
        programs,
        langs: langs.to_vec(),
        sim,
        to_test,
    })
}

/// The product's simulator (`skillpost simulate`, docs/SIMULATE.md) runs the same cell 5
/// times under random inputs and timing: no run may have a problem (a deadlock, a step out of
/// the chart's order, a wire set while a motion ran, controllers deciding differently), and
/// every run ends, runs the chart's rounds or stops at its step limit (random inputs that keep
/// a loop going). One kind is allowed: `stuck` — the flow base's
/// `Gripper_Closed` is an output of the robot, which this co-simulation's world sets and the
/// product's does not (nothing in the programs sets it).
fn product_simulator_agrees(dir: &std::path::Path) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args([
            "simulate",
            "Blackboard.aml",
            "Cell",
            "--runs",
            "10",
            "--format",
            "json",
        ])
        .current_dir(dir)
        .output()
        .unwrap();
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "skillpost simulate in {}: not JSON ({e}): {}",
            dir.display(),
            String::from_utf8_lossy(&out.stderr)
        )
    });
    assert!(
        matches!(out.status.code(), Some(0 | 1)),
        "skillpost simulate in {}: {}",
        dir.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    for run in report["runs"].as_array().unwrap() {
        let problems = run["problems"].as_array().unwrap();
        let other: Vec<&serde_json::Value> =
            problems.iter().filter(|p| p["kind"] != "stuck").collect();
        // `SKILLPOST_KEEP_FAILED=DIR`: the project is copied there to look at.
        if !other.is_empty()
            && let Some(keep) = std::env::var_os("SKILLPOST_KEEP_FAILED")
        {
            static N: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
            let n = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let keep = std::path::Path::new(&keep).join(n.to_string());
            let keep = keep.as_path();
            let _ = std::fs::create_dir_all(keep);
            for e in std::fs::read_dir(dir).unwrap().flatten() {
                let _ = std::fs::copy(e.path(), keep.join(e.file_name()));
            }
        }
        assert!(
            other.is_empty(),
            "skillpost simulate found a problem in {}: {other:#?}",
            dir.display()
        );
        assert!(
            run["ended"] == true
                || run["repeats"] == true
                || run["capped"] == true
                || !problems.is_empty(),
            "{}: {run:#}",
            dir.display()
        );
    }
}

/// Runs a compiled cell `runs` times with random timing and inputs; the first failure, if any.
pub fn co_simulate(
    chart: &Chart,
    cell: &CellPrograms,
    robot_of: &HashMap<String, usize>,
    seed: u64,
    runs: usize,
    mutation: Mutation,
    only: Option<Lang>,
) -> Result<Report, String> {
    co_simulate_in(
        chart,
        cell,
        robot_of,
        seed,
        runs,
        mutation,
        only,
        Scenario::Once,
    )
}

/// The pairs of controllers (the test's order) whose programs read a wire of the other
/// (partners: they meet at the start barrier), both ways round.
fn partners(sim: &SimCell, programs: &[Program]) -> std::collections::BTreeSet<(usize, usize)> {
    let mut pairs = std::collections::BTreeSet::new();
    for (a, p) in programs.iter().enumerate() {
        let mut keys = Vec::new();
        for (i, _) in &p.ins {
            match i {
                Ins::Wait { cond, .. } | Ins::JumpIfNot(cond, _) => cond.inputs(&mut keys),
                _ => {}
            }
        }
        for w in &sim.wires {
            if w.to.0 == a && keys.contains(&w.to.1) {
                pairs.insert((a, w.from.0));
                pairs.insert((w.from.0, a));
            }
        }
    }
    pairs
}

/// One run of the chart by the controllers (the steps of one run of each program): the chart
/// explains it (`ended`: all programs ended, so the chart ends there too), and no step started
/// before a step the chart puts before it had ended — or at all, when that step was cut short.
fn check_run(
    chart: &Chart,
    runs: &[(&[Step], Option<usize>)],
    robot_of: &HashMap<String, usize>,
    ended: bool,
) -> Result<(), String> {
    let seen: Vec<Vec<String>> = runs
        .iter()
        .map(|(steps, _)| steps.iter().map(|s| s.0.clone()).collect())
        .collect();
    let Some(explained) = chart.explain(&seen, &|name| robot_of[name], ended) else {
        return Err(format!(
            "the controllers did not do what one run of the chart does: {seen:?} (all ended: {ended})"
        ));
    };
    // Each action of the run: its robot's how-manieth step.
    let mut counts = vec![0usize; runs.len()];
    let place: Vec<(usize, usize)> = explained
        .iter()
        .map(|(name, _)| {
            let c = robot_of[name];
            counts[c] += 1;
            (c, counts[c] - 1)
        })
        .collect();
    for (i, (name, preds)) in explained.iter().enumerate() {
        let (c, k) = place[i];
        let start = runs[c].0[k].1;
        for &p in preds {
            let (pc, pk) = place[p];
            let end = runs[pc].0[pk].2;
            if runs[pc].1 == Some(pk) {
                return Err(format!(
                    "step {name} on R{} started at {start:.4} after step {} on R{} was cut short by a start again",
                    c + 1,
                    explained[p].0,
                    pc + 1
                ));
            }
            if end > start + 1e-9 {
                return Err(format!(
                    "step {name} on R{} started at {start:.4}, before step {} on R{} ended at {end:.4}",
                    c + 1,
                    explained[p].0,
                    pc + 1
                ));
            }
        }
    }
    Ok(())
}

/// What the co-simulation saw besides the faults it reports.
#[derive(Debug, Default, Clone)]
pub struct Report {
    /// The messages of waits on partners that lasted (shown and taken away again), by the
    /// language of the program that showed them.
    pub messages: std::collections::BTreeMap<String, usize>,
}

/// A signal's value in a phase for the simulator: an integer as a number, else a truth.
fn phase_value(integer: bool, v: i64) -> Val {
    if integer {
        Val::Num(v as f64)
    } else {
        Val::Bool(v != 0)
    }
}

/// The scenario of one run: the inputs of each phase (the flow base's signals by name, a
/// fixture's own inputs a bit of their own per phase; the base's `Gripper_Closed`, an output
/// nothing drives, forced as from the pendant), when each phase begins, each controller's
/// timing, and the operator's starts.
fn run_scenario(
    sim: &SimCell,
    rng: &mut Rng,
    scenario: Scenario,
) -> (simulate::Scenario, Option<usize>) {
    let seq = sequences(rng.next(), 1).remove(0);
    let mut s = simulate::Scenario::with_file();
    // Steps take 1 to 49 ms (times a controller's factor).
    s.default_step_s = 0.025;
    s.jitter = 0.96;
    s.max_steps = CAP * sim.controllers.len();
    let mut t = 0.0;
    let driven: Vec<(usize, &String)> = sim.wires.iter().map(|w| (w.from.0, &w.from.1)).collect();
    for (k, phase) in seq.iter().enumerate() {
        if k > 0 {
            t += (rng.next() % 400) as f64 / 1000.0;
        }
        let signals = sim.inputs.iter().chain(
            sim.outputs
                .iter()
                .filter(|o| o.key.len() == 1 && !driven.contains(&(o.controller, &o.key[0]))),
        );
        for inp in signals {
            let v = match SIGNALS
                .iter()
                .find(|s| s.name.eq_ignore_ascii_case(&inp.name))
            {
                Some(sig) => phase_value(sig.integer, phase.get(sig.name).copied().unwrap_or(0)),
                None if inp.integer => Val::Num((rng.next() % 4) as f64),
                None => Val::Bool(rng.next() & 1 == 1),
            };
            if k == 0 {
                s.start.push((inp.controller, inp.key.clone(), v));
            } else {
                s.changes.push(Change {
                    when: When::At(t),
                    controller: inp.controller,
                    key: inp.key.clone(),
                    value: v,
                });
            }
        }
    }
    for c in 0..sim.controllers.len() {
        s.timing.insert(
            c,
            Timing {
                start_s: Some((rng.next() % 200) as f64 / 1000.0),
                motion_factor: [0.1, 1.0, 3.0, 10.0][(rng.next() % 4) as usize],
                statement_s: [1e-6, 1e-4, 1e-3][(rng.next() % 3) as usize],
                ..Timing::default()
            },
        );
    }
    let mut victim = None;
    match scenario {
        Scenario::Once => {}
        Scenario::Cycles(n) => {
            s.cycles = n.max(1);
            s.cycle_pause_s = 0.2;
            s.max_steps *= n.max(1);
        }
        Scenario::Fault => {
            // One started again at a random time once all have started (every program starts
            // before 0.2 s), the others later, each at a random time.
            let n = sim.controllers.len();
            let v = (rng.next() % n as u64) as usize;
            let at = 0.3 + (rng.next() % 400) as f64 / 1000.0;
            for c in 0..n {
                let when = if c == v {
                    at
                } else {
                    at + 0.001 + (rng.next() % 600) as f64 / 1000.0
                };
                s.restarts.push(Restart {
                    when: When::At(when),
                    controller: c,
                });
            }
            s.max_steps *= 2;
            victim = Some(v);
        }
    }
    (s, victim)
}

/// Each controller's runs (one per start): its steps, and the index of a step a start again
/// cut short.
type Sessions = Vec<Vec<(Vec<Step>, Option<usize>)>>;

/// In the test's order (`to_test`: each simulated controller's index there, of `n`; a robot
/// without steps has no program and no controller in the simulation).
fn sessions(out: &simulate::engine::Outcome, to_test: &[usize], n: usize) -> Sessions {
    let mut by: Sessions = vec![vec![(Vec::new(), None)]; n];
    let mut steps: Vec<&StepRun> = out.timeline.iter().collect();
    steps.sort_by(|a, b| a.start.total_cmp(&b.start));
    let mut restarts: Vec<(usize, f64)> = out.restarts.clone();
    restarts.sort_by(|a, b| a.1.total_cmp(&b.1));
    for (c, &t) in to_test.iter().enumerate() {
        let starts: Vec<f64> = restarts.iter().filter(|r| r.0 == c).map(|r| r.1).collect();
        by[t].extend(starts.iter().map(|_| (Vec::new(), None)));
        for s in steps.iter().filter(|s| s.controller == c) {
            let k = starts.iter().filter(|&&r| r <= s.start).count();
            let name = s
                .name
                .split_whitespace()
                .next()
                .unwrap_or_default()
                .to_owned();
            let session = &mut by[t][k];
            if s.cut {
                session.1 = Some(session.0.len());
            }
            session.0.push((name, s.start, s.end));
        }
    }
    by
}

/// [`co_simulate`] with the operator starting the programs as `scenario` says.
#[allow(clippy::too_many_arguments)]
pub fn co_simulate_in(
    chart: &Chart,
    cell: &CellPrograms,
    robot_of: &HashMap<String, usize>,
    seed: u64,
    runs: usize,
    mutation: Mutation,
    only: Option<Lang>,
    scenario: Scenario,
) -> Result<Report, String> {
    let mut report = Report::default();
    let sim = &cell.sim;
    let programs: Vec<Program> = (0..sim.controllers.len())
        .map(|k| match &cell.programs[cell.to_test[k]] {
            Some((main, dat)) => {
                let lang = cell.langs[cell.to_test[k]];
                // Only the programs of one language are broken, when one is named.
                let m = match mutation {
                    Mutation::None => Mutation::None,
                    _ if only.is_some_and(|l| l != lang) => Mutation::None,
                    m => m,
                };
                sim.read_program(k, &mutate(main, m, lang), dat)
            }
            None => Program::default(),
        })
        .collect();
    for (k, p) in programs.iter().enumerate() {
        if let Some((text, line)) = p.unknown.first() {
            return Err(format!(
                "R{}: the simulator does not run line {line}: {text}",
                cell.to_test[k] + 1
            ));
        }
    }
    let pairs: std::collections::BTreeSet<(usize, usize)> = partners(sim, &programs)
        .into_iter()
        .map(|(a, b)| (cell.to_test[a], cell.to_test[b]))
        .collect();
    let mut rng = Rng(seed | 1);
    // Fault runs that reached their step limit before every program was started again (a
    // program that loops on its own, fast): only their part before the starts is checked.
    let mut stopped_early = 0;
    for run in 0..runs {
        let (s, victim) = run_scenario(sim, &mut rng, scenario);
        let out = simulate::run_once(sim, &programs, &s, rng.next());
        let fail = |why: String| Err(format!("run {run} ({scenario:?}): {why}"));
        let capped = out.timeline.len() >= s.max_steps;
        if let Some(p) = out.problems.iter().find(|p| {
            p.kind != simulate::ProblemKind::Stuck
                && !(p.kind == simulate::ProblemKind::Limit && capped)
        }) {
            return fail(format!("{}: {}", p.kind.name(), p.message));
        }
        for &(c, _, _) in &out.messages {
            *report
                .messages
                .entry(format!("{:?}", cell.langs[cell.to_test[c]]))
                .or_default() += 1;
        }
        let ended = out.ended;
        let sessions = sessions(&out, &cell.to_test, cell.programs.len());
        let as_runs = |k: usize| -> Vec<(&[Step], Option<usize>)> {
            sessions
                .iter()
                .map(|s| s.get(k).map_or((&[][..], None), |x| (x.0.as_slice(), x.1)))
                .collect()
        };
        match scenario {
            Scenario::Once => {
                if let Err(e) = check_run(chart, &as_runs(0), robot_of, ended) {
                    return fail(e);
                }
            }
            Scenario::Cycles(_) => {
                let k_max = sessions.iter().map(Vec::len).max().unwrap_or(1);
                for k in 0..k_max {
                    // Every program ended this cycle (a capped one did not).
                    let done = sessions
                        .iter()
                        .all(|s| k + 1 < s.len() || (k + 1 == s.len() && ended));
                    if let Err(e) = check_run(chart, &as_runs(k), robot_of, done) {
                        return fail(format!("cycle {}: {e}", k + 1));
                    }
                }
                // A partner's next cycle begins after this one's steps have ended.
                for &(a, b) in &pairs {
                    for k in 1..k_max {
                        let (Some(prev), Some(next)) = (sessions[b].get(k - 1), sessions[a].get(k))
                        else {
                            continue;
                        };
                        let done = prev.0.iter().map(|s| s.2).fold(f64::MIN, f64::max);
                        if let Some(s) = next.0.iter().find(|s| s.1 + 1e-9 < done) {
                            return fail(format!(
                                "cycle {}: step {} on R{} started at {:.4}, before R{} ended cycle {k} at {done:.4}",
                                k + 1,
                                s.0,
                                a + 1,
                                s.1,
                                b + 1
                            ));
                        }
                    }
                }
            }
            Scenario::Fault => {
                let victim = cell.to_test[victim.unwrap()] + 1;
                // Before the starts again: a part of one run of the chart, no step after one
                // cut short.
                if let Err(e) = check_run(chart, &as_runs(0), robot_of, false) {
                    return fail(format!("before the starts again (R{victim} first): {e}"));
                }
                if out.restarts.len() < sim.controllers.len() {
                    if !capped {
                        return fail(format!(
                            "only {} of {} programs were started again",
                            out.restarts.len(),
                            sim.controllers.len()
                        ));
                    }
                    stopped_early += 1;
                    continue;
                }
                // After: no step before every partner was started again, then one whole run.
                for &(a, b) in &pairs {
                    let Some(again) = out
                        .restarts
                        .iter()
                        .filter(|r| cell.to_test[r.0] == b)
                        .map(|r| r.1)
                        .fold(None, |m: Option<f64>, t| Some(m.map_or(t, |m| m.max(t))))
                    else {
                        continue;
                    };
                    if let Some(s) = sessions[a].last().unwrap().0.iter().find(|s| s.1 < again) {
                        return fail(format!(
                            "R{} started step {} at {:.4}, before its partner R{} was started again at {again:.4}",
                            a + 1,
                            s.0,
                            s.1,
                            b + 1
                        ));
                    }
                }
                let last: Vec<(&[Step], Option<usize>)> = sessions
                    .iter()
                    .map(|s| {
                        let x = s.last().unwrap();
                        (x.0.as_slice(), x.1)
                    })
                    .collect();
                if let Err(e) = check_run(chart, &last, robot_of, ended) {
                    return fail(format!("after the starts again (R{victim} first): {e}"));
                }
            }
        }
    }
    if stopped_early * 10 > runs {
        return Err(format!(
            "{stopped_early} of {runs} fault runs reached their step limit before every program was started again"
        ));
    }
    Ok(report)
}

/// Wires from each robot of a random cell to each other: a strobe, the data bits of the
/// largest decision, an acknowledgement, the run and the ready wire.
pub const WIRES: usize = 7;

/// A random chart on 2 to 4 robots, compiled; `None` when it uses fewer than two robots.
pub fn random_cell(
    dir: &std::path::Path,
    seed: u64,
) -> Option<(Chart, CellPrograms, HashMap<String, usize>, usize)> {
    match random_cell_of(dir, seed, &ChartGen::chart(seed)) {
        Ok(cell) => cell,
        Err(e) => panic!(
            "seed {seed}: the cell does not compile: {e}\n{}",
            ChartGen::chart(seed)
        ),
    }
}

/// [`random_cell`] of the chart `text` (the random chart of `seed`, changed): `Err` when the
/// cell does not compile.
pub type RandomCell = (Chart, CellPrograms, HashMap<String, usize>, usize);
pub fn random_cell_of(
    dir: &std::path::Path,
    seed: u64,
    text: &str,
) -> Result<Option<RandomCell>, String> {
    let mut rng = Rng(seed.wrapping_mul(0x2545_F491_4F6C_DD1D) | 1);
    // KUKA cells, ABB cells, KUKA and ABB mixed, a UR with a robot of any kind.
    let any = |rng: &mut Rng| [Lang::Krl, Lang::Rapid][(rng.next() % 2) as usize];
    let langs: Vec<Lang> = match seed % 4 {
        0..=2 => {
            let n = 2 + (rng.next() % 3) as usize;
            (0..n)
                .map(|_| match seed % 4 {
                    0 => Lang::Krl,
                    1 => Lang::Rapid,
                    _ => any(&mut rng),
                })
                .collect()
        }
        _ => vec![
            Lang::UrScript,
            [Lang::Krl, Lang::Rapid, Lang::UrScript][(rng.next() % 3) as usize],
        ],
    };
    let n = langs.len();
    let (chart, robot_of) = spread(text, n, &mut rng);
    let used: std::collections::BTreeSet<usize> = robot_of.values().copied().collect();
    if used.len() < 2 {
        return Ok(None);
    }
    let cell = compile_cell(dir, &chart, &langs, WIRES)?;
    Ok(Some((Chart::read(&dir.join("sfc.xml")), cell, robot_of, n)))
}

/// A cell fixture (`fixtures/ok/<case>`) compiled with the binary: its programs (name and
/// language) in the order of `controllers`, each step's program (by the step titles of each),
/// its chart.
pub fn fixture_cell(
    dir: &std::path::Path,
    case: &str,
    programs: &[(&str, Lang)],
    controllers: &[&str],
) -> (Chart, CellPrograms, HashMap<String, usize>) {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
    let toml: toml::Value = toml::from_str(
        &std::fs::read_to_string(repo().join("fixtures/ok").join(case).join("case.toml")).unwrap(),
    )
    .unwrap();
    let program = toml["program"].as_str().unwrap().to_owned();
    let bases: Vec<&str> = match toml.get("base") {
        Some(toml::Value::String(b)) => vec![b.as_str()],
        Some(toml::Value::Array(v)) => v.iter().map(|b| b.as_str().unwrap()).collect(),
        _ => Vec::new(),
    };
    for base in bases {
        crate::copy_dir(&repo().join("fixtures/base").join(base), dir);
    }
    crate::copy_dir(&repo().join("fixtures/ok").join(case), dir);
    let bb_name = match toml.get("blackboard") {
        Some(b) => b.as_str().unwrap().to_owned(),
        None => std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .find(|n| n.ends_with(".aml"))
            .unwrap(),
    };
    // The case's own arguments too (`--max-lines` of a split cell).
    let args: Vec<String> = toml
        .get("args")
        .and_then(|a| a.as_array())
        .map(|a| a.iter().map(|v| v.as_str().unwrap().to_owned()).collect())
        .unwrap_or_default();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["--lf", &bb_name, &program])
        .args(&args)
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{case}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let names: Vec<String> = controllers.iter().map(|c| c.to_string()).collect();
    let (sim, to_test) = sim_cell(dir, &bb_name, &program, &args, &names);
    let mut robot_of = HashMap::new();
    let texts: Vec<Option<(String, String)>> = programs
        .iter()
        .enumerate()
        .map(|(k, (p, lang))| {
            let main = std::fs::read_to_string(dir.join(format!("{p}.{}", lang.ext()))).unwrap();
            let dat = match lang {
                Lang::Krl => std::fs::read_to_string(dir.join(format!("{p}.dat"))).unwrap(),
                _ => String::new(),
            };
            // A split program's calls of its parts followed.
            let (main, dat) = crate::parts::follow(*lang, dir, main, dat);
            let p = to_test.iter().position(|&t| t == k).unwrap();
            for (i, _) in sim.read_program(p, &main, &dat).ins {
                if let Ins::Step { name, .. } = i {
                    let first = name.split_whitespace().next().unwrap_or_default();
                    robot_of.insert(first.to_owned(), k);
                }
            }
            Some((main, dat))
        })
        .collect();
    (
        Chart::read(&dir.join("sfc.xml")),
        CellPrograms {
            programs: texts,
            langs: programs.iter().map(|p| p.1).collect(),
            sim,
            to_test,
        },
        robot_of,
    )
}
