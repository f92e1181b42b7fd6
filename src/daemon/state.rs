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

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::SystemTime;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::events::Event;

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

/// Writes the snapshot to a temporary file beside `path` (mode 0644: `skillpost status` is for
/// anyone who may read the folder), then renames it over `path`.
pub fn write_atomically(path: &Path, snap: &Snapshot) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    if !dir.exists() {
        use std::os::unix::fs::DirBuilderExt as _;
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(&dir)?;
    }
    let mut tmp = tempfile::Builder::new()
        .prefix(".status-")
        .suffix(".tmp")
        .tempfile_in(&dir)?;
    let mut text = serde_json::to_vec_pretty(snap).map_err(std::io::Error::other)?;
    text.push(b'\n');
    tmp.as_file_mut().write_all(&text)?;
    {
        use std::os::unix::fs::PermissionsExt as _;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644))?;
    }
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// The state file the daemon writes by default: `$RUNTIME_DIRECTORY/status.json` (a service's own
/// runtime folder), else `status-<pid>.json` beside the lock files (a daemon started by hand: one
/// file per daemon).
pub fn default_path() -> PathBuf {
    if std::env::var_os("RUNTIME_DIRECTORY").is_some_and(|d| !d.is_empty()) {
        super::lock::runtime_dir().join(FILE_NAME)
    } else {
        super::lock::runtime_dir().join(own_name(std::process::id()))
    }
}

/// The state file name of the daemon with this pid, started by hand.
fn own_name(pid: u32) -> String {
    format!("status-{pid}.json")
}

/// Whether `name` is a daemon's state file: `status.json` or `status-<pid>.json`.
pub fn is_state_name(name: &str) -> bool {
    name == FILE_NAME
        || name
            .strip_prefix("status-")
            .and_then(|n| n.strip_suffix(".json"))
            .is_some_and(|pid| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
}

/// The folders `skillpost status` looks in without `--state`, in order: `$RUNTIME_DIRECTORY`
/// (when set), the service's `/run/skillpost`, then the folder of daemons started by hand
/// (`$XDG_RUNTIME_DIR/skillpost`, else `/tmp/skillpost-<uid>`).
pub fn candidate_dirs() -> Vec<PathBuf> {
    let mut v = Vec::new();
    if std::env::var_os("RUNTIME_DIRECTORY").is_some_and(|d| !d.is_empty()) {
        v.push(super::lock::runtime_dir());
    }
    if let Some(service) = Path::new(SERVICE_STATE).parent() {
        v.push(service.to_owned());
    }
    let by_hand = match std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        Some(d) => PathBuf::from(d).join("skillpost"),
        None => {
            std::env::temp_dir().join(format!("skillpost-{}", rustix::process::getuid().as_raw()))
        }
    };
    if !v.contains(&by_hand) {
        v.push(by_hand);
    }
    v
}

/// Every state file in [`candidate_dirs`] that can be read, with its path; and the problems
/// (a folder not to be trusted, a file that is no state file) as sentences. A file removed
/// between the listing and the read is left out silently.
pub fn discover() -> (Vec<(PathBuf, Snapshot)>, Vec<String>) {
    let (mut found, mut problems) = (Vec::new(), Vec::new());
    for dir in candidate_dirs() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        let mut names: Vec<PathBuf> = entries
            .flatten()
            .filter(|e| e.file_name().to_str().is_some_and(is_state_name))
            .map(|e| e.path())
            .collect();
        if names.is_empty() {
            continue;
        }
        if let Some(why) = untrusted_folder(&dir) {
            problems.push(why);
            continue;
        }
        names.sort();
        for path in names {
            match read(&path) {
                Ok(s) => found.push((path, s)),
                Err(_) if !path.exists() => {}
                Err(e) => problems.push(e),
            }
        }
    }
    (found, problems)
}

/// The start time of process `pid` (field 22 of `/proc/<pid>/stat`: clock ticks after boot).
pub fn process_start(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2, in parentheses) may hold spaces and parentheses itself.
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(19)?.parse().ok()
}

/// Whether the process that wrote the state still runs: its pid is alive and, where the file
/// records it, started when the writer did (a pid used again is another process). True where
/// that cannot be told (no `/proc`).
pub fn writer_alive(s: &Snapshot) -> bool {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return true;
    }
    match s.pid_start {
        Some(t) => process_start(s.pid) == Some(t),
        None => proc.join(s.pid.to_string()).exists(),
    }
}

/// Whether the daemon of this state runs: not `stopped`, and its writer alive.
pub fn running(s: &Snapshot) -> bool {
    s.daemon != "stopped" && writer_alive(s)
}

/// The state restricted to the projects that concern `folder` (the project itself, a folder in
/// it, or a folder it is in, such as a root); `None` when none does.
pub fn watching(s: &Snapshot, folder: &Path) -> Option<Snapshot> {
    let canon = |p: &Path| {
        std::fs::canonicalize(p).unwrap_or_else(|_| {
            std::env::current_dir()
                .map(|d| d.join(p))
                .unwrap_or_else(|_| p.to_owned())
        })
    };
    let folder = canon(folder);
    let projects: Vec<ProjectState> = s
        .projects
        .iter()
        .filter(|p| {
            let p = canon(Path::new(&p.project));
            p.starts_with(&folder) || folder.starts_with(&p)
        })
        .cloned()
        .collect();
    (!projects.is_empty()).then(|| Snapshot {
        projects,
        ..s.clone()
    })
}

/// Before a daemon's first write to `path` (a `status-<pid>.json` of a daemon started by hand):
/// removes the state files beside it of daemons that no longer run, so stopped daemons' files
/// do not pile up (the last ones stay until the next start, for `skillpost status`).
fn sweep_stopped(path: &Path) {
    let own = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    if own == FILE_NAME || !is_state_name(own) {
        return;
    }
    let Some(Ok(entries)) = path.parent().map(std::fs::read_dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        if name.to_str().is_none_or(|n| n == own || !is_state_name(n)) {
            continue;
        }
        if read(&e.path()).is_ok_and(|s| !running(&s)) {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// Reads a state file.
pub fn read(path: &Path) -> Result<Snapshot, String> {
    // Without blocking, a regular file only, at most MAX_STATE bytes: a FIFO, `/dev/zero` or a
    // huge file at the path is an error at once, not a hang or a read without end.
    let text = crate::load::read_limited(path, MAX_STATE)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    serde_json::from_slice(&text)
        .map_err(|e| format!("{} is not a skillpost state file: {e}", path.display()))
}

/// The largest state file `skillpost status` reads (64 MiB: 100,000 projects' lines fit).
const MAX_STATE: u64 = 64 << 20;

/// Whether a folder the state file is looked for in without `--state` is one only its owner
/// can write to, and that owner is this user, root, or a user whose folder only a privileged
/// one could have made (its parent is root's and not writable by others, like `/run`): a
/// folder another user made first in `/tmp` (`/tmp/skillpost-<uid>`) is not trusted. The
/// reason when not.
pub fn untrusted_folder(dir: &Path) -> Option<String> {
    use std::os::unix::fs::MetadataExt as _;
    let m = match std::fs::symlink_metadata(dir) {
        Ok(m) => m,
        Err(e) => return Some(format!("{}: {e}", dir.display())),
    };
    let me = rustix::process::getuid().as_raw();
    let parent_privileged = dir
        .parent()
        .and_then(|p| std::fs::symlink_metadata(p).ok())
        .is_some_and(|p| p.uid() == 0 && p.mode() & 0o022 == 0);
    if !m.is_dir() || m.mode() & 0o022 != 0 || !(m.uid() == me || m.uid() == 0 || parent_privileged)
    {
        return Some(format!(
            "{} is not a folder of this user (or of a service) that only its owner can write to; \
             not reading a state file from it (name the file with --state)",
            dir.display()
        ));
    }
    None
}

/// The state as an aligned table (spaces, no tabs), with a heading line.
pub fn table(s: &Snapshot) -> String {
    let mut out = if s.daemon == "stopped" {
        format!(
            "skillpost {} (pid {}) stopped; last state written {}\n",
            s.version, s.pid, s.updated
        )
    } else {
        format!(
            "skillpost {} (pid {}) {} since {}: {}\n",
            s.version, s.pid, s.daemon, s.started, s.summary
        )
    };
    if s.daemon != "stopped" && !writer_alive(s) {
        out.push_str(&format!(
            "warning: pid {} is not running: the daemon ended without updating this state\n",
            s.pid
        ));
    }
    if s.projects.is_empty() {
        return out;
    }
    out.push('\n');
    let header = [
        "PROJECT", "RESULT", "LAST RUN", "ERRORS", "WARNINGS", "OUTPUTS",
    ];
    let rows: Vec<[String; 6]> = s
        .projects
        .iter()
        .map(|p| {
            // A project waiting for its folder: why (its outputs may be gone with the folder).
            let outputs = if let Some(w) = &p.waiting {
                w.clone()
            } else if p.result == "failed" {
                p.first_error.clone().unwrap_or_default()
            } else {
                let name = |o: &String| {
                    Path::new(o)
                        .file_name()
                        .map_or_else(|| o.clone(), |n| n.to_string_lossy().into_owned())
                };
                let mut s = p.outputs.iter().map(name).collect::<Vec<_>>().join(", ");
                if !p.stale.is_empty() {
                    s.push_str(&format!(
                        "; stale (not written, kept): {}",
                        p.stale.iter().map(name).collect::<Vec<_>>().join(", ")
                    ));
                }
                s
            };
            [
                p.project.clone(),
                p.result.clone(),
                p.time.clone().unwrap_or_else(|| "-".into()),
                p.errors.to_string(),
                p.warnings.to_string(),
                outputs,
            ]
        })
        .collect();
    out.push_str(&aligned(header, &rows));
    out.push_str(&deploy_table(s));
    out.push_str(&simulation_table(s));
    out
}

/// The last simulation of each project that simulates (nothing when none does).
fn simulation_table(s: &Snapshot) -> String {
    let header = ["PROJECT", "SIMULATION", "WHEN", "CYCLE", "FIRST PROBLEM"];
    let rows: Vec<[String; 5]> = s
        .projects
        .iter()
        .filter_map(|p| {
            let sim = p.simulation.as_ref()?;
            Some([
                p.project.clone(),
                format!(
                    "{} ({} run{})",
                    sim.result,
                    sim.runs,
                    if sim.runs == 1 { "" } else { "s" }
                ),
                sim.time.clone(),
                sim.cycle_s
                    .map_or_else(|| "-".into(), |c| format!("{c:.2} s")),
                sim.problem.clone().unwrap_or_default(),
            ])
        })
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    format!("\n{}", aligned(header, &rows))
}

/// The last deploy of each program, under the projects (nothing when no project deploys).
fn deploy_table(s: &Snapshot) -> String {
    let header = ["PROJECT", "PROGRAM", "DEPLOY", "WHEN", "WHY"];
    let rows: Vec<[String; 5]> = s
        .projects
        .iter()
        .flat_map(|p| {
            p.deploys.iter().map(|d| {
                [
                    p.project.clone(),
                    match &d.controller {
                        Some(c) => format!("{} ({c})", d.program),
                        None => d.program.clone(),
                    },
                    d.result.clone(),
                    d.time.clone(),
                    d.reason.clone().unwrap_or_default(),
                ]
            })
        })
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    format!("\n{}", aligned(header, &rows))
}

/// Rows under their header, each column as wide as its widest cell plus two spaces; line
/// breaks and tabs in a cell become spaces, no trailing blanks.
/// `s` with its control characters escaped (`\u{1b}`; a tab and line breaks become spaces
/// first where a caller wants that): what a table or a log line shows of a name from disk.
pub fn printable(s: &str) -> std::borrow::Cow<'_, str> {
    if !s.chars().any(char::is_control) {
        return std::borrow::Cow::Borrowed(s);
    }
    std::borrow::Cow::Owned(crate::paths::escaped(std::path::Path::new(s)))
}

fn aligned<const N: usize>(header: [&str; N], rows: &[[String; N]]) -> String {
    let rows: Vec<[String; N]> = rows
        .iter()
        .map(|r| {
            r.each_ref()
                .map(|c| printable(&c.replace(['\t', '\n', '\r'], " ")).into_owned())
        })
        .collect();
    let rows = &rows[..];
    let mut width = header.map(|h| h.chars().count());
    for r in rows {
        for (w, c) in width.iter_mut().zip(r) {
            *w = (*w).max(c.chars().count());
        }
    }
    let line = |cells: &[&str]| {
        let mut l = String::new();
        for (i, c) in cells.iter().enumerate() {
            let c = c.replace(['\t', '\n', '\r'], " ");
            l.push_str(&c);
            if i + 1 < cells.len() {
                l.push_str(&" ".repeat(width[i] - c.chars().count() + 2));
            }
        }
        l.truncate(l.trim_end().len());
        l.push('\n');
        l
    };
    let mut out = line(&header);
    for r in rows {
        out.push_str(&line(&r.each_ref().map(String::as_str)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::daemon::events::{Counts, OutputInfo};

    #[test]
    fn the_status_line_reads_like_a_sentence() {
        let s = |projects, failing, compiling, pending, directories| {
            sentence(Tally {
                projects,
                failing,
                compiling,
                pending,
                waiting: 0,
                directories,
            })
        };
        assert_eq!(
            s(4, 1, 0, 0, 9),
            "4 projects, 1 failing; watching 9 directories"
        );
        assert_eq!(
            s(1, 0, 0, 0, 1),
            "1 project, all compiled; watching 1 directory"
        );
        assert_eq!(
            s(3, 2, 1, 0, 6),
            "3 projects, 2 failing, 1 compiling; watching 6 directories"
        );
        assert_eq!(
            s(2, 0, 2, 0, 4),
            "2 projects, 2 compiling; watching 4 directories"
        );
        assert_eq!(
            s(2, 0, 0, 1, 3),
            "2 projects, 1 not compiled yet; watching 3 directories"
        );
        assert_eq!(s(0, 0, 0, 0, 0), "0 projects; watching 0 directories");
        let w = |projects, pending, waiting| {
            sentence(Tally {
                projects,
                pending,
                waiting,
                directories: 2,
                ..Tally::default()
            })
        };
        assert_eq!(
            w(1, 0, 1),
            "1 project, 1 waiting for its folder; watching 2 directories"
        );
        assert_eq!(
            w(3, 1, 2),
            "3 projects, 1 not compiled yet, 2 waiting for their folders; watching 2 directories"
        );
    }

    #[test]
    fn a_project_whose_folder_does_not_exist_yet_is_waiting_for_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("status.json");
        let t = Tracker::new(Some(path.clone()));
        let why = "the project folder does not exist; waiting for it";
        t.observe(
            Some("/p/not-yet"),
            &Event::WatchDegraded {
                root: None,
                reason: why.into(),
                backend: Some("none"),
            },
        );
        let projects = [Path::new("/p/not-yet"), Path::new("/p/other")];
        let s = t.sync(projects.iter().copied(), 0, 2, true);
        assert_eq!(
            s,
            "2 projects, 1 not compiled yet, 1 waiting for its folder; watching 2 directories"
        );
        let snap = read(&path).unwrap();
        assert_eq!(snap.projects[0].result, "waiting");
        assert_eq!(snap.projects[0].waiting.as_deref(), Some(why));
        assert_eq!(snap.projects[1].result, "pending");
        assert_eq!(snap.projects[1].waiting, None);
        let text = table(&snap);
        assert!(
            text.lines()
                .any(|l| l.contains("/p/not-yet") && l.contains("waiting") && l.contains(why)),
            "{text}"
        );
        // The folder appears: watched, then compiled; no longer waiting.
        t.observe(
            Some("/p/not-yet"),
            &Event::Watching {
                root: None,
                blackboard: None,
                backend: "inotify",
                reason: Some("the project folder is back".into()),
                program: None,
            },
        );
        std::thread::sleep(MIN_WRITE_INTERVAL);
        let s = t.sync(projects.iter().copied(), 0, 2, true);
        assert_eq!(s, "2 projects, 2 not compiled yet; watching 2 directories");
        let snap = read(&path).unwrap();
        assert_eq!(snap.projects[0].result, "pending");
        assert_eq!(snap.projects[0].waiting, None);
    }

    #[test]
    fn a_state_whose_daemon_is_gone_says_so() {
        let mut snap = Snapshot {
            schema: SCHEMA.into(),
            version: "0".into(),
            pid: std::process::id(),
            pid_start: None,
            started: now(),
            updated: now(),
            daemon: "running".into(),
            compiling: 0,
            summary: "0 projects; watching 0 directories".into(),
            projects: vec![],
        };
        assert!(!table(&snap).contains("warning"), "{}", table(&snap));
        // Above the kernel's largest pid (4194304).
        snap.pid = 4_194_400;
        assert!(table(&snap).contains("warning: pid 4194400 is not running"));
        snap.daemon = "stopped".into();
        assert!(!table(&snap).contains("warning"));
    }

    #[test]
    fn state_files_are_told_by_name_and_rows_by_folder() {
        for n in ["status.json", "status-42.json"] {
            assert!(is_state_name(n), "{n}");
        }
        for n in [
            "status-.json",
            "status-4a.json",
            ".status-x.tmp",
            "status-42.json.tmp",
        ] {
            assert!(!is_state_name(n), "{n}");
        }
        let row = |p: &str| ProjectState {
            project: p.into(),
            result: "ok".into(),
            ..ProjectState::default()
        };
        let snap = Snapshot {
            schema: SCHEMA.into(),
            version: "0".into(),
            pid: 1,
            pid_start: None,
            started: now(),
            updated: now(),
            daemon: "running".into(),
            compiling: 0,
            summary: String::new(),
            projects: vec![
                row("/srv/cells/A"),
                row("/srv/cells/AB"),
                row("/srv/other/C"),
            ],
        };
        let of = |f: &str| {
            watching(&snap, Path::new(f)).map(|s| {
                s.projects
                    .into_iter()
                    .map(|p| p.project)
                    .collect::<Vec<_>>()
            })
        };
        // The project, a folder in it, a root holding it; never a sibling with a longer name.
        assert_eq!(of("/srv/cells/A").unwrap(), ["/srv/cells/A"]);
        assert_eq!(of("/srv/cells/A/sub").unwrap(), ["/srv/cells/A"]);
        assert_eq!(of("/srv/cells").unwrap(), ["/srv/cells/A", "/srv/cells/AB"]);
        assert_eq!(of("/srv/nothing"), None);
    }

    #[test]
    fn describes_a_diagnostic_on_one_line() {
        let d = serde_json::json!({"severity": "error", "code": "E604", "message": "cannot write",
            "file": "a/P.src", "line": 3, "column": 7});
        assert_eq!(describe(&d), "E604 a/P.src:3:7: cannot write");
        let d = serde_json::json!({"severity": "error", "code": "E000", "message": "boom"});
        assert_eq!(describe(&d), "E000: boom");
    }

    #[test]
    fn results_are_written_atomically_and_printed_aligned() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("status.json");
        let t = Tracker::new(Some(path.clone()));
        t.observe(
            Some("/p/Zelle_A"),
            &Event::CompileSucceeded {
                run_id: 1,
                duration_ms: 5,
                outputs: vec![OutputInfo {
                    path: "/p/Zelle_A/Zelle_A.src".into(),
                    written: true,
                    program: "Zelle_A".into(),
                    controller: Some("KUKA KR15-2".into()),
                }],
                stale: vec![],
                counts: Counts {
                    steps: 3,
                    warnings: 1,
                },
                warnings: vec![],
            },
        );
        t.observe(
            Some("/p/B"),
            &Event::failed_with(2, 1, "E604", "cannot write".into()),
        );
        let projects = [
            Path::new("/p/B"),
            Path::new("/p/C"),
            Path::new("/p/Zelle_A"),
        ];
        let s = t.sync(projects.iter().copied(), 0, 6, true);
        assert_eq!(
            s,
            "3 projects, 1 failing, 1 not compiled yet; watching 6 directories"
        );
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        assert_eq!(names, ["status.json"], "no temporary file left");
        let snap = read(&path).unwrap();
        assert_eq!(snap.projects.len(), 3);
        assert_eq!(snap.projects[0].result, "failed");
        assert_eq!(snap.projects[1].result, "pending");
        assert_eq!(snap.projects[2].outputs, ["/p/Zelle_A/Zelle_A.src"]);
        let text = table(&snap);
        assert!(!text.contains('\t'), "{text}");
        let lines: Vec<&str> = text.lines().skip(2).collect();
        let col = lines[0].find("RESULT").unwrap();
        for l in &lines[1..] {
            assert_eq!(&l[col - 2..col], "  ", "aligned: {text}");
            assert!(!l[col..].starts_with(' '), "aligned: {text}");
        }
        assert!(text.contains("E604: cannot write"), "{text}");
        // A removed project leaves the file at the next sync, once the rate limit allows.
        t.sync([Path::new("/p/Zelle_A")].into_iter(), 0, 2, true);
        assert_eq!(read(&path).unwrap().projects.len(), 3, "held back");
        std::thread::sleep(MIN_WRITE_INTERVAL);
        t.sync([Path::new("/p/Zelle_A")].into_iter(), 0, 2, true);
        assert_eq!(read(&path).unwrap().projects.len(), 1);
        t.observe(
            None,
            &Event::Stopped {
                reason: "SIGTERM".into(),
                requested: None,
                compiling: None,
            },
        );
        let snap = read(&path).unwrap();
        assert_eq!(snap.daemon, "stopped");
        assert!(table(&snap).contains("stopped"));
    }
}
