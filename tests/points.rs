//! Issue 38, item 1: teachable points through the binary (docs/LANGUAGES.md, "Points"). A motion
//! to a literal position becomes a motion to a named point the technician can touch up: KUKA's
//! inline form with its data in the `.dat`, or `PTP XName` when the program sets its own
//! velocity (W210); the `Points` attribute keeps literal positions (`inline`) or is an error at
//! the attribute (E216).

mod inproc;

use std::collections::HashMap;
use std::fs;
use std::path::Path;
use std::process::{Command, Output};

use inproc::{Workspace, copy_fixture_layers};

fn compile(dir: &Path, blackboard: &str, program: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["--warn", "--lf", blackboard, program])
        .current_dir(dir)
        .output()
        .unwrap()
}

fn ok(o: &Output) -> String {
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The `.dat`'s declarations: name → (type, value).
fn dat(text: &str) -> HashMap<String, (String, String)> {
    let mut out = HashMap::new();
    for l in text.lines() {
        let Some(rest) = l.trim().strip_prefix("DECL ") else {
            continue;
        };
        let (ty, rest) = rest.split_once(' ').unwrap();
        let (name, value) = rest.split_once('=').unwrap();
        let dup = out.insert(name.to_owned(), (ty.to_owned(), value.to_owned()));
        assert!(dup.is_none(), "`{name}` declared twice");
    }
    out
}

/// Adds `<Attribute Name="Points">` with `value` to the resource `name` of the blackboard.
fn set_points(blackboard: &Path, name: &str, value: &str) {
    let text = fs::read_to_string(blackboard).unwrap();
    let at = text.find(&format!("Name=\"{name}\"")).unwrap();
    let end = at + text[at..].find('>').unwrap() + 1;
    let attr = format!("<Attribute Name=\"Points\"><Value>{value}</Value></Attribute>");
    fs::write(
        blackboard,
        format!("{}{attr}{}", &text[..end], &text[end..]),
    )
    .unwrap();
}

#[test]
fn every_motion_of_a_krl_program_goes_to_a_named_point_in_an_inline_form() {
    let w = Workspace::new();
    let p = w.ws().join("Cyclic");
    copy_fixture_layers(&p, &["base/flow", "ok/flow-cyclic"]);
    let err = ok(&compile(&p, "Blackboard.aml", "Cyclic"));
    assert!(!err.contains("W210"), "{err}");
    let src = fs::read_to_string(p.join("Cyclic.src")).unwrap();
    let decls = dat(&fs::read_to_string(p.join("Cyclic.dat")).unwrap());
    // Each step's motion: the inline form of a point named after the step, its data declared.
    let mut forms = 0;
    for step in ["Calibrate", "Cycle", "Work"] {
        let title = format!(";FOLD LIN {step} Vel=2 m/s CPDAT");
        let at = src.find(&title).unwrap_or_else(|| panic!("{step}:\n{src}"));
        let form: Vec<&str> = src[at..].lines().take(7).map(str::trim).collect();
        assert!(
            form[0].contains(&format!("%P 1:LIN, 2:{step}, 3:, 5:2, 7:CPDAT")),
            "{form:?}"
        );
        let ldat = form[2].strip_prefix("LDAT_ACT=").unwrap();
        assert_eq!(form[3], format!("FDAT_ACT=F{step}"));
        assert_eq!(form[5], format!("LIN X{step}"));
        assert_eq!(decls[ldat].0, "LDAT");
        assert_eq!(decls[&format!("F{step}")].0, "FDAT");
        assert_eq!(decls[&format!("X{step}")].0, "E6POS");
        forms += 1;
    }
    assert_eq!(forms, src.matches("%CMOVE").count());
    // The values are the chart's: Calibrate goes to X 10, Y 3.
    assert_eq!(decls["XCalibrate"].1, "{X 10, Y 3, Z 0, A 0, B 0, C 0}");
    // No literal position is left in a motion.
    assert!(!src.contains("LIN {"), "{src}");
    // The same inputs give the same names and bytes.
    let again = ok(&compile(&p, "Blackboard.aml", "Cyclic"));
    assert!(!again.contains("W210"));
    assert_eq!(fs::read_to_string(p.join("Cyclic.src")).unwrap(), src);
}

/// Adds attributes (XML) to the resource `name` of the blackboard.
fn add_attributes(blackboard: &Path, name: &str, xml: &str) {
    let text = fs::read_to_string(blackboard).unwrap();
    let at = text.find(&format!("Name=\"{name}\"")).unwrap();
    let end = at + text[at..].find('>').unwrap() + 1;
    fs::write(blackboard, format!("{}{xml}{}", &text[..end], &text[end..])).unwrap();
}

/// A numbered tool and base (KUKA's `TOOL_DATA[3]`, `BASE_DATA[2]`) are the inline forms' own:
/// `Tool[3] Base[2]` and `FDAT` `TOOL_NO 3, BASE_NO 2`, so a form's `BAS` sets what the program
/// set. A tool given as a frame (`$TOOL = {…}`), which a form's `FDAT` cannot say, keeps the
/// motions out of inline forms (`W210` naming the statement).
#[test]
fn inline_forms_carry_the_blackboards_numbered_tool_and_base_and_no_frame() {
    let w = Workspace::new();
    let p = w.ws().join("Cyclic");
    copy_fixture_layers(&p, &["base/flow", "ok/flow-cyclic"]);
    let bb = p.join("Blackboard.aml");
    let original = fs::read_to_string(&bb).unwrap();
    add_attributes(
        &bb,
        "KUKA KR15-2",
        "<Attribute Name=\"ToolNumber\"><Value>3</Value></Attribute><Attribute Name=\"BaseNumber\"><Value>2</Value></Attribute>",
    );
    let err = ok(&compile(&p, "Blackboard.aml", "Cyclic"));
    assert!(!err.contains("W210"), "{err}");
    let src = fs::read_to_string(p.join("Cyclic.src")).unwrap();
    assert!(
        src.contains("BAS(#TOOL, 3)") && src.contains("BAS(#BASE, 2)"),
        "{src}"
    );
    assert_eq!(src.matches("%CMOVE").count(), 3, "{src}");
    assert_eq!(src.matches("Tool[3] Base[2];%{PE}").count(), 3, "{src}");
    let decls = dat(&fs::read_to_string(p.join("Cyclic.dat")).unwrap());
    assert!(
        decls["FCalibrate"].1.starts_with("{TOOL_NO 3,BASE_NO 2,"),
        "{decls:?}"
    );

    fs::write(&bb, &original).unwrap();
    add_attributes(
        &bb,
        "KUKA KR15-2",
        "<Attribute Name=\"Tool\"><Attribute Name=\"x\"><Value>0</Value></Attribute><Attribute Name=\"y\"><Value>0</Value></Attribute><Attribute Name=\"z\"><Value>0.12</Value></Attribute><Attribute Name=\"rx\"><Value>0</Value></Attribute><Attribute Name=\"ry\"><Value>0</Value></Attribute><Attribute Name=\"rz\"><Value>0</Value></Attribute></Attribute>",
    );
    let err = ok(&compile(&p, "Blackboard.aml", "Cyclic"));
    assert!(
        err.contains("warning[W210]") && err.contains("`$TOOL = {"),
        "{err}"
    );
    let src = fs::read_to_string(p.join("Cyclic.src")).unwrap();
    assert!(
        !src.contains("%CMOVE") && src.contains("  LIN XCalibrate\n"),
        "{src}"
    );
    assert!(src.find("$TOOL = {").unwrap() < src.find("LIN XCalibrate").unwrap());
}

#[test]
fn a_program_that_sets_its_own_velocity_keeps_it_and_is_told_why_there_is_no_inline_form() {
    let w = Workspace::new();
    let p = w.ws().join("Sample");
    copy_fixture_layers(&p, &["ok/reference-sample"]);
    let err = ok(&compile(&p, "Blackboard.aml", "demo"));
    // W210 names the statement and where it is.
    assert!(err.contains("warning[W210]"), "{err}");
    assert!(
        err.contains("`$VEL.CP = VALUE`") && err.contains("SetVelCP"),
        "{err}"
    );
    assert!(err.contains("kr15-2.irl:"), "{err}");
    let src = fs::read_to_string(p.join("demo.src")).unwrap();
    // The planner's velocity comes before the motion, and nothing after it replaces it.
    assert!(src.contains("  SetVelCP (0.5)\n  PTP XP2P\n"), "{src}");
    assert!(src.contains("  LIN XLIN\n"), "{src}");
    assert!(src.contains("  SetVelCP (0.3)\n  PTP XP2P_2\n"), "{src}");
    assert!(!src.contains("%CMOVE") && !src.contains("BAS(#"), "{src}");
    let decls = dat(&fs::read_to_string(p.join("demo.dat")).unwrap());
    assert_eq!(
        decls["XP2P"],
        (
            "E6POS".into(),
            "{X 100, Y 200, Z 300, A 0, B 90, C 0}".into()
        )
    );
    assert_eq!(decls["XP2P_2"].1, "{X 6, Y 6, Z 6, A 0, B 0, C 0}");
    assert_eq!(decls.len(), 3, "{decls:?}");
}

#[test]
fn points_inline_keeps_literal_positions_and_a_bad_value_is_an_error_at_the_attribute() {
    let w = Workspace::new();
    let p = w.ws().join("Sample");
    copy_fixture_layers(&p, &["ok/reference-sample"]);
    let bb = p.join("Blackboard.aml");
    let original = fs::read_to_string(&bb).unwrap();
    set_points(&bb, "KUKA KR15-2", "Inline");
    let err = ok(&compile(&p, "Blackboard.aml", "demo"));
    assert!(!err.contains("W210"), "{err}");
    let src = fs::read_to_string(p.join("demo.src")).unwrap();
    assert!(
        src.contains("  PTP {X 100, Y 200, Z 300, A 0, B 90, C 0}\n"),
        "{src}"
    );
    assert!(
        !fs::read_to_string(p.join("demo.dat"))
            .unwrap()
            .contains("E6POS")
    );

    fs::write(&bb, &original).unwrap();
    fs::remove_file(p.join("demo.src")).unwrap();
    set_points(&bb, "KUKA KR15-2", "nammed");
    let o = compile(&p, "Blackboard.aml", "demo");
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("error[E216]") && err.contains("`Points` is `nammed`"),
        "{err}"
    );
    assert!(err.contains("did you mean `named`?"), "{err}");
    assert!(err.contains("Blackboard.aml:6:"), "{err}");
    assert!(!p.join("demo.src").exists(), "nothing is written");

    // `forms`: inline forms, whatever the code sets; no W210.
    fs::write(&bb, &original).unwrap();
    set_points(&bb, "KUKA KR15-2", "forms");
    let err = ok(&compile(&p, "Blackboard.aml", "demo"));
    assert!(!err.contains("W210"), "{err}");
    let src = fs::read_to_string(p.join("demo.src")).unwrap();
    assert_eq!(src.matches("%CMOVE").count(), 3, "{src}");
    assert!(
        src.contains("SetVelCP (0.3)\n  ;FOLD PTP P2P_2 Vel=100 % PDAT2"),
        "{src}"
    );
}

#[test]
fn rapid_and_urscript_programs_move_to_points_declared_before_their_use() {
    for (case, base, file, decl, motion) in [
        (
            "abb-irb1200",
            "abb",
            "Palletize.mod",
            "CONST robtarget pPick := [[400, 0, 300],",
            "MoveL pPick, v200, fine, tGripper;",
        ),
        (
            "ur10e",
            "ur",
            "Palletize.script",
            "global pPick = p[0.4, 0, 0.3, 0, 3.141593, 0]",
            "movel(pPick, a=1.2, v=0.25)",
        ),
    ] {
        let w = Workspace::new();
        let p = w.ws().join("P");
        copy_fixture_layers(&p, &[&format!("base/{base}"), &format!("ok/{case}")]);
        let bb = fs::read_dir(&p)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .find(|n| n.ends_with(".aml"))
            .unwrap();
        ok(&compile(&p, &bb, "Palletize"));
        let text = fs::read_to_string(p.join(file)).unwrap();
        let d = text.find(decl).unwrap_or_else(|| panic!("{case}:\n{text}"));
        let m = text
            .find(motion)
            .unwrap_or_else(|| panic!("{case}:\n{text}"));
        assert!(d < m, "{case}: declared after its use");
        assert_eq!(text.matches(decl).count(), 1, "{case}");
    }
}

/// A point named after a long step is cut to the language's length: KRL names are at most 24
/// characters (KUKA System Software 8.x, operating and programming instructions for system
/// integrators, "Names"). Before, a step's only point kept the whole name
/// (`XCalibrateTheGripperAgainstTheFixture`, which the controller refuses).
#[test]
fn a_point_named_after_a_long_step_fits_the_languages_names() {
    let w = Workspace::new();
    let p = w.ws().join("Cyclic");
    copy_fixture_layers(&p, &["base/flow", "ok/flow-cyclic"]);
    let sfc = p.join("sfc.xml");
    let text = fs::read_to_string(&sfc).unwrap();
    fs::write(
        &sfc,
        text.replace(
            "name=\"Calibrate\"",
            "name=\"Calibrate the gripper against the fixture\"",
        ),
    )
    .unwrap();
    ok(&compile(&p, "Blackboard.aml", "Cyclic"));
    let decls = dat(&fs::read_to_string(p.join("Cyclic.dat")).unwrap());
    let long: Vec<&String> = decls.keys().filter(|n| n.len() > 24).collect();
    assert!(long.is_empty(), "names longer than 24 characters: {long:?}");
    assert_eq!(
        decls["XCalibrateTheGripperAgai"].1,
        "{X 10, Y 3, Z 0, A 0, B 0, C 0}"
    );
    let src = fs::read_to_string(p.join("Cyclic.src")).unwrap();
    assert!(src.contains("LIN XCalibrateTheGripperAgai\n"), "{src}");
}
