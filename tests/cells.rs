//! Issue 25 (cells) through the daemon: a robot and the gripper on its controller are one
//! project with one program; `compile-succeeded` names each output's program and controller, and
//! an edit of any input (the gripper's own IRL file included) compiles it again.

mod inproc;

use std::fs;
use std::path::Path;

use inproc::{InProc, WAIT, Workspace, is_for};

/// `ws/<name>`: fixtures/base/cell (a KUKA KR15-2 with a gripper mounted on it).
fn cell(w: &Workspace, name: &str) -> std::path::PathBuf {
    let dir = w.ws().join(name);
    fs::create_dir_all(&dir).unwrap();
    copy_base(&dir, "cell");
    dir
}

/// Copies `fixtures/base/<base>` into `dir`.
fn copy_base(dir: &Path, base: &str) {
    inproc::copy_fixture_layers(dir, &[&format!("base/{base}")]);
}

/// The `compile-succeeded` of the daemon's first compile of `p`.
fn startup_compile(d: &InProc, p: &Path) -> serde_json::Value {
    let evs = d.wait_for("the startup compile", WAIT, |e| {
        is_for(e, "compile-succeeded", p)
    });
    evs.into_iter()
        .find(|e| is_for(e, "compile-succeeded", p))
        .unwrap()
}

#[test]
fn a_robot_and_its_gripper_compile_as_one_program_and_follow_every_input() {
    let w = Workspace::new();
    let p = cell(&w, "Cell");
    let d = InProc::with_dirs(&[&p]);
    let ok = startup_compile(&d, &p);
    let outputs = ok["outputs"].as_array().unwrap();
    assert_eq!(outputs.len(), 3, "the .src, .dat and I/O list: {ok}");
    for o in outputs {
        assert_eq!(o["program"], "Blackboard", "{o}");
        assert_eq!(o["controller"], "KUKA KR15-2", "{o}");
    }
    d.startup(&[&p]);
    // The gripper's own IRL file is an input of the project like the robot's.
    let irl = fs::read_to_string(p.join("greifer.irl")).unwrap();
    fs::write(
        p.join("greifer.irl"),
        irl.replace("$OUT[7] = TRUE", "$OUT[8] = TRUE"),
    )
    .unwrap();
    assert!(
        inproc::wait_until(WAIT, || inproc::read_string(&inproc::src_of(&p))
            .contains("$OUT[8] = TRUE")),
        "the gripper's IRL edit was not compiled\n{}",
        inproc::dump(&d.events())
    );
}

/// `ws/<name>`: fixtures/base/cell2 over fixtures/base/cell (two KUKA robots on controllers of
/// their own, wired: the case fixtures/ok/cell-two-robots-weld).
fn two_robots(w: &Workspace, name: &str) -> std::path::PathBuf {
    let dir = cell(w, name);
    copy_base(&dir, "cell2");
    dir
}

#[test]
fn a_cell_of_two_controllers_compiles_both_programs_on_every_input_edit() {
    let w = Workspace::new();
    let p = two_robots(&w, "Weld");
    let d = InProc::with_dirs(&[&p]);
    let ok = startup_compile(&d, &p);
    // One event lists both programs, each output with its program and controller.
    let outputs: Vec<(String, String, String)> = ok["outputs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| {
            let path = o["path"].as_str().unwrap();
            let file = Path::new(path)
                .file_name()
                .unwrap()
                .to_string_lossy()
                .into_owned();
            (
                file,
                o["program"].as_str().unwrap().to_owned(),
                o["controller"].as_str().unwrap().to_owned(),
            )
        })
        .collect();
    let want = |f: &str, prog: &str, c: &str| (f.to_owned(), prog.to_owned(), c.to_owned());
    assert_eq!(
        outputs,
        vec![
            want(
                "Blackboard_KUKA_KR15_2.src",
                "Blackboard_KUKA_KR15_2",
                "KUKA KR15-2"
            ),
            want(
                "Blackboard_KUKA_KR15_2.dat",
                "Blackboard_KUKA_KR15_2",
                "KUKA KR15-2"
            ),
            want(
                "Blackboard_KUKA_KR15_2.io.csv",
                "Blackboard_KUKA_KR15_2",
                "KUKA KR15-2"
            ),
            want(
                "Blackboard_KUKA_KR16_2.src",
                "Blackboard_KUKA_KR16_2",
                "KUKA KR16-2"
            ),
            want(
                "Blackboard_KUKA_KR16_2.dat",
                "Blackboard_KUKA_KR16_2",
                "KUKA KR16-2"
            ),
            want(
                "Blackboard_KUKA_KR16_2.io.csv",
                "Blackboard_KUKA_KR16_2",
                "KUKA KR16-2"
            ),
        ],
        "{ok}"
    );
    d.startup(&[&p]);
    // Both paths are written back, each into its Code interface.
    let bb = fs::read_to_string(p.join("Blackboard.aml")).unwrap();
    assert!(
        bb.contains("<Value>Blackboard_KUKA_KR15_2.src</Value>"),
        "{bb}"
    );
    assert!(
        bb.contains("<Value>Blackboard_KUKA_KR16_2.src</Value>"),
        "{bb}"
    );
    // An edit of the second robot's device's IRL file recompiles the cell: its program
    // changes, and the first robot's stays in step (same handshakes).
    let irl = fs::read_to_string(p.join("schweiss.irl")).unwrap();
    fs::write(
        p.join("schweiss.irl"),
        irl.replace("CURRENT / 400", "CURRENT / 500"),
    )
    .unwrap();
    assert!(
        inproc::wait_until(WAIT, || inproc::read_string(
            &p.join("Blackboard_KUKA_KR16_2.src")
        )
        .contains("CURRENT / 500")),
        "the weld source's IRL edit was not compiled\n{}",
        inproc::dump(&d.events())
    );
    // An edit of the chart renames a step of the first robot: its program changes, the
    // second one's too (its handshake comments name the step).
    let sfc = fs::read_to_string(p.join("sfc.xml")).unwrap();
    fs::write(
        p.join("sfc.xml"),
        sfc.replace("name=\"Grip\"", "name=\"Grasp\""),
    )
    .unwrap();
    assert!(
        inproc::wait_until(WAIT, || {
            inproc::read_string(&p.join("Blackboard_KUKA_KR15_2.src")).contains("Grasp")
                && inproc::read_string(&p.join("Blackboard_KUKA_KR16_2.src")).contains("Grasp")
        }),
        "the chart's edit did not reach both programs\n{}",
        inproc::dump(&d.events())
    );
}
