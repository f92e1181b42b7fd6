//! The deploy hook (`on_success`, docs/DAEMON.md "Deploying"), through the daemon in this
//! process and its control channel: success (the worked example: copy to a controller share with
//! `install -m 0644`), failure with its stderr, a timeout that kills the hook's process group, a
//! hook that hangs while new compiles arrive (they go on; the newest waiting hook runs after it),
//! a stop while a hook runs, a hook printing megabytes, and a configuration in a project folder
//! that tries to set a hook.

mod inproc;

use std::fs;
use std::path::Path;
use std::thread::sleep;
use std::time::{Duration, Instant};

use inproc::*;
use serde_json::Value;

fn deploys(evs: &[Value], event: &str, project: &Path) -> Vec<Value> {
    evs.iter()
        .filter(|e| is_for(e, event, project))
        .cloned()
        .collect()
}

/// A configuration with one project and its hook (TOML array of strings).
fn config(w: &Workspace, project: &Path, hook: &[&str], extra: &str) -> std::path::PathBuf {
    let argv: Vec<String> = hook.iter().map(|a| format!("{a:?}")).collect();
    w.config(&format!(
        "{extra}\n[[project]]\npath = \"{}\"\non_success = [{}]\n",
        project.display(),
        argv.join(", ")
    ))
}

/// Whether a process with this pid exists (and is no zombie).
fn alive(pid: u32) -> bool {
    fs::read_to_string(format!("/proc/{pid}/stat"))
        .map(|s| {
            let state = s.rsplit(')').next().unwrap_or("").trim_start();
            !state.starts_with('Z')
        })
        .unwrap_or(false)
}

fn pid_in(file: &Path) -> u32 {
    let mut text = String::new();
    wait_until(WAIT, || {
        text = fs::read_to_string(file).unwrap_or_default();
        text.trim().parse::<u32>().is_ok()
    });
    text.trim().parse().unwrap()
}

#[test]
fn a_successful_compile_installs_its_outputs_on_the_share() {
    let w = Workspace::new();
    let a = w.project("A");
    let share = w.root.join("share");
    fs::create_dir(&share).unwrap();
    let share_s = format!("{}/", share.display());
    // The worked example of docs/DAEMON.md.
    let c = config(
        &w,
        &a,
        &["install", "-m", "0644", "{src}", "{dat}", &share_s],
        "",
    );
    let d = InProc::with_config(&c);
    let evs = d.wait_for("the startup deploy", WAIT, |e| {
        is_for(e, "deploy-succeeded", &a) || is_for(e, "deploy-failed", &a)
    });
    let ok = deploys(&evs, "deploy-succeeded", &a);
    assert_eq!(ok.len(), 1, "{}", dump(&evs));
    let started = deploys(&evs, "deploy-started", &a);
    // A bare name is the program PATH's absolute folders hold, found when the configuration
    // was read.
    let install = started[0]["argv"][0].as_str().unwrap().to_owned();
    assert!(
        install.starts_with('/') && install.ends_with("/install"),
        "{install}"
    );
    // `{src}` and `{dat}`: the daemon's own copy of what it wrote (same names), not the files
    // in the project folder that anyone who writes there could replace; gone after the hook.
    let argv: Vec<&str> = started[0]["argv"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap())
        .collect();
    assert_eq!(argv[1..3], ["-m", "0644"]);
    assert_eq!(argv[5], share_s);
    for (copy, name) in [(argv[3], "Blackboard.src"), (argv[4], "Blackboard.dat")] {
        let copy = Path::new(copy);
        assert_eq!(copy.file_name().unwrap(), name, "{argv:?}");
        assert!(!copy.starts_with(&a), "{argv:?}");
        assert!(
            copy.parent().unwrap().parent().unwrap().ends_with("deploy"),
            "{argv:?}"
        );
        assert!(
            !copy.exists(),
            "the copy outlived its hook: {}",
            copy.display()
        );
    }
    assert_eq!(
        fs::read(share.join("Blackboard.dat")).unwrap(),
        fs::read(a.join("Blackboard.dat")).unwrap()
    );
    // After the outputs: the compile's run, its files as written.
    let compiled = evs
        .iter()
        .find(|e| is_for(e, "compile-succeeded", &a))
        .unwrap();
    assert_eq!(started[0]["run_id"], compiled["run_id"]);
    assert!(seq(&started[0]) > seq(compiled));
    let wb = evs.iter().find(|e| is_for(e, "write-back", &a)).unwrap();
    assert!(seq(&started[0]) > seq(wb), "after the write-back");
    assert_eq!(
        fs::read(share.join("Blackboard.src")).unwrap(),
        fs::read(a.join("Blackboard.src")).unwrap()
    );
    use std::os::unix::fs::PermissionsExt as _;
    let mode = fs::metadata(share.join("Blackboard.dat"))
        .unwrap()
        .permissions()
        .mode();
    assert_eq!(mode & 0o777, 0o644);
    // An edit: deployed again, with the new program.
    let mark = d.mark();
    fs::write(a.join("sfc.xml"), sfc_with_x(321)).unwrap();
    d.wait_for("the edit's deploy", WAIT, |e| {
        is_after(e, "deploy-succeeded", &a, mark)
    });
    assert!(read_string(&share.join("Blackboard.src")).contains(&ptp_with_x(321)));
    // Same bytes again (a comment-free save of the same content): nothing new, no deploy.
    let mark = d.mark();
    fs::write(a.join("sfc.xml"), sfc_with_x(321)).unwrap();
    sleep(Duration::from_millis(SETTLE_MS * 8));
    assert!(
        !d.events()
            .iter()
            .any(|e| is_after(e, "deploy-started", &a, mark)),
        "{}",
        dump(&d.events())
    );
    d.stop(WAIT);
}

#[test]
fn a_failing_hook_reports_its_status_and_the_end_of_its_stderr() {
    let w = Workspace::new();
    let a = w.project("A");
    let c = config(
        &w,
        &a,
        &[
            "sh",
            "-c",
            "echo first line >&2; echo \"cannot reach $1\" >&2; exit 3",
            "sh",
            "{program}",
        ],
        "",
    );
    let d = InProc::with_config(&c);
    let evs = d.wait_for("the failed deploy", WAIT, |e| {
        is_for(e, "deploy-failed", &a)
    });
    let f = &deploys(&evs, "deploy-failed", &a)[0];
    assert_eq!(f["level"], "error");
    assert_eq!(f["exit_code"], 3);
    assert_eq!(f["timed_out"], false);
    assert_eq!(f["stderr"], "first line\ncannot reach Blackboard");
    assert!(f["reason"].as_str().unwrap().contains("status 3"), "{f}");
    // A program that does not exist: said so, the daemon goes on.
    d.stop(WAIT);
    let w2 = Workspace::new();
    let b = w2.project("B");
    let c = config(&w2, &b, &["/nonexistent/deploy", "{src}"], "");
    let d = InProc::with_config(&c);
    let evs = d.wait_for("the failed deploy", WAIT, |e| {
        is_for(e, "deploy-failed", &b)
    });
    let f = &deploys(&evs, "deploy-failed", &b)[0];
    assert!(
        f["reason"]
            .as_str()
            .unwrap()
            .contains("cannot run /nonexistent/deploy"),
        "{f}"
    );
    d.stop(WAIT);
}

#[test]
fn a_hook_past_its_timeout_is_killed_with_its_process_group() {
    let w = Workspace::new();
    let a = w.project("A");
    let pids = w.root.join("pids");
    // The hook starts a child of its own, then waits: both must be gone after the timeout.
    let script = format!(
        "sleep 600 & echo $! > {p}.child; echo $$ > {p}.hook; wait",
        p = pids.display()
    );
    let c = config(&w, &a, &["sh", "-c", &script], "deploy_timeout_s = 1");
    let d = InProc::with_config(&c);
    let hook = pid_in(&w.root.join("pids.hook"));
    let child = pid_in(&w.root.join("pids.child"));
    let t0 = Instant::now();
    let evs = d.wait_for("the timeout", WAIT, |e| is_for(e, "deploy-failed", &a));
    let f = &deploys(&evs, "deploy-failed", &a)[0];
    assert_eq!(f["timed_out"], true, "{f}");
    assert_eq!(f["signal"], 9, "{f}");
    assert!(f["duration_ms"].as_u64().unwrap() >= 1000, "{f}");
    assert!(t0.elapsed() < Duration::from_secs(4));
    assert!(
        wait_until(Duration::from_secs(2), || !alive(hook) && !alive(child)),
        "the hook ({hook}) or its child ({child}) outlived the timeout"
    );
    d.stop(WAIT);
}

#[test]
fn compiles_go_on_while_a_hook_hangs_and_the_newest_waiting_hook_runs_after_it() {
    let w = Workspace::new();
    let a = w.project("A");
    let log = w.root.join("deployed.log");
    let gate = w.root.join("gate");
    // Each hook notes the x of the program it deploys; the first one waits for the gate.
    let script = format!(
        "grep -o 'PTP {{{{X [0-9]*' \"$1\" | head -n1 >> {log}; while [ ! -e {gate} ]; do sleep 0.05; done",
        log = log.display(),
        gate = gate.display()
    );
    let c = config(&w, &a, &["sh", "-c", &script, "sh", "{src}"], "");
    let d = InProc::with_config(&c);
    d.wait_for("the first hook", WAIT, |e| is_for(e, "deploy-started", &a));
    // Three edits while it hangs: each compiles at once.
    for x in [501, 502, 503] {
        let mark = d.mark();
        fs::write(a.join("sfc.xml"), sfc_with_x(x)).unwrap();
        d.wait_for(&format!("the compile of {x} during the hook"), WAIT, |e| {
            is_after(e, "compile-succeeded", &a, mark)
        });
        assert!(read_string(&src_of(&a)).contains(&ptp_with_x(x)));
    }
    let evs = d.events();
    assert_eq!(
        deploys(&evs, "deploy-started", &a).len(),
        1,
        "one hook at a time\n{}",
        dump(&evs)
    );
    // The programs of a compile go to the hook's queue once the inputs have been quiet for the
    // quiet period after it; on a slow machine an earlier edit's may already wait there. No
    // event says when the last one is queued: the gate opens after ten quiet periods, so that
    // the newest is the one waiting (opened earlier, the waiting one runs and the newest after
    // it: three hooks, also right, but not what this test is about).
    sleep(Duration::from_millis(10 * SETTLE_MS));
    fs::write(&gate, "").unwrap();
    let evs = d.wait_for("the second hook's end", WAIT, |e| {
        is_for(e, "deploy-succeeded", &a) && e["run_id"].as_u64() > Some(1)
    });
    sleep(Duration::from_millis(300));
    let evs = d.events().into_iter().chain(evs).collect::<Vec<_>>();
    let started = deploys(&evs, "deploy-started", &a);
    // The startup's hook, then only the newest of the three waiting ones.
    let runs: std::collections::BTreeSet<u64> = started
        .iter()
        .map(|e| e["run_id"].as_u64().unwrap())
        .collect();
    assert_eq!(runs.len(), 2, "{}", dump(&evs));
    let last_compile = evs
        .iter()
        .filter(|e| is_for(e, "compile-succeeded", &a))
        .map(|e| e["run_id"].as_u64().unwrap())
        .max()
        .unwrap();
    assert_eq!(runs.iter().max(), Some(&last_compile));
    let lines = read_string(&log);
    assert_eq!(lines.lines().count(), 2, "{lines}");
    assert!(lines.lines().last().unwrap().contains("503"), "{lines}");
    d.stop(WAIT);
}

#[test]
fn a_stop_while_a_hook_runs_ends_it_within_the_stop_timeout() {
    let w = Workspace::new();
    let a = w.project("A");
    let pid = w.root.join("pid");
    // A hook that ignores SIGTERM: the stop's SIGKILL ends it.
    let script = format!(
        "trap '' TERM; echo $$ > {}; sleep 600 & wait; wait",
        pid.display()
    );
    let c = config(&w, &a, &["sh", "-c", &script], "");
    let d = InProc::with_config(&c);
    let hook = pid_in(&pid);
    d.wait_for("the hook", WAIT, |e| is_for(e, "deploy-started", &a));
    let took = d.stop(Duration::from_secs(10));
    assert!(took < Duration::from_secs(5), "the stop took {took:?}");
    assert!(
        wait_until(Duration::from_secs(2), || !alive(hook)),
        "the hook outlived the daemon"
    );
}

#[test]
fn a_hook_printing_megabytes_is_read_and_only_the_end_of_stderr_kept() {
    let w = Workspace::new();
    let a = w.project("A");
    let c = config(
        &w,
        &a,
        &[
            "sh",
            "-c",
            "head -c 50000000 /dev/zero; i=0; while [ $i -lt 20000 ]; do echo \"noise $i\"; i=$((i+1)); done >&2; echo last words >&2",
        ],
        "",
    );
    let d = InProc::with_config(&c);
    let evs = d.wait_for("the deploy", Duration::from_secs(30), |e| {
        is_for(e, "deploy-succeeded", &a) || is_for(e, "deploy-failed", &a)
    });
    let ok = deploys(&evs, "deploy-succeeded", &a);
    assert_eq!(ok.len(), 1, "{}", dump(&evs));
    let tail = ok[0]["stderr"].as_str().unwrap();
    assert!(tail.len() <= 4096, "{} bytes", tail.len());
    assert!(tail.ends_with("last words"), "{tail}");
    assert!(
        tail.starts_with("noise "),
        "from a line start: {}",
        &tail[..20]
    );
    d.stop(WAIT);
}

#[test]
fn a_configuration_in_a_project_folder_may_not_set_a_hook() {
    let w = Workspace::new();
    let a = w.project("A");
    // The configuration file a planner could write: in the project folder.
    let file = a.join("skillpost.toml");
    fs::write(
        &file,
        format!(
            "settle_ms = 50\n[[project]]\npath = \"{}\"\non_success = [\"sh\", \"-c\", \"touch /tmp/owned\"]\n",
            a.display()
        ),
    )
    .unwrap();
    let sources = skillpost::daemon::Sources {
        config_file: Some(file.clone()),
        ..Default::default()
    };
    let e = sources.load().expect_err("refused");
    assert_eq!(e.line, Some(4), "{e:?}");
    assert!(e.message.contains("lies in the project folder"), "{e:?}");
    // And through the command line: exit status 2, the message, nothing run.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["watch", "--config"])
        .arg(&file)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("on_success"), "{stderr}");
    assert!(stderr.contains(":4:"), "located: {stderr}");
    // The same hook from a configuration outside the folder is fine.
    let outside = w.config(&format!(
        "[[project]]\npath = \"{}\"\non_success = [\"true\"]\n",
        a.display()
    ));
    let sources = skillpost::daemon::Sources {
        config_file: Some(outside),
        ..Default::default()
    };
    assert!(sources.load().is_ok());
}

/// A cell of two controllers: each program goes to its own controller. The hook runs once per
/// written program with that program's placeholders (`{program}`, `{controller}`, `{src}`); a
/// failed one is a `deploy-failed` for that program, and `skillpost status` shows the last
/// deploy of each program, ok or failed and why.
#[test]
fn a_cell_deploys_each_program_to_its_own_controller() {
    let w = Workspace::new();
    let a = w.ws().join("Cell");
    inproc::copy_fixture_layers(&a, &inproc::TWO_CONTROLLER_CELL);
    let log = w.root.join("deployed.log");
    // The second robot's share is offline.
    let script = format!(
        "echo \"$1|$2|$(basename \"$3\")\" >> {log}; cat \"$3\" > {root}/\"$2\".got; if [ \"$1\" = 'KUKA KR16-2' ]; then echo 'share //kr16/r1 offline' >&2; exit 4; fi",
        log = log.display(),
        root = w.root.display()
    );
    let c = config(
        &w,
        &a,
        &[
            "sh",
            "-c",
            &script,
            "sh",
            "{controller}",
            "{program}",
            "{src}",
        ],
        "",
    );
    let sources = skillpost::daemon::Sources {
        config_file: Some(c.clone()),
        settle_ms: Some(SETTLE_MS),
        ..Default::default()
    };
    let state = w.root.join("status.json");
    let d = InProc::start_with_state(sources.load().unwrap(), sources, &state);
    // The second program's deploy (the one that fails) runs after the first's.
    let evs = d.wait_for("both deploys", WAIT, |e| is_for(e, "deploy-failed", &a));
    let started = deploys(&evs, "deploy-started", &a);
    let programs: Vec<(&str, &str)> = started
        .iter()
        .map(|e| {
            (
                e["program"].as_str().unwrap(),
                e["controller"].as_str().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        programs,
        [
            ("Blackboard_KUKA_KR15_2", "KUKA KR15-2"),
            ("Blackboard_KUKA_KR16_2", "KUKA KR16-2")
        ],
        "{}",
        dump(&evs)
    );
    // Each run got its own program's file.
    assert_eq!(
        read_string(&log),
        "KUKA KR15-2|Blackboard_KUKA_KR15_2|Blackboard_KUKA_KR15_2.src\n\
         KUKA KR16-2|Blackboard_KUKA_KR16_2|Blackboard_KUKA_KR16_2.src\n"
    );
    for program in ["Blackboard_KUKA_KR15_2", "Blackboard_KUKA_KR16_2"] {
        assert_eq!(
            read_string(&w.root.join(format!("{program}.got"))),
            read_string(&a.join(format!("{program}.src"))),
            "{program}: the hook got another program's bytes"
        );
    }
    let ok = deploys(&evs, "deploy-succeeded", &a);
    assert_eq!(ok.len(), 1, "{}", dump(&evs));
    assert_eq!(ok[0]["program"], "Blackboard_KUKA_KR15_2");
    let failed = deploys(&evs, "deploy-failed", &a);
    assert_eq!(failed[0]["program"], "Blackboard_KUKA_KR16_2");
    assert_eq!(failed[0]["exit_code"], 4);
    // `skillpost status` (the state file, read by the binary): the last deploy of each program.
    let mut table = String::new();
    wait_until(WAIT, || {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
            .args(["status", "--state"])
            .arg(&state)
            .output()
            .unwrap();
        table = String::from_utf8_lossy(&out.stdout).into_owned();
        table.contains("Blackboard_KUKA_KR16_2 (KUKA KR16-2)")
    });
    let row = |program: &str| {
        table
            .lines()
            .find(|l| l.contains(program) && (l.contains(" ok ") || l.contains(" failed ")))
            .unwrap_or_else(|| panic!("no deploy row for {program}:\n{table}"))
            .to_owned()
    };
    assert!(
        row("Blackboard_KUKA_KR15_2 (KUKA KR15-2)").contains(" ok "),
        "{table}"
    );
    let bad = row("Blackboard_KUKA_KR16_2 (KUKA KR16-2)");
    assert!(bad.contains(" failed "), "{table}");
    assert!(
        bad.contains("exited with status 4: share //kr16/r1 offline"),
        "{table}"
    );
    d.stop(WAIT);
}

/// Issue 37, item 6: what a hook leaves running ends with it, also in a session of its own
/// (`setsid`) and without its parent: after a hook that exits at once, after the timeout, and at
/// a stop.
#[test]
fn a_hooks_background_processes_end_with_it_also_under_setsid() {
    let w = Workspace::new();
    let a = w.project("A");
    let p = w.root.join("pid");
    // Two detached children: one in a session of its own, one also without its parent (the
    // subshell ends), neither holding the hook's pipes.
    let leave = format!(
        "setsid sleep 600 </dev/null >/dev/null 2>&1 & echo $! > {p}.a; \
         (setsid sleep 601 </dev/null >/dev/null 2>&1 & echo $! > {p}.b)",
        p = p.display()
    );
    let c = config(&w, &a, &["sh", "-c", &format!("{leave}; exit 0")], "");
    let d = InProc::with_config(&c);
    let evs = d.wait_for("the deploy", WAIT, |e| {
        is_for(e, "deploy-succeeded", &a) || is_for(e, "deploy-failed", &a)
    });
    assert_eq!(
        deploys(&evs, "deploy-succeeded", &a).len(),
        1,
        "{}",
        dump(&evs)
    );
    let (x, y) = (pid_in(&w.root.join("pid.a")), pid_in(&w.root.join("pid.b")));
    assert!(
        wait_until(Duration::from_secs(5), || !alive(x) && !alive(y)),
        "a hook's detached processes ({x}, {y}) outlived it"
    );
    d.stop(WAIT);

    // Past the timeout: the hook and what it detached.
    let b = w.project("B");
    let c = config(
        &w,
        &b,
        &[
            "sh",
            "-c",
            &format!("{leave}; echo $$ > {p}.c; sleep 600", p = p.display()),
        ],
        "deploy_timeout_s = 1",
    );
    for f in ["pid.a", "pid.b"] {
        fs::remove_file(w.root.join(f)).unwrap();
    }
    let d = InProc::with_config(&c);
    let evs = d.wait_for("the timeout", WAIT, |e| is_for(e, "deploy-failed", &b));
    let f = &deploys(&evs, "deploy-failed", &b)[0];
    assert_eq!(f["timed_out"], true, "{f}");
    let pids = ["pid.a", "pid.b", "pid.c"].map(|f| pid_in(&w.root.join(f)));
    assert!(
        wait_until(Duration::from_secs(5), || pids.iter().all(|p| !alive(*p))),
        "processes of a timed-out hook ({pids:?}) outlived it"
    );
    d.stop(WAIT);

    // A stop while the hook runs.
    let e = w.project("E");
    for f in ["pid.a", "pid.b", "pid.c"] {
        fs::remove_file(w.root.join(f)).unwrap();
    }
    let c = config(
        &w,
        &e,
        &[
            "sh",
            "-c",
            &format!("{leave}; echo $$ > {p}.c; sleep 600", p = p.display()),
        ],
        "",
    );
    let d = InProc::with_config(&c);
    let pids = ["pid.a", "pid.b", "pid.c"].map(|f| pid_in(&w.root.join(f)));
    d.stop(Duration::from_secs(10));
    assert!(
        wait_until(Duration::from_secs(5), || pids.iter().all(|p| !alive(*p))),
        "processes of a hook ({pids:?}) outlived the daemon's stop"
    );
}

/// Issue 37, item 8: a hook's program in a project folder (where planners write) is refused:
/// by the daemon (exit status 2, and a reload would keep the old configuration) and as a
/// PROBLEM row of `--check-config`.
#[test]
fn a_hook_program_in_a_project_folder_is_refused() {
    use std::os::unix::fs::PermissionsExt as _;
    let w = Workspace::new();
    let a = w.project("A");
    let script = a.join("deploy.sh");
    fs::write(&script, "#!/bin/sh\ntouch \"$0.ran\"\n").unwrap();
    fs::set_permissions(&script, fs::Permissions::from_mode(0o755)).unwrap();
    let c = config(&w, &a, &[script.to_str().unwrap(), "{src}"], "");
    let sources = skillpost::daemon::Sources {
        config_file: Some(c.clone()),
        ..Default::default()
    };
    let e = sources.load().expect_err("refused");
    assert!(e.message.contains("lies in the project folder"), "{e:?}");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["watch", "--config"])
        .arg(&c)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("deploy.sh lies in the project folder"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["watch", "--check-config", "--config"])
        .arg(&c)
        .output()
        .unwrap();
    let table = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{table}");
    assert!(
        table
            .lines()
            .any(|l| l.starts_with("(deploy)") && l.contains("PROBLEM: the deploy hook's program")),
        "{table}"
    );
    assert!(!a.join("deploy.sh.ran").exists());
}

/// Issue 37, item 8: with an empty entry in `PATH` (the current folder), a bare hook name never
/// runs a planner's program of that name in the project folder: it is looked up in PATH's
/// absolute folders only, when the configuration is read.
#[test]
fn an_empty_path_entry_never_runs_a_planners_program() {
    use std::os::unix::fs::PermissionsExt as _;
    let w = Workspace::new();
    let a = w.project("A");
    let planted = a.join("skp-deploy-37");
    fs::write(&planted, "#!/bin/sh\ntouch \"$PWD/owned\"\n").unwrap();
    fs::set_permissions(&planted, fs::Permissions::from_mode(0o755)).unwrap();
    let c = config(&w, &a, &["skp-deploy-37", "{src}"], "");
    let ev = w.root.join("events.jsonl");
    let path = format!(":{}", std::env::var("PATH").unwrap_or_default());
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["watch", "--settle", "50", "--config"])
        .arg(&c)
        .arg("--events")
        .arg(&ev)
        .env("PATH", &path)
        .env("XDG_RUNTIME_DIR", &w.root)
        .env_remove("RUNTIME_DIRECTORY")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let done = wait_until(Duration::from_secs(30), || {
        let t = read_string(&ev);
        t.contains("\"deploy-failed\"") || t.contains("\"deploy-succeeded\"")
    });
    let _ = child.kill();
    let _ = child.wait();
    let text = read_string(&ev);
    assert!(done, "no deploy: {text}");
    assert!(
        !a.join("owned").exists(),
        "the planner's program ran: {text}"
    );
    assert!(text.contains("\"deploy-failed\""), "{text}");
    assert!(text.contains("absolute folders of PATH"), "{text}");
}
