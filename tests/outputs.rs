//! What the outputs may not overwrite, through the command line and the daemon: a symbolic
//! link's target, an input of the compile, a read-only file.

mod common;

use std::fs;
use std::os::unix::fs::PermissionsExt as _;
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

fn run(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `<tmp>/proj` holding the sample, and `<tmp>/outside/precious.txt`.
fn layout() -> (tempfile::TempDir, std::path::PathBuf, std::path::PathBuf) {
    let t = tempfile::tempdir().unwrap();
    let proj = t.path().join("proj");
    fs::create_dir(&proj).unwrap();
    common::copy_sample(&proj);
    let outside = t.path().join("outside");
    fs::create_dir(&outside).unwrap();
    let precious = outside.join("precious.txt");
    fs::write(&precious, "precious\n").unwrap();
    (t, proj, precious)
}

#[test]
fn cli_refuses_an_output_that_is_a_symlink() {
    let (_t, proj, precious) = layout();
    std::os::unix::fs::symlink("../outside/precious.txt", proj.join("Blackboard.src")).unwrap();
    let bb = fs::read(proj.join("Blackboard.aml")).unwrap();
    let o = run(&["Blackboard.aml", "Blackboard"], &proj);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("symbolic link"), "{}", stderr(&o));
    assert_eq!(fs::read_to_string(&precious).unwrap(), "precious\n");
    assert!(
        fs::symlink_metadata(proj.join("Blackboard.src"))
            .unwrap()
            .file_type()
            .is_symlink()
    );
    // Nothing of the pair, no write-back.
    assert!(!proj.join("Blackboard.dat").exists());
    assert_eq!(fs::read(proj.join("Blackboard.aml")).unwrap(), bb);
}

#[test]
fn cli_refuses_an_input_named_like_an_output() {
    // The SFC named `Cell.dat`, the program `Cell`: E605 at the SFC's refURI.
    let (_t, proj, _) = layout();
    fs::rename(proj.join("sfc.xml"), proj.join("Cell.dat")).unwrap();
    let bb = fs::read_to_string(proj.join("Blackboard.aml"))
        .unwrap()
        .replace("<Value>sfc.xml</Value>", "<Value>./Cell.dat</Value>");
    fs::write(proj.join("Blackboard.aml"), &bb).unwrap();
    let sfc = fs::read(proj.join("Cell.dat")).unwrap();
    let o = run(&["--format", "json", "Blackboard.aml", "Cell"], &proj);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout).into_owned() + &stderr(&o);
    let line = out
        .lines()
        .find(|l| l.contains("\"E605\""))
        .unwrap_or_else(|| panic!("no E605: {out}"));
    let d: serde_json::Value = serde_json::from_str(line).unwrap();
    assert_eq!(d["file"], "Blackboard.aml");
    assert_eq!(d["line"], 97, "{d}");
    assert_eq!(fs::read(proj.join("Cell.dat")).unwrap(), sfc);
    assert!(!proj.join("Cell.src").exists());
    assert_eq!(fs::read_to_string(proj.join("Blackboard.aml")).unwrap(), bb);
}

#[test]
fn cli_refuses_an_input_reached_through_a_link() {
    // The IRL reference names `kr15-2.irl`, a link to `Cell.src`: the output `Cell.src` is that
    // input.
    let (_t, proj, _) = layout();
    fs::rename(proj.join("kr15-2.irl"), proj.join("Cell.src")).unwrap();
    std::os::unix::fs::symlink("Cell.src", proj.join("kr15-2.irl")).unwrap();
    let irl = fs::read(proj.join("Cell.src")).unwrap();
    let o = run(&["Blackboard.aml", "Cell"], &proj);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("E605"), "{}", stderr(&o));
    assert_eq!(fs::read(proj.join("Cell.src")).unwrap(), irl);
}

#[test]
fn cli_respects_a_read_only_output() {
    let (_t, proj, _) = layout();
    let src = proj.join("Prog.src");
    fs::write(&src, "frozen by hand\r\n").unwrap();
    fs::set_permissions(&src, fs::Permissions::from_mode(0o444)).unwrap();
    let o = run(&["Blackboard.aml", "Prog"], &proj);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("read-only (mode 0444)"),
        "{}",
        stderr(&o)
    );
    assert_eq!(fs::read_to_string(&src).unwrap(), "frozen by hand\r\n");
    assert_eq!(
        fs::metadata(&src).unwrap().permissions().mode() & 0o7777,
        0o444
    );
    assert!(!proj.join("Prog.dat").exists());
}

#[test]
fn daemon_refuses_a_symlink_output_and_a_read_only_one() {
    let (t, proj, precious) = layout();
    std::os::unix::fs::symlink("../outside/precious.txt", proj.join("Blackboard.src")).unwrap();
    let mut w = common::Watch::start(t.path(), 50, &[proj.to_str().unwrap()]);
    let evs = w.wait_for("compile-failed", Duration::from_secs(20), |e| {
        e["event"] == "compile-failed"
    });
    let failed = evs.iter().find(|e| e["event"] == "compile-failed").unwrap();
    let d = &failed["diagnostics"][0];
    assert_eq!(d["code"], "E604", "{failed}");
    assert!(
        d["message"].as_str().unwrap().contains("symbolic link"),
        "{failed}"
    );
    assert_eq!(fs::read_to_string(&precious).unwrap(), "precious\n");
    assert!(!proj.join("Blackboard.dat").exists());
    drop(w);

    // A read-only output: the same, its bytes and mode kept.
    fs::remove_file(proj.join("Blackboard.src")).unwrap();
    fs::write(proj.join("Blackboard.src"), "frozen").unwrap();
    fs::set_permissions(
        proj.join("Blackboard.src"),
        fs::Permissions::from_mode(0o444),
    )
    .unwrap();
    fs::remove_file(t.path().join("events.jsonl")).unwrap();
    let mut w = common::Watch::start(t.path(), 50, &[proj.to_str().unwrap()]);
    let evs = w.wait_for("compile-failed", Duration::from_secs(20), |e| {
        e["event"] == "compile-failed"
    });
    let failed = evs.iter().find(|e| e["event"] == "compile-failed").unwrap();
    assert_eq!(failed["diagnostics"][0]["code"], "E604", "{failed}");
    assert_eq!(
        fs::read_to_string(proj.join("Blackboard.src")).unwrap(),
        "frozen"
    );
    assert_eq!(
        fs::metadata(proj.join("Blackboard.src"))
            .unwrap()
            .permissions()
            .mode()
            & 0o7777,
        0o444
    );
}

#[test]
fn daemon_refuses_an_input_named_like_an_output() {
    let t = tempfile::tempdir().unwrap();
    let proj = t.path().join("Cell");
    fs::create_dir(&proj).unwrap();
    let case =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/err/e605_irl_named_like_output");
    for f in ["Blackboard.aml", "sfc.xml", "Cell.src"] {
        fs::copy(case.join(f), proj.join(f)).unwrap();
    }
    fs::rename(proj.join("Blackboard.aml"), proj.join("Cell.aml")).unwrap();
    let irl = fs::read(proj.join("Cell.src")).unwrap();
    let mut w = common::Watch::start(t.path(), 50, &[proj.to_str().unwrap()]);
    let evs = w.wait_for("compile-failed", Duration::from_secs(20), |e| {
        e["event"] == "compile-failed"
    });
    let failed = evs.iter().find(|e| e["event"] == "compile-failed").unwrap();
    // The error (a warning of the compile, W211 for the robot without tool data, may come first).
    let d = failed["diagnostics"]
        .as_array()
        .unwrap()
        .iter()
        .find(|d| d["severity"] == "error")
        .unwrap();
    assert_eq!(d["code"], "E605", "{failed}");
    assert_eq!(d["line"], 89, "{failed}");
    assert_eq!(fs::read(proj.join("Cell.src")).unwrap(), irl);
    assert!(!proj.join("Cell.dat").exists());
}

// ---- the write-back's refusals, through the daemon -------------------------------------------

#[test]
fn daemon_does_not_split_a_hard_linked_blackboard() {
    let t = tempfile::tempdir().unwrap();
    let proj = t.path().join("proj");
    fs::create_dir(&proj).unwrap();
    common::copy_sample(&proj);
    let other = t.path().join("second-name.aml");
    fs::hard_link(proj.join("Blackboard.aml"), &other).unwrap();
    let before = fs::read(&other).unwrap();
    let mut w = common::Watch::start(t.path(), 50, &[proj.to_str().unwrap()]);
    let evs = w.wait_for("write-back", Duration::from_secs(20), |e| {
        e["event"] == "write-back"
    });
    let wb = evs.iter().find(|e| e["event"] == "write-back").unwrap();
    assert_eq!(wb["written"], false, "{wb}");
    assert!(
        wb["reason"].as_str().unwrap().contains("hard links"),
        "{wb}"
    );
    assert_eq!(wb["level"], "warn", "{wb}");
    // Not retried in a loop, and both names still one file with the old bytes.
    std::thread::sleep(Duration::from_millis(800));
    let starts = w
        .events()
        .iter()
        .filter(|e| e["event"] == "compile-started")
        .count();
    assert_eq!(starts, 1, "{:?}", w.events());
    use std::os::unix::fs::MetadataExt as _;
    let (a, b) = (
        fs::metadata(proj.join("Blackboard.aml")).unwrap(),
        fs::metadata(&other).unwrap(),
    );
    assert_eq!(a.ino(), b.ino());
    assert_eq!(fs::read(&other).unwrap(), before);
}

#[test]
fn daemon_waits_for_a_program_holding_the_blackboard_open() {
    let t = tempfile::tempdir().unwrap();
    let proj = t.path().join("proj");
    fs::create_dir(&proj).unwrap();
    common::copy_sample(&proj);
    let bb = proj.join("Blackboard.aml");
    // Another program has the blackboard open (for writing) during the startup compile.
    let held = fs::File::options().append(true).open(&bb).unwrap();
    let mut w = common::Watch::start(t.path(), 50, &[proj.to_str().unwrap()]);
    let evs = w.wait_for("write-back", Duration::from_secs(20), |e| {
        e["event"] == "write-back"
    });
    let wb = evs.iter().find(|e| e["event"] == "write-back").unwrap();
    if wb["written"] == true {
        // No lease here (it would have been refused): the fallback wrote.
        common::skip("no file lease on this file system: the write-back cannot see open files");
        return;
    }
    assert!(
        wb["reason"]
            .as_str()
            .unwrap()
            .contains("has the blackboard open"),
        "{wb}"
    );
    assert!(
        fs::read_to_string(&bb)
            .unwrap()
            .contains("<Value>none</Value>")
    );
    // The program saves and closes: the save compiles and the value is written.
    let text = fs::read_to_string(&bb)
        .unwrap()
        .replacen("?>", "?><!-- saved -->", 1);
    drop(held);
    fs::write(&bb, text).unwrap();
    w.wait_for(
        "the write-back after the save",
        Duration::from_secs(20),
        |e| e["event"] == "write-back" && e["written"] == true,
    );
    let after = fs::read_to_string(&bb).unwrap();
    assert!(after.contains("<!-- saved -->") && after.contains("<Value>Blackboard.src</Value>"));
}

#[test]
fn daemon_writes_back_once_a_program_lets_go_of_the_blackboard_without_saving() {
    let t = tempfile::tempdir().unwrap();
    let proj = t.path().join("proj");
    fs::create_dir(&proj).unwrap();
    common::copy_sample(&proj);
    let bb = proj.join("Blackboard.aml");
    // A program (an indexer, a viewer) has the blackboard open, then closes it without a save:
    // no edit follows, so the daemon itself must try again.
    let held = fs::File::options().append(true).open(&bb).unwrap();
    let mut w = common::Watch::start(t.path(), 50, &[proj.to_str().unwrap()]);
    let evs = w.wait_for("write-back", Duration::from_secs(20), |e| {
        e["event"] == "write-back"
    });
    let wb = evs.iter().find(|e| e["event"] == "write-back").unwrap();
    if wb["written"] == true {
        common::skip("no file lease on this file system: the write-back cannot see open files");
        return;
    }
    drop(held);
    let evs = w.wait_for(
        "the write-back once the blackboard is closed",
        Duration::from_secs(20),
        |e| e["event"] == "write-back" && e["written"] == true,
    );
    let again = evs
        .iter()
        .filter(|e| e["event"] == "compile-started")
        .skip(1)
        .all(|e| e["trigger"] == "write-back-skipped");
    assert!(again, "{evs:?}");
    assert!(
        fs::read_to_string(&bb)
            .unwrap()
            .contains("<Value>Blackboard.src</Value>")
    );
}

/// Issue 24, finding 4: a read-only blackboard is the planner's "do not change": the outputs
/// are written, the blackboard keeps its bytes and inode, and stdout says why.
#[test]
fn cli_leaves_a_read_only_blackboard_alone() {
    use std::os::unix::fs::MetadataExt as _;
    let (_t, proj, _) = layout();
    let bb = proj.join("Blackboard.aml");
    fs::set_permissions(&bb, fs::Permissions::from_mode(0o444)).unwrap();
    let (before, ino) = (fs::read(&bb).unwrap(), fs::metadata(&bb).unwrap().ino());
    let o = run(&["Blackboard.aml", "Cell"], &proj);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("blackboard not updated") && out.contains("read-only"),
        "{out}"
    );
    assert!(proj.join("Cell.src").exists() && proj.join("Cell.dat").exists());
    assert_eq!(fs::read(&bb).unwrap(), before);
    assert_eq!(fs::metadata(&bb).unwrap().ino(), ino);
    assert_eq!(fs::metadata(&bb).unwrap().mode() & 0o7777, 0o444);
}

/// Issue 24, finding 4: a user who may replace files in the folder but cannot give a new file
/// the blackboard's owner (no CAP_CHOWN) does not replace it: it would become that user's.
#[test]
fn cli_does_not_take_over_another_users_blackboard() {
    use std::os::unix::fs::MetadataExt as _;
    let Some(mut nobody) = common::as_nobody("make a blackboard of another user") else {
        return;
    };
    let (t, proj, _) = layout();
    // The folder is the unprivileged user's (it may rename in it), the blackboard root's.
    fs::set_permissions(t.path(), fs::Permissions::from_mode(0o755)).unwrap();
    for e in fs::read_dir(&proj).unwrap() {
        let p = e.unwrap().path();
        fs::set_permissions(&p, fs::Permissions::from_mode(0o644)).unwrap();
    }
    std::os::unix::fs::chown(&proj, Some(65534), Some(65534)).unwrap();
    let bb = proj.join("Blackboard.aml");
    let (before, ino) = (fs::read(&bb).unwrap(), fs::metadata(&bb).unwrap().ino());
    let o = nobody
        .arg(env!("CARGO_BIN_EXE_skillpost"))
        .args(["Blackboard.aml", "Cell"])
        .current_dir(&proj)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("blackboard not updated") && out.contains("owner"),
        "{out}"
    );
    assert!(proj.join("Cell.src").exists());
    assert_eq!(fs::read(&bb).unwrap(), before);
    let m = fs::metadata(&bb).unwrap();
    assert_eq!((m.ino(), m.uid(), m.gid()), (ino, 0, 0));
    assert!(
        fs::read_dir(&proj).unwrap().all(|e| !e
            .unwrap()
            .file_name()
            .to_string_lossy()
            .starts_with(".skillpost-")),
        "a temporary file was left"
    );
}

#[test]
fn cli_writes_back_into_a_blackboard_that_starts_with_two_boms_and_keeps_them() {
    // A tool that wrote a BOM before text that had one already (the blackboard fuzz target's
    // finding crash-c836d2b5 was about this shape): the write-back changes the value only, the
    // second run finds it right.
    let (_t, proj, _) = layout();
    let bb = proj.join("Blackboard.aml");
    let text = fs::read(&bb).unwrap();
    let body = text.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&text).to_vec();
    let body = String::from_utf8(body)
        .unwrap()
        .replace("<Value>none</Value>", "<Value>old.src</Value>");
    assert!(body.contains("<Value>old.src</Value>"));
    let mut two = b"\xEF\xBB\xBF\xEF\xBB\xBF".to_vec();
    two.extend_from_slice(body.as_bytes());
    fs::write(&bb, &two).unwrap();
    let o = run(&["Blackboard.aml", "Prog"], &proj);
    assert!(o.status.success(), "{}", stderr(&o));
    let after = fs::read(&bb).unwrap();
    let expected = [
        b"\xEF\xBB\xBF\xEF\xBB\xBF".as_slice(),
        body.replace("<Value>old.src</Value>", "<Value>Prog.src</Value>")
            .as_bytes(),
    ]
    .concat();
    assert_eq!(after, expected, "only the value changed, both BOMs kept");
    let o = run(&["Blackboard.aml", "Prog"], &proj);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("wrote back"), "{}", stderr(&o));
    assert_eq!(fs::read(&bb).unwrap(), expected);
}
