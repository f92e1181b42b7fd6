//! The daemon and the SFC's control flow (issue 11, "Daemon"): nothing new is watched, but a
//! blackboard edit that declares a signal a condition needs recompiles the project, and the
//! events' diagnostics carry the new codes (E318 for an undeclared signal).

mod inproc;

use std::fs;
use std::path::{Path, PathBuf};

use inproc::*;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The flow fixtures' blackboard with the `Part_OK` signal's declaration taken out, and the
/// whole original text.
fn blackboard_without_part_ok() -> (String, String) {
    let full = fs::read_to_string(repo().join("fixtures/base/flow/Blackboard.aml")).unwrap();
    let start = full
        .find("        <ExternalInterface Name=\"Part_OK\"")
        .expect("the flow base declares Part_OK");
    let end = start
        + full[start..].find("</ExternalInterface>\n").unwrap()
        + "</ExternalInterface>\n".len();
    let mut without = full.clone();
    without.replace_range(start..end, "");
    assert!(!without.contains("Part_OK"));
    (without, full)
}

/// A project from the flow fixtures: the guarded sequence, whose first condition is `Part_OK`.
fn flow_project(dir: &Path, blackboard: &str) {
    fs::create_dir_all(dir).unwrap();
    fs::write(dir.join("Blackboard.aml"), blackboard).unwrap();
    fs::copy(
        repo().join("fixtures/base/flow/kr15-2.irl"),
        dir.join("kr15-2.irl"),
    )
    .unwrap();
    fs::copy(
        repo().join("fixtures/ok/flow-guarded-sequence/sfc.xml"),
        dir.join("sfc.xml"),
    )
    .unwrap();
}

#[test]
fn declaring_a_missing_signal_in_the_blackboard_recompiles() {
    let w = Workspace::new();
    let p = w.ws().join("Cell");
    let (without, full) = blackboard_without_part_ok();
    flow_project(&p, &without);
    let d = InProc::with_dirs(&[&p]);
    let evs = d.wait_for("the first compile", WAIT, |e| {
        is_for(e, "compile-failed", &p) || is_for(e, "compile-succeeded", &p)
    });
    let failed = evs
        .iter()
        .find(|e| is_for(e, "compile-failed", &p))
        .unwrap_or_else(|| panic!("an undeclared signal must fail:\n{}", dump(&evs)));
    let e318 = failed["diagnostics"]
        .as_array()
        .unwrap()
        .iter()
        .find(|x| x["code"] == "E318")
        .unwrap_or_else(|| panic!("E318 in the event: {failed}"));
    assert!(
        e318["message"].as_str().unwrap().contains("Part_OK"),
        "{e318}"
    );
    assert!(
        e318["file"].as_str().unwrap().ends_with("sfc.xml") && e318["line"].as_u64().is_some(),
        "located in the SFC: {e318}"
    );
    assert!(!src_of(&p).exists(), "nothing written on an error");

    // The planner declares the signal: the blackboard changed, so the project compiles, and
    // the program waits for the input the signal names.
    let mark = d.mark();
    fs::write(p.join("Blackboard.aml"), &full).unwrap();
    let evs = d.wait_for("the compile after the declaration", WAIT, |e| {
        is_after(e, "compile-succeeded", &p, mark) || is_after(e, "compile-failed", &p, mark)
    });
    assert!(
        evs.iter()
            .any(|e| is_after(e, "compile-succeeded", &p, mark)),
        "{}",
        dump(&evs)
    );
    let src = read_string(&src_of(&p));
    assert!(src.contains("WAIT FOR $IN[1]"), "{src}");
    d.stop(WAIT);
}
