//! Issue 24 (Trust II): the attacks a third review found, each through the entry point a user
//! uses: the binary (`skillpost watch …`) or the daemon in this process (its control channel).
//! The write-back race of finding 1 is in tests/race.rs and `write::writeback`'s unit tests;
//! the read-only and foreign blackboards of finding 4 in tests/outputs.rs.

mod common;
mod inproc;

use std::fs;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use inproc::{InProc, WAIT, Workspace, is_for};

/// Runs `skillpost watch ARGS` and waits at most `limit` for it to end: its exit status and
/// stderr, or `None` when it was still running (then it is killed).
fn watch_exits(args: &[&str], cwd: &Path, limit: Duration) -> Option<(i32, String)> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .arg("watch")
        .args(args)
        .current_dir(cwd)
        .env("XDG_RUNTIME_DIR", cwd)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let end = Instant::now() + limit;
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            let out = child.wait_with_output().unwrap();
            return Some((
                st.code().unwrap_or(-1),
                String::from_utf8_lossy(&out.stderr).into_owned(),
            ));
        }
        if Instant::now() >= end {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Finding 2: `--events` or `--state` naming the blackboard (or any file in a watched folder)
/// is refused before anything is written.
#[test]
fn events_or_state_file_in_a_project_folder_is_refused() {
    let w = Workspace::new();
    let p = w.project("P");
    let bb = p.join("Blackboard.aml");
    let before = fs::read(&bb).unwrap();
    for flag in ["--events", "--state"] {
        let (code, err) = watch_exits(
            &[flag, bb.to_str().unwrap(), p.to_str().unwrap()],
            &w.root,
            Duration::from_secs(10),
        )
        .unwrap_or_else(|| panic!("{flag} Blackboard.aml: the daemon kept running"));
        assert_eq!(code, 2, "{flag}: {err}");
        assert!(
            err.contains("lies in the project folder") && err.contains("Blackboard.aml"),
            "{flag}: {err}"
        );
        assert_eq!(fs::read(&bb).unwrap(), before, "{flag}");
        assert!(
            !p.join("Blackboard.src").exists(),
            "{flag}: compiled anyway"
        );
    }
    // A file of its own in the folder (a log beside the project) is refused as well.
    let (code, err) = watch_exits(
        &[
            "--events",
            p.join("events.jsonl").to_str().unwrap(),
            p.to_str().unwrap(),
        ],
        &w.root,
        Duration::from_secs(10),
    )
    .unwrap();
    assert_eq!(code, 2, "{err}");
    assert!(!p.join("events.jsonl").exists());
}

/// Finding 2: a reload into a configuration whose events file lies in a project folder is a
/// `reload-failed`; the daemon goes on with the old configuration and writes nothing there.
#[test]
fn a_reload_that_puts_the_events_file_in_a_project_is_refused() {
    let w = Workspace::new();
    let p = w.project("P");
    let cfg = w.config(&format!("[[project]]\npath = \"{}\"\n", p.display()));
    let d = InProc::with_config(&cfg);
    d.startup(&[&p]);
    fs::write(
        &cfg,
        format!(
            "events = \"{}\"\n[[project]]\npath = \"{}\"\n",
            p.join("Blackboard.aml").display(),
            p.display()
        ),
    )
    .unwrap();
    let bb = fs::read(p.join("Blackboard.aml")).unwrap();
    d.reload();
    let evs = d.wait_for("reload-failed", WAIT, |e| inproc::is(e, "reload-failed"));
    let e = evs.iter().find(|e| inproc::is(e, "reload-failed")).unwrap();
    assert!(
        e["error"]
            .as_str()
            .unwrap()
            .contains("lies in the project folder"),
        "{e}"
    );
    assert_eq!(fs::read(p.join("Blackboard.aml")).unwrap(), bb);
    // Still watching: an edit compiles.
    fs::write(p.join("sfc.xml"), inproc::sfc_with_x(123)).unwrap();
    assert!(inproc::wait_until(WAIT, || inproc::read_string(
        &inproc::src_of(&p)
    )
    .contains(&inproc::ptp_with_x(123))));
}

/// Finding 2: a file a project reads is never removed as a "stale temporary", whatever its
/// name; a real leftover of ours is.
#[test]
fn an_input_named_like_a_temporary_is_kept_and_compiled() {
    let w = Workspace::new();
    let p = w.project("P");
    for name in [".skillpost-plan.tmp", ".skillpost-plan01.tmp"] {
        // The SFC under that name (the command line compiles it like any SFC).
        let sfc = p.join(name);
        if p.join("sfc.xml").exists() {
            fs::rename(p.join("sfc.xml"), &sfc).unwrap();
        } else {
            fs::write(&sfc, inproc::sample_text("sfc.xml")).unwrap();
        }
        let bb = inproc::sample_text("Blackboard.aml")
            .replace("<Value>sfc.xml</Value>", &format!("<Value>{name}</Value>"));
        fs::write(p.join("Blackboard.aml"), bb).unwrap();
        // A leftover of ours from a crash.
        let stale = p.join(".skillpost-a1B2c3.tmp");
        fs::write(&stale, "half a file").unwrap();
        let d = InProc::with_dirs(&[&p]);
        d.wait_for("the startup compile", WAIT, |e| {
            is_for(e, "compile-succeeded", &p) || is_for(e, "compile-failed", &p)
        });
        let evs = d.events();
        assert!(
            evs.iter().any(|e| is_for(e, "compile-succeeded", &p)),
            "{name}: {}",
            inproc::dump(&evs)
        );
        assert!(sfc.exists(), "{name}: the input was removed");
        d.startup(&[&p]);
        assert!(sfc.exists(), "{name}: the input was removed");
        assert!(!stale.exists(), "the stale temporary is still there");
        // And its edits compile.
        fs::write(&sfc, inproc::sfc_with_x(321)).unwrap();
        assert!(
            inproc::wait_until(WAIT, || inproc::read_string(&inproc::src_of(&p))
                .contains(&inproc::ptp_with_x(321))),
            "{name}: an edit of the SFC was not compiled\n{}",
            inproc::dump(&d.events())
        );
        d.stop(WAIT);
        fs::remove_file(&sfc).unwrap();
    }
}

/// Finding 6: `--events FIFO` ends at once with a clear error instead of hanging in `open`.
#[test]
fn a_fifo_as_events_file_is_refused_at_once() {
    let w = Workspace::new();
    let p = w.project("P");
    let fifo = w.root.join("events.fifo");
    inproc::mkfifo(&fifo);
    let (code, err) = watch_exits(
        &["--events", fifo.to_str().unwrap(), p.to_str().unwrap()],
        &w.root,
        Duration::from_secs(10),
    )
    .expect("the daemon hung opening a FIFO as its events file");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("FIFO"), "{err}");
}

/// Finding 6: the events file replaced by a FIFO before logrotate's `SIGHUP`: the reopen fails
/// at once (the old file is kept), edits are still compiled, `SIGTERM` still stops it.
#[test]
fn a_fifo_swapped_in_before_sighup_does_not_block_the_daemon() {
    let w = Workspace::new();
    let p = w.project("P");
    let ev = w.root.join("events.jsonl");
    let mut child = Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["watch", "--settle", "50", "--events"])
        .arg(&ev)
        .arg(&p)
        .env("XDG_RUNTIME_DIR", &w.root)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let pid = rustix::process::Pid::from_child(&child);
    assert!(
        inproc::wait_until(Duration::from_secs(20), || inproc::read_string(&ev)
            .contains("\"write-back\"")),
        "no startup write-back: {}",
        inproc::read_string(&ev)
    );
    fs::remove_file(&ev).unwrap();
    inproc::mkfifo(&ev);
    rustix::process::kill_process(pid, rustix::process::Signal::HUP).unwrap();
    std::thread::sleep(Duration::from_millis(200));
    fs::write(p.join("sfc.xml"), inproc::sfc_with_x(222)).unwrap();
    let compiled = inproc::wait_until(Duration::from_secs(10), || {
        inproc::read_string(&inproc::src_of(&p)).contains(&inproc::ptp_with_x(222))
    });
    rustix::process::kill_process(pid, rustix::process::Signal::TERM).unwrap();
    let end = Instant::now() + Duration::from_secs(15);
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break Some(st);
        }
        if Instant::now() >= end {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(compiled, "the edit after SIGHUP was not compiled");
    assert!(status.is_some(), "SIGTERM did not stop the daemon");
}

/// Finding 11: a blackboard whose SFC is the daemon's own state file gets one clear failure,
/// not a compile at every state write.
#[test]
fn the_daemons_own_state_file_as_an_input_fails_once() {
    let w = Workspace::new();
    let p = w.project("P");
    let state = w.root.join("state.json");
    let bb = inproc::sample_text("Blackboard.aml").replace(
        "<Value>sfc.xml</Value>",
        &format!("<Value>{}</Value>", state.display()),
    );
    fs::write(p.join("Blackboard.aml"), bb).unwrap();
    let sources = skillpost::daemon::Sources {
        dirs: vec![p.clone()],
        settle_ms: Some(inproc::SETTLE_MS),
        ..Default::default()
    };
    let mut config = sources.load().unwrap();
    config.allow_outside = true;
    let d = InProc::start_with_state(config, sources, &state);
    let evs = d.wait_for("compile-failed", WAIT, |e| is_for(e, "compile-failed", &p));
    let failed = evs
        .iter()
        .find(|e| is_for(e, "compile-failed", &p))
        .unwrap();
    assert!(
        failed.to_string().contains("own events or state file"),
        "{failed}"
    );
    // The state file is rewritten after every compile; none of that starts another one.
    std::thread::sleep(Duration::from_millis(1500));
    let evs = d.events();
    let started = evs
        .iter()
        .filter(|e| is_for(e, "compile-started", &p))
        .count();
    let retrying = evs
        .iter()
        .filter(|e| is_for(e, "compile-retrying", &p))
        .count();
    assert_eq!((started, retrying), (1, 0), "{}", inproc::dump(&evs));
}

/// Finding 15: only a file that is still changing is retried; a FIFO, a folder, a DOCTYPE
/// blackboard and a blackboard that is not UTF-8 fail at once.
#[test]
fn inputs_that_are_not_being_written_fail_without_retrying() {
    let w = Workspace::new();
    let fifo = w.project("Fifo");
    fs::remove_file(fifo.join("sfc.xml")).unwrap();
    inproc::mkfifo(&fifo.join("sfc.xml"));
    let folder = w.project("Folder");
    fs::remove_file(folder.join("sfc.xml")).unwrap();
    fs::create_dir(folder.join("sfc.xml")).unwrap();
    let doctype = w.project("Doctype");
    let text = inproc::sample_text("Blackboard.aml").replacen(
        "?>",
        "?><!DOCTYPE CAEXFile [<!ENTITY a \"b\">]>",
        1,
    );
    fs::write(doctype.join("Blackboard.aml"), text).unwrap();
    let latin1 = w.project("Latin1");
    let mut bytes = inproc::sample_text("Blackboard.aml").into_bytes();
    let at = bytes.windows(4).position(|x| x == b"Name").unwrap();
    bytes.insert(at, 0xF6); // ö in Latin-1: not UTF-8
    fs::write(latin1.join("Blackboard.aml"), bytes).unwrap();
    let all: [&Path; 4] = [&fifo, &folder, &doctype, &latin1];
    let d = InProc::with_dirs(&all);
    for p in all {
        d.wait_for(&format!("{} fails", p.display()), WAIT, |e| {
            is_for(e, "compile-failed", p)
        });
    }
    std::thread::sleep(Duration::from_millis(300));
    let evs = d.events();
    for p in all {
        let retrying = evs
            .iter()
            .filter(|e| is_for(e, "compile-retrying", p))
            .count();
        assert_eq!(retrying, 0, "{}: {}", p.display(), inproc::dump(&evs));
    }
}

/// Finding 14: a run after a skipped write-back says so (`write-back-skipped`), and every run
/// whose trigger is `change` follows a `change-detected`.
#[test]
fn runs_after_a_skipped_write_back_say_why() {
    let w = Workspace::new();
    let p = w.project("P");
    let bb = p.join("Blackboard.aml");
    let d = InProc::with_dirs(&[&p]);
    d.startup(&[&p]);
    // Another program holds the blackboard open while an edit compiles: the write-back waits,
    // skips, and the daemon compiles again a few times.
    let held = fs::File::options().append(true).open(&bb).unwrap();
    let text = fs::read_to_string(&bb)
        .unwrap()
        .replace("<Value>Blackboard.src</Value>", "<Value>wrong</Value>");
    fs::write(&bb, text).unwrap();
    let evs = d.wait_for("a skipped write-back", Duration::from_secs(20), |e| {
        is_for(e, "write-back", &p) && e["written"] == false
    });
    let skipped = evs
        .iter()
        .find(|e| is_for(e, "write-back", &p) && e["written"] == false)
        .unwrap();
    if !skipped["reason"]
        .as_str()
        .unwrap_or_default()
        .contains("open")
    {
        common::skip("no file lease here: the write-back cannot see the open file");
        return;
    }
    d.wait_for("the run after it", Duration::from_secs(20), |e| {
        is_for(e, "compile-started", &p) && e["trigger"] == "write-back-skipped"
    });
    // A save while that run waits for the blackboard: its event arrives during the run.
    let text = fs::read_to_string(&bb)
        .unwrap()
        .replacen("?>", "?><!-- saved meanwhile -->", 1);
    fs::write(&bb, text).unwrap();
    let mark = d.mark();
    d.wait_for("the run after the save", Duration::from_secs(20), |e| {
        inproc::is_after(e, "compile-started", &p, mark)
    });
    drop(held);
    d.wait_for("the value written", Duration::from_secs(20), |e| {
        is_for(e, "write-back", &p) && e["written"] == true
    });
    let evs = d.events();
    let mut detected = false;
    for e in evs.iter().filter(|e| inproc::project_is(e, &p)) {
        match e["event"].as_str().unwrap() {
            "change-detected" => detected = true,
            "compile-started" => {
                if e["trigger"] == "change" {
                    assert!(
                        detected,
                        "a `change` run without change-detected: {e}\n{}",
                        inproc::dump(&evs)
                    );
                }
                detected = false;
            }
            _ => {}
        }
    }
}
