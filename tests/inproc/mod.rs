//! A reusable harness that runs the daemon **in this process**: `skillpost::daemon::run` on a
//! thread of its own with its own tokio runtime, events into a shared buffer
//! (`EventSink::to`), and the control channel (`Control::Reload`, `Control::Stop`) instead of
//! signals. Real file operations still need real time (inotify), so waits poll the buffer for an
//! expected event until a deadline; nothing sleeps for a fixed time to "let things settle"
//! except where a test checks that nothing happens.
//!
//! Use it from a test file with `mod inproc;` (see tests/daemon_inproc.rs):
//!
//! ```ignore
//! let w = inproc::Workspace::new();
//! let a = w.project("A");
//! let d = inproc::InProc::with_dirs(&[&a]);
//! d.startup(&[&a]);
//! std::fs::write(a.join("sfc.xml"), inproc::sfc_with_x(111)).unwrap();
//! d.wait_for("the recompile", inproc::WAIT, |e| inproc::is_for(e, "compile-succeeded", &a));
//! d.stop(inproc::WAIT);
//! ```

#![allow(dead_code)]

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::thread::sleep;
use std::time::{Duration, Instant};

use serde_json::Value;
use skillpost::daemon::config::Config;
use skillpost::daemon::events::EventSink;
use skillpost::daemon::{self, Control, Sources};

/// The quiet period the daemons of these tests run with (ms).
pub const SETTLE_MS: u64 = 50;
/// The longest any expected event may take to appear.
pub const WAIT: Duration = Duration::from_secs(5);
/// The project files copied from the reference sample.
pub const FILES: [&str; 3] = ["Blackboard.aml", "sfc.xml", "kr15-2.irl"];

// ---------------------------------------------------------------------------------------------
// Files
// ---------------------------------------------------------------------------------------------

pub fn sample() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ok/reference-sample")
}

pub fn sample_text(name: &str) -> String {
    fs::read_to_string(sample().join(name)).unwrap()
}

/// The reference sample's SFC with the first PTP's x set to `x` (originally 100).
pub fn sfc_with_x(x: u32) -> String {
    let orig = sample_text("sfc.xml");
    assert!(orig.contains("(100, 200, 300,"));
    orig.replace("(100, 200, 300,", &format!("({x}, 200, 300,"))
}

/// What the `.src` holds for that x.
pub fn ptp_with_x(x: u32) -> String {
    format!("PTP {{X {x}, Y 200, Z 300")
}

/// Copies the reference sample's inputs into `dir` (created).
pub fn copy_project(dir: &Path) {
    fs::create_dir_all(dir).unwrap();
    for f in FILES {
        fs::copy(sample().join(f), dir.join(f)).unwrap();
    }
    literal_points(dir);
}

/// Copies the fixtures' folders `layers` (relative to `fixtures/`, e.g. `base/cell`) into `dir`
/// (created), each over the one before, without their `case.toml` and `README.txt`: a
/// fixture case as a project folder (`["base/cell", "base/cell2", "ok/cell-tell-at-once"]`, a
/// two-controller cell).
pub fn copy_fixture_layers(dir: &Path, layers: &[&str]) {
    fs::create_dir_all(dir).unwrap();
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    for layer in layers {
        for e in fs::read_dir(fixtures.join(layer)).unwrap() {
            let e = e.unwrap();
            let name = e.file_name();
            if name != "case.toml" && name != "README.txt" {
                fs::copy(e.path(), dir.join(name)).unwrap();
            }
        }
    }
}

/// The layers of a two-controller cell for [`copy_fixture_layers`].
pub const TWO_CONTROLLER_CELL: [&str; 3] = ["base/cell", "base/cell2", "ok/cell-tell-at-once"];

pub fn src_of(project: &Path) -> PathBuf {
    project.join("Blackboard.src")
}

pub fn read_string(p: &Path) -> String {
    fs::read_to_string(p).unwrap_or_default()
}

/// Creates a FIFO (named pipe) at `path`.
pub fn mkfifo(path: &Path) {
    rustix::fs::mknodat(
        rustix::fs::CWD,
        path,
        rustix::fs::FileType::Fifo,
        rustix::fs::Mode::from_raw_mode(0o644),
        0,
    )
    .unwrap();
}

/// Polls `cond` until it holds or `timeout` passes; returns whether it held.
pub fn wait_until(timeout: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + timeout;
    loop {
        if cond() {
            return true;
        }
        if Instant::now() >= deadline {
            return false;
        }
        sleep(Duration::from_millis(10));
    }
}

/// A temporary folder (canonical path) with `ws/` for the projects.
pub struct Workspace {
    _tmp: tempfile::TempDir,
    pub root: PathBuf,
}

impl Default for Workspace {
    fn default() -> Self {
        Self::new()
    }
}

impl Workspace {
    pub fn new() -> Self {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().canonicalize().unwrap();
        fs::create_dir(root.join("ws")).unwrap();
        Workspace { _tmp: tmp, root }
    }

    pub fn ws(&self) -> PathBuf {
        self.root.join("ws")
    }

    /// A fresh copy of the reference sample as `ws/<name>`.
    pub fn project(&self, name: &str) -> PathBuf {
        let dir = self.ws().join(name);
        copy_project(&dir);
        dir
    }

    /// Writes `skillpost.toml` in the workspace root.
    pub fn config(&self, text: &str) -> PathBuf {
        let p = self.root.join("skillpost.toml");
        fs::write(&p, text).unwrap();
        p
    }
}

// ---------------------------------------------------------------------------------------------
// Events
// ---------------------------------------------------------------------------------------------

pub fn seq(e: &Value) -> u64 {
    e["seq"].as_u64().unwrap()
}

pub fn is(e: &Value, event: &str) -> bool {
    e["event"] == event
}

pub fn project_is(e: &Value, project: &Path) -> bool {
    e["project"].as_str() == Some(project.to_str().unwrap())
}

pub fn is_for(e: &Value, event: &str, project: &Path) -> bool {
    is(e, event) && project_is(e, project)
}

/// `event` for `project` after the mark `since`.
pub fn is_after(e: &Value, event: &str, project: &Path, since: u64) -> bool {
    seq(e) > since && is_for(e, event, project)
}

pub fn count_after(evs: &[Value], event: &str, project: &Path, since: u64) -> usize {
    evs.iter()
        .filter(|e| is_after(e, event, project, since))
        .count()
}

pub fn dump(evs: &[Value]) -> String {
    evs.iter().map(|e| format!("{e}\n")).collect()
}

/// A writer into a shared buffer (the event stream of an in-process daemon).
#[derive(Clone, Default)]
pub struct Buffer(pub Arc<Mutex<Vec<u8>>>);

impl Write for Buffer {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// The daemon
// ---------------------------------------------------------------------------------------------

/// The folder of the lock notes of this process's daemons: a temporary folder shared by those
/// running at the same time, removed when the last one has ended (each daemon's thread holds
/// it), so a test run leaves nothing behind, in the real runtime folder or elsewhere.
fn shared_runtime_dir() -> Arc<tempfile::TempDir> {
    static RUN: Mutex<std::sync::Weak<tempfile::TempDir>> = Mutex::new(std::sync::Weak::new());
    let mut run = RUN.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(d) = run.upgrade() {
        return d;
    }
    let d = Arc::new(
        tempfile::Builder::new()
            .prefix("skillpost-test-run-")
            .tempdir()
            .unwrap(),
    );
    *run = Arc::downgrade(&d);
    d
}

/// A daemon running in this process; stopped (and waited for, boundedly) when dropped.
pub struct InProc {
    buf: Buffer,
    /// With [`InProc::start_appending`]: the events file and this run's `instance`.
    file: Option<(PathBuf, String)>,
    tx: tokio::sync::mpsc::UnboundedSender<Control>,
    thread: Option<std::thread::JoinHandle<Result<(), String>>>,
}

impl InProc {
    /// Runs the daemon on `config`; waits for `started`. `Err`: `run` returned before (with
    /// its error, e.g. another daemon keeps a folder).
    pub fn try_start(config: Config, sources: Sources) -> Result<Self, String> {
        Self::spawn(config, sources, false)
    }

    /// Runs the daemon under tokio's paused clock: whenever it has nothing to do, its clock
    /// jumps to its next timer, so the daemon's own periods (the 2 s checks, `forget_after_s`,
    /// quiet periods) pass at once while file events still arrive in real time. For what
    /// depends on the daemon's timers, not on how fast the kernel reports.
    pub fn start_paused(config: Config, sources: Sources) -> Self {
        Self::spawn(config, sources, true).unwrap_or_else(|e| panic!("the daemon stopped: {e}"))
    }

    /// Like [`InProc::start`], with the state file at `state` (as `--state`).
    pub fn start_with_state(config: Config, sources: Sources, state: &Path) -> Self {
        Self::spawn_with(config, sources, false, Some(state.to_owned()), None)
            .unwrap_or_else(|e| panic!("the daemon stopped: {e}"))
    }

    /// Like [`InProc::start`], with the events appended to the configuration's events file
    /// (`Sources::events`, as `--events FILE`; reopened by a reload), where other runs may have
    /// written before; [`InProc::events`] reads this run's lines.
    pub fn start_appending(config: Config, sources: Sources) -> Self {
        let events = config
            .events
            .clone()
            .expect("an events file (Sources::events)");
        Self::spawn_with(config, sources, false, None, Some(events))
            .unwrap_or_else(|e| panic!("the daemon stopped: {e}"))
    }

    fn spawn(config: Config, sources: Sources, paused: bool) -> Result<Self, String> {
        Self::spawn_with(config, sources, paused, None, None)
    }

    fn spawn_with(
        config: Config,
        mut sources: Sources,
        paused: bool,
        state: Option<PathBuf>,
        events_file: Option<PathBuf>,
    ) -> Result<Self, String> {
        // The lock notes in a temporary folder, never in the real runtime folder: one shared by
        // the daemons running at the same time (so a refusal still names the holder's pid),
        // removed when the last of them has ended (issue 27, item 4).
        let run = sources.runtime_dir.is_none().then(shared_runtime_dir);
        if let Some(run) = &run {
            sources.runtime_dir = Some(run.path().to_owned());
        }
        let buf = Buffer::default();
        let (mut sink, file) = match events_file {
            // As `--events FILE`: appended to the file; this run's lines are those of its
            // `instance`.
            Some(path) => {
                let sink = EventSink::append(&path).map_err(|e| e.to_string())?;
                let instance = sink.instance().to_owned();
                (sink, Some((path, instance)))
            }
            None => (EventSink::to(Box::new(buf.clone())), None),
        };
        if let Some(state) = state {
            sink = sink.with_state_file(state);
        }
        let sink = Arc::new(sink);
        let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
        let thread = std::thread::spawn(move || {
            // The runtime folder lives as long as the daemon does.
            let _run = run;
            let rt = if paused {
                tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .start_paused(true)
                    .build()
            } else {
                tokio::runtime::Builder::new_multi_thread()
                    .worker_threads(2)
                    .enable_all()
                    .build()
            }
            .map_err(|e| e.to_string())?;
            rt.block_on(daemon::run(config, sources, sink, rx))
        });
        let d = InProc {
            buf,
            file,
            tx,
            thread: Some(thread),
        };
        let deadline = Instant::now() + WAIT;
        loop {
            if d.events().iter().any(|e| is(e, "started")) {
                return Ok(d);
            }
            if d.thread.as_ref().is_some_and(|t| t.is_finished()) {
                let mut d = d;
                let r = d.thread.take().unwrap().join().unwrap();
                return Err(r.err().unwrap_or_else(|| "stopped at once".into()));
            }
            assert!(Instant::now() < deadline, "no `started` within {WAIT:?}");
            sleep(Duration::from_millis(5));
        }
    }

    pub fn start(config: Config, sources: Sources) -> Self {
        Self::try_start(config, sources).unwrap_or_else(|e| panic!("the daemon stopped: {e}"))
    }

    /// The daemon on these project folders (as on the command line), quiet period
    /// [`SETTLE_MS`].
    pub fn with_dirs(dirs: &[&Path]) -> Self {
        let sources = Sources {
            dirs: dirs.iter().map(|d| d.to_path_buf()).collect(),
            settle_ms: Some(SETTLE_MS),
            ..Sources::default()
        };
        let config = sources.load().unwrap();
        Self::start(config, sources)
    }

    /// The daemon on a configuration file (reloaded by [`InProc::reload`]); quiet period
    /// [`SETTLE_MS`].
    pub fn with_config(file: &Path) -> Self {
        let sources = Sources {
            config_file: Some(file.to_owned()),
            settle_ms: Some(SETTLE_MS),
            ..Sources::default()
        };
        let config = sources.load().unwrap();
        Self::start(config, sources)
    }

    /// Every event so far.
    pub fn events(&self) -> Vec<Value> {
        let bytes = match &self.file {
            Some((path, _)) => fs::read(path).unwrap_or_default(),
            None => self.buf.0.lock().unwrap().clone(),
        };
        let text = String::from_utf8(bytes).expect("the event stream is UTF-8");
        text.lines()
            .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
            .filter(|e: &Value| match &self.file {
                Some((_, instance)) => e["instance"] == instance.as_str(),
                None => true,
            })
            .collect()
    }

    /// The `seq` of the last event so far (0 before any).
    pub fn mark(&self) -> u64 {
        self.events().last().map(seq).unwrap_or(0)
    }

    /// Waits until an event matching `pred` appears; returns every event seen by then. Panics
    /// with the event stream on timeout.
    pub fn wait_for(
        &self,
        what: &str,
        timeout: Duration,
        pred: impl Fn(&Value) -> bool,
    ) -> Vec<Value> {
        let deadline = Instant::now() + timeout;
        loop {
            let evs = self.events();
            if evs.iter().any(&pred) {
                return evs;
            }
            if self.thread.as_ref().is_some_and(|t| t.is_finished()) {
                panic!(
                    "the daemon stopped while waiting for {what}\n{}",
                    dump(&evs)
                );
            }
            if Instant::now() >= deadline {
                panic!(
                    "timed out after {timeout:?} waiting for {what}\n{}",
                    dump(&evs)
                );
            }
            sleep(Duration::from_millis(10));
        }
    }

    /// Waits for the startup compile (success and write-back) of each project, then lets the
    /// daemon see the events of its own writes.
    pub fn startup(&self, projects: &[&Path]) {
        for p in projects {
            self.wait_for(
                &format!("startup write-back of {}", p.display()),
                WAIT,
                |e| is_for(e, "write-back", p),
            );
        }
        sleep(Duration::from_millis(SETTLE_MS * 6));
    }

    /// `Control::Reload` (as `SIGHUP`).
    pub fn reload(&self) {
        self.tx.send(Control::Reload).unwrap();
    }

    /// `Control::Stop`, then waits for `run` to return; panics if it takes longer than
    /// `timeout`. Returns how long it took.
    pub fn stop(mut self, timeout: Duration) -> Duration {
        let t = Instant::now();
        let _ = self.tx.send(Control::Stop("test".into()));
        let thread = self.thread.take().unwrap();
        if !wait_until(timeout, || thread.is_finished()) {
            panic!(
                "the daemon did not stop within {timeout:?}\n{}",
                dump(&self.events())
            );
        }
        thread.join().unwrap().unwrap();
        t.elapsed()
    }
}

impl Drop for InProc {
    fn drop(&mut self) {
        let _ = self.tx.send(Control::Stop("test over".into()));
        if let Some(t) = self.thread.take() {
            // Bounded: a hung daemon must not hang the test run (its thread is left behind).
            if wait_until(WAIT, || t.is_finished()) {
                let _ = t.join();
            }
        }
    }
}

/// The daemon's tests read the compiled `.src` for the chart's values (`PTP {X 100, …}`): the
/// robot keeps literal positions (`Points` = `inline`, docs/LANGUAGES.md "Points").
pub fn literal_points(dir: &Path) {
    let bb = dir.join("Blackboard.aml");
    let text = fs::read_to_string(&bb).unwrap();
    let at = text.find("Name=\"KUKA KR15-2\"").unwrap();
    let end = at + text[at..].find('>').unwrap() + 1;
    let attr = "<Attribute Name=\"Points\"><Value>inline</Value></Attribute>";
    fs::write(&bb, format!("{}{attr}{}", &text[..end], &text[end..])).unwrap();
}
