//! Long programs in parts (docs/LANGUAGES.md, "Long programs: parts"), as a user meets them on
//! the command line: the parts and the main program's calls, the write-back, `-pO`, all files or
//! none, and the parts a later, shorter compile no longer needs.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn run(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

fn stdout(o: &Output) -> String {
    String::from_utf8(o.stdout.clone()).unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8(o.stderr.clone()).unwrap()
}

/// `fixtures/base/<base>` with the input files of `fixtures/ok/<case>` over it.
fn project(base: &str, case: &str) -> tempfile::TempDir {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let t = tempfile::tempdir().unwrap();
    for dir in [root.join("base").join(base), root.join("ok").join(case)] {
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

fn parts(dir: &Path, stem: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            let n = p.file_name().unwrap().to_string_lossy();
            n.starts_with(&format!("{stem}_")) && !n.ends_with(".io.csv")
        })
        .collect();
    v.sort();
    v
}

#[test]
fn a_long_program_is_split_into_parts_that_its_main_program_calls() {
    let p = project("flow", "flow-step-time");
    let o = run(
        &["--warn", "--max-lines", "8", "Blackboard.aml", "StepTime"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let names: Vec<String> = parts(p.path(), "StepTime")
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    let want: Vec<String> = (1..=6)
        .flat_map(|n| [format!("StepTime_{n}.dat"), format!("StepTime_{n}.src")])
        .collect();
    assert_eq!(names, want);
    let main = std::fs::read_to_string(p.path().join("StepTime.src")).unwrap();
    for n in 1..=6 {
        assert!(main.contains(&format!("\r\nStepTime_{n}()\r\n")), "{main}");
    }
    // No step is left in the main program; each part is a sub-program of its own.
    assert!(!main.contains(";FOLD 1 "), "{main}");
    let part = std::fs::read_to_string(p.path().join("StepTime_2.src")).unwrap();
    assert!(part.contains("\r\nDEF StepTime_2()\r\n"), "{part}");
    // The selection is one block, longer than the limit: whole in one part, and said.
    assert!(
        stderr(&o).contains("warning[W310]: part 4 of StepTime"),
        "{}",
        stderr(&o)
    );
    // The write-back names the main program.
    let bb = std::fs::read_to_string(p.path().join("Blackboard.aml")).unwrap();
    assert!(bb.contains("<Value>StepTime.src</Value>"), "{bb}");
    assert!(!bb.contains("StepTime_1"));
    // The same compile again writes nothing.
    let o = run(
        &["--max-lines", "8", "Blackboard.aml", "StepTime"],
        p.path(),
    );
    assert!(!stdout(&o).contains("wrote "), "{}", stdout(&o));
}

#[test]
fn order_listing_says_which_part_holds_which_step() {
    let p = project("flow", "flow-step-time");
    let o = run(
        &["-pO", "--max-lines", "8", "Blackboard.aml", "StepTime"],
        p.path(),
    );
    let out = stdout(&o);
    assert!(
        out.contains("parts of StepTime (StepTime.src calls them in this order):\n  StepTime_1 in StepTime_1.src: steps #1 to #2\n  StepTime_2 in StepTime_2.src: no step\n"),
        "{out}"
    );
    let o = run(
        &[
            "-pO",
            "--format",
            "json",
            "--max-lines",
            "8",
            "Blackboard.aml",
            "StepTime",
        ],
        p.path(),
    );
    let order: serde_json::Value = stdout(&o)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .find(|v| v["listing"] == "order")
        .unwrap();
    let parts = order["parts"].as_array().unwrap();
    assert_eq!(parts.len(), 6);
    assert_eq!(parts[0]["file"], "StepTime_1.src");
    assert_eq!(parts[0]["first_step"], 1);
    // Every step in exactly one part, in order.
    let mut next = 1;
    for part in parts {
        if let Some(first) = part["first_step"].as_u64() {
            assert_eq!(first, next, "{order}");
            next = part["last_step"].as_u64().unwrap() + 1;
        }
    }
    assert_eq!(next - 1, order["steps"].as_u64().unwrap());
}

#[test]
fn a_shorter_compile_removes_only_the_parts_skillpost_wrote() {
    let p = project("flow", "flow-step-time");
    let o = run(
        &["--max-lines", "8", "Blackboard.aml", "StepTime"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // A file of the user's own, named like a later part.
    std::fs::write(
        p.path().join("StepTime_7.src"),
        "DEF StepTime_7( )\r\nEND\r\n",
    )
    .unwrap();
    // Fewer parts: the last ones go, the user's file stays.
    let o = run(
        &["--max-lines", "30", "Blackboard.aml", "StepTime"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = stdout(&o);
    let left: Vec<PathBuf> = parts(p.path(), "StepTime");
    assert!(left.len() < 12 && left.len() >= 4, "{left:?}\n{out}");
    assert!(
        out.contains("removed ")
            && out.contains("StepTime_6.src (a part of the program an earlier compile wrote)"),
        "{out}"
    );
    assert!(p.path().join("StepTime_7.src").exists());
    // Not split any more: no part is left but the user's.
    let o = run(
        &["--max-lines", "0", "Blackboard.aml", "StepTime"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(
        parts(p.path(), "StepTime"),
        vec![p.path().join("StepTime_7.src")]
    );
    let main = std::fs::read_to_string(p.path().join("StepTime.src")).unwrap();
    assert!(
        main.contains(";FOLD 1 ") && !main.contains("StepTime_1()"),
        "{main}"
    );
}

#[test]
fn a_part_that_cannot_be_written_leaves_every_file_as_it_was() {
    let p = project("flow", "flow-step-time");
    let o = run(
        &["--max-lines", "8", "Blackboard.aml", "StepTime"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // A part's file that cannot be written (a folder is in its way).
    let blocked = p.path().join("StepTime_1.dat");
    std::fs::remove_file(&blocked).unwrap();
    std::fs::create_dir(&blocked).unwrap();
    let before: Vec<(PathBuf, Vec<u8>)> = parts(p.path(), "StepTime")
        .into_iter()
        .filter(|f| *f != blocked)
        .chain([p.path().join("StepTime.src"), p.path().join("StepTime.dat")])
        .map(|f| {
            let b = std::fs::read(&f).unwrap();
            (f, b)
        })
        .collect();
    // Fewer, longer parts: every file changes, none is written.
    let o = run(
        &["--max-lines", "30", "Blackboard.aml", "StepTime"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("E604"), "{}", stderr(&o));
    for (f, b) in &before {
        assert_eq!(&std::fs::read(f).unwrap(), b, "{} changed", f.display());
    }
}

#[test]
fn the_limit_is_per_language_and_checked() {
    let p = project("flow", "flow-step-time");
    // A limit for another language leaves the KRL program whole.
    let o = run(
        &[
            "--max-lines",
            "rapid=8",
            "--max-lines",
            "urscript=8",
            "Blackboard.aml",
            "StepTime",
        ],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(parts(p.path(), "StepTime").is_empty());
    let o = run(
        &["--max-lines", "krl=8", "Blackboard.aml", "StepTime"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!parts(p.path(), "StepTime").is_empty());
    for bad in ["many", "cobol=3", "krl=-1"] {
        let o = run(
            &["--max-lines", bad, "Blackboard.aml", "StepTime"],
            p.path(),
        );
        assert_eq!(o.status.code(), Some(2), "{bad}: {}", stderr(&o));
        assert!(stderr(&o).contains("--max-lines"), "{bad}: {}", stderr(&o));
    }
}

#[test]
fn a_rapid_module_is_split_into_modules() {
    let p = project("abb", "abb-irb1200");
    let o = run(&["--max-lines", "12", "Cell.aml", "Palletize"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let main = std::fs::read_to_string(p.path().join("Palletize.mod")).unwrap();
    assert!(main.contains("    Palletize_1_run;"), "{main}");
    let part = std::fs::read_to_string(p.path().join("Palletize_2.mod")).unwrap();
    assert!(part.starts_with("MODULE Palletize_2\r\n"), "{part}");
    assert!(part.contains("  PROC Palletize_2_run("), "{part}");
    // The loop's flag is the part's own variable.
    assert!(part.contains("VAR bool skp_loop1 := TRUE;"), "{part}");
}
