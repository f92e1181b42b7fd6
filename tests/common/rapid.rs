//! The RAPID syntax check: `rapidchecker` (PyPI), which docs/LANGUAGES.md says every generated RAPID module
//! passes. `.ci/run` installs the pinned version into a venv (see [`venv_python`]).
//!
//! rapidchecker installs no command of its own: it is run as `python -m rapidchecker FILE…`. It
//! prints each file with problems, then one `line:col message` per problem (only the first
//! grammar error of a file, plus every whitespace error), and exits 1; with none it prints
//! `No RAPID format errors found!` and exits 0. Some rejections (not starting with `MODULE`,
//! text after `ENDMODULE`, a byte sequence that is not UTF-8, an expression nested too deeply)
//! are a Python traceback on stderr, also with exit status 1. It reads `rapidchecker.toml` from
//! its working directory, so it is run in an empty one: the defaults are what we check against.
//! It takes about 5 ms per line: check small modules, not a 100k-step program.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The version `.ci/run` installs and the one whose rules the RAPID emitter was checked against.
pub const RAPIDCHECKER_VERSION: &str = "0.1.5";

/// The venv `.ci/run` makes: `${XDG_CACHE_HOME:-$HOME/.cache}/skillpost/rapidchecker-<version>`.
pub fn venv_python() -> Option<PathBuf> {
    let cache = match std::env::var_os("XDG_CACHE_HOME").filter(|v| !v.is_empty()) {
        Some(c) => PathBuf::from(c),
        None => PathBuf::from(std::env::var_os("HOME")?).join(".cache"),
    };
    Some(
        cache
            .join("skillpost")
            .join(format!("rapidchecker-{RAPIDCHECKER_VERSION}"))
            .join("bin/python"),
    )
}

/// The Python that has rapidchecker [`RAPIDCHECKER_VERSION`]: `$SKILLPOST_RAPIDCHECKER_PYTHON`,
/// else the venv of `.ci/run` ([`venv_python`]), else `python3` on `PATH`. `Err` says what was
/// found instead.
fn python() -> &'static Result<PathBuf, String> {
    static PYTHON: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    PYTHON.get_or_init(|| {
        let mut candidates: Vec<PathBuf> = Vec::new();
        if let Some(p) = std::env::var_os("SKILLPOST_RAPIDCHECKER_PYTHON").filter(|p| !p.is_empty())
        {
            candidates.push(p.into());
        }
        candidates.extend(venv_python());
        candidates.push("python3".into());
        let mut seen = Vec::new();
        for py in candidates {
            let out = Command::new(&py)
                .args([
                    "-c",
                    "import importlib.metadata as m, rapidchecker.cli; print(m.version('rapidchecker'))",
                ])
                .env("PYTHONUTF8", "1")
                .output();
            match out {
                Ok(o) if o.status.success() => {
                    let v = String::from_utf8_lossy(&o.stdout).trim().to_string();
                    if v == RAPIDCHECKER_VERSION {
                        return Ok(py);
                    }
                    seen.push(format!("{}: rapidchecker {v}", py.display()));
                }
                Ok(_) => seen.push(format!("{}: no rapidchecker", py.display())),
                Err(e) => seen.push(format!("{}: {e}", py.display())),
            }
        }
        Err(format!(
            "no rapidchecker {RAPIDCHECKER_VERSION} (.ci/run installs it; or set \
             SKILLPOST_RAPIDCHECKER_PYTHON to a python that has it): {}",
            seen.join("; ")
        ))
    })
}

/// The Python to run `-m rapidchecker` with (for a batch of files), or why there is none.
pub fn rapidchecker_python() -> Result<PathBuf, String> {
    python().clone()
}

/// Whether rapidchecker [`RAPIDCHECKER_VERSION`] can be run here.
pub fn rapidchecker_available() -> bool {
    python().is_ok()
}

/// Why rapidchecker cannot be run here (for `common::skip`), `None` when it can.
pub fn rapidchecker_missing() -> Option<String> {
    python().as_ref().err().cloned()
}

/// Runs rapidchecker on the RAPID module `path` with its default rules. `Err` holds its
/// complaints (`line:col message` lines, or a traceback's last line), or why it could not run.
pub fn rapidcheck(path: &Path) -> Result<(), String> {
    let py = python().as_ref().map_err(Clone::clone)?;
    let path = std::path::absolute(path).map_err(|e| format!("{}: {e}", path.display()))?;
    // An empty working directory: a rapidchecker.toml there would change the rules.
    let cwd = tempfile::tempdir().map_err(|e| e.to_string())?;
    let out = Command::new(py)
        .arg("-m")
        .arg("rapidchecker")
        .arg(&path)
        .current_dir(cwd.path())
        // Its output goes through `rich`, which wraps at 80 columns when not on a terminal.
        .env("COLUMNS", "100000")
        .env("NO_COLOR", "1")
        .env("TERM", "dumb")
        .env("PYTHONUTF8", "1")
        .output()
        .map_err(|e| format!("cannot run {} -m rapidchecker: {e}", py.display()))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    if out.status.success() && stderr.trim().is_empty() {
        return Ok(());
    }
    let shown = path.display().to_string();
    let mut complaints: Vec<String> = stdout
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && *l != shown)
        .map(str::to_string)
        .collect();
    // A traceback: its last line names the exception.
    if let Some(last) = stderr.lines().rev().find(|l| !l.trim().is_empty()) {
        complaints.push(last.trim().to_string());
    }
    if complaints.is_empty() {
        complaints.push(format!("rapidchecker: {}", out.status));
    }
    Err(complaints.join("\n"))
}
