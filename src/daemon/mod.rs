//! `skillpost watch`: keeps project folders compiled (docs/DAEMON.md).
//!
//! # Layout
//!
//! - [`config`]: the TOML file and the command line → [`config::Config`].
//! - [`events`]: the JSON event stream.
//! - [`settle`]: when to compile (quiet period, cap, one at a time, one follow-up).
//! - `watch`, `poll`: directory watches (inotify, or polling where there is no change
//!   notification).
//! - `project`: the project table (projects, their watched folders, the directory index).
//! - `route`: file events → the projects they concern; roots; folders that come and go.
//! - `job`: one compile on a blocking thread (hash check, compile, write, its events).
//! - [`state`]: each project's last result → the state file (`skillpost status`) and systemd's
//!   `STATUS=` line; `journal`: failures also logged through `tracing` (the journal).
//! - `stop`: the end: running compiles and the last events waited for, both bounded.
//! - this module: the event loop. [`run`] takes its control channel as a parameter (stop and
//!   reload), so tests drive it without signals; the command line connects the signals.
//!
//! # Invariants
//!
//! - Compiles run off the event loop (`spawn_blocking`), at most one per project, at most
//!   [`parallel_compiles`] at once; projects never wait for each other's events.
//! - A change starts a compile only if an input's bytes changed: every input's content hash is
//!   kept from the last compile (our own write-back updates it), so reads, `touch`, saves of the
//!   same bytes and our own writes start nothing. (An attribute change of the project folder
//!   itself compiles without the check: `route`.)
//! - The watched directories are exactly: each project folder and its parent (to see the folder
//!   deleted and created again), the folders of every file the last compile read, and each root
//!   and its direct subfolders.

pub mod check;
pub mod config;
pub mod deploy;
pub mod events;
mod job;
pub mod journal;
pub mod lock;
mod poll;
mod project;
mod route;
pub mod settle;
mod simulation;
pub mod snapshot;
pub mod state;
mod stop;
mod watch;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::time::Instant;

use config::Config;
use events::{Event, EventSink};
use job::{Job, Outcome, Report};
use project::Project;
pub use stop::STOP_TIMEOUT;
use watch::Watchers;

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
    /// Blackboards named on the command line: each one's folder is a project, with it.
    pub blackboards: Vec<PathBuf>,
    pub events: Option<PathBuf>,
    pub settle_ms: Option<u64>,
    /// Where the lock notes go instead of [`lock::runtime_dir`] (tests keep them in their own
    /// folders).
    pub runtime_dir: Option<PathBuf>,
    /// The daemon is the process (`skillpost watch`), not a test running it: it becomes the
    /// subreaper of its hooks' processes ([`deploy::Pool::new`]).
    pub own_process: bool,
}

impl Sources {
    /// Reads the configuration file (if any) and merges the command line over it; refused when
    /// a hook's program lies in a project folder or root.
    pub fn load(&self) -> Result<Config, config::ConfigError> {
        let c = self.read()?;
        if let Some(why) = config::hook_programs(&c)
            .into_iter()
            .find_map(|p| config::hook_program_problem(&c, p))
        {
            return Err(config::ConfigError::plain(why, c.file.clone()));
        }
        Ok(c)
    }

    /// [`Sources::load`] without the check of the hooks' programs (`--check-config` shows it as
    /// a row of its own).
    pub fn read(&self) -> Result<Config, config::ConfigError> {
        let file = match &self.config_file {
            Some(f) => Some(config::load(f)?),
            None => None,
        };
        let file_name = file.as_ref().and_then(|f| f.file.clone());
        let mut c = config::merge(file, &self.dirs, self.events.clone(), self.settle_ms);
        for b in &self.blackboards {
            config::add_blackboard(&mut c, b);
        }
        // Absolute (as `started.config` reports it), whatever the command line said.
        c.file = file_name;
        // A folder of the command line may hold the configuration file too.
        if let Some(why) = config::hook_from_a_planners_folder(&c) {
            return Err(config::ConfigError::plain(why, c.file.clone()));
        }
        Ok(c)
    }
}

/// The default quiet period.
pub const DEFAULT_SETTLE_MS: u64 = 100;
/// Retries of a compile that failed on a file caught half-written.
const MAX_RETRIES: u32 = 3;
/// Retries of a compile that ran short of descriptors or memory, 1 s after the first, each
/// twice as long after the one before (about a minute in all).
const MAX_STARVED_RETRIES: u32 = 6;
/// Compiles again after a write-back skipped because the blackboard was open elsewhere.
const MAX_IN_USE_ROUNDS: u32 = 5;
/// How often missing project folders are looked for again.
const MISSING_RETRY: Duration = Duration::from_secs(2);

/// How many compiles run at once: as many as the machine has cores, at least 2 (docs/DAEMON.md).
/// Not more: each compile holds its inputs' trees in memory, so memory stays bounded by this
/// many times the largest compile.
pub fn parallel_compiles() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(2)
        .max(2)
}

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
    let sources_own_process = sources.own_process;
    // One daemon per folder: a second one on any of these folders stops here (exit status 2).
    lock::raise_open_file_limit();
    let runtime = sources
        .runtime_dir
        .clone()
        .unwrap_or_else(lock::runtime_dir);
    let hooks = config.max_deploys();
    let mut locks =
        lock::Locks::new(runtime.clone()).reserving(hooks as u64 * deploy::FDS_PER_HOOK);
    for folder in config.projects.iter().map(|p| p.path.clone()).chain(
        config
            .roots
            .iter()
            .flat_map(|r| std::iter::once(r.path.clone()).chain(config::discover(&r.path))),
    ) {
        // Beyond the open-file limit a folder is refused on its own (`watch-degraded`), and
        // the daemon serves the others.
        if let Err(e) = locks.acquire(&folder)
            && !locks.at_limit()
        {
            return Err(e);
        }
    }
    let mut d = Daemon {
        sink: sink.clone(),
        watchers: Watchers::new(wtx, Duration::from_secs(1)),
        projects: BTreeMap::new(),
        by_dir: HashMap::new(),
        roots: BTreeMap::new(),
        locks,
        done: dtx,
        run_ids: HashMap::new(),
        running: 0,
        parallel: parallel_compiles(),
        queue: Vec::new(),
        config: Config::default(),
        sources,
        force_poll,
        ready: false,
        deploys: HashMap::new(),
        deploy_stop: tokio::sync::watch::channel(false).0,
        runtime,
        deploy_pool: Arc::new(deploy::Pool::new(hooks, sources_own_process)),
    };
    sink.emit(
        None,
        Event::Started {
            version: crate::VERSION,
            pid: std::process::id(),
            config: config.file.as_ref().map(|p| p.display().to_string()),
        },
    );
    d.apply_config(config, Instant::now());
    tracing::info!(
        projects = d.projects.len(),
        roots = d.roots.len(),
        "skillpost {} watching",
        crate::VERSION
    );
    d.sink.emit(
        None,
        Event::Rescan {
            reason: "startup".into(),
            projects: Some(d.projects.len()),
            error: None,
        },
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
        d.deploy_when_quiet(Instant::now());
        let next = d.next_deadline(Instant::now());
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
            _ = missing_tick.tick() => {
                d.look_for_missing(Instant::now());
                // The state file catches up with changes its rate limit held back.
                d.notify_status();
            }
        }
    }
    // A write-back waiting for another program to close the blackboard gives up now.
    d.sink.set_stopping();
    d.stop(stop_reason, drx, control).await
}

/// The next `run_id` of a project.
fn next_run_id(run_ids: &mut HashMap<PathBuf, u64>, key: &Path) -> u64 {
    let n = run_ids.entry(key.to_owned()).or_insert(0);
    *n += 1;
    *n
}

/// Half the watchdog interval systemd asks for (`WATCHDOG_USEC`), if it asks.
fn sd_notify_watchdog() -> Option<Duration> {
    sd_notify::watchdog_enabled()
        .filter(|d| !d.is_zero())
        .map(|d| d / 2)
}

struct Daemon {
    sink: Arc<EventSink>,
    watchers: Watchers,
    projects: BTreeMap<PathBuf, Project>,
    /// Directory → the projects an event in it can concern, so an event never scans them all.
    by_dir: HashMap<PathBuf, BTreeSet<PathBuf>>,
    /// Roots and the subfolders watched in them.
    roots: BTreeMap<PathBuf, project::Root>,
    /// The folders this daemon keeps (one daemon per folder).
    locks: lock::Locks,
    done: mpsc::UnboundedSender<Report>,
    /// The last `run_id` of each project: run_ids count a project's runs from 1, consecutively,
    /// across reloads that drop and add it again (a forgotten root project starts again).
    run_ids: HashMap<PathBuf, u64>,
    running: usize,
    /// At most this many compiles at once.
    parallel: usize,
    /// Projects whose compile is due but waits for a free slot.
    queue: Vec<PathBuf>,
    config: Config,
    sources: Sources,
    force_poll: bool,
    ready: bool,
    /// Each project's deploy hooks, run one at a time on a task of their own.
    deploys: HashMap<PathBuf, deploy::Worker>,
    /// Turns true at a stop: running hooks are ended.
    deploy_stop: tokio::sync::watch::Sender<bool>,
    /// The runtime directory (lock notes, the deploy hooks' snapshots).
    runtime: PathBuf,
    /// The cap on hooks at once, of all projects (`max_deploys`), and their processes.
    deploy_pool: Arc<deploy::Pool>,
}

fn settle_of(c: &Config) -> Duration {
    Duration::from_millis(c.settle_ms.unwrap_or(DEFAULT_SETTLE_MS).clamp(1, 60_000))
}

/// The cap on how long a stream of changes can delay a compile.
fn max_wait_of(settle: Duration) -> Duration {
    (settle * 10).max(Duration::from_secs(1))
}

impl Daemon {
    /// Runs `hook` for the compile `run_id` of `key` after the project's running hook, if any
    /// (docs/DAEMON.md, "Deploying").
    fn deploy(
        &mut self,
        key: &Path,
        run_id: u64,
        hook: deploy::Hook,
        programs: Vec<deploy::Context>,
    ) {
        if self.deploys.get(key).is_some_and(|w| w.is_finished()) {
            self.deploys.remove(key);
        }
        let worker = self.deploys.entry(key.to_owned()).or_insert_with(|| {
            deploy::Worker::start(
                self.sink.clone(),
                self.deploy_stop.subscribe(),
                self.deploy_pool.clone(),
            )
        });
        worker.submit(deploy::Request {
            project: key.display().to_string(),
            run_id,
            hook,
            programs,
        });
    }

    fn next_deadline(&self, now: Instant) -> Option<Instant> {
        self.projects
            .values()
            .filter_map(|p| p.sched.deadline())
            .chain(
                self.projects
                    .values()
                    .filter(|p| !p.held.is_empty() && p.last_ok)
                    .filter_map(|p| p.sched.quiet_at(now)),
            )
            .min()
    }

    /// Hands each project's held programs to its hook once its inputs have been quiet for the
    /// whole quiet period since the last change and its last compile succeeded: a compile
    /// that read half of a save (the SFC saved, the blackboard a moment later) is replaced by
    /// the next one before its programs go to a controller. A change during the wait keeps them
    /// waiting for the compile it brings.
    fn deploy_when_quiet(&mut self, now: Instant) {
        let due: Vec<PathBuf> = self
            .projects
            .iter()
            .filter(|(_, p)| {
                !p.held.is_empty() && p.last_ok && p.sched.quiet_at(now).is_some_and(|t| t <= now)
            })
            .map(|(k, _)| k.clone())
            .collect();
        for k in due {
            let Some(p) = self.projects.get_mut(&k) else {
                continue;
            };
            let programs = std::mem::take(&mut p.held);
            let run_id = p.held_run;
            if let Some(hook) = p.spec.on_success.clone() {
                self.deploy(&k, run_id, hook, programs);
            }
        }
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
            // A file still open for writing: wait (bounded by the cap of the burst). A change
            // is not always followed by a close: `truncate(2)` by path changes a file that
            // nobody opened, and a close can be lost with a watch renewed in that instant. So
            // a file that a read lease shows nobody has open for writing is written, whatever
            // the events said; where leases cannot tell, the time bound stays.
            let cap = max_wait_of(settle_of(&self.config));
            p.writing.retain(|path, since| {
                now.duration_since(*since) < cap * 5
                    && crate::write::writeback::lease::open_for_writing(path) != Some(false)
            });
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
                if self.claim_blackboard(&k, now) {
                    self.queue.push(k);
                }
            }
        }
        while self.running < self.parallel && !self.queue.is_empty() {
            let k = self.queue.remove(0);
            self.spawn_compile(&k);
        }
        // Only projects whose folder does not exist yet: nothing to compile, so no compile's
        // end would say READY=1 (systemd would wait for it until its start timeout).
        if !self.ready
            && self.running == 0
            && self.queue.is_empty()
            && self
                .projects
                .values()
                .all(|p| p.missing || p.sched.deadline().is_none())
        {
            self.ready = true;
            let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
            self.notify_status();
        }
    }

    fn spawn_compile(&mut self, key: &Path) {
        let Some(p) = self.projects.get_mut(key) else {
            return;
        };
        let run_id = next_run_id(&mut self.run_ids, key);
        let changed: Vec<PathBuf> = std::mem::take(&mut p.changed).into_iter().collect();
        let trigger = p.trigger.take().unwrap_or("change");
        let progress = Arc::new(job::Progress::default());
        let job = Job {
            key: key.to_owned(),
            spec: p.spec.clone(),
            known: if p.force {
                None
            } else {
                Some(p.inputs.clone())
            },
            changed,
            trigger,
            run: p.sched.run(),
            may_retry: p.retries < MAX_RETRIES,
            attempt: p.retries + p.starved + 1,
            may_retry_starved: p.starved < MAX_STARVED_RETRIES,
            confine: !self.config.allow_outside,
            max_file_size: self
                .config
                .max_file_size_mb
                .map_or(crate::load::DEFAULT_MAX_FILE_SIZE, |mb| mb * 1024 * 1024),
            run_id,
            sink: self.sink.clone(),
            progress: progress.clone(),
            snapshots: p.spec.on_success.is_some().then(|| self.runtime.clone()),
        };
        p.force = false;
        self.running += 1;
        let done = self.done.clone();
        tokio::task::spawn_blocking(move || {
            // The compile's log lines (and the journal's failure line) carry project and run_id.
            let span = tracing::warn_span!("compile", project = %job.key.display(), run_id);
            let _span = span.enter();
            stop::test_hook_sleep("SKILLPOST_TEST_HANG_MS");
            let key = job.key.clone();
            let sink = job.sink.clone();
            // A panic is a bug, never input: report it and keep serving the other projects.
            let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| job.run()))
                .unwrap_or_else(|_| {
                    job::after_panic(&sink, &key, run_id, trigger, &progress);
                    Outcome::Failed
                });
            stop::test_hook_sleep("SKILLPOST_TEST_REPORT_LAG_MS");
            let _ = done.send(Report {
                key,
                run_id,
                outcome,
            });
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
        if matches!(r.outcome, Outcome::Unchanged | Outcome::Deferred { .. })
            && self.run_ids.get(&r.key) == Some(&r.run_id)
        {
            // No event named this run: the next one takes its run_id, so they stay consecutive.
            self.run_ids.insert(r.key.clone(), r.run_id - 1);
        }
        let Some(mut p) = self.projects.remove(&r.key) else {
            return;
        };
        match r.outcome {
            Outcome::Unchanged => {
                p.retries = 0;
                p.starved = 0;
                p.sched.finished(now);
            }
            Outcome::Failed => {
                p.retries = 0;
                p.last_ok = false;
                p.sched.finished(now);
            }
            Outcome::Deferred {
                changed,
                trigger,
                forced,
            } => {
                // The early run said nothing: the next run reports what this one was given.
                p.changed.extend(changed);
                p.trigger = Some(trigger);
                p.force |= forced;
                p.sched.finished(now);
                p.sched.confirm(now);
            }
            Outcome::Retry { starved: true, .. } => {
                p.force = true;
                p.trigger = Some("retry");
                p.sched.finished(now);
                p.sched
                    .retry_after(now, Duration::from_secs(1) * (1 << p.starved.min(6)));
                p.starved += 1;
            }
            Outcome::Retry { counted, .. } => {
                p.force = true;
                p.trigger = Some("retry");
                // The writer is still at it (the file's bytes changed after the read, or changes
                // arrived during the attempt): the next attempt comes after them. Only attempts
                // that nothing followed count towards `MAX_RETRIES` (a file left half-written);
                // counting every attempt made a long burst of saves on a loaded machine end in
                // `compile-failed`.
                if !p.sched.finished(now) && counted {
                    p.retries += 1;
                }
                p.sched.postpone(now);
            }
            Outcome::Compiled {
                inputs,
                outputs,
                again,
                in_use,
                deploy,
                succeeded,
            } => {
                // Held until the inputs have been quiet for the whole period
                // (`deploy_when_quiet`): a newer compile's program replaces the same program's.
                if let (Some(_), Some(ctxs)) = (&p.spec.on_success, deploy) {
                    p.held
                        .retain(|old| !ctxs.iter().any(|c| c.program == old.program));
                    p.held.extend(ctxs);
                    p.held_run = r.run_id;
                }
                p.last_ok = succeeded;
                p.retries = 0;
                p.starved = 0;
                // Another program had the blackboard open (each write-back already waits about
                // 1.3 s for it): a few more rounds, then the next edit tries again.
                p.in_use_rounds = if in_use { p.in_use_rounds + 1 } else { 0 };
                let again = again || (in_use && p.in_use_rounds <= MAX_IN_USE_ROUNDS);
                let mut dirs: BTreeSet<PathBuf> = inputs
                    .keys()
                    .filter_map(|f| f.parent().map(Path::to_owned))
                    .collect();
                dirs.insert(p.spec.path.clone());
                if let Some(parent) = p.spec.path.parent() {
                    dirs.insert(parent.to_owned());
                }
                if p.sweep {
                    p.sweep = false;
                    project::remove_stale_temporaries(&p.spec.path, &inputs);
                }
                p.inputs = inputs;
                p.outputs = outputs.into_iter().collect();
                self.set_watches(&mut p, dirs);
                self.reindex(&mut p);
                let follow_up = p.sched.finished(now);
                if again {
                    // Forced even when a follow-up is already due (our own write-back's events
                    // during the compile schedule one): without the force, that follow-up finds
                    // the inputs' hashes unchanged and compiles nothing, and the write-back is
                    // never tried again.
                    // The reason, whatever events of our own write came meanwhile: this run
                    // skips the hash check, so no `change-detected` precedes it.
                    p.trigger = Some("write-back-skipped");
                    p.force = true;
                    if !follow_up {
                        p.sched.change(now);
                    }
                }
            }
        }
        self.projects.insert(r.key, p);
    }

    /// systemd's status line ("4 projects, 1 failing; ..."), and the state file with it.
    fn notify_status(&self) {
        let status = self.sink.state().sync(
            self.projects.keys().map(PathBuf::as_path),
            self.running,
            self.watchers.len(),
            self.ready,
        );
        let _ = sd_notify::notify(&[sd_notify::NotifyState::Status(&status)]);
    }

    fn reload(&mut self, now: Instant) {
        let loaded = self.sources.load().and_then(|c| {
            // The events file the new configuration names, and the state file.
            let mut own: Vec<PathBuf> = c.events.iter().cloned().collect();
            own.extend(self.sink.state().path().map(Path::to_path_buf));
            match config::own_files_problem(&c, &own) {
                Some(why) => Err(config::ConfigError::plain(why, c.file.clone())),
                None => Ok(c),
            }
        });
        // The events file again (logrotate moved it away), or the one the configuration names now.
        let events = match &loaded {
            Ok(c) => c.events.clone(),
            Err(_) => self.config.events.clone(),
        };
        if let Err(e) = self.sink.reopen(events.as_deref()) {
            tracing::error!("cannot open the event file again (keeping the old one): {e}");
        }
        match loaded {
            Ok(c) => {
                let hooks = c.max_deploys();
                self.deploy_pool.set_cap(hooks);
                self.locks.reserve(hooks as u64 * deploy::FDS_PER_HOOK);
                let (added, removed) = self.apply_config(c, now);
                // New projects, and those whose last compile could not write (E604: an
                // administrator fixed the folder's permissions and reloads), compile now.
                let retry: Vec<PathBuf> = self
                    .projects
                    .keys()
                    .filter(|k| {
                        !added.contains(*k)
                            && self
                                .sink
                                .state()
                                .failed_with(&k.display().to_string(), "E604")
                    })
                    .cloned()
                    .collect();
                for k in &added {
                    if let Some(p) = self.projects.get_mut(k) {
                        p.trigger = Some("reload");
                        p.sched.immediately(now);
                    }
                }
                for k in &retry {
                    if let Some(p) = self.projects.get_mut(k) {
                        // Its inputs are as they were: the compile must not be skipped for it.
                        p.trigger = Some("reload");
                        p.force = true;
                        p.sched.immediately(now);
                    }
                }
                self.sink.emit(
                    None,
                    Event::Reloaded {
                        projects: self.projects.len(),
                        added: added.iter().map(|p| p.display().to_string()).collect(),
                        removed: removed.iter().map(|p| p.display().to_string()).collect(),
                    },
                );
            }
            Err(e) => self.sink.emit(
                None,
                Event::ReloadFailed {
                    error: e.message,
                    file: e.file.as_ref().map(|f| f.display().to_string()),
                    line: e.line,
                    column: e.column,
                },
            ),
        }
        self.notify_status();
    }
}
