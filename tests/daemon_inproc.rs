//! The daemon in this process (`skillpost::daemon::run` with its control channel, events into a
//! buffer; harness in tests/inproc/mod.rs): files that must never block it, roots and aliases
//! that must never stop being watched, editor-like input names, a blackboard shared by two
//! projects, one daemon per folder; the run's `instance` in its events; nothing left outside
//! temporary folders.

mod common;
mod inproc;

use std::fs;
use std::path::Path;
use std::thread::sleep;
use std::time::{Duration, Instant};

use inproc::*;

/// Diagnostics codes of a `compile-failed` event.
fn codes(e: &serde_json::Value) -> Vec<String> {
    e["diagnostics"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|d| d["code"].as_str().map(str::to_owned))
                .collect()
        })
        .unwrap_or_default()
}

/// Edits `project`'s SFC to x and waits for the compile that has it. (A compile that was already
/// running when the edit came may succeed after it with the old SFC; the daemon compiles again
/// after it, and that compile has the edit.)
fn edit_and_expect(d: &InProc, project: &Path, x: u32) {
    let mark = d.mark();
    fs::write(project.join("sfc.xml"), sfc_with_x(x)).unwrap();
    let want = ptp_with_x(x);
    d.wait_for(
        &format!("recompile of {} with x {x}", project.display()),
        WAIT,
        |e| {
            is_after(e, "compile-succeeded", project, mark)
                && read_string(&src_of(project)).contains(&want)
        },
    );
}

// ---------------------------------------------------------------------------------------------
// Never block: FIFOs and devices
// ---------------------------------------------------------------------------------------------

#[test]
fn fifo_inputs_neither_hang_their_project_nor_starve_others() {
    let w = Workspace::new();
    let good = w.project("good");
    // Ten projects whose SFC is a FIFO from the start (a compile reading it would wait for a
    // writer for ever; so would the half-written check hashing it).
    let mut bad = Vec::new();
    for i in 0..10 {
        let p = w.project(&format!("fifo{i}"));
        fs::remove_file(p.join("sfc.xml")).unwrap();
        mkfifo(&p.join("sfc.xml"));
        bad.push(p);
    }
    // And one whose SFC becomes a FIFO after a good compile (its content hash is then checked).
    let later = w.project("later");
    let mut dirs: Vec<&Path> = bad.iter().map(|p| p.as_path()).collect();
    dirs.push(&good);
    dirs.push(&later);
    let d = InProc::with_dirs(&dirs);
    d.startup(&[&good, &later]);
    for p in &bad {
        let evs = d.wait_for(&format!("compile-failed of {}", p.display()), WAIT, |e| {
            is_for(e, "compile-failed", p)
        });
        let e = evs.iter().find(|e| is_for(e, "compile-failed", p)).unwrap();
        assert!(
            e.to_string().contains("not a regular file"),
            "the FIFO is named as such: {e}"
        );
    }
    let mark = d.mark();
    fs::remove_file(later.join("sfc.xml")).unwrap();
    mkfifo(&later.join("sfc.xml"));
    d.wait_for(
        "compile-failed of the project whose SFC became a FIFO",
        WAIT,
        |e| is_after(e, "compile-failed", &later, mark),
    );
    // The healthy project is not starved: an edit compiles at once.
    let t = Instant::now();
    edit_and_expect(&d, &good, 111);
    assert!(t.elapsed() < Duration::from_secs(3), "{:?}", t.elapsed());
    // And the daemon stops promptly (a compile stuck on a FIFO would keep it).
    let took = d.stop(Duration::from_secs(3));
    assert!(took < Duration::from_secs(2), "stop took {took:?}");
}

#[test]
fn fifo_or_device_as_the_configuration_fails_the_reload_and_the_daemon_goes_on() {
    let w = Workspace::new();
    let a = w.project("A");
    let config = w.config(&format!("[[project]]\npath = \"{}\"\n", a.display()));
    let d = InProc::with_config(&config);
    d.startup(&[&a]);
    for (what, make) in [
        (
            "a FIFO",
            Box::new(|p: &Path| mkfifo(p)) as Box<dyn Fn(&Path)>,
        ),
        (
            "a link to /dev/zero",
            Box::new(|p: &Path| std::os::unix::fs::symlink("/dev/zero", p).unwrap()),
        ),
    ] {
        fs::remove_file(&config).unwrap();
        make(&config);
        let mark = d.mark();
        let t = Instant::now();
        d.reload();
        let evs = d.wait_for(&format!("reload-failed for {what}"), WAIT, |e| {
            seq(e) > mark && is(e, "reload-failed")
        });
        assert!(
            t.elapsed() < Duration::from_secs(1),
            "{what}: {:?}",
            t.elapsed()
        );
        let e = evs
            .iter()
            .find(|e| seq(e) > mark && is(e, "reload-failed"))
            .unwrap();
        assert!(
            e["error"].as_str().unwrap().contains("not a regular file"),
            "{what}: {e}"
        );
    }
    // Still serving the old configuration.
    edit_and_expect(&d, &a, 222);
    d.stop(WAIT);
}

// ---------------------------------------------------------------------------------------------
// Watching that never silently stops
// ---------------------------------------------------------------------------------------------

#[test]
fn root_missing_at_start_then_created_deleted_and_created_again() {
    let w = Workspace::new();
    let root = w.ws().join("cells").join("root");
    let config = w.config(&format!("[[root]]\npath = \"{}\"\n", root.display()));
    let d = InProc::with_config(&config);
    d.wait_for("watch-degraded for the missing root", WAIT, |e| {
        is(e, "watch-degraded") && e["root"] == root.to_str().unwrap()
    });
    // Created later, two levels at once: the nearest existing ancestor is watched.
    let a = root.join("A");
    copy_project(&a);
    d.wait_for("the new root's project compiled", WAIT, |e| {
        is_for(e, "write-back", &a)
    });
    let evs = d.events();
    assert!(
        evs.iter()
            .any(|e| is(e, "watching") && e["root"] == root.to_str().unwrap()),
        "a `watching` event says the root is watched now\n{}",
        dump(&evs)
    );
    sleep(Duration::from_millis(SETTLE_MS * 6));
    edit_and_expect(&d, &a, 301);

    // Deleted and created again (a new inode: the kernel ended the old watches).
    let mark = d.mark();
    fs::remove_dir_all(&root).unwrap();
    d.wait_for("watch-degraded for the removed root", WAIT, |e| {
        seq(e) > mark && is(e, "watch-degraded") && e["root"] == root.to_str().unwrap()
    });
    let b = root.join("B");
    copy_project(&b);
    d.wait_for("the re-created root's new project compiled", WAIT, |e| {
        is_after(e, "write-back", &b, mark)
    });
    sleep(Duration::from_millis(SETTLE_MS * 6));
    edit_and_expect(&d, &b, 302);
    d.stop(WAIT);
}

#[test]
fn root_replaced_between_two_checks_is_watched_again() {
    let w = Workspace::new();
    let root = w.ws().join("root");
    let a = root.join("A");
    copy_project(&a);
    let config = w.config(&format!("[[root]]\npath = \"{}\"\n", root.display()));
    let d = InProc::with_config(&config);
    d.startup(&[&a]);
    // A root that exists at startup is `watching` (issue 27, item 6), without a reason.
    let evs = d.events();
    assert!(
        evs.iter().any(|e| is(e, "watching")
            && e["root"] == root.to_str().unwrap()
            && e.get("reason").is_none()),
        "{}",
        dump(&evs)
    );
    // Replaced by rename in one step: the path never disappears for a stat.
    let mark = d.mark();
    let new = w.ws().join("root.new");
    copy_project(&new.join("A"));
    let old = w.ws().join("root.old");
    fs::rename(&root, &old).unwrap();
    fs::rename(&new, &root).unwrap();
    fs::remove_dir_all(&old).unwrap();
    // (After the startup's `watching` for the root.)
    d.wait_for("the root is watched again", WAIT, |e| {
        seq(e) > mark && is(e, "watching") && e["root"] == root.to_str().unwrap()
    });
    sleep(Duration::from_millis(SETTLE_MS * 6));
    edit_and_expect(&d, &a, 303);
    // A project created in the new root is found.
    let b = root.join("B");
    copy_project(&b);
    d.wait_for("the new project in the replaced root", WAIT, |e| {
        is_for(e, "write-back", &b)
    });
    d.stop(WAIT);
}

#[test]
fn removing_a_symlink_alias_by_reload_keeps_the_real_project_compiling() {
    let w = Workspace::new();
    let real = w.project("real");
    let alias = w.ws().join("alias");
    std::os::unix::fs::symlink(&real, &alias).unwrap();
    let both = format!(
        "[[project]]\npath = \"{}\"\n[[project]]\npath = \"{}\"\n",
        real.display(),
        alias.display()
    );
    let config = w.config(&both);
    let d = InProc::with_config(&config);
    // One folder, two names: one of them compiles, the other is refused (one blackboard).
    let evs = d.wait_for("the alias refused", WAIT, |e| {
        is(e, "compile-failed") && codes(e) == ["E701"]
    });
    let refused = evs.iter().find(|e| is(e, "compile-failed")).unwrap();
    let msg = refused["diagnostics"][0]["message"].as_str().unwrap();
    assert!(msg.contains("real") && msg.contains("alias"), "{msg}");
    sleep(Duration::from_millis(SETTLE_MS * 6));

    // Drop the alias: the real project (same inode, the same inotify watch) goes on.
    w.config(&format!("[[project]]\npath = \"{}\"\n", real.display()));
    let mark = d.mark();
    d.reload();
    d.wait_for("reloaded", WAIT, |e| seq(e) > mark && is(e, "reloaded"));
    sleep(Duration::from_millis(SETTLE_MS * 6));
    for x in [401, 402] {
        edit_and_expect(&d, &real, x);
    }

    // And the other way round: alias kept, real removed.
    w.config(&format!("[[project]]\npath = \"{}\"\n", alias.display()));
    let mark = d.mark();
    d.reload();
    d.wait_for("the alias compiled", WAIT, |e| {
        is_after(e, "compile-succeeded", &alias, mark)
    });
    sleep(Duration::from_millis(SETTLE_MS * 6));
    edit_and_expect(&d, &alias, 403);
    d.stop(WAIT);
}

#[test]
fn inputs_with_editor_like_names_are_tracked() {
    let w = Workspace::new();
    let p = w.ws().join("P");
    fs::create_dir_all(&p).unwrap();
    let bb = sample_text("Blackboard.aml")
        .replace(">sfc.xml<", ">plan.tmp<")
        .replace(">kr15-2.irl<", ">robot.swp<");
    fs::write(p.join("Blackboard.aml"), bb).unwrap();
    fs::write(p.join("plan.tmp"), sample_text("sfc.xml")).unwrap();
    fs::write(p.join("robot.swp"), sample_text("kr15-2.irl")).unwrap();
    inproc::literal_points(&p);
    let d = InProc::with_dirs(&[&p]);
    d.startup(&[&p]);
    for x in [501, 502] {
        let mark = d.mark();
        fs::write(p.join("plan.tmp"), sfc_with_x(x)).unwrap();
        d.wait_for("recompile after an edit of plan.tmp", WAIT, |e| {
            is_after(e, "compile-succeeded", &p, mark)
        });
        assert!(read_string(&src_of(&p)).contains(&ptp_with_x(x)));
    }
    let mark = d.mark();
    let irl = sample_text("kr15-2.irl");
    assert!(irl.contains("\t\t\tSetVelCP (VALUE)"));
    fs::write(
        p.join("robot.swp"),
        irl.replace("\t\t\tSetVelCP (VALUE)", "\t\t\tSetVelCP (VALUE) ; edited"),
    )
    .unwrap();
    d.wait_for("recompile after an edit of robot.swp", WAIT, |e| {
        is_after(e, "compile-succeeded", &p, mark)
    });
    assert!(read_string(&src_of(&p)).contains("; edited"));
    // Real editor noise beside them still starts nothing.
    sleep(Duration::from_millis(SETTLE_MS * 6));
    let mark = d.mark();
    for n in ["4913", "plan.tmp~", ".plan.tmp.swp", "other.tmp"] {
        fs::write(p.join(n), "x").unwrap();
    }
    sleep(Duration::from_millis(SETTLE_MS * 8));
    let evs = d.events();
    assert_eq!(
        count_after(&evs, "compile-started", &p, mark),
        0,
        "{}",
        dump(&evs)
    );
    d.stop(WAIT);
}

// ---------------------------------------------------------------------------------------------
// Two projects, one blackboard; two daemons, one folder
// ---------------------------------------------------------------------------------------------

#[test]
fn a_blackboard_shared_by_two_projects_is_not_rewritten_back_and_forth() {
    let w = Workspace::new();
    let a = w.project("A");
    let b = w.ws().join("B");
    fs::create_dir(&b).unwrap();
    for f in ["sfc.xml", "kr15-2.irl"] {
        fs::copy(sample().join(f), b.join(f)).unwrap();
    }
    std::os::unix::fs::symlink(a.join("Blackboard.aml"), b.join("Blackboard.aml")).unwrap();
    let config = w.config(&format!(
        "allow_outside = true\n[[project]]\npath = \"{}\"\n[[project]]\npath = \"{}\"\n",
        a.display(),
        b.display()
    ));
    let d = InProc::with_config(&config);
    let evs = d.wait_for("B refused", WAIT, |e| {
        is_for(e, "compile-failed", &b) && codes(e) == ["E701"]
    });
    let e = evs
        .iter()
        .find(|e| is_for(e, "compile-failed", &b))
        .unwrap();
    let msg = e["diagnostics"][0]["message"].as_str().unwrap();
    assert!(
        msg.contains(a.to_str().unwrap()),
        "names the other project: {msg}"
    );
    d.wait_for("A compiled", WAIT, |e| is_for(e, "write-back", &a));
    // No edits for 3 s: at most the startup write-back, never a ping-pong.
    sleep(Duration::from_secs(3));
    let evs = d.events();
    let written = evs
        .iter()
        .filter(|e| is(e, "write-back") && e["written"] == true)
        .count();
    assert!(written <= 1, "{written} write-backs\n{}", dump(&evs));
    let compiles = evs.iter().filter(|e| is(e, "compile-started")).count();
    assert!(compiles <= 2, "{compiles} compiles\n{}", dump(&evs));

    // Give B its own blackboard: it compiles.
    let mark = d.mark();
    fs::remove_file(b.join("Blackboard.aml")).unwrap();
    fs::copy(sample().join("Blackboard.aml"), b.join("Blackboard.aml")).unwrap();
    d.wait_for("B compiled with its own blackboard", WAIT, |e| {
        is_after(e, "compile-succeeded", &b, mark)
    });
    d.stop(WAIT);
}

#[test]
fn a_second_daemon_on_the_same_folder_is_refused_and_touches_nothing() {
    let w = Workspace::new();
    let a = w.project("A");
    let d = InProc::with_dirs(&[&a]);
    d.startup(&[&a]);
    // A file the first daemon has staged (it would be renamed into place next).
    let staged = a.join(".skillpost-012345.tmp");
    fs::write(&staged, "staged").unwrap();
    // The second: the same folder under another name (a link), its own configuration.
    let link = w.ws().join("link");
    std::os::unix::fs::symlink(&a, &link).unwrap();
    let sources = skillpost::daemon::Sources {
        dirs: vec![link.clone()],
        settle_ms: Some(SETTLE_MS),
        ..Default::default()
    };
    let err = match InProc::try_start(sources.load().unwrap(), sources) {
        Ok(_) => panic!("a second daemon started on the same folder"),
        Err(e) => e,
    };
    assert!(err.contains("another skillpost daemon"), "{err}");
    assert!(
        err.contains(&format!("pid {}", std::process::id())),
        "{err}"
    );
    assert_eq!(
        read_string(&staged),
        "staged",
        "the first daemon's staged file is kept"
    );
    fs::remove_file(&staged).unwrap();
    edit_and_expect(&d, &a, 601);
    d.stop(WAIT);
    // Stopped: the folder is free again.
    let sources = skillpost::daemon::Sources {
        dirs: vec![a.clone()],
        settle_ms: Some(SETTLE_MS),
        ..Default::default()
    };
    let again = InProc::start(sources.load().unwrap(), sources);
    again.stop(WAIT);
}

// ---------------------------------------------------------------------------------------------
// Forgetting, under the paused clock (the default 30 s pass at once)
// ---------------------------------------------------------------------------------------------

#[test]
fn root_projects_gone_are_forgotten_after_the_default_period_explicit_ones_never() {
    let w = Workspace::new();
    let root = w.ws().join("root");
    let a = root.join("A");
    copy_project(&a);
    let e = w.project("E");
    let config = w.config(&format!(
        "[[root]]\npath = \"{}\"\n[[project]]\npath = \"{}\"\n",
        root.display(),
        e.display()
    ));
    let sources = skillpost::daemon::Sources {
        config_file: Some(config.clone()),
        settle_ms: Some(SETTLE_MS),
        ..Default::default()
    };
    let d = InProc::start_paused(sources.load().unwrap(), sources);
    for p in [&a, &e] {
        d.wait_for("startup compile", WAIT, |ev| is_for(ev, "write-back", p));
    }
    fs::remove_dir_all(&a).unwrap();
    fs::remove_dir_all(&e).unwrap();
    let evs = d.wait_for("A forgotten", WAIT, |ev| {
        is_for(ev, "watch-degraded", &a)
            && ev["reason"]
                .as_str()
                .is_some_and(|r| r.contains("forgotten"))
    });
    let forgotten = evs
        .iter()
        .find(|ev| {
            is_for(ev, "watch-degraded", &a) && ev["reason"].to_string().contains("forgotten")
        })
        .unwrap();
    assert!(
        forgotten["reason"].as_str().unwrap().contains("30 s"),
        "the default period: {forgotten}"
    );
    // The explicit project is only reported missing, never forgotten, however long it is gone.
    sleep(Duration::from_millis(300));
    let evs = d.events();
    assert!(
        !evs.iter()
            .any(|ev| is_for(ev, "watch-degraded", &e)
                && ev["reason"].to_string().contains("forgotten")),
        "{}",
        dump(&evs)
    );
    // Back: the root's project is found again as a new project, the explicit one picked up.
    let mark = d.mark();
    copy_project(&a);
    copy_project(&e);
    for p in [&a, &e] {
        d.wait_for("compiled again", WAIT, |ev| {
            is_after(ev, "compile-succeeded", p, mark)
        });
    }
    d.stop(WAIT);
}

// ---------------------------------------------------------------------------------------------
// Robot languages
// ---------------------------------------------------------------------------------------------

#[test]
fn rapid_and_urscript_projects_are_compiled_watched_and_reported_like_krl_ones() {
    let w = Workspace::new();
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/base");
    // (folder, fixture base, output extension, IRL file, an edit of it); the program is named
    // after the blackboard, `Cell.aml`.
    let cases = [
        (
            "Cell_UR",
            "ur",
            "script",
            "ur10e.irl",
            ("sleep(T)", "sleep(T)\n\t\t\tsync()"),
        ),
        (
            "Cell_ABB",
            "abb",
            "mod",
            "irb1200.irl",
            ("WaitTime T;", "WaitTime T;\n\t\t\tWaitTime 0.1;"),
        ),
    ];
    let mut dirs = Vec::new();
    for (name, b, ..) in &cases {
        let dir = w.ws().join(name);
        fs::create_dir(&dir).unwrap();
        for e in fs::read_dir(base.join(b)).unwrap() {
            let e = e.unwrap();
            fs::copy(e.path(), dir.join(e.file_name())).unwrap();
        }
        dirs.push(dir);
    }
    let refs: Vec<&Path> = dirs.iter().map(|p| p.as_path()).collect();
    let d = InProc::with_dirs(&refs);
    d.startup(&refs);
    for ((name, _, ext, irl, (from, to)), dir) in cases.iter().zip(&dirs) {
        let output = dir.join(format!("Cell.{ext}"));
        let evs = d.events();
        let ok = evs
            .iter()
            .find(|e| is_for(e, "compile-succeeded", dir))
            .unwrap_or_else(|| panic!("no compile-succeeded for {name}:\n{}", dump(&evs)));
        let paths: Vec<&str> = ok["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|o| o["path"].as_str().unwrap())
            .collect();
        // The program, its I/O list, and for RAPID its EIO.cfg fragment.
        let mut want = vec![
            output.display().to_string(),
            dir.join("Cell.io.csv").display().to_string(),
        ];
        if *ext == "mod" {
            want.push(dir.join("Cell.eio.cfg").display().to_string());
        }
        assert_eq!(paths, want, "{name}: {ok}");
        assert!(!dir.join("Cell.src").exists(), "{name}: a .src");
        let bb = read_string(&dir.join("Cell.aml"));
        assert!(
            bb.contains(&format!("<Value>Cell.{ext}</Value>")),
            "{name}: the write-back names the .{ext}"
        );
        // The IRL file is an input: editing it recompiles into the language's output.
        let mark = d.mark();
        let text = read_string(&dir.join(irl));
        assert!(text.contains(from));
        fs::write(dir.join(irl), text.replace(from, to)).unwrap();
        d.wait_for(&format!("the recompile of {name}"), WAIT, |e| {
            is_after(e, "compile-succeeded", dir, mark)
        });
        let new_line = to.lines().last().unwrap().trim();
        assert!(
            read_string(&output).contains(new_line),
            "{name}: the .{ext} holds `{new_line}`"
        );
    }
    d.stop(WAIT);
}

// ---------------------------------------------------------------------------------------------
// The run's identity; nothing left behind
// ---------------------------------------------------------------------------------------------

/// Issue 27, item 11: `seq` starts at 1 in every run, so two runs appended to one events file
/// (`--events`, a restart) are told apart by `instance`: the same in every event of a run,
/// across a reload (which reopens the file), and another in the next run.
#[test]
fn runs_appended_to_one_events_file_have_their_own_instance() {
    let w = Workspace::new();
    let a = w.project("A");
    let events = w.root.join("events.jsonl");
    for x in [701, 702] {
        let sources = skillpost::daemon::Sources {
            dirs: vec![a.clone()],
            events: Some(events.clone()),
            settle_ms: Some(SETTLE_MS),
            ..Default::default()
        };
        let d = InProc::start_appending(sources.load().unwrap(), sources);
        d.startup(&[&a]);
        d.reload();
        d.wait_for("the reload", WAIT, |e| is(e, "reloaded"));
        edit_and_expect(&d, &a, x);
        d.stop(WAIT);
    }
    let all: Vec<serde_json::Value> = read_string(&events)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    // The runs in the order they appended, each one's events together.
    let mut runs: Vec<(String, Vec<&serde_json::Value>)> = Vec::new();
    for e in &all {
        let instance = e["instance"]
            .as_str()
            .unwrap_or_else(|| panic!("no instance: {e}"));
        assert!(!instance.is_empty(), "{e}");
        match runs.last_mut() {
            Some((i, evs)) if i == instance => evs.push(e),
            _ => runs.push((instance.to_owned(), vec![e])),
        }
    }
    assert_eq!(
        runs.len(),
        2,
        "two runs, one instance each:\n{}",
        dump(&all)
    );
    assert_ne!(runs[0].0, runs[1].0, "the second run has another instance");
    for (instance, evs) in &runs {
        let seqs: Vec<u64> = evs.iter().map(|e| e["seq"].as_u64().unwrap()).collect();
        assert_eq!(
            seqs,
            (1..=evs.len() as u64).collect::<Vec<_>>(),
            "{instance}: seq from 1 without gaps, as in every run"
        );
        assert!(is(evs[0], "started"), "{instance} starts with started");
        assert!(
            is(evs[evs.len() - 1], "stopped"),
            "{instance} ends with stopped"
        );
        assert!(evs.iter().any(|e| is(e, "reloaded")), "{instance}");
        assert!(evs.iter().any(|e| is(e, "compile-succeeded")), "{instance}");
    }
}

/// Issue 27, item 4: the daemon tests keep everything in temporary folders — nothing in the
/// real runtime folder (`/tmp/skillpost-<uid>`, `$XDG_RUNTIME_DIR/skillpost`), nothing kept in
/// `/tmp`. Two in-process daemons (the second refused, naming the first's pid from its lock
/// note) run again with `TMPDIR`, `HOME` and `XDG_RUNTIME_DIR` in a sandbox that must be empty
/// afterwards. The harness used to keep a `skillpost-test-run-*` folder in the temporary
/// directory for good, one per test binary run.
#[test]
fn daemon_tests_leave_nothing_outside_their_temporary_folders() {
    for test in [
        "a_second_daemon_on_the_same_folder_is_refused_and_touches_nothing",
        "runs_appended_to_one_events_file_have_their_own_instance",
    ] {
        let left = common::leftovers_of(test);
        assert!(left.is_empty(), "{test} left {left:#?}");
    }
}

// ---------------------------------------------------------------------------------------------
// Issue 27, item 10: a blackboard another program holds open
// ---------------------------------------------------------------------------------------------

/// A planner's save of `p`'s blackboard that sets the write-back value wrong (so the compile
/// must write it back), with `comment` in it; returns the program holding it open read-only
/// (a viewer), opened before the save so that it holds the compile's write-back.
fn save_with_a_viewer(p: &Path, comment: &str) -> fs::File {
    let bb = p.join("Blackboard.aml");
    let viewer = fs::File::open(&bb).unwrap();
    let text = read_string(&bb)
        .replace("<Value>Blackboard.src</Value>", "<Value>wrong</Value>")
        .replacen("?>", &format!("?><!-- {comment} -->"), 1);
    fs::write(&bb, text).unwrap();
    viewer
}

/// Whether this file system refused the write-back's lease while the viewer had the file open
/// (else nothing can wait for it: the write-back wrote at once).
fn leases_here(wb: &serde_json::Value) -> bool {
    !(wb["written"] == true && wb.get("waited_ms").is_none())
}

/// A viewer holding the blackboard open read-only for 3 s across a save: one compile (it was
/// one compile plus a `write-back-skipped` compile every ~1.3 s), whose write-back waits for
/// the viewer and then writes; `duration_ms` is the compile's own time, the wait is the
/// write-back's `waited_ms`.
#[test]
fn a_blackboard_held_open_gives_one_compile_whose_write_back_waits() {
    let w = Workspace::new();
    let p = w.project("P");
    let bb = p.join("Blackboard.aml");
    let d = InProc::with_dirs(&[&p]);
    d.startup(&[&p]);
    let mark = d.mark();
    let viewer = save_with_a_viewer(&p, "saved");
    let held = Instant::now();
    let closer = std::thread::spawn(move || {
        sleep(Duration::from_secs(3));
        drop(viewer);
    });
    let evs = d.wait_for("the write-back", Duration::from_secs(20), |e| {
        is_after(e, "write-back", &p, mark)
    });
    closer.join().unwrap();
    let wb = evs
        .iter()
        .find(|e| is_after(e, "write-back", &p, mark))
        .unwrap();
    if !leases_here(wb) {
        common::skip("no file lease here: the write-back cannot see the open file");
        return;
    }
    assert_eq!(wb["written"], true, "written once the viewer closed: {wb}");
    assert!(
        held.elapsed() >= Duration::from_millis(2900),
        "not before the viewer closed it"
    );
    let waited = wb["waited_ms"].as_u64().expect("waited_ms");
    assert!(waited >= 2000, "the wait is the write-back's: {wb}");
    let done = evs
        .iter()
        .find(|e| is_after(e, "compile-succeeded", &p, mark))
        .unwrap();
    let compile_ms = done["duration_ms"].as_u64().unwrap();
    assert!(
        compile_ms < 1000,
        "duration_ms is the compile's, without the wait: {done}"
    );
    assert!(
        seq(done) < seq(wb),
        "compile-succeeded comes before the write-back"
    );
    assert_eq!(done["run_id"], wb["run_id"]);
    // Nothing more: no compile of the daemon's own write, no round after a skipped write-back.
    sleep(Duration::from_millis(SETTLE_MS * 10));
    let evs = d.events();
    assert_eq!(
        count_after(&evs, "compile-started", &p, mark),
        1,
        "one save, one compile:\n{}",
        dump(&evs)
    );
    let after = read_string(&bb);
    assert!(after.contains("<!-- saved -->") && after.contains("<Value>Blackboard.src</Value>"));
}

/// A save during the write-back's wait is never overwritten: the wait ends at once (the
/// write-back is skipped), the save is compiled, and its write-back waits for the viewer.
#[test]
fn a_save_while_the_write_back_waits_is_kept_and_compiled() {
    let w = Workspace::new();
    let p = w.project("P");
    let bb = p.join("Blackboard.aml");
    let d = InProc::with_dirs(&[&p]);
    d.startup(&[&p]);
    let mark = d.mark();
    let viewer = save_with_a_viewer(&p, "first");
    d.wait_for("the first compile", WAIT, |e| {
        is_after(e, "compile-succeeded", &p, mark)
    });
    sleep(Duration::from_millis(300));
    if d.events()
        .iter()
        .any(|e| is_after(e, "write-back", &p, mark) && e["written"] == true)
    {
        common::skip("no file lease here: the write-back cannot see the open file");
        return;
    }
    // The planner saves again (in place) while the write-back waits for the viewer.
    let text = read_string(&bb).replace("<!-- first -->", "<!-- second -->");
    fs::write(&bb, text).unwrap();
    let evs = d.wait_for("the skipped write-back", WAIT, |e| {
        is_after(e, "write-back", &p, mark)
    });
    let wb = evs
        .iter()
        .find(|e| is_after(e, "write-back", &p, mark))
        .unwrap();
    assert_eq!(wb["written"], false, "{wb}");
    assert!(
        wb["reason"].as_str().unwrap().contains("changed on disk"),
        "{wb}"
    );
    assert!(
        read_string(&bb).contains("<!-- second -->"),
        "the save is kept"
    );
    // Its compile's write-back waits for the viewer too, and writes once it is closed.
    sleep(Duration::from_millis(500));
    drop(viewer);
    d.wait_for("the value written", Duration::from_secs(20), |e| {
        is_after(e, "write-back", &p, mark) && e["written"] == true
    });
    let after = read_string(&bb);
    assert!(after.contains("<!-- second -->") && after.contains("<Value>Blackboard.src</Value>"));
    let evs = d.events();
    assert_eq!(
        count_after(&evs, "compile-started", &p, mark),
        2,
        "the first save and the save meanwhile:\n{}",
        dump(&evs)
    );
}

/// A stop does not wait for the viewer: the waiting write-back gives up at once (skipped,
/// another program has the blackboard open), the daemon stops cleanly (it waited out its
/// ~1.3 s of tries).
#[test]
fn a_stop_ends_the_write_backs_wait() {
    let w = Workspace::new();
    let p = w.project("P");
    let d = InProc::with_dirs(&[&p]);
    d.startup(&[&p]);
    let mark = d.mark();
    let viewer = save_with_a_viewer(&p, "saved");
    d.wait_for("the compile", WAIT, |e| {
        is_after(e, "compile-started", &p, mark)
    });
    sleep(Duration::from_millis(400));
    let took = d.stop(Duration::from_secs(5));
    drop(viewer);
    assert!(took < Duration::from_millis(500), "the stop took {took:?}");
}

// ---------------------------------------------------------------------------------------------
// A folder the outputs cannot be written to, fixed by a permission change (issue 27, item 5)
// ---------------------------------------------------------------------------------------------

/// A daemon of an unprivileged user (the binary, as `nobody`: root may write anywhere) and a
/// project folder it may read but not write (what `cp -r` of a `0755` folder gives the service):
/// the first compile fails with E604. Its inputs were all read, so the hash check found nothing
/// to do afterwards; now the permission fix of the folder (`chmod`) compiles it without an edit,
/// and so does a `touch` of the folder. A `touch` of an input still starts nothing.
#[test]
fn a_project_whose_outputs_could_not_be_written_compiles_after_its_folder_is_fixed() {
    use std::os::unix::fs::PermissionsExt as _;
    let Some(mut nobody) = common::as_nobody("run the daemon as a user a folder can refuse") else {
        return;
    };
    let w = Workspace::new();
    fs::set_permissions(&w.root, fs::Permissions::from_mode(0o755)).unwrap();
    fs::set_permissions(w.ws(), fs::Permissions::from_mode(0o755)).unwrap();
    let p = w.project("P");
    let run = w.root.join("run");
    fs::create_dir(&run).unwrap();
    for d in [&p, &run] {
        std::os::unix::fs::chown(d, Some(65534), Some(65534)).unwrap();
    }
    for f in FILES {
        std::os::unix::fs::chown(p.join(f), Some(65534), Some(65534)).unwrap();
    }
    fs::set_permissions(&p, fs::Permissions::from_mode(0o555)).unwrap();
    let ev = run.join("events.jsonl");
    let mut child = nobody
        .arg(env!("CARGO_BIN_EXE_skillpost"))
        .args(["watch", "--settle", "50", "--events"])
        .arg(&ev)
        .arg(&p)
        .env("XDG_RUNTIME_DIR", &run)
        .env_remove("RUNTIME_DIRECTORY")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let events = || -> Vec<serde_json::Value> {
        read_string(&ev)
            .lines()
            .filter_map(|l| serde_json::from_str(l).ok())
            .collect()
    };
    let count = |what: &str| events().iter().filter(|e| is(e, what)).count();
    let result = (|| -> Result<(), String> {
        if !wait_until(Duration::from_secs(20), || count("compile-failed") >= 1) {
            return Err("no compile-failed in the unwritable folder".into());
        }
        let failed = events()
            .into_iter()
            .find(|e| is(e, "compile-failed"))
            .unwrap();
        if codes(&failed) != ["E604"] || !failed.to_string().contains("Permission denied") {
            return Err(format!("not E604 Permission denied: {failed}"));
        }
        // Nothing else happens by itself.
        sleep(Duration::from_millis(300));
        if count("compile-started") != 1 {
            return Err("a compile without a change".into());
        }
        // The fix: the folder made writable.
        fs::set_permissions(&p, fs::Permissions::from_mode(0o755)).unwrap();
        if !wait_until(Duration::from_secs(10), || {
            count("compile-succeeded") == 1 && count("write-back") == 1
        }) {
            return Err("not compiled after the folder's permission was fixed".into());
        }
        if !read_string(&src_of(&p)).contains("PTP") {
            return Err("no program written".into());
        }
        // `touch` of an input: nothing; `touch` of the folder: one compile.
        let touch = |path: &Path| {
            let ok = std::process::Command::new("touch")
                .arg(path)
                .status()
                .unwrap()
                .success();
            assert!(ok);
        };
        touch(&p.join("sfc.xml"));
        sleep(Duration::from_millis(500));
        if count("compile-started") != 2 {
            return Err("a touch of an input started a compile".into());
        }
        touch(&p);
        if !wait_until(Duration::from_secs(10), || count("compile-succeeded") == 2) {
            return Err("a touch of the project folder did not compile it".into());
        }
        sleep(Duration::from_millis(300));
        if count("compile-started") != 3 {
            return Err("more than one compile for a touch of the folder".into());
        }
        Ok(())
    })();
    let _ = child.kill();
    let _ = child.wait();
    if let Err(e) = result {
        panic!("{e}:\n{}", read_string(&ev));
    }
}

/// Issue 27, item 5: a reload retries a project whose last compile could not write its outputs
/// (E604), as an administrator does after fixing the cause. Here the cause is a folder named
/// like the program's `.src`; removing it is no input change, so nothing else compiles again.
#[test]
fn a_reload_retries_a_project_whose_outputs_could_not_be_written() {
    let w = Workspace::new();
    let p = w.project("P");
    let src = src_of(&p);
    let _ = fs::remove_file(&src);
    fs::create_dir(&src).unwrap();
    let config = w.config(&format!("[[project]]\npath = \"{}\"\n", p.display()));
    let d = InProc::with_config(&config);
    d.wait_for("E604 for the folder named like the output", WAIT, |e| {
        is_for(e, "compile-failed", &p) && codes(e).first().map(String::as_str) == Some("E604")
    });
    let fixed = d.mark();
    fs::remove_dir(&src).unwrap();
    sleep(Duration::from_millis(SETTLE_MS * 6));
    assert_eq!(
        count_after(&d.events(), "compile-started", &p, fixed),
        0,
        "the fix alone started a compile: {}",
        dump(&d.events())
    );
    let mark = d.mark();
    d.reload();
    d.wait_for("the retry after the reload", WAIT, |e| {
        is_after(e, "compile-succeeded", &p, mark)
    });
    assert!(src.is_file());
    d.stop(WAIT);
}

/// A cell's `Program` renamed (`Welding` → `WeldingB`): the new program is written and the old
/// one's file stays (it may still be on the controller) — never deleted, but named as stale in
/// `compile-succeeded` and in `skillpost status`. The write-back event lists every program's
/// value (each controller's), not only the first.
#[test]
fn a_renamed_programs_old_files_are_named_stale_and_kept() {
    let w = Workspace::new();
    let a = w.ws().join("Cell");
    fs::create_dir_all(&a).unwrap();
    let step5 = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/tutorial/step5");
    for e in fs::read_dir(&step5).unwrap() {
        let e = e.unwrap();
        fs::copy(e.path(), a.join(e.file_name())).unwrap();
    }
    let sources = skillpost::daemon::Sources {
        dirs: vec![a.clone()],
        settle_ms: Some(SETTLE_MS),
        ..Default::default()
    };
    let state = w.root.join("status.json");
    let d = InProc::start_with_state(sources.load().unwrap(), sources, &state);
    let evs = d.wait_for("the first compile", WAIT, |e| is_for(e, "write-back", &a));
    let first = evs
        .iter()
        .find(|e| is_for(e, "compile-succeeded", &a))
        .unwrap();
    assert!(first.get("stale").is_none(), "{first}");
    let wb = evs.iter().find(|e| is_for(e, "write-back", &a)).unwrap();
    let values = wb["values"].as_array().unwrap();
    assert_eq!(values.len(), 2, "both controllers' values: {wb}");
    assert!(values.iter().any(|v| v == "Welding.mod"), "{wb}");
    assert!(a.join("Welding.mod").exists());

    let mark = d.mark();
    let bb = a.join("Blackboard.aml");
    let text = fs::read_to_string(&bb).unwrap();
    fs::write(
        &bb,
        text.replace(
            "<Attribute Name=\"Program\"><Value>Welding</Value></Attribute>",
            "<Attribute Name=\"Program\"><Value>WeldingB</Value></Attribute>",
        ),
    )
    .unwrap();
    let evs = d.wait_for("the compile of the rename", WAIT, |e| {
        is_after(e, "compile-succeeded", &a, mark)
    });
    let second = evs
        .iter()
        .find(|e| is_after(e, "compile-succeeded", &a, mark))
        .unwrap();
    assert_eq!(
        second["stale"],
        serde_json::json!([a.join("Welding.mod").display().to_string()]),
        "{second}"
    );
    assert!(a.join("WeldingB.mod").exists());
    assert!(a.join("Welding.mod").exists(), "never deleted");
    let mut table = String::new();
    wait_until(WAIT, || {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
            .args(["status", "--state"])
            .arg(&state)
            .output()
            .unwrap();
        table = String::from_utf8_lossy(&out.stdout).into_owned();
        table.contains("stale")
    });
    assert!(
        table.contains("WeldingB.eio.cfg; stale (not written, kept): Welding.mod"),
        "{table}"
    );
    d.stop(WAIT);
}
