//! The built-in check (`skillpost check`, issue 28) against the external checks the tests use:
//! the KRL grammar (tests/common/krl_check.rs), rapidchecker (PyPI) and the URScript block test
//! (tests/common/urscript.rs). Over every ok fixture's generated programs, through the binary:
//! - every generated program passes both (the compile itself already refuses one that fails
//!   the built-in check: E606);
//! - every program broken by deleting one block line (an `END…`, `end`, or an opening line) fails
//!   both: the built-in check never lets through what the external checker refuses, and never
//!   refuses what it takes.

mod common;
#[path = "common/krl_check.rs"]
mod krl_check;

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

#[derive(serde::Deserialize)]
struct Case {
    base: Option<common::Bases>,
    program: String,
    blackboard: Option<String>,
    #[serde(default)]
    args: Vec<String>,
}

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_skillpost")
}

/// Compiles `fixtures/ok/<name>` in `dir`; the generated program files.
fn compile(name: &str, dir: &Path) -> Vec<PathBuf> {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let case_dir = repo.join("fixtures/ok").join(name);
    let case: Case =
        toml::from_str(&fs::read_to_string(case_dir.join("case.toml")).unwrap()).unwrap();
    fn copy(from: &Path, to: &Path) {
        for e in fs::read_dir(from).unwrap() {
            let e = e.unwrap();
            let t = e.file_type().unwrap();
            if t.is_file() {
                fs::copy(e.path(), to.join(e.file_name())).unwrap();
            } else if t.is_dir() {
                fs::create_dir_all(to.join(e.file_name())).unwrap();
                copy(&e.path(), &to.join(e.file_name()));
            }
        }
    }
    for b in case.base.iter().flat_map(common::Bases::list) {
        copy(&repo.join("fixtures/base").join(b), dir);
    }
    copy(&case_dir, dir);
    let before: Vec<PathBuf> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    let bb = match case.blackboard {
        Some(b) => dir.join(b),
        None => before
            .iter()
            .find(|p| p.extension().is_some_and(|x| x == "aml"))
            .unwrap()
            .clone(),
    };
    let o = Command::new(bin())
        .args(&case.args)
        .arg(&bb)
        .arg(&case.program)
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let mut out: Vec<PathBuf> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| !before.contains(p))
        .filter(|p| {
            p.extension()
                .is_some_and(|x| ["src", "dat", "mod", "script"].contains(&&*x.to_string_lossy()))
        })
        .collect();
    out.sort();
    out
}

/// `skillpost check FILE`: passes?
fn ours(path: &Path) -> bool {
    let o = Command::new(bin()).arg("check").arg(path).output().unwrap();
    assert!(
        matches!(o.status.code(), Some(0 | 1)),
        "{}: {}",
        path.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    o.status.success()
}

/// The external checker of the file's language: `None` where it cannot run here.
fn theirs(path: &Path, text: &str, dat: Option<&str>) -> Option<bool> {
    let ext = path.extension()?.to_string_lossy().into_owned();
    let lf = !text.contains("\r\n");
    match ext.as_str() {
        "src" => {
            let program = path.file_stem()?.to_string_lossy().into_owned();
            Some(krl_check::check_krl(text, dat?, &program, lf).is_ok())
        }
        "mod" => {
            if !common::rapid::rapidchecker_available() {
                return None;
            }
            Some(common::rapid::rapidcheck(path).is_ok())
        }
        "script" => Some(common::urscript::check_urscript(text).is_ok()),
        _ => None,
    }
}

/// The lines that open or close a block, by language (the mutation deletes one of them).
fn is_block_line(ext: &str, line: &str) -> bool {
    let t = line.trim();
    let w = t
        .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .next()
        .unwrap_or("");
    match ext {
        "src" => matches!(
            w.to_ascii_uppercase().as_str(),
            "IF" | "ENDIF" | "LOOP" | "ENDLOOP" | "WHILE" | "ENDWHILE" | "END" | "DEF"
        ),
        "mod" => {
            let u = w.to_ascii_uppercase();
            matches!(
                u.as_str(),
                "ENDIF" | "ENDWHILE" | "ENDPROC" | "WHILE" | "PROC"
            ) || (u == "IF" && t.to_ascii_uppercase().ends_with("THEN"))
        }
        "script" => matches!(w, "if" | "while" | "end" | "def" | "thread") && t != "end()",
        _ => false,
    }
}

#[test]
fn the_built_in_check_agrees_with_the_external_checkers() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut names: Vec<String> = fs::read_dir(repo.join("fixtures/ok"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    let (mut programs, mut mutants, mut external) = (0, 0, 0);
    let mut disagreements = Vec::new();
    let mut rapid_missing = false;
    for name in &names {
        let tmp = tempfile::tempdir().unwrap();
        let files = compile(name, tmp.path());
        for f in &files {
            let ext = f.extension().unwrap().to_string_lossy().into_owned();
            let text = fs::read_to_string(f).unwrap();
            let dat_path = f.with_extension("dat");
            let dat = (ext == "src").then(|| fs::read_to_string(&dat_path).unwrap_or_default());
            programs += 1;
            assert!(
                ours(f),
                "{name}: the generated {} fails `skillpost check`",
                f.display()
            );
            match theirs(f, &text, dat.as_deref()) {
                Some(ok) => assert!(ok, "{name}: the external check refuses {}", f.display()),
                None => rapid_missing |= ext == "mod",
            }
            if ext == "dat" {
                continue;
            }
            // Mutants: each block line deleted in turn (at most 12 per file; RAPID's checker is
            // slow).
            let lines: Vec<&str> = text.split_inclusive('\n').collect();
            let candidates: Vec<usize> = (0..lines.len())
                .filter(|&i| is_block_line(&ext, lines[i]))
                .collect();
            let step = (candidates.len() / 12).max(1);
            for &i in candidates.iter().step_by(step) {
                let mutant: String = lines
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| *k != i)
                    .map(|(_, l)| *l)
                    .collect();
                let path = tmp.path().join(format!("mutant.{ext}"));
                fs::write(&path, &mutant).unwrap();
                mutants += 1;
                let o = ours(&path);
                let t = theirs(&path, &mutant, dat.as_deref());
                if let Some(t) = t {
                    external += 1;
                    if o != t {
                        disagreements.push(format!(
                            "{name} {}: line {} (`{}`) deleted: skillpost check {}, the external \
                             check {}",
                            f.display(),
                            i + 1,
                            lines[i].trim(),
                            if o { "passes" } else { "refuses" },
                            if t { "passes" } else { "refuses" }
                        ));
                    }
                }
                // Whatever the external checker says: a deleted block line is never fine.
                assert!(
                    !o,
                    "{name}: `skillpost check` passes {} with line {} (`{}`) deleted",
                    f.display(),
                    i + 1,
                    lines[i].trim()
                );
            }
        }
    }
    if rapid_missing {
        common::skip("rapidchecker is not installed: the RAPID agreement was not checked");
    }
    eprintln!(
        "{programs} generated programs pass both checks; {mutants} mutants refused by \
         `skillpost check`, {external} of them also run through the external checker"
    );
    assert!(programs > 40, "{programs}");
    assert!(
        disagreements.is_empty(),
        "{} disagreements:\n{}",
        disagreements.len(),
        disagreements.join("\n")
    );
}

#[test]
fn skillpost_check_says_where_and_exits_by_what_it_found() {
    let tmp = tempfile::tempdir().unwrap();
    let good = tmp.path().join("good.src");
    let bad = tmp.path().join("bad.mod");
    let odd = tmp.path().join("notes.txt");
    fs::write(
        &good,
        "DEF good( )\r\n  LOOP\r\n    EXIT\r\n  ENDLOOP\r\nEND\r\n",
    )
    .unwrap();
    fs::write(
        &bad,
        "MODULE bad\n  PROC main()\n    IF a THEN\n      b;\n  ENDPROC\nENDMODULE\n",
    )
    .unwrap();
    fs::write(&odd, "if a:\n").unwrap();
    let run = |args: &[&Path], extra: &[&str]| {
        let o = Command::new(bin())
            .arg("check")
            .args(extra)
            .args(args)
            .output()
            .unwrap();
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stdout).into_owned(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (code, out, _) = run(&[&good], &[]);
    assert_eq!(code, Some(0), "{out}");
    assert_eq!(out, "1 file checked: no problems\n");
    let (code, out, _) = run(&[&good, &bad], &[]);
    assert_eq!(code, Some(1), "{out}");
    assert_eq!(
        out,
        format!(
            "{}:5:3: error: `ENDPROC` where `IF` is still open (opened at 3:5)\n\
             1 problem in 1 of 2 files\n",
            bad.display()
        )
    );
    // A file whose extension names no language: exit 2, unless --language says it.
    let (code, _, err) = run(&[&odd], &[]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--language"), "{err}");
    let (code, out, _) = run(&[&odd], &["--language", "urscript"]);
    assert_eq!(code, Some(1));
    assert!(out.contains(":1:1: error: `if` is never closed"), "{out}");
    let (code, _, err) = run(&[&tmp.path().join("missing.src")], &[]);
    assert_eq!(code, Some(2));
    assert!(err.contains("cannot read"), "{err}");
}

#[test]
fn a_broken_definition_the_program_does_not_use_is_no_error() {
    // The IRL file of fixtures/err/e405_krl_definition_if_without_endif (SetVelCP opens an IF it
    // never closes) with a chart that never sets a velocity: SetVelCP is not written, so the
    // program loads; calls are checked whether used or not.
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let tmp = tempfile::tempdir().unwrap();
    fs::copy(
        repo.join("fixtures/base/flow/Blackboard.aml"),
        tmp.path().join("Blackboard.aml"),
    )
    .unwrap();
    fs::copy(
        repo.join("fixtures/ok/flow-loop-exit/sfc.xml"),
        tmp.path().join("sfc.xml"),
    )
    .unwrap();
    fs::copy(
        repo.join("fixtures/err/e405_krl_definition_if_without_endif/kr15-2.irl"),
        tmp.path().join("kr15-2.irl"),
    )
    .unwrap();
    let o = Command::new(bin())
        .args(["Blackboard.aml", "LoopExit"])
        .current_dir(tmp.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let src = fs::read_to_string(tmp.path().join("LoopExit.src")).unwrap();
    assert!(!src.contains("SetVelCP"));
    assert!(ours(&tmp.path().join("LoopExit.src")));
}
