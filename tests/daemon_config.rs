//! The daemon's configuration as a team uses it (issue 10, "Configuration"): `template` and
//! `line_endings` write exactly what the command line writes, and follow edits and reloads;
//! root projects whose folder or blackboard name is not a KRL name get a derived program name;
//! `skillpost watch FILE` and `skillpost watch /typo` on the command line;
//! `skillpost watch --check-config` (issue 27, item 3) and a missing template located at its line
//! (item 7).

mod common;
mod inproc;

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use inproc::*;
use serde_json::Value;

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_skillpost")
}

/// `skillpost [--template T] [--lf] <blackboard> <program>` through the binary.
fn cli_compile(blackboard: &Path, program: &str, template: Option<&Path>, lf: bool) {
    let mut cmd = Command::new(bin());
    if let Some(t) = template {
        cmd.arg("--template").arg(t);
    }
    if lf {
        cmd.arg("--lf");
    }
    let out = cmd.arg(blackboard).arg(program).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The built-in template with a marker comment in the `.src` header.
fn team_template(marker: &str) -> String {
    let t = fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("templates/krl.toml"))
        .unwrap();
    assert!(t.contains("&REL 1\n&COMMENT {{comment}}\nDEF"));
    t.replacen(
        "&REL 1\n&COMMENT {{comment}}\nDEF",
        &format!("&REL 1\n&COMMENT {{{{comment}}}}\n; {marker}\nDEF"),
        1,
    )
}

/// Asserts that the daemon's project `a` holds byte for byte what the command line wrote into
/// the copy `b` (outputs and the written-back blackboard).
fn assert_same_outputs(a: &Path, b: &Path, program: &str) {
    for f in [
        format!("{program}.src"),
        format!("{program}.dat"),
        "Blackboard.aml".into(),
    ] {
        let (x, y) = (fs::read(a.join(&f)).unwrap(), fs::read(b.join(&f)).unwrap());
        assert!(
            x == y,
            "{f} differs:\n--- daemon\n{}\n--- command line\n{}",
            String::from_utf8_lossy(&x),
            String::from_utf8_lossy(&y)
        );
    }
}

fn started_after<'a>(evs: &'a [Value], project: &Path, since: u64) -> Vec<&'a Value> {
    evs.iter()
        .filter(|e| is_after(e, "compile-started", project, since))
        .collect()
}

#[test]
fn template_and_line_endings_write_what_the_command_line_writes_and_follow_changes() {
    let w = Workspace::new();
    let a = w.project("A");
    let b = w.project("B"); // the command line's copy
    let r = w.root.join("root");
    copy_project(&r.join("C"));
    let c_cli = w.project("C_cli");
    let team = w.root.join("team.toml");
    fs::write(&team, team_template("team v1")).unwrap();
    let root_tpl = w.root.join("root.toml");
    fs::write(&root_tpl, team_template("root template")).unwrap();
    let config = |endings: &str| {
        format!(
            "template = \"team.toml\"\nline_endings = \"{endings}\"\n\
             [[project]]\npath = \"ws/A\"\n\
             [[root]]\npath = \"root\"\ntemplate = \"root.toml\"\nline_endings = \"crlf\"\n"
        )
    };
    let cfg = w.config(&config("lf"));
    let d = InProc::with_config(&cfg);
    let c = r.join("C");
    d.startup(&[&a, &c]);

    // Global template + LF for A; the root's own template and CRLF for C.
    cli_compile(&b.join("Blackboard.aml"), "Blackboard", Some(&team), true);
    assert_same_outputs(&a, &b, "Blackboard");
    let src = read_string(&src_of(&a));
    assert!(src.contains("; team v1\n") && !src.contains('\r'), "{src}");
    cli_compile(
        &c_cli.join("Blackboard.aml"),
        "Blackboard",
        Some(&root_tpl),
        false,
    );
    assert_same_outputs(&c, &c_cli, "Blackboard");
    assert!(read_string(&src_of(&c)).contains("; root template\r\n"));

    // The template is an input: editing it recompiles the projects using it (A), not C.
    let mark = d.mark();
    fs::write(&team, team_template("team v2")).unwrap();
    let evs = d.wait_for("A recompiled for the new template", WAIT, |e| {
        is_after(e, "compile-succeeded", &a, mark)
    });
    let changed = evs
        .iter()
        .find(|e| is_after(e, "change-detected", &a, mark))
        .unwrap_or_else(|| panic!("{}", dump(&evs)));
    assert_eq!(
        changed["paths"],
        serde_json::json!([team.to_str().unwrap()]),
        "{changed}"
    );
    assert!(read_string(&src_of(&a)).contains("; team v2\n"));
    cli_compile(&b.join("Blackboard.aml"), "Blackboard", Some(&team), true);
    assert_same_outputs(&a, &b, "Blackboard");
    std::thread::sleep(Duration::from_millis(SETTLE_MS * 6));
    assert!(
        started_after(&d.events(), &c, mark).is_empty(),
        "C does not use the team template\n{}",
        dump(&d.events())
    );

    // A broken template: E603 in compile-failed, the outputs stay; fixed: compiles again.
    let mark = d.mark();
    fs::write(&team, "src = 1\n").unwrap();
    let evs = d.wait_for("compile-failed for the broken template", WAIT, |e| {
        is_after(e, "compile-failed", &a, mark)
    });
    let failed = evs
        .iter()
        .find(|e| is_after(e, "compile-failed", &a, mark))
        .unwrap();
    assert!(failed.to_string().contains("E603"), "{failed}");
    assert!(read_string(&src_of(&a)).contains("; team v2\n"));
    let mark = d.mark();
    fs::write(&team, team_template("team v3")).unwrap();
    d.wait_for("A compiles again", WAIT, |e| {
        is_after(e, "compile-succeeded", &a, mark)
    });

    // A reload that changes the line endings compiles A again (trigger `reload`): CRLF now.
    let mark = d.mark();
    fs::write(&cfg, config("crlf")).unwrap();
    d.reload();
    let evs = d.wait_for("A recompiled after the reload", WAIT, |e| {
        is_after(e, "compile-succeeded", &a, mark)
    });
    let started = started_after(&evs, &a, mark);
    assert_eq!(started[0]["trigger"], "reload", "{}", dump(&evs));
    cli_compile(&b.join("Blackboard.aml"), "Blackboard", Some(&team), false);
    assert_same_outputs(&a, &b, "Blackboard");
    assert!(read_string(&src_of(&a)).contains("; team v3\r\n"));
    std::thread::sleep(Duration::from_millis(SETTLE_MS * 6));
    assert!(
        started_after(&d.events(), &c, mark).is_empty(),
        "C's settings did not change\n{}",
        dump(&d.events())
    );
    d.stop(WAIT);
}

/// A copy of the sample in `dir` whose blackboard is called `name`.
fn project_with_blackboard(dir: &Path, name: &str) -> PathBuf {
    copy_project(dir);
    fs::rename(dir.join("Blackboard.aml"), dir.join(name)).unwrap();
    dir.join(name)
}

fn warning_codes(e: &Value) -> Vec<String> {
    e["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w["code"].as_str().unwrap().to_owned())
        .collect()
}

#[test]
fn root_projects_with_names_that_are_not_krl_names_get_a_derived_program() {
    let w = Workspace::new();
    let r = w.root.join("cells");
    let pal = r.join("Palletizing Cell");
    project_with_blackboard(&pal, "Palletizing Cell.aml");
    let ueb = r.join("Zelle_Übergabe");
    project_with_blackboard(&ueb, "Zelle_Übergabe.aml");
    let ok = r.join("Zelle_A");
    project_with_blackboard(&ok, "Zelle_A.aml");
    // A second root whose programs are named by a pattern.
    let r2 = w.root.join("lines");
    let l1 = r2.join("2024 Linie");
    project_with_blackboard(&l1, "Blackboard.aml");
    let cfg = w.config(
        "[[root]]\npath = \"cells\"\n[[root]]\npath = \"lines\"\nprogram = \"L_{folder}\"\n",
    );
    let d = InProc::with_config(&cfg);
    for (project, program, derived) in [
        (&pal, "Palletizing_Cell", true),
        (&ueb, "Zelle_Uebergabe", true),
        (&ok, "Zelle_A", false),
        (&l1, "L_2024_Linie", true),
    ] {
        let evs = d.wait_for(&format!("{program} compiled"), WAIT, |e| {
            is_for(e, "write-back", project)
        });
        let watching = evs.iter().find(|e| is_for(e, "watching", project)).unwrap();
        assert_eq!(watching["program"], program, "{watching}");
        let done = evs
            .iter()
            .find(|e| is_for(e, "compile-succeeded", project))
            .unwrap_or_else(|| panic!("{}", dump(&evs)));
        assert_eq!(
            warning_codes(done).contains(&"W701".to_owned()),
            derived,
            "{done}"
        );
        if derived {
            let w701 = done["warnings"]
                .as_array()
                .unwrap()
                .iter()
                .find(|w| w["code"] == "W701")
                .unwrap();
            let msg = w701["message"].as_str().unwrap();
            assert!(
                msg.contains(&format!("`{program}`")) && msg.contains("`program`"),
                "names the program used and how to choose another: {msg}"
            );
        }
        assert!(project.join(format!("{program}.src")).is_file());
        assert!(project.join(format!("{program}.dat")).is_file());
        let bb = fs::read_dir(project)
            .unwrap()
            .flatten()
            .find(|e| e.path().extension().is_some_and(|x| x == "aml"))
            .unwrap()
            .path();
        assert!(
            read_string(&bb).contains(&format!("<Value>{program}.src</Value>")),
            "{program}"
        );
    }
    // What the daemon wrote is what the command line writes with that name.
    let copy = w.ws().join("pal_cli");
    let bb = project_with_blackboard(&copy, "Palletizing Cell.aml");
    cli_compile(&bb, "Palletizing_Cell", None, false);
    for f in ["Palletizing_Cell.src", "Palletizing_Cell.dat"] {
        assert_eq!(
            fs::read(pal.join(f)).unwrap(),
            fs::read(copy.join(f)).unwrap()
        );
    }
    let evs = d.events();
    assert!(
        !evs.iter()
            .any(|e| is(e, "compile-failed") || e.to_string().contains("E601")),
        "{}",
        dump(&evs)
    );
    d.stop(WAIT);
}

#[test]
fn an_invalid_program_name_in_the_configuration_says_how_to_fix_it() {
    let w = Workspace::new();
    let a = w.project("A");
    let cfg = w.config("[[project]]\npath = \"ws/A\"\n");
    let d = InProc::with_config(&cfg);
    d.startup(&[&a]);
    let mark = d.mark();
    fs::write(
        &cfg,
        "[[project]]\npath = \"ws/A\"\nprogram = \"Zelle A\"\n",
    )
    .unwrap();
    d.reload();
    let evs = d.wait_for("reload-failed", WAIT, |e| {
        seq(e) > mark && is(e, "reload-failed")
    });
    let e = evs
        .iter()
        .find(|e| seq(e) > mark && is(e, "reload-failed"))
        .unwrap();
    assert_eq!(
        (e["line"].as_u64(), e["column"].as_u64()),
        (Some(3), Some(11))
    );
    let msg = e["error"].as_str().unwrap();
    assert!(
        msg.contains("not a KRL name")
            && msg.contains("\"Zelle_A\"")
            && msg.contains("{blackboard}"),
        "{msg}"
    );
    d.stop(WAIT);

    // At startup: exit status 2 with the same sentence.
    let out = Command::new(bin())
        .args(["watch", "--config"])
        .arg(&cfg)
        // Were it to start after all: its state and lock notes in the workspace.
        .env("XDG_RUNTIME_DIR", &w.root)
        .env_remove("RUNTIME_DIRECTORY")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(":3:11:") && err.contains("\"Zelle_A\""),
        "{err}"
    );
}

/// `skillpost watch` with neither a folder nor `--config` (issue 27, item 8): a `SIGHUP` could
/// add nothing, so it does not wait for one; it exits at once with status 2 and says what to
/// pass, writing nothing (the daemon, docs/DAEMON.md, takes projects from the command line and the configuration
/// only, so the current folder is not watched on its own). With `--config` it does start.
#[test]
fn watch_without_folders_or_configuration_exits_with_a_usage_hint() {
    let w = Workspace::new();
    // The current folder is a project: still not watched without being named.
    let cwd = w.project("here");
    for extra in [
        &[][..],
        &["--settle", "50"][..],
        &["--events", "ev.jsonl"][..],
    ] {
        let t = Instant::now();
        let out = Command::new(bin())
            .arg("watch")
            .args(extra)
            .current_dir(&cwd)
            .env("XDG_RUNTIME_DIR", &w.root)
            .env_remove("RUNTIME_DIRECTORY")
            .stdin(Stdio::null())
            .output()
            .unwrap();
        assert!(t.elapsed() < Duration::from_secs(5), "exits at once");
        assert_eq!(out.status.code(), Some(2), "{extra:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("nothing to watch"), "{err}");
        assert!(
            err.contains("--config FILE") && err.contains("skillpost watch .  "),
            "names what to pass: {err}"
        );
        assert!(out.stdout.is_empty(), "no events: {:?}", out.stdout);
        assert!(!cwd.join("ev.jsonl").exists(), "no events file");
        assert!(!src_of(&cwd).exists(), "the current folder is not compiled");
    }
    assert!(
        !w.root.join("skillpost").exists(),
        "no state file, no lock note"
    );

    // A configuration file without projects starts the daemon: a reload may add some.
    let cfg = w.config("");
    let mut child = Command::new(bin())
        .args(["watch", "--events"])
        .arg(w.root.join("ev.jsonl"))
        .arg("--config")
        .arg(&cfg)
        .env("XDG_RUNTIME_DIR", &w.root)
        .env_remove("RUNTIME_DIRECTORY")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let started = wait_until(WAIT, || {
        read_string(&w.root.join("ev.jsonl")).contains("\"started\"")
    });
    let _ = child.kill();
    let _ = child.wait();
    assert!(started, "{}", read_string(&w.root.join("ev.jsonl")));
}

#[test]
fn watch_on_the_command_line_refuses_a_missing_folder_and_takes_a_blackboard() {
    let w = Workspace::new();
    let a = w.project("A");
    fs::write(a.join("notes.txt"), "x").unwrap();
    for (arg, says) in [
        (w.root.join("typo"), "no project folder"),
        (
            a.join("notes.txt"),
            "neither a project folder nor a blackboard",
        ),
    ] {
        let t = Instant::now();
        let out = Command::new(bin())
            .arg("watch")
            .arg(&a)
            .arg(&arg)
            .env("XDG_RUNTIME_DIR", &w.root)
            .env_remove("RUNTIME_DIRECTORY")
            .stdin(Stdio::null())
            .output()
            .unwrap();
        assert!(t.elapsed() < Duration::from_secs(5), "exits at once");
        assert_eq!(out.status.code(), Some(2), "{}", arg.display());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(says) && err.contains(arg.to_str().unwrap()),
            "{err}"
        );
        assert!(out.stdout.is_empty(), "no events: {:?}", out.stdout);
        assert!(!src_of(&a).exists(), "nothing compiled");
    }

    // A blackboard: its folder, with that blackboard (a second one in the folder is not used).
    fs::copy(a.join("Blackboard.aml"), a.join("Other.aml")).unwrap();
    let events = w.root.join("ev.jsonl");
    let mut child = Command::new(bin())
        .env("XDG_RUNTIME_DIR", &w.root)
        .env_remove("RUNTIME_DIRECTORY")
        .args(["watch", "--settle", "50", "--events"])
        .arg(&events)
        .arg(a.join("Blackboard.aml"))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let done = wait_until(WAIT, || read_string(&events).contains("\"write-back\""));
    let _ = child.kill();
    let _ = child.wait();
    let text = read_string(&events);
    assert!(done, "{text}");
    let evs: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let watching = evs.iter().find(|e| is_for(e, "watching", &a)).unwrap();
    assert_eq!(
        watching["blackboard"],
        a.join("Blackboard.aml").to_str().unwrap()
    );
    assert_eq!(watching["program"], "Blackboard");
    assert!(evs.iter().any(|e| is_for(e, "compile-succeeded", &a)));
    assert!(src_of(&a).is_file());
}

#[test]
fn started_names_the_configuration_by_its_absolute_path() {
    let w = Workspace::new();
    let a = w.project("A");
    w.config("settle_ms = 50\n[[project]]\npath = \"ws/A\"\n");
    let events = w.root.join("ev.jsonl");
    // A relative `--config`, from the workspace as the working directory.
    let mut child = Command::new(bin())
        .current_dir(&w.root)
        .env("XDG_RUNTIME_DIR", &w.root)
        .env_remove("RUNTIME_DIRECTORY")
        .args([
            "watch",
            "--config",
            "skillpost.toml",
            "--events",
            "ev.jsonl",
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let done = wait_until(WAIT, || read_string(&events).contains("\"write-back\""));
    let _ = child.kill();
    let _ = child.wait();
    let text = read_string(&events);
    assert!(done, "{text}");
    let started: Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
    assert_eq!(started["event"], "started");
    assert_eq!(
        started["config"],
        w.root.join("skillpost.toml").to_str().unwrap(),
        "{started}"
    );
    assert!(src_of(&a).is_file());
}

#[test]
fn pou_is_passed_like_the_command_lines() {
    let w = Workspace::new();
    let a = w.project("A");
    let b = w.project("B");
    let cfg = w.config("pou = \"Nope\"\n[[project]]\npath = \"ws/A\"\n[[project]]\npath = \"ws/B\"\npou = \"Demo\"\n");
    let d = InProc::with_config(&cfg);
    let evs = d.wait_for("A fails: no such POU", WAIT, |e| {
        is_for(e, "compile-failed", &a)
    });
    let failed = evs
        .iter()
        .find(|e| is_for(e, "compile-failed", &a))
        .unwrap();
    assert!(
        failed.to_string().contains("no POU named `Nope`"),
        "{failed}"
    );
    d.wait_for("B compiles with its own POU", WAIT, |e| {
        is_for(e, "write-back", &b)
    });
    // A reload naming the right POU compiles A (trigger `reload`).
    let mark = d.mark();
    fs::write(&cfg, "pou = \"Demo\"\n[[project]]\npath = \"ws/A\"\n[[project]]\npath = \"ws/B\"\npou = \"Demo\"\n").unwrap();
    d.reload();
    let evs = d.wait_for("A compiles after the reload", WAIT, |e| {
        is_after(e, "compile-succeeded", &a, mark)
    });
    assert_eq!(started_after(&evs, &a, mark)[0]["trigger"], "reload");
    d.stop(WAIT);
    let copy = w.project("A_cli");
    let out = Command::new(bin())
        .args(["--pou", "Demo"])
        .arg(copy.join("Blackboard.aml"))
        .arg("Blackboard")
        .output()
        .unwrap();
    assert!(out.status.success());
    assert_same_outputs(&a, &copy, "Blackboard");
}

/// Every file and folder under `dir` with its size, mode and modification time.
fn listing(dir: &Path) -> Vec<(PathBuf, u64, u32, std::time::SystemTime)> {
    use std::os::unix::fs::PermissionsExt;
    let mut out = Vec::new();
    let mut todo = vec![dir.to_owned()];
    while let Some(d) = todo.pop() {
        for e in fs::read_dir(&d).unwrap().flatten() {
            let m = e.path().symlink_metadata().unwrap();
            if m.is_dir() {
                todo.push(e.path());
            }
            out.push((
                e.path(),
                if m.is_dir() { 0 } else { m.len() },
                m.permissions().mode(),
                m.modified().unwrap(),
            ));
        }
    }
    out.sort();
    out
}

/// `skillpost watch --check-config ARGS` through the binary, its runtime folder in `w`.
fn check_config(w: &Workspace, mut cmd: Command, args: &[&Path]) -> (Option<i32>, String) {
    cmd.args(["watch", "--check-config", "--config"])
        .args(args)
        .env("XDG_RUNTIME_DIR", w.root.join("run"))
        .env_remove("RUNTIME_DIRECTORY")
        .stdin(Stdio::null());
    let out = cmd.output().unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{text}");
    (out.status.code(), text)
}

/// Issue 27, item 3: `--check-config` reads the configuration, resolves every project and
/// root, prints a table and exits 0, writing nothing anywhere (no events, no state, no lock,
/// no outputs, no write-back: the listing of the whole workspace is the same after).
#[test]
fn check_config_checks_everything_and_writes_nothing() {
    let w = Workspace::new();
    let a = w.project("A");
    let b = w.ws().join("root").join("B");
    copy_project(&b);
    let cfg = w.config(
        "events = \"ev.jsonl\"\n[[project]]\npath = \"ws/A\"\n[[root]]\npath = \"ws/root\"\n",
    );
    let before = listing(&w.root);
    let (code, out) = check_config(&w, Command::new(bin()), &[&cfg]);
    assert_eq!(code, Some(0), "{out}");
    assert_eq!(listing(&w.root), before, "nothing written: {out}");
    assert!(!w.root.join("run").exists());
    assert!(out.contains("PROJECT") && out.contains("FOLDER") && out.contains("RESULT"));
    let line = |folder: &Path| {
        let f = format!("  {}  ", folder.display());
        out.lines()
            .find(|l| l.contains(&f))
            .unwrap_or_else(|| panic!("a line for {f}: {out}"))
            .to_owned()
    };
    for p in [&a, &b] {
        let l = line(p);
        assert!(
            l.starts_with("Blackboard ") && l.contains("ok: reads 3 inputs"),
            "{l}"
        );
    }
    assert!(
        line(&w.ws().join("root")).contains("ok: lists the root: 1 project"),
        "{out}"
    );
    assert!(line(&w.root.join("ev.jsonl")).contains("ok: creates the events file"));
    assert!(out.ends_with("configuration OK\n"), "{out}");

    // A project folder that does not exist (`ws/Alhpa` for `ws/Alpha`), a blackboard name
    // that does not exist, a root that does not exist: a problem row each, all in one run,
    // exit status 1, the near names suggested.
    fs::create_dir(w.ws().join("Alpha")).unwrap();
    fs::write(
        &cfg,
        "[[project]]\npath = \"ws/Alhpa\"\n[[project]]\npath = \"ws/A\"\nblackboard = \"Blackbord.aml\"\n\
         [[root]]\npath = \"ws/rot\"\n",
    )
    .unwrap();
    let before = listing(&w.root);
    let (code, out) = check_config(&w, Command::new(bin()), &[&cfg]);
    assert_eq!(code, Some(1), "{out}");
    assert_eq!(listing(&w.root), before, "nothing written: {out}");
    let line = |folder: &Path| {
        let f = format!("  {}  ", folder.display());
        out.lines()
            .find(|l| l.contains(&f))
            .unwrap_or_else(|| panic!("a line for {f}: {out}"))
            .to_owned()
    };
    assert!(
        line(&w.ws().join("Alhpa")).contains(&format!(
            "PROBLEM: the project folder does not exist; did you mean {}? (the daemon would wait for it)",
            w.ws().join("Alpha").display()
        )),
        "{out}"
    );
    assert!(
        line(&a).contains(
            "PROBLEM: the blackboard Blackbord.aml does not exist in the folder; did you mean `Blackboard.aml`?"
        ),
        "{out}"
    );
    assert!(
        line(&w.ws().join("rot")).contains(&format!(
            "PROBLEM: the root does not exist; did you mean {}?",
            w.ws().join("root").display()
        )),
        "{out}"
    );
    assert!(
        out.ends_with("configuration check failed: 3 problems\n"),
        "{out}"
    );

    // An invalid configuration: the error with file, line and column, exit status 1.
    fs::write(&cfg, "[[project]]\npath = \"ws/A\"\nsettle = 5\n").unwrap();
    let before = listing(&w.root);
    let (code, out) = check_config(&w, Command::new(bin()), &[&cfg]);
    assert_eq!(code, Some(1), "{out}");
    assert!(
        out.contains(&format!("{}:3:1: unknown field `settle`", cfg.display())),
        "{out}"
    );
    assert_eq!(listing(&w.root), before);
}

/// Issue 28, deploy: `--check-config` names each deploy hook's program and whether this user
/// can run it (a bare name in `PATH`), writing nothing and running nothing.
#[test]
fn check_config_checks_the_deploy_hooks_program() {
    let w = Workspace::new();
    let a = w.project("A");
    let marker = w.root.join("ran");
    let cfg = w.config(&format!(
        "on_success = [\"touch\", \"{}\"]\n[[project]]\npath = \"ws/A\"\n\
         [[project]]\npath = \"ws/B\"\non_success = [\"./no-such-deploy\", \"{{src}}\"]\n",
        marker.display()
    ));
    copy_project(&w.ws().join("B"));
    let before = listing(&w.root);
    let (code, out) = check_config(&w, Command::new(bin()), &[&cfg]);
    assert_eq!(code, Some(1), "{out}");
    assert_eq!(listing(&w.root), before, "nothing written or run: {out}");
    assert!(!marker.exists());
    // A bare name: the program PATH's absolute folders hold, found when the configuration
    // was read (issue 37, item 8).
    let touch = out
        .lines()
        .find(|l| l.starts_with("(deploy)") && l.contains("/touch  "))
        .expect(&out);
    assert!(touch.contains("ok: the deploy hook runs /"), "{touch}");
    let missing = w.root.join("no-such-deploy");
    let bad = out
        .lines()
        .find(|l| l.contains(&missing.display().to_string()))
        .expect(&out);
    assert!(bad.contains("does not exist or cannot be run"), "{bad}");
    let _ = a;
}

/// Issue 27, item 3: as an unprivileged user (`nobody` when the tests run as root), an SFC the
/// user cannot read and a project folder it cannot write to are problems: named, exit status 1,
/// nothing written.
#[test]
fn check_config_names_an_unreadable_sfc_and_an_unwritable_folder() {
    use std::os::unix::fs::PermissionsExt;
    let w = Workspace::new();
    let a = w.project("A");
    let log = w.root.join("log");
    fs::create_dir(&log).unwrap();
    let root = rustix::process::geteuid().is_root();
    let runner = || {
        if root {
            let mut c = common::as_nobody("check as an unprivileged user")?;
            c.arg("--").arg(bin());
            Some(c)
        } else {
            Some(Command::new(bin()))
        }
    };
    if runner().is_none() {
        return;
    }
    if root {
        // The user's own project and events folder; the workspace readable for it.
        fs::set_permissions(&w.root, fs::Permissions::from_mode(0o755)).unwrap();
        for p in [&a, &log] {
            std::os::unix::fs::chown(p, Some(65534), Some(65534)).unwrap();
        }
        for f in fs::read_dir(&a).unwrap().flatten() {
            std::os::unix::fs::chown(f.path(), Some(65534), Some(65534)).unwrap();
        }
    }
    let cfg = w.config("events = \"log/ev.jsonl\"\n[[project]]\npath = \"ws/A\"\n");
    let (code, out) = check_config(&w, runner().unwrap(), &[&cfg]);
    assert_eq!(code, Some(0), "all is well for the project's owner: {out}");

    let sfc = a.join("sfc.xml");
    fs::set_permissions(&sfc, fs::Permissions::from_mode(0o000)).unwrap();
    let before = listing(&w.root);
    let (code, out) = check_config(&w, runner().unwrap(), &[&cfg]);
    assert_eq!(code, Some(1), "{out}");
    assert!(
        out.contains(&format!(
            "PROBLEM: cannot read {}: Permission denied",
            sfc.display()
        )),
        "{out}"
    );
    assert!(
        out.ends_with("configuration check failed: 1 problem\n"),
        "{out}"
    );
    assert_eq!(listing(&w.root), before, "nothing written");
    fs::set_permissions(&sfc, fs::Permissions::from_mode(0o644)).unwrap();

    fs::set_permissions(&a, fs::Permissions::from_mode(0o555)).unwrap();
    let before = listing(&w.root);
    let (code, out) = check_config(&w, runner().unwrap(), &[&cfg]);
    assert_eq!(listing(&w.root), before, "nothing written");
    fs::set_permissions(&a, fs::Permissions::from_mode(0o755)).unwrap();
    assert_eq!(code, Some(1), "{out}");
    assert!(
        out.contains("PROBLEM: cannot create files in the folder (the outputs, the write-back): Permission denied"),
        "{out}"
    );
    assert!(
        out.ends_with("configuration check failed: 1 problem\n"),
        "{out}"
    );
}

/// Issue 27, item 7: a `template` that does not exist is an error of the configuration at its
/// line (`watch` exits 2 at startup, `--check-config` 1), not only a compile naming the file.
#[test]
fn a_missing_template_is_located_in_the_configuration() {
    let w = Workspace::new();
    w.project("A");
    let cfg = w.config("[[project]]\npath = \"ws/A\"\ntemplate = \"../templates/krl.toml\"\n");
    let wanted = format!(
        "{}:3:12: `template`: {} does not exist",
        cfg.display(),
        w.root
            .parent()
            .unwrap()
            .join("templates/krl.toml")
            .display()
    );
    let out = Command::new(bin())
        .args(["watch", "--events"])
        .arg(w.root.join("ev.jsonl"))
        .arg("--config")
        .arg(&cfg)
        .env("XDG_RUNTIME_DIR", w.root.join("run"))
        .env_remove("RUNTIME_DIRECTORY")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains(&wanted), "{err}");
    assert!(!w.root.join("ev.jsonl").exists());
    let (code, out) = check_config(&w, Command::new(bin()), &[&cfg]);
    assert_eq!(code, Some(1), "{out}");
    assert!(out.contains(&wanted), "{out}");
}
