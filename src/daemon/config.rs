//! The daemon's configuration (SPEC.md section 7): a TOML file and the command line.
//! (being written: parsing, validation with line/column, discovery)

use std::path::PathBuf;

/// The whole configuration, paths absolute.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Config {
    /// Where the configuration was read from (for `SIGHUP`).
    pub file: Option<PathBuf>,
    /// Append the event stream to this file instead of stdout.
    pub events: Option<PathBuf>,
    /// The quiet period after the last change, in milliseconds (default 100).
    pub settle_ms: Option<u64>,
    /// Allow `refURI`s (and symlinks) that leave the project folder.
    pub allow_outside: bool,
    /// Explicit projects.
    pub projects: Vec<ProjectSpec>,
    /// Folders whose direct subfolders holding a blackboard are projects.
    pub roots: Vec<PathBuf>,
}

/// A `[[project]]` entry (or a folder named on the command line).
#[derive(Debug, Clone, PartialEq)]
pub struct ProjectSpec {
    /// The project folder.
    pub path: PathBuf,
    /// The blackboard, relative to the folder (default: the single `*.aml` in it).
    pub blackboard: Option<PathBuf>,
    /// The program name (default: the blackboard's file stem).
    pub program: Option<String>,
}

// TEMPORARY minimal versions, replaced by the full module (same signatures).
use std::path::Path;

#[derive(Debug, Clone, PartialEq)]
pub struct ConfigError {
    pub file: Option<PathBuf>,
    pub line: Option<usize>,
    pub column: Option<usize>,
    pub message: String,
}

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.message)
    }
}

pub fn load(path: &Path) -> Result<Config, ConfigError> {
    Err(ConfigError {
        file: Some(path.to_owned()),
        line: None,
        column: None,
        message: "configuration files are not supported yet".into(),
    })
}

pub fn discover(root: &Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(root)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_dir())
        .filter(|p| {
            std::fs::read_dir(p)
                .into_iter()
                .flatten()
                .flatten()
                .any(|e| {
                    e.path()
                        .extension()
                        .is_some_and(|x| x.eq_ignore_ascii_case("aml"))
                })
        })
        .collect();
    out.sort();
    out
}

pub fn resolve(spec: &ProjectSpec) -> Result<(PathBuf, String), String> {
    let bb = match &spec.blackboard {
        Some(b) => spec.path.join(b),
        None => {
            let found: Vec<PathBuf> = std::fs::read_dir(&spec.path)
                .map_err(|e| format!("cannot read {}: {e}", spec.path.display()))?
                .flatten()
                .map(|e| e.path())
                .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("aml")))
                .collect();
            match found.as_slice() {
                [one] => one.clone(),
                [] => return Err(format!("no *.aml in {}", spec.path.display())),
                _ => return Err(format!("several *.aml in {}", spec.path.display())),
            }
        }
    };
    let program = spec.program.clone().unwrap_or_else(|| {
        bb.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    });
    Ok((bb, program))
}

pub fn merge(
    file: Option<Config>,
    dirs: &[PathBuf],
    events: Option<PathBuf>,
    settle_ms: Option<u64>,
) -> Config {
    let mut c = file.unwrap_or_default();
    let cwd = std::env::current_dir().unwrap_or_default();
    for d in dirs {
        c.projects.push(ProjectSpec {
            path: cwd.join(d),
            blackboard: None,
            program: None,
        });
    }
    if events.is_some() {
        c.events = events.map(|e| cwd.join(e));
    }
    if settle_ms.is_some() {
        c.settle_ms = settle_ms;
    }
    c
}
