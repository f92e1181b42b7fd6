//! Write faults: a full disk (a small tmpfs) and a folder nothing may be written to (`chattr +i`,
//! which holds even for root). Each test says it is skipped, and why, where the machine does not
//! allow the fault (mounting needs root).

mod common;

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::thread::sleep;
use std::time::{Duration, Instant};

use serde_json::Value;

fn sample() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ok/reference-sample")
}

fn copy_project(to: &Path) {
    fs::create_dir_all(to).unwrap();
    for f in ["Blackboard.aml", "sfc.xml", "kr15-2.irl"] {
        fs::copy(sample().join(f), to.join(f)).unwrap();
    }
}

fn temporaries(dir: &Path) -> Vec<String> {
    fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".skillpost-"))
        .collect()
}

/// A tmpfs of `kib` KiB at `dir`, unmounted on drop.
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(dir: &Path, kib: u32) -> Option<Self> {
        fs::create_dir_all(dir).unwrap();
        let ok = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={kib}k"), "tmpfs"])
            .arg(dir)
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        ok.then(|| Tmpfs(dir.to_owned()))
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}

/// `chattr +i` on a folder, undone on drop.
struct Immutable(PathBuf);

impl Immutable {
    fn set(dir: &Path) -> Option<Self> {
        let ok = Command::new("chattr")
            .arg("+i")
            .arg(dir)
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        ok.then(|| Immutable(dir.to_owned()))
    }
}

impl Drop for Immutable {
    fn drop(&mut self) {
        let _ = Command::new("chattr").arg("-i").arg(&self.0).status();
    }
}

/// Fills the file system of `dir` until less than `leave` bytes are free.
fn fill(dir: &Path, leave: u64) {
    let mut f = fs::File::create(dir.join("filler")).unwrap();
    let chunk = vec![b'x'; 1024];
    use std::io::Write;
    loop {
        let st = rustix::fs::statvfs(dir).unwrap();
        if st.f_bavail * st.f_frsize < leave {
            break;
        }
        if f.write_all(&chunk).is_err() {
            break;
        }
        let _ = f.flush();
    }
}

struct Daemon(Child, PathBuf);

impl Daemon {
    fn start(events: &Path, projects: &[&Path]) -> Self {
        let child = Command::new(env!("CARGO_BIN_EXE_skillpost"))
            // Its state and lock notes beside the events, not in the real runtime folder.
            .env("XDG_RUNTIME_DIR", events.parent().unwrap())
            .env_remove("RUNTIME_DIRECTORY")
            .args(["watch", "--settle", "30", "--events"])
            .arg(events)
            .args(projects)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        Daemon(child, events.to_owned())
    }

    fn events(&self) -> Vec<Value> {
        fs::read_to_string(&self.1)
            .unwrap_or_default()
            .lines()
            .filter_map(|l| serde_json::from_str(l).ok())
            .collect()
    }

    fn wait_for(&self, what: &str, pred: impl Fn(&Value) -> bool) -> Vec<Value> {
        let deadline = Instant::now() + Duration::from_secs(8);
        loop {
            let evs = self.events();
            if evs.iter().any(&pred) {
                return evs;
            }
            assert!(
                Instant::now() < deadline,
                "no {what}; events:\n{}",
                evs.iter().map(|e| format!("{e}\n")).collect::<String>()
            );
            sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn is(e: &Value, event: &str, project: &Path) -> bool {
    e["event"] == event && e["project"] == project.to_str().unwrap()
}

fn failed_with(e: &Value, project: &Path, code: &str) -> bool {
    is(e, "compile-failed", project)
        && e["diagnostics"]
            .as_array()
            .is_some_and(|d| d.iter().any(|x| x["code"] == code))
}

#[test]
fn full_disk_is_a_clear_failure_and_other_projects_go_on() {
    let dir = tempfile::tempdir().unwrap();
    let ok = dir.path().join("ok");
    copy_project(&ok);
    let Some(_fs) = Tmpfs::mount(&dir.path().join("small"), 256) else {
        common::skip("cannot mount a tmpfs here (needs root)");
        return;
    };
    let full = dir.path().join("small/full");
    copy_project(&full);
    // An earlier good output, to be kept.
    fs::write(full.join("Blackboard.src"), "previous\r\n").unwrap();
    fill(&dir.path().join("small"), 2048);

    let d = Daemon::start(&dir.path().join("events.jsonl"), &[&ok, &full]);
    let evs = d.wait_for("E604 for the full disk", |e| failed_with(e, &full, "E604"));
    let f = evs.iter().find(|e| failed_with(e, &full, "E604")).unwrap();
    let msg = f["diagnostics"][0]["message"].as_str().unwrap().to_owned();
    assert!(msg.contains("No space left"), "{msg}");
    assert_eq!(
        fs::read_to_string(full.join("Blackboard.src")).unwrap(),
        "previous\r\n"
    );
    assert!(temporaries(&full).is_empty(), "{:?}", temporaries(&full));
    // The other project compiled, and still compiles after an edit.
    d.wait_for("the healthy project compiled", |e| {
        is(e, "compile-succeeded", &ok)
    });
    let sfc = fs::read_to_string(ok.join("sfc.xml")).unwrap();
    fs::write(
        ok.join("sfc.xml"),
        sfc.replace("Value=\"0.5\"", "Value=\"0.25\""),
    )
    .unwrap();
    d.wait_for("the healthy project recompiled", |e| {
        is(e, "compile-succeeded", &ok) && e["run_id"].as_u64() > Some(1)
    });
    assert!(
        fs::read_to_string(ok.join("Blackboard.src"))
            .unwrap()
            .contains("SetVelCP (0.25)")
    );
    // Space again: the next change compiles.
    fs::remove_file(dir.path().join("small/filler")).unwrap();
    let sfc = fs::read_to_string(full.join("sfc.xml")).unwrap();
    fs::write(
        full.join("sfc.xml"),
        sfc.replace("Value=\"0.5\"", "Value=\"0.75\""),
    )
    .unwrap();
    d.wait_for("the full project compiled after space was freed", |e| {
        is(e, "compile-succeeded", &full)
    });
    assert!(
        fs::read_to_string(full.join("Blackboard.src"))
            .unwrap()
            .contains("SetVelCP (0.75)")
    );
}

#[test]
fn unwritable_folder_is_a_clear_failure_and_nothing_partial_is_left() {
    let dir = tempfile::tempdir().unwrap();
    let ok = dir.path().join("ok");
    let locked = dir.path().join("locked");
    copy_project(&ok);
    copy_project(&locked);
    let bb_before = fs::read(locked.join("Blackboard.aml")).unwrap();
    let Some(_imm) = Immutable::set(&locked) else {
        common::skip("chattr +i is not available here");
        return;
    };
    let d = Daemon::start(&dir.path().join("events.jsonl"), &[&ok, &locked]);
    let evs = d.wait_for("E604 for the locked folder", |e| {
        failed_with(e, &locked, "E604")
    });
    let f = evs
        .iter()
        .find(|e| failed_with(e, &locked, "E604"))
        .unwrap();
    let msg = f["diagnostics"][0]["message"].as_str().unwrap();
    assert!(msg.contains("not permitted"), "{msg}");
    assert_eq!(fs::read(locked.join("Blackboard.aml")).unwrap(), bb_before);
    assert!(!locked.join("Blackboard.src").exists());
    assert!(temporaries(&locked).is_empty());
    d.wait_for("the other project compiled", |e| {
        is(e, "compile-succeeded", &ok)
    });
}

#[test]
fn command_line_on_a_full_disk_exits_2_and_leaves_no_partial_file() {
    let dir = tempfile::tempdir().unwrap();
    let Some(_fs) = Tmpfs::mount(&dir.path().join("small"), 256) else {
        common::skip("cannot mount a tmpfs here (needs root)");
        return;
    };
    let p = dir.path().join("small/p");
    copy_project(&p);
    let bb_before = fs::read(p.join("Blackboard.aml")).unwrap();
    fill(&dir.path().join("small"), 2048);
    let o = Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["Blackboard.aml", "out"])
        .current_dir(&p)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("cannot write") && e.contains("No space left"),
        "{e}"
    );
    assert!(temporaries(&p).is_empty(), "{:?}", temporaries(&p));
    assert_eq!(fs::read(p.join("Blackboard.aml")).unwrap(), bb_before);
    // The pair is written together or not at all.
    assert!(!p.join("out.src").exists(), "no .src without its .dat");
    assert!(!p.join("out.dat").exists());
}

/// One output of the pair cannot be replaced (an immutable file, as a file owned by someone
/// else in a sticky folder would be): the other is not written either.
#[test]
fn an_output_that_cannot_be_replaced_keeps_the_pair_unwritten() {
    for locked in ["out.dat", "out.src"] {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("p");
        copy_project(&p);
        let bb_before = fs::read(p.join("Blackboard.aml")).unwrap();
        fs::write(p.join(locked), "stale\r\n").unwrap();
        let Some(_imm) = Immutable::set(&p.join(locked)) else {
            common::skip("chattr +i is not available here");
            return;
        };
        let o = Command::new(env!("CARGO_BIN_EXE_skillpost"))
            .args(["Blackboard.aml", "out"])
            .current_dir(&p)
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{locked}: {e}");
        assert!(
            e.contains(locked) && e.contains("not permitted"),
            "{locked}: {e}"
        );
        assert_eq!(fs::read_to_string(p.join(locked)).unwrap(), "stale\r\n");
        let other = if locked == "out.dat" {
            "out.src"
        } else {
            "out.dat"
        };
        assert!(
            !p.join(other).exists(),
            "{locked} locked, {other} written: {e}"
        );
        assert!(temporaries(&p).is_empty(), "{:?}", temporaries(&p));
        assert_eq!(fs::read(p.join("Blackboard.aml")).unwrap(), bb_before);
    }
}
