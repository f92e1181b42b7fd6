//! The event stream under trouble, with the real binary: a reader that stops reading stdout, a
//! compile that hangs at shutdown, an events file rotated away (logrotate's `create` and
//! `copytruncate`), a full disk under the events file. In every case the daemon goes on
//! compiling, stops within a bound, and every line of the stream is one whole JSON object whose
//! `seq` grows, with gaps exactly where `events-dropped` says events were lost.
//!
//! The helpers are copied from tests/daemon.rs (kept small; that file is not shared).

mod common;

use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::sleep;
use std::time::{Duration, Instant};

use serde_json::Value;

const SETTLE_MS: &str = "50";
/// The longest any expected event may take to appear.
const WAIT: Duration = Duration::from_secs(10);
const FILES: [&str; 3] = ["Blackboard.aml", "sfc.xml", "kr15-2.irl"];

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

use common::skip;

fn sample() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ok/reference-sample")
}

fn copy_project(dir: &Path) {
    fs::create_dir_all(dir).unwrap();
    for f in FILES {
        fs::copy(sample().join(f), dir.join(f)).unwrap();
    }
    literal_points(dir);
}

/// Sets the first PTP's x in the project's SFC (originally 100).
fn edit(project: &Path, x: u32) {
    let orig = fs::read_to_string(sample().join("sfc.xml")).unwrap();
    assert!(orig.contains("(100, 200, 300,"));
    fs::write(
        project.join("sfc.xml"),
        orig.replace("(100, 200, 300,", &format!("({x}, 200, 300,")),
    )
    .unwrap();
}

fn compiled_with(project: &Path, x: u32) -> bool {
    fs::read_to_string(project.join("Blackboard.src"))
        .unwrap_or_default()
        .contains(&format!("PTP {{X {x}, Y 200, Z 300"))
}

fn wait_until(timeout: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + timeout;
    loop {
        if cond() {
            return true;
        }
        if Instant::now() >= deadline {
            return false;
        }
        sleep(Duration::from_millis(20));
    }
}

/// The lines of an event stream: every one must be a whole JSON object (the text ends with a
/// newline). Panics with the text otherwise.
fn parse_lines(text: &str, what: &str) -> Vec<Value> {
    assert!(
        text.is_empty() || text.ends_with('\n'),
        "{what} ends inside a line:\n{text}"
    );
    text.lines()
        .map(|l| {
            serde_json::from_str::<Value>(l)
                .unwrap_or_else(|e| panic!("{what}: a line is not JSON ({e}): {l:?}\n{text}"))
        })
        .collect()
}

fn seq(e: &Value) -> u64 {
    e["seq"].as_u64().unwrap()
}

fn is(e: &Value, event: &str) -> bool {
    e["event"] == event
}

/// `seq` grows line by line, and the gaps add up to the `events-dropped` counts; returns the
/// number of events reported lost.
fn check_seq(evs: &[Value], what: &str) -> u64 {
    let (mut last, mut gaps, mut reported) = (0, 0, 0);
    for e in evs {
        assert_eq!(e["schema"], "skillpost.event/1", "{what}: {e}");
        let s = seq(e);
        assert!(s > last, "{what}: seq {s} after {last}");
        gaps += s - last - 1;
        last = s;
        if is(e, "events-dropped") {
            assert_eq!(e["level"], "warn");
            reported += e["count"].as_u64().unwrap();
        }
    }
    assert_eq!(
        gaps, reported,
        "{what}: gaps in seq vs events-dropped counts"
    );
    reported
}

/// A running `skillpost watch`, killed when dropped.
struct Daemon {
    child: Child,
    stderr: PathBuf,
    exited: Option<ExitStatus>,
}

impl Daemon {
    /// Starts `skillpost watch --settle 50 <args>` in `cwd` with `env`; stdout piped (and not
    /// read) when `pipe`, else discarded.
    fn start(cwd: &Path, args: &[&str], env: &[(&str, &str)], pipe: bool) -> Self {
        let stderr = cwd.join("stderr.log");
        let child = Command::new(env!("CARGO_BIN_EXE_skillpost"))
            .arg("watch")
            .args(["--settle", SETTLE_MS])
            .args(args)
            .env("RUST_LOG", "info")
            // Its state and lock notes in the test's folder, not in the real runtime folder.
            .env("XDG_RUNTIME_DIR", cwd)
            .env_remove("RUNTIME_DIRECTORY")
            .envs(env.iter().copied())
            .current_dir(cwd)
            .stdin(Stdio::null())
            .stdout(if pipe { Stdio::piped() } else { Stdio::null() })
            .stderr(fs::File::create(&stderr).unwrap())
            .spawn()
            .unwrap();
        Daemon {
            child,
            stderr,
            exited: None,
        }
    }

    fn log(&self) -> String {
        fs::read_to_string(&self.stderr).unwrap_or_default()
    }

    fn signal(&self, sig: &str) {
        let st = Command::new("kill")
            .args([format!("-{sig}"), self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(st.success(), "kill -{sig} failed");
    }

    /// Waits for the process to exit; panics (with the log) after `timeout`.
    fn wait_exit(&mut self, timeout: Duration) -> ExitStatus {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(st) = self.exited {
                return st;
            }
            self.exited = self.child.try_wait().unwrap();
            if self.exited.is_none() && Instant::now() >= deadline {
                panic!(
                    "the daemon did not exit within {timeout:?}\n--- stderr ---\n{}",
                    self.log()
                );
            }
            sleep(Duration::from_millis(20));
        }
    }

    fn assert_running(&mut self) {
        if let Some(st) = self.child.try_wait().unwrap() {
            self.exited = Some(st);
            panic!("the daemon exited ({st})\n--- stderr ---\n{}", self.log());
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if self.exited.is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Polls an events file until an event matching `pred` is in it; returns its events.
fn wait_for_event(
    d: &mut Daemon,
    file: &Path,
    what: &str,
    pred: impl Fn(&Value) -> bool,
) -> Vec<Value> {
    let deadline = Instant::now() + WAIT;
    loop {
        let text = fs::read_to_string(file).unwrap_or_default();
        // Only complete lines: the writer may be in the middle of one.
        let whole = &text[..text.rfind('\n').map_or(0, |i| i + 1)];
        let evs = parse_lines(whole, what);
        if evs.iter().any(&pred) {
            return evs;
        }
        d.assert_running();
        if Instant::now() >= deadline {
            panic!(
                "timed out waiting for {what}\n--- {} ---\n{text}--- stderr ---\n{}",
                file.display(),
                d.log()
            );
        }
        sleep(Duration::from_millis(20));
    }
}

/// A temporary folder (canonical path).
fn workspace() -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().canonicalize().unwrap();
    (tmp, root)
}

/// `n` projects with long folder names (long paths make long events: the pipe fills sooner).
fn many_projects(root: &Path, n: usize) -> Vec<PathBuf> {
    let long = "p".repeat(200);
    (0..n)
        .map(|i| {
            let dir = root.join("ws").join(&long).join(format!("{long}{i:03}"));
            copy_project(&dir);
            dir
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// A reader that stops reading stdout
// ---------------------------------------------------------------------------------------------

/// Projects at startup; with 30 projects of ~500-byte paths the startup events alone are
/// ~150 KB, well over a 64 KiB pipe plus a 16-event queue.
const STALL_PROJECTS: usize = 30;
/// The queue bound for these tests (default 4096).
const STALL_QUEUE: &str = "16";

fn stalled_daemon(root: &Path, projects: &[PathBuf]) -> Daemon {
    let args: Vec<&str> = projects.iter().map(|p| p.to_str().unwrap()).collect();
    let mut d = Daemon::start(root, &args, &[("SKILLPOST_EVENT_QUEUE", STALL_QUEUE)], true);
    // The writer is stuck on the full pipe and the queue overflowed: dropping has begun.
    assert!(
        wait_until(WAIT, || d.log().contains("dropping events")),
        "no drops reported\n{}",
        d.log()
    );
    d.assert_running();
    d
}

#[test]
fn stalled_stdout_reader_does_not_stop_compiles() {
    let (_tmp, root) = workspace();
    let projects = many_projects(&root, STALL_PROJECTS);
    let mut d = stalled_daemon(&root, &projects);
    // Every startup compile happens although nobody reads the events.
    assert!(
        wait_until(WAIT, || projects.iter().all(|p| compiled_with(p, 100))),
        "startup compiles missing while stdout is stalled\n{}",
        d.log()
    );
    // And every edit is compiled.
    let t = Instant::now();
    for p in &projects {
        edit(p, 4242);
    }
    assert!(
        wait_until(WAIT, || projects.iter().all(|p| compiled_with(p, 4242))),
        "edits not compiled while stdout is stalled\n{}",
        d.log()
    );
    eprintln!(
        "{} edits compiled in {:?} with stdout stalled",
        projects.len(),
        t.elapsed()
    );
    // The reader comes back.
    let mut out = d.child.stdout.take().unwrap();
    let text = Arc::new(Mutex::new(String::new()));
    let reader = {
        let text = text.clone();
        std::thread::spawn(move || {
            let mut buf = [0u8; 8192];
            while let Ok(n) = out.read(&mut buf) {
                if n == 0 {
                    break;
                }
                text.lock()
                    .unwrap()
                    .push_str(std::str::from_utf8(&buf[..n]).unwrap());
            }
        })
    };
    let complete = |t: &str| t[..t.rfind('\n').map_or(0, |i| i + 1)].to_owned();
    assert!(
        wait_until(WAIT, || {
            let t = complete(&text.lock().unwrap());
            parse_lines(&t, "stdout")
                .iter()
                .any(|e| is(e, "events-dropped"))
        }),
        "no events-dropped after the reader resumed\n{}",
        text.lock().unwrap()
    );
    // One more edit: its events arrive in full after the report.
    let before = parse_lines(&complete(&text.lock().unwrap()), "stdout").len();
    edit(&projects[0], 777);
    assert!(wait_until(WAIT, || {
        let t = complete(&text.lock().unwrap());
        parse_lines(&t, "stdout")
            .iter()
            .skip(before)
            .any(|e| is(e, "compile-succeeded"))
    }));
    d.signal("TERM");
    let t = Instant::now();
    assert_eq!(d.wait_exit(WAIT).code(), Some(0), "{}", d.log());
    eprintln!("exit {:?} after SIGTERM", t.elapsed());
    reader.join().unwrap();
    let text = text.lock().unwrap().clone();
    let evs = parse_lines(&text, "stdout");
    let lost = check_seq(&evs, "stdout");
    assert!(lost > 0);
    let written = evs.iter().filter(|e| !is(e, "events-dropped")).count();
    eprintln!(
        "stdout stalled: {} lines read, {lost} events dropped and reported, {written} delivered",
        evs.len()
    );
    assert!(is(evs.last().unwrap(), "stopped"));
    assert!(compiled_with(&projects[0], 777));
    // The first drop is logged once, not per event.
    assert_eq!(d.log().matches("dropping events").count(), 1, "{}", d.log());
}

#[test]
fn sigterm_with_a_stalled_stdout_reader_exits_within_the_bound() {
    let (_tmp, root) = workspace();
    let projects = many_projects(&root, STALL_PROJECTS);
    let mut d = stalled_daemon(&root, &projects);
    assert!(wait_until(WAIT, || projects
        .iter()
        .all(|p| compiled_with(p, 100))));
    d.signal("TERM");
    let t = Instant::now();
    let st = d.wait_exit(Duration::from_secs(8));
    let took = t.elapsed();
    eprintln!("exit {st} {took:?} after SIGTERM with stdout stalled");
    // The final flush waits 2 s for the reader, then the process ends anyway, with status 2.
    assert!(took < Duration::from_secs(5), "{took:?}");
    assert_eq!(st.code(), Some(2), "{}", d.log());
    assert!(d.log().contains("not written"), "{}", d.log());
}

// ---------------------------------------------------------------------------------------------
// A compile that hangs at shutdown
// ---------------------------------------------------------------------------------------------

/// Starts a daemon whose every compile hangs for a minute (the `SKILLPOST_TEST_HANG_MS` hook),
/// on one project, and waits until its startup compile is under way.
fn hanging_daemon(root: &Path, stop_timeout_ms: &str) -> (Daemon, PathBuf, PathBuf) {
    let a = root.join("ws/A");
    copy_project(&a);
    let ev = root.join("ev.jsonl");
    let mut d = Daemon::start(
        root,
        &["--events", ev.to_str().unwrap(), a.to_str().unwrap()],
        &[
            ("SKILLPOST_TEST_HANG_MS", "60000"),
            ("SKILLPOST_STOP_TIMEOUT_MS", stop_timeout_ms),
        ],
        false,
    );
    wait_for_event(&mut d, &ev, "the startup rescan", |e| is(e, "rescan"));
    // The compile is spawned right after the rescan event.
    sleep(Duration::from_millis(300));
    (d, a, ev)
}

#[test]
fn a_hung_compile_does_not_hold_sigterm() {
    let (_tmp, root) = workspace();
    let (mut d, a, ev) = hanging_daemon(&root, "1500");
    d.signal("TERM");
    let t = Instant::now();
    let st = d.wait_exit(Duration::from_secs(8));
    let took = t.elapsed();
    eprintln!("exit {st} {took:?} after SIGTERM with a hung compile (stop timeout 1.5 s)");
    assert!(took >= Duration::from_millis(1400), "{took:?}");
    assert!(took < Duration::from_secs(4), "{took:?}");
    assert_eq!(st.code(), Some(2), "{}", d.log());
    let evs = parse_lines(&fs::read_to_string(&ev).unwrap(), "events");
    check_seq(&evs, "events");
    let last = evs.last().unwrap();
    assert!(is(last, "stopped"), "{last}");
    assert_eq!(last["reason"], "timeout");
    assert_eq!(last["level"], "error");
    assert_eq!(last["requested"], "SIGTERM");
    assert_eq!(last["compiling"], serde_json::json!([a.to_str().unwrap()]));
    assert!(d.log().contains("still running"), "{}", d.log());
}

#[test]
fn a_second_signal_ends_the_wait_for_a_hung_compile() {
    let (_tmp, root) = workspace();
    // A stop timeout longer than the test: only the second signal can end the wait.
    let (mut d, _a, ev) = hanging_daemon(&root, "60000");
    d.signal("TERM");
    sleep(Duration::from_millis(300));
    d.assert_running();
    d.signal("INT");
    let st = d.wait_exit(Duration::from_secs(5));
    assert_eq!(st.code(), Some(2), "{}", d.log());
    let evs = parse_lines(&fs::read_to_string(&ev).unwrap(), "events");
    let last = evs.last().unwrap();
    assert_eq!(last["reason"], "timeout", "{last}");
    assert_eq!(last["requested"], "SIGTERM");
}

// ---------------------------------------------------------------------------------------------
// Rotation
// ---------------------------------------------------------------------------------------------

/// A daemon on one project with `--events ev.jsonl`, after its startup compile.
fn file_daemon(root: &Path, ev: &Path) -> (Daemon, PathBuf) {
    file_daemon_env(root, ev, &[])
}

fn file_daemon_env(root: &Path, ev: &Path, env: &[(&str, &str)]) -> (Daemon, PathBuf) {
    let a = root.join("ws/A");
    copy_project(&a);
    let mut d = Daemon::start(
        root,
        &["--events", ev.to_str().unwrap(), a.to_str().unwrap()],
        env,
        false,
    );
    wait_for_event(&mut d, ev, "the startup write-back", |e| {
        is(e, "write-back")
    });
    sleep(Duration::from_millis(300));
    (d, a)
}

#[test]
fn sighup_after_mv_or_rm_writes_a_new_events_file() {
    let (_tmp, root) = workspace();
    let ev = root.join("ev.jsonl");
    let (mut d, a) = file_daemon(&root, &ev);

    // logrotate's `create`: the file is renamed (and maybe created empty), then SIGHUP.
    let rotated = root.join("ev.jsonl.1");
    fs::rename(&ev, &rotated).unwrap();
    d.signal("HUP");
    let new = wait_for_event(&mut d, &ev, "reloaded in the new file", |e| {
        is(e, "reloaded")
    });
    edit(&a, 4711);
    let new = {
        let _ = new;
        wait_for_event(&mut d, &ev, "compile-succeeded in the new file", |e| {
            is(e, "compile-succeeded")
        })
    };
    let old = parse_lines(&fs::read_to_string(&rotated).unwrap(), "rotated file");
    assert!(old.iter().any(|e| is(e, "write-back")));
    assert!(
        !old.iter().any(|e| is(e, "reloaded")),
        "reloaded is in the new file"
    );
    // One stream across the two files.
    let mut all = old.clone();
    all.extend(new.iter().cloned());
    check_seq(&all, "rotated + new");
    assert_eq!(seq(&new[0]), seq(old.last().unwrap()) + 1);

    // Deleted, then SIGHUP: created again.
    fs::remove_file(&ev).unwrap();
    d.signal("HUP");
    wait_for_event(&mut d, &ev, "reloaded after rm", |e| is(e, "reloaded"));

    d.signal("TERM");
    assert_eq!(d.wait_exit(WAIT).code(), Some(0));
    let last = parse_lines(&fs::read_to_string(&ev).unwrap(), "events");
    assert!(is(last.last().unwrap(), "stopped"));
    // The rotated file was left alone after the SIGHUP.
    let old_again = parse_lines(&fs::read_to_string(&rotated).unwrap(), "rotated file");
    assert_eq!(old_again.len(), old.len());
}

#[test]
fn sighup_switches_to_the_events_file_the_config_names_now() {
    let (_tmp, root) = workspace();
    let a = root.join("ws/A");
    copy_project(&a);
    let config = root.join("skillpost.toml");
    let write_config = |events: &str| {
        fs::write(
            &config,
            format!("events = \"{events}\"\n\n[[project]]\npath = \"ws/A\"\n"),
        )
        .unwrap()
    };
    write_config("one.jsonl");
    let mut d = Daemon::start(&root, &["--config", config.to_str().unwrap()], &[], false);
    let one = root.join("one.jsonl");
    let two = root.join("two.jsonl");
    wait_for_event(&mut d, &one, "startup write-back", |e| is(e, "write-back"));
    write_config("two.jsonl");
    d.signal("HUP");
    wait_for_event(&mut d, &two, "reloaded in two.jsonl", |e| is(e, "reloaded"));
    // An invalid configuration: reload-failed, in the same file (reopened).
    fs::write(&config, "nonsense = [\n").unwrap();
    d.signal("HUP");
    let evs = wait_for_event(&mut d, &two, "reload-failed", |e| is(e, "reload-failed"));
    let all: Vec<Value> = parse_lines(&fs::read_to_string(&one).unwrap(), "one")
        .into_iter()
        .chain(evs)
        .collect();
    check_seq(&all, "one + two");
    d.signal("TERM");
    assert_eq!(d.wait_exit(WAIT).code(), Some(0));
}

/// The logrotate configuration shown in docs/DAEMON.md, for the events file `ev`, with the
/// `postrotate` reload replaced by `kill -HUP pid` (no systemd here) and no user to create for.
fn documented_logrotate_config(ev: &Path, pid: u32) -> String {
    let doc = include_str!("../docs/DAEMON.md");
    let start = doc
        .find("/var/log/skillpost/events.jsonl {")
        .expect("a logrotate snippet in docs/DAEMON.md");
    let end = start + doc[start..].find("```").unwrap();
    let snippet = &doc[start..end];
    assert!(snippet.contains("systemctl reload skillpost"), "{snippet}");
    snippet
        .replace("/var/log/skillpost/events.jsonl", ev.to_str().unwrap())
        .replace("systemctl reload skillpost", &format!("kill -HUP {pid}"))
        .replace("create 0640 skillpost skillpost", "create 0640")
}

#[test]
fn logrotate_with_the_documented_configuration() {
    let Ok(version) = Command::new("logrotate").arg("--version").output() else {
        return skip("logrotate is not installed");
    };
    assert!(version.status.success());
    let (_tmp, root) = workspace();
    let ev = root.join("ev.jsonl");
    let (mut d, a) = file_daemon(&root, &ev);
    let conf = root.join("logrotate.conf");
    fs::write(&conf, documented_logrotate_config(&ev, d.child.id())).unwrap();
    let rotate = || {
        let out = Command::new("logrotate")
            .arg("-f")
            .arg("-s")
            .arg(root.join("logrotate.state"))
            .arg(&conf)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "logrotate: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    rotate();
    wait_for_event(&mut d, &ev, "reloaded after logrotate", |e| {
        is(e, "reloaded")
    });
    edit(&a, 4713);
    let new = wait_for_event(&mut d, &ev, "compile-succeeded after logrotate", |e| {
        is(e, "compile-succeeded")
    });
    // `delaycompress`: the rotated file is still plain text, and ends with a whole line.
    let old = parse_lines(
        &fs::read_to_string(root.join("ev.jsonl.1")).unwrap(),
        "ev.jsonl.1",
    );
    let all: Vec<Value> = old.into_iter().chain(new).collect();
    check_seq(&all, "ev.jsonl.1 + ev.jsonl");
    // Once more: the first rotation is compressed now, the daemon follows again.
    rotate();
    assert!(root.join("ev.jsonl.2.gz").is_file());
    wait_for_event(&mut d, &ev, "reloaded after the second logrotate", |e| {
        is(e, "reloaded")
    });
    edit(&a, 4714);
    wait_for_event(
        &mut d,
        &ev,
        "compile-succeeded after the second logrotate",
        |e| is(e, "compile-succeeded"),
    );
    d.signal("TERM");
    assert_eq!(d.wait_exit(WAIT).code(), Some(0));
}

#[test]
fn copytruncate_keeps_whole_lines() {
    let (_tmp, root) = workspace();
    let ev = root.join("ev.jsonl");
    let (mut d, a) = file_daemon(&root, &ev);
    // logrotate's `copytruncate`: copy, then truncate in place; no signal.
    fs::copy(&ev, root.join("ev.jsonl.1")).unwrap();
    fs::OpenOptions::new()
        .write(true)
        .open(&ev)
        .unwrap()
        .set_len(0)
        .unwrap();
    edit(&a, 4712);
    let evs = wait_for_event(&mut d, &ev, "compile-succeeded after truncation", |e| {
        is(e, "compile-succeeded")
    });
    // Appended at the new end: no hole of zero bytes before the first line.
    assert!(is(&evs[0], "change-detected"), "{}", evs[0]);
    assert!(!fs::read(&ev).unwrap().contains(&0));
}

// ---------------------------------------------------------------------------------------------
// A full disk under the events file
// ---------------------------------------------------------------------------------------------

/// A small tmpfs mounted on a folder; unmounted when dropped.
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(dir: &Path, size: &str) -> Result<Self, String> {
        fs::create_dir_all(dir).unwrap();
        let out = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(dir)
            .output()
            .map_err(|e| format!("cannot run mount: {e}"))?;
        if !out.status.success() {
            return Err(format!(
                "cannot mount a tmpfs: {}",
                String::from_utf8_lossy(&out.stderr).trim()
            ));
        }
        Ok(Tmpfs(dir.to_owned()))
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
    }
}

/// Fills the file system holding `path` with a file there, until `ENOSPC`.
fn fill(path: &Path) {
    use std::io::Write;
    let mut f = fs::File::create(path).unwrap();
    let chunk = [b'x'; 512];
    loop {
        match f.write(&chunk) {
            Ok(0) | Err(_) => break,
            Ok(_) => {}
        }
    }
    // Down to the last byte.
    while matches!(f.write(b"x"), Ok(1)) {}
}

#[test]
fn a_full_disk_never_leaves_half_a_line() {
    let (_tmp, root) = workspace();
    let logs = root.join("logs");
    let _mnt = match Tmpfs::mount(&logs, "256k") {
        Ok(m) => m,
        Err(why) => return skip(&why),
    };
    let ev = logs.join("ev.jsonl");
    let (mut d, a) = file_daemon_env(
        &root,
        &ev,
        &[("RUST_LOG", "info,skillpost::daemon::events=debug")],
    );
    let filler = logs.join("filler");
    fill(&filler);
    // Compiles go on while no event can be written.
    let lines_before = fs::read_to_string(&ev).unwrap().lines().count();
    for x in [501, 502, 503] {
        edit(&a, x);
        assert!(
            wait_until(WAIT, || compiled_with(&a, x)),
            "no compile on a full disk\n{}",
            d.log()
        );
    }
    // The writer thread has met the full disk (it writes after the outputs, on its own thread:
    // a fixed sleep could free the space before it tried).
    assert!(
        wait_until(WAIT, || d.log().contains("cannot write the event stream")),
        "no write error logged on a full disk\n{}",
        d.log()
    );
    d.assert_running();
    // Free the space: the next events are whole lines, the lost ones reported.
    fs::remove_file(&filler).unwrap();
    edit(&a, 504);
    let evs = wait_for_event(
        &mut d,
        &ev,
        "events-dropped after the disk was freed",
        |e| is(e, "events-dropped"),
    );
    let lost = check_seq(&evs, "events file");
    let dropped = evs.iter().find(|e| is(e, "events-dropped")).unwrap();
    assert_eq!(dropped["reason"], "write-error", "{dropped}");
    assert!(lost > 0);
    eprintln!(
        "full disk: {} lines before, {lost} events lost and reported, {} lines after",
        lines_before,
        evs.len()
    );
    wait_for_event(&mut d, &ev, "the compile after freeing", |e| {
        is(e, "compile-succeeded") && e["outputs"].to_string().contains("Blackboard.src")
    });
    assert!(wait_until(WAIT, || compiled_with(&a, 504)));
    d.signal("TERM");
    assert_eq!(d.wait_exit(WAIT).code(), Some(0), "{}", d.log());
    let evs = parse_lines(&fs::read_to_string(&ev).unwrap(), "events file");
    check_seq(&evs, "events file");
    assert!(is(evs.last().unwrap(), "stopped"));
    // The failure is logged once, and its end once.
    let log = d.log();
    assert_eq!(
        log.matches("cannot write the event stream").count(),
        1,
        "{log}"
    );
    assert_eq!(log.matches("can be written again").count(), 1, "{log}");
    // The disk filled in the middle of lines, and those were cut off again.
    let taken_back = log.matches("took back").count();
    assert!(taken_back > 0, "{log}");
    eprintln!(
        "full disk: partial lines taken back: {taken_back}, events lost: {}",
        evs.iter()
            .filter(|e| is(e, "events-dropped"))
            .map(|e| e["count"].as_u64().unwrap())
            .sum::<u64>()
    );
}

// ---------------------------------------------------------------------------------------------
// systemd
// ---------------------------------------------------------------------------------------------

/// A `Key=` value of the unit in seconds (`60s` or `60`).
fn unit_seconds(unit: &str, key: &str) -> u64 {
    let value = unit
        .lines()
        .filter_map(|l| l.trim().strip_prefix(&format!("{key}=")))
        .next_back()
        .unwrap_or_else(|| panic!("{key}= in the unit"));
    let v = value.trim();
    v.strip_suffix('s')
        .unwrap_or(v)
        .parse()
        .unwrap_or_else(|_| panic!("{key}={v}: seconds expected"))
}

#[test]
fn systemd_timeouts_exceed_the_daemons_own_bounds() {
    let unit = include_str!("../systemd/skillpost.service");
    let own = skillpost::daemon::STOP_TIMEOUT + skillpost::daemon::events::FLUSH_TIMEOUT;
    // systemd sends SIGKILL after TimeoutStopSec: the daemon's own bounds must end it first.
    let stop = unit_seconds(unit, "TimeoutStopSec");
    assert!(
        Duration::from_secs(stop) > own + Duration::from_secs(5),
        "TimeoutStopSec={stop}s must exceed the daemon's stop timeout and final flush ({own:?})"
    );
    // No watchdog pings while stopping: the stop must end well within one watchdog interval.
    let watchdog = unit_seconds(unit, "WatchdogSec");
    assert!(
        Duration::from_secs(watchdog) > own,
        "WatchdogSec={watchdog}s must exceed the stop's bounds ({own:?})"
    );
}

/// Issue 27, item 4: the binary daemons of these tests keep their state file and lock notes in
/// the test's folder (`XDG_RUNTIME_DIR`), never in the real runtime folder
/// (`/tmp/skillpost-<uid>`): run again with `TMPDIR`, `HOME` and `XDG_RUNTIME_DIR` in a sandbox,
/// a test that starts, signals and stops one leaves the sandbox empty.
#[test]
fn binary_daemon_tests_leave_nothing_outside_their_temporary_folders() {
    let test = "sighup_after_mv_or_rm_writes_a_new_events_file";
    let left = common::leftovers_of(test);
    assert!(left.is_empty(), "{test} left {left:#?}");
}

// ---------------------------------------------------------------------------------------------
// Issue 27, item 9: what goes where (docs/DAEMON.md, "Where output goes")
// ---------------------------------------------------------------------------------------------

/// The daemon's stdout after it exited (it was piped and not read: these few events fit).
fn stdout_of(d: &mut Daemon) -> String {
    let mut out = String::new();
    if let Some(mut s) = d.child.stdout.take() {
        s.read_to_string(&mut out).unwrap();
    }
    out
}

/// The startup compile, a broken edit and a fixed one, then `SIGTERM`; returns the log (stderr).
fn three_compiles(d: &mut Daemon, a: &Path, compiles: impl Fn(&Daemon) -> usize) -> String {
    assert!(
        wait_until(WAIT, || compiles(d) >= 1),
        "the startup compile\n{}",
        d.log()
    );
    sleep(Duration::from_millis(300));
    let orig = fs::read_to_string(sample().join("sfc.xml")).unwrap();
    fs::write(
        a.join("sfc.xml"),
        orig.replace("(100, 200, 300,", "(100, 200, 300"),
    )
    .unwrap();
    assert!(
        wait_until(WAIT, || compiles(d) >= 2),
        "the broken edit\n{}",
        d.log()
    );
    sleep(Duration::from_millis(300));
    edit(a, 7);
    assert!(
        wait_until(WAIT, || compiles(d) >= 3),
        "the fixed edit\n{}",
        d.log()
    );
    d.signal("TERM");
    assert!(d.wait_exit(WAIT).success());
    d.log()
}

/// With `--events FILE` stdout stays empty, and the log (stderr, the default `human` format)
/// has one line per compile: `<project> compiled in N ms: <outputs>` and `compile failed:
/// <project>: <code> <file>:<line>:<col>: <message>`, with the file named inside the project, no span,
/// no module path, no colour when stderr is not a terminal.
#[test]
fn the_log_says_each_compile_in_one_line_and_stdout_stays_empty_with_an_events_file() {
    let (_tmp, root) = workspace();
    let a = root.join("ws/A");
    copy_project(&a);
    let ev = root.join("ev.jsonl");
    let mut d = Daemon::start(
        &root,
        &["--events", ev.to_str().unwrap(), a.to_str().unwrap()],
        &[],
        true,
    );
    let outcomes = |_: &Daemon| {
        let text = fs::read_to_string(&ev).unwrap_or_default();
        text.lines()
            .filter(|l| l.contains("\"compile-succeeded\"") || l.contains("\"compile-failed\""))
            .count()
    };
    let log = three_compiles(&mut d, &a, outcomes);
    assert_eq!(stdout_of(&mut d), "", "nothing on stdout with --events");
    assert!(!log.contains('\x1b'), "no colours in a file:\n{log}");
    let project = a.display().to_string();
    let compiled: Vec<&str> = log
        .lines()
        .filter(|l| l.contains(" compiled in "))
        .collect();
    let failed: Vec<&str> = log
        .lines()
        .filter(|l| l.contains(" compile failed: "))
        .collect();
    assert_eq!(compiled.len(), 2, "one line per successful compile:\n{log}");
    assert_eq!(failed.len(), 1, "one line per failed compile:\n{log}");
    for l in &compiled {
        let (_, rest) = l
            .split_once(&format!(" INFO {project} compiled in "))
            .unwrap_or_else(|| panic!("`<time> INFO <project> compiled in`: {l}"));
        let (ms, files) = rest.split_once(" ms: ").expect("N ms: outputs");
        ms.parse::<u64>().expect("milliseconds");
        assert!(files.starts_with("Blackboard.src"), "{l}");
        assert!(files.contains("Blackboard.dat"), "{l}");
        assert!(!l.contains("compile{") && !l.contains("skillpost::"), "{l}");
    }
    assert!(
        failed[0].contains(&format!(" WARN compile failed: {project}: E502 sfc.xml:")),
        "{}",
        failed[0]
    );
    assert_eq!(
        log.lines().filter(|l| l.contains(" WARN ")).count(),
        1,
        "nothing else to warn about:\n{log}"
    );
}

/// Without `--events` the events are on stdout and nothing else is (every line an event);
/// `--log-format json` makes every log line a JSON object, the compile lines with the
/// project, `run_id` and `duration_ms`.
#[test]
fn events_on_stdout_and_json_log_lines_on_stderr() {
    let (_tmp, root) = workspace();
    let a = root.join("ws/A");
    copy_project(&a);
    let mut d = Daemon::start(
        &root,
        &["--log-format", "json", a.to_str().unwrap()],
        &[],
        true,
    );
    let outcomes = |d: &Daemon| {
        d.log()
            .lines()
            .filter(|l| l.contains(" compiled in ") || l.contains("compile failed: "))
            .count()
    };
    let log = three_compiles(&mut d, &a, outcomes);
    let out = stdout_of(&mut d);
    let evs = parse_lines(&out, "stdout");
    assert!(evs.iter().all(|e| e["schema"] == "skillpost.event/1"));
    assert_eq!(evs.iter().filter(|e| is(e, "compile-started")).count(), 3);
    let lines = parse_lines(&log, "stderr");
    let compiles: Vec<&Value> = lines
        .iter()
        .filter(|l| l["fields"]["duration_ms"].is_u64())
        .collect();
    assert_eq!(compiles.len(), 3, "{log}");
    for (n, l) in compiles.iter().enumerate() {
        assert_eq!(l["fields"]["project"], a.display().to_string(), "{l}");
        assert_eq!(l["fields"]["run_id"], n as u64 + 1, "{l}");
        assert_eq!(l["span"]["run_id"], n as u64 + 1, "{l}");
    }
    assert_eq!(compiles[1]["level"], "WARN");
    assert_eq!(compiles[1]["fields"]["code"], "E502");
}

/// A deploy that fails is a warning line in the log (the journal under systemd: `journalctl
/// -p warning` lists it) naming the project, the program and the hook's last stderr line; one
/// that succeeds an info line.
#[test]
fn a_failed_deploy_is_a_warning_line_in_the_log() {
    let (_tmp, root) = workspace();
    let a = root.join("ws/A");
    copy_project(&a);
    let ev = root.join("ev.jsonl");
    let config = root.join("skillpost.toml");
    fs::write(
        &config,
        format!(
            "[[project]]\npath = \"{}\"\non_success = [\"sh\", \"-c\", \"echo trying >&2; echo share //r1 offline >&2; exit 3\"]\n",
            a.display()
        ),
    )
    .unwrap();
    let mut d = Daemon::start(
        &root,
        &[
            "--events",
            ev.to_str().unwrap(),
            "--config",
            config.to_str().unwrap(),
        ],
        &[],
        false,
    );
    let project = a.display().to_string();
    // The hook's program as resolved in PATH when the configuration was read (`/usr/bin/sh`).
    let line = format!(" WARN {project}: deploy of Blackboard (controller KUKA KR15-2) failed: /");
    let end = "/sh exited with status 3: share //r1 offline";
    assert!(
        wait_until(WAIT, || d
            .log()
            .lines()
            .any(|l| l.contains(&line) && l.ends_with(end))),
        "{}",
        d.log()
    );
    d.signal("TERM");
    assert!(d.wait_exit(WAIT).success());
    let log = d.log();
    assert_eq!(
        log.lines().filter(|l| l.contains(&line)).count(),
        1,
        "one warning line for the failed deploy:\n{log}"
    );
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
