//! The configuration file read and checked: [`load`], [`parse`], the error they give
//! ([`ConfigError`], located by line and column) and the file's raw TOML shape.

use std::fmt;
use std::ops::{Range, RangeInclusive};
use std::path::{Component, Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use super::{
    Config, FORGET_AFTER_S_RANGE, MAX_CONFIG_SIZE, MAX_FILE_SIZE_MB_RANGE, MAX_SIMULATE_RUNS,
    ProjectSpec, RootSpec, SETTLE_MS_RANGE, Simulate, check_program, hook_from_a_planners_folder,
    too_long,
};
use crate::paths::{absolute, normalize};

/// `simulate = N` (0: none) or `simulate = "FILE"` (a file in the project folder).
fn simulate_setting(v: &Spanned<toml::Value>) -> Result<Option<Simulate>, String> {
    match v.get_ref() {
        toml::Value::Integer(0) | toml::Value::Boolean(false) => Ok(None),
        toml::Value::Integer(n) if (1..=MAX_SIMULATE_RUNS).contains(n) => {
            Ok(Some(Simulate::Runs(*n as usize)))
        }
        toml::Value::String(f) => {
            let path = Path::new(f.trim());
            if f.trim().is_empty()
                || path.is_absolute()
                || path
                    .components()
                    .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir))
            {
                Err(format!(
                    "`simulate` names a scenario file in the project folder (`shift.toml`, \
                     `sim/shift.toml`), not `{f}`"
                ))
            } else {
                Ok(Some(Simulate::Scenario(path.to_path_buf())))
            }
        }
        _ => Err(format!(
            "`simulate` is a number of random runs (1 to {MAX_SIMULATE_RUNS}; 0: none) or a \
             scenario file in the project folder"
        )),
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
    let max_lines = match &raw.max_lines {
        Some(v) => split_limits(v, crate::emit::split::Limits::default())
            .map_err(|m| at(Some(v.span()), m))?,
        None => crate::emit::split::Limits::default(),
    };
    let simulate = match &raw.simulate {
        Some(v) => simulate_setting(v).map_err(|m| at(Some(v.span()), m))?,
        None => None,
    };
    let own_simulate = |v: &Option<Spanned<toml::Value>>| match v {
        Some(v) => simulate_setting(v).map_err(|m| at(Some(v.span()), m)),
        None => Ok(simulate.clone()),
    };
    let own_limits = |v: &Option<Spanned<toml::Value>>| match v {
        Some(v) => split_limits(v, max_lines).map_err(|m| at(Some(v.span()), m)),
        None => Ok(max_lines),
    };
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

    // A whole number key within its range (`settle_ms` is 0, expected 1..=60000 (milliseconds)).
    let ranged = |v: &Option<Spanned<i64>>,
                  key: &str,
                  range: &RangeInclusive<u64>,
                  unit: &str|
     -> Result<Option<u64>, ConfigError> {
        let Some(v) = v else { return Ok(None) };
        let n = *v.get_ref();
        match u64::try_from(n) {
            Ok(n) if range.contains(&n) => Ok(Some(n)),
            _ => Err(at(
                Some(v.span()),
                format!(
                    "`{key}` is {n}, expected {}..={} ({unit})",
                    range.start(),
                    range.end()
                ),
            )),
        }
    };
    let settle_ms = ranged(
        &raw.settle_ms,
        "settle_ms",
        &SETTLE_MS_RANGE,
        "milliseconds",
    )?;
    let max_file_size_mb = ranged(
        &raw.max_file_size_mb,
        "max_file_size_mb",
        &MAX_FILE_SIZE_MB_RANGE,
        "MiB",
    )?;
    let forget_after_s = ranged(
        &raw.forget_after_s,
        "forget_after_s",
        &FORGET_AFTER_S_RANGE,
        "seconds",
    )?;
    let max_deploys = ranged(
        &raw.max_deploys,
        "max_deploys",
        &crate::daemon::deploy::MAX_DEPLOYS_RANGE,
        "deploy hooks at once",
    )?
    .map(|n| n as usize);

    // The deploy hook: checked where it is written; a timeout of its own or the global one.
    let timeout_of =
        |t: &Option<Spanned<i64>>, default: Duration| -> Result<Duration, ConfigError> {
            Ok(ranged(
                t,
                "deploy_timeout_s",
                &crate::daemon::deploy::DEPLOY_TIMEOUT_S_RANGE,
                "seconds",
            )?
            .map_or(default, Duration::from_secs))
        };
    let global_timeout = timeout_of(
        &raw.deploy_timeout_s,
        Duration::from_secs(crate::daemon::deploy::DEFAULT_DEPLOY_TIMEOUT_S),
    )?;
    let hook = |h: &Spanned<Vec<String>>,
                timeout: Duration|
     -> Result<crate::daemon::deploy::Hook, ConfigError> {
        crate::daemon::deploy::check(h.get_ref()).map_err(|m| at(Some(h.span()), m))?;
        let mut argv = h.get_ref().clone();
        argv[0] = crate::daemon::deploy::program_path(&argv[0], &base);
        Ok(crate::daemon::deploy::Hook { argv, timeout })
    };
    let on_success = raw
        .on_success
        .as_ref()
        .map(|h| hook(h, global_timeout))
        .transpose()?;
    // A project's or root's own hook, else the global one (with its own timeout, if set).
    let own_hook = |h: &Option<Spanned<Vec<String>>>,
                    t: &Option<Spanned<i64>>|
     -> Result<Option<crate::daemon::deploy::Hook>, ConfigError> {
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
            max_lines: own_limits(&p.max_lines)?,
            on_success: own_hook(&p.on_success, &p.deploy_timeout_s)?,
            picture: p.picture.unwrap_or(raw.picture),
            simulate: own_simulate(&p.simulate)?,
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
            max_lines: own_limits(&r.max_lines)?,
            on_success: own_hook(&r.on_success, &r.deploy_timeout_s)?,
            picture: r.picture.unwrap_or(raw.picture),
            simulate: own_simulate(&r.simulate)?,
        });
    }

    let config = Config {
        file: Some(file.clone()),
        events,
        settle_ms,
        allow_outside: raw.allow_outside,
        max_file_size_mb,
        forget_after_s,
        max_deploys,
        template,
        lf,
        pou,
        max_lines,
        on_success,
        picture: raw.picture,
        simulate,
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

/// `max_lines`: a number of lines for every language (0 never splits), or a table of them by
/// language (`{ krl = 3000, rapid = 0 }`), over `base`.
fn split_limits(
    value: &Spanned<toml::Value>,
    base: crate::emit::split::Limits,
) -> Result<crate::emit::split::Limits, String> {
    let number = |k: &str, v: &toml::Value| -> Result<String, String> {
        match v.as_integer() {
            Some(n) if n >= 0 => Ok(n.to_string()),
            _ => Err(format!(
                "`max_lines`{k} is {v}, expected a number of lines (0 never splits)"
            )),
        }
    };
    let mut limits = base;
    match value.get_ref() {
        toml::Value::Table(t) => {
            for (k, v) in t {
                let n = number(&format!(".{k}"), v)?;
                limits
                    .set(&format!("{k}={n}"))
                    .map_err(|m| format!("`max_lines.{k}`: {m}"))?;
            }
        }
        v => limits.set(&number("", v)?)?,
    }
    Ok(limits)
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
    max_lines: Option<Spanned<toml::Value>>,
    settle_ms: Option<Spanned<i64>>,
    #[serde(default)]
    allow_outside: bool,
    max_file_size_mb: Option<Spanned<i64>>,
    forget_after_s: Option<Spanned<i64>>,
    max_deploys: Option<Spanned<i64>>,
    on_success: Option<Spanned<Vec<String>>>,
    deploy_timeout_s: Option<Spanned<i64>>,
    #[serde(default)]
    picture: bool,
    simulate: Option<Spanned<toml::Value>>,
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
    max_lines: Option<Spanned<toml::Value>>,
    on_success: Option<Spanned<Vec<String>>>,
    deploy_timeout_s: Option<Spanned<i64>>,
    picture: Option<bool>,
    simulate: Option<Spanned<toml::Value>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRoot {
    path: Spanned<String>,
    program: Option<Spanned<String>>,
    template: Option<Spanned<String>>,
    line_endings: Option<Spanned<String>>,
    pou: Option<String>,
    max_lines: Option<Spanned<toml::Value>>,
    on_success: Option<Spanned<Vec<String>>>,
    deploy_timeout_s: Option<Spanned<i64>>,
    picture: Option<bool>,
    simulate: Option<Spanned<toml::Value>>,
}
