//! Issue 37 (Trust III): the attacks a fourth review found against the picture, the deploy hook
//! and the names of projects, each through the entry point a user uses: the binary or the
//! daemon in this process. (The hooks' descriptors and process trees, foreign locks and hook
//! programs are in tests/trust.rs and tests/daemon_deploy.rs; memory budgets in tests/cli.rs.)

#[path = "../benches/common/generator.rs"]
mod generator;
mod inproc;

use std::fs;
use std::path::Path;
use std::time::Duration;

use inproc::{InProc, Workspace, is_for};

/// Spins until `file` exists (at most `limit`), then replaces its folder `p` by a link to
/// `to` (`mv P P.real; ln -s OUT P`). Whether it swapped.
fn swap_when_it_lands(file: &Path, p: &Path, to: &Path, limit: Duration) -> bool {
    let deadline = std::time::Instant::now() + limit;
    while std::time::Instant::now() < deadline {
        if fs::symlink_metadata(file).is_ok() {
            fs::rename(p, p.with_extension("real")).unwrap();
            std::os::unix::fs::symlink(to, p).unwrap();
            return true;
        }
        std::thread::yield_now();
    }
    false
}

/// Finding 1: the project folder swapped for a link right after the program lands. The
/// picture goes where the programs went (the folder the inputs were read from, `P.real` now);
/// a file in the link's target is never replaced.
#[test]
fn the_picture_never_lands_in_a_folder_swapped_in_after_the_program() {
    let mut swapped_before_the_end = 0;
    for trial in 0..3 {
        let w = Workspace::new();
        let p = w.ws().join("P");
        let out = w.root.join("OUT");
        generator::write_project(&p, &generator::Spec::flat(20_000)).unwrap();
        fs::create_dir(&out).unwrap();
        fs::write(out.join("Blackboard.svg"), "a planner's file").unwrap();
        let cfg = w.config(&format!(
            "picture = true\n[[project]]\npath = \"{}\"\n",
            p.display()
        ));
        let (src, p2, out2) = (p.join("Blackboard.src"), p.clone(), out.clone());
        let swapper = std::thread::spawn(move || {
            swap_when_it_lands(&src, &p2, &out2, Duration::from_secs(60))
        });
        let d = InProc::with_config(&cfg);
        assert!(swapper.join().unwrap(), "trial {trial}: no program landed");
        let evs = d.wait_for("the first compile", Duration::from_secs(60), |e| {
            is_for(e, "compile-succeeded", &p) || is_for(e, "compile-failed", &p)
        });
        // The swap came before the compile's end (the picture is written after the programs).
        let done = evs
            .iter()
            .find(|e| is_for(e, "compile-succeeded", &p))
            .expect("the compile succeeded");
        let svg = done["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .any(|o| o["path"].as_str().is_some_and(|s| s.ends_with(".svg")));
        assert!(svg, "no picture among the outputs: {done}");
        if fs::symlink_metadata(p.with_extension("real").join("Blackboard.svg")).is_ok() {
            swapped_before_the_end += 1;
        }
        d.stop(Duration::from_secs(10));
        assert!(
            fs::read(out.join("Blackboard.svg")).unwrap() == b"a planner's file",
            "trial {trial}: the picture replaced a file in the folder the link leads to"
        );
        assert_eq!(
            fs::read_dir(&out).unwrap().count(),
            1,
            "trial {trial}: something was written into OUT"
        );
    }
    assert!(
        swapped_before_the_end > 0,
        "no trial swapped the folder before the picture was written"
    );
}

fn skillpost(args: &[&str], cwd: &Path) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

/// Finding 12: `--svg` naming one of the program's own files is refused before anything is
/// written (before, the picture went over `P.src` and a failed write of the pair left it there).
#[test]
fn a_picture_named_like_a_program_file_is_refused_and_nothing_is_written() {
    let w = Workspace::new();
    let p = w.project("P");
    let before = fs::read_dir(&p).unwrap().count();
    let o = skillpost(&["--svg", "out.src", "Blackboard.aml", "out"], &p);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("error[E604]") && err.contains("--svg"),
        "{err}"
    );
    assert!(
        err.contains("out.svg"),
        "the message suggests a name: {err}"
    );
    assert_eq!(
        fs::read_dir(&p).unwrap().count(),
        before,
        "a file was written"
    );
}

/// Finding 12: when the programs cannot be written, neither is the picture, so "nothing was
/// written" is true.
#[test]
fn a_picture_is_not_written_when_the_programs_are_not() {
    let w = Workspace::new();
    let p = w.project("P");
    // The `.dat` cannot be written: a folder stands at its name.
    fs::create_dir(p.join("out.dat")).unwrap();
    let o = skillpost(&["--svg", "plan.svg", "Blackboard.aml", "out"], &p);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("nothing was written"), "{err}");
    assert!(
        !p.join("plan.svg").exists(),
        "the picture was written: {err}"
    );
    assert!(!p.join("out.src").exists());
    // And with the programs written, the picture is too.
    fs::remove_dir(p.join("out.dat")).unwrap();
    let o = skillpost(&["--svg", "plan.svg", "Blackboard.aml", "out"], &p);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains("wrote plan.svg"));
    assert!(
        fs::read_to_string(p.join("plan.svg"))
            .unwrap()
            .starts_with("<svg")
    );
}

/// A deploy hook that waits for `<root>/go` before copying `{src}` and `{dat}` into
/// `<root>/share/`, and the configuration running it for project `p`.
fn waiting_hook(w: &Workspace, p: &Path) -> std::path::PathBuf {
    fs::create_dir_all(w.root.join("share")).unwrap();
    w.config(&format!(
        "on_success = [\"sh\", \"-c\", \"while [ ! -e \\\"$0/go\\\" ]; do sleep 0.01; done; \
         rm \\\"$0/go\\\"; cp \\\"$1\\\" \\\"$2\\\" \\\"$0/share/\\\"\", \"{root}\", \"{{src}}\", \"{{dat}}\"]\n\
         [[project]]\npath = \"{p}\"\n",
        root = w.root.display(),
        p = p.display()
    ))
}

/// Finding 2: a hand-written `.src` renamed over the compiled one, or the folder swapped for
/// another with its own program, after the compile and before the hook copies: the hook still
/// ships the bytes the daemon wrote, never a program it did not write.
#[test]
fn the_hook_ships_the_bytes_the_daemon_wrote_whatever_replaced_them() {
    for swap_folder in [false, true] {
        let w = Workspace::new();
        let p = w.project("P");
        fs::write(p.join("sfc.xml"), inproc::sfc_with_x(111)).unwrap();
        let d = InProc::with_config(&waiting_hook(&w, &p));
        d.wait_for("the hook", Duration::from_secs(10), |e| {
            is_for(e, "deploy-started", &p)
        });
        let compiled = fs::read_to_string(p.join("Blackboard.src")).unwrap();
        assert!(compiled.contains(&inproc::ptp_with_x(111)));
        let forged = "DEF Blackboard()\nPTP {A1 -170}\nEND\n";
        if swap_folder {
            let other = w.root.join("OTHER");
            fs::create_dir(&other).unwrap();
            fs::write(other.join("Blackboard.src"), forged).unwrap();
            fs::write(other.join("Blackboard.dat"), "DEFDAT Blackboard\nENDDAT\n").unwrap();
            fs::rename(&p, p.with_extension("real")).unwrap();
            std::os::unix::fs::symlink(&other, &p).unwrap();
        } else {
            fs::write(p.join("forged"), forged).unwrap();
            fs::rename(p.join("forged"), p.join("Blackboard.src")).unwrap();
        }
        fs::write(w.root.join("go"), "").unwrap();
        let evs = d.wait_for("the hook's end", Duration::from_secs(10), |e| {
            is_for(e, "deploy-succeeded", &p) || is_for(e, "deploy-failed", &p)
        });
        assert!(
            evs.iter().any(|e| is_for(e, "deploy-succeeded", &p)),
            "{}",
            inproc::dump(&evs)
        );
        let shipped = fs::read_to_string(w.root.join("share/Blackboard.src")).unwrap();
        assert!(
            shipped == compiled,
            "swap_folder {swap_folder}: the hook shipped a program the daemon did not write:\n{shipped}"
        );
        let dat = fs::read_to_string(w.root.join("share/Blackboard.dat")).unwrap();
        assert!(dat.contains("DEFDAT"), "{dat}");
        d.stop(Duration::from_secs(10));
    }
}

/// Finding 2: a slow hook and a new compile while it waits: the hook ships its own compile's
/// `.src` and `.dat` (a pair of one compile), and the next hook the next compile's.
#[test]
fn a_slow_hook_ships_the_pair_of_its_own_compile() {
    let w = Workspace::new();
    let p = w.project("P");
    fs::write(p.join("sfc.xml"), inproc::sfc_with_x(111)).unwrap();
    let d = InProc::with_config(&waiting_hook(&w, &p));
    d.wait_for("the hook", Duration::from_secs(10), |e| {
        is_for(e, "deploy-started", &p)
    });
    let (src1, dat1) = (
        fs::read(p.join("Blackboard.src")).unwrap(),
        fs::read(p.join("Blackboard.dat")).unwrap(),
    );
    // The next compile lands while the first hook waits.
    let mark = d.mark();
    fs::write(p.join("sfc.xml"), inproc::sfc_with_x(222)).unwrap();
    d.wait_for("the edit's compile", Duration::from_secs(10), |e| {
        inproc::is_after(e, "compile-succeeded", &p, mark)
    });
    assert!(inproc::read_string(&p.join("Blackboard.src")).contains(&inproc::ptp_with_x(222)));
    fs::write(w.root.join("go"), "").unwrap();
    d.wait_for("the first hook's end", Duration::from_secs(10), |e| {
        is_for(e, "deploy-succeeded", &p)
    });
    assert!(fs::read(w.root.join("share/Blackboard.src")).unwrap() == src1);
    assert!(fs::read(w.root.join("share/Blackboard.dat")).unwrap() == dat1);
    // The second one ships the second compile's pair.
    let mark = d.mark();
    fs::write(w.root.join("go"), "").unwrap();
    d.wait_for("the second hook's end", Duration::from_secs(10), |e| {
        inproc::is_after(e, "deploy-succeeded", &p, mark)
    });
    assert!(
        fs::read(w.root.join("share/Blackboard.src")).unwrap()
            == fs::read(p.join("Blackboard.src")).unwrap()
    );
    assert!(
        fs::read(w.root.join("share/Blackboard.dat")).unwrap()
            == fs::read(p.join("Blackboard.dat")).unwrap()
    );
}

/// Finding 3: a save of two files 20 ms apart (the SFC, then the IRL file), five times. The
/// compile that read the SFC's new bytes and the IRL file's old ones may run (an early run
/// after a complete write), but it is never deployed: a deploy waits until the inputs have been
/// quiet for the whole quiet period, and the next compile's program replaces it.
#[test]
fn a_compile_of_half_a_save_is_never_deployed() {
    let w = Workspace::new();
    let p = w.project("P");
    let shipped = w.root.join("shipped");
    fs::create_dir(&shipped).unwrap();
    let cfg = w.config(&format!(
        "settle_ms = 300\n\
         on_success = [\"sh\", \"-c\", \"cat \\\"$1\\\" > \\\"$0/$(date +%s%N)\\\"\", \"{}\", \"{{src}}\"]\n\
         [[project]]\npath = \"{}\"\n",
        shipped.display(),
        p.display()
    ));
    let d = InProc::with_config(&cfg);
    d.wait_for("the startup deploy", Duration::from_secs(10), |e| {
        is_for(e, "deploy-succeeded", &p)
    });
    let irl = inproc::sample_text("kr15-2.irl");
    assert!(irl.contains("$VEL.CP = VALUE\n"));
    for round in 1..=5u32 {
        let mark = d.mark();
        let x = 100 + round;
        fs::write(p.join("sfc.xml"), inproc::sfc_with_x(x)).unwrap();
        std::thread::sleep(Duration::from_millis(20));
        let marked = irl.replace(
            "$VEL.CP = VALUE\n",
            &format!("$VEL.CP = VALUE ; save {round}\n"),
        );
        fs::write(p.join("kr15-2.irl"), marked).unwrap();
        d.wait_for("the save's deploy", Duration::from_secs(10), |e| {
            inproc::is_after(e, "deploy-succeeded", &p, mark)
        });
    }
    std::thread::sleep(Duration::from_millis(500));
    let evs = d.events();
    let compiles = evs
        .iter()
        .filter(|e| is_for(e, "compile-succeeded", &p))
        .count();
    // Every program shipped is one of a whole save: its x and its IRL file's mark agree.
    let mut n = 0;
    for f in fs::read_dir(&shipped).unwrap() {
        let text = fs::read_to_string(f.unwrap().path()).unwrap();
        for round in 1..=5u32 {
            if text.contains(&inproc::ptp_with_x(100 + round)) {
                assert!(
                    text.contains(&format!("; save {round}")),
                    "round {round}: a program of half a save was deployed"
                );
            }
        }
        n += 1;
    }
    assert_eq!(
        n, 6,
        "one deploy at startup and one per save ({compiles} compiles)"
    );
}

/// Finding 4: `A\xff` (not UTF-8) and `A\u{FFFD}` (`A\xEF\xBF\xBD`) under one root, with a
/// hook: the first is refused with its bytes named, the second compiles and its hook gets its
/// own folder and files; the events and the state never merge the two.
#[test]
fn a_folder_name_that_is_not_utf8_is_refused_never_merged_with_its_look_alike() {
    use std::os::unix::ffi::OsStrExt as _;
    let w = Workspace::new();
    let root = w.ws();
    let bad = root.join(std::ffi::OsStr::from_bytes(b"A\xff"));
    let good = root.join("A\u{FFFD}");
    inproc::copy_project(&bad);
    inproc::copy_project(&good);
    let log = w.root.join("hook.log");
    let cfg = w.config(&format!(
        "on_success = [\"sh\", \"-c\", \"echo \\\"$1|$2\\\" >> {}\", \"sh\", \"{{project}}\", \"{{src}}\"]\n\
         [[root]]\npath = \"{}\"\n",
        log.display(),
        root.display()
    ));
    let d = InProc::with_config(&cfg);
    let evs = d.wait_for("the good one's deploy", Duration::from_secs(10), |e| {
        is_for(e, "deploy-succeeded", &good)
    });
    std::thread::sleep(Duration::from_millis(300));
    let evs2 = d.events();
    let refusal = evs2
        .iter()
        .find(|e| {
            inproc::is(e, "watch-degraded")
                && e["reason"].as_str().is_some_and(|r| r.contains("A\\xFF"))
        })
        .unwrap_or_else(|| panic!("no refusal naming A\\xFF:\n{}", inproc::dump(&evs)));
    assert!(
        refusal["reason"].as_str().unwrap().contains("not UTF-8"),
        "{refusal}"
    );
    // One compile, of the good one; the hook got the good folder.
    let compiles: Vec<&serde_json::Value> = evs2
        .iter()
        .filter(|e| inproc::is(e, "compile-started"))
        .collect();
    assert_eq!(compiles.len(), 1, "{}", inproc::dump(&evs2));
    assert_eq!(compiles[0]["project"], good.display().to_string());
    let hooked = fs::read_to_string(&log).unwrap();
    assert_eq!(hooked.lines().count(), 1, "{hooked}");
    assert!(
        hooked.starts_with(&format!("{}|", good.display())),
        "{hooked}"
    );
    assert!(!bad.join("Blackboard.src").exists());
}

/// Finding 12: a folder named with an escape sequence: the log (the journal) and the
/// `skillpost status` table show it escaped, never the raw ESC.
#[test]
fn escape_sequences_in_folder_names_never_reach_the_log_or_the_status_table_raw() {
    let w = Workspace::new();
    let p = w.ws().join("P\u{1b}[31mX");
    inproc::copy_project(&p);
    let state = w.root.join("state.json");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["watch", "--settle", "50", "--state"])
        .arg(&state)
        .arg(&p)
        .env("XDG_RUNTIME_DIR", &w.root)
        .env_remove("RUNTIME_DIRECTORY")
        .env_remove("JOURNAL_STREAM")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let compiled = inproc::wait_until(Duration::from_secs(20), || {
        p.join("Blackboard.src").exists() && state.exists()
    });
    // The state file follows the compile (rate-limited): wait for it to name the project.
    inproc::wait_until(Duration::from_secs(5), || {
        inproc::read_string(&state).contains("compiled")
            || inproc::read_string(&state).contains("ok")
    });
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["status", "--state"])
        .arg(&state)
        .output()
        .unwrap();
    let _ = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status();
    let _ = child.wait();
    let mut log = Vec::new();
    std::io::Read::read_to_end(child.stderr.as_mut().unwrap(), &mut log).unwrap();
    let log = String::from_utf8_lossy(&log);
    assert!(compiled, "no compile: {log}");
    assert!(log.contains("compiled in"), "{log}");
    assert!(!log.contains('\u{1b}'), "a raw ESC in the log: {log:?}");
    assert!(log.contains("P\\u{1b}[31mX"), "{log}");
    let table = String::from_utf8_lossy(&status.stdout);
    assert!(table.contains("P\\u{1b}[31mX"), "{table}");
    assert!(
        !table.contains('\u{1b}'),
        "a raw ESC in the status table: {table:?}"
    );
}

/// Finding 4, the blackboard: a project whose only blackboard's name is not UTF-8 fails with
/// the reason (its bytes escaped); nothing is written, no hook runs.
#[test]
fn a_blackboard_name_that_is_not_utf8_is_a_clear_failure() {
    use std::os::unix::ffi::OsStrExt as _;
    let w = Workspace::new();
    let p = w.project("P");
    fs::rename(
        p.join("Blackboard.aml"),
        p.join(std::ffi::OsStr::from_bytes(b"Cell\xff.aml")),
    )
    .unwrap();
    let d = InProc::with_dirs(&[&p]);
    let evs = d.wait_for("the failure", Duration::from_secs(10), |e| {
        is_for(e, "compile-failed", &p)
    });
    let failed = evs
        .iter()
        .find(|e| is_for(e, "compile-failed", &p))
        .unwrap();
    let message = failed["diagnostics"][0]["message"].as_str().unwrap_or("");
    assert!(
        message.contains("Cell\\xFF.aml") && message.contains("not UTF-8"),
        "{failed}"
    );
    assert!(fs::read_dir(&p).unwrap().all(|e| {
        let n = e.unwrap().file_name();
        !n.as_bytes().ends_with(b".src")
    }));
}

/// Finding 5: a cell's hook that cannot tell the programs apart (DAEMON.md's single-robot
/// install example, `install {src} {dat} /mnt/…/R1/`) would put robot 2's program on robot 1's
/// share: neither program is deployed, each `deploy-failed` says why; with `{controller}` each
/// program goes to its own controller's share.
#[test]
fn a_cell_program_never_goes_to_another_controllers_share() {
    let w = Workspace::new();
    let a = w.ws().join("Cell");
    inproc::copy_fixture_layers(&a, &inproc::TWO_CONTROLLER_CELL);
    let r1 = w.root.join("R1");
    fs::create_dir(&r1).unwrap();
    let cfg = w.config(&format!(
        "on_success = [\"install\", \"-m\", \"0644\", \"{{src}}\", \"{{dat}}\", \"{}/\"]\n\
         [[project]]\npath = \"{}\"\n",
        r1.display(),
        a.display()
    ));
    let d = InProc::with_config(&cfg);
    d.wait_for("the compile", Duration::from_secs(10), |e| {
        is_for(e, "compile-succeeded", &a)
    });
    std::thread::sleep(Duration::from_millis(500));
    let evs = d.events();
    let failed: Vec<&serde_json::Value> = evs
        .iter()
        .filter(|e| is_for(e, "deploy-failed", &a))
        .collect();
    assert_eq!(failed.len(), 2, "{}", inproc::dump(&evs));
    assert!(
        failed[0]["reason"]
            .as_str()
            .unwrap()
            .contains("name neither `{controller}` nor `{program}`"),
        "{}",
        failed[0]
    );
    assert!(!evs.iter().any(|e| is_for(e, "deploy-started", &a)));
    assert_eq!(
        fs::read_dir(&r1).unwrap().count(),
        0,
        "a program on R1's share"
    );
    d.stop(Duration::from_secs(10));

    // Chosen by `{controller}`: each program on its own controller's share.
    let b = w.ws().join("Cell2");
    inproc::copy_fixture_layers(&b, &inproc::TWO_CONTROLLER_CELL);
    let shares = w.root.join("shares");
    for ctl in ["KUKA KR15-2", "KUKA KR16-2"] {
        fs::create_dir_all(shares.join(ctl)).unwrap();
    }
    let cfg = w.config(&format!(
        "on_success = [\"sh\", \"-c\", \"install -m 0644 \\\"$1\\\" \\\"$2\\\" \\\"$0/$3/\\\"\", \"{}\", \"{{src}}\", \"{{dat}}\", \"{{controller}}\"]\n\
         [[project]]\npath = \"{}\"\n",
        shares.display(),
        b.display()
    ));
    let d = InProc::with_config(&cfg);
    d.wait_for("both deploys", Duration::from_secs(10), |e| {
        is_for(e, "deploy-succeeded", &b) && e["controller"] == "KUKA KR16-2"
    });
    for (ctl, program) in [
        ("KUKA KR15-2", "Blackboard_KUKA_KR15_2"),
        ("KUKA KR16-2", "Blackboard_KUKA_KR16_2"),
    ] {
        let names: Vec<String> = fs::read_dir(shares.join(ctl))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        let mut names = names;
        names.sort();
        assert_eq!(
            names,
            [format!("{program}.dat"), format!("{program}.src")],
            "{ctl}"
        );
    }
}
