//! [`Tracker`]: each project's last result, taken from the events as they are emitted, and the
//! snapshot it writes to the state file (at most every [`MIN_WRITE_INTERVAL`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use serde_json::Value;

use super::files::{process_start, sweep_stopped, write_atomically};
use super::{
    DeployState, ProjectState, SCHEMA, SimulationState, Snapshot, Tally, describe, now, sentence,
};
use crate::daemon::events::Event;

fn count(diags: &[Value], severity: &str) -> usize {
    diags
        .iter()
        .filter(|d| d.get("severity").and_then(Value::as_str) == Some(severity))
        .count()
}

struct Inner {
    results: BTreeMap<String, ProjectState>,
    /// The projects and counts of the last [`Tracker::sync`].
    last: Option<Snapshot>,
    /// When the file was last written, and whether anything changed since.
    written: Option<std::time::Instant>,
    dirty: bool,
    /// The projects, compiles, directories and readiness of the last [`Tracker::sync`].
    shape: Option<(usize, usize, usize, bool)>,
    /// How many of `results` failed.
    failing: usize,
    /// Projects not watched now (`watch-degraded` with backend `none`: the folder is missing,
    /// or another daemon keeps it) → the reason; until their `watching`.
    waiting: BTreeMap<String, String>,
    warned: bool,
    /// Whether the state files of daemons that no longer run were removed (at the first write).
    swept: bool,
}

impl Inner {
    /// The projects waiting for their folder that were never compiled.
    fn waiting_uncompiled(&self) -> usize {
        self.waiting
            .keys()
            .filter(|p| !self.results.contains_key(*p))
            .count()
    }
}

/// The file is written at most this often (a startup of 1,000 projects would otherwise write
/// it 1,000 times); a change within it is written by a later [`Tracker::sync`] (the event loop
/// calls it at least every 2 s) or at stop.
pub const MIN_WRITE_INTERVAL: std::time::Duration = std::time::Duration::from_millis(250);

/// The projects' last results, and the state file they are written to.
pub struct Tracker {
    path: Option<PathBuf>,
    started: String,
    inner: Mutex<Inner>,
}

impl Tracker {
    /// Results kept in memory only (tests, or no file wanted).
    pub fn new(path: Option<PathBuf>) -> Self {
        Tracker {
            path,
            started: now(),
            inner: Mutex::new(Inner {
                results: BTreeMap::new(),
                last: None,
                written: None,
                dirty: false,
                shape: None,
                failing: 0,
                waiting: BTreeMap::new(),
                warned: false,
                swept: false,
            }),
        }
    }

    pub fn path(&self) -> Option<&Path> {
        self.path.as_deref()
    }

    /// Whether `project`'s last compile failed with the error `code` first (`E604`: its
    /// outputs or write-back could not be written).
    pub fn failed_with(&self, project: &str, code: &str) -> bool {
        self.lock().results.get(project).is_some_and(|r| {
            r.result == "failed"
                && r.first_error
                    .as_deref()
                    .is_some_and(|e| e.split([' ', ':']).next() == Some(code))
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Takes what concerns the state from an event as it is emitted (any thread): the
    /// compile results; and `stopped`, which writes the file one last time.
    pub fn observe(&self, project: Option<&str>, event: &Event) {
        let simulation = match (project, event) {
            (
                Some(p),
                Event::SimulationSucceeded {
                    run_id,
                    runs,
                    cycle_s,
                    ..
                },
            ) => Some((
                p,
                SimulationState {
                    result: "ok".into(),
                    time: now(),
                    run_id: *run_id,
                    runs: *runs,
                    cycle_s: *cycle_s,
                    problem: None,
                },
            )),
            (
                Some(p),
                Event::SimulationFailed {
                    run_id,
                    runs,
                    cycle_s,
                    kind,
                    message,
                    file,
                    line,
                    ..
                },
            ) => Some((
                p,
                SimulationState {
                    result: "failed".into(),
                    time: now(),
                    run_id: *run_id,
                    runs: *runs,
                    cycle_s: *cycle_s,
                    problem: Some(match (file, line) {
                        (Some(f), Some(l)) => format!("{kind}: {message} [{f}:{l}]"),
                        _ => format!("{kind}: {message}"),
                    }),
                },
            )),
            _ => None,
        };
        if let Some((p, sim)) = simulation {
            let mut st = self.lock();
            if let Some(r) = st.results.get_mut(p) {
                r.simulation = Some(sim);
                st.dirty = true;
            }
            return;
        }
        let deploy = match (project, event) {
            (
                Some(p),
                Event::DeployStarted {
                    run_id,
                    program,
                    controller,
                    ..
                },
            ) => Some((p, *run_id, program, controller, "running", None)),
            (
                Some(p),
                Event::DeploySucceeded {
                    run_id,
                    program,
                    controller,
                    ..
                },
            ) => Some((p, *run_id, program, controller, "ok", None)),
            (
                Some(p),
                Event::DeployFailed {
                    run_id,
                    program,
                    controller,
                    reason,
                    stderr,
                    ..
                },
            ) => {
                let why = Event::deploy_failure(reason, stderr);
                Some((p, *run_id, program, controller, "failed", Some(why)))
            }
            _ => None,
        };
        if let Some((p, run_id, program, controller, result, reason)) = deploy {
            let mut st = self.lock();
            if let Some(r) = st.results.get_mut(p) {
                let d = DeployState {
                    program: program.clone(),
                    controller: controller.clone(),
                    result: result.into(),
                    time: now(),
                    run_id,
                    reason,
                };
                match r.deploys.iter_mut().find(|x| x.program == *program) {
                    Some(x) => *x = d,
                    None => r.deploys.push(d),
                }
                st.dirty = true;
            }
            return;
        }
        let result = match (project, event) {
            (
                Some(p),
                Event::CompileSucceeded {
                    run_id,
                    duration_ms,
                    outputs,
                    stale,
                    counts,
                    ..
                },
            ) => ProjectState {
                stale: stale.clone(),
                project: p.to_owned(),
                result: "ok".into(),
                time: Some(now()),
                run_id: Some(*run_id),
                duration_ms: Some(*duration_ms),
                outputs: outputs.iter().map(|o| o.path.clone()).collect(),
                errors: 0,
                warnings: counts.warnings,
                first_error: None,
                waiting: None,
                deploys: Vec::new(),
                simulation: None,
            },
            (
                Some(p),
                Event::CompileFailed {
                    run_id,
                    duration_ms,
                    diagnostics,
                },
            ) => ProjectState {
                project: p.to_owned(),
                result: "failed".into(),
                time: Some(now()),
                run_id: Some(*run_id),
                duration_ms: Some(*duration_ms),
                outputs: Vec::new(),
                errors: count(diagnostics, "error").max(1),
                warnings: count(diagnostics, "warning"),
                first_error: diagnostics
                    .iter()
                    .find(|d| d.get("severity").and_then(Value::as_str) == Some("error"))
                    .or(diagnostics.first())
                    .map(describe),
                waiting: None,
                stale: Vec::new(),
                deploys: Vec::new(),
                simulation: None,
            },
            // A project folder that is not watched (missing, or kept by another daemon) is
            // waited for; `watching` ends the wait.
            (
                Some(p),
                Event::WatchDegraded {
                    root: None,
                    reason,
                    backend: Some("none"),
                },
            ) => {
                let mut st = self.lock();
                st.waiting.insert(p.to_owned(), reason.clone());
                st.dirty = true;
                return;
            }
            (Some(p), Event::Watching { .. }) => {
                let mut st = self.lock();
                if st.waiting.remove(p).is_some() {
                    st.dirty = true;
                }
                return;
            }
            (_, Event::Stopped { .. }) => {
                let mut st = self.lock();
                if let Some(mut snap) = st.last.clone() {
                    // The results held back by the rate limit, too.
                    for p in &mut snap.projects {
                        if let Some(r) = st.results.get(&p.project) {
                            *p = r.clone();
                        }
                        p.waiting = st.waiting.get(&p.project).cloned();
                        if p.result == "waiting" && p.waiting.is_none() {
                            p.result = "pending".into();
                        }
                    }
                    snap.daemon = "stopped".into();
                    snap.compiling = 0;
                    snap.updated = now();
                    self.write(&mut st, &snap);
                }
                return;
            }
            _ => return,
        };
        let mut st = self.lock();
        let failed = result.result == "failed";
        let mut result = result;
        // The last deploys stay: a compile that deploys nothing leaves the controllers as they
        // were.
        if let Some(b) = st.results.get_mut(&result.project) {
            result.deploys = std::mem::take(&mut b.deploys);
            // So does the last simulation, until the next one says otherwise.
            result.simulation = b.simulation.take();
        }
        let before = st.results.insert(result.project.clone(), result);
        let was = before.is_some_and(|b| b.result == "failed");
        match (was, failed) {
            (false, true) => st.failing += 1,
            (true, false) => st.failing = st.failing.saturating_sub(1),
            _ => {}
        }
        st.dirty = true;
    }

    /// The state of `projects` now (the daemon's table: removed and forgotten projects are
    /// left out), written to the state file (at most every [`MIN_WRITE_INTERVAL`]); returns the
    /// [`sentence`] for systemd. `ready`: the startup compiles are done (systemd's `READY=1`);
    /// before, `daemon` is `starting`.
    ///
    /// Called after every compile: constant time unless the file is written (then one pass over
    /// the projects), so a startup of many projects does not slow down the event loop.
    pub fn sync<'a>(
        &self,
        projects: impl ExactSizeIterator<Item = &'a Path>,
        compiling: usize,
        directories: usize,
        ready: bool,
    ) -> String {
        let mut st = self.lock();
        let n = projects.len();
        // Between writes the results may still hold a project removed since the last one.
        // Waiting projects are few (missing folders): counting them is no pass over all.
        let waiting = st.waiting_uncompiled().min(n);
        let mut summary = sentence(Tally {
            projects: n,
            failing: st.failing.min(n),
            compiling,
            pending: n.saturating_sub(st.results.len() + waiting),
            waiting,
            directories,
        });
        let shape = (n, compiling, directories, ready);
        if st.shape != Some(shape) {
            st.shape = Some(shape);
            st.dirty = true;
        }
        let due = st.written.is_none_or(|t| t.elapsed() >= MIN_WRITE_INTERVAL);
        if !(st.dirty && due) {
            return summary;
        }
        let mut kept = BTreeMap::new();
        let mut kept_waiting = BTreeMap::new();
        let list: Vec<ProjectState> = projects
            .map(|p| {
                let key = p.display().to_string();
                let waiting = st.waiting.remove(&key);
                if let Some(w) = &waiting {
                    kept_waiting.insert(key.clone(), w.clone());
                }
                match st.results.remove(&key) {
                    Some(r) => {
                        kept.insert(key, r.clone());
                        ProjectState { waiting, ..r }
                    }
                    None => ProjectState {
                        project: key,
                        result: if waiting.is_some() {
                            "waiting"
                        } else {
                            "pending"
                        }
                        .into(),
                        waiting,
                        ..ProjectState::default()
                    },
                }
            })
            .collect();
        st.results = kept;
        st.waiting = kept_waiting;
        st.failing = st.results.values().filter(|r| r.result == "failed").count();
        let waiting = st.waiting_uncompiled();
        summary = sentence(Tally {
            projects: n,
            failing: st.failing,
            compiling,
            pending: n - st.results.len() - waiting,
            waiting,
            directories,
        });
        let snap = Snapshot {
            schema: SCHEMA.into(),
            version: crate::VERSION.into(),
            pid: std::process::id(),
            pid_start: process_start(std::process::id()),
            started: self.started.clone(),
            updated: now(),
            daemon: if ready { "running" } else { "starting" }.into(),
            compiling,
            summary: summary.clone(),
            projects: list,
        };
        self.write(&mut st, &snap);
        st.last = Some(snap);
        st.dirty = false;
        st.written = Some(std::time::Instant::now());
        summary
    }

    fn write(&self, st: &mut Inner, snap: &Snapshot) {
        let Some(path) = &self.path else {
            return;
        };
        if !st.swept {
            st.swept = true;
            sweep_stopped(path);
        }
        if let Err(e) = write_atomically(path, snap) {
            if !st.warned {
                st.warned = true;
                tracing::warn!(
                    "cannot write the state file {} (`skillpost status` will not see this daemon): {e}",
                    path.display()
                );
            }
        } else {
            st.warned = false;
        }
    }
}
