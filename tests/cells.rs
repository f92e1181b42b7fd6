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
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/base/cell");
    for e in fs::read_dir(base).unwrap() {
        let e = e.unwrap();
        fs::copy(e.path(), dir.join(e.file_name())).unwrap();
    }
    dir
}

#[test]
fn a_robot_and_its_gripper_compile_as_one_program_and_follow_every_input() {
    let w = Workspace::new();
    let p = cell(&w, "Cell");
    let d = InProc::with_dirs(&[&p]);
    let evs = d.wait_for("the startup compile", WAIT, |e| {
        is_for(e, "compile-succeeded", &p)
    });
    let ok = evs
        .iter()
        .find(|e| is_for(e, "compile-succeeded", &p))
        .unwrap();
    let outputs = ok["outputs"].as_array().unwrap();
    assert_eq!(outputs.len(), 2, "{ok}");
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
