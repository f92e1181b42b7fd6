//! One compile of one project, run on a blocking thread: the check whether any input's bytes
//! changed, the compile, the writing, and the events of the run. Its [`Report`] goes back to the
//! event loop. `hashing.rs`: the file source that hashes what the compile reads; `deploys.rs`:
//! what a deploy hook gets; `tests.rs`: the unit tests.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};
use std::time::Duration;

use crate::compile::{self, Compilation, Options};
use crate::diag::{Code, Severity};
use crate::load::FsSource;

use super::config::{self, ProjectSpec};
use super::events::{Counts, Event, EventSink, OutputInfo};
use super::settle::Run;

/// The code of the warning that a project's program name was derived (made a KRL name from a
/// folder or blackboard name; a daemon-only code: the command line is given the name).
pub(super) const PROGRAM_DERIVED: &str = "W701";

/// A finished compile, sent back to the event loop.
pub(super) struct Report {
    pub(super) key: PathBuf,
    /// The run's `run_id` (given back when nothing was compiled: no event used it).
    pub(super) run_id: u64,
    pub(super) outcome: Outcome,
}

pub(super) enum Outcome {
    /// No input changed: nothing compiled.
    Unchanged,
    /// A file was caught half-written: try again after a quiet period. `counted`: whether
    /// the attempt counts towards the limit (not when the file's bytes were still changing).
    /// `starved`: the process ran out of descriptors or memory ([`starved`]): try again later.
    Retry { counted: bool, starved: bool },
    Compiled {
        inputs: HashMap<PathBuf, Option<u64>>,
        outputs: Vec<PathBuf>,
        /// The write-back was skipped because the blackboard changed: compile again.
        again: bool,
        /// The write-back was skipped because another program had the blackboard open: the
        /// event loop compiles again a few times ([`super::MAX_IN_USE_ROUNDS`]).
        in_use: bool,
        /// A successful compile that wrote at least one output: what a deploy hook is given,
        /// one per program with new bytes.
        deploy: Option<Vec<super::deploy::Context>>,
        /// The compile succeeded and its outputs are on disk.
        succeeded: bool,
    },
    /// The project could not be set up (no blackboard): reported.
    Failed,
    /// An early run ([`Run::Early`]) that did not compile: nothing was reported or written.
    /// The event loop compiles again once the inputs have been quiet for the whole period, with
    /// what this run was given.
    Deferred {
        changed: Vec<PathBuf>,
        trigger: &'static str,
        /// The run skipped the hash check.
        forced: bool,
    },
}

use crate::load::hash_bytes;

mod deploys;
mod hashing;

use hashing::Hashing;

/// How long a write-back waits for another program (a viewer, an editor) to close the
/// blackboard before it is reported skipped (docs/DAEMON.md); the event loop then compiles
/// again a few times ([`super::MAX_IN_USE_ROUNDS`]).
pub(super) const WRITE_BACK_WAIT: Duration = Duration::from_secs(10);

/// The hash of a file's bytes; `None` for anything but a readable regular file. Through
/// [`crate::load::hash_file`]: a FIFO or device among the inputs is refused at once (a blocking
/// read hung the project's compile for good), the file is read in pieces, and nothing past the
/// largest file size a configuration can allow is read.
///
/// A file another program holds a write lease on (a file server's oplock on a shared folder) is
/// refused for a moment while the kernel asks that program to let go: the hash is tried again
/// after each of [`LEASE_WAITS`] before the file counts as unreadable. Taken at once for a
/// change, the refusal compiled the project a second time for nothing (a `write-back-skipped`
/// run whose write-back then found the blackboard "already right").
pub(super) fn hash_file(p: &Path) -> Option<u64> {
    let max = config::MAX_FILE_SIZE_MB_RANGE.end() * 1024 * 1024;
    for wait in LEASE_WAITS {
        match crate::load::hash_file(p, max) {
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => std::thread::sleep(wait),
            hashed => return hashed.ok(),
        }
    }
    crate::load::hash_file(p, max).ok()
}

/// The waits of [`hash_file`] for a lease being given up: 310 ms in all. A holder that answers
/// (Samba, the daemon's own write-back) lets go within milliseconds; one that does not keeps
/// the file for the kernel's `lease-break-time` (45 s by default), and the check goes on without
/// it.
const LEASE_WAITS: [Duration; 5] = [
    Duration::from_millis(10),
    Duration::from_millis(20),
    Duration::from_millis(40),
    Duration::from_millis(80),
    Duration::from_millis(160),
];

/// How far a run got in its events: every `compile-started` gets exactly one outcome
/// (`compile-succeeded`, `compile-failed`, `compile-retrying`) and every outcome has a
/// `compile-started`. Shared with the panic handler, which completes what a panic cut short.
#[derive(Debug, Default)]
pub(super) struct Progress(AtomicU8);

const STARTED: u8 = 1;
const FINISHED: u8 = 2;

impl Progress {
    fn set(&self, state: u8) {
        self.0.store(state, Ordering::SeqCst);
    }

    fn get(&self) -> u8 {
        self.0.load(Ordering::SeqCst)
    }
}

/// After a panic in a run (a bug, never input): `compile-started` if the run had not said it
/// yet, then `compile-failed` with `E000`, unless the run had already given its outcome (then
/// only the log says it).
pub(super) fn after_panic(
    sink: &EventSink,
    key: &Path,
    run_id: u64,
    trigger: &'static str,
    progress: &Progress,
) {
    let project = key.display().to_string();
    let state = progress.get();
    if state == FINISHED {
        tracing::error!("{project}: run {run_id} panicked after its outcome (a bug)");
        return;
    }
    if state < STARTED {
        sink.emit(
            Some(&project),
            Event::CompileStarted {
                run_id,
                trigger,
                changed: Vec::new(),
            },
        );
    }
    sink.emit(
        Some(&project),
        Event::failed_with(
            run_id,
            0,
            "E000",
            "internal error (a bug in skillpost): the compile panicked; see the log".into(),
        ),
    );
    progress.set(FINISHED);
}

/// One compile, run on a blocking thread.
pub(super) struct Job {
    pub(super) key: PathBuf,
    pub(super) spec: ProjectSpec,
    /// The input hashes of the last compile; `None` compiles without checking.
    pub(super) known: Option<HashMap<PathBuf, Option<u64>>>,
    pub(super) changed: Vec<PathBuf>,
    pub(super) trigger: &'static str,
    /// Early (after a complete write, a failure is not reported), settled, or the confirmation
    /// of an early run's failure.
    pub(super) run: Run,
    pub(super) may_retry: bool,
    /// Which retry a half-written file would cause (1 for the first).
    pub(super) attempt: u32,
    /// Whether a compile that ran out of descriptors or memory may be tried again
    /// ([`starved`]; counted apart from the half-written retries).
    pub(super) may_retry_starved: bool,
    pub(super) confine: bool,
    pub(super) max_file_size: u64,
    pub(super) run_id: u64,
    pub(super) sink: Arc<EventSink>,
    pub(super) progress: Arc<Progress>,
    /// The runtime directory, where the copies a deploy hook ships are kept
    /// ([`super::snapshot`]); `None` when the project has no hook.
    pub(super) snapshots: Option<PathBuf>,
}

impl Job {
    pub(super) fn project(&self) -> String {
        self.key.display().to_string()
    }

    /// Emits `compile-failed` with these diagnostics (JSON objects as `--format json` prints).
    /// A run that failed because the process ran out of descriptors or memory (`why`, the
    /// error's text): `compile-retrying` saying so, and the retry, while more may follow.
    fn starved_retry(&self, duration_ms: u64, why: &str) -> Option<Outcome> {
        if !self.may_retry_starved || !starved(why) {
            return None;
        }
        let project = self.project();
        tracing::warn!("{project}: {why}; trying again");
        self.outcome(Event::CompileRetrying {
            run_id: self.run_id,
            duration_ms,
            file: Some(project),
            attempt: self.attempt,
            reason: Some(format!(
                "the daemon ran short of a resource ({why}); trying again shortly"
            )),
        });
        Some(Outcome::Retry {
            counted: false,
            starved: true,
        })
    }

    pub(super) fn failed(&self, duration_ms: u64, diagnostics: Vec<serde_json::Value>) {
        self.outcome(Event::CompileFailed {
            run_id: self.run_id,
            duration_ms,
            diagnostics,
        });
    }

    /// Emits `compile-started`.
    fn started(&self) {
        self.sink.emit(
            Some(&self.project()),
            Event::CompileStarted {
                run_id: self.run_id,
                trigger: self.trigger,
                changed: self
                    .changed
                    .iter()
                    .map(|p| p.display().to_string())
                    .collect(),
            },
        );
        self.progress.set(STARTED);
    }

    /// Emits the run's one outcome.
    fn outcome(&self, event: Event) {
        self.sink.emit(Some(&self.project()), event);
        self.progress.set(FINISHED);
    }

    /// One attempt of the write-back, through the folder the blackboard was read from.
    fn write_back_once(
        &self,
        c: &Compilation,
        wb: &compile::WriteBack,
    ) -> std::io::Result<crate::write::WriteBackOutcome> {
        let path = match &c.folder {
            Some(f) => f.route(&wb.blackboard),
            None => wb.blackboard.clone(),
        };
        crate::write::write_back_all(&path, &wb.expected, wb.bom, &wb.splices()).map_err(|e| {
            let e = match &c.folder {
                Some(f) => std::io::Error::new(e.kind(), f.unroute(&e.to_string())),
                None => e,
            };
            std::io::Error::new(e.kind(), format!("{}: {e}", wb.blackboard.display()))
        })
    }

    /// The write-back while another program has the blackboard open (its write lease is
    /// refused): tried again, 40 ms apart at first and doubling up to 500 ms, until the other
    /// program closes it, for at most [`WRITE_BACK_WAIT`]. It stops waiting at once when the
    /// blackboard's bytes change (a save: skipped, compiled again; the save is never
    /// overwritten, `write_back_all` checks that) and, within 20 ms, when the daemon stops.
    /// Returns the last
    /// outcome, how long it waited, and the error that ended it (as the reason).
    fn wait_for_blackboard(
        &self,
        c: &Compilation,
        wb: &compile::WriteBack,
    ) -> (
        crate::write::WriteBackOutcome,
        Option<Duration>,
        Option<String>,
    ) {
        use crate::write::WriteBackOutcome as W;
        let start = std::time::Instant::now();
        let read = hash_bytes(&wb.expected);
        let mut step = Duration::from_millis(40);
        let mut outcome = W::SkippedInUse;
        let mut error = None;
        while outcome == W::SkippedInUse && !self.sink.stopping() {
            let left = WRITE_BACK_WAIT.saturating_sub(start.elapsed());
            if left.is_zero() {
                break;
            }
            // In slices, so that a stop ends the wait within one.
            let until = std::time::Instant::now() + step.min(left);
            while !self.sink.stopping() {
                let now = std::time::Instant::now();
                if now >= until {
                    break;
                }
                std::thread::sleep((until - now).min(Duration::from_millis(20)));
            }
            if self.sink.stopping() {
                break;
            }
            step = (step * 2).min(Duration::from_millis(500));
            if hash_file(&wb.blackboard) != Some(read) {
                outcome = W::SkippedChangedOnDisk;
                break;
            }
            match self.write_back_once(c, wb) {
                Ok(o) => outcome = o,
                Err(e) => {
                    error = Some(format!("cannot write: {e}"));
                    break;
                }
            }
        }
        (outcome, Some(start.elapsed()), error)
    }

    /// Hands the compile's programs to the simulation (docs/SIMULATE.md, "In the daemon").
    fn simulate(
        &self,
        c: &compile::Compilation,
        sim: &super::config::Simulate,
        inputs: &mut HashMap<PathBuf, Option<u64>>,
    ) {
        use crate::simulate::{Cell, Scenario, scenario};
        let (cell, programs) = match Cell::from_compilation(c) {
            Ok(x) => x,
            Err(e) => {
                tracing::warn!("{}: nothing simulated: {}", self.project(), e.0);
                return;
            }
        };
        let scenario = match sim {
            super::config::Simulate::Runs(n) => Ok(Scenario {
                runs: *n,
                ..Scenario::random()
            }),
            super::config::Simulate::Scenario(f) => {
                let path = self.key.join(f);
                // The setting names a file in the project folder; a symbolic link there that
                // leads out of it is not followed (the daemon may read what its user may, the
                // project's writers not). Read once: the input's hash is of the bytes simulated
                // (a file not read is hashed as it stands, so that an unchanged one stays so).
                let read = crate::load::read_limited_inside(&path, scenario::MAX_SIZE, &self.key);
                let hash = match &read {
                    Ok(bytes) => Some(hash_bytes(bytes)),
                    Err(_) => hash_file(&path),
                };
                inputs.insert(path.clone(), hash);
                scenario::load_from(&path, &cell, read)
            }
        };
        super::simulation::submit(super::simulation::Request {
            project: self.project(),
            run_id: self.run_id,
            cell,
            programs,
            scenario,
            sink: self.sink.clone(),
        });
    }

    /// The plan's picture, an output like the others (atomic, only when changed), beside the
    /// main output, added to `outputs`: its path, or the warning why it was not written (the
    /// programs stand).
    fn draw_picture(
        &self,
        c: &Compilation,
        program: &str,
        inputs: &HashMap<PathBuf, Option<u64>>,
        outputs: &mut Vec<(PathBuf, bool)>,
    ) -> (Option<PathBuf>, Option<serde_json::Value>) {
        let Some(main) = outputs.first().map(|(p, _)| p.clone()) else {
            return (None, None);
        };
        let path = main.with_file_name(format!("{program}.svg"));
        let result = if inputs.contains_key(&path) {
            Err(format!(
                "{} is an input of the compile: the picture is not written over it",
                path.display()
            ))
        } else {
            match compile::picture(c, program) {
                Some(svg) => compile::write_beside(c, &path, svg.as_bytes())
                    .map(|o| o == crate::write::WriteOutcome::Written)
                    .map_err(|e| format!("cannot write the picture {}: {e}", path.display())),
                None => Err("no plan to draw".to_owned()),
            }
        };
        match result {
            Ok(written) => {
                outputs.push((path.clone(), written));
                (Some(path), None)
            }
            Err(why) => (
                None,
                Some(serde_json::json!({
                    "severity": "warning",
                    "code": Code::CannotWrite.as_str(),
                    "message": why,
                })),
            ),
        }
    }

    pub(super) fn run(self) -> Outcome {
        let project = self.project();
        // Only when an input's bytes changed (or a new blackboard appeared): reads, `touch`,
        // saves of the same bytes and our own writes start nothing, not even an event.
        // An early run says nothing until it knows it compiled: its failure is not reported
        // (the inputs may be half of a save of several files), and then no event may name it.
        let mut detected = None;
        if let Some(known) = &self.known
            && !known.is_empty()
        {
            let mut differ: Vec<&PathBuf> = known
                .iter()
                .filter(|(path, h)| hash_file(path) != **h)
                .map(|(p, _)| p)
                .collect();
            differ.extend(self.changed.iter().filter(|c| {
                !known.contains_key(*c)
                    && c.extension().is_some_and(|x| x.eq_ignore_ascii_case("aml"))
            }));
            if differ.is_empty() {
                tracing::debug!("{project}: no input changed");
                return Outcome::Unchanged;
            }
            differ.sort();
            detected = Some(Event::ChangeDetected {
                paths: differ.iter().map(|p| p.display().to_string()).collect(),
            });
        }
        let early = self.run == Run::Early;
        let deferred = |job: Job| Outcome::Deferred {
            forced: job.known.is_none(),
            changed: job.changed,
            trigger: job.trigger,
        };
        let announce = |job: &Job, detected: &mut Option<Event>| {
            if let Some(e) = detected.take() {
                job.sink.emit(Some(&job.project()), e);
            }
            job.started();
        };
        if !early {
            announce(&self, &mut detected);
        }
        let (blackboard, program) = match config::resolve_project(&self.spec) {
            Err(_) if early => return deferred(self),
            Ok(x) => x,
            Err(why) => {
                if let Some(o) = self.starved_retry(0, &why) {
                    return o;
                }
                self.failed(
                    0,
                    vec![serde_json::json!({"severity": "error", "code": Code::FileUnreadable.as_str(), "message": why, "file": project})],
                );
                return Outcome::Failed;
            }
        };
        let started = std::time::Instant::now();
        let fs = Hashing {
            fs: FsSource {
                max_file_size: self.max_file_size,
            },
            seen: Default::default(),
            own: self
                .sink
                .own_files()
                .iter()
                .filter_map(|p| std::fs::canonicalize(p).ok())
                .collect(),
        };
        let renamed = program.derived_from.as_ref().map(|from| {
            serde_json::json!({
                "severity": "warning",
                "code": PROGRAM_DERIVED,
                "message": format!(
                    "`{from}` is not a program name every robot language takes: the program is \
                     called `{}`; set `program` in the configuration to choose the name",
                    program.name
                ),
                "file": blackboard.display().to_string(),
            })
        });
        // Exactly what `skillpost [--template F] [--lf] [--pou P] BLACKBOARD PROGRAM` writes.
        let opts = Options {
            program: Some(program.name.clone()),
            lf: self.spec.lf,
            template: self.spec.template.clone(),
            confine_to: self.confine.then(|| self.key.clone()),
            pou: self.spec.pou.clone(),
            // The chart and its plan only for the picture and the simulation.
            keep_model: self.spec.picture || self.spec.simulate.is_some(),
            drop_warnings: false,
            bind_split_from: None,
            picture: None,
            max_lines: self.spec.max_lines,
        };
        let mut c = compile::compile(&fs, &blackboard, &opts);
        let mut inputs = fs.seen.into_inner().unwrap_or_else(|p| p.into_inner());
        add_link_targets(&mut inputs);
        let ms = || started.elapsed().as_millis() as u64;
        if early {
            if c.has_errors() || compile::folder_replaced(&c).is_some() {
                tracing::debug!(
                    "{project}: the early compile failed; again when the inputs are quiet"
                );
                return deferred(self);
            }
            announce(&self, &mut detected);
        }
        if c.has_errors() {
            // A file whose bytes differ now from those read is being written right now: the
            // writer is still at it, and such an attempt never counts towards the limit (on a
            // loaded machine a burst of saves caught it half-written four times in a row and
            // ended in `compile-failed` while the saves went on).
            if let Some((file, moving)) = half_written(&c, &inputs, self.run == Run::Confirm)
                && (self.may_retry || moving)
                && !fs
                    .own
                    .contains(&std::fs::canonicalize(&file).unwrap_or_else(|_| file.clone()))
            {
                tracing::info!("{project}: a file is still being written; trying again");
                self.outcome(Event::CompileRetrying {
                    run_id: self.run_id,
                    duration_ms: ms(),
                    file: Some(file.display().to_string()),
                    attempt: self.attempt,
                    reason: None,
                });
                return Outcome::Retry {
                    counted: !moving,
                    starved: false,
                };
            }
            let why = c
                .diagnostics
                .iter()
                .filter(|d| d.severity == Severity::Error)
                .find(|d| starved(&d.message));
            if let Some(d) = why
                && let Some(o) = self.starved_retry(ms(), &d.message)
            {
                return o;
            }
            let diags = renamed
                .into_iter()
                .chain(
                    c.diagnostics
                        .iter()
                        .map(|d| serde_json::json!(d.locate(&c.sources))),
                )
                .collect();
            self.failed(ms(), diags);
            return Outcome::Compiled {
                inputs,
                outputs: Vec::new(),
                again: false,
                in_use: false,
                deploy: None,
                succeeded: false,
            };
        }
        // The folder was moved or replaced meanwhile (its inputs may come from two folders):
        // nothing is written; the next attempt reads whatever is at the name then.
        if compile::folder_replaced(&c).is_some() && self.may_retry {
            tracing::info!("{project}: the project folder was replaced during the compile");
            self.outcome(Event::CompileRetrying {
                run_id: self.run_id,
                duration_ms: ms(),
                file: Some(project.clone()),
                attempt: self.attempt,
                reason: None,
            });
            return Outcome::Retry {
                counted: true,
                starved: false,
            };
        }
        // The outputs first; the write-back is tried here, so that a wait for another program
        // to close the blackboard is neither part of the compile's `duration_ms` nor of a new
        // compile (it was: 6 compiles of ~1.3 s each for a viewer open 8 s).
        let write_back = c.write_back.take();
        let applied = compile::apply(&c).and_then(|a| {
            let Some(wb) = &write_back else {
                return Ok((a, None));
            };
            match self.write_back_once(&c, wb) {
                Ok(o) => Ok((a, Some(o))),
                Err(e) => Err(e),
            }
        });
        let (applied, first) = match applied {
            Ok(a) => a,
            Err(e) => {
                if let Some(o) = self.starved_retry(ms(), &e.to_string()) {
                    return o;
                }
                self.outcome(Event::failed_with(
                    self.run_id,
                    ms(),
                    Code::CannotWrite.as_str(),
                    format!("cannot write: {e}"),
                ));
                return Outcome::Compiled {
                    inputs,
                    outputs: c.outputs.iter().map(|(p, _)| p.clone()).collect(),
                    again: false,
                    in_use: false,
                    deploy: None,
                    succeeded: false,
                };
            }
        };
        let mut applied = applied;
        let (picture_path, picture_warning) = if self.spec.picture {
            self.draw_picture(&c, &program.name, &inputs, &mut applied.outputs)
        } else {
            (None, None)
        };
        let warnings: Vec<_> = renamed
            .into_iter()
            .chain(picture_warning)
            .chain(
                c.diagnostics
                    .iter()
                    .filter(|d| d.severity == Severity::Warning)
                    .map(|d| serde_json::json!(d.locate(&c.sources))),
            )
            .collect();
        let stale = stale_programs(&applied.outputs, &inputs);
        // The compile itself: reading, compiling, writing the outputs, one write-back attempt.
        self.outcome(Event::CompileSucceeded {
            stale,
            run_id: self.run_id,
            duration_ms: ms(),
            outputs: applied
                .outputs
                .iter()
                .enumerate()
                .map(|(k, (p, w))| {
                    // A cell's outputs each name their program and controller (docs/CELLS.md).
                    let (prog, controller) = match c.output_programs.get(k) {
                        Some((prog, ctl)) => (prog.clone(), Some(ctl.clone())),
                        None => (program.name.clone(), c.controller.clone()),
                    };
                    OutputInfo {
                        path: p.display().to_string(),
                        written: *w,
                        program: prog,
                        controller,
                    }
                })
                .collect(),
            counts: Counts {
                steps: c.skill_steps,
                warnings: warnings.len(),
            },
            warnings,
        });
        // (The outputs are our other writes: never inputs (E605), and their events are ignored,
        // so they need no known state.)
        let mut again = false;
        let mut in_use = false;
        if let (Some(wb), Some(first)) = (&write_back, first) {
            use crate::write::WriteBackOutcome as W;
            // Another program has the blackboard open (a viewer, an editor): wait for it to
            // close it, in this run (see `wait_for_blackboard`).
            let (outcome, waited, error) = if first == W::SkippedInUse {
                self.wait_for_blackboard(&c, wb)
            } else {
                (first, None, None)
            };
            let (written, reason) = (outcome == W::Written, outcome.reason());
            if written {
                // Our own write: the bytes *we* wrote are the known state, so the event of our
                // write starts nothing. Not the bytes on disk now: a planner's save may already
                // have replaced ours, and hashing it would take that save for our write.
                let ours = wb.new_bytes().map(|b| hash_bytes(&b));
                inputs.insert(wb.blackboard.clone(), ours);
                // A linked blackboard: the file it points to is an input too (add_link_targets).
                if let Ok(real) = std::fs::canonicalize(&wb.blackboard)
                    && let Some(h) = inputs.get_mut(&real)
                {
                    *h = ours;
                }
                // A save that raced our write: compile again.
                again = hash_file(&wb.blackboard) != ours;
            }
            again |= outcome == W::SkippedChangedOnDisk;
            in_use = outcome == W::SkippedInUse && error.is_none();
            self.sink.emit(
                Some(&project),
                Event::WriteBack {
                    run_id: self.run_id,
                    file: wb.blackboard.display().to_string(),
                    value: wb.value.clone(),
                    values: wb.splices().iter().map(|(_, v)| (*v).to_owned()).collect(),
                    written,
                    reason: error.or(reason.map(str::to_owned)),
                    waited_ms: waited.map(|d| d.as_millis() as u64),
                    skipped: !matches!(outcome, W::Written | W::AlreadyRight),
                },
            );
        }
        let deploy = self.deploys(
            &c,
            &applied.outputs,
            picture_path.as_ref(),
            &program.name,
            &blackboard,
        );
        // The simulation: on a thread of its own; its scenario file is an input (an edit of it
        // compiles and simulates again).
        if let Some(sim) = &self.spec.simulate {
            self.simulate(&c, sim, &mut inputs);
        }
        Outcome::Compiled {
            inputs,
            outputs: applied.outputs.iter().map(|(p, _)| p.clone()).collect(),
            again,
            in_use,
            deploy,
            succeeded: true,
        }
    }
}

/// Program files (`.src`, `.dat`, `.mod`, `.script`) in the folders of `outputs` that are
/// neither an output of this compile nor one of its inputs, sorted: the files of a program
/// this compile no longer writes (its `Program` renamed). Only named, never deleted: the old
/// program may still run on a controller.
fn stale_programs(
    outputs: &[(PathBuf, bool)],
    inputs: &HashMap<PathBuf, Option<u64>>,
) -> Vec<String> {
    let mut folders: Vec<&Path> = outputs.iter().filter_map(|(p, _)| p.parent()).collect();
    folders.sort();
    folders.dedup();
    let mut stale = Vec::new();
    for dir in folders {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        for e in entries.flatten() {
            let path = e.path();
            let program = path.extension().is_some_and(|x| {
                ["src", "dat", "mod", "script"]
                    .iter()
                    .any(|k| x.to_string_lossy().eq_ignore_ascii_case(k))
            });
            if program
                && e.file_type().is_ok_and(|t| t.is_file())
                && !outputs.iter().any(|(o, _)| *o == path)
                && !inputs.contains_key(&path)
            {
                stale.push(path.display().to_string());
            }
        }
    }
    stale.sort();
    stale
}

/// Adds, for every input reached through a symbolic link (the file or a folder on its path), the
/// file the link resolves to, with the same hash: an edit of that file is an event in its own
/// folder, which names the target, not the link. Its folder is then watched and routed like any
/// input's. (A link in the middle of a chain that is pointed elsewhere is not seen until the
/// next event of the project.)
pub(super) fn add_link_targets(inputs: &mut HashMap<PathBuf, Option<u64>>) {
    let targets: Vec<(PathBuf, Option<u64>)> = inputs
        .iter()
        .filter_map(|(path, hash)| {
            let real = std::fs::canonicalize(path).ok()?;
            (real != *path).then_some((real, *hash))
        })
        .collect();
    for (real, hash) in targets {
        inputs.entry(real).or_insert(hash);
    }
}

/// Whether the compile failed on a file caught while it was being written: a syntax error (or
/// unreadable text) in a regular file whose bytes differ now from those read, or, saved within
/// the last second, differ [`STILL_WRITING`] later. Returns that file and `true` (its bytes are
/// moving). A file that is not regular, or whose bytes stay, is not being written: the failure
/// is reported at once. `complete`: the watch saw the save end (closed or renamed into place)
/// and the inputs quiet for the whole period since: a file saved a moment ago is not looked at
/// again.
pub(super) fn half_written(
    c: &Compilation,
    read: &HashMap<PathBuf, Option<u64>>,
    complete: bool,
) -> Option<(PathBuf, bool)> {
    c.diagnostics.iter().find_map(|d| {
        if !matches!(
            d.code,
            Code::XmlSyntax | Code::FileUnreadable | Code::BadTemplate
        ) {
            return None;
        }
        // An unreadable file's diagnostic points at the `refURI` naming it; its path is the file.
        let file = d
            .path
            .clone()
            .or_else(|| d.span.as_ref().map(|s| c.sources.get(s.file).path.clone()))?;
        // Only a regular file can be in the middle of a save: a FIFO, a folder or a device
        // stays what it is, however often it is tried.
        let meta = std::fs::metadata(&file).ok().filter(|m| m.is_file())?;
        let now_hash = hash_file(&file);
        if read.get(&file).is_some_and(|h| *h != now_hash) {
            return Some((file, true));
        }
        // The bytes read are still there. A writer may still be at it: a program that has the
        // file open for writing (an in-place save that truncated and has not written yet) says
        // so; a file saved a moment ago is looked at once more after a short while (the rest of
        // a save written in two goes), and where leases cannot tell, an empty one is taken for a
        // save in progress. A complete file that is wrong (a DOCTYPE, not UTF-8) stays the same
        // and fails now, not after three retries.
        let open = crate::write::writeback::lease::open_for_writing(&file);
        if open == Some(true) {
            return Some((file, true));
        }
        let recent = meta
            .modified()
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age < Duration::from_secs(1));
        if recent && !complete {
            if open.is_none() && meta.len() == 0 {
                return Some((file, false));
            }
            std::thread::sleep(STILL_WRITING);
            if hash_file(&file) != now_hash {
                return Some((file, true));
            }
        }
        None
    })
}

/// Whether an error's text is that of a resource the process ran short of, which passes: too
/// many open files (`EMFILE`), in the system too (`ENFILE`), no memory (`ENOMEM`), a thread or
/// process that could not be started now (`EAGAIN`). The text is the operating system's, as
/// `std::io::Error` writes it (`... (os error 24)`), wherever the error was wrapped.
pub(super) fn starved(text: &str) -> bool {
    use rustix::io::Errno;
    [Errno::MFILE, Errno::NFILE, Errno::NOMEM, Errno::AGAIN]
        .iter()
        .any(|e| text.contains(&format!("(os error {})", e.raw_os_error())))
}

/// How long [`half_written`] waits to see whether a file saved a moment ago is still changing.
const STILL_WRITING: Duration = Duration::from_millis(50);

#[cfg(test)]
mod tests;
