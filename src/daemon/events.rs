//! The event stream (docs/DAEMON.md, "Events"): one JSON object per line, flushed per line,
//! on stdout or appended to a file. Every event carries the envelope `schema`, `ts` (RFC 3339,
//! UTC), `seq` (per-process counter), `instance` (this daemon run's identity: the same in
//! every event of one sink, another in the next run, so runs appended to one file can be told
//! apart although each one's `seq` starts at 1), `event`, `level`, and `project` where one
//! applies.
//!
//! Every event the daemon can emit is a variant of [`Event`]; [`EventSink::emit`] is the one
//! place that turns one into a line. docs/DAEMON.md's event table lists the same names and
//! fields (a test keeps the two in sync).
//!
//! # The writer
//!
//! The event stream must never slow down or stop the daemon, and never be corrupted:
//!
//! - [`EventSink::emit`] turns the event into its line, numbers it and puts it in a queue
//!   bounded in events and bytes; one writer thread writes the lines. A reader that stops reading (a stalled
//!   stdout pipe) stops the writer thread, not the compiles. When the queue is full the event is
//!   dropped and counted; once the writer has caught up (the queue is half empty again), an
//!   `events-dropped` event says how many were lost. `seq` is given when the event is emitted,
//!   so the lines' `seq` always grows, with a gap exactly where events were lost.
//! - Each line is written with one `write` (continued only after a short write). When a write
//!   fails (a full disk), the bytes of the line that did get out are taken back (the file is
//!   truncated to its length before the line); where that is impossible (a pipe), the next line
//!   starts with a newline, so it is a whole line of its own. Lines lost that way are counted
//!   and reported by `events-dropped` once writing works again; the failure is logged once
//!   (`tracing`), and once more when it is over.
//! - [`EventSink::reopen`] opens the events file again (`SIGHUP` after logrotate moved it away)
//!   or switches to the file the configuration names now; the writer takes the new file before
//!   its next line. Files are opened with `O_APPEND`, so logrotate's `copytruncate` works too.
//! - [`EventSink::flush`] waits, bounded, until every queued event is written: a stalled reader
//!   cannot hold up the end of the process.

use std::collections::VecDeque;
use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime};

use serde::Serialize;
use serde_json::{Map, Value, json};

/// The schema name of every event; fields are only ever added within `/1`.
pub const SCHEMA: &str = "skillpost.event/1";

/// How important an event is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    Info,
    Warn,
    Error,
}

impl Level {
    fn as_str(self) -> &'static str {
        match self {
            Level::Info => "info",
            Level::Warn => "warn",
            Level::Error => "error",
        }
    }
}

/// One output of a successful compile.
#[derive(Debug, Clone, Serialize)]
pub struct OutputInfo {
    pub path: String,
    /// False when the file already held these bytes.
    pub written: bool,
    /// The program the file belongs to (docs/CELLS.md: one per controller of the cell).
    pub program: String,
    /// The resource whose controller runs that program.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub controller: Option<String>,
}

/// The counts of a successful compile.
#[derive(Debug, Clone, Serialize)]
pub struct Counts {
    pub steps: usize,
    pub warnings: usize,
}

/// Every event of the `skillpost.event/1` stream. `None` fields are left out of the line.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "event", rename_all = "kebab-case")]
pub enum Event {
    Started {
        version: &'static str,
        pid: u32,
        config: Option<String>,
    },
    Watching {
        root: Option<String>,
        blackboard: Option<String>,
        backend: &'static str,
        /// Why a folder is watched again (it came back).
        reason: Option<String>,
        /// The program name the project compiles to (`<program>.src`), when its blackboard is
        /// known.
        program: Option<String>,
    },
    WatchDegraded {
        root: Option<String>,
        reason: String,
        backend: Option<&'static str>,
    },
    Rescan {
        reason: String,
        projects: Option<usize>,
        error: Option<String>,
    },
    ChangeDetected {
        paths: Vec<String>,
    },
    CompileStarted {
        run_id: u64,
        trigger: &'static str,
        changed: Vec<String>,
    },
    CompileSucceeded {
        run_id: u64,
        duration_ms: u64,
        outputs: Vec<OutputInfo>,
        /// Program files beside the outputs that this compile did not write (`.src`, `.dat`,
        /// `.mod`, `.script`): most likely a program's before its `Program` was renamed. Never
        /// deleted: they may be on a controller too. Left out when there are none.
        #[serde(skip_serializing_if = "Vec::is_empty")]
        stale: Vec<String>,
        counts: Counts,
        /// Diagnostics as `--format json` prints them.
        warnings: Vec<Value>,
    },
    CompileFailed {
        run_id: u64,
        duration_ms: u64,
        /// Diagnostics as `--format json` prints them.
        diagnostics: Vec<Value>,
    },
    /// The outcome of a run that failed on a file caught half-written: nothing is reported as an
    /// error yet; a new run (`trigger` `retry`) follows after a quiet period.
    CompileRetrying {
        run_id: u64,
        duration_ms: u64,
        /// The file that was still being written.
        file: Option<String>,
        /// Which retry follows (1 to 3).
        attempt: u32,
        /// Why, when it is not a file caught half-written (the daemon ran out of descriptors
        /// or memory).
        reason: Option<String>,
    },
    WriteBack {
        run_id: u64,
        file: String,
        /// The first program's value; `values` has every program's (a cell writes one per
        /// controller), in the order of the outputs.
        value: String,
        values: Vec<String>,
        written: bool,
        reason: Option<String>,
        /// How long the write-back waited for another program to close the blackboard (left
        /// out when it did not wait); not part of the compile's `duration_ms`.
        waited_ms: Option<u64>,
        /// The write-back did not happen although the value was wrong (a `warn` event).
        #[serde(skip)]
        skipped: bool,
    },
    /// The deploy hook of a compile starts (docs/DAEMON.md, "Deploying"): the argument vector
    /// with its placeholders replaced.
    DeployStarted {
        run_id: u64,
        /// The program deployed (a compile of a cell deploys each program it wrote) and its
        /// controller's resource.
        program: String,
        controller: Option<String>,
        argv: Vec<String>,
    },
    DeploySucceeded {
        run_id: u64,
        program: String,
        controller: Option<String>,
        duration_ms: u64,
        /// The last lines of the hook's stderr (at most 4 KiB; empty when it said nothing).
        stderr: String,
    },
    DeployFailed {
        run_id: u64,
        program: String,
        controller: Option<String>,
        duration_ms: u64,
        exit_code: Option<i32>,
        /// The signal that ended the hook (9 after a timeout).
        signal: Option<i32>,
        /// Ended (with its process group) because it ran longer than `deploy_timeout_s`.
        timed_out: bool,
        reason: String,
        stderr: String,
    },
    /// The simulation after a compile (`simulate` in the configuration; docs/SIMULATE.md)
    /// found no problem in any run.
    SimulationSucceeded {
        /// The compile whose programs ran.
        run_id: u64,
        runs: usize,
        duration_ms: u64,
        /// The first run's cycle time (none when the chart repeats).
        cycle_s: Option<f64>,
        /// Steps and branches no run reached.
        never_reached: usize,
    },
    /// The simulation found a problem (the outputs stand: the compile succeeded), or could not
    /// run (`kind` `scenario`: the scenario file, located by `file`, `line`, `column`).
    SimulationFailed {
        run_id: u64,
        runs: usize,
        duration_ms: u64,
        cycle_s: Option<f64>,
        /// Problems over all runs.
        problems: usize,
        /// The first problem: its kind (`deadlock`, `stuck`, …), where and when.
        kind: String,
        message: String,
        controller: Option<String>,
        file: Option<String>,
        line: Option<u64>,
        column: Option<u64>,
        local_id: Option<u64>,
        time_s: Option<f64>,
    },
    Reloaded {
        projects: usize,
        added: Vec<String>,
        removed: Vec<String>,
    },
    ReloadFailed {
        error: String,
        file: Option<String>,
        line: Option<usize>,
        column: Option<usize>,
    },
    /// The daemon stops: `reason` is the signal, or `timeout` when compiles were still running
    /// after [`super::STOP_TIMEOUT`] (the process then exits with status 2).
    Stopped {
        reason: String,
        /// With `timeout`: what asked the daemon to stop (`SIGTERM`, `SIGINT`).
        requested: Option<String>,
        /// With `timeout`: the projects whose compile was still running.
        compiling: Option<Vec<String>>,
    },
    /// Events were lost: `queue-full` (the reader of the stream did not keep up) or
    /// `write-error` (the events file could not be written, e.g. a full disk). The lines' `seq`
    /// skips exactly `count` numbers for them.
    EventsDropped {
        count: u64,
        reason: &'static str,
    },
}

impl Event {
    /// The event's name, as in the line's `event` field.
    pub fn name(&self) -> &'static str {
        match self {
            Event::Started { .. } => "started",
            Event::Watching { .. } => "watching",
            Event::WatchDegraded { .. } => "watch-degraded",
            Event::Rescan { .. } => "rescan",
            Event::ChangeDetected { .. } => "change-detected",
            Event::CompileStarted { .. } => "compile-started",
            Event::CompileSucceeded { .. } => "compile-succeeded",
            Event::CompileFailed { .. } => "compile-failed",
            Event::CompileRetrying { .. } => "compile-retrying",
            Event::WriteBack { .. } => "write-back",
            Event::DeployStarted { .. } => "deploy-started",
            Event::DeploySucceeded { .. } => "deploy-succeeded",
            Event::DeployFailed { .. } => "deploy-failed",
            Event::SimulationSucceeded { .. } => "simulation-succeeded",
            Event::SimulationFailed { .. } => "simulation-failed",
            Event::Reloaded { .. } => "reloaded",
            Event::ReloadFailed { .. } => "reload-failed",
            Event::Stopped { .. } => "stopped",
            Event::EventsDropped { .. } => "events-dropped",
        }
    }

    /// The event's level.
    pub fn level(&self) -> Level {
        match self {
            Event::WatchDegraded { .. } | Event::EventsDropped { .. } => Level::Warn,
            Event::Stopped { reason, .. } if reason == "timeout" => Level::Error,
            Event::Rescan { reason, .. } if reason != "startup" => Level::Warn,
            Event::WriteBack { skipped: true, .. } | Event::SimulationFailed { .. } => Level::Warn,
            Event::CompileFailed { .. }
            | Event::ReloadFailed { .. }
            | Event::DeployFailed { .. } => Level::Error,
            _ => Level::Info,
        }
    }

    /// Why a deploy failed, for a line a person reads (the log, `skillpost status`): the
    /// reason and the last non-blank line of the hook's stderr.
    pub fn deploy_failure(reason: &str, stderr: &str) -> String {
        match stderr.lines().rev().find(|l| !l.trim().is_empty()) {
            Some(l) => format!("{reason}: {}", l.trim()),
            None => reason.to_owned(),
        }
    }

    /// `deploy-failed` for a hook that did not run (or could not be started): no exit status,
    /// no stderr, the reason.
    pub fn deploy_not_run(
        program: &str,
        controller: Option<&str>,
        run_id: u64,
        duration_ms: u64,
        reason: String,
    ) -> Event {
        Event::DeployFailed {
            program: program.to_owned(),
            controller: controller.map(str::to_owned),
            run_id,
            duration_ms,
            exit_code: None,
            signal: None,
            timed_out: false,
            reason,
            stderr: String::new(),
        }
    }

    /// A `compile-failed` event with one diagnostic of our own (not from the compiler).
    pub fn failed_with(run_id: u64, duration_ms: u64, code: &str, message: String) -> Event {
        Event::CompileFailed {
            run_id,
            duration_ms,
            diagnostics: vec![json!({"severity": "error", "code": code, "message": message})],
        }
    }
}

/// How many events wait for the writer at most, unless `SKILLPOST_EVENT_QUEUE` says otherwise.
pub const DEFAULT_QUEUE: usize = 4096;

/// How many bytes of lines wait for the writer at most (events with thousands of diagnostics
/// are large); one event is always taken.
pub const MAX_QUEUE_BYTES: usize = 16 << 20;

/// How long the end of the daemon waits for the last events to be written.
pub const FLUSH_TIMEOUT: Duration = Duration::from_secs(2);

/// Where the lines go: a file (which can take back a partial line), or any writer.
trait Output: Send {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize>;
    fn flush(&mut self) -> std::io::Result<()>;
    /// Takes back the last `n` bytes written; false where the output cannot (a pipe).
    fn unwrite(&mut self, n: u64) -> bool;
}

impl Output for File {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        Write::write(self, buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
    fn unwrite(&mut self, n: u64) -> bool {
        let Ok(meta) = self.metadata() else {
            return false;
        };
        if !meta.is_file() || meta.len() < n {
            return false;
        }
        let len = meta.len() - n;
        // Not `O_APPEND` (stdout redirected with `>`): the offset must come back too.
        self.set_len(len).is_ok() && self.seek(SeekFrom::Start(len)).is_ok()
    }
}

/// Any writer (tests, or stdout when it cannot be duplicated).
struct Plain(Box<dyn Write + Send>);

impl Output for Plain {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.0.flush()
    }
    fn unwrite(&mut self, _n: u64) -> bool {
        false
    }
}

/// What kind of output a sink was made for, so that [`EventSink::reopen`] knows what to do.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Kind {
    Stdout,
    File(PathBuf),
    /// A writer given by the caller: never replaced.
    Custom,
}

/// A line waiting for the writer.
struct Pending {
    line: Vec<u8>,
    /// For an `events-dropped` line: its reason and count (put back when the line is lost).
    report: Option<(&'static str, u64)>,
}

struct State {
    queue: VecDeque<Pending>,
    /// The bytes of the lines in the queue.
    bytes: usize,
    seq: u64,
    /// Events dropped because the queue was full / because their write failed, not yet reported.
    dropped_full: u64,
    dropped_failed: u64,
    /// The writer is writing a line (taken from the queue).
    busy: bool,
    /// The output the writer takes before its next line.
    replace: Option<Box<dyn Output>>,
    kind: Kind,
    /// The sink is gone: the writer ends once the queue is empty.
    closed: bool,
    /// When dropping for a full queue was last logged.
    warned_full: Option<Instant>,
}

struct Shared {
    state: Mutex<State>,
    /// To the writer: an event, a new output, or the end.
    work: Condvar,
    /// From the writer: the queue is empty and nothing is being written.
    idle: Condvar,
    capacity: usize,
    /// This run's identity (see [`new_instance`]), after `seq` in every line.
    instance: String,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Where events go. Shared by the daemon's tasks; see the module documentation.
pub struct EventSink {
    shared: Arc<Shared>,
    /// Sees every event as it is emitted: the projects' results (`skillpost status`, systemd's
    /// status line); failures also go to the log ([`super::journal`]).
    state: Arc<super::state::Tracker>,
    /// Set when the daemon stops: a write-back waiting for another program to close the
    /// blackboard gives up at once instead of holding the stop (`job`).
    stopping: std::sync::atomic::AtomicBool,
}

impl EventSink {
    /// Events on stdout.
    pub fn stdout() -> Self {
        Self::start(stdout_output(), Kind::Stdout, queue_capacity())
    }

    /// Events appended to a file (created if missing).
    pub fn append(path: &Path) -> std::io::Result<Self> {
        let f = open_append(path)?;
        Ok(Self::start(
            Box::new(f),
            Kind::File(path.to_owned()),
            queue_capacity(),
        ))
    }

    /// Events into any writer (tests).
    pub fn to(out: Box<dyn Write + Send>) -> Self {
        Self::start(Box::new(Plain(out)), Kind::Custom, queue_capacity())
    }

    fn start(out: Box<dyn Output>, kind: Kind, capacity: usize) -> Self {
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                queue: VecDeque::new(),
                bytes: 0,
                seq: 0,
                dropped_full: 0,
                dropped_failed: 0,
                busy: false,
                replace: None,
                kind,
                closed: false,
                warned_full: None,
            }),
            work: Condvar::new(),
            idle: Condvar::new(),
            capacity: capacity.max(2),
            instance: new_instance(),
        });
        let writer = Writer {
            shared: shared.clone(),
            out,
            dirty: false,
            failing: false,
            logged_failure: false,
            warned_failure: None,
        };
        let spawned = std::thread::Builder::new()
            .name("skillpost-events".into())
            .spawn(move || writer.run());
        if let Err(e) = spawned {
            // Without a writer events only pile up to the queue's bound and are counted.
            tracing::error!("cannot start the event writer thread: {e}");
        }
        EventSink {
            shared,
            state: Arc::new(super::state::Tracker::new(None)),
            stopping: Default::default(),
        }
    }

    /// The same sink, writing the projects' results to a state file (`skillpost status`).
    pub fn with_state_file(mut self, path: PathBuf) -> Self {
        self.state = Arc::new(super::state::Tracker::new(Some(path)));
        self
    }

    /// The files the daemon writes besides outputs: the events file (when events go to one)
    /// and the state file. A project may not read them (`job`), and they may not lie in a
    /// project's folder (`config::own_files_problem`).
    pub fn own_files(&self) -> Vec<PathBuf> {
        let mut v = Vec::new();
        if let Kind::File(p) = &self.shared.lock().kind {
            v.push(p.clone());
        }
        v.extend(self.state.path().map(Path::to_path_buf));
        v
    }

    /// This run's identity, the `instance` of every event it emits (see `new_instance`).
    pub fn instance(&self) -> &str {
        &self.shared.instance
    }

    /// The daemon stops: running write-backs stop waiting (see [`EventSink::stopping`]).
    pub fn set_stopping(&self) {
        self.stopping
            .store(true, std::sync::atomic::Ordering::Relaxed);
    }

    /// Whether the daemon is stopping.
    pub fn stopping(&self) -> bool {
        self.stopping.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// The projects' results as the events told them.
    pub fn state(&self) -> &super::state::Tracker {
        &self.state
    }

    /// Emits one event: numbers it and queues its line for the writer; never waits for the
    /// output. When the queue is full the event is dropped and counted (see `events-dropped`).
    pub fn emit(&self, project: Option<&str>, event: Event) {
        super::journal::log(project, &event);
        self.state.observe(project, &event);
        let (head, tail) = render(SystemTime::now(), project, &event);
        let mut st = self.shared.lock();
        st.seq += 1;
        let full = st.queue.len() >= self.shared.capacity
            || (st.bytes + head.len() + tail.len() > MAX_QUEUE_BYTES && !st.queue.is_empty());
        if full {
            if st.dropped_full == 0 && due(&mut st.warned_full) {
                tracing::warn!(
                    "the event stream is not read fast enough: dropping events until it catches up"
                );
            }
            st.dropped_full += 1;
            return;
        }
        let line = with_seq(head, st.seq, &self.shared.instance, &tail);
        st.bytes += line.len();
        st.queue.push_back(Pending { line, report: None });
        drop(st);
        self.shared.work.notify_one();
    }

    /// Opens the output again: the file `events` (created if missing; the same path again after
    /// logrotate moved it away, or a new one), or stdout when `None`. The writer takes it before
    /// its next line. A sink made by [`EventSink::to`] keeps its writer. On error the current
    /// output is kept.
    pub fn reopen(&self, events: Option<&Path>) -> std::io::Result<()> {
        let kind = match events {
            Some(p) => Kind::File(p.to_owned()),
            None => Kind::Stdout,
        };
        {
            let st = self.shared.lock();
            if st.kind == Kind::Custom || (st.kind == Kind::Stdout && kind == Kind::Stdout) {
                return Ok(());
            }
        }
        let out: Box<dyn Output> = match events {
            Some(p) => Box::new(open_append(p)?),
            None => stdout_output(),
        };
        let mut st = self.shared.lock();
        st.replace = Some(out);
        st.kind = kind;
        drop(st);
        self.shared.work.notify_one();
        Ok(())
    }

    /// Waits until every event emitted so far is written (or dropped), at most `timeout`.
    /// Returns how many are still waiting (0: all out).
    pub fn flush(&self, timeout: Duration) -> usize {
        let deadline = Instant::now() + timeout;
        let mut st = self.shared.lock();
        loop {
            let waiting = st.queue.len() + usize::from(st.busy);
            let now = Instant::now();
            if waiting == 0 || now >= deadline {
                return waiting;
            }
            st = self
                .shared
                .idle
                .wait_timeout(st, deadline - now)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }
}

impl Drop for EventSink {
    /// The writer writes what is queued, then ends (it is not waited for).
    fn drop(&mut self) {
        self.shared.lock().closed = true;
        self.shared.work.notify_all();
    }
}

/// Opens the events file for appending, created if missing (mode `0666 & !umask`). Without
/// blocking, and only a regular file or a character device (`/dev/null`): a FIFO would hold the
/// daemon in `open` until a reader came (at startup, or in the event loop at `SIGHUP`), and a
/// reader that stops reading would stall every event.
fn open_append(path: &Path) -> std::io::Result<File> {
    use std::os::unix::fs::{FileTypeExt as _, OpenOptionsExt as _};
    let f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .custom_flags(rustix::fs::OFlags::NONBLOCK.bits() as i32)
        .open(path)
        .map_err(|e| {
            if e.raw_os_error() == Some(rustix::io::Errno::NXIO.raw_os_error()) {
                not_a_file(path, "a FIFO")
            } else {
                e
            }
        })?;
    let kind = f.metadata()?.file_type();
    if kind.is_fifo() {
        return Err(not_a_file(path, "a FIFO"));
    }
    if !kind.is_file() && !kind.is_char_device() {
        return Err(not_a_file(path, "not a regular file"));
    }
    // Writes block as they always did (a full disk is reported by the writer thread).
    rustix::fs::fcntl_setfl(&f, rustix::fs::OFlags::APPEND)?;
    Ok(f)
}

fn not_a_file(path: &Path, what: &str) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!(
            "{} is {what}; the events file must be a regular file (for a program that reads the events as they come, leave out --events and pipe stdout to it)",
            path.display()
        ),
    )
}

/// Stdout as a file of its own (a duplicate descriptor): unbuffered, one `write` per line, and a
/// partial line can be taken back when stdout is a regular file.
fn stdout_output() -> Box<dyn Output> {
    use std::os::fd::AsFd;
    match std::io::stdout().as_fd().try_clone_to_owned() {
        Ok(fd) => Box::new(File::from(fd)),
        Err(_) => Box::new(Plain(Box::new(std::io::stdout()))),
    }
}

/// The queue bound: `SKILLPOST_EVENT_QUEUE`, else [`DEFAULT_QUEUE`].
fn queue_capacity() -> usize {
    std::env::var("SKILLPOST_EVENT_QUEUE")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(DEFAULT_QUEUE)
}

/// The writer thread: takes events from the queue, writes them as lines.
struct Writer {
    shared: Arc<Shared>,
    out: Box<dyn Output>,
    /// The output does not end at a line boundary (a partial line that could not be taken back).
    dirty: bool,
    /// Writing fails.
    failing: bool,
    /// This failure was logged (then its end is logged too).
    logged_failure: bool,
    /// When a failure was last logged.
    warned_failure: Option<Instant>,
}

impl Writer {
    fn run(mut self) {
        loop {
            let pending = {
                let mut st = self.shared.lock();
                loop {
                    if let Some(out) = st.replace.take() {
                        self.out = out;
                        self.dirty = false;
                    }
                    if let Some(p) = st.queue.pop_front() {
                        st.bytes -= p.line.len();
                        st.busy = true;
                        break p;
                    }
                    if st.closed {
                        return;
                    }
                    st = self.shared.work.wait(st).unwrap_or_else(|p| p.into_inner());
                }
            };
            let ok = self.write(&pending.line);
            let mut st = self.shared.lock();
            st.busy = false;
            if !ok {
                st.dropped_failed += 1;
                // A lost report of losses: its count is reported again with the next one.
                match pending.report {
                    Some(("queue-full", count)) => st.dropped_full += count,
                    Some((_, count)) => st.dropped_failed += count,
                    None => {}
                }
            }
            // Caught up: report what was lost, as one more event after those queued.
            let caught_up =
                st.queue.len() <= self.shared.capacity / 2 && st.bytes <= MAX_QUEUE_BYTES / 2;
            let mut report = Vec::new();
            if st.dropped_full > 0 && caught_up {
                report.push(("queue-full", std::mem::take(&mut st.dropped_full)));
            }
            if ok && st.dropped_failed > 0 {
                report.push(("write-error", std::mem::take(&mut st.dropped_failed)));
            }
            for (reason, count) in report {
                st.seq += 1;
                tracing::debug!("{count} events were lost ({reason}); reported in the stream");
                let (head, tail) = render(
                    SystemTime::now(),
                    None,
                    &Event::EventsDropped { count, reason },
                );
                let line = with_seq(head, st.seq, &self.shared.instance, &tail);
                st.bytes += line.len();
                st.queue.push_back(Pending {
                    line,
                    report: Some((reason, count)),
                });
            }
            if st.queue.is_empty() {
                self.shared.idle.notify_all();
            }
        }
    }

    /// Writes one line; true if it is out whole. After a failure no partial line stays behind.
    fn write(&mut self, line: &[u8]) -> bool {
        let pre = usize::from(self.dirty);
        let mut buf = Vec::with_capacity(line.len() + pre);
        if self.dirty {
            buf.push(b'\n');
        }
        buf.extend_from_slice(line);
        let mut done = 0;
        let mut result = Ok(());
        while done < buf.len() {
            match self.out.write(&buf[done..]) {
                Ok(0) => {
                    result = Err(std::io::Error::from(std::io::ErrorKind::WriteZero));
                    break;
                }
                Ok(n) => done += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
        }
        if result.is_ok() {
            result = self.out.flush();
            if result.is_err() {
                // Buffered somewhere: how much of it got out is unknown.
                self.dirty = true;
            } else {
                self.dirty = false;
            }
        } else if done > pre {
            // Part of the line is out: take it back, else end it with the next line's newline.
            let n = (done - pre) as u64;
            self.dirty = !self.out.unwrite(n);
            if self.dirty {
                tracing::debug!("{n} bytes of a line are out; the next line starts a new one");
            } else {
                tracing::debug!("took back {n} bytes of a partial line");
            }
        } else if done == pre {
            self.dirty = false;
        }
        match result {
            Ok(()) => {
                if std::mem::take(&mut self.failing) && std::mem::take(&mut self.logged_failure) {
                    tracing::warn!("the event stream can be written again");
                }
                true
            }
            Err(e) => {
                if !self.failing {
                    self.failing = true;
                    // A disk that is almost full fails and works by turns: logged once a minute.
                    self.logged_failure = due(&mut self.warned_failure);
                    if self.logged_failure {
                        tracing::error!(
                            "cannot write the event stream: {e}; events are lost until it works again"
                        );
                    }
                }
                false
            }
        }
    }
}

/// How often a trouble of the event stream is logged at most.
const LOG_EVERY: Duration = Duration::from_secs(60);

/// Whether a message last logged at `last` is due again; if so, `last` becomes now.
fn due(last: &mut Option<Instant>) -> bool {
    let now = Instant::now();
    if last.is_some_and(|t| now.duration_since(t) < LOG_EVERY) {
        return false;
    }
    *last = Some(now);
    true
}

/// One event as the two parts of its line around `seq`: the envelope up to `ts`, and the rest
/// (`event`, `level`, `project`, then the event's fields, those that are `None` left out).
/// Done before the sink's lock is taken; [`with_seq`] joins them under it.
fn render(ts: SystemTime, project: Option<&str>, event: &Event) -> (Vec<u8>, Vec<u8>) {
    let mut head = Map::new();
    head.insert("schema".into(), json!(SCHEMA));
    head.insert(
        "ts".into(),
        json!(humantime::format_rfc3339_millis(ts).to_string()),
    );
    let mut tail = Map::new();
    tail.insert("event".into(), json!(event.name()));
    tail.insert("level".into(), json!(event.level().as_str()));
    if let Some(p) = project {
        tail.insert("project".into(), json!(p));
    }
    if let Ok(Value::Object(f)) = serde_json::to_value(event) {
        // Absent is clearer than null in a log that people read.
        for (k, v) in f.into_iter().filter(|(k, v)| k != "event" && !v.is_null()) {
            tail.insert(k, v);
        }
    }
    // `{"schema":…,"ts":"…"` and `"event":…}` (both objects are never empty).
    let mut head = serde_json::to_vec(&Value::Object(head)).unwrap_or_default();
    head.pop();
    let mut tail = serde_json::to_vec(&Value::Object(tail)).unwrap_or_default();
    tail.remove(0);
    (head, tail)
}

/// The whole line: `head`, `,"seq":N,"instance":"…",`, `tail`, newline.
fn with_seq(mut head: Vec<u8>, seq: u64, instance: &str, tail: &[u8]) -> Vec<u8> {
    head.reserve(tail.len() + 64);
    head.extend_from_slice(format!(",\"seq\":{seq},\"instance\":\"{instance}\",").as_bytes());
    head.extend_from_slice(tail);
    head.push(b'\n');
    head
}

/// A daemon run's identity, for the `instance` of its events: the start time (milliseconds since
/// 1970, hexadecimal), the pid and 32 random bits, e.g. `19ac35e2f01-1a2b-9f3c0d1e`. Runs of one
/// machine differ by time and pid; the random part separates runs of several machines (or
/// containers with the same pid) appending to one file in the same millisecond. Only letters,
/// digits and `-`: written into the line as it is, without escaping.
fn new_instance() -> String {
    use std::hash::{BuildHasher, Hasher};
    let ms = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis());
    // std's hasher keys are random per process (and per `RandomState` after the first).
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(ms);
    h.write_u32(std::process::id());
    let random = h.finish() as u32;
    format!("{ms:x}-{:x}-{random:08x}", std::process::id())
}

/// An event output in memory, for the unit tests of the daemon's modules.
#[cfg(test)]
#[derive(Clone, Default)]
pub(crate) struct MemOut(pub(crate) Arc<Mutex<Vec<u8>>>);

#[cfg(test)]
impl Write for MemOut {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;
    use std::sync::mpsc;

    use super::MemOut as Buf;

    #[test]
    fn envelope_and_sequence() {
        let buf = Buf::default();
        let sink = EventSink::to(Box::new(buf.clone()));
        sink.emit(
            None,
            Event::Started {
                version: "x",
                pid: 1,
                config: None,
            },
        );
        sink.emit(Some("A"), Event::failed_with(3, 0, "E101", "gone".into()));
        assert_eq!(sink.flush(Duration::from_secs(5)), 0);
        let text = String::from_utf8(buf.0.lock().unwrap().clone()).unwrap();
        let lines: Vec<Value> = text
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(lines.len(), 2);
        assert_eq!(lines[0]["schema"], SCHEMA);
        assert_eq!(lines[0]["seq"], 1);
        assert_eq!(lines[1]["seq"], 2);
        // One run, one instance; another sink (the next run) has another.
        assert_eq!(lines[0]["instance"], sink.instance());
        assert_eq!(lines[1]["instance"], sink.instance());
        let next = EventSink::to(Box::new(Buf::default()));
        assert_ne!(next.instance(), sink.instance());
        assert_eq!(lines[0]["event"], "started");
        assert_eq!(lines[0]["version"], "x");
        assert_eq!(lines[1]["event"], "compile-failed");
        assert_eq!(lines[1]["diagnostics"][0]["code"], "E101");
        assert!(lines[0].get("project").is_none());
        assert!(lines[0].get("config").is_none(), "nulls are left out");
        // The envelope comes first.
        assert!(
            text.starts_with("{\"schema\":\"skillpost.event/1\",\"ts\":"),
            "{text}"
        );
        assert_eq!(lines[1]["project"], "A");
        let keys: Vec<&str> = lines[1]
            .as_object()
            .unwrap()
            .keys()
            .map(String::as_str)
            .collect();
        assert_eq!(
            keys,
            [
                "schema",
                "ts",
                "seq",
                "instance",
                "event",
                "level",
                "project",
                "run_id",
                "duration_ms",
                "diagnostics"
            ]
        );
        assert_eq!(lines[1]["level"], "error");
        let ts = lines[0]["ts"].as_str().unwrap();
        assert!(ts.ends_with('Z') && ts.len() == 24, "{ts}");
        assert!(humantime::parse_rfc3339(ts).is_ok());
    }

    fn started() -> Event {
        Event::Started {
            version: "x",
            pid: 1,
            config: None,
        }
    }

    fn lines_of(bytes: &[u8]) -> Vec<String> {
        String::from_utf8(bytes.to_vec())
            .unwrap()
            .lines()
            .map(str::to_owned)
            .collect()
    }

    fn json_lines(bytes: &[u8]) -> Vec<Value> {
        lines_of(bytes)
            .iter()
            .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
            .collect()
    }

    /// `seq` grows line by line; every gap is accounted for by `events-dropped` (the sum of
    /// their counts equals the sum of the gaps).
    fn check_seq(lines: &[Value]) -> u64 {
        let mut gaps = 0;
        let mut reported = 0;
        let mut last = 0;
        for l in lines {
            let seq = l["seq"].as_u64().unwrap();
            assert!(seq > last, "seq {seq} after {last}");
            gaps += seq - last - 1;
            last = seq;
            if l["event"] == "events-dropped" {
                assert_eq!(l["level"], "warn");
                reported += l["count"].as_u64().unwrap();
            }
        }
        assert_eq!(gaps, reported, "gaps in seq = events-dropped counts");
        reported
    }

    /// A writer that blocks in its first `write` until released (a stalled reader).
    struct Gate {
        entered: mpsc::Sender<()>,
        open: Arc<(Mutex<bool>, Condvar)>,
        buf: Buf,
    }

    impl Write for Gate {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            let _ = self.entered.send(());
            let (m, cv) = &*self.open;
            let mut open = m.lock().unwrap();
            while !*open {
                open = cv.wait(open).unwrap();
            }
            self.buf.write(b)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_full_queue_drops_counts_and_reports_once_caught_up() {
        let (tx, rx) = mpsc::channel();
        let open = Arc::new((Mutex::new(false), Condvar::new()));
        let buf = Buf::default();
        let gate = Gate {
            entered: tx,
            open: open.clone(),
            buf: buf.clone(),
        };
        let sink = EventSink::start(Box::new(Plain(Box::new(gate))), Kind::Custom, 8);
        // The first event is taken by the writer, which then hangs in `write`.
        sink.emit(None, started());
        rx.recv_timeout(Duration::from_secs(5)).unwrap();
        // 8 fit in the queue, 5 are dropped; emitting never waits.
        let t = Instant::now();
        for i in 0..13 {
            sink.emit(Some(&format!("P{i}")), started());
        }
        assert!(t.elapsed() < Duration::from_secs(1));
        // A stalled writer: flush gives up after its timeout.
        let t = Instant::now();
        assert_eq!(sink.flush(Duration::from_millis(200)), 9);
        assert!(t.elapsed() < Duration::from_secs(2));
        *open.0.lock().unwrap() = true;
        open.1.notify_all();
        assert_eq!(sink.flush(Duration::from_secs(5)), 0);
        let lines = json_lines(&buf.0.lock().unwrap());
        assert_eq!(lines.len(), 1 + 8 + 1, "{lines:?}");
        let dropped: Vec<&Value> = lines
            .iter()
            .filter(|l| l["event"] == "events-dropped")
            .collect();
        assert_eq!(dropped.len(), 1, "{lines:?}");
        assert_eq!(dropped[0]["count"], 5);
        assert_eq!(dropped[0]["reason"], "queue-full");
        assert!(dropped[0].get("project").is_none());
        assert_eq!(check_seq(&lines), 5);
        // The events after the drop follow it.
        sink.emit(None, started());
        assert_eq!(sink.flush(Duration::from_secs(5)), 0);
        let lines = json_lines(&buf.0.lock().unwrap());
        assert_eq!(lines.last().unwrap()["seq"], 16);
        check_seq(&lines);
    }

    #[test]
    fn the_queue_is_bounded_in_bytes_too() {
        let (tx, rx) = mpsc::channel();
        let open = Arc::new((Mutex::new(false), Condvar::new()));
        let buf = Buf::default();
        let gate = Gate {
            entered: tx,
            open: open.clone(),
            buf: buf.clone(),
        };
        let sink = EventSink::start(Box::new(Plain(Box::new(gate))), Kind::Custom, 100);
        sink.emit(None, started());
        rx.recv_timeout(Duration::from_secs(5)).unwrap();
        let big = || Event::failed_with(1, 0, "E000", "x".repeat(MAX_QUEUE_BYTES / 2 + 1));
        sink.emit(Some("big1"), big());
        // Over the byte bound with the first one queued: dropped.
        sink.emit(Some("big2"), big());
        sink.emit(Some("small"), started());
        *open.0.lock().unwrap() = true;
        open.1.notify_all();
        assert_eq!(sink.flush(Duration::from_secs(5)), 0);
        let lines = json_lines(&buf.0.lock().unwrap());
        let projects: Vec<&str> = lines
            .iter()
            .map(|l| l["project"].as_str().unwrap_or("-"))
            .collect();
        assert_eq!(projects, ["-", "big1", "small", "-"]);
        assert_eq!(check_seq(&lines), 1);
    }

    /// A file-like output that fails on one write after accepting half of it, and can take
    /// bytes back (like a file on a full disk).
    struct HalfThenFail {
        buf: Buf,
        /// Which write (counting from 0) accepts half and then fails.
        fail_at: Vec<usize>,
        writes: usize,
        failing: bool,
        truncatable: bool,
    }

    impl Output for HalfThenFail {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            if self.failing {
                self.failing = false;
                return Err(std::io::Error::other("No space left on device"));
            }
            let n = self.writes;
            self.writes += 1;
            if self.fail_at.contains(&n) {
                // Half now, the error on the next call (as a full disk does).
                self.failing = true;
                let half = b.len() / 2;
                self.buf.0.lock().unwrap().extend_from_slice(&b[..half]);
                return Ok(half);
            }
            self.buf.0.lock().unwrap().extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
        fn unwrite(&mut self, n: u64) -> bool {
            if !self.truncatable {
                return false;
            }
            let mut v = self.buf.0.lock().unwrap();
            let len = v.len() - n as usize;
            v.truncate(len);
            true
        }
    }

    fn failing_sink(truncatable: bool) -> (EventSink, Buf) {
        let buf = Buf::default();
        let out = HalfThenFail {
            buf: buf.clone(),
            fail_at: vec![1, 3],
            writes: 0,
            failing: false,
            truncatable,
        };
        (
            EventSink::start(Box::new(out), Kind::Custom, DEFAULT_QUEUE),
            buf,
        )
    }

    #[test]
    fn a_failed_write_is_taken_back() {
        let (sink, buf) = failing_sink(true);
        for i in 0..6 {
            sink.emit(Some(&format!("P{i}")), started());
            assert_eq!(sink.flush(Duration::from_secs(5)), 0);
        }
        // Every line whole. Lost: P1, then the first report of it (the 4th write); the second
        // report counts both.
        let lines = json_lines(&buf.0.lock().unwrap());
        assert_eq!(check_seq(&lines), 2);
        assert_eq!(
            lines.iter().filter(|l| l["event"] == "started").count(),
            5,
            "{lines:?}"
        );
        let dropped: Vec<&Value> = lines
            .iter()
            .filter(|l| l["event"] == "events-dropped")
            .collect();
        assert!(dropped.iter().all(|d| d["reason"] == "write-error"));
    }

    #[test]
    fn a_failed_write_that_cannot_be_taken_back_is_ended_by_the_next_line() {
        let (sink, buf) = failing_sink(false);
        for i in 0..6 {
            sink.emit(Some(&format!("P{i}")), started());
            assert_eq!(sink.flush(Duration::from_secs(5)), 0);
        }
        let bytes = buf.0.lock().unwrap().clone();
        let lines = lines_of(&bytes);
        // The half lines stand alone; every other line is a whole event.
        let (whole, broken): (Vec<&String>, Vec<&String>) = lines
            .iter()
            .partition(|l| serde_json::from_str::<Value>(l).is_ok());
        assert_eq!(broken.len(), 2, "{lines:?}");
        assert!(broken.iter().all(|l| l.starts_with("{\"schema\"")));
        let whole: Vec<Value> = whole
            .iter()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(check_seq(&whole), 2);
        assert_eq!(whole.len(), 5 + 1);
        assert!(bytes.ends_with(b"}\n"));
    }

    #[test]
    fn reopen_follows_a_rotated_file() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("ev.jsonl");
        let sink = EventSink::append(&path).unwrap();
        sink.emit(None, started());
        assert_eq!(sink.flush(Duration::from_secs(5)), 0);
        let rotated = tmp.path().join("ev.jsonl.1");
        std::fs::rename(&path, &rotated).unwrap();
        // Until reopened, events go to the moved file.
        sink.emit(None, started());
        assert_eq!(sink.flush(Duration::from_secs(5)), 0);
        sink.reopen(Some(&path)).unwrap();
        sink.emit(None, started());
        assert_eq!(sink.flush(Duration::from_secs(5)), 0);
        let old = json_lines(&std::fs::read(&rotated).unwrap());
        let new = json_lines(&std::fs::read(&path).unwrap());
        assert_eq!(old.len(), 2);
        assert_eq!(new.len(), 1);
        assert_eq!(new[0]["seq"], 3);
        // Deleted: created again.
        std::fs::remove_file(&path).unwrap();
        sink.reopen(Some(&path)).unwrap();
        sink.emit(None, started());
        assert_eq!(sink.flush(Duration::from_secs(5)), 0);
        assert_eq!(json_lines(&std::fs::read(&path).unwrap())[0]["seq"], 4);
        // A folder that does not exist: an error, and the old file is kept.
        assert!(sink.reopen(Some(&tmp.path().join("no/ev.jsonl"))).is_err());
        sink.emit(None, started());
        assert_eq!(sink.flush(Duration::from_secs(5)), 0);
        assert_eq!(json_lines(&std::fs::read(&path).unwrap()).len(), 2);
    }

    #[test]
    fn a_custom_writer_is_kept_on_reopen() {
        let buf = Buf::default();
        let sink = EventSink::to(Box::new(buf.clone()));
        sink.reopen(None).unwrap();
        sink.emit(None, started());
        assert_eq!(sink.flush(Duration::from_secs(5)), 0);
        assert_eq!(json_lines(&buf.0.lock().unwrap()).len(), 1);
    }

    /// Every variant once, every optional field set.
    fn every_event() -> Vec<Event> {
        let s = || Some("x".to_owned());
        vec![
            Event::Started {
                version: "x",
                pid: 1,
                config: s(),
            },
            Event::Watching {
                root: s(),
                blackboard: s(),
                backend: "inotify",
                reason: s(),
                program: s(),
            },
            Event::WatchDegraded {
                root: s(),
                reason: "x".into(),
                backend: Some("poll"),
            },
            Event::Rescan {
                reason: "startup".into(),
                projects: Some(1),
                error: s(),
            },
            Event::ChangeDetected { paths: vec![] },
            Event::CompileStarted {
                run_id: 1,
                trigger: "change",
                changed: vec![],
            },
            Event::CompileSucceeded {
                run_id: 1,
                duration_ms: 1,
                outputs: vec![],
                stale: vec!["x".into()],
                counts: Counts {
                    steps: 1,
                    warnings: 0,
                },
                warnings: vec![],
            },
            Event::failed_with(1, 1, "E000", "x".into()),
            Event::CompileRetrying {
                run_id: 1,
                duration_ms: 1,
                file: s(),
                attempt: 1,
                reason: s(),
            },
            Event::WriteBack {
                run_id: 1,
                file: "x".into(),
                value: "x".into(),
                values: vec!["x".into()],
                written: true,
                reason: s(),
                waited_ms: Some(1),
                skipped: false,
            },
            Event::DeployStarted {
                run_id: 1,
                program: "x".into(),
                controller: s(),
                argv: vec!["x".into()],
            },
            Event::DeploySucceeded {
                run_id: 1,
                program: "x".into(),
                controller: s(),
                duration_ms: 1,
                stderr: "x".into(),
            },
            Event::DeployFailed {
                run_id: 1,
                program: "x".into(),
                controller: s(),
                duration_ms: 1,
                exit_code: Some(1),
                signal: Some(9),
                timed_out: true,
                reason: "x".into(),
                stderr: "x".into(),
            },
            Event::SimulationSucceeded {
                run_id: 1,
                runs: 1,
                duration_ms: 1,
                cycle_s: Some(1.5),
                never_reached: 0,
            },
            Event::SimulationFailed {
                run_id: 1,
                runs: 1,
                duration_ms: 1,
                cycle_s: None,
                problems: 1,
                kind: "deadlock".into(),
                message: "x".into(),
                controller: s(),
                file: s(),
                line: Some(1),
                column: None,
                local_id: Some(5),
                time_s: Some(2.5),
            },
            Event::Reloaded {
                projects: 1,
                added: vec![],
                removed: vec![],
            },
            Event::ReloadFailed {
                error: "x".into(),
                file: s(),
                line: Some(1),
                column: Some(1),
            },
            Event::Stopped {
                reason: "timeout".into(),
                requested: s(),
                compiling: Some(vec![]),
            },
            Event::EventsDropped {
                count: 1,
                reason: "queue-full",
            },
        ]
    }

    #[test]
    fn every_variant_has_an_example() {
        // A new variant breaks this match: add it to `every_event` (and to docs/DAEMON.md).
        let ordinal = |e: &Event| match e {
            Event::Started { .. } => 0,
            Event::Watching { .. } => 1,
            Event::WatchDegraded { .. } => 2,
            Event::Rescan { .. } => 3,
            Event::ChangeDetected { .. } => 4,
            Event::CompileStarted { .. } => 5,
            Event::CompileSucceeded { .. } => 6,
            Event::CompileFailed { .. } => 7,
            Event::WriteBack { .. } => 8,
            Event::Reloaded { .. } => 9,
            Event::ReloadFailed { .. } => 10,
            Event::Stopped { .. } => 11,
            Event::EventsDropped { .. } => 12,
            Event::CompileRetrying { .. } => 13,
            Event::DeployStarted { .. } => 14,
            Event::DeploySucceeded { .. } => 15,
            Event::DeployFailed { .. } => 16,
            Event::SimulationSucceeded { .. } => 17,
            Event::SimulationFailed { .. } => 18,
        };
        let seen: BTreeSet<usize> = every_event().iter().map(ordinal).collect();
        assert_eq!(seen, (0..19).collect());
    }

    /// The rows of docs/DAEMON.md's event table: (name, level, fields cell).
    fn doc_rows() -> Vec<(String, String, String)> {
        let doc = include_str!("../../docs/DAEMON.md");
        let mut rows = Vec::new();
        let mut in_table = false;
        for line in doc.lines() {
            if line.starts_with("| event | level | fields |") {
                in_table = true;
                continue;
            }
            if !in_table || line.starts_with("|---") {
                continue;
            }
            if !line.starts_with('|') {
                break;
            }
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            rows.push((
                cells[1].trim_matches('`').to_owned(),
                cells[2].to_owned(),
                cells[3..].join("|"),
            ));
        }
        assert!(!rows.is_empty(), "no event table in docs/DAEMON.md");
        rows
    }

    #[test]
    fn docs_event_table_matches_the_code() {
        let rows = doc_rows();
        let events = every_event();
        for e in &events {
            let name = e.name();
            let row = rows
                .iter()
                .find(|r| r.0 == name)
                .unwrap_or_else(|| panic!("event `{name}` missing from docs/DAEMON.md"));
            assert!(
                row.1.contains(e.level().as_str()),
                "docs/DAEMON.md: `{name}` has level {}, the table says {}",
                e.level().as_str(),
                row.1
            );
            let Value::Object(fields) = serde_json::to_value(e).unwrap() else {
                panic!("{name} is not an object");
            };
            for f in fields.keys().filter(|k| *k != "event") {
                assert!(
                    row.2.contains(&format!("`{f}`")),
                    "docs/DAEMON.md: field `{f}` of `{name}` missing from its row"
                );
            }
        }
        for r in &rows {
            assert!(
                events.iter().any(|e| e.name() == r.0),
                "docs/DAEMON.md lists an event `{}` that the code does not have",
                r.0
            );
        }
    }
}
