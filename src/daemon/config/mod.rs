//! The daemon's configuration (docs/DAEMON.md): a TOML file and the command line.
//!
//! The file (see `config/skillpost.toml` for a commented example):
//!
//! ```toml
//! events = "/var/log/skillpost/events.jsonl"   # optional
//! settle_ms = 100                              # optional, 1..=60000
//! allow_outside = false                        # optional
//! forget_after_s = 30                          # optional, 1..=86400
//! template = "krl.toml"                       # optional, like --template
//! line_endings = "lf"                          # optional, "crlf" (default) or "lf"
//! on_success = ["/usr/local/bin/deploy", "{src}"]  # optional: the deploy hook (docs/DAEMON.md)
//! deploy_timeout_s = 60                        # optional, 1..=3600
//! max_deploys = 4                              # optional, 1..=64: hooks at once, all projects
//! picture = true                               # optional: <program>.svg, the plan's timeline
//! simulate = 20                                # optional: random runs after each compile, or
//!                                              # a scenario file in the project ("shift.toml")
//! [[project]]
//! path = "cells/Zelle_A"
//! blackboard = "Zelle_A.aml"   # optional
//! program = "Zelle_A"          # optional: a KRL name or a pattern ("P_{folder}")
//! template = "a.toml"          # optional (default: the global one)
//! line_endings = "crlf"        # optional (default: the global one)
//! on_success = ["…"]           # optional (default: the global one); deploy_timeout_s too
//! [[root]]
//! path = "/srv/planning/projects"
//! program = "{folder}"         # optional, default "{blackboard}"; template, line_endings too
//! ```
//!
//! Relative paths in the file are relative to the file's folder; all paths in a [`Config`] are
//! absolute and lexically normalised (`.` and `..` removed, symlinks not resolved). `~` is not
//! expanded (a service has no home directory): a path starting with `~/` is an error. Unknown
//! keys, wrong types, empty paths, `settle_ms` outside [`SETTLE_MS_RANGE`] and two entries naming
//! the same folder are errors located by line and column.
//!
//! # The files
//!
//! - `mod.rs` (here): the settings ([`Config`], [`ProjectSpec`], [`RootSpec`], [`Simulate`]) and
//!   their limits, program names, root discovery and blackboard resolution, the command line
//!   merged over the file.
//! - `parse.rs`: the file read and checked ([`load`], [`parse()`], [`ConfigError`]).
//! - `planners.rs`: what stays out of planners' folders.
//! - `tests.rs`: the unit tests.

use std::ffi::OsStr;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::paths::{absolute, normalize};

mod planners;
pub use planners::{
    hook_from_a_planners_folder, hook_program_problem, hook_programs, own_files_problem,
};

mod parse;
pub use parse::{ConfigError, load, parse};

/// The quiet period when neither the file nor the command line sets one.
pub const DEFAULT_SETTLE_MS: u64 = 100;

/// The allowed values of `max_file_size_mb` / `--max-file-size` (MiB).
pub const MAX_FILE_SIZE_MB_RANGE: std::ops::RangeInclusive<u64> = 1..=4096;

/// The largest configuration file read (1 MiB).
pub const MAX_CONFIG_SIZE: u64 = 1024 * 1024;

/// How long a root's project folder may be gone before the project is forgotten (seconds).
pub const DEFAULT_FORGET_AFTER_S: u64 = 30;

/// The allowed values of `forget_after_s`.
pub const FORGET_AFTER_S_RANGE: RangeInclusive<u64> = 1..=86_400;

/// The allowed values of `settle_ms` / `--settle`.
pub const SETTLE_MS_RANGE: RangeInclusive<u64> = 1..=60_000;

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
    /// The largest input file read, in MiB (default [`crate::load::DEFAULT_MAX_FILE_SIZE`]).
    pub max_file_size_mb: Option<u64>,
    /// A root's project whose folder has been gone this many seconds is forgotten (default
    /// [`DEFAULT_FORGET_AFTER_S`]).
    pub forget_after_s: Option<u64>,
    /// How many deploy hooks run at once, of all projects (`max_deploys`; default
    /// [`super::deploy::DEFAULT_MAX_DEPLOYS`]).
    pub max_deploys: Option<usize>,
    /// The output template of every project that does not name its own (`template`; default:
    /// the built-in one), absolute.
    pub template: Option<PathBuf>,
    /// LF line endings for every project that does not say otherwise (`line_endings = "lf"`;
    /// default CRLF).
    pub lf: bool,
    /// The SFC POU of every project that does not name its own (`pou`, like `--pou`).
    pub pou: Option<String>,
    /// The longest program per language before it is split (`max_lines`, like `--max-lines`).
    pub max_lines: crate::emit::split::Limits,
    /// The deploy hook of every project that does not have its own (`on_success`).
    pub on_success: Option<super::deploy::Hook>,
    /// Every project that does not say otherwise draws its plan (`picture = true`).
    pub picture: bool,
    /// What every project that does not say otherwise simulates after a compile.
    pub simulate: Option<Simulate>,
    /// Explicit projects, with the global `template`/`line_endings` already applied.
    pub projects: Vec<ProjectSpec>,
    /// Folders whose direct subfolders holding a blackboard are projects.
    pub roots: Vec<RootSpec>,
}

/// The longest path the kernel takes in one call (`PATH_MAX`, with its closing NUL).
const PATH_MAX: usize = 4096;

/// An error when `p` is longer than the kernel takes in one call: every operation on it would
/// fail with "file name too long", which looked like a folder that does not exist.
pub fn too_long(p: &Path) -> Result<(), String> {
    use std::os::unix::ffi::OsStrExt as _;
    let n = p.as_os_str().as_bytes().len();
    if n >= PATH_MAX {
        return Err(format!(
            "the path is {n} bytes long; Linux takes paths of at most {} bytes (move the \
             folder higher up, or give it a shorter name)",
            PATH_MAX - 1
        ));
    }
    Ok(())
}

/// A `[[project]]` entry (or a folder named on the command line).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ProjectSpec {
    /// The project folder.
    pub path: PathBuf,
    /// The blackboard, relative to the folder (default: the single `*.aml` in it).
    pub blackboard: Option<PathBuf>,
    /// The program name, or a pattern with `{folder}`/`{blackboard}` (see [`program_name`]);
    /// default `{blackboard}`.
    pub program: Option<String>,
    /// The output template (absolute; default: the built-in one), like `--template`.
    pub template: Option<PathBuf>,
    /// LF line endings instead of CRLF, like `--lf`.
    pub lf: bool,
    /// The SFC POU to use, like `--pou`.
    pub pou: Option<String>,
    /// The longest program per language before it is split, like `--max-lines`.
    pub max_lines: crate::emit::split::Limits,
    /// What runs after a compile that wrote new outputs (docs/DAEMON.md, "Deploying").
    pub on_success: Option<super::deploy::Hook>,
    /// Write `<program>.svg`, the plan's timeline, beside the outputs.
    pub picture: bool,
    /// Simulate the programs after a successful compile (docs/SIMULATE.md, "In the daemon").
    pub simulate: Option<Simulate>,
}

/// What the daemon simulates after a compile (`simulate`).
#[derive(Debug, Clone, PartialEq)]
pub enum Simulate {
    /// So many random runs.
    Runs(usize),
    /// The scenario file, relative to the project folder.
    Scenario(PathBuf),
}

/// The most runs `simulate = N` asks for (each compile's simulation stays short).
pub const MAX_SIMULATE_RUNS: i64 = 10_000;

/// A `[[root]]` entry: its folder and what its projects get.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RootSpec {
    pub path: PathBuf,
    /// The program name pattern of its projects (default `{blackboard}`).
    pub program: Option<String>,
    /// The output template of its projects (the root's, else the global one).
    pub template: Option<PathBuf>,
    /// LF line endings for its projects (the root's setting, else the global one).
    pub lf: bool,
    /// The SFC POU of its projects (the root's, else the global one).
    pub pou: Option<String>,
    /// The split limits of its projects (the root's, else the global ones).
    pub max_lines: crate::emit::split::Limits,
    /// The deploy hook of its projects (the root's, else the global one).
    pub on_success: Option<super::deploy::Hook>,
    /// Its projects draw their plans (the root's setting, else the global one).
    pub picture: bool,
    /// What its projects simulate (the root's setting, else the global one).
    pub simulate: Option<Simulate>,
}

impl RootSpec {
    /// The spec of the project in its subfolder `dir`.
    pub fn project(&self, dir: PathBuf) -> ProjectSpec {
        ProjectSpec {
            path: dir,
            blackboard: None,
            program: self.program.clone(),
            template: self.template.clone(),
            lf: self.lf,
            pou: self.pou.clone(),
            max_lines: self.max_lines,
            on_success: self.on_success.clone(),
            picture: self.picture,
            simulate: self.simulate.clone(),
        }
    }
}

/// The placeholders a `program` pattern may hold.
pub const PROGRAM_PLACEHOLDERS: [&str; 2] = ["{folder}", "{blackboard}"];

/// A project's program name, and where it came from when it had to be changed into a KRL name.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgramName {
    pub name: String,
    /// The text the pattern gave (`Palletizing Cell`) when it was not a KRL name and `name` was
    /// derived from it.
    pub derived_from: Option<String>,
}

/// The program name of the project in `folder` compiling `blackboard`: `program` as written
/// when it has no placeholder (a KRL name: the configuration checks it); otherwise the pattern
/// (default `{blackboard}`) with `{folder}` (the folder's name) and `{blackboard}` (the
/// blackboard's file name without `.aml`) filled in and made a KRL name by
/// [`crate::names::to_krl_name`].
pub fn program_name(program: Option<&str>, folder: &Path, blackboard: &Path) -> ProgramName {
    let pattern = program.unwrap_or("{blackboard}");
    if !pattern.contains('{') {
        return ProgramName {
            name: pattern.to_owned(),
            derived_from: None,
        };
    }
    let name_of = |p: &Path, stem: bool| {
        let n = if stem { p.file_stem() } else { p.file_name() };
        n.unwrap_or_default().to_string_lossy().into_owned()
    };
    let text = pattern
        .replace("{folder}", &name_of(folder, false))
        .replace("{blackboard}", &name_of(blackboard, true));
    let name = crate::names::to_krl_name(&text);
    ProgramName {
        derived_from: (name != text).then_some(text),
        name,
    }
}

/// Checks a `program` value of the configuration: a KRL name, or a pattern whose only braces
/// are [`PROGRAM_PLACEHOLDERS`]. The error says how to fix it.
pub fn check_program(value: &str) -> Result<(), String> {
    let mut rest = value.to_owned();
    for p in PROGRAM_PLACEHOLDERS {
        rest = rest.replace(p, "");
    }
    if rest.contains('{') || rest.contains('}') {
        return Err(format!(
            "`program` {value:?}: the only placeholders are {{folder}} (the project folder's \
             name) and {{blackboard}} (the blackboard's file name without .aml)"
        ));
    }
    if value.contains('{')
        || (crate::names::is_krl_name(value) && !crate::names::is_krl_keyword(value))
    {
        return Ok(());
    }
    if crate::names::is_krl_name(value) {
        return Err(format!(
            "`program` {value:?} is a KRL keyword, which cannot name a program: write e.g. \
             {:?}",
            crate::names::to_krl_name(value)
        ));
    }
    Err(format!(
        "`program` {value:?} is not a KRL name (a letter or `_`, then letters, digits or `_`, at \
         most 24 characters): write it as one, e.g. {:?}, or use a pattern such as \
         \"{{blackboard}}\", whose result is made a KRL name",
        crate::names::to_krl_name(value)
    ))
}

impl Config {
    /// How many deploy hooks run at once.
    pub fn max_deploys(&self) -> usize {
        self.max_deploys
            .unwrap_or(super::deploy::DEFAULT_MAX_DEPLOYS)
    }

    /// How long a root's project folder may be gone before the project is forgotten.
    pub fn forget_after(&self) -> Duration {
        Duration::from_secs(self.forget_after_s.unwrap_or(DEFAULT_FORGET_AFTER_S))
    }

    /// The quiet period: `settle_ms`, else [`DEFAULT_SETTLE_MS`], capped to [`SETTLE_MS_RANGE`].
    pub fn settle(&self) -> Duration {
        let ms = self.settle_ms.unwrap_or(DEFAULT_SETTLE_MS);
        Duration::from_millis(ms.clamp(*SETTLE_MS_RANGE.start(), *SETTLE_MS_RANGE.end()))
    }
}

/// The project folders of a root: its direct subfolders holding at least one `*.aml` file
/// (case-insensitive extension), sorted by path. Unreadable entries are skipped. Not recursive.
///
/// Symlinked subfolders count (their targets are read); hidden subfolders (`.snapshot`, `.git`,
/// …) do not, and neither do hidden files (see [`is_blackboard_name`]).
pub fn discover(root: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(root) else {
        return Vec::new();
    };
    let mut found: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .filter(|e| !is_hidden(&e.file_name()))
        .map(|e| e.path())
        .filter(|p| p.is_dir() && !blackboards(p).unwrap_or_default().is_empty())
        .collect();
    found.sort();
    found
}

/// Which blackboard and program a project uses; see [`resolve_project`].
pub fn resolve(spec: &ProjectSpec) -> Result<(PathBuf, String), String> {
    resolve_project(spec).map(|(b, p)| (b, p.name))
}

/// Which blackboard and program a project uses: the explicit blackboard (relative to the
/// folder), else the single `*.aml` in the folder (error when none or several: say which);
/// the program by [`program_name`] (`Zelle_A.aml` → `Zelle_A`; `Palletizing Cell.aml` →
/// `Palletizing_Cell`, derived).
pub fn resolve_project(spec: &ProjectSpec) -> Result<(PathBuf, ProgramName), String> {
    let blackboard = match &spec.blackboard {
        Some(b) => normalize(&spec.path.join(b)),
        None => {
            let found = blackboards(&spec.path).map_err(|e| {
                format!(
                    "cannot read the project folder {}: {e}",
                    spec.path.display()
                )
            })?;
            match found.as_slice() {
                [] => {
                    return Err(format!(
                        "no blackboard (*.aml) in the project folder {}",
                        spec.path.display()
                    ));
                }
                [one] => one.clone(),
                several => {
                    let names: Vec<String> = several
                        .iter()
                        .map(|p| p.file_name().unwrap_or_default().to_string_lossy().into())
                        .collect();
                    return Err(format!(
                        "{} blackboards in the project folder {}: {}; name the one to use with \
                         `blackboard = \"…\"` in a [[project]] entry",
                        several.len(),
                        spec.path.display(),
                        names.join(", ")
                    ));
                }
            }
        }
    };
    if blackboard.to_str().is_none() {
        return Err(format!(
            "the blackboard's name {} is not UTF-8: a deploy hook's arguments and the events \
             could not name it exactly; rename it",
            crate::paths::escaped(&blackboard)
        ));
    }
    let program = program_name(spec.program.as_deref(), &spec.path, &blackboard);
    Ok((blackboard, program))
}

/// The command line merged over the file: `dirs` become projects (made absolute against the
/// current directory), `events`/`settle` from the command line win over the file's.
///
/// A folder that is already a project of the file is not added again (the file's entry, with
/// its `blackboard`/`program`, stays). `settle_ms` is taken as given: the command line checks
/// it against [`SETTLE_MS_RANGE`].
pub fn merge(
    file: Option<Config>,
    dirs: &[PathBuf],
    events: Option<PathBuf>,
    settle_ms: Option<u64>,
) -> Config {
    let mut config = file.unwrap_or_default();
    for dir in dirs {
        let dir = absolute(dir);
        if !config.projects.iter().any(|p| p.path == dir) {
            config.projects.push(ProjectSpec {
                path: dir,
                template: config.template.clone(),
                lf: config.lf,
                pou: config.pou.clone(),
                max_lines: config.max_lines,
                on_success: config.on_success.clone(),
                picture: config.picture,
                simulate: config.simulate.clone(),
                ..ProjectSpec::default()
            });
        }
    }
    if let Some(events) = events {
        config.events = Some(absolute(&events));
    }
    if settle_ms.is_some() {
        config.settle_ms = settle_ms;
    }
    config
}

/// `skillpost watch` with neither a folder nor a configuration file has nothing to watch, and a
/// `SIGHUP` could add nothing (there is no file to read again): the usage hint to print before
/// exit status 2. A configuration file without projects is waited on (a reload may add some).
pub fn nothing_to_watch(config: Option<&Path>, args: &[PathBuf]) -> Option<String> {
    if config.is_some() || !args.is_empty() {
        return None;
    }
    Some(
        [
            "error: nothing to watch: name project folders or blackboards, or a configuration file",
            "",
            "Usage: skillpost watch [OPTIONS] [DIR|BLACKBOARD]...",
            "       skillpost watch --config FILE [OPTIONS]",
            "",
            "e.g.   skillpost watch .                         the current folder",
            "       skillpost watch cells/A cells/B           two project folders",
            "       skillpost watch --config skillpost.toml   the projects of a configuration file",
            "",
            "See `skillpost watch --help`.",
        ]
        .join("\n"),
    )
}

/// Sorts the arguments of `skillpost watch` into project folders and blackboards (a blackboard
/// stands for its folder, with that blackboard). Unlike folders of the configuration file, which
/// are waited for, an argument must exist: a typo fails at once, saying what was expected.
pub fn command_line_targets(args: &[PathBuf]) -> Result<(Vec<PathBuf>, Vec<PathBuf>), String> {
    let mut dirs = Vec::new();
    let mut blackboards = Vec::new();
    for arg in args {
        too_long(&absolute(arg)).map_err(|m| format!("{}: {m}", arg.display()))?;
        match std::fs::metadata(arg) {
            Ok(m) if m.is_dir() => dirs.push(arg.clone()),
            Ok(m) if m.is_file() && arg.file_name().is_some_and(is_blackboard_name) => {
                blackboards.push(arg.clone())
            }
            Ok(_) => {
                return Err(format!(
                    "{} is neither a project folder nor a blackboard (*.aml): `skillpost watch` \
                     takes project folders (or their blackboards)",
                    arg.display()
                ));
            }
            Err(e) => {
                return Err(format!(
                    "no project folder {}: {e}; `skillpost watch` takes existing project folders \
                     (or their blackboards); a folder that does not exist yet can be named in the \
                     configuration file (`[[project]]`), where it is waited for",
                    arg.display()
                ));
            }
        }
    }
    Ok((dirs, blackboards))
}

/// Adds the project of a blackboard named on the command line: its folder, with that blackboard
/// (and the global settings). A folder that is a project already keeps its entry.
pub fn add_blackboard(config: &mut Config, blackboard: &Path) {
    let blackboard = absolute(blackboard);
    let (Some(dir), Some(name)) = (blackboard.parent(), blackboard.file_name()) else {
        return;
    };
    if config.projects.iter().any(|p| p.path == dir) {
        return;
    }
    config.projects.push(ProjectSpec {
        path: dir.to_owned(),
        blackboard: Some(PathBuf::from(name)),
        template: config.template.clone(),
        lf: config.lf,
        pou: config.pou.clone(),
        max_lines: config.max_lines,
        ..ProjectSpec::default()
    });
}

/// Whether a file name names a blackboard: ends in `.aml` (any case) and is not hidden (editor
/// lock and swap files such as `.#Zelle_A.aml` start with a dot).
pub fn is_blackboard_name(name: &OsStr) -> bool {
    let name = name.to_string_lossy();
    !name.starts_with('.')
        && name.len() > 4
        && name
            .get(name.len() - 4..)
            .is_some_and(|ext| ext.eq_ignore_ascii_case(".aml"))
}

/// The blackboards directly in `dir` (regular files, symlinks followed), sorted.
pub(super) fn blackboards(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(Result::ok)
        .filter(|e| is_blackboard_name(&e.file_name()))
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .collect();
    found.sort();
    Ok(found)
}

fn is_hidden(name: &OsStr) -> bool {
    name.as_encoded_bytes().first() == Some(&b'.')
}

#[cfg(test)]
mod tests;
