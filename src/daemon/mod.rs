//! `skillpost watch`: keeps project folders compiled (SPEC.md section 7).
//!
//! # Layout
//!
//! - [`config`]: the TOML file and the command line → [`config::Config`].
//! - [`events`]: the JSON event stream.
//! - [`settle`]: when to compile (quiet period, cap, one at a time, one follow-up).
//! - `watch`: directory watches (inotify, or polling where there is no change notification).
//! - this module: the event loop. [`run`] takes its control channel as a parameter (stop and
//!   reload), so tests drive it without signals; the command line connects the signals.
//!
//! # Invariants
//!
//! - Compiles run off the event loop (`spawn_blocking`), at most one per project, at most
//!   [`Daemon::parallel`] at once; projects never wait for each other's events.
//! - A change starts a compile only if an input's bytes changed: every input's content hash is
//!   kept from the last compile (our own write-back updates it), so reads, `touch`, saves of the
//!   same bytes and our own writes start nothing.
//! - The watched directories are exactly: each project folder and its parent (to see the folder
//!   deleted and created again), the folders of every file the last compile read, and each root
//!   and its direct subfolders.

pub mod config;
pub mod events;
mod poll;
pub mod settle;
mod watch;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use serde_json::json;
use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::compile::{self, Compilation, Options};
use crate::diag::{Code, Severity};
use crate::load::{FileSource, FsSource};
use config::{Config, ProjectSpec};
use events::{EventSink, Level};
use settle::Scheduler;
use watch::{Backend, WatchFailure, WatchMsg, Watchers};

/// What the command line (signals) or a test tells the daemon.
#[derive(Debug)]
pub enum Control {
    /// Read the configuration again (`SIGHUP`).
    Reload,
    /// Finish running compiles and stop (`SIGTERM`, `SIGINT`); the reason goes into `stopped`.
    Stop(String),
}

/// What [`run`] needs besides the configuration: how to read it again on reload.
#[derive(Debug, Clone, Default)]
pub struct Sources {
    pub config_file: Option<PathBuf>,
    pub dirs: Vec<PathBuf>,
    pub events: Option<PathBuf>,
    pub settle_ms: Option<u64>,
}

impl Sources {
    /// Reads the configuration file (if any) and merges the command line over it.
    pub fn load(&self) -> Result<Config, config::ConfigError> {
        let file = match &self.config_file {
            Some(f) => Some(config::load(f)?),
            None => None,
        };
        let mut c = config::merge(file, &self.dirs, self.events.clone(), self.settle_ms);
        c.file = self.config_file.clone();
        Ok(c)
    }
}

/// The default quiet period.
pub const DEFAULT_SETTLE_MS: u64 = 100;
/// Retries of a compile that failed on a file caught half-written.
const MAX_RETRIES: u32 = 3;
/// How often missing project folders are looked for again.
const MISSING_RETRY: Duration = Duration::from_secs(2);

/// Runs the daemon until a [`Control::Stop`]. Emits `started` first and `stopped` last.
pub async fn run(
    config: Config,
    sources: Sources,
    sink: Arc<EventSink>,
    mut control: mpsc::UnboundedReceiver<Control>,
) -> Result<(), String> {
    let (wtx, mut wrx) = mpsc::unbounded_channel();
    let (dtx, mut drx) = mpsc::unbounded_channel();
    let force_poll = std::env::var_os("SKILLPOST_FORCE_POLL").is_some();
    let mut d = Daemon {
        sink: sink.clone(),
        watchers: Watchers::new(wtx, Duration::from_secs(1)),
        projects: BTreeMap::new(),
        by_dir: HashMap::new(),
        roots: BTreeMap::new(),
        done: dtx,
        run_seq: 0,
        running: 0,
        // Compiles of small projects mostly wait for fsync: twice the cores, at least 4.
        parallel: (2 * std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(2))
        .max(4),
        queue: Vec::new(),
        config: Config::default(),
        sources,
        force_poll,
        ready: false,
    };
    sink.emit(
        "started",
        Level::Info,
        None,
        json!({
            "version": crate::VERSION,
            "pid": std::process::id(),
            "config": config.file.as_ref().map(|p| p.display().to_string()),
        }),
    );
    d.apply_config(config, Instant::now());
    tracing::info!(
        projects = d.projects.len(),
        roots = d.roots.len(),
        "skillpost {} watching",
        crate::VERSION
    );
    d.sink.emit(
        "rescan",
        Level::Info,
        None,
        json!({"reason": "startup", "projects": d.projects.len()}),
    );
    let now = Instant::now();
    for p in d.projects.values_mut() {
        p.sched.immediately(now);
    }
    if d.projects.is_empty() {
        d.ready = true;
        let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
    }
    d.notify_status();

    let watchdog = sd_notify_watchdog();
    let mut watchdog_tick = tokio::time::interval(watchdog.unwrap_or(Duration::from_secs(3600)));
    let mut missing_tick = tokio::time::interval(MISSING_RETRY);
    let stop_reason;
    loop {
        d.start_due(Instant::now());
        let next = d.next_deadline();
        let sleep = async {
            match next {
                Some(t) => tokio::time::sleep_until(t).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            Some(msg) = wrx.recv() => {
                // Take every waiting event at once: one pass of the loop per batch.
                let now = Instant::now();
                d.on_watch(msg, now);
                while let Ok(msg) = wrx.try_recv() {
                    d.on_watch(msg, now);
                }
            }
            Some(r) = drx.recv() => d.on_done(r, Instant::now()),
            c = control.recv() => match c {
                Some(Control::Reload) => d.reload(Instant::now()),
                Some(Control::Stop(why)) => { stop_reason = why; break; }
                None => { stop_reason = "control channel closed".to_owned(); break; }
            },
            _ = sleep => {}
            _ = watchdog_tick.tick(), if watchdog.is_some() => {
                let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
            }
            _ = missing_tick.tick() => d.look_for_missing(Instant::now()),
        }
    }
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
    // Finish the running compiles; start no new ones.
    d.queue.clear();
    while d.running > 0 {
        match drx.recv().await {
            Some(r) => {
                d.running -= 1;
                d.finish_report(r, Instant::now());
            }
            None => break,
        }
    }
    tracing::info!(reason = %stop_reason, "stopped");
    sink.emit("stopped", Level::Info, None, json!({"reason": stop_reason}));
    Ok(())
}

/// Half the watchdog interval systemd asks for (`WATCHDOG_USEC`), if it asks.
fn sd_notify_watchdog() -> Option<Duration> {
    sd_notify::watchdog_enabled()
        .filter(|d| !d.is_zero())
        .map(|d| d / 2)
}

/// Where a project came from.
#[derive(Debug, Clone, PartialEq)]
enum Origin {
    Explicit,
    Root(PathBuf),
}

struct Project {
    spec: ProjectSpec,
    origin: Origin,
    /// Every file the last compile read, with the hash of the bytes it read (`None`: unreadable).
    inputs: HashMap<PathBuf, Option<u64>>,
    /// The outputs of the last compile (never inputs).
    outputs: BTreeSet<PathBuf>,
    /// The directories watched for this project.
    watched: BTreeSet<PathBuf>,
    /// The directories whose events can concern this project (its folder and its inputs'
    /// folders): its entries in [`Daemon::by_dir`].
    indexed: BTreeSet<PathBuf>,
    backend: Backend,
    sched: Scheduler,
    /// Paths changed since the last compile started.
    changed: BTreeSet<PathBuf>,
    /// Files being written (modified, not yet closed), with when that was first seen.
    writing: HashMap<PathBuf, Instant>,
    /// Why the next compile runs: the first reason of the burst counts.
    trigger: Option<&'static str>,
    retries: u32,
    missing: bool,
    /// Compile without the hash check (startup, rescan of a new project, retry).
    force: bool,
}

/// A finished compile, sent back to the event loop.
struct Report {
    key: PathBuf,
    outcome: Outcome,
}

enum Outcome {
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

struct Daemon {
    sink: Arc<EventSink>,
    watchers: Watchers,
    projects: BTreeMap<PathBuf, Project>,
    /// Directory → the projects an event in it can concern, so an event never scans them all.
    by_dir: HashMap<PathBuf, BTreeSet<PathBuf>>,
    /// Roots and the subfolders watched in them.
    roots: BTreeMap<PathBuf, BTreeSet<PathBuf>>,
    done: mpsc::UnboundedSender<Report>,
    run_seq: u64,
    running: usize,
    /// At most this many compiles at once.
    parallel: usize,
    /// Projects whose compile is due but waits for a free slot.
    queue: Vec<PathBuf>,
    config: Config,
    sources: Sources,
    force_poll: bool,
    ready: bool,
}

fn settle_of(c: &Config) -> Duration {
    Duration::from_millis(c.settle_ms.unwrap_or(DEFAULT_SETTLE_MS).clamp(1, 60_000))
}

/// The cap on how long a stream of changes can delay a compile.
fn max_wait_of(settle: Duration) -> Duration {
    (settle * 10).max(Duration::from_secs(1))
}

fn hash_bytes(b: &[u8]) -> u64 {
    let mut h = std::hash::DefaultHasher::new();
    b.hash(&mut h);
    h.finish()
}

fn hash_file(p: &Path) -> Option<u64> {
    std::fs::read(p).ok().map(|b| hash_bytes(&b))
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

impl Daemon {
    fn key_str(key: &Path) -> String {
        key.display().to_string()
    }

    /// Takes a (new) configuration: adds the projects it names, drops those it no longer does.
    fn apply_config(&mut self, config: Config, now: Instant) -> (Vec<PathBuf>, Vec<PathBuf>) {
        let settle = settle_of(&config);
        let mut wanted: BTreeMap<PathBuf, (ProjectSpec, Origin)> = BTreeMap::new();
        for p in &config.projects {
            wanted.insert(p.path.clone(), (p.clone(), Origin::Explicit));
        }
        for root in &config.roots {
            for dir in config::discover(root) {
                wanted.entry(dir.clone()).or_insert((
                    ProjectSpec {
                        path: dir,
                        blackboard: None,
                        program: None,
                    },
                    Origin::Root(root.clone()),
                ));
            }
        }
        let removed: Vec<PathBuf> = self
            .projects
            .keys()
            .filter(|k| !wanted.contains_key(*k))
            .cloned()
            .collect();
        for k in &removed {
            self.drop_project(k);
        }
        // Roots: watch each and its subfolders (a blackboard may appear in any of them).
        let old_roots: Vec<PathBuf> = self.roots.keys().cloned().collect();
        for r in old_roots {
            if !config.roots.contains(&r) {
                self.unwatch_root(&r);
            }
        }
        for r in &config.roots {
            if !self.roots.contains_key(r) {
                self.watch_root(r);
            }
        }
        let mut added = Vec::new();
        for (k, (spec, origin)) in wanted {
            match self.projects.get_mut(&k) {
                Some(p) => {
                    if p.spec != spec {
                        p.spec = spec;
                        p.force = true;
                        p.sched.immediately(now);
                    }
                    p.sched.set_timing(settle, max_wait_of(settle));
                }
                None => {
                    self.add_project(spec, origin, settle);
                    added.push(k);
                }
            }
        }
        self.config = config;
        (added, removed)
    }

    fn watch_root(&mut self, root: &Path) {
        let mut subs = BTreeSet::new();
        match self.watchers.add(root, self.force_poll) {
            Ok(_) => {
                for e in std::fs::read_dir(root).into_iter().flatten().flatten() {
                    let p = e.path();
                    if p.is_dir() && self.watchers.add(&p, self.force_poll).is_ok() {
                        subs.insert(p);
                    }
                }
            }
            Err(e) => self.sink.emit(
                "watch-degraded",
                Level::Warn,
                None,
                json!({"root": root.display().to_string(), "reason": failure_text(&e)}),
            ),
        }
        self.roots.insert(root.to_owned(), subs);
    }

    fn unwatch_root(&mut self, root: &Path) {
        if let Some(subs) = self.roots.remove(root) {
            for s in subs {
                self.watchers.remove(&s);
            }
            self.watchers.remove(root);
        }
    }

    fn add_project(&mut self, spec: ProjectSpec, origin: Origin, settle: Duration) {
        let key = spec.path.clone();
        remove_stale_temporaries(&key);
        let mut p = Project {
            spec,
            origin,
            inputs: HashMap::new(),
            outputs: BTreeSet::new(),
            watched: BTreeSet::new(),
            indexed: BTreeSet::new(),
            backend: Backend::Native,
            sched: Scheduler::new(settle, max_wait_of(settle)),
            changed: BTreeSet::new(),
            writing: HashMap::new(),
            trigger: Some("startup"),
            retries: 0,
            missing: false,
            force: true,
        };
        let mut dirs = BTreeSet::new();
        dirs.insert(key.clone());
        if let Some(parent) = key.parent() {
            dirs.insert(parent.to_owned());
        }
        self.set_watches(&mut p, dirs);
        let blackboard = config::resolve(&p.spec).ok().map(|(b, _)| b);
        self.sink.emit(
            "watching",
            Level::Info,
            Some(&Self::key_str(&key)),
            json!({
                "root": match &p.origin { Origin::Root(r) => Some(r.display().to_string()), Origin::Explicit => None },
                "blackboard": blackboard.map(|b| b.display().to_string()),
                "backend": p.backend.as_str(),
            }),
        );
        self.reindex(&mut p);
        self.projects.insert(key, p);
    }

    fn drop_project(&mut self, key: &Path) {
        if let Some(p) = self.projects.remove(key) {
            for d in &p.watched {
                self.watchers.remove(d);
            }
            for d in &p.indexed {
                if let Some(set) = self.by_dir.get_mut(d) {
                    set.remove(key);
                    if set.is_empty() {
                        self.by_dir.remove(d);
                    }
                }
            }
            self.queue.retain(|k| k != key);
        }
    }

    /// Changes a project's watched directories to `dirs` (adding before removing, so a shared
    /// directory is never unwatched in between).
    fn set_watches(&mut self, p: &mut Project, dirs: BTreeSet<PathBuf>) {
        let key = p.spec.path.clone();
        let poll = self.force_poll;
        for d in dirs.difference(&p.watched.clone()) {
            match self.watchers.add(d, poll) {
                Ok((backend, why)) => {
                    p.watched.insert(d.clone());
                    if d == &key {
                        p.missing = false;
                        if backend != p.backend || why.is_some() {
                            p.backend = backend;
                            if let Some(why) = why {
                                self.sink.emit(
                                    "watch-degraded",
                                    Level::Warn,
                                    Some(&Self::key_str(&key)),
                                    json!({"reason": why, "backend": backend.as_str()}),
                                );
                            }
                        }
                    }
                }
                Err(WatchFailure::Missing) if d == &key => {
                    if !p.missing {
                        p.missing = true;
                        self.sink.emit(
                            "watch-degraded",
                            Level::Warn,
                            Some(&Self::key_str(&key)),
                            json!({"reason": "the project folder does not exist; waiting for it", "backend": "none"}),
                        );
                    }
                }
                Err(WatchFailure::Missing) => {}
                Err(WatchFailure::Other(e)) => {
                    tracing::warn!("cannot watch {}: {e}", d.display());
                }
            }
        }
        for d in p.watched.clone().difference(&dirs) {
            self.watchers.remove(d);
            p.watched.remove(d);
        }
    }

    /// Updates [`Daemon::by_dir`] for a project: its folder and the folders of its inputs.
    fn reindex(&mut self, p: &mut Project) {
        let key = p.spec.path.clone();
        let mut dirs: BTreeSet<PathBuf> = p
            .inputs
            .keys()
            .filter_map(|f| f.parent().map(Path::to_owned))
            .collect();
        dirs.insert(key.clone());
        for d in p.indexed.difference(&dirs) {
            if let Some(set) = self.by_dir.get_mut(d) {
                set.remove(&key);
                if set.is_empty() {
                    self.by_dir.remove(d);
                }
            }
        }
        for d in dirs.difference(&p.indexed) {
            self.by_dir
                .entry(d.clone())
                .or_default()
                .insert(key.clone());
        }
        p.indexed = dirs;
    }

    fn next_deadline(&self) -> Option<Instant> {
        self.projects
            .values()
            .filter_map(|p| p.sched.deadline())
            .min()
    }

    /// Starts every compile whose quiet period is over, as far as the parallel limit allows.
    fn start_due(&mut self, now: Instant) {
        let due: Vec<PathBuf> = self
            .projects
            .iter()
            .filter(|(_, p)| p.sched.deadline().is_some_and(|d| d <= now))
            .map(|(k, _)| k.clone())
            .collect();
        for k in due {
            let Some(p) = self.projects.get_mut(&k) else {
                continue;
            };
            // A file still open for writing: wait (bounded by the cap of the burst).
            let cap = max_wait_of(settle_of(&self.config));
            p.writing
                .retain(|_, since| now.duration_since(*since) < cap * 5);
            if !p.writing.is_empty() {
                p.sched.postpone(now);
                continue;
            }
            if p.sched.fire(now) {
                if p.missing {
                    // Its folder is gone (reported): nothing to compile until it is back.
                    p.sched.finished(now);
                    p.changed.clear();
                    p.trigger = None;
                    continue;
                }
                self.queue.push(k);
            }
        }
        while self.running < self.parallel && !self.queue.is_empty() {
            let k = self.queue.remove(0);
            self.spawn_compile(&k);
        }
    }

    fn spawn_compile(&mut self, key: &Path) {
        let Some(p) = self.projects.get_mut(key) else {
            return;
        };
        self.run_seq += 1;
        let run_id = self.run_seq;
        let changed: Vec<PathBuf> = std::mem::take(&mut p.changed).into_iter().collect();
        let job = Job {
            key: key.to_owned(),
            spec: p.spec.clone(),
            known: if p.force {
                None
            } else {
                Some(p.inputs.clone())
            },
            changed,
            trigger: p.trigger.take().unwrap_or("change"),
            may_retry: p.retries < MAX_RETRIES,
            confine: !self.config.allow_outside,
            max_file_size: self
                .config
                .max_file_size_mb
                .map_or(crate::load::DEFAULT_MAX_FILE_SIZE, |mb| mb * 1024 * 1024),
            run_id,
            sink: self.sink.clone(),
        };
        p.force = false;
        self.running += 1;
        let done = self.done.clone();
        tokio::task::spawn_blocking(move || {
            let key = job.key.clone();
            let sink = job.sink.clone();
            // A panic is a bug, never input: report it and keep serving the other projects.
            let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| job.run()))
                .unwrap_or_else(|_| {
                    emit_failed(&sink, &key, run_id, 0, json!([{"severity": "error", "code": "E000", "message": "internal error (a bug in skillpost): the compile panicked; see the log"}]));
                    Outcome::Failed
                });
            let _ = done.send(Report { key, outcome });
        });
    }

    fn on_done(&mut self, r: Report, now: Instant) {
        self.running = self.running.saturating_sub(1);
        self.finish_report(r, now);
        if !self.ready && self.running == 0 && self.queue.is_empty() {
            self.ready = true;
            let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
        }
        self.notify_status();
    }

    fn finish_report(&mut self, r: Report, now: Instant) {
        let Some(mut p) = self.projects.remove(&r.key) else {
            return;
        };
        match r.outcome {
            Outcome::Unchanged | Outcome::Failed => {
                p.retries = 0;
                p.sched.finished(now);
            }
            Outcome::Retry => {
                p.retries += 1;
                p.force = true;
                p.sched.finished(now);
                p.sched.postpone(now);
            }
            Outcome::Compiled {
                inputs,
                outputs,
                again,
            } => {
                p.retries = 0;
                let mut dirs: BTreeSet<PathBuf> = inputs
                    .keys()
                    .filter_map(|f| f.parent().map(Path::to_owned))
                    .collect();
                dirs.insert(p.spec.path.clone());
                if let Some(parent) = p.spec.path.parent() {
                    dirs.insert(parent.to_owned());
                }
                p.inputs = inputs;
                p.outputs = outputs.into_iter().collect();
                self.set_watches(&mut p, dirs);
                self.reindex(&mut p);
                let follow_up = p.sched.finished(now);
                if again && !follow_up {
                    p.trigger.get_or_insert("write-back-skipped");
                    p.force = true;
                    p.sched.change(now);
                }
            }
        }
        self.projects.insert(r.key, p);
    }

    fn notify_status(&self) {
        let status = format!(
            "watching {} project(s), {} director{} ; {} compile(s) running",
            self.projects.len(),
            self.watchers.len(),
            if self.watchers.len() == 1 { "y" } else { "ies" },
            self.running
        );
        let _ = sd_notify::notify(&[sd_notify::NotifyState::Status(&status)]);
    }

    fn on_watch(&mut self, msg: WatchMsg, now: Instant) {
        match msg {
            WatchMsg::Error(e) => {
                tracing::warn!("watcher error: {e}");
                self.rescan("watcher-error", Some(e.to_string()), now);
            }
            WatchMsg::Event(e) => {
                if e.need_rescan() {
                    self.rescan("overflow", None, now);
                    return;
                }
                self.route(&e, now);
            }
        }
    }

    /// Every project checks its inputs again (a compile only where bytes changed).
    fn rescan(&mut self, reason: &str, error: Option<String>, now: Instant) {
        self.sink.emit(
            "rescan",
            Level::Warn,
            None,
            json!({"reason": reason, "error": error}),
        );
        for p in self.projects.values_mut() {
            p.trigger.get_or_insert("rescan");
            p.sched.change(now);
        }
    }

    fn route(&mut self, e: &notify::Event, now: Instant) {
        use notify::EventKind as K;
        use notify::event::{AccessKind, AccessMode, MetadataKind, ModifyKind};
        let kind = e.kind;
        // Reads and metadata-only changes (`touch`, chmod) never change bytes.
        let closed_write = matches!(kind, K::Access(AccessKind::Close(AccessMode::Write)));
        if matches!(kind, K::Access(_)) && !closed_write {
            return;
        }
        // Polling reports a new write time (the content hash then tells a `touch` from an edit);
        // other metadata (attributes, permissions; inotify's `touch`) never change bytes.
        if matches!(kind, K::Modify(ModifyKind::Metadata(m)) if m != MetadataKind::WriteTime) {
            return;
        }
        let data_write = matches!(
            kind,
            K::Modify(ModifyKind::Data(_)) | K::Modify(ModifyKind::Any)
        );
        // Only these say that a project folder itself came or went.
        let structural = matches!(
            kind,
            K::Create(_) | K::Remove(_) | K::Modify(ModifyKind::Name(_)) | K::Any | K::Other
        );
        for path in &e.paths {
            if watch::is_noise(path) {
                continue;
            }
            self.route_roots(path, now);
            if structural && self.projects.contains_key(path) {
                self.folder_event(path, now);
            }
            let Some(keys) = path.parent().and_then(|d| self.by_dir.get(d)) else {
                continue;
            };
            let keys: Vec<PathBuf> = keys.iter().cloned().collect();
            for k in keys {
                let Some(p) = self.projects.get_mut(&k) else {
                    continue;
                };
                if p.outputs.contains(path) {
                    continue;
                }
                let is_input = p.inputs.contains_key(path);
                let new_blackboard = path.parent() == Some(k.as_path())
                    && path.file_name().is_some_and(config::is_blackboard_name);
                if !(is_input || new_blackboard) {
                    continue;
                }
                // Polling reports no closes: only native watches track open writes.
                if data_write && p.backend == Backend::Native {
                    p.writing.entry(path.clone()).or_insert(now);
                } else {
                    // Closed, created, removed or renamed: the write is complete.
                    p.writing.remove(path);
                }
                p.changed.insert(path.clone());
                p.trigger.get_or_insert("change");
                p.sched.change(now);
            }
        }
    }

    /// An event inside a root: a new subfolder, or a blackboard appearing in one.
    fn route_roots(&mut self, path: &Path, now: Instant) {
        let Some(parent) = path.parent() else { return };
        let roots: Vec<PathBuf> = self.roots.keys().cloned().collect();
        for root in roots {
            let folder = if parent == root {
                path.to_owned()
            } else if parent.parent() == Some(root.as_path()) {
                parent.to_owned()
            } else {
                continue;
            };
            if folder.is_dir() && !self.roots[&root].contains(&folder) {
                if self.watchers.add(&folder, self.force_poll).is_ok() {
                    self.roots
                        .get_mut(&root)
                        .expect("root")
                        .insert(folder.clone());
                }
            } else if !folder.exists() && self.roots.get_mut(&root).expect("root").remove(&folder) {
                self.watchers.remove(&folder);
            }
            if !self.projects.contains_key(&folder) && holds_blackboard(&folder) {
                let settle = settle_of(&self.config);
                self.add_project(
                    ProjectSpec {
                        path: folder.clone(),
                        blackboard: None,
                        program: None,
                    },
                    Origin::Root(root.clone()),
                    settle,
                );
                if let Some(p) = self.projects.get_mut(&folder) {
                    p.trigger = Some("new-project");
                    p.sched.change(now);
                }
            }
        }
    }

    /// The project folder itself was created, removed or renamed.
    fn folder_event(&mut self, key: &Path, now: Instant) {
        let Some(mut p) = self.projects.remove(key) else {
            return;
        };
        if key.is_dir() {
            let was_missing = p.missing;
            match self.watchers.renew(key, self.force_poll) {
                Ok(b) => {
                    p.missing = false;
                    p.backend = b;
                    p.watched.insert(key.to_owned());
                }
                Err(_) => p.missing = true,
            }
            if was_missing && !p.missing {
                self.sink.emit(
                    "watching",
                    Level::Info,
                    Some(&Self::key_str(key)),
                    json!({"backend": p.backend.as_str(), "reason": "the project folder is back"}),
                );
            }
            p.trigger.get_or_insert("folder-created");
            p.force = true;
            p.sched.change(now);
        } else if !p.missing {
            p.missing = true;
            self.sink.emit(
                "watch-degraded",
                Level::Warn,
                Some(&Self::key_str(key)),
                json!({"reason": "the project folder was removed; waiting for it", "backend": "none"}),
            );
        }
        self.projects.insert(key.to_owned(), p);
    }

    /// Missing project folders that appeared without an event we saw (their parent was missing
    /// too): watch and compile them.
    fn look_for_missing(&mut self, now: Instant) {
        let missing: Vec<PathBuf> = self
            .projects
            .iter()
            .filter(|(k, p)| p.missing && k.is_dir())
            .map(|(k, _)| k.clone())
            .collect();
        for k in missing {
            let Some(mut p) = self.projects.remove(&k) else {
                continue;
            };
            let mut dirs = p.watched.clone();
            dirs.insert(k.clone());
            if let Some(parent) = k.parent() {
                dirs.insert(parent.to_owned());
            }
            p.watched.remove(&k);
            self.set_watches(&mut p, dirs);
            if !p.missing {
                self.sink.emit(
                    "watching",
                    Level::Info,
                    Some(&Self::key_str(&k)),
                    json!({"backend": p.backend.as_str(), "reason": "the project folder is back"}),
                );
                p.trigger = Some("folder-created");
                p.force = true;
                p.sched.change(now);
            }
            self.projects.insert(k, p);
        }
    }

    fn reload(&mut self, now: Instant) {
        match self.sources.load() {
            Ok(c) => {
                let (added, removed) = self.apply_config(c, now);
                for k in &added {
                    if let Some(p) = self.projects.get_mut(k) {
                        p.sched.immediately(now);
                    }
                }
                self.sink.emit(
                    "reloaded",
                    Level::Info,
                    None,
                    json!({
                        "projects": self.projects.len(),
                        "added": added.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
                        "removed": removed.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
                    }),
                );
            }
            Err(e) => self.sink.emit(
                "reload-failed",
                Level::Error,
                None,
                json!({
                    "error": e.message,
                    "file": e.file.as_ref().map(|f| f.display().to_string()),
                    "line": e.line,
                    "column": e.column,
                }),
            ),
        }
        self.notify_status();
    }
}

/// Removes the temporary files an interrupted run of ours left in a project folder (a crash or
/// `kill -9` between writing and renaming). Only `.skillpost-*.tmp` files are touched; they are
/// never anything but ours, and the daemon writes none while it sets a project up.
fn remove_stale_temporaries(folder: &Path) {
    for e in std::fs::read_dir(folder).into_iter().flatten().flatten() {
        let name = e.file_name();
        let Some(name) = name.to_str() else { continue };
        if name.starts_with(".skillpost-")
            && name.ends_with(".tmp")
            && e.file_type().is_ok_and(|t| t.is_file())
        {
            match std::fs::remove_file(e.path()) {
                Ok(()) => tracing::info!("removed a stale temporary file {}", e.path().display()),
                Err(err) => tracing::warn!("cannot remove {}: {err}", e.path().display()),
            }
        }
    }
}

/// Whether a folder holds a blackboard (what makes a root's subfolder a project).
fn holds_blackboard(folder: &Path) -> bool {
    std::fs::read_dir(folder)
        .into_iter()
        .flatten()
        .flatten()
        .any(|e| config::is_blackboard_name(&e.file_name()) && e.path().is_file())
}

fn failure_text(e: &WatchFailure) -> String {
    match e {
        WatchFailure::Missing => "missing".to_owned(),
        WatchFailure::Other(s) => s.clone(),
    }
}

/// The `compile-failed` event.
fn emit_failed(
    sink: &EventSink,
    key: &Path,
    run_id: u64,
    duration_ms: u64,
    diagnostics: serde_json::Value,
) {
    sink.emit(
        "compile-failed",
        Level::Error,
        Some(&key.display().to_string()),
        json!({"run_id": run_id, "duration_ms": duration_ms, "diagnostics": diagnostics}),
    );
}

/// One compile, run on a blocking thread.
struct Job {
    key: PathBuf,
    spec: ProjectSpec,
    /// The input hashes of the last compile; `None` compiles without checking.
    known: Option<HashMap<PathBuf, Option<u64>>>,
    changed: Vec<PathBuf>,
    trigger: &'static str,
    may_retry: bool,
    confine: bool,
    max_file_size: u64,
    run_id: u64,
    sink: Arc<EventSink>,
}

impl Job {
    fn project(&self) -> String {
        self.key.display().to_string()
    }

    /// Emits `compile-failed` with these diagnostics (JSON objects as `--format json` prints).
    fn failed(&self, duration_ms: u64, diagnostics: serde_json::Value) {
        emit_failed(&self.sink, &self.key, self.run_id, duration_ms, diagnostics);
    }

    fn run(self) -> Outcome {
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
                "change-detected",
                Level::Info,
                Some(&project),
                json!({"paths": differ.iter().map(|p| p.display().to_string()).collect::<Vec<_>>()}),
            );
        }
        let (blackboard, program) = match config::resolve(&self.spec) {
            Ok(x) => x,
            Err(why) => {
                self.failed(0, json!([{"severity": "error", "code": Code::FileUnreadable.as_str(), "message": why, "file": project}]));
                return Outcome::Failed;
            }
        };
        self.sink.emit(
            "compile-started",
            Level::Info,
            Some(&project),
            json!({"run_id": self.run_id, "trigger": self.trigger, "changed": self.changed.iter().map(|p| p.display().to_string()).collect::<Vec<_>>()}),
        );
        let started = std::time::Instant::now();
        let fs = Hashing {
            fs: FsSource {
                max_file_size: self.max_file_size,
            },
            seen: Default::default(),
        };
        let opts = Options {
            program,
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
            let diags: Vec<_> = c.diagnostics.iter().map(|d| d.locate(&c.sources)).collect();
            self.failed(ms(), json!(diags));
            return Outcome::Compiled {
                inputs,
                outputs: Vec::new(),
                again: false,
            };
        }
        let applied = match compile::apply(&c) {
            Ok(a) => a,
            Err(e) => {
                self.failed(ms(), json!([{"severity": "error", "code": Code::CannotWrite.as_str(), "message": format!("cannot write: {e}")}]));
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
            .map(|d| d.locate(&c.sources))
            .collect();
        self.sink.emit(
            "compile-succeeded",
            Level::Info,
            Some(&project),
            json!({
                "run_id": self.run_id,
                "duration_ms": ms(),
                "outputs": applied.outputs.iter().map(|(p, w)| json!({"path": p.display().to_string(), "written": w})).collect::<Vec<_>>(),
                "counts": {"steps": c.skill_steps, "warnings": warnings.len()},
                "warnings": warnings,
            }),
        );
        let mut again = false;
        if let (Some(wb), Some(outcome)) = (&c.write_back, &applied.write_back) {
            use crate::write::WriteBackOutcome as W;
            let (written, reason) = match outcome {
                W::Written => (true, None),
                W::AlreadyRight => (false, Some("already right")),
                W::SkippedChangedOnDisk => (
                    false,
                    Some("the blackboard changed on disk since it was read; compiling again"),
                ),
            };
            if *outcome == W::Written {
                // Our own write: its bytes are the new known state, so its event starts nothing.
                inputs.insert(wb.blackboard.clone(), hash_file(&wb.blackboard));
            }
            again = *outcome == W::SkippedChangedOnDisk;
            self.sink.emit(
                "write-back",
                if again { Level::Warn } else { Level::Info },
                Some(&project),
                json!({"run_id": self.run_id, "file": wb.blackboard.display().to_string(), "value": wb.value, "written": written, "reason": reason}),
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
fn add_link_targets(inputs: &mut HashMap<PathBuf, Option<u64>>) {
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
fn half_written(c: &Compilation, read: &HashMap<PathBuf, Option<u64>>) -> bool {
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
