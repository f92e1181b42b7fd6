//! The RAPID syntax check itself (`common::rapid`): rapidchecker is there (under
//! `SKILLPOST_STRICT_TESTS=1` its absence fails), passes a module of the shape the RAPID emitter
//! writes, and rejects what the emitter must not write. Each case is the good module with one
//! change, so a changed rule of a new rapidchecker shows here first.

mod common;

use common::rapid::{rapidcheck, rapidchecker_missing};

/// The shape the emitter writes: 2 spaces per level (MODULE 0, PROC 1, its body 2, `CASE` at
/// the level of `TEST`), upper-case keywords, `VAR`s first in the routine, loops left by a flag,
/// one value per `CASE`, a `WaitUntil` condition that starts with `(` wrapped whole in `( )`.
const GOOD: &str = r#"MODULE Cell
  ! Company name: x Product name: y; "quoted" ! 'single' \ [x] {y} %z%
  PROC main()
    VAR bool skp_loop1 := TRUE;
    VAR num skp_branch := 0;
    ! step 1 Pick: pick @ robot (localId 3)
    MoveJ [[500,0,600],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v1000, z50, tool0;
    MoveL [[-500.25,-0.5,1E3],[0.707107,0,-0.707107,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, fine, tool0\WObj:=wobj0;
    SetDO do_Gripper, 1;
    WaitTime 0.5;

    ! transition localId 7: Part
    WaitUntil di_Part = 1;
    IF (di_Part = 1) AND (gi_Type = 2) THEN
      MoveL p10, v100, fine, tool0;
    ELSEIF NOT (di_Part = 1) THEN
      WaitTime 1;
    ELSE
      WaitTime 2;
    ENDIF
    skp_branch := 0;
    WHILE skp_branch = 0 DO
      WaitUntil ((di_A = 1) OR (di_B = 1) XOR (gi_Type <> 2));
      IF di_A = 1 THEN
        skp_branch := 1;
      ELSEIF di_B = 1 THEN
        skp_branch := 2;
      ENDIF
    ENDWHILE
    TEST skp_branch
    CASE 1:
      WaitTime 1;
    CASE 2:
      WaitTime -1.5;
    DEFAULT:
      WaitTime 2;
    ENDTEST
    skp_loop1 := TRUE;
    WHILE skp_loop1 DO
      WaitTime 1;
      IF di_Done = 1 THEN
        skp_loop1 := FALSE;
      ENDIF
      IF skp_loop1 THEN
        WaitTime 1;
      ENDIF
    ENDWHILE
    WHILE TRUE DO
      WaitTime 1;
    ENDWHILE
  ENDPROC


  PROC Grip(num value)
    SetDO do_Gripper, value;
  ENDPROC
ENDMODULE
"#;

/// Writes `text` to a temporary `.mod` file and checks it.
fn check(text: &str) -> Result<(), String> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("Cell.mod");
    std::fs::write(&path, text).unwrap();
    rapidcheck(&path)
}

/// `GOOD` with `old` (which must occur) replaced once by `new`.
fn variant(old: &str, new: &str) -> String {
    assert!(GOOD.contains(old), "{old:?} is not in the good module");
    GOOD.replacen(old, new, 1)
}

fn available() -> bool {
    match rapidchecker_missing() {
        None => true,
        Some(why) => {
            common::skip(&why);
            false
        }
    }
}

#[test]
fn accepts_the_emitters_shape() {
    if !available() {
        return;
    }
    let cases: Vec<(&str, String)> = vec![
        ("the module", GOOD.to_string()),
        ("CRLF line endings", GOOD.replace('\n', "\r\n")),
        (
            "a module-level declaration and comment",
            variant(
                "  PROC main()",
                "  CONST num skp_k := 3;\n  ! routines\n  PROC main()",
            ),
        ),
        (
            "a comment at column 1 inside a routine",
            variant("    ! step 1", "! step 1"),
        ),
        (
            "an empty routine",
            variant("    SetDO do_Gripper, value;\n", ""),
        ),
    ];
    for (what, text) in cases {
        if let Err(e) = check(&text) {
            panic!("rapidchecker rejects {what}:\n{e}\n--- module ---\n{text}");
        }
    }
}

#[test]
fn rejects_what_the_emitter_must_not_write() {
    if !available() {
        return;
    }
    // (what, module, a fragment of the complaint)
    let cases: Vec<(&str, String, &str)> = vec![
        (
            "4-space indentation",
            variant("    SetDO do_Gripper, 1;", "      SetDO do_Gripper, 1;"),
            "Bad indentation",
        ),
        (
            "CASE indented under TEST",
            variant(
                "    CASE 1:\n      WaitTime 1;",
                "      CASE 1:\n        WaitTime 1;",
            ),
            "Bad indentation",
        ),
        (
            "a lower-case keyword",
            variant(") AND (", ") and ("),
            "Expected ';'",
        ),
        (
            "a trailing space",
            variant("    SetDO do_Gripper, 1;", "    SetDO do_Gripper, 1; "),
            "Line ends with space",
        ),
        (
            "no line break at the end",
            GOOD.trim_end().to_string(),
            "Line does not end with a new line character",
        ),
        (
            "three blank lines",
            variant("    WaitTime 0.5;\n", "    WaitTime 0.5;\n\n\n\n"),
            "Too many empty lines",
        ),
        (
            "two values in one CASE",
            variant("    CASE 1:", "    CASE 1, 3:"),
            "Expected ':'",
        ),
        (
            "a label",
            variant(
                "    ENDWHILE\n  ENDPROC",
                "    ENDWHILE\n    skp_end1:\n  ENDPROC",
            ),
            "found ':'",
        ),
        (
            "a declaration after a statement",
            variant(
                "    WaitTime 0.5;",
                "    WaitTime 0.5;\n    VAR num skp_late := 0;",
            ),
            "Bad indentation",
        ),
        (
            "a procedure call whose first argument starts with '('",
            variant(
                "WaitUntil ((di_A = 1) OR (di_B = 1) XOR (gi_Type <> 2));",
                "WaitUntil (di_A = 1) OR (di_B = 1);",
            ),
            "found 'OR'",
        ),
        (
            "a doubled quote in a string",
            variant("    WaitTime 0.5;", "    TPWrite \"say \"\"hi\"\"\";"),
            "Expected ';'",
        ),
        (
            "text before MODULE",
            format!("x\n{GOOD}"),
            "Expected RapidKeyword 'MODULE'",
        ),
    ];
    for (what, text, complaint) in cases {
        match check(&text) {
            Ok(()) => panic!("rapidchecker accepts {what}:\n{text}"),
            Err(e) => assert!(
                e.contains(complaint),
                "rapidchecker rejects {what}, but not with {complaint:?}:\n{e}"
            ),
        }
    }
}

/// What the emitter writes passes the checker through the binary: the ABB cell, and the same
/// cell with an SFC without a file header (the header comment line is then empty; RAPID lines
/// keep no trailing space).
#[test]
fn the_emitters_modules_pass() {
    if let Some(why) = rapidchecker_missing() {
        common::skip(&why);
        return;
    }
    let base = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/base/abb");
    let dir = tempfile::tempdir().unwrap();
    for e in std::fs::read_dir(&base).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), dir.path().join(e.file_name())).unwrap();
    }
    let sfc = dir.path().join("sfc.xml");
    let text = std::fs::read_to_string(&sfc).unwrap();
    let start = text.find("<fileHeader").unwrap();
    let end = start + text[start..].find("/>").unwrap() + 2;
    let headerless = format!("{}<fileHeader/>{}", &text[..start], &text[end..]);
    for (what, sfc_text) in [("as is", text.clone()), ("without a header", headerless)] {
        std::fs::write(&sfc, &sfc_text).unwrap();
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
            .args(["--lf", "Cell.aml", "Palletize"])
            .current_dir(dir.path())
            .output()
            .unwrap();
        assert_eq!(
            o.status.code(),
            Some(0),
            "{what}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let module = dir.path().join("Palletize.mod");
        let m = std::fs::read_to_string(&module).unwrap();
        assert!(
            !m.lines().any(|l| l.ends_with(' ')),
            "{what}: a trailing space:\n{m}"
        );
        if let Err(e) = rapidcheck(&module) {
            panic!("{what}: rapidchecker: {e}\n{m}");
        }
    }
}
