//! A program of the flow base run by the product's simulator (`skillpost::simulate`) under the
//! model of `flow_run.rs`: the program the binary wrote, read by the product's reader of its
//! language, on the cell the library's compile sees, in a scenario made from an input
//! sequence.
//!
//! - An action (a step's motion) takes [`ACTION_MS`]: every step's time is set to it.
//! - Phase `k` of the sequence holds once `k` actions have run: the scenario's changes come
//!   `after_steps = k` (when the `k`-th step's motion has ended).
//! - A wait reads its condition every [`TICK_MS`] (`poll`), from its start on.
//! - The flow base's `Gripper_Closed`, an output of the robot's own, is forced as from the
//!   pendant.
//!
//! A run ends as the simulator says: every program ended (done); a `stuck` problem (a wait for
//! inputs that no longer change); the step limit (still running). Any other problem is a fault
//! of the program (a value of the wrong type, a variable read before it has one, a motion to a
//! point it does not declare) and fails the test with the simulator's message.

use std::sync::Arc;

use skillpost::simulate::{
    self, Cell as SimCell, Change, Poll, Scenario, Timing, When, engine, ir::Key, ir::Program,
    ir::Val,
};

use crate::{ACTION_MS, Lang, Outcome, Phase, SIGNALS, Sig, TICK_MS};

/// A flow base signal's value in a phase, as the simulator takes it.
pub fn phase_value(integer: bool, v: i64) -> Val {
    if integer {
        Val::Num(v as f64)
    } else {
        Val::Bool(v != 0)
    }
}

/// The cell the library's compile of the project in `dir` sees (blackboard `bb`, program
/// `program`, split at `max_lines` as the binary's `--max-lines` would).
pub fn compile_cell(
    dir: &std::path::Path,
    bb: &str,
    program: &str,
    max_lines: skillpost::emit::split::Limits,
) -> SimCell {
    let opts = skillpost::compile::Options {
        program: Some(program.to_owned()),
        keep_model: true,
        drop_warnings: true,
        max_lines,
        ..Default::default()
    };
    let c =
        skillpost::compile::compile(&skillpost::load::FsSource::default(), &dir.join(bb), &opts);
    assert!(
        !c.has_errors(),
        "{}: the library's compile failed",
        dir.display()
    );
    SimCell::from_compilation(&c).unwrap().0
}

/// [`compile_cell`] of a single program, every step's time one action.
pub fn cell(dir: &std::path::Path, bb: &str, program: &str) -> Arc<SimCell> {
    let mut sim = compile_cell(dir, bb, program, Default::default());
    for s in sim.steps.values_mut() {
        s.duration = Some(ACTION_MS as f64 / 1000.0);
    }
    Arc::new(sim)
}

/// A program read by the product's reader, ready to run on its cell.
pub struct Runnable {
    /// The cell, with the numbers the program compares its inputs with (what a flickering
    /// run's world gives them).
    cell: SimCell,
    program: Program,
    lang: Lang,
    /// Each flow base signal the cell has: the signal, its keys.
    signals: Vec<(&'static Sig, Vec<Key>)>,
}

impl Runnable {
    pub fn new(cell: Arc<SimCell>, lang: Lang, main: &str, dat: &str) -> Runnable {
        let program = cell.read_program(0, main, dat);
        let mut cell = Arc::unwrap_or_clone(cell);
        cell.input_values = simulate::compared_values(&cell, std::slice::from_ref(&program));
        let signals = SIGNALS
            .iter()
            .filter_map(|s| {
                let found = cell
                    .inputs
                    .iter()
                    .chain(&cell.outputs)
                    .find(|i| i.controller == 0 && i.name.eq_ignore_ascii_case(s.name))?;
                Some((s, found.key.clone()))
            })
            .collect();
        Runnable {
            cell,
            program,
            lang,
            signals,
        }
    }

    /// The scenario's common part: one action per step, at most [`crate::max_actions`]
    /// steps, waits read every `poll`.
    fn base(&self, poll: Poll) -> Scenario {
        let mut s = Scenario::with_file();
        s.max_steps = crate::max_actions();
        s.timing.insert(
            0,
            Timing {
                start_s: Some(0.0),
                poll,
                ..Timing::default()
            },
        );
        s
    }

    fn run_scenario(&self, s: &Scenario, seed: u64) -> engine::Outcome {
        simulate::run_once(&self.cell, std::slice::from_ref(&self.program), s, seed)
    }

    /// The actions and how the run ended; a problem besides `stuck` and the step limit panics.
    fn judge(&self, out: &engine::Outcome, what: &str) -> (Vec<String>, Outcome) {
        let actions: Vec<String> = out.timeline.iter().map(|s| s.name.clone()).collect();
        if actions.len() >= crate::max_actions() {
            return (actions, Outcome::Running);
        }
        let bad: Vec<String> = out
            .problems
            .iter()
            .filter(|p| !matches!(p.kind.name(), "stuck" | "limit"))
            .map(|p| format!("{}: {}", p.kind.name(), p.message))
            .collect();
        assert!(
            bad.is_empty(),
            "{:?} ({what}): the simulator finds {bad:?} after {actions:?}",
            self.lang
        );
        if out.ended {
            return (actions, Outcome::Done);
        }
        assert!(
            out.problems.iter().any(|p| p.kind.name() == "stuck"),
            "{:?} ({what}): neither ended nor stuck after {actions:?}: {:?}",
            self.lang,
            out.problems
        );
        (actions, Outcome::Stuck)
    }

    /// Runs under the input sequence `seq` (phase `k` once `k` actions have run); with
    /// `flicker`, under inputs that change every 10 ms or so at random instead (each of them;
    /// one of the six every 2 ms or so), each statement taking a millisecond, so a signal often
    /// changes between a wait and the test after it; for at most a quarter second per action.
    pub fn run(&self, seq: &[Phase], flicker: bool) -> (Vec<String>, Outcome) {
        let mut s = self.base(Poll::Every(TICK_MS as f64 / 1000.0));
        if flicker {
            s.random = true;
            s.change_every_s = Some(0.01);
            // Long enough for the first actions (each 0.1 s, a wait seldom longer); a run whose
            // wait the world cannot answer (a step time past its window) stops here, its changes
            // do not go on for the default day.
            s.max_time_s = 0.25 * crate::max_actions() as f64;
            if let Some(t) = s.timing.get_mut(&0) {
                t.statement_s = 0.001;
            }
            let seed =
                seq.len() as u64 * 7919 + seq.iter().flat_map(|p| p.values()).sum::<i64>() as u64;
            let out = self.run_scenario(&s, seed);
            let faults: Vec<&str> = out
                .problems
                .iter()
                .filter(|p| p.kind.name() == "fault")
                .map(|p| p.message.as_str())
                .collect();
            assert!(
                faults.is_empty(),
                "{:?} (flickering inputs): the simulator finds {faults:?}",
                self.lang
            );
            let actions = out.timeline.iter().map(|s| s.name.clone()).collect();
            let outcome = if out.ended {
                Outcome::Done
            } else {
                Outcome::Running
            };
            return (actions, outcome);
        }
        for (k, phase) in seq.iter().enumerate() {
            for (sig, key) in &self.signals {
                let v = phase_value(sig.integer, phase.get(sig.name).copied().unwrap_or(0));
                if k == 0 {
                    s.start.push((0, key.clone(), v));
                } else if seq[k - 1].get(sig.name) != phase.get(sig.name) {
                    s.changes.push(Change {
                        when: When::AfterSteps(k),
                        controller: 0,
                        key: key.clone(),
                        value: v,
                    });
                }
            }
        }
        let out = self.run_scenario(&s, 1);
        self.judge(&out, &format!("inputs {seq:?}"))
    }

    /// The actions of a run under the phase `quiet`, in which `change` holds from `delay_ms`
    /// after step `after` began on; each wait reads its condition at the controller's own
    /// rate (KRL's interpreter cycle, RAPID's `\PollRate`, URScript's control cycle).
    pub fn run_timed(
        &self,
        quiet: &Phase,
        after: &str,
        delay_ms: i64,
        change: &Phase,
    ) -> Vec<String> {
        let mut s = self.base(Poll::Controller);
        for (sig, key) in &self.signals {
            let v = |p: &Phase| phase_value(sig.integer, p.get(sig.name).copied().unwrap_or(0));
            s.start.push((0, key.clone(), v(quiet)));
        }
        // When `after` begins: its start in a run without the change.
        let began = self
            .run_scenario(&s, 1)
            .timeline
            .iter()
            .find(|r| r.name == after)
            .unwrap_or_else(|| panic!("{after} never runs"))
            .start;
        for (sig, key) in &self.signals {
            if change.contains_key(sig.name) {
                s.changes.push(Change {
                    when: When::At(began + delay_ms as f64 / 1000.0),
                    controller: 0,
                    key: key.clone(),
                    value: phase_value(sig.integer, change[sig.name]),
                });
            }
        }
        let out = self.run_scenario(&s, 1);
        self.judge(&out, &format!("{change:?} {delay_ms} ms after {after}"))
            .0
    }
}
