//! One compile of one project, run on a blocking thread: the check whether any input's bytes
//! changed, the compile, the writing, and the events of the run. Its [`Report`] goes back to the
//! event loop.

use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use crate::compile::{self, Compilation, Options};
use crate::diag::{Code, Severity};
use crate::load::{FileSource, FsSource};

use super::config::{self, ProjectSpec};
use super::events::{Counts, Event, EventSink, OutputInfo};

/// A finished compile, sent back to the event loop.
pub(super) struct Report {
    pub(super) key: PathBuf,
    pub(super) outcome: Outcome,
}

pub(super) enum Outcome {
    /// No input changed: nothing compiled.
    Unchanged,
    /// A file was caught half-written: try again after a quiet period.
    Retry,
    Compiled {
        inputs: HashMap<PathBuf, Option<u64>>,
        outputs: Vec<PathBuf>,
        /// The write-back was skipped because the blackboard changed: compile again.
        again: bool,
    },
    /// The project could not be set up (no blackboard): reported.
    Failed,
}

pub(super) fn hash_bytes(b: &[u8]) -> u64 {
    let mut h = std::hash::DefaultHasher::new();
    b.hash(&mut h);
    h.finish()
}

/// The hash of a file's bytes; `None` for anything but a readable regular file. Read through
/// [`crate::load::read_limited`]: a FIFO or device among the inputs is refused at once (a
/// blocking read hung the project's compile for good), and nothing past the largest file size a
/// configuration can allow is read.
pub(super) fn hash_file(p: &Path) -> Option<u64> {
    let max = config::MAX_FILE_SIZE_MB_RANGE.end() * 1024 * 1024;
    crate::load::read_limited(p, max)
        .ok()
        .map(|b| hash_bytes(&b))
}

/// Reads files like [`FsSource`] and keeps the hash of every file's bytes.
struct Hashing {
    fs: FsSource,
    seen: std::sync::Mutex<HashMap<PathBuf, Option<u64>>>,
}

impl FileSource for Hashing {
    fn real_path(&self, path: &Path) -> Option<PathBuf> {
        self.fs.real_path(path)
    }

    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        let r = self.fs.read(path);
        let h = r.as_ref().ok().map(|b| hash_bytes(b));
        self.seen
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(path.to_owned(), h);
        r
    }
}

/// One compile, run on a blocking thread.
pub(super) struct Job {
    pub(super) key: PathBuf,
    pub(super) spec: ProjectSpec,
    /// The input hashes of the last compile; `None` compiles without checking.
    pub(super) known: Option<HashMap<PathBuf, Option<u64>>>,
    pub(super) changed: Vec<PathBuf>,
    pub(super) trigger: &'static str,
    pub(super) may_retry: bool,
    pub(super) confine: bool,
    pub(super) max_file_size: u64,
    pub(super) run_id: u64,
    pub(super) sink: Arc<EventSink>,
}

impl Job {
    pub(super) fn project(&self) -> String {
        self.key.display().to_string()
    }

    /// Emits `compile-failed` with these diagnostics (JSON objects as `--format json` prints).
    pub(super) fn failed(&self, duration_ms: u64, diagnostics: Vec<serde_json::Value>) {
        self.sink.emit(
            Some(&self.project()),
            Event::CompileFailed {
                run_id: self.run_id,
                duration_ms,
                diagnostics,
            },
        );
    }

    pub(super) fn run(self) -> Outcome {
        let project = self.project();
        // Only when an input's bytes changed (or a new blackboard appeared): reads, `touch`,
        // saves of the same bytes and our own writes start nothing, not even an event.
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
            self.sink.emit(
                Some(&project),
                Event::ChangeDetected {
                    paths: differ.iter().map(|p| p.display().to_string()).collect(),
                },
            );
        }
        let (blackboard, program) = match config::resolve(&self.spec) {
            Ok(x) => x,
            Err(why) => {
                self.failed(
                    0,
                    vec![serde_json::json!({"severity": "error", "code": Code::FileUnreadable.as_str(), "message": why, "file": project})],
                );
                return Outcome::Failed;
            }
        };
        self.sink.emit(
            Some(&project),
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
        let started = std::time::Instant::now();
        let fs = Hashing {
            fs: FsSource {
                max_file_size: self.max_file_size,
            },
            seen: Default::default(),
        };
        let opts = Options {
            program: Some(program),
            confine_to: self.confine.then(|| self.key.clone()),
            ..Options::default()
        };
        let c = compile::compile(&fs, &blackboard, &opts);
        let mut inputs = fs.seen.into_inner().unwrap_or_else(|p| p.into_inner());
        add_link_targets(&mut inputs);
        let ms = || started.elapsed().as_millis() as u64;
        if c.has_errors() {
            if self.may_retry && half_written(&c, &inputs) {
                tracing::info!("{project}: a file is still being written; trying again");
                return Outcome::Retry;
            }
            let diags = c
                .diagnostics
                .iter()
                .map(|d| serde_json::json!(d.locate(&c.sources)))
                .collect();
            self.failed(ms(), diags);
            return Outcome::Compiled {
                inputs,
                outputs: Vec::new(),
                again: false,
            };
        }
        let applied = match compile::apply(&c) {
            Ok(a) => a,
            Err(e) => {
                self.sink.emit(
                    Some(&project),
                    Event::failed_with(
                        self.run_id,
                        ms(),
                        Code::CannotWrite.as_str(),
                        format!("cannot write: {e}"),
                    ),
                );
                return Outcome::Compiled {
                    inputs,
                    outputs: c.outputs.iter().map(|(p, _)| p.clone()).collect(),
                    again: false,
                };
            }
        };
        let warnings: Vec<_> = c
            .diagnostics
            .iter()
            .filter(|d| d.severity == Severity::Warning)
            .map(|d| serde_json::json!(d.locate(&c.sources)))
            .collect();
        self.sink.emit(
            Some(&project),
            Event::CompileSucceeded {
                run_id: self.run_id,
                duration_ms: ms(),
                outputs: applied
                    .outputs
                    .iter()
                    .map(|(p, w)| OutputInfo {
                        path: p.display().to_string(),
                        written: *w,
                    })
                    .collect(),
                counts: Counts {
                    steps: c.skill_steps,
                    warnings: warnings.len(),
                },
                warnings,
            },
        );
        // (The outputs are our other writes: never inputs (E605), and their events are ignored,
        // so they need no known state.)
        let mut again = false;
        if let (Some(wb), Some(outcome)) = (&c.write_back, &applied.write_back) {
            use crate::write::WriteBackOutcome as W;
            let (written, reason) = (*outcome == W::Written, outcome.reason());
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
            again |= *outcome == W::SkippedChangedOnDisk;
            self.sink.emit(
                Some(&project),
                Event::WriteBack {
                    run_id: self.run_id,
                    file: wb.blackboard.display().to_string(),
                    value: wb.value.clone(),
                    written,
                    reason: reason.map(str::to_owned),
                    skipped: !matches!(outcome, W::Written | W::AlreadyRight),
                },
            );
        }
        Outcome::Compiled {
            inputs,
            outputs: c.outputs.iter().map(|(p, _)| p.clone()).collect(),
            again,
        }
    }
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
/// unreadable text) in a file whose bytes differ now from those read, or that was modified
/// within the last second.
pub(super) fn half_written(c: &Compilation, read: &HashMap<PathBuf, Option<u64>>) -> bool {
    c.diagnostics.iter().any(|d| {
        if !matches!(d.code, Code::XmlSyntax | Code::FileUnreadable) {
            return false;
        }
        // An unreadable file's diagnostic points at the `refURI` naming it; its path is the file.
        let Some(file) = d
            .path
            .clone()
            .or_else(|| d.span.as_ref().map(|s| c.sources.get(s.file).path.clone()))
        else {
            return false;
        };
        let now_hash = hash_file(&file);
        let changed = read.get(&file).is_some_and(|h| *h != now_hash);
        let recent = std::fs::metadata(&file)
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age < Duration::from_secs(1));
        changed || recent
    })
}
