//! `skillpost status` and the journal lines, through the binary: a daemon on a good and a
//! broken project (`--log-format json`, `--state FILE`), then a reload with an invalid
//! configuration.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

const BIN: &str = env!("CARGO_BIN_EXE_skillpost");

fn copy_sample(dir: &Path) {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ok/reference-sample");
    fs::create_dir_all(dir).unwrap();
    for f in ["Blackboard.aml", "sfc.xml", "kr15-2.irl"] {
        fs::copy(sample.join(f), dir.join(f)).unwrap();
    }
}

fn lines(p: &Path) -> Vec<Value> {
    fs::read_to_string(p)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

fn wait_for(what: &str, mut cond: impl FnMut() -> bool) {
    let end = Instant::now() + Duration::from_secs(10);
    while Instant::now() < end {
        if cond() {
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("timed out waiting for {what}");
}

struct Kill(Child);
impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn status(state: &Path, format: &str) -> (i32, String, String) {
    let o = Command::new(BIN)
        .args(["status", "--state"])
        .arg(state)
        .args(["--format", format])
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8(o.stdout).unwrap(),
        String::from_utf8(o.stderr).unwrap(),
    )
}

#[test]
fn status_and_journal_after_a_success_a_failure_and_a_failed_reload() {
    let tmp = tempfile::tempdir().unwrap();
    let root: PathBuf = tmp.path().canonicalize().unwrap();
    let (good, bad) = (root.join("good"), root.join("bad"));
    copy_sample(&good);
    copy_sample(&bad);
    // Not well-formed, and stable (older than the half-written check's second).
    fs::write(bad.join("sfc.xml"), "<pou").unwrap();
    let old = std::time::SystemTime::now() - Duration::from_secs(10);
    fs::File::options()
        .write(true)
        .open(bad.join("sfc.xml"))
        .unwrap()
        .set_modified(old)
        .unwrap();
    let config = root.join("skillpost.toml");
    fs::write(
        &config,
        "[[project]]\npath = \"good\"\n[[project]]\npath = \"bad\"\n",
    )
    .unwrap();
    let state = root.join("run/status.json");
    let (events, log) = (root.join("ev.jsonl"), root.join("log.jsonl"));

    let (code, _, err) = status(&state, "table");
    assert_eq!(code, 1, "no daemon state yet: {err}");
    assert!(err.contains("no daemon state"), "{err}");

    let daemon = Kill(
        Command::new(BIN)
            .args(["watch", "--log-format", "json", "--config"])
            .arg(&config)
            .arg("--events")
            .arg(&events)
            .arg("--state")
            .arg(&state)
            .env("RUNTIME_DIRECTORY", root.join("locks"))
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(fs::File::create(&log).unwrap())
            .spawn()
            .unwrap(),
    );
    let ended = |name: &str| {
        lines(&events)
            .iter()
            .filter(|e| e["event"] == "compile-succeeded" || e["event"] == "compile-failed")
            .any(|e| e["project"].as_str().is_some_and(|p| p.ends_with(name)))
    };
    wait_for("both compiles", || ended("/good") && ended("/bad"));
    wait_for("the state file", || {
        status(&state, "json").1.contains("\"failed\"")
            && status(&state, "json").1.contains("\"ok\"")
    });

    // JSON: the state file's content.
    let (code, json, _) = status(&state, "json");
    assert_eq!(code, 0);
    let snap: Value = serde_json::from_str(&json).unwrap();
    assert_eq!(snap["schema"], "skillpost.status/1");
    assert_eq!(
        snap["summary"].as_str().unwrap().split(';').next(),
        Some("2 projects, 1 failing")
    );
    let by = |p: &Path| {
        snap["projects"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["project"] == p.display().to_string())
            .cloned()
            .unwrap()
    };
    assert_eq!(by(&good)["result"], "ok");
    // The .src, .dat and I/O list.
    assert_eq!(by(&good)["outputs"].as_array().unwrap().len(), 3);
    assert_eq!(by(&good)["errors"], 0);
    assert_eq!(by(&bad)["result"], "failed");
    assert!(by(&bad)["errors"].as_u64().unwrap() >= 1);
    assert!(by(&bad)["time"].is_string());

    // Table: aligned with spaces.
    let (code, table, _) = status(&state, "table");
    assert_eq!(code, 0);
    assert!(!table.contains('\t'), "{table}");
    assert!(table.contains("2 projects, 1 failing"), "{table}");
    let rows: Vec<&str> = table
        .lines()
        .skip_while(|l| !l.starts_with("PROJECT"))
        .collect();
    assert_eq!(rows.len(), 3, "{table}");
    let col = rows[0].find("RESULT").unwrap();
    for r in &rows[1..] {
        assert!(
            r[col..].starts_with("ok") || r[col..].starts_with("failed"),
            "{table}"
        );
    }
    // Replaced atomically: no temporary file beside it.
    let left: Vec<_> = fs::read_dir(state.parent().unwrap())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, [std::ffi::OsString::from("status.json")]);

    // The failed compile in the log: one warn line with project, run_id and the location.
    let logs = lines(&log);
    let failed: Vec<&Value> = logs
        .iter()
        .filter(|l| {
            l["fields"]["message"]
                .as_str()
                .is_some_and(|m| m.starts_with("compile failed"))
        })
        .collect();
    assert_eq!(failed.len(), 1, "{logs:#?}");
    let f = failed[0];
    assert_eq!(f["level"], "WARN");
    assert_eq!(f["span"]["project"], bad.display().to_string());
    assert!(f["span"]["run_id"].is_u64(), "{f}");
    let msg = f["fields"]["message"].as_str().unwrap();
    assert!(msg.contains("E102") && msg.contains("sfc.xml:1:"), "{msg}");

    // A failed reload: one error line with file:line:col.
    fs::write(&config, "settle_ms = \"soon\"\n").unwrap();
    Command::new("kill")
        .args(["-HUP", &daemon.0.id().to_string()])
        .status()
        .unwrap();
    wait_for("reload-failed", || {
        lines(&events).iter().any(|e| e["event"] == "reload-failed")
    });
    wait_for("the reload's log line", || {
        lines(&log).iter().any(|l| {
            l["level"] == "ERROR"
                && l["fields"]["message"]
                    .as_str()
                    .is_some_and(|m| m.contains("reload failed") && m.contains("skillpost.toml:1:"))
        })
    });

    // Stopped: the file says so.
    Command::new("kill")
        .args(["-TERM", &daemon.0.id().to_string()])
        .status()
        .unwrap();
    wait_for("the stopped state", || {
        status(&state, "json").1.contains("\"stopped\"")
    });
    assert!(status(&state, "table").1.contains("stopped"));
}

/// A fresh host: the service configuration names a project folder that does not exist yet.
/// The daemon must still say READY=1 (systemd waits for it), and the state file says `running`
/// with the project `waiting` for its folder (issue 27, item 12: not "pending", "not compiled
/// yet", as if a compile were coming); once the folder is there, it is compiled.
#[test]
fn ready_with_only_a_missing_project() {
    use std::os::unix::net::UnixDatagram;
    let tmp = tempfile::tempdir().unwrap();
    let root: PathBuf = tmp.path().canonicalize().unwrap();
    let sock_path = root.join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let state = root.join("status.json");
    // In the configuration, as on such a host: the command line takes existing folders only.
    let config = root.join("skillpost.toml");
    fs::write(
        &config,
        format!(
            "[[project]]\npath = \"{}\"\n",
            root.join("not-yet").display()
        ),
    )
    .unwrap();
    let _daemon = Kill(
        Command::new(BIN)
            .arg("watch")
            .arg("--state")
            .arg(&state)
            .arg("--events")
            .arg(root.join("ev.jsonl"))
            .arg("--config")
            .arg(&config)
            .env("RUNTIME_DIRECTORY", root.join("locks"))
            .env("NOTIFY_SOCKET", &sock_path)
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let end = Instant::now() + Duration::from_secs(10);
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    while Instant::now() < end && !got.iter().any(|m: &String| m.contains("READY=1")) {
        if let Ok(n) = sock.recv(&mut buf) {
            got.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
    }
    assert!(got.iter().any(|m| m.contains("READY=1")), "{got:?}");
    wait_for("the running state", || {
        status(&state, "json").1.contains("\"running\"")
    });
    let (code, json, _) = status(&state, "json");
    assert_eq!(code, 0);
    let snap: Value = serde_json::from_str(&json).unwrap();
    let p = &snap["projects"][0];
    assert_eq!(p["project"], root.join("not-yet").display().to_string());
    assert_eq!(p["result"], "waiting", "{json}");
    assert_eq!(
        p["waiting"], "the project folder does not exist; waiting for it",
        "{json}"
    );
    assert!(
        snap["summary"]
            .as_str()
            .unwrap()
            .starts_with("1 project, 1 waiting for its folder;"),
        "{json}"
    );
    assert!(
        !json.contains("pending") && !json.contains("not compiled yet"),
        "{json}"
    );
    let (code, table, _) = status(&state, "table");
    assert_eq!(code, 0);
    let row = table
        .lines()
        .find(|l| l.contains("not-yet"))
        .unwrap_or_else(|| panic!("{table}"));
    assert!(
        row.contains(" waiting ")
            && row.ends_with("the project folder does not exist; waiting for it"),
        "{table}"
    );
    assert!(table.contains("1 waiting for its folder"), "{table}");

    // The folder appears: it is compiled, and waits no more.
    copy_sample(&root.join("not-yet"));
    wait_for("the compile of the new folder", || {
        status(&state, "json").1.contains("\"ok\"")
    });
    let (_, json, _) = status(&state, "json");
    assert!(!json.contains("waiting"), "{json}");
}

/// `skillpost status [FOLDER]` as a daemon started by hand runs it: no `--state`, the runtime
/// folder `$XDG_RUNTIME_DIR/skillpost` (made in the test's folder).
fn status_by_hand(xdg: &Path, args: &[&str]) -> (i32, String, String) {
    let o = Command::new(BIN)
        .arg("status")
        .args(args)
        .env_remove("RUNTIME_DIRECTORY")
        .env("XDG_RUNTIME_DIR", xdg)
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8(o.stdout).unwrap(),
        String::from_utf8(o.stderr).unwrap(),
    )
}

/// Issue 27, item 1: two daemons started by hand by one user (one runtime folder) each keep
/// their own state. After one stops, `status` shows the other, running (exit 0); the stopped
/// one's state shows only for its folder, as stopped, with exit status 3 (as `systemctl
/// status`); once none runs, exit 3 too; a daemon killed without a word is not taken for a
/// running one. The next daemon started removes the states of those that ended.
#[test]
fn status_shows_the_daemons_that_run_and_a_stopped_one_as_stopped() {
    use std::os::unix::fs::PermissionsExt as _;
    let tmp = tempfile::tempdir().unwrap();
    let root: PathBuf = tmp.path().canonicalize().unwrap();
    let (p, q) = (root.join("P"), root.join("Q"));
    copy_sample(&p);
    copy_sample(&q);
    let xdg = root.join("xdg");
    fs::create_dir(&xdg).unwrap();
    fs::set_permissions(&xdg, fs::Permissions::from_mode(0o700)).unwrap();
    let start = |folder: &Path, events: &str| {
        Kill(
            Command::new(BIN)
                .arg("watch")
                .arg("--events")
                .arg(root.join(events))
                .arg(folder)
                .env_remove("RUNTIME_DIRECTORY")
                .env("XDG_RUNTIME_DIR", &xdg)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap(),
        )
    };
    let st = |args: &[&str]| status_by_hand(&xdg, args);
    let (ps, qs, other) = (
        p.to_str().unwrap(),
        q.to_str().unwrap(),
        root.join("xdg").display().to_string(),
    );
    let running = |pid: u32| format!("(pid {pid}) running since");
    let mut a = start(&p, "a.jsonl");
    let mut b = start(&q, "b.jsonl");
    let (pa, pb) = (a.0.id(), b.0.id());
    wait_for("both daemons running", || {
        let (code, out, _) = st(&[]);
        code == 0 && out.contains(&running(pa)) && out.contains(&running(pb))
    });
    // JSON: one object per daemon.
    let (code, json, _) = st(&["--format", "json"]);
    assert_eq!(code, 0);
    let objects: Vec<Value> = serde_json::Deserializer::from_str(&json)
        .into_iter()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(objects.len(), 2, "{json}");
    // A folder: the daemon watching it, and its projects only.
    let (code, out, _) = st(&[ps]);
    assert_eq!(code, 0, "{out}");
    assert!(
        out.contains(&running(pa)) && !out.contains(&format!("pid {pb}")),
        "{out}"
    );
    assert!(out.contains(ps) && !out.contains(qs), "{out}");
    let (code, _, err) = st(&[&other]);
    assert_eq!(code, 1, "no daemon watches it: {err}");

    // A stops: `status` shows B, running; A only for its folder, stopped, exit 3.
    Command::new("kill")
        .args(["-TERM", &pa.to_string()])
        .status()
        .unwrap();
    a.0.wait().unwrap();
    let (code, out, err) = st(&[]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains(&running(pb)), "{out}");
    assert!(
        !out.contains("stopped") && !out.contains(&format!("pid {pa}")),
        "{out}"
    );
    let (code, out, _) = st(&[ps]);
    assert_eq!(code, 3, "{out}");
    assert!(out.contains(&format!("(pid {pa}) stopped")), "{out}");
    assert_eq!(st(&[qs]).0, 0);

    // None runs: the last one stopped, exit 3.
    Command::new("kill")
        .args(["-TERM", &pb.to_string()])
        .status()
        .unwrap();
    b.0.wait().unwrap();
    let (code, out, _) = st(&[]);
    assert_eq!(code, 3, "{out}");
    assert!(out.contains(&format!("(pid {pb}) stopped")), "{out}");

    // The next daemon removes the states of those that ended, and is shown alone.
    let mut c = start(&p, "c.jsonl");
    let pc = c.0.id();
    let states = || -> Vec<String> {
        fs::read_dir(xdg.join("skillpost"))
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .filter(|n| n.starts_with("status"))
            .collect()
    };
    wait_for("the stopped daemons' states removed", || {
        states() == [format!("status-{pc}.json")]
    });
    wait_for("C running", || st(&[]).1.contains(&running(pc)));
    // Killed without a word: its state says `running`, but it is not taken for it.
    c.0.kill().unwrap();
    c.0.wait().unwrap();
    let (code, out, _) = st(&[]);
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains(&format!("warning: pid {pc} is not running")),
        "{out}"
    );
}
