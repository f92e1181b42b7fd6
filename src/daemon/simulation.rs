//! The simulation after a compile (`simulate` in the configuration; docs/SIMULATE.md, "In the
//! daemon"): the compile's programs run on the built-in simulator on a thread of their own, so
//! a compile never waits for a simulation. One simulation per project at a time; a compile that
//! finishes meanwhile leaves its programs waiting (the newest only), and the result of a
//! simulation whose programs a newer compile has replaced is not reported. Its events:
//! `simulation-succeeded`, `simulation-failed` (a warning: the outputs stand).

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;

use super::events::{Event, EventSink};
use crate::simulate::{self, Cell, Scenario, ir::Program, report, scenario::ScenarioError};

/// A compile's programs to simulate.
pub(super) struct Request {
    pub(super) project: String,
    pub(super) run_id: u64,
    pub(super) cell: Cell,
    pub(super) programs: Vec<Program>,
    pub(super) scenario: Result<Scenario, ScenarioError>,
    pub(super) sink: Arc<EventSink>,
}

#[derive(Default)]
struct Slot {
    running: bool,
    pending: Option<Request>,
}

fn slots() -> std::sync::MutexGuard<'static, HashMap<String, Slot>> {
    static SLOTS: OnceLock<Mutex<HashMap<String, Slot>>> = OnceLock::new();
    SLOTS
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|p| p.into_inner())
}

/// Simulates `req` now, or after the project's running simulation (replacing any request
/// that waited).
pub(super) fn submit(req: Request) {
    let mut all = slots();
    let slot = all.entry(req.project.clone()).or_default();
    if slot.running {
        slot.pending = Some(req);
        return;
    }
    slot.running = true;
    drop(all);
    let project = req.project.clone();
    let spawned = std::thread::Builder::new()
        .name("skillpost-simulate".into())
        .spawn(move || worker(req));
    if let Err(e) = spawned {
        tracing::warn!("{project}: the simulation could not start: {e}");
        if let Some(s) = slots().get_mut(&project) {
            s.running = false;
            s.pending = None;
        }
    }
}

fn worker(mut req: Request) {
    loop {
        let started = Instant::now();
        let event = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run(&req)))
            .unwrap_or_else(|_| {
                failed(
                    &req,
                    "internal",
                    "the simulator panicked (a bug in skillpost); see the log".into(),
                )
            });
        let event = with_duration(event, started.elapsed().as_millis() as u64);
        let mut all = slots();
        let Some(slot) = all.get_mut(&req.project) else {
            return;
        };
        // Newer programs wait: this result describes programs that are gone.
        if slot.pending.is_none() && !req.sink.stopping() {
            req.sink.emit(Some(&req.project), event);
        }
        match slot.pending.take() {
            Some(next) => req = next,
            None => {
                slot.running = false;
                return;
            }
        }
    }
}

fn failed(req: &Request, kind: &str, message: String) -> Event {
    Event::SimulationFailed {
        run_id: req.run_id,
        runs: 0,
        duration_ms: 0,
        cycle_s: None,
        problems: 1,
        kind: kind.into(),
        message,
        controller: None,
        file: None,
        line: None,
        column: None,
        local_id: None,
        time_s: None,
    }
}

fn with_duration(mut e: Event, ms: u64) -> Event {
    match &mut e {
        Event::SimulationSucceeded { duration_ms, .. }
        | Event::SimulationFailed { duration_ms, .. } => *duration_ms = ms,
        _ => {}
    }
    e
}

fn run(req: &Request) -> Event {
    let scenario = match &req.scenario {
        Ok(s) => s.clone(),
        Err(e) => {
            return Event::SimulationFailed {
                run_id: req.run_id,
                runs: 0,
                duration_ms: 0,
                cycle_s: None,
                problems: 1,
                kind: "scenario".into(),
                message: e.message.clone(),
                controller: None,
                file: Some(e.file.clone()),
                line: e.line.map(|l| l as u64),
                column: e.column.map(|c| c as u64),
                local_id: None,
                time_s: None,
            };
        }
    };
    let r = simulate::simulate(req.cell.clone(), &req.programs, scenario, None, None);
    let cycle_s = r.runs.first().and_then(|(_, o)| report::cycle(o));
    let first = r.runs.iter().flat_map(|(_, o)| &o.problems).next().cloned();
    match first {
        None => Event::SimulationSucceeded {
            run_id: req.run_id,
            runs: r.runs.len(),
            duration_ms: 0,
            cycle_s,
            never_reached: r.never_steps.len() + r.never_branches.len(),
        },
        Some(p) => Event::SimulationFailed {
            run_id: req.run_id,
            runs: r.runs.len(),
            duration_ms: 0,
            cycle_s,
            problems: r.problems(),
            kind: p.kind.name().into(),
            message: p.message.clone(),
            controller: p.controller.map(|c| r.cell.controllers[c].name.clone()),
            file: p.controller.map(|c| r.cell.controllers[c].file.clone()),
            line: p.line.map(u64::from),
            column: None,
            local_id: p.local_id,
            time_s: Some(p.time),
        },
    }
}
