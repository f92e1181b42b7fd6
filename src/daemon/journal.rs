//! The log's lines about compiles (stderr, i.e. the journal under systemd): one line per
//! compile outcome, so a person at a terminal (or `journalctl -u skillpost`) sees what happened
//! without reading the event stream, as `cargo watch` and `typst watch` print:
//!
//! - `compile-succeeded`: `info`, `<project> compiled in 3 ms: P.src, P.dat` (the outputs'
//!   file names; `(unchanged)` after those whose bytes were already right; `, 2 warnings`);
//! - `compile-failed`: `warn`, `compile failed: <project>: E311 sfc.xml:74:66: <message>` (the
//!   first error; a file inside the project folder by its relative name) and `(and N more
//!   errors)`: the form DAEMON-INSTALL.md documents (and scripts may grep), kept;
//! - `write-back` that was skipped: `warn`, `<project>: write-back into <file> skipped: <why>`;
//!   one that waited for another program to close the blackboard: `info`, with how long;
//! - `deploy-succeeded`: `info`, `<project>: deployed <program> (controller <c>) in 80 ms`;
//! - `deploy-failed`: `warn`, `<project>: deploy of <program> (controller <c>) failed: <why>:
//!   <the hook's last stderr line>`;
//! - `reload-failed`: `error`, `reload failed, keeping the previous configuration: ...`.
//!
//! Each is one line (a message's line breaks become spaces). A compile's lines are inside the
//! span `compile` with `project` and `run_id` (set by the event loop around each compile), and
//! carry `run_id`, `code` or `duration_ms` as fields, so `--log-format json` carries them too.

use serde_json::Value;

use super::events::Event;
use super::state::describe;

/// One line: line breaks in a message become spaces, and every other control character is
/// written escaped (`\u{1b}`): a folder named with an escape sequence cannot recolour or rewrite
/// a terminal or the journal.
fn one_line(s: &str) -> String {
    super::state::printable(
        &s.split(['\n', '\r'])
            .filter(|l| !l.trim().is_empty())
            .map(str::trim)
            .collect::<Vec<_>>()
            .join(" "),
    )
    .into_owned()
}

/// A path as the line shows it: relative to the project folder when inside it.
fn short(project: &str, path: &str) -> String {
    std::path::Path::new(path)
        .strip_prefix(project)
        .ok()
        .filter(|r| !r.as_os_str().is_empty())
        .map_or_else(|| path.to_owned(), |r| r.display().to_string())
}

/// Logs the outcomes among the events (called for every event as it is emitted).
pub fn log(project: Option<&str>, event: &Event) {
    let name = project.unwrap_or("?");
    match event {
        Event::CompileSucceeded {
            run_id,
            duration_ms,
            outputs,
            stale,
            counts,
            ..
        } => {
            let files: Vec<String> = outputs
                .iter()
                .map(|o| {
                    let f = short(name, &o.path);
                    if o.written {
                        f
                    } else {
                        format!("{f} (unchanged)")
                    }
                })
                .collect();
            let warnings = match counts.warnings {
                0 => String::new(),
                1 => ", 1 warning".to_owned(),
                n => format!(", {n} warnings"),
            };
            let stale = if stale.is_empty() {
                String::new()
            } else {
                let files: Vec<String> = stale.iter().map(|f| short(name, f)).collect();
                format!(
                    "; stale, not written (a renamed program?): {}",
                    files.join(", ")
                )
            };
            tracing::info!(
                project = name,
                run_id,
                duration_ms,
                "{name} compiled in {duration_ms} ms: {}{warnings}{stale}",
                files.join(", ")
            );
        }
        Event::CompileFailed {
            run_id,
            diagnostics,
            duration_ms,
        } => {
            let errors: Vec<&Value> = diagnostics
                .iter()
                .filter(|d| d.get("severity").and_then(Value::as_str) != Some("warning"))
                .collect();
            let first: Option<&Value> = errors.first().copied().or(diagnostics.first());
            let code = first
                .and_then(|d| d.get("code"))
                .and_then(Value::as_str)
                .unwrap_or("");
            let what = first.map_or_else(String::new, |d| {
                let mut d = d.clone();
                if let Some(f) = d
                    .get("file")
                    .and_then(Value::as_str)
                    .map(|f| short(name, f))
                {
                    d["file"] = Value::String(f);
                }
                one_line(&describe(&d))
            });
            let more = match errors.len() {
                0 | 1 => String::new(),
                n => format!(
                    " (and {} more error{})",
                    n - 1,
                    if n == 2 { "" } else { "s" }
                ),
            };
            tracing::warn!(
                project = name,
                run_id,
                code,
                duration_ms,
                "compile failed: {name}: {what}{more}"
            );
        }
        Event::WriteBack {
            run_id,
            file,
            reason,
            skipped,
            waited_ms,
            ..
        } => {
            let waited = waited_ms.map_or_else(String::new, |ms| {
                format!(" after waiting {ms} ms for another program to close it")
            });
            if *skipped {
                tracing::warn!(
                    project = name,
                    run_id,
                    "{name}: write-back into {} skipped{waited}: {}",
                    short(name, file),
                    one_line(reason.as_deref().unwrap_or("")),
                );
            } else if waited_ms.is_some() {
                tracing::info!(
                    project = name,
                    run_id,
                    "{name}: wrote back into {}{waited}",
                    short(name, file),
                );
            }
        }
        Event::DeploySucceeded {
            run_id,
            program,
            controller,
            duration_ms,
            ..
        } => {
            tracing::info!(
                project = name,
                run_id,
                duration_ms,
                "{name}: deployed {program}{} in {duration_ms} ms",
                controller
                    .as_deref()
                    .map_or_else(String::new, |c| format!(" (controller {c})")),
            );
        }
        Event::DeployFailed {
            run_id,
            program,
            controller,
            reason,
            stderr,
            ..
        } => {
            tracing::warn!(
                project = name,
                run_id,
                "{name}: deploy of {program}{} failed: {}",
                controller
                    .as_deref()
                    .map_or_else(String::new, |c| format!(" (controller {c})")),
                one_line(&Event::deploy_failure(reason, stderr)),
            );
        }
        Event::SimulationSucceeded {
            run_id,
            runs,
            cycle_s,
            ..
        } => {
            tracing::info!(
                project = name,
                run_id,
                "{name}: simulated {runs} run(s), no problem{}",
                cycle_s.map_or_else(String::new, |c| format!("; cycle time {c:.2} s")),
            );
        }
        Event::SimulationFailed {
            run_id,
            problems,
            kind,
            message,
            file,
            line,
            ..
        } => {
            let at = match (file, line) {
                (Some(f), Some(l)) => format!(" [{f}:{l}]"),
                _ => String::new(),
            };
            tracing::warn!(
                project = name,
                run_id,
                "{name}: simulation found {problems} problem(s), first {kind}: {}{at}",
                one_line(message),
            );
        }
        Event::ReloadFailed {
            error,
            file,
            line,
            column,
        } => {
            let mut at = file.clone().unwrap_or_default();
            for n in [line, column].into_iter().flatten() {
                at.push_str(&format!(":{n}"));
            }
            let at = if at.is_empty() { at } else { format!("{at}: ") };
            tracing::error!(
                "reload failed, keeping the previous configuration: {at}{}",
                one_line(error)
            );
        }
        _ => {}
    }
}

/// The `--log-format human` line: `<time> <LEVEL> <message>` and, except on the compile lines
/// above (whose message says it all), the event's other fields as `key=value`. No span and no
/// module name: a person reads it. One line per event (line breaks in a field become spaces).
///
/// - On a terminal the level is coloured; nowhere else (a file, a pipe, the journal).
/// - When stderr is the journal (systemd's `JOURNAL_STREAM` names it), the time is left out
///   (the journal has its own) and each line starts with its syslog priority (`<4>` for a
///   warning, `<3>` for an error, `<6>` info, `<7>` debug), which journald takes as the line's
///   priority and strips: `journalctl -u skillpost -p warning` lists the failures.
pub struct Human {
    ansi: bool,
    journal: bool,
}

impl Human {
    /// The format for this process's stderr.
    pub fn for_stderr() -> Self {
        use std::io::IsTerminal as _;
        Human {
            ansi: std::io::stderr().is_terminal(),
            journal: stderr_is_journal(),
        }
    }

    /// A given format (tests).
    pub fn with(ansi: bool, journal: bool) -> Self {
        Human { ansi, journal }
    }
}

/// Whether stderr is the journal's stream: `JOURNAL_STREAM` is `<device>:<inode>` of it.
fn stderr_is_journal() -> bool {
    let Some(v) = std::env::var_os("JOURNAL_STREAM") else {
        return false;
    };
    let Ok(st) = rustix::fs::fstat(std::io::stderr()) else {
        return false;
    };
    v.to_string_lossy() == format!("{}:{}", st.st_dev, st.st_ino)
}

/// Collects an event's message and other fields.
#[derive(Default)]
struct Fields {
    message: String,
    rest: String,
}

impl tracing::field::Visit for Fields {
    fn record_str(&mut self, field: &tracing::field::Field, value: &str) {
        if field.name() == "message" {
            self.message = value.to_owned();
        } else {
            self.rest.push_str(&format!(" {}={value:?}", field.name()));
        }
    }

    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.message = format!("{value:?}");
        } else {
            self.rest.push_str(&format!(" {}={value:?}", field.name()));
        }
    }
}

impl<S, N> tracing_subscriber::fmt::FormatEvent<S, N> for Human
where
    S: tracing::Subscriber + for<'a> tracing_subscriber::registry::LookupSpan<'a>,
    N: for<'a> tracing_subscriber::fmt::FormatFields<'a> + 'static,
{
    fn format_event(
        &self,
        _ctx: &tracing_subscriber::fmt::FmtContext<'_, S, N>,
        mut w: tracing_subscriber::fmt::format::Writer<'_>,
        event: &tracing::Event<'_>,
    ) -> std::fmt::Result {
        use tracing::Level;
        let meta = event.metadata();
        let level = *meta.level();
        let mut f = Fields::default();
        event.record(&mut f);
        if meta.target() == module_path!() {
            // The compile lines: their fields are for `--log-format json`.
            f.rest.clear();
        }
        let (name, priority, colour) = match level {
            Level::ERROR => ("ERROR", 3, "31"),
            Level::WARN => ("WARN", 4, "33"),
            Level::INFO => ("INFO", 6, "32"),
            Level::DEBUG => ("DEBUG", 7, "34"),
            Level::TRACE => ("TRACE", 7, "35"),
        };
        let text = one_line(&format!("{}{}", f.message, f.rest));
        if self.journal {
            return writeln!(w, "<{priority}>{name} {text}");
        }
        let now = humantime::format_rfc3339_millis(std::time::SystemTime::now());
        if self.ansi {
            writeln!(w, "{now} \x1b[{colour}m{name:>5}\x1b[0m {text}")
        } else {
            writeln!(w, "{now} {name:>5} {text}")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    #[derive(Clone, Default)]
    struct Buf(Arc<Mutex<Vec<u8>>>);

    impl std::io::Write for Buf {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// The log lines `f` makes in the `human` format.
    fn lines(format: Human, f: impl FnOnce()) -> Vec<String> {
        let buf = Buf::default();
        let out = buf.clone();
        let sub = tracing_subscriber::fmt()
            .with_writer(move || out.clone())
            .event_format(format)
            .finish();
        tracing::subscriber::with_default(sub, f);
        let text = String::from_utf8(buf.0.lock().unwrap().clone()).unwrap();
        text.lines().map(str::to_owned).collect()
    }

    fn failure() -> Event {
        Event::CompileFailed {
            run_id: 2,
            duration_ms: 3,
            diagnostics: vec![serde_json::json!({
                "severity": "error", "code": "E311", "file": "/p/P/sfc.xml",
                "line": 74, "column": 66, "message": "unknown resource\n`Gripper`"
            })],
        }
    }

    #[test]
    fn in_the_journal_a_line_has_its_priority_and_no_time() {
        let l = lines(Human::with(false, true), || {
            let span = tracing::warn_span!("compile", project = "/p/P", run_id = 2);
            let _e = span.enter();
            log(Some("/p/P"), &failure());
            tracing::info!(reason = "SIGTERM", "stopped");
        });
        assert_eq!(
            l,
            [
                "<4>WARN compile failed: /p/P: E311 sfc.xml:74:66: unknown resource `Gripper`",
                "<6>INFO stopped reason=\"SIGTERM\"",
            ]
        );
    }

    #[test]
    fn on_a_terminal_only_the_level_is_coloured() {
        let l = lines(Human::with(true, false), || log(Some("/p/P"), &failure()));
        assert_eq!(l.len(), 1);
        assert!(
            l[0].ends_with(
                " \x1b[33m WARN\x1b[0m compile failed: /p/P: E311 sfc.xml:74:66: unknown resource `Gripper`"
            ),
            "{:?}",
            l[0]
        );
        let plain = lines(Human::with(false, false), || log(Some("/p/P"), &failure()));
        assert!(!plain[0].contains('\x1b'));
        assert!(humantime::parse_rfc3339(plain[0].split(' ').next().unwrap()).is_ok());
    }
}
