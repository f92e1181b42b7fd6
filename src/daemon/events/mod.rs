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
//!
//! # The files
//!
//! - `mod.rs` (here): the event types ([`Level`], [`OutputInfo`], [`Counts`], [`Event`]).
//! - `sink.rs`: [`EventSink`], its queue and its writer thread, and how a line is made.
//! - `tests.rs`: the unit tests of both, and that docs/DAEMON.md's event table matches [`Event`].

use serde::Serialize;
use serde_json::{Value, json};

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

mod sink;

pub use sink::{DEFAULT_QUEUE, EventSink, FLUSH_TIMEOUT, MAX_QUEUE_BYTES};

#[cfg(test)]
pub(crate) use sink::MemOut;

#[cfg(test)]
mod tests;
