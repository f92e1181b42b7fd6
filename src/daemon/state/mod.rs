//! The daemon's state file and `skillpost status`.
//!
//! The event loop keeps each project's last result (taken from the events as they are emitted,
//! see [`Tracker::observe`]) and writes a small JSON file with it whenever a compile ends, the
//! configuration is reloaded, and when the daemon stops. The file is replaced atomically (a
//! temporary file in the same folder, then a rename), so a reader never sees half of it.
//!
//! Where: `watch --state FILE`, else `$RUNTIME_DIRECTORY/status.json` (`/run/skillpost` under the
//! shipped unit: systemd gives each service its own runtime folder), else `status-<pid>.json` in
//! the folder of the lock files ([`super::lock::runtime_dir`]: `$XDG_RUNTIME_DIR/skillpost`, else
//! `/tmp/skillpost-<uid>`): one file per daemon, so daemons started by hand never overwrite each
//! other's state. A daemon's file stays after it stops (saying `stopped`); the next daemon
//! started in that folder removes the files of daemons that no longer run.
//!
//! `skillpost status` reads every state file in those folders and in `/run/skillpost` (the
//! service's, for an administrator's shell) ([`discover`]): the daemons that run ([`running`]:
//! not `stopped`, and the writer is the same process still — its pid alive with the start time
//! the file records), or else the last one that stopped.
//!
//! The same numbers make systemd's `STATUS=` line ([`sentence`]).
//!
//! # The files
//!
//! - `mod.rs` (here): the state file's types ([`Snapshot`], [`ProjectState`], [`DeployState`],
//!   [`SimulationState`]), the status line ([`Tally`], [`sentence`]) and [`describe`].
//! - `tracker.rs`: [`Tracker`], the projects' last results taken from the events, and when the
//!   file is written.
//! - `files.rs`: the state files on disk: where they are, written atomically, found, read,
//!   trusted, swept; whether their daemon runs.
//! - `table.rs`: the state as `skillpost status` prints it ([`table()`], [`printable`]).
//! - `tests.rs`: the unit tests.

use std::time::SystemTime;

use serde::{Deserialize, Serialize};
use serde_json::Value;

/// The schema of the state file; fields are only ever added.
pub const SCHEMA: &str = "skillpost.status/1";

/// The file name in a runtime directory.
pub const FILE_NAME: &str = "status.json";

/// Where the service's state file is under the shipped unit (`RuntimeDirectory=skillpost`).
pub const SERVICE_STATE: &str = "/run/skillpost/status.json";

/// The whole state file.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Snapshot {
    pub schema: String,
    pub version: String,
    pub pid: u32,
    /// The writer's start time (clock ticks after boot, `/proc/<pid>/stat`), so a pid used again
    /// by another process is not taken for the daemon (absent in files of older versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pid_start: Option<u64>,
    /// When the daemon started (RFC 3339, UTC).
    pub started: String,
    /// When this file was written.
    pub updated: String,
    /// `starting` (the startup compiles are not done), `running`, or `stopped` once the daemon
    /// has ended.
    pub daemon: String,
    /// Compiles running when the file was written.
    pub compiling: usize,
    /// The systemd status line of the same moment.
    pub summary: String,
    pub projects: Vec<ProjectState>,
}

/// One project's last result.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct ProjectState {
    pub project: String,
    /// `ok`, `failed`, `pending` (not compiled yet), or `waiting` (not compiled yet because its
    /// folder does not exist yet, or another daemon keeps it: [`ProjectState::waiting`] says).
    pub result: String,
    /// Why the project is not watched now (`watch-degraded`'s reason, e.g. "the project folder
    /// does not exist; waiting for it"): while it waits for its folder, also after compiles.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub waiting: Option<String>,
    /// When the last compile ended (RFC 3339, UTC).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub run_id: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_ms: Option<u64>,
    /// The files of the last successful compile.
    #[serde(default)]
    pub outputs: Vec<String>,
    /// Diagnostics of the last compile.
    pub errors: usize,
    pub warnings: usize,
    /// The first error of a failed compile, `code file:line:col: message`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub first_error: Option<String>,
    /// Program files beside the outputs the last successful compile did not write (a program
    /// renamed since: its old files stay, never deleted).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stale: Vec<String>,
    /// The last deploy of each program (the deploy hook, `on_success`), in the order they ran.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub deploys: Vec<DeployState>,
    /// The last simulation (`simulate` in the configuration).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation: Option<SimulationState>,
}

/// The last simulation of a project's programs.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct SimulationState {
    /// `ok` or `failed`.
    pub result: String,
    /// When it ended (RFC 3339, UTC).
    pub time: String,
    /// The compile whose programs ran.
    pub run_id: u64,
    pub runs: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cycle_s: Option<f64>,
    /// The first problem: `kind: message [file:line]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub problem: Option<String>,
}

/// The last deploy of one program of a project.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct DeployState {
    pub program: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub controller: Option<String>,
    /// `running`, `ok` or `failed`.
    pub result: String,
    /// When it started (`running`) or ended (RFC 3339, UTC).
    pub time: String,
    pub run_id: u64,
    /// Why it failed: the reason and the hook's last stderr line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// The counts [`sentence`] reads.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Tally {
    pub projects: usize,
    pub failing: usize,
    pub compiling: usize,
    /// Not compiled yet (at startup), other than those waiting for their folder.
    pub pending: usize,
    /// Not compiled yet because their folder does not exist yet (or another daemon keeps it).
    pub waiting: usize,
    pub directories: usize,
}

/// systemd's `STATUS=` line: "4 projects, 1 failing", "1 project, all compiled", with the
/// running compiles, the projects not compiled yet, those waiting for their folder and the
/// watched directories.
pub fn sentence(c: Tally) -> String {
    let Tally {
        projects,
        failing,
        compiling,
        pending,
        waiting,
        directories,
    } = c;
    let mut s = format!("{projects} project{}", plural(projects));
    if projects > 0 {
        if failing > 0 {
            s.push_str(&format!(", {failing} failing"));
        }
        if compiling > 0 {
            s.push_str(&format!(", {compiling} compiling"));
        }
        if pending > 0 {
            s.push_str(&format!(", {pending} not compiled yet"));
        }
        if waiting > 0 {
            s.push_str(&format!(
                ", {waiting} waiting for {}",
                if waiting == 1 {
                    "its folder"
                } else {
                    "their folders"
                }
            ));
        }
        if failing == 0 && compiling == 0 && pending == 0 && waiting == 0 {
            s.push_str(", all compiled");
        }
    }
    s.push_str(&format!(
        "; watching {directories} director{}",
        if directories == 1 { "y" } else { "ies" }
    ));
    s
}

fn plural(n: usize) -> &'static str {
    if n == 1 { "" } else { "s" }
}

fn now() -> String {
    humantime::format_rfc3339_seconds(SystemTime::now()).to_string()
}

/// `code file:line:col: message` of a diagnostic as the events carry it.
pub fn describe(d: &Value) -> String {
    let s = |k: &str| d.get(k).and_then(Value::as_str).unwrap_or("");
    let mut at = s("file").to_owned();
    for k in ["line", "column"] {
        if let Some(n) = d.get(k).and_then(Value::as_u64) {
            at.push_str(&format!(":{n}"));
        }
    }
    let code = s("code");
    match (at.is_empty(), code.is_empty()) {
        (true, true) => s("message").to_owned(),
        (true, false) => format!("{code}: {}", s("message")),
        (false, _) => format!("{code} {at}: {}", s("message"))
            .trim_start()
            .to_owned(),
    }
}

mod files;
mod table;
mod tracker;

pub use files::{
    candidate_dirs, default_path, discover, is_state_name, process_start, read, running,
    untrusted_folder, watching, write_atomically, writer_alive,
};
pub use table::{printable, table};
pub use tracker::{MIN_WRITE_INTERVAL, Tracker};

#[cfg(test)]
mod tests;
