//! Helpers shared by the integration tests (`mod common;` in a test file).

#![allow(dead_code)]

pub mod rapid;
pub mod urscript;

/// Skips a test that cannot run on this machine: prints `skipped: <reason>` and returns, so the
/// caller `return`s next. Under `SKILLPOST_STRICT_TESTS=1` (CI sets it) it fails instead, so a
/// machine that silently cannot run a test does not pass for one that ran it.
pub fn skip(reason: &str) {
    if strict() {
        panic!("cannot run here: {reason} (SKILLPOST_STRICT_TESTS=1 makes this a failure)");
    }
    eprintln!("skipped: {reason}");
}

/// `text` with `insert` put in after the `n`th `</step>` (from the start), and where it went in.
pub fn with_after_step_at(text: &[u8], n: usize, insert: &[u8]) -> (Vec<u8>, usize) {
    let s = String::from_utf8_lossy(text);
    let at = s
        .match_indices("</step>")
        .nth(n)
        .map(|(i, m)| i + m.len())
        .expect("enough steps");
    let mut out = text[..at].to_vec();
    out.extend_from_slice(insert);
    out.extend_from_slice(&text[at..]);
    (out, at)
}

/// [`with_after_step_at`] without the place.
pub fn with_after_step(text: &[u8], n: usize, insert: &[u8]) -> Vec<u8> {
    with_after_step_at(text, n, insert).0
}

/// Whether `SKILLPOST_STRICT_TESTS=1` is set.
pub fn strict() -> bool {
    std::env::var("SKILLPOST_STRICT_TESTS").as_deref() == Ok("1")
}

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

/// The reference sample project.
/// A fixture's `base` (`case.toml`, `expect.toml`): one folder of `fixtures/base/`, or several,
/// copied in order (later ones over earlier ones).
#[derive(Debug, serde::Deserialize)]
#[serde(untagged)]
pub enum Bases {
    One(String),
    Many(Vec<String>),
}

impl Bases {
    pub fn list(&self) -> Vec<&str> {
        match self {
            Bases::One(b) => vec![b.as_str()],
            Bases::Many(v) => v.iter().map(String::as_str).collect(),
        }
    }
}

pub fn sample() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ok/reference-sample")
}

/// The files below `fixtures/` whose name ends in `.{ext}`, sorted.
pub fn fixture_files(ext: &str) -> Vec<PathBuf> {
    fn walk(dir: &Path, ext: &str, out: &mut Vec<PathBuf>) {
        for e in fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, ext, out);
            } else if p.extension().is_some_and(|e| e == ext) {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    walk(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures"),
        ext,
        &mut out,
    );
    out.sort();
    out
}

/// Every XML fixture (more than 100 of them), named by its path, as the SFC reader gets it: the
/// compile strips one byte-order mark before the reader.
pub fn fixture_xml() -> Vec<(String, Vec<u8>)> {
    let files = fixture_files("xml");
    assert!(files.len() > 100, "fixtures found: {}", files.len());
    files
        .iter()
        .map(|f| {
            let mut text = fs::read(f).unwrap();
            if text.starts_with(b"\xEF\xBB\xBF") {
                text.drain(..3);
            }
            (f.display().to_string(), text)
        })
        .collect()
}

/// Copies the regular files of the reference sample into `dir`.
pub fn copy_sample(dir: &Path) {
    for e in fs::read_dir(sample()).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            fs::copy(e.path(), dir.join(e.file_name())).unwrap();
        }
    }
}

/// A running `skillpost watch --events FILE --settle MS <args>`, killed when dropped.
pub struct Watch {
    child: Child,
    pub events: PathBuf,
    stderr: PathBuf,
}

impl Watch {
    /// Starts the daemon in `cwd` (events and log go there) and waits for `started`.
    pub fn start(cwd: &Path, settle_ms: u64, args: &[&str]) -> Watch {
        Self::start_bin(
            Path::new(env!("CARGO_BIN_EXE_skillpost")),
            cwd,
            settle_ms,
            args,
        )
    }

    /// [`Watch::start`] with another binary (an older build, to show a test catches its bug).
    pub fn start_bin(bin: &Path, cwd: &Path, settle_ms: u64, args: &[&str]) -> Watch {
        let events = cwd.join("events.jsonl");
        let stderr = cwd.join("stderr.log");
        let child = Command::new(bin)
            .arg("watch")
            .arg("--events")
            .arg(&events)
            .arg("--settle")
            .arg(settle_ms.to_string())
            .args(args)
            .current_dir(cwd)
            .env("RUST_LOG", "info")
            // The daemon's folder locks stay in the test's workspace.
            .env_remove("RUNTIME_DIRECTORY")
            .env("XDG_RUNTIME_DIR", cwd)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(fs::File::create(&stderr).unwrap())
            .spawn()
            .unwrap();
        let mut w = Watch {
            child,
            events,
            stderr,
        };
        w.wait_for("started", Duration::from_secs(20), |e| {
            e["event"] == "started"
        });
        w
    }

    /// Every complete event line so far.
    pub fn events(&self) -> Vec<Value> {
        let text = fs::read_to_string(&self.events).unwrap_or_default();
        text.lines()
            .filter(|l| !l.is_empty())
            .filter_map(|l| serde_json::from_str(l).ok())
            .collect()
    }

    /// Waits until an event matching `pred` appears; returns all events by then. Fails (with
    /// the events and the log) on a timeout or when the daemon exits.
    pub fn wait_for(
        &mut self,
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
            if let Some(st) = self.child.try_wait().unwrap() {
                self.fail(&format!(
                    "the daemon exited ({st}) while waiting for {what}"
                ));
            }
            if Instant::now() >= deadline {
                self.fail(&format!("timed out after {timeout:?} waiting for {what}"));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Whether the daemon is still running.
    pub fn alive(&mut self) -> bool {
        self.child.try_wait().unwrap().is_none()
    }

    /// Panics with the event stream and the daemon's log.
    pub fn fail(&self, msg: &str) -> ! {
        let ev = fs::read_to_string(&self.events).unwrap_or_default();
        let tail: Vec<&str> = ev.lines().rev().take(60).collect();
        panic!(
            "{msg}\n--- last events ---\n{}\n--- stderr ---\n{}",
            tail.into_iter().rev().collect::<Vec<_>>().join("\n"),
            fs::read_to_string(&self.stderr).unwrap_or_default()
        );
    }
}

impl Drop for Watch {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `setpriv` running what follows as `nobody` (uid and gid 65534) without any capability: an
/// unprivileged user, for the tests of what such a user may not do. `None` (the test is skipped,
/// saying why `what` cannot be tried, and fails under `SKILLPOST_STRICT_TESTS=1`) when this
/// process is not root or has no `setpriv`.
pub fn as_nobody(what: &str) -> Option<std::process::Command> {
    if !rustix::process::geteuid().is_root() {
        skip(&format!("not root: cannot {what}"));
        return None;
    }
    if std::process::Command::new("setpriv")
        .arg("--version")
        .output()
        .is_err()
    {
        skip("no setpriv (util-linux)");
        return None;
    }
    let mut c = std::process::Command::new("setpriv");
    c.args([
        "--reuid=65534",
        "--regid=65534",
        "--clear-groups",
        "--inh-caps=-all",
        "--bounding-set=-all",
    ]);
    Some(c)
}

/// Runs the test `name` of this test binary again, alone, in a sandbox: `TMPDIR`, `HOME` and
/// `XDG_RUNTIME_DIR` are empty folders of a temporary directory and `RUNTIME_DIRECTORY` is
/// unset, so whatever the test and the daemons it starts leave behind — in the default runtime
/// folder (`$TMPDIR/skillpost-<uid>`, `$XDG_RUNTIME_DIR/skillpost`: lock notes, the state
/// file) or anywhere else there — is found. Panics when the test fails; returns the paths left
/// in the sandbox (empty: everything went into temporary folders that were removed).
pub fn leftovers_of(name: &str) -> Vec<PathBuf> {
    use std::os::unix::fs::PermissionsExt;
    let sandbox = tempfile::tempdir().unwrap();
    let dirs = ["tmp", "home", "xdg"].map(|d| sandbox.path().join(d));
    for d in &dirs {
        fs::create_dir(d).unwrap();
        fs::set_permissions(d, fs::Permissions::from_mode(0o700)).unwrap();
    }
    let out = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", name, "--test-threads", "1"])
        .env("TMPDIR", &dirs[0])
        .env("HOME", &dirs[1])
        .env("XDG_RUNTIME_DIR", &dirs[2])
        .env_remove("RUNTIME_DIRECTORY")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && stdout.contains("1 passed"),
        "{name} in the sandbox:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    fn walk(dir: &Path, found: &mut Vec<PathBuf>) {
        for e in fs::read_dir(dir).into_iter().flatten().flatten() {
            found.push(e.path());
            if e.file_type().is_ok_and(|t| t.is_dir()) {
                walk(&e.path(), found);
            }
        }
    }
    let mut found = Vec::new();
    for d in &dirs {
        walk(d, &mut found);
    }
    found
}

/// A copy of `fixtures/ok/<name>` with its bases, in a temporary folder (as `ok_fixtures`
/// builds it).
pub fn fixture_project(name: &str) -> tempfile::TempDir {
    fn copy_dir(from: &Path, to: &Path) {
        for e in fs::read_dir(from).unwrap() {
            let e = e.unwrap();
            let target = to.join(e.file_name());
            if e.file_type().unwrap().is_dir() {
                fs::create_dir_all(&target).unwrap();
                copy_dir(&e.path(), &target);
            } else {
                fs::copy(e.path(), &target).unwrap();
            }
        }
    }
    #[derive(serde::Deserialize)]
    struct Case {
        base: Option<Bases>,
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let case_dir = root.join("ok").join(name);
    let case: Case = toml::from_str(&fs::read_to_string(case_dir.join("case.toml")).unwrap())
        .unwrap_or_else(|e| panic!("{name}: case.toml: {e}"));
    let tmp = tempfile::tempdir().unwrap();
    for base in case.base.iter().flat_map(Bases::list) {
        copy_dir(&root.join("base").join(base), tmp.path());
    }
    copy_dir(&case_dir, tmp.path());
    tmp
}
