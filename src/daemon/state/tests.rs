//! The unit tests of the state: the status line, the tracker, the state files, the table.

use super::*;
use crate::daemon::events::{Counts, Event, OutputInfo};
use std::path::Path;

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
