//! The daemon's simulation after a compile (`simulate` in the configuration; docs/SIMULATE.md,
//! "In the daemon"), in this process (tests/inproc/mod.rs): the result of each compile's
//! programs as an event and in the state file; an edit that makes the programs deadlock is
//! reported for the compile of that edit; a scenario that cannot be used is located; the
//! outputs stand either way.

mod common;
mod inproc;

use std::fs;
use std::path::Path;

use inproc::*;

/// The weld cell (two KUKA controllers) as `ws/<name>`, with a scenario `ok.toml`.
fn weld_cell(w: &Workspace, name: &str) -> std::path::PathBuf {
    let dir = w.ws().join(name);
    fs::create_dir_all(&dir).unwrap();
    let fixture = common::fixture_project("cell-two-robots-weld");
    for e in fs::read_dir(fixture.path()).unwrap() {
        let e = e.unwrap();
        fs::copy(e.path(), dir.join(e.file_name())).unwrap();
    }
    fs::write(
        dir.join("ok.toml"),
        "[inputs.\"KUKA KR16-2\"]\nMore_Parts = false\n",
    )
    .unwrap();
    dir
}

fn start(w: &Workspace, project: &Path, simulate: &str) -> (InProc, std::path::PathBuf) {
    let config = w.config(&format!(
        "[[project]]\npath = \"{}\"\nprogram = \"Weld\"\nsimulate = {simulate}\n",
        project.display()
    ));
    let sources = skillpost::daemon::Sources {
        config_file: Some(config),
        settle_ms: Some(SETTLE_MS),
        ..Default::default()
    };
    let state = w.root.join("status.json");
    let d = InProc::start_with_state(sources.load().unwrap(), sources, &state);
    (d, state)
}

/// The run_id of the last `compile-succeeded` of `project` in `evs`.
fn last_compile(evs: &[serde_json::Value], project: &Path) -> u64 {
    evs.iter()
        .rev()
        .find(|e| is_for(e, "compile-succeeded", project))
        .and_then(|e| e["run_id"].as_u64())
        .expect("a compile-succeeded")
}

#[test]
fn an_edit_that_deadlocks_the_cell_is_reported_for_the_compile_of_that_edit() {
    let w = Workspace::new();
    let p = weld_cell(&w, "weld");
    let (d, state) = start(&w, &p, "\"ok.toml\"");
    let evs = d.wait_for("the first simulation", WAIT, |e| {
        is_for(e, "simulation-succeeded", &p)
    });
    let ok = evs
        .iter()
        .find(|e| is_for(e, "simulation-succeeded", &p))
        .unwrap();
    assert_eq!(
        ok["run_id"].as_u64(),
        Some(last_compile(&evs, &p)),
        "{}",
        dump(&evs)
    );
    assert_eq!(ok["runs"], 1);
    assert_eq!(ok["level"], "info");
    let cycle = ok["cycle_s"].as_f64().expect("the cell ends");
    assert!(cycle > 0.0);

    // The gripper's code now waits for a wire its partner sets only later: a deadlock.
    let mark = d.mark();
    let irl = read_string(&p.join("greifer.irl"));
    fs::write(
        p.join("greifer.irl"),
        irl.replace("$OUT[7] = TRUE", "$OUT[7] = TRUE\n\t\t\t\tWAIT FOR $IN[21]"),
    )
    .unwrap();
    let evs = d.wait_for("the simulation of the edit", WAIT, |e| {
        is_after(e, "simulation-failed", &p, mark)
    });
    let failed = evs
        .iter()
        .find(|e| is_after(e, "simulation-failed", &p, mark))
        .unwrap();
    // Within the compile cycle of the edit: the run_id of the compile that read it.
    assert_eq!(
        failed["run_id"].as_u64(),
        Some(last_compile(&evs, &p)),
        "{}",
        dump(&evs)
    );
    assert_eq!(
        count_after(&evs, "compile-succeeded", &p, mark),
        1,
        "{}",
        dump(&evs)
    );
    assert_eq!(failed["level"], "warn");
    assert_eq!(failed["kind"], "deadlock", "{failed:#}");
    let message = failed["message"].as_str().unwrap();
    assert!(
        message.contains("KUKA KR15-2") && message.contains("KUKA KR16-2"),
        "{message}"
    );
    assert!(failed["line"].as_u64().is_some() && failed["file"].as_str().is_some());
    // The outputs stand: the compile succeeded and wrote them.
    assert!(read_string(&p.join("Weld_KUKA_KR15_2.src")).contains("WAIT FOR $IN[21]"));
    // `skillpost status` shows the last simulation.
    assert!(wait_until(WAIT, || {
        let s = fs::read_to_string(&state).unwrap_or_default();
        s.contains("\"simulation\"") && s.contains("deadlock")
    }));
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["status", "--state"])
        .arg(&state)
        .output()
        .unwrap();
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.contains("SIMULATION")
            && table.contains("failed (1 run)")
            && table.contains("deadlock"),
        "{table}"
    );

    // An edit of the scenario file alone simulates again.
    let mark = d.mark();
    fs::write(p.join("greifer.irl"), &irl).unwrap();
    d.wait_for("the simulation after the fix", WAIT, |e| {
        is_after(e, "simulation-succeeded", &p, mark)
    });
    let mark = d.mark();
    fs::write(
        p.join("ok.toml"),
        "[inputs.\"KUKA KR16-2\"]\nMore_Parts = fals\n",
    )
    .unwrap();
    let evs = d.wait_for("the scenario's error", WAIT, |e| {
        is_after(e, "simulation-failed", &p, mark)
    });
    let bad = evs
        .iter()
        .find(|e| is_after(e, "simulation-failed", &p, mark))
        .unwrap();
    assert_eq!(bad["kind"], "scenario", "{bad:#}");
    assert_eq!(bad["line"], 2);
    assert!(bad["file"].as_str().unwrap().ends_with("ok.toml"));
    d.stop(WAIT);
}

#[test]
fn random_runs_are_simulated_and_a_wrong_setting_is_a_configuration_error() {
    let w = Workspace::new();
    let p = weld_cell(&w, "weld");
    let (d, _) = start(&w, &p, "25");
    let evs = d.wait_for("the simulation", WAIT, |e| {
        is_for(e, "simulation-succeeded", &p) || is_for(e, "simulation-failed", &p)
    });
    let e = evs
        .iter()
        .find(|e| is_for(e, "simulation-succeeded", &p))
        .unwrap_or_else(|| panic!("{}", dump(&evs)));
    assert_eq!(e["runs"], 25);
    d.stop(WAIT);
    for (value, expected) in [
        (
            "\"../x.toml\"",
            "names a scenario file in the project folder",
        ),
        ("-3", "a number of random runs (1 to 10000; 0: none)"),
        ("100001", "a number of random runs"),
    ] {
        let file = w.config(&format!(
            "[[project]]\npath = \"{}\"\nsimulate = {value}\n",
            p.display()
        ));
        let err = skillpost::daemon::config::load(&file)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(expected) && err.contains(":3:"),
            "{value}: {err}"
        );
    }
}

/// A scenario file that is a symbolic link leading out of the project folder is not read (the
/// project's writers could point the daemon at any file its user may read): the simulation
/// fails with the reason, the outputs stand.
#[test]
fn a_scenario_linked_out_of_the_project_is_not_read() {
    let w = Workspace::new();
    let p = weld_cell(&w, "weld");
    let outside = w.root.join("outside.toml");
    fs::write(&outside, "[inputs.\"KUKA KR16-2\"]\nMore_Parts = false\n").unwrap();
    std::os::unix::fs::symlink(&outside, p.join("linked.toml")).unwrap();
    let mark = 0;
    let (d, _state) = start(&w, &p, "\"linked.toml\"");
    let evs = d.wait_for("the refused scenario", WAIT, |e| {
        is_after(e, "simulation-failed", &p, mark)
    });
    let bad = evs
        .iter()
        .find(|e| is_after(e, "simulation-failed", &p, mark))
        .unwrap();
    assert_eq!(bad["kind"], "scenario", "{bad:#}");
    assert!(
        bad["message"]
            .as_str()
            .unwrap()
            .contains("leads out of the project folder"),
        "{bad:#}"
    );
    assert!(p.join("Weld_KUKA_KR15_2.src").exists());
    d.stop(WAIT);
}
