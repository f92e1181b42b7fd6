//! Error fixtures: every folder in `fixtures/err/` is a small project (a copy of the original
//! sample, changed minimally) that the compiler must reject with the diagnostics its
//! `expect.toml` lists, writing nothing.
//!
//! `expect.toml`:
//!
//! ```toml
//! # What the case breaks (one line, for the reader).
//! base = "flow"                 # optional: fixtures/base/<base>/ first (a list: each in order),
//!                                # the case's files over it
//! program = "output"             # the PROGRAM argument (default "output")
//! blackboard = "Blackboard.aml"  # default: the only *.aml in the folder
//! template = "bad.toml"          # passed as `--template` (optional)
//! exact = true                   # the set of error codes reported equals the listed ones
//!
//! [[error]]
//! code = "E305"
//! file = "sfc.xml"   # relative to the case folder, compared as a path suffix;
//!                    # omitted: the diagnostic has no file
//! line = 31          # 1-based; omitted: the diagnostic has no line
//! # optional: column = 12, element = "localId 7", message_contains = "...",
//! # note_contains = "..."
//! ```
//!
//! Each case runs the built binary with `--format json` on a fresh copy of the folder and must
//! exit with status 1, report every listed error, and leave every file byte for byte as it was
//! (no `.src`/`.dat`, no write-back). All failures of all cases are collected and reported at
//! once. `fixtures/err-pending/` holds cases that fail because of known compiler bugs; they are
//! not run here.

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use serde::Deserialize;
use skillpost::diag::Code;

/// E-codes no fixture needs to cover, each with the reason. Keep this list as short as possible.
const UNCOVERED: &[(&str, &str)] = &[(
    "E604",
    "a write failure, not an input error: tests/cli.rs (exit 2) and the daemon tests cover it",
)];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Expect {
    base: Option<common::Bases>,
    #[serde(default = "default_program")]
    program: String,
    blackboard: Option<String>,
    template: Option<String>,
    #[serde(default)]
    exact: bool,
    #[serde(default)]
    error: Vec<ExpectedError>,
}

fn default_program() -> String {
    "output".to_owned()
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ExpectedError {
    code: String,
    file: Option<String>,
    line: Option<usize>,
    column: Option<usize>,
    element: Option<String>,
    message_contains: Option<String>,
    /// Text one of the diagnostic's notes must contain.
    note_contains: Option<String>,
}

/// One diagnostic as `--format json` prints it.
#[derive(Debug, Deserialize)]
struct Reported {
    severity: String,
    code: String,
    message: String,
    file: Option<String>,
    line: Option<usize>,
    column: Option<usize>,
    element: Option<String>,
    #[serde(default)]
    notes: Vec<String>,
}

impl Reported {
    fn short(&self) -> String {
        format!(
            "{} {} {}:{}:{} [{}] {}",
            self.severity,
            self.code,
            self.file.as_deref().unwrap_or("-"),
            opt(self.line),
            opt(self.column),
            self.element.as_deref().unwrap_or("-"),
            self.message
        )
    }
}

fn opt(n: Option<usize>) -> String {
    n.map_or_else(|| "-".to_owned(), |n| n.to_string())
}

impl ExpectedError {
    fn matches(&self, r: &Reported) -> bool {
        let file_ok = match (&self.file, &r.file) {
            (Some(want), Some(got)) => Path::new(got).ends_with(want),
            (None, None) => true,
            _ => false,
        };
        r.severity == "error"
            && r.code == self.code
            && file_ok
            && r.line == self.line
            && self.column.is_none_or(|c| r.column == Some(c))
            && self
                .element
                .as_ref()
                .is_none_or(|e| r.element.as_ref() == Some(e))
            && self
                .message_contains
                .as_ref()
                .is_none_or(|m| r.message.contains(m.as_str()))
            && self
                .note_contains
                .as_ref()
                .is_none_or(|m| r.notes.iter().any(|n| n.contains(m.as_str())))
    }

    fn describe(&self) -> String {
        let mut s = format!(
            "{} at {}:{}",
            self.code,
            self.file.as_deref().unwrap_or("-"),
            opt(self.line)
        );
        if let Some(c) = self.column {
            s.push_str(&format!(":{c}"));
        }
        if let Some(e) = &self.element {
            s.push_str(&format!(" [{e}]"));
        }
        if let Some(m) = &self.message_contains {
            s.push_str(&format!(" with message containing {m:?}"));
        }
        if let Some(m) = &self.note_contains {
            s.push_str(&format!(" with a note containing {m:?}"));
        }
        s
    }
}

fn fixtures_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/err")
}

/// The case folders, sorted by name.
fn cases() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(fixtures_dir())
        .expect("fixtures/err exists")
        .map(|e| e.expect("readable fixtures/err").path())
        .filter(|p| p.is_dir())
        .collect();
    v.sort();
    v
}

fn read_expect(case: &Path) -> Result<Expect, String> {
    let path = case.join("expect.toml");
    let text = std::fs::read_to_string(&path).map_err(|e| format!("expect.toml: {e}"))?;
    toml::from_str(&text).map_err(|e| format!("expect.toml: {e}"))
}

/// Every file under `dir` (relative path → bytes), `expect.toml` at the top excluded.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<PathBuf, Vec<u8>>) {
        for e in std::fs::read_dir(dir).expect("readable folder") {
            let p = e.expect("readable entry").path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                let rel = p.strip_prefix(root).expect("under root").to_owned();
                if rel != Path::new("expect.toml") {
                    out.insert(rel, std::fs::read(&p).expect("readable file"));
                }
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn copy_into(files: &BTreeMap<PathBuf, Vec<u8>>, dir: &Path) {
    for (rel, bytes) in files {
        let p = dir.join(rel);
        if let Some(parent) = p.parent() {
            std::fs::create_dir_all(parent).expect("create folder");
        }
        std::fs::write(&p, bytes).expect("write fixture copy");
    }
}

/// Runs one case; returns its problems (empty when it passes).
fn run_case(case: &Path) -> Vec<String> {
    let mut problems = Vec::new();
    let expect = match read_expect(case) {
        Ok(e) => e,
        Err(e) => return vec![e],
    };
    if expect.error.is_empty() {
        problems.push("expect.toml lists no [[error]]".to_owned());
    }
    let known: BTreeSet<&str> = Code::ALL.iter().map(|c| c.as_str()).collect();
    for e in &expect.error {
        if !e.code.starts_with('E') || !known.contains(e.code.as_str()) {
            problems.push(format!("expect.toml: `{}` is not an error code", e.code));
        }
    }

    let mut files: BTreeMap<PathBuf, Vec<u8>> = Default::default();
    for b in expect.base.iter().flat_map(common::Bases::list) {
        files.extend(snapshot(
            &Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("fixtures/base")
                .join(b),
        ));
    }
    files.extend(snapshot(case));
    let blackboard = match &expect.blackboard {
        Some(b) => b.clone(),
        None => {
            let amls: Vec<&PathBuf> = files
                .keys()
                .filter(|p| p.parent() == Some(Path::new("")))
                .filter(|p| p.extension().is_some_and(|x| x == "aml"))
                .collect();
            match amls.as_slice() {
                [one] => one.to_string_lossy().into_owned(),
                _ => {
                    problems.push(format!(
                        "expect.toml names no blackboard and the folder holds {} *.aml files",
                        amls.len()
                    ));
                    return problems;
                }
            }
        }
    };

    let tmp = tempfile::tempdir().expect("temporary folder");
    copy_into(&files, tmp.path());
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_skillpost"));
    cmd.current_dir(tmp.path()).args(["--format", "json"]);
    if let Some(t) = &expect.template {
        cmd.arg("--template").arg(tmp.path().join(t));
    }
    cmd.arg(tmp.path().join(&blackboard)).arg(&expect.program);
    let out = match cmd.output() {
        Ok(o) => o,
        Err(e) => return vec![format!("cannot run skillpost: {e}")],
    };

    let stdout = String::from_utf8_lossy(&out.stdout);
    let mut reported = Vec::new();
    for line in stdout.lines().filter(|l| !l.trim().is_empty()) {
        match serde_json::from_str::<Reported>(line) {
            Ok(r) => reported.push(r),
            Err(e) => problems.push(format!("stdout line is not a diagnostic ({e}): {line}")),
        }
    }

    if out.status.code() != Some(1) {
        problems.push(format!(
            "exit status {:?}, expected 1; stderr: {}",
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    for e in &expect.error {
        if !reported.iter().any(|r| e.matches(r)) {
            problems.push(format!("missing {}", e.describe()));
        }
    }
    if expect.exact {
        let got: BTreeSet<&str> = reported
            .iter()
            .filter(|r| r.severity == "error")
            .map(|r| r.code.as_str())
            .collect();
        let want: BTreeSet<&str> = expect.error.iter().map(|e| e.code.as_str()).collect();
        if got != want {
            problems.push(format!(
                "exact: error codes reported {got:?}, expected {want:?}"
            ));
        }
    }

    // Nothing written: the folder holds exactly the files it was given, byte for byte.
    let after = snapshot(tmp.path());
    for (rel, bytes) in &after {
        match files.get(rel) {
            None => problems.push(format!("created {}", rel.display())),
            Some(b) if b != bytes => problems.push(format!("changed {}", rel.display())),
            Some(_) => {}
        }
    }
    for rel in files.keys().filter(|rel| !after.contains_key(*rel)) {
        problems.push(format!("removed {}", rel.display()));
    }

    if !problems.is_empty() {
        problems.push("reported:".to_owned());
        problems.extend(reported.iter().map(|r| format!("  {}", r.short())));
    }
    problems
}

#[test]
fn error_fixtures() {
    let cases = cases();
    assert!(
        !cases.is_empty(),
        "no cases in {}",
        fixtures_dir().display()
    );
    let mut failures = Vec::new();
    for case in &cases {
        let problems = run_case(case);
        if !problems.is_empty() {
            let name = case.file_name().unwrap_or_default().to_string_lossy();
            failures.push(format!("{name}:\n    {}", problems.join("\n    ")));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} error fixtures failed:\n\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n\n")
    );
}

#[test]
fn every_error_code_has_a_fixture() {
    let mut covered = BTreeSet::new();
    for case in cases() {
        if let Ok(e) = read_expect(&case) {
            covered.extend(e.error.into_iter().map(|e| e.code));
        }
    }
    let allowed: BTreeMap<&str, &str> = UNCOVERED.iter().copied().collect();
    let mut problems = Vec::new();
    for code in Code::ALL.iter().map(|c| c.as_str()) {
        if !code.starts_with('E') {
            continue;
        }
        match (covered.contains(code), allowed.get(code)) {
            (false, None) => problems.push(format!("{code}: no fixture in fixtures/err")),
            (true, Some(_)) => problems.push(format!(
                "{code}: has a fixture now; remove it from UNCOVERED"
            )),
            _ => {}
        }
    }
    for code in allowed.keys() {
        if !Code::ALL.iter().any(|c| c.as_str() == *code) {
            problems.push(format!("{code}: in UNCOVERED but not a diagnostic code"));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn missing_blackboard_is_an_io_failure() {
    let tmp = tempfile::tempdir().expect("temporary folder");
    let out = Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .current_dir(tmp.path())
        .args(["--format", "json"])
        .arg(tmp.path().join("Missing.aml"))
        .arg("output")
        .output()
        .expect("run skillpost");
    assert_eq!(
        out.status.code(),
        Some(2),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let left: Vec<_> = std::fs::read_dir(tmp.path())
        .expect("readable")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert!(left.is_empty(), "files were created: {left:?}");
}
