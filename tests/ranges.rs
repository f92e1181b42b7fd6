//! Issue 38, item 5: values a CAEX `Constraint` on a skill parameter limits are checked when
//! compiling (`E506` at the SFC variable, a note at the constraint), through the binary, on the
//! reference sample with its `Move PTP` `Velocity` (steps set 0.5 and 0.3) constrained.

use std::path::Path;
use std::process::{Command, Output};

/// The reference sample in a temporary folder, `Move PTP`'s `Velocity` with `constraint`
/// (the XML of one `Constraint` element) and of type `ty`.
fn project(constraint: &str, ty: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ok/reference-sample");
    for f in ["sfc.xml", "kr15-2.irl"] {
        std::fs::copy(sample.join(f), dir.path().join(f)).unwrap();
    }
    let bb = std::fs::read_to_string(sample.join("Blackboard.aml")).unwrap();
    let old = "<Attribute Name=\"Velocity\" AttributeDataType=\"xs:double\" Unit=\"m/s\">\n              <Description>TCP movement speed</Description>\n              <Value>Velocity</Value>\n";
    assert_eq!(bb.matches(old).count(), 1);
    let new = format!(
        "<Attribute Name=\"Velocity\" AttributeDataType=\"{ty}\" Unit=\"m/s\">\n              <Description>TCP movement speed</Description>\n              <Value>Velocity</Value>\n              {constraint}\n"
    );
    std::fs::write(dir.path().join("Blackboard.aml"), bb.replace(old, &new)).unwrap();
    dir
}

fn run(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(args)
        .args(["Blackboard.aml", "P"])
        .current_dir(dir)
        .output()
        .unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn ordinal(min: &str, max: &str) -> String {
    format!(
        "<Constraint Name=\"speed\"><OrdinalScaledType><RequiredMaxValue>{max}</RequiredMaxValue><RequiredMinValue>{min}</RequiredMinValue></OrdinalScaledType></Constraint>"
    )
}

#[test]
fn values_within_the_constraint_compile_as_before() {
    let p = project(&ordinal("0.3", "0.5"), "xs:double");
    let o = run(p.path(), &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    assert!(p.path().join("P.src").exists());
    // The blackboard is valid CAEX with the constraint (the schema, when xmllint is here).
    let xsd =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/schemas/CAEX_ClassModel_V2.15.xsd");
    if xsd.exists()
        && let Ok(v) = Command::new("xmllint")
            .args(["--noout", "--schema"])
            .arg(&xsd)
            .arg(p.path().join("Blackboard.aml"))
            .output()
    {
        assert!(v.status.success(), "{}", text(&v.stderr));
    }
}

#[test]
fn a_value_above_the_maximum_is_an_error_at_the_value_and_nothing_is_written() {
    let p = project(&ordinal("0", "0.4"), "xs:double");
    let o = run(p.path(), &[]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("error[E506]"), "{err}");
    assert!(
        err.contains("`Velocity` = `0.5` for parameter `Velocity`: the blackboard's constraint `speed` allows no value above 0.4 (from 0 to 0.4)"),
        "{err}"
    );
    assert!(
        err.contains("sfc.xml:43:"),
        "located at the step's value: {err}"
    );
    assert!(err.contains("the constraint"), "{err}");
    assert!(!p.path().join("P.src").exists());
}

#[test]
fn a_value_that_is_none_of_the_required_values_names_the_nearest() {
    let c = "<Constraint Name=\"speeds\"><NominalScaledType><RequiredValue>0.5</RequiredValue><RequiredValue>0.35</RequiredValue></NominalScaledType></Constraint>";
    let p = project(c, "xs:double");
    let o = run(p.path(), &["--format", "json"]);
    let lines: Vec<serde_json::Value> = text(&o.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect();
    let e506: Vec<&serde_json::Value> = lines.iter().filter(|d| d["code"] == "E506").collect();
    assert_eq!(e506.len(), 1, "{lines:?}");
    let m = e506[0]["message"].as_str().unwrap();
    assert!(
        m.contains("allows only 0.5, 0.35; the nearest is `0.35`"),
        "{m}"
    );
    assert_eq!(e506[0]["line"], 77, "{}", e506[0]);
    // Numbers compare as numbers: 0.50 is 0.5.
    let c = "<Constraint Name=\"speeds\"><NominalScaledType><RequiredValue>0.50</RequiredValue><RequiredValue>0.30</RequiredValue></NominalScaledType></Constraint>";
    let p = project(c, "xs:double");
    let o = run(p.path(), &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
}

#[test]
fn a_constraint_that_cannot_be_checked_is_a_warning_and_the_compile_goes_on() {
    for (c, says) in [
        (ordinal("slow", "2"), "its RequiredMinValue `slow` is not a number"),
        (ordinal("2", "1"), "its RequiredMinValue 2 is above its RequiredMaxValue 1"),
        (
            "<Constraint Name=\"speed\"><UnknownType><Requirements>fast enough</Requirements></UnknownType></Constraint>".to_owned(),
            "it names no value",
        ),
    ] {
        let p = project(&c, "xs:double");
        let o = run(p.path(), &["--warn"]);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{err}");
        assert!(err.contains("warning[W209]") && err.contains(says), "{says}: {err}");
    }
}
