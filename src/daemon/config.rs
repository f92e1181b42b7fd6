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
//! picture = true                               # optional: <program>.svg, the plan's timeline
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

use std::ffi::OsStr;
use std::fmt;
use std::ops::{Range, RangeInclusive};
use std::path::{Component, Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use crate::paths::{absolute, normalize};

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
    /// The output template of every project that does not name its own (`template`; default:
    /// the built-in one), absolute.
    pub template: Option<PathBuf>,
    /// LF line endings for every project that does not say otherwise (`line_endings = "lf"`;
    /// default CRLF).
    pub lf: bool,
    /// The SFC POU of every project that does not name its own (`pou`, like `--pou`).
    pub pou: Option<String>,
    /// The deploy hook of every project that does not have its own (`on_success`).
    pub on_success: Option<super::deploy::Hook>,
    /// Every project that does not say otherwise draws its plan (`picture = true`).
    pub picture: bool,
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

/// A path as the file system names it: the folder canonical (when it exists), the name kept.
fn canonical_or_literal(p: &Path) -> PathBuf {
    if let Ok(c) = std::fs::canonicalize(p) {
        return c;
    }
    match (p.parent(), p.file_name()) {
        (Some(dir), Some(name)) => std::fs::canonicalize(dir)
            .map(|d| d.join(name))
            .unwrap_or_else(|_| p.to_path_buf()),
        _ => p.to_path_buf(),
    }
}

/// Whether one of the daemon's own files (`own`: the events file, the state file) lies in a
/// project folder or a root of `config`: the daemon would write into a planner's folder (with
/// `--state P/Blackboard.aml`, replace the blackboard), and its own writes would be changes in
/// a watched folder. The sentence says which file and which folder; `None` when all is well.
pub fn own_files_problem(config: &Config, own: &[PathBuf]) -> Option<String> {
    let folders = config
        .projects
        .iter()
        .map(|p| ("project folder", &p.path))
        .chain(config.roots.iter().map(|r| ("root", &r.path)));
    let own: Vec<(PathBuf, &PathBuf)> = own.iter().map(|o| (canonical_or_literal(o), o)).collect();
    for (what, folder) in folders {
        let real = canonical_or_literal(folder);
        for (o, given) in &own {
            if o.starts_with(&real) || given.starts_with(folder) {
                return Some(format!(
                    "{} (the daemon's own events or state file) lies in the {what} {}: the daemon \
                     never writes its files among a planner's; put it elsewhere (say, \
                     /var/log/skillpost/events.jsonl, or --state in the runtime folder)",
                    given.display(),
                    folder.display()
                ));
            }
        }
    }
    None
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
    /// What runs after a compile that wrote new outputs (docs/DAEMON.md, "Deploying").
    pub on_success: Option<super::deploy::Hook>,
    /// Write `<program>.svg`, the plan's timeline, beside the outputs.
    pub picture: bool,
}

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
    /// The deploy hook of its projects (the root's, else the global one).
    pub on_success: Option<super::deploy::Hook>,
    /// Its projects draw their plans (the root's setting, else the global one).
    pub picture: bool,
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
            on_success: self.on_success.clone(),
            picture: self.picture,
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

/// A configuration problem, located when it comes from the file.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigError {
    pub file: Option<PathBuf>,
    pub line: Option<usize>,
    pub column: Option<usize>,
    pub message: String,
}

impl ConfigError {
    /// An error of the whole configuration, without a line.
    pub fn plain(message: String, file: Option<PathBuf>) -> Self {
        ConfigError {
            file,
            line: None,
            column: None,
            message,
        }
    }
}

impl fmt::Display for ConfigError {
    /// `file:line:column: message`; the parts that are unknown are left out.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(file) = &self.file {
            write!(f, "{}", file.display())?;
            if let Some(line) = self.line {
                write!(f, ":{line}")?;
                if let Some(column) = self.column {
                    write!(f, ":{column}")?;
                }
            }
            write!(f, ": ")?;
        } else if let Some(line) = self.line {
            write!(f, "{line}")?;
            if let Some(column) = self.column {
                write!(f, ":{column}")?;
            }
            write!(f, ": ")?;
        }
        f.write_str(&self.message)
    }
}

impl std::error::Error for ConfigError {}

/// Reads and checks a configuration file. Relative paths in it are resolved against the file's
/// folder (made absolute: if the file path itself is relative, join with the current dir first).
pub fn load(path: &Path) -> Result<Config, ConfigError> {
    let file = absolute(path);
    let error = |message: String| ConfigError {
        file: Some(file.clone()),
        line: None,
        column: None,
        message,
    };
    // Non-blocking and size-limited: a FIFO must not block a reload, `/dev/zero` not fill memory.
    let bytes = crate::load::read_limited(&file, MAX_CONFIG_SIZE)
        .map_err(|e| error(format!("cannot read the configuration: {e}")))?;
    let text = String::from_utf8(bytes)
        .map_err(|e| error(format!("the configuration is not UTF-8: {e}")))?;
    parse_with(&text, &file, true)
}

/// Parses configuration text as if read from `file` (the files it names are not looked at).
pub fn parse(text: &str, file: &Path) -> Result<Config, ConfigError> {
    parse_with(text, file, false)
}

/// [`parse`]; with `files`, a `template` that does not exist is an error at its line, as
/// [`load`] (startup, reload, `--check-config`) reports it: a compile could only name the
/// template file, not the line of the configuration that named it.
fn parse_with(text: &str, file: &Path, files: bool) -> Result<Config, ConfigError> {
    let file = absolute(file);
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let base = file.parent().map(Path::to_path_buf).unwrap_or_default();
    let at = |span: Option<Range<usize>>, message: String| {
        let (line, column) = match span {
            Some(span) => {
                let (l, c) = line_column(text, span.start);
                (Some(l), Some(c))
            }
            None => (None, None),
        };
        ConfigError {
            file: Some(file.clone()),
            line,
            column,
            message,
        }
    };

    let raw: RawConfig = toml::from_str(text).map_err(|e| at(e.span(), toml_message(&e, text)))?;

    // A path from the file: not empty, no `~`, resolved against the file's folder.
    let path = |value: &Spanned<String>, key: &str| -> Result<PathBuf, ConfigError> {
        let s = value.get_ref();
        if s.trim().is_empty() {
            return Err(at(Some(value.span()), format!("`{key}` is empty")));
        }
        if s == "~" || s.starts_with("~/") {
            return Err(at(
                Some(value.span()),
                format!(
                    "`{key}` starts with `~`, which is not expanded (a service has no home \
                     directory): write the absolute path"
                ),
            ));
        }
        let full = normalize(&base.join(s));
        too_long(&full).map_err(|m| at(Some(value.span()), format!("`{key}`: {m}")))?;
        if files
            && key == "template"
            && std::fs::metadata(&full).is_err_and(|e| e.kind() == std::io::ErrorKind::NotFound)
        {
            return Err(at(
                Some(value.span()),
                format!(
                    "`template`: {} does not exist (a relative path is relative to this file's \
                     folder; the templates are installed in /usr/local/share/skillpost/templates)",
                    full.display()
                ),
            ));
        }
        Ok(full)
    };

    let events = raw.events.as_ref().map(|e| path(e, "events")).transpose()?;
    let template = raw
        .template
        .as_ref()
        .map(|t| path(t, "template"))
        .transpose()?;
    let lf = match &raw.line_endings {
        Some(v) => line_endings(v).map_err(|m| at(Some(v.span()), m))?,
        None => false,
    };
    // A project's or root's own settings, else the global ones.
    let pou = raw.pou.clone();
    let settings = |t: &Option<Spanned<String>>,
                    le: &Option<Spanned<String>>,
                    program: &Option<Spanned<String>>|
     -> Result<(Option<PathBuf>, bool, Option<String>), ConfigError> {
        let template = match t {
            Some(t) => Some(path(t, "template")?),
            None => template.clone(),
        };
        let lf = match le {
            Some(v) => line_endings(v).map_err(|m| at(Some(v.span()), m))?,
            None => lf,
        };
        if let Some(p) = program {
            check_program(p.get_ref()).map_err(|m| at(Some(p.span()), m))?;
        }
        Ok((template, lf, program.as_ref().map(|p| p.get_ref().clone())))
    };

    let settle_ms = match &raw.settle_ms {
        None => None,
        Some(v) => {
            let n = *v.get_ref();
            match u64::try_from(n) {
                Ok(n) if SETTLE_MS_RANGE.contains(&n) => Some(n),
                _ => {
                    return Err(at(
                        Some(v.span()),
                        format!(
                            "`settle_ms` is {n}, expected {}..={} (milliseconds)",
                            SETTLE_MS_RANGE.start(),
                            SETTLE_MS_RANGE.end()
                        ),
                    ));
                }
            }
        }
    };

    let max_file_size_mb = match &raw.max_file_size_mb {
        None => None,
        Some(v) => {
            let n = *v.get_ref();
            match u64::try_from(n) {
                Ok(n) if MAX_FILE_SIZE_MB_RANGE.contains(&n) => Some(n),
                _ => {
                    return Err(at(
                        Some(v.span()),
                        format!(
                            "`max_file_size_mb` is {n}, expected {}..={} (MiB)",
                            MAX_FILE_SIZE_MB_RANGE.start(),
                            MAX_FILE_SIZE_MB_RANGE.end()
                        ),
                    ));
                }
            }
        }
    };

    let forget_after_s = match &raw.forget_after_s {
        None => None,
        Some(v) => {
            let n = *v.get_ref();
            match u64::try_from(n) {
                Ok(n) if FORGET_AFTER_S_RANGE.contains(&n) => Some(n),
                _ => {
                    return Err(at(
                        Some(v.span()),
                        format!(
                            "`forget_after_s` is {n}, expected {}..={} (seconds)",
                            FORGET_AFTER_S_RANGE.start(),
                            FORGET_AFTER_S_RANGE.end()
                        ),
                    ));
                }
            }
        }
    };

    // The deploy hook: checked where it is written; a timeout of its own or the global one.
    let timeout_of =
        |t: &Option<Spanned<i64>>, default: Duration| -> Result<Duration, ConfigError> {
            let Some(v) = t else { return Ok(default) };
            let n = *v.get_ref();
            match u64::try_from(n) {
                Ok(n) if super::deploy::DEPLOY_TIMEOUT_S_RANGE.contains(&n) => {
                    Ok(Duration::from_secs(n))
                }
                _ => Err(at(
                    Some(v.span()),
                    format!(
                        "`deploy_timeout_s` is {n}, expected {}..={} (seconds)",
                        super::deploy::DEPLOY_TIMEOUT_S_RANGE.start(),
                        super::deploy::DEPLOY_TIMEOUT_S_RANGE.end()
                    ),
                )),
            }
        };
    let global_timeout = timeout_of(
        &raw.deploy_timeout_s,
        Duration::from_secs(super::deploy::DEFAULT_DEPLOY_TIMEOUT_S),
    )?;
    let hook =
        |h: &Spanned<Vec<String>>, timeout: Duration| -> Result<super::deploy::Hook, ConfigError> {
            super::deploy::check(h.get_ref()).map_err(|m| at(Some(h.span()), m))?;
            let mut argv = h.get_ref().clone();
            argv[0] = super::deploy::program_path(&argv[0], &base);
            Ok(super::deploy::Hook { argv, timeout })
        };
    let on_success = raw
        .on_success
        .as_ref()
        .map(|h| hook(h, global_timeout))
        .transpose()?;
    // A project's or root's own hook, else the global one (with its own timeout, if set).
    let own_hook = |h: &Option<Spanned<Vec<String>>>,
                    t: &Option<Spanned<i64>>|
     -> Result<Option<super::deploy::Hook>, ConfigError> {
        let timeout = timeout_of(t, global_timeout)?;
        Ok(match h {
            Some(h) => Some(hook(h, timeout)?),
            None => on_success.clone().map(|mut g| {
                g.timeout = timeout;
                g
            }),
        })
    };

    let mut projects: Vec<ProjectSpec> = Vec::new();
    let mut seen: Vec<(PathBuf, &Spanned<String>)> = Vec::new();
    for p in &raw.project {
        let dir = path(&p.path, "path")?;
        if let Some((_, first)) = seen.iter().find(|(d, _)| *d == dir) {
            return Err(duplicate(&at, "project", &dir, first, &p.path, text));
        }
        let blackboard = match &p.blackboard {
            None => None,
            Some(b) => Some(blackboard_path(b).map_err(|m| at(Some(b.span()), m))?),
        };
        seen.push((dir.clone(), &p.path));
        let (template, lf, program) = settings(&p.template, &p.line_endings, &p.program)?;
        projects.push(ProjectSpec {
            path: dir,
            blackboard,
            program,
            template,
            lf,
            pou: p.pou.clone().or_else(|| pou.clone()),
            on_success: own_hook(&p.on_success, &p.deploy_timeout_s)?,
            picture: p.picture.unwrap_or(raw.picture),
        });
    }

    let mut roots: Vec<RootSpec> = Vec::new();
    let mut seen: Vec<(PathBuf, &Spanned<String>)> = Vec::new();
    for r in &raw.root {
        let dir = path(&r.path, "path")?;
        if let Some((_, first)) = seen.iter().find(|(d, _)| *d == dir) {
            return Err(duplicate(&at, "root", &dir, first, &r.path, text));
        }
        seen.push((dir.clone(), &r.path));
        let (template, lf, program) = settings(&r.template, &r.line_endings, &r.program)?;
        roots.push(RootSpec {
            path: dir,
            program,
            template,
            lf,
            pou: r.pou.clone().or_else(|| pou.clone()),
            on_success: own_hook(&r.on_success, &r.deploy_timeout_s)?,
            picture: r.picture.unwrap_or(raw.picture),
        });
    }

    let config = Config {
        file: Some(file.clone()),
        events,
        settle_ms,
        allow_outside: raw.allow_outside,
        max_file_size_mb,
        forget_after_s,
        template,
        lf,
        pou,
        on_success,
        picture: raw.picture,
        projects,
        roots,
    };
    let first_hook = raw
        .on_success
        .iter()
        .chain(raw.project.iter().filter_map(|p| p.on_success.as_ref()))
        .chain(raw.root.iter().filter_map(|r| r.on_success.as_ref()))
        .next();
    if let Some(h) = first_hook
        && let Some(why) = hook_from_a_planners_folder(&config)
    {
        return Err(at(Some(h.span()), why));
    }
    Ok(config)
}

/// Whether `config` sets a deploy hook although its file lies in one of its project folders or
/// roots, where planners write: the hook would run whatever they write into the file. The
/// sentence to refuse it with.
pub fn hook_from_a_planners_folder(config: &Config) -> Option<String> {
    let file = config.file.as_ref()?;
    let any_hook = config.on_success.is_some()
        || config.projects.iter().any(|p| p.on_success.is_some())
        || config.roots.iter().any(|r| r.on_success.is_some());
    if !any_hook {
        return None;
    }
    let real = canonical_or_literal(file);
    let folders = config
        .projects
        .iter()
        .map(|p| ("project folder", &p.path))
        .chain(config.roots.iter().map(|r| ("root", &r.path)));
    for (what, folder) in folders {
        if real.starts_with(canonical_or_literal(folder)) || file.starts_with(folder) {
            return Some(format!(
                "`on_success` in {}, which lies in the {what} {}: a deploy hook runs programs, \
                 and only the daemon's own configuration may say which, never a file planners \
                 can write; move the configuration out of the folder (say, to \
                 /etc/skillpost/skillpost.toml)",
                file.display(),
                folder.display()
            ));
        }
    }
    None
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
                on_success: config.on_success.clone(),
                picture: config.picture,
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

/// An explicit blackboard: relative to the project folder and staying inside it (the outputs are
/// written beside it).
fn blackboard_path(value: &Spanned<String>) -> Result<PathBuf, String> {
    let s = value.get_ref();
    if s.trim().is_empty() {
        return Err("`blackboard` is empty".into());
    }
    let p = Path::new(s);
    if p.is_absolute() || p.components().any(|c| !matches!(c, Component::Normal(_))) {
        return Err(format!(
            "`blackboard` must be a path inside the project folder, relative to it \
             (no leading `/`, `~`, `.` or `..`): {s:?}"
        ));
    }
    if s == "~" || s.starts_with("~/") {
        return Err(format!(
            "`blackboard` starts with `~`, which is not expanded: {s:?}"
        ));
    }
    Ok(p.to_path_buf())
}

fn duplicate<F>(
    at: &F,
    what: &str,
    dir: &Path,
    first: &Spanned<String>,
    second: &Spanned<String>,
    text: &str,
) -> ConfigError
where
    F: Fn(Option<Range<usize>>, String) -> ConfigError,
{
    let (line, column) = line_column(text, first.span().start);
    at(
        Some(second.span()),
        format!(
            "duplicate [[{what}]]: {:?} is the folder {}, already named by {:?} at line {line}, \
             column {column}",
            second.get_ref(),
            dir.display(),
            first.get_ref()
        ),
    )
}

/// The parser's message, with serde's type names put in the file's terms.
fn toml_message(e: &toml::de::Error, text: &str) -> String {
    // The key of the line the error is on (`on_success = ...`).
    let key = e.span().and_then(|span| {
        let before = text.get(..span.start)?;
        let line = &text[before.rfind('\n').map_or(0, |i| i + 1)..];
        let (key, _) = line.split_once('=')?;
        Some(key.trim().to_owned())
    });
    let sequence = if key.as_deref() == Some("on_success") {
        "expected a list of strings: the program and its arguments, \
         e.g. [\"/usr/local/bin/deploy\", \"{src}\"] (never a shell line)"
    } else {
        "expected a list of tables (write `[[project]]` or `[[root]]` with double brackets)"
    };
    e.message()
        .trim_end()
        .replace("expected i64", "expected an integer")
        .replace("expected a sequence", sequence)
}

/// 1-based line and column (in characters) of a byte offset.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before[line_start..].chars().count() + 1;
    (line, column)
}

/// `line_endings`: `"crlf"` (the default) or `"lf"`; true for LF.
fn line_endings(value: &Spanned<String>) -> Result<bool, String> {
    match value.get_ref().as_str() {
        "crlf" | "CRLF" => Ok(false),
        "lf" | "LF" => Ok(true),
        other => Err(format!(
            "`line_endings` is {other:?}, expected \"crlf\" (the default, as the controller \
             expects) or \"lf\""
        )),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    events: Option<Spanned<String>>,
    template: Option<Spanned<String>>,
    line_endings: Option<Spanned<String>>,
    pou: Option<String>,
    settle_ms: Option<Spanned<i64>>,
    #[serde(default)]
    allow_outside: bool,
    max_file_size_mb: Option<Spanned<i64>>,
    forget_after_s: Option<Spanned<i64>>,
    on_success: Option<Spanned<Vec<String>>>,
    deploy_timeout_s: Option<Spanned<i64>>,
    #[serde(default)]
    picture: bool,
    #[serde(default)]
    project: Vec<RawProject>,
    #[serde(default)]
    root: Vec<RawRoot>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProject {
    path: Spanned<String>,
    blackboard: Option<Spanned<String>>,
    program: Option<Spanned<String>>,
    template: Option<Spanned<String>>,
    line_endings: Option<Spanned<String>>,
    pou: Option<String>,
    on_success: Option<Spanned<Vec<String>>>,
    deploy_timeout_s: Option<Spanned<i64>>,
    picture: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRoot {
    path: Spanned<String>,
    program: Option<Spanned<String>>,
    template: Option<Spanned<String>>,
    line_endings: Option<Spanned<String>>,
    pou: Option<String>,
    on_success: Option<Spanned<Vec<String>>>,
    deploy_timeout_s: Option<Spanned<i64>>,
    picture: Option<bool>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    fn file() -> PathBuf {
        PathBuf::from("/etc/skillpost/skillpost.toml")
    }

    fn err(text: &str) -> ConfigError {
        parse(text, &file()).expect_err("should be rejected")
    }

    fn spec(path: &Path) -> ProjectSpec {
        ProjectSpec {
            path: path.to_path_buf(),
            ..ProjectSpec::default()
        }
    }

    fn root_paths(c: &Config) -> Vec<PathBuf> {
        c.roots.iter().map(|r| r.path.clone()).collect()
    }

    fn root(path: &str) -> RootSpec {
        RootSpec {
            path: path.into(),
            ..RootSpec::default()
        }
    }

    #[test]
    fn valid_file_with_all_keys() {
        let text = r#"
events = "/var/log/skillpost/events.jsonl"
settle_ms = 250
allow_outside = true
max_file_size_mb = 64
forget_after_s = 120

[[project]]
path = "/srv/cells/Zelle_A"
blackboard = "Zelle_A.aml"
program = "ZELLE_A"

[[project]]
path = "/srv/cells/Zelle_B"

[[root]]
path = "/srv/planning/projects"
"#;
        let c = parse(text, &file()).unwrap();
        assert_eq!(
            c,
            Config {
                file: Some(file()),
                events: Some("/var/log/skillpost/events.jsonl".into()),
                settle_ms: Some(250),
                allow_outside: true,
                max_file_size_mb: Some(64),
                forget_after_s: Some(120),
                template: None,
                lf: false,
                pou: None,
                on_success: None,
                picture: false,
                projects: vec![
                    ProjectSpec {
                        path: "/srv/cells/Zelle_A".into(),
                        blackboard: Some("Zelle_A.aml".into()),
                        program: Some("ZELLE_A".into()),
                        ..ProjectSpec::default()
                    },
                    spec(Path::new("/srv/cells/Zelle_B")),
                ],
                roots: vec![root("/srv/planning/projects")],
            }
        );
        assert_eq!(c.settle(), Duration::from_millis(250));
    }

    #[test]
    fn the_example_in_config_is_valid_and_sets_every_key() {
        let text = include_str!("../../config/skillpost.toml");
        let c = parse(text, &file()).unwrap();
        assert!(c.events.is_some());
        assert!(c.settle_ms.is_some());
        assert!(!c.projects.is_empty() && !c.roots.is_empty());
        let p = &c.projects[0];
        assert!(p.blackboard.is_some() && p.program.is_some());
        assert!(c.template.is_some());
        assert!(c.roots[0].program.is_some());
        for key in [
            "events",
            "settle_ms",
            "allow_outside",
            "forget_after_s",
            "template",
            "line_endings",
            // Commented out: a POU name that an example project lacks would fail it.
            "# pou",
            "[[project]]",
            "[[root]]",
        ] {
            assert!(
                text.contains(&format!("\n{key}")),
                "{key} is set in the example"
            );
        }
        for key in ["path", "blackboard", "program", "template", "line_endings"] {
            assert!(
                text.contains(&format!("\n{key} = ")),
                "{key} is set in the example"
            );
        }
    }

    #[test]
    fn empty_file_is_an_empty_config() {
        let c = parse("# nothing\n", &file()).unwrap();
        assert_eq!(
            c,
            Config {
                file: Some(file()),
                ..Config::default()
            }
        );
        assert_eq!(c.settle(), Duration::from_millis(DEFAULT_SETTLE_MS));
    }

    #[test]
    fn relative_paths_resolve_against_the_files_folder() {
        let text = r#"
events = "log/events.jsonl"
[[project]]
path = "cells/./Zelle_A"
[[project]]
path = "../other/Zelle_B"
[[root]]
path = "."
"#;
        let c = parse(text, Path::new("/opt/plan/conf/skillpost.toml")).unwrap();
        assert_eq!(
            c.events.as_deref(),
            Some(Path::new("/opt/plan/conf/log/events.jsonl"))
        );
        assert_eq!(
            c.projects[0].path,
            PathBuf::from("/opt/plan/conf/cells/Zelle_A")
        );
        assert_eq!(c.projects[1].path, PathBuf::from("/opt/plan/other/Zelle_B"));
        assert_eq!(root_paths(&c), vec![PathBuf::from("/opt/plan/conf")]);
    }

    #[test]
    fn load_makes_a_relative_file_path_absolute() {
        let dir = tempfile::tempdir().unwrap();
        fs::write(
            dir.path().join("s.toml"),
            "[[project]]\npath = \"cells/A\"\n",
        )
        .unwrap();
        let c = load(&dir.path().join("s.toml")).unwrap();
        assert_eq!(c.file.as_deref(), Some(dir.path().join("s.toml").as_path()));
        assert_eq!(c.projects[0].path, dir.path().join("cells/A"));

        // A relative file name: against the current directory.
        let cwd = std::env::current_dir().unwrap();
        let c = parse("[[root]]\npath = \"r\"\n", Path::new("conf/s.toml")).unwrap();
        assert_eq!(root_paths(&c), vec![cwd.join("conf/r")]);
        assert_eq!(c.file, Some(cwd.join("conf/s.toml")));
    }

    #[test]
    fn load_of_a_missing_file_names_it() {
        let dir = tempfile::tempdir().unwrap();
        let e = load(&dir.path().join("nope.toml")).unwrap_err();
        assert_eq!(e.file, Some(dir.path().join("nope.toml")));
        assert_eq!(e.line, None);
        assert!(e.message.contains("cannot read"), "{e}");
    }

    #[test]
    fn load_locates_a_template_that_does_not_exist() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = dir.path().join("skillpost.toml");
        let text = "settle_ms = 100\n[[project]]\npath = \"p\"\ntemplate = \"missing/krl.toml\"\n";
        std::fs::write(&cfg, text).unwrap();
        let e = load(&cfg).unwrap_err();
        assert_eq!(
            (e.file.as_ref(), e.line, e.column),
            (Some(&cfg), Some(4), Some(12))
        );
        assert!(e.message.contains("missing/krl.toml does not exist"), "{e}");
        // Text alone is not checked against the disk; an existing template loads.
        assert!(parse(text, &cfg).is_ok());
        std::fs::create_dir(dir.path().join("t")).unwrap();
        std::fs::write(dir.path().join("t/krl.toml"), "").unwrap();
        std::fs::write(&cfg, "template = \"t/krl.toml\"\n").unwrap();
        assert!(load(&cfg).is_ok());
    }

    #[test]
    fn unknown_key_at_top_level() {
        let e = err("settle_ms = 100\n  setle = 5\n");
        assert_eq!((e.line, e.column), (Some(2), Some(3)), "{e}");
        assert!(e.message.contains("unknown field `setle`"), "{e}");
        assert_eq!(
            e.to_string(),
            format!("/etc/skillpost/skillpost.toml:2:3: {}", e.message)
        );
    }

    #[test]
    fn unknown_key_inside_project() {
        let e = err("[[project]]\npath = \"a\"\n\n[[project]]\npath = \"b\"\nprogam = \"X\"\n");
        assert_eq!((e.line, e.column), (Some(6), Some(1)), "{e}");
        assert!(e.message.contains("unknown field `progam`"), "{e}");
        assert!(e.message.contains("program"), "lists the known keys: {e}");
    }

    #[test]
    fn unknown_key_column_counts_characters() {
        let e = err("[[root]]\npath = \"Zelle_ä\"; Größe = 1\n");
        // A syntax error after a value: located after the multi-byte characters.
        assert_eq!(e.line, Some(2), "{e}");
        assert_eq!(e.column, Some(17), "{e}");
        let e = err("[[root]]\npath = \"ä\"\n\"größe\" = 1\n");
        assert_eq!((e.line, e.column), (Some(3), Some(1)), "{e}");
        let e = err("[[root]]\npath = \"ä\"\nx = { \"größe\" = 1 }\n");
        assert_eq!(e.line, Some(3), "{e}");
    }

    #[test]
    fn wrong_types() {
        let e = err("settle_ms = \"fast\"\n");
        assert_eq!((e.line, e.column), (Some(1), Some(13)), "{e}");
        assert!(e.message.contains("invalid type"), "{e}");
        assert!(e.message.contains("expected an integer"), "{e}");
        let e = err("allow_outside = \"yes\"\n");
        assert_eq!((e.line, e.column), (Some(1), Some(17)), "{e}");
        let e = err("[[project]]\npath = 3\n");
        assert_eq!((e.line, e.column), (Some(2), Some(8)), "{e}");
        let e = err("project = \"x\"\n");
        assert_eq!(e.line, Some(1), "{e}");
        let e = err("[project]\npath = \"x\"\n");
        assert!(e.message.contains("[[project]]"), "{e}");
        let e = err("[[project]]\nblackboard = \"a.aml\"\n");
        assert!(e.message.contains("missing field `path`"), "{e}");
        assert_eq!(e.line, Some(1), "{e}");
    }

    #[test]
    fn syntax_error_is_located() {
        let e = err("events = \"a\"\nsettle_ms = \n");
        assert_eq!(e.line, Some(2), "{e}");
    }

    #[test]
    fn settle_out_of_range() {
        for (text, col) in [
            ("settle_ms = 0\n", 13),
            ("settle_ms =   60001\n", 15),
            ("settle_ms = -5\n", 13),
        ] {
            let e = err(&format!("# c\n{text}"));
            assert_eq!((e.line, e.column), (Some(2), Some(col)), "{e}");
            assert!(e.message.contains("1..=60000"), "{e}");
        }
        assert_eq!(
            parse("settle_ms = 60000", &file()).unwrap().settle_ms,
            Some(60000)
        );
        assert_eq!(parse("settle_ms = 1", &file()).unwrap().settle_ms, Some(1));
    }

    #[test]
    fn empty_and_home_paths() {
        let e = err("[[project]]\npath = \"a\"\n[[project]]\npath = \"\"\n");
        assert_eq!((e.line, e.column), (Some(4), Some(8)), "{e}");
        assert!(e.message.contains("empty"), "{e}");
        let e = err("[[root]]\npath = \"  \"\n");
        assert_eq!((e.line, e.column), (Some(2), Some(8)), "{e}");
        let e = err("events = \"\"\n");
        assert_eq!((e.line, e.column), (Some(1), Some(10)), "{e}");
        let e = err("[[root]]\npath = \"~/projects\"\n");
        assert_eq!((e.line, e.column), (Some(2), Some(8)), "{e}");
        assert!(e.message.contains("not expanded"), "{e}");
        // A folder merely named `~x` is an ordinary relative path.
        let c = parse("[[root]]\npath = \"~x\"\n", &file()).unwrap();
        assert_eq!(root_paths(&c), vec![PathBuf::from("/etc/skillpost/~x")]);
    }

    #[test]
    fn bad_blackboard() {
        for bb in ["/abs/a.aml", "../a.aml", "./a.aml", "", "~/a.aml"] {
            let e = err(&format!(
                "[[project]]\npath = \"p\"\nblackboard = \"{bb}\"\n"
            ));
            assert_eq!((e.line, e.column), (Some(3), Some(14)), "{bb}: {e}");
        }
        let c = parse(
            "[[project]]\npath = \"p\"\nblackboard = \"sub/B.AML\"\n",
            &file(),
        )
        .unwrap();
        assert_eq!(c.projects[0].blackboard, Some("sub/B.AML".into()));
    }

    #[test]
    fn duplicate_projects_name_both() {
        let e = err(
            "[[project]]\npath = \"cells/A\"\n[[project]]\npath = \"/etc/skillpost/cells/x/../A\"\n",
        );
        assert_eq!((e.line, e.column), (Some(4), Some(8)), "{e}");
        assert!(e.message.contains("\"cells/A\""), "{e}");
        assert!(e.message.contains("/etc/skillpost/cells/x/../A"), "{e}");
        assert!(e.message.contains("line 2, column 8"), "{e}");
        let e = err("[[root]]\npath = \"r\"\n[[root]]\npath = \"./r\"\n");
        assert_eq!((e.line, e.column), (Some(4), Some(8)), "{e}");
        assert!(e.message.contains("[[root]]"), "{e}");
    }

    #[test]
    fn crlf_and_bom() {
        let e = err("\u{feff}events = \"a\"\r\nfoo = 1\r\n");
        assert_eq!((e.line, e.column), (Some(2), Some(1)), "{e}");
        let c = parse("\u{feff}settle_ms = 5\r\n", &file()).unwrap();
        assert_eq!(c.settle_ms, Some(5));
    }

    #[test]
    fn display_without_location() {
        let e = ConfigError {
            file: None,
            line: None,
            column: None,
            message: "boom".into(),
        };
        assert_eq!(e.to_string(), "boom");
        let e = ConfigError {
            file: Some("/x.toml".into()),
            line: None,
            column: None,
            message: "boom".into(),
        };
        assert_eq!(e.to_string(), "/x.toml: boom");
    }

    #[test]
    fn discover_finds_direct_subfolders_with_a_blackboard() {
        let root = tempfile::tempdir().unwrap();
        let r = root.path();
        for d in [
            "b_upper",
            "a_lower",
            "empty",
            "other",
            "nested",
            ".snapshot",
        ] {
            fs::create_dir(r.join(d)).unwrap();
        }
        fs::write(r.join("a_lower/a.aml"), "").unwrap();
        fs::write(r.join("b_upper/A.AML"), "").unwrap();
        fs::write(r.join("other/notes.txt"), "").unwrap();
        fs::write(r.join("other/.#x.aml"), "").unwrap();
        fs::create_dir(r.join("other/x.aml")).unwrap(); // a folder, not a blackboard
        fs::create_dir(r.join("nested/deeper")).unwrap();
        fs::write(r.join("nested/deeper/n.aml"), "").unwrap();
        fs::write(r.join(".snapshot/s.aml"), "").unwrap();
        fs::write(r.join("file.aml"), "").unwrap(); // a file, not a folder
        assert_eq!(discover(r), vec![r.join("a_lower"), r.join("b_upper")]);
        assert!(discover(&r.join("missing")).is_empty());
    }

    #[cfg(unix)]
    #[test]
    fn discover_follows_symlinked_folders_and_skips_broken_ones() {
        let root = tempfile::tempdir().unwrap();
        let elsewhere = tempfile::tempdir().unwrap();
        fs::write(elsewhere.path().join("c.aml"), "").unwrap();
        std::os::unix::fs::symlink(elsewhere.path(), root.path().join("linked")).unwrap();
        std::os::unix::fs::symlink("/nonexistent/x", root.path().join("broken")).unwrap();
        assert_eq!(discover(root.path()), vec![root.path().join("linked")]);
    }

    #[test]
    fn resolve_none_one_several_explicit() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();

        let e = resolve(&spec(d)).unwrap_err();
        assert!(e.contains("no blackboard"), "{e}");
        assert!(e.contains(&d.display().to_string()), "{e}");

        fs::write(d.join("Zelle_A.aml"), "").unwrap();
        fs::write(d.join("Zelle_A.aml~"), "").unwrap();
        fs::write(d.join(".Zelle_A.aml"), "").unwrap();
        assert_eq!(
            resolve(&spec(d)).unwrap(),
            (d.join("Zelle_A.aml"), "Zelle_A".to_string())
        );

        fs::write(d.join("b.AML"), "").unwrap();
        let e = resolve(&spec(d)).unwrap_err();
        assert!(e.contains("2 blackboards"), "{e}");
        assert!(e.contains("Zelle_A.aml, b.AML"), "{e}");

        let explicit = ProjectSpec {
            path: d.to_path_buf(),
            blackboard: Some("b.AML".into()),
            ..ProjectSpec::default()
        };
        assert_eq!(
            resolve(&explicit).unwrap(),
            (d.join("b.AML"), "b".to_string())
        );
        let both = ProjectSpec {
            program: Some("Not a KRL name!".into()),
            ..explicit
        };
        assert_eq!(
            resolve(&both).unwrap(),
            (d.join("b.AML"), "Not a KRL name!".to_string())
        );

        let e = resolve(&spec(&d.join("missing"))).unwrap_err();
        assert!(e.contains("cannot read"), "{e}");
    }

    #[test]
    fn template_and_line_endings_global_per_project_and_per_root() {
        let text = r#"
template = "krl-team.toml"
line_endings = "lf"
[[project]]
path = "A"
[[project]]
path = "B"
template = "/opt/b.toml"
line_endings = "crlf"
[[root]]
path = "r1"
[[root]]
path = "r2"
line_endings = "CRLF"
template = "t/r2.toml"
"#;
        let c = parse(text, &file()).unwrap();
        assert_eq!(c.template, Some("/etc/skillpost/krl-team.toml".into()));
        assert!(c.lf);
        let a = &c.projects[0];
        assert_eq!(a.template, Some("/etc/skillpost/krl-team.toml".into()));
        assert!(a.lf);
        let b = &c.projects[1];
        assert_eq!(b.template, Some("/opt/b.toml".into()));
        assert!(!b.lf);
        let p1 = c.roots[0].project("/etc/skillpost/r1/X".into());
        assert_eq!(p1.template, Some("/etc/skillpost/krl-team.toml".into()));
        assert!(p1.lf);
        let p2 = c.roots[1].project("/etc/skillpost/r2/Y".into());
        assert_eq!(p2.template, Some("/etc/skillpost/t/r2.toml".into()));
        assert!(!p2.lf);
        assert_eq!(p2.path, PathBuf::from("/etc/skillpost/r2/Y"));

        // The command line's folders get the global settings.
        let m = merge(Some(c), &["/srv/C".into()], None, None);
        let cli = m.projects.last().unwrap();
        assert_eq!(cli.path, PathBuf::from("/srv/C"));
        assert_eq!(cli.template, Some("/etc/skillpost/krl-team.toml".into()));
        assert!(cli.lf);

        // Defaults: built-in template, CRLF, the POU the SFC says.
        let c = parse("[[project]]\npath = \"A\"\n", &file()).unwrap();
        assert_eq!(c.projects[0].template, None);
        assert!(!c.projects[0].lf);
        assert_eq!(c.projects[0].pou, None);

        // `pou` likewise.
        let c = parse(
            "pou = \"Main\"\n[[project]]\npath = \"A\"\n[[project]]\npath = \"B\"\npou = \"Other\"\n\
             [[root]]\npath = \"r\"\n[[root]]\npath = \"s\"\npou = \"S\"\n",
            &file(),
        )
        .unwrap();
        assert_eq!(c.projects[0].pou.as_deref(), Some("Main"));
        assert_eq!(c.projects[1].pou.as_deref(), Some("Other"));
        assert_eq!(c.roots[0].project("x".into()).pou.as_deref(), Some("Main"));
        assert_eq!(c.roots[1].project("x".into()).pou.as_deref(), Some("S"));
    }

    #[test]
    fn bad_line_endings_and_templates_are_located() {
        let e = err("\nline_endings = \"unix\"\n");
        assert_eq!((e.line, e.column), (Some(2), Some(16)), "{e}");
        assert!(
            e.message.contains("\"crlf\"") && e.message.contains("\"lf\""),
            "{e}"
        );
        let e = err("[[root]]\npath = \"r\"\nline_endings = \"cr\"\n");
        assert_eq!((e.line, e.column), (Some(3), Some(16)), "{e}");
        let e = err("[[project]]\npath = \"p\"\ntemplate = \"\"\n");
        assert_eq!((e.line, e.column), (Some(3), Some(12)), "{e}");
        let e = err("template = \"~/t.toml\"\n");
        assert!(e.message.contains("not expanded"), "{e}");
        let e = err("[[root]]\npath = \"r\"\ntemplat = \"t\"\n");
        assert!(e.message.contains("unknown field `templat`"), "{e}");
    }

    #[test]
    fn program_patterns() {
        let c = parse(
            "[[root]]\npath = \"r\"\nprogram = \"P_{folder}\"\n[[root]]\npath = \"s\"\n",
            &file(),
        )
        .unwrap();
        assert_eq!(c.roots[0].program.as_deref(), Some("P_{folder}"));
        assert_eq!(c.roots[1].program, None);
        for (text, col) in [
            ("program = \"Zelle A\"", 11),
            ("program = \"{ordner}\"", 11),
            ("program = \"P_{folder\"", 11),
            ("program = \"1abc\"", 11),
        ] {
            let e = err(&format!("[[root]]\npath = \"r\"\n{text}\n"));
            assert_eq!((e.line, e.column), (Some(3), Some(col)), "{text}: {e}");
        }
        let e = err("[[project]]\npath = \"p\"\nprogram = \"Zelle A\"\n");
        assert!(e.message.contains("not a KRL name"), "{e}");
        assert!(e.message.contains("\"Zelle_A\""), "says how to fix it: {e}");
        let e = err("[[root]]\npath = \"r\"\nprogram = \"{ordner}\"\n");
        assert!(e.message.contains("{folder}"), "{e}");
        let e = err("[[root]]\npath = \"r\"\nprogram = \"Loop\"\n");
        assert!(
            e.message.contains("keyword") && e.message.contains("\"Loop_\""),
            "{e}"
        );

        let bb = Path::new("/r/Palletizing Cell/Palletizing Cell.aml");
        let folder = Path::new("/r/Palletizing Cell");
        assert_eq!(
            program_name(None, folder, bb),
            ProgramName {
                name: "Palletizing_Cell".into(),
                derived_from: Some("Palletizing Cell".into()),
            }
        );
        let ok = Path::new("/r/x/Zelle_A.aml");
        assert_eq!(
            program_name(None, Path::new("/r/x"), ok),
            ProgramName {
                name: "Zelle_A".into(),
                derived_from: None,
            }
        );
        let p = program_name(Some("{folder}"), Path::new("/r/Zelle_Übergabe"), ok);
        assert_eq!(p.name, "Zelle_Uebergabe");
        assert_eq!(p.derived_from.as_deref(), Some("Zelle_Übergabe"));
        let p = program_name(Some("Cell_{folder}_{blackboard}"), Path::new("/r/7"), ok);
        assert_eq!(p.name, "Cell_7_Zelle_A");
        assert_eq!(p.derived_from, None);
        let p = program_name(Some("Main"), folder, bb);
        assert_eq!(p.name, "Main");
        let p = program_name(Some("{folder}"), Path::new("/r/2024 Linie"), ok);
        assert_eq!(p.name, "_2024_Linie");
    }

    #[test]
    fn forget_after_out_of_range_is_located() {
        let e = parse("\nforget_after_s = 0\n", &file()).unwrap_err();
        assert_eq!((e.line, e.column), (Some(2), Some(18)));
        assert!(e.message.contains("forget_after_s"), "{e}");
        let c = parse("forget_after_s = 5\n", &file()).unwrap();
        assert_eq!(c.forget_after(), Duration::from_secs(5));
        assert_eq!(
            Config::default().forget_after(),
            Duration::from_secs(DEFAULT_FORGET_AFTER_S)
        );
    }

    #[test]
    fn a_fifo_or_device_as_the_configuration_is_refused_at_once() {
        let d = tempfile::tempdir().unwrap();
        let fifo = d.path().join("skillpost.toml");
        rustix::fs::mknodat(
            rustix::fs::CWD,
            &fifo,
            rustix::fs::FileType::Fifo,
            rustix::fs::Mode::from_raw_mode(0o600),
            0,
        )
        .unwrap();
        let t = std::time::Instant::now();
        let e = load(&fifo).unwrap_err();
        assert!(e.message.contains("not a regular file"), "{e}");
        let link = d.path().join("zero.toml");
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        assert!(
            load(&link)
                .unwrap_err()
                .message
                .contains("not a regular file")
        );
        let big = d.path().join("big.toml");
        std::fs::write(&big, vec![b'#'; MAX_CONFIG_SIZE as usize + 1]).unwrap();
        assert!(load(&big).unwrap_err().message.contains("limit"));
        assert!(t.elapsed() < Duration::from_secs(1));
    }

    #[test]
    fn max_file_size_out_of_range_is_located() {
        let e = parse("\nmax_file_size_mb = 0\n", &file()).unwrap_err();
        assert_eq!((e.line, e.column), (Some(2), Some(20)), "{e}");
        assert!(e.message.contains("1..=4096"), "{e}");
    }

    #[test]
    fn deploy_hooks_are_inherited_overridden_and_checked_where_written() {
        let c = parse(
            "on_success = [\"deploy\", \"{src}\"]\ndeploy_timeout_s = 30\n\
             [[project]]\npath = \"/srv/A\"\n\
             [[project]]\npath = \"/srv/B\"\non_success = [\"bin/copy\", \"{outputs}\"]\n\
             [[project]]\npath = \"/srv/C\"\ndeploy_timeout_s = 5\n\
             [[root]]\npath = \"/srv/R\"\n",
            &file(),
        )
        .unwrap();
        let hook = |i: usize| c.projects[i].on_success.clone().unwrap();
        assert_eq!(hook(0).argv, ["deploy", "{src}"]);
        assert_eq!(hook(0).timeout, Duration::from_secs(30));
        // A relative program path is the configuration folder's.
        assert_eq!(hook(1).argv, ["/etc/skillpost/bin/copy", "{outputs}"]);
        assert_eq!(hook(2).argv, ["deploy", "{src}"]);
        assert_eq!(hook(2).timeout, Duration::from_secs(5));
        assert_eq!(c.roots[0].on_success, c.on_success);
        assert_eq!(
            c.roots[0].project("/srv/R/x".into()).on_success,
            c.on_success
        );
        // Without any: none, and the default timeout for a hook without one.
        let c = parse("on_success = [\"true\"]\n", &file()).unwrap();
        assert_eq!(c.on_success.unwrap().timeout, Duration::from_secs(60));
        for (text, at, says) in [
            ("on_success = []\n", (1, 14), "empty"),
            (
                "on_success = [\"cp\", \"{sauce}\"]\n",
                (1, 14),
                "unknown placeholder",
            ),
            ("deploy_timeout_s = 0\n", (1, 20), "1..=3600"),
            (
                "[[project]]\npath = \"/a\"\non_success = [\"cp\", \"x{outputs}\"]\n",
                (3, 14),
                "whole argument",
            ),
            (
                "on_success = \"deploy {src}\"\n",
                (1, 14),
                "list of strings",
            ),
        ] {
            let e = err(text);
            assert_eq!((e.line, e.column), (Some(at.0), Some(at.1)), "{text}: {e}");
            assert!(e.message.contains(says), "{text}: {e}");
        }
    }

    #[test]
    fn merge_precedence() {
        let cwd = std::env::current_dir().unwrap();
        let file = Config {
            file: Some("/etc/s.toml".into()),
            events: Some("/var/log/e.jsonl".into()),
            settle_ms: Some(300),
            allow_outside: true,
            max_file_size_mb: None,
            forget_after_s: None,
            template: None,
            lf: false,
            pou: None,
            on_success: None,
            picture: false,
            projects: vec![ProjectSpec {
                path: "/srv/A".into(),
                blackboard: Some("A.aml".into()),
                program: Some("PA".into()),
                ..ProjectSpec::default()
            }],
            roots: vec![root("/srv/root")],
        };

        // Nothing on the command line: the file as is.
        assert_eq!(merge(Some(file.clone()), &[], None, None), file);

        let m = merge(
            Some(file.clone()),
            &["/srv/A".into(), "rel/B".into(), "/srv/C/".into()],
            Some("ev.jsonl".into()),
            Some(50),
        );
        assert_eq!(m.events, Some(cwd.join("ev.jsonl")));
        assert_eq!(m.settle_ms, Some(50));
        assert!(m.allow_outside);
        assert_eq!(m.roots, file.roots);
        assert_eq!(m.file, file.file);
        assert_eq!(
            m.projects,
            vec![
                file.projects[0].clone(),
                spec(&cwd.join("rel/B")),
                spec(Path::new("/srv/C")),
            ]
        );

        // No file: only the command line.
        let m = merge(None, &["x".into()], None, None);
        assert_eq!(
            m,
            Config {
                projects: vec![spec(&cwd.join("x"))],
                ..Config::default()
            }
        );
    }

    #[test]
    fn settle_is_capped() {
        let c = Config {
            settle_ms: Some(10_000_000),
            ..Config::default()
        };
        assert_eq!(c.settle(), Duration::from_millis(60_000));
        let c = Config {
            settle_ms: Some(0),
            ..Config::default()
        };
        assert_eq!(c.settle(), Duration::from_millis(1));
    }

    #[test]
    fn blackboard_names() {
        assert!(is_blackboard_name(OsStr::new("a.aml")));
        assert!(is_blackboard_name(OsStr::new("A.AmL")));
        assert!(!is_blackboard_name(OsStr::new(".aml")));
        assert!(!is_blackboard_name(OsStr::new(".#a.aml")));
        assert!(!is_blackboard_name(OsStr::new("a.aml~")));
        assert!(!is_blackboard_name(OsStr::new("a.aml.swp")));
        assert!(!is_blackboard_name(OsStr::new("ä.xml")));
        assert!(is_blackboard_name(OsStr::new("Zelle_ä.aml")));
    }
}
