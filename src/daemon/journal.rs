//! Failures in the journal: `compile-failed` and `reload-failed` are also logged through
//! `tracing` (stderr, i.e. the journal under systemd), one line each, so `journalctl -u
//! skillpost -p warning` shows them without the event stream. A compile's lines are inside the
//! span `compile` with `project` and `run_id` (set by the event loop around each compile), so
//! `--log-format json` carries both.

use serde_json::Value;

use super::events::Event;
use super::state::describe;

/// Logs the failures among the events (called for every event as it is emitted).
pub fn log(project: Option<&str>, event: &Event) {
    match event {
        Event::CompileFailed {
            run_id,
            diagnostics,
            ..
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
            let what = first.map_or_else(String::new, describe);
            let more = match errors.len() {
                0 | 1 => String::new(),
                n => format!(
                    " (and {} more error{})",
                    n - 1,
                    if n == 2 { "" } else { "s" }
                ),
            };
            tracing::warn!(
                project = project.unwrap_or(""),
                run_id,
                code,
                "compile failed: {}: {what}{more}",
                project.unwrap_or("?")
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
            tracing::error!("reload failed, keeping the previous configuration: {at}{error}");
        }
        _ => {}
    }
}
