//! Tool, base and load from the blackboard (docs/INPUTS.md, "Tool, base and load"), through the
//! binary: which tool a step moves with, where the program sets it, and the warning for a
//! resource that moves without them. The forms of each language are in the snapshots of
//! `fixtures/ok/cell-tool-base-load`; the refusals in `fixtures/err/e216_*`.

use std::path::Path;
use std::process::{Command, Output};

fn run(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8(o.stderr.clone()).unwrap()
}

/// A temporary copy of `fixtures/base/<base>` (and `fixtures/ok/<case>` over it, when given).
fn project(base: &str, case: Option<&str>) -> tempfile::TempDir {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let t = tempfile::tempdir().unwrap();
    let dirs =
        std::iter::once(root.join("base").join(base)).chain(case.map(|c| root.join("ok").join(c)));
    for dir in dirs {
        for e in std::fs::read_dir(dir).unwrap() {
            let e = e.unwrap();
            let name = e.file_name();
            if name != "case.toml" && name != "README.txt" {
                std::fs::copy(e.path(), t.path().join(name)).unwrap();
            }
        }
    }
    t
}

/// Puts `attributes` first inside the `InternalElement` named `element` of `file`.
fn add_attributes(file: &Path, element: &str, attributes: &str) {
    let text = std::fs::read_to_string(file).unwrap();
    let open = format!("<InternalElement Name=\"{element}\"");
    let at = text.find(&open).expect("the element");
    let end = at + text[at..].find('>').unwrap() + 1;
    let text = format!("{}\n{attributes}{}", &text[..end], &text[end..]);
    std::fs::write(file, text).unwrap();
}

/// A `Tool` frame `z` metres along the flange's Z.
fn tool_z(z: &str) -> String {
    format!(
        "<Attribute Name=\"Tool\"><Attribute Name=\"z\" AttributeDataType=\"xs:double\" Unit=\"m\"><Value>{z}</Value></Attribute></Attribute>\n"
    )
}

/// The lines of `text` that set `$TOOL` in a step (the template's fold, before the steps, left
/// out).
fn tool_lines(text: &str) -> Vec<&str> {
    let steps = text.find(";FOLD 1 ").expect("a first step");
    text[steps..]
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with("$TOOL = ") || l.starts_with("BAS(#TOOL"))
        .collect()
}

#[test]
fn a_moving_resource_without_tool_base_or_load_is_warned_once_and_its_program_is_unchanged() {
    let p = project("flow", Some("flow-loop-exit"));
    let o = run(&["--warn", "Blackboard.aml", "LoopExit"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let err = stderr(&o);
    assert_eq!(err.matches("W211").count(), 1, "{err}");
    assert!(
        err.contains(
            "resource `KUKA KR15-2`: its steps move, but the blackboard gives no tool (`Tool` or `ToolNumber`), no base (`Base` or `BaseNumber`) and no load (`Load`, or a device's `Mass`) for them"
        ),
        "{err}"
    );
    let src = std::fs::read_to_string(p.path().join("LoopExit.src")).unwrap();
    assert!(
        tool_lines(&src).is_empty() && !src.contains("$LOAD"),
        "{src}"
    );
    // Without --warn the warning is counted, not shown.
    let o = run(&["Blackboard.aml", "LoopExit"], p.path());
    assert_eq!(o.status.code(), Some(0));
    assert!(!stderr(&o).contains("W211"), "{}", stderr(&o));
}

#[test]
fn each_step_moves_with_its_devices_tool_and_the_tool_changes_only_where_it_differs() {
    // The KUKA KR15-2 with its own tool and the gripper mounted on it with another: the robot's
    // two moves use the robot's tool (set once), the gripper's step its own.
    let p = project("cell", None);
    let bb = p.path().join("Blackboard.aml");
    add_attributes(&bb, "KUKA KR15-2", &tool_z("0.1"));
    add_attributes(&bb, "Greifer G1", &tool_z("0.2"));
    let o = run(&["--warn", "Blackboard.aml", "Cell"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = std::fs::read_to_string(p.path().join("Cell.src")).unwrap();
    assert_eq!(
        tool_lines(&src),
        [
            "$TOOL = {X 0, Y 0, Z 100, A 0, B 0, C 0}",
            "$TOOL = {X 0, Y 0, Z 200, A 0, B 0, C 0}"
        ],
        "{src}"
    );
    assert!(src.contains(";FOLD 3 Grip: Close @ Greifer G1 (localId 6)\r\n  ;tool of Greifer G1\r\n  $TOOL = {X 0, Y 0, Z 200"), "{src}");
    // The robot still has no base and no load: named once.
    let err = stderr(&o);
    assert!(
        err.contains("gives no base (`Base` or `BaseNumber`) and no load"),
        "{err}"
    );
    // `-pB` shows what was read, in the program's units.
    let o = run(&["--validate", "-pB", "Blackboard.aml"], p.path());
    let listing = String::from_utf8(o.stdout).unwrap();
    assert!(
        listing.contains("        (Tool) X 0, Y 0, Z 200, A 0, B 0, C 0 (mm, degrees)\n"),
        "{listing}"
    );

    // Without its own tool, the robot's moves use the only tool on its controller: the
    // gripper's, set once before the first step.
    let p = project("cell", None);
    add_attributes(
        &p.path().join("Blackboard.aml"),
        "Greifer G1",
        &tool_z("0.2"),
    );
    let o = run(&["Blackboard.aml", "Cell"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = std::fs::read_to_string(p.path().join("Cell.src")).unwrap();
    assert_eq!(
        tool_lines(&src),
        ["$TOOL = {X 0, Y 0, Z 200, A 0, B 0, C 0}"],
        "{src}"
    );
    assert!(
        src.contains(
            ";FOLD 1 P2P: Move PTP @ KUKA KR15-2 (localId 3)\r\n  ;tool of Greifer G1\r\n"
        ),
        "{src}"
    );
}

#[test]
fn a_loop_sets_its_tool_again_at_its_first_step_each_round() {
    // The tool in effect when a loop comes round again is the one its last step left, and the
    // one before the loop on the first round: the first step of the body sets it each time.
    let p = project("flow", Some("flow-loop-exit"));
    let bb = p.path().join("Blackboard.aml");
    add_attributes(
        &bb,
        "KUKA KR15-2",
        &format!(
            "{}<Attribute Name=\"BaseNumber\"><Value>4</Value></Attribute>\n<Attribute Name=\"Load\" Unit=\"kg\"><Value>3.5</Value></Attribute>\n",
            tool_z("0.1")
        ),
    );
    let o = run(&["--warn", "Blackboard.aml", "LoopExit"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!stderr(&o).contains("W211"), "{}", stderr(&o));
    let src = std::fs::read_to_string(p.path().join("LoopExit.src")).unwrap();
    let loop_at = src.find("\r\nLOOP\r\n").expect("a loop");
    let first_in_loop = loop_at + src[loop_at..].find(";FOLD ").unwrap();
    let fold_end = first_in_loop + src[first_in_loop..].find(";ENDFOLD").unwrap();
    let fold = &src[first_in_loop..fold_end];
    for line in [
        "$TOOL = {X 0, Y 0, Z 100, A 0, B 0, C 0}",
        "$LOAD = {M 3.5, CM {X 0, Y 0, Z 0, A 0, B 0, C 0}, J {X 0, Y 0, Z 0}}",
        "BAS(#BASE, 4)",
    ] {
        assert!(fold.contains(line), "{line} in\n{fold}");
    }
    // Set before the loop too, once per place where it may differ.
    assert_eq!(
        src.matches("BAS(#BASE, 4)").count(),
        tool_lines(&src).len(),
        "{src}"
    );
}

#[test]
fn a_rapid_robot_moves_with_its_tool_frame_where_a_numbered_tool_stands_beside_it() {
    let p = project("abb", None);
    let cell = p.path().join("Cell.aml");
    add_attributes(
        &cell,
        "ABB IRB 1200",
        &format!(
            "{}<Attribute Name=\"ToolNumber\"><Value>3</Value></Attribute>\n",
            tool_z("0.12")
        ),
    );
    let o = run(&["--warn", "Cell.aml", "Palletize"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let module = std::fs::read_to_string(p.path().join("Palletize.mod")).unwrap();
    assert!(
        module.contains("PERS tooldata skp_tool1 := [TRUE, [[0, 0, 120], [1, 0, 0, 0]], [0.001, [0, 0, 0.001], [1, 0, 0, 0], 0, 0, 0]];"),
        "{module}"
    );
    assert!(
        module.contains("    skp_tool := skp_tool1;\r\n"),
        "{module}"
    );
}
