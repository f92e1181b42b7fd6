//! The event stream (SPEC.md section 7, "Events"): one JSON object per line, flushed per line,
//! on stdout or appended to a file. Every event carries the envelope `schema`, `ts` (RFC 3339,
//! UTC), `seq` (per-process counter), `event`, `level`, and `project` where one applies.
//!
//! Every event the daemon can emit is a variant of [`Event`]; [`EventSink::emit`] is the one
//! place that turns one into a line. docs/DAEMON.md's event table lists the same names and
//! fields (a test keeps the two in sync).

use std::io::Write;
use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use serde::Serialize;
use serde_json::{Map, Value, json};

/// The schema name of every event; fields are only ever added within `/1`.
pub const SCHEMA: &str = "skillpost.event/1";

/// How important an event is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    Info,
    Warn,
    Error,
}

impl Level {
    fn as_str(self) -> &'static str {
        match self {
            Level::Info => "info",
            Level::Warn => "warn",
            Level::Error => "error",
        }
    }
}

/// One output of a successful compile.
#[derive(Debug, Clone, Serialize)]
pub struct OutputInfo {
    pub path: String,
    /// False when the file already held these bytes.
    pub written: bool,
}

/// The counts of a successful compile.
#[derive(Debug, Clone, Serialize)]
pub struct Counts {
    pub steps: usize,
    pub warnings: usize,
}

/// Every event of the `skillpost.event/1` stream. `None` fields are left out of the line.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "event", rename_all = "kebab-case")]
pub enum Event {
    Started {
        version: &'static str,
        pid: u32,
        config: Option<String>,
    },
    Watching {
        root: Option<String>,
        blackboard: Option<String>,
        backend: &'static str,
        /// Why a folder is watched again (it came back).
        reason: Option<String>,
    },
    WatchDegraded {
        root: Option<String>,
        reason: String,
        backend: Option<&'static str>,
    },
    Rescan {
        reason: String,
        projects: Option<usize>,
        error: Option<String>,
    },
    ChangeDetected {
        paths: Vec<String>,
    },
    CompileStarted {
        run_id: u64,
        trigger: &'static str,
        changed: Vec<String>,
    },
    CompileSucceeded {
        run_id: u64,
        duration_ms: u64,
        outputs: Vec<OutputInfo>,
        counts: Counts,
        /// Diagnostics as `--format json` prints them.
        warnings: Vec<Value>,
    },
    CompileFailed {
        run_id: u64,
        duration_ms: u64,
        /// Diagnostics as `--format json` prints them.
        diagnostics: Vec<Value>,
    },
    WriteBack {
        run_id: u64,
        file: String,
        value: String,
        written: bool,
        reason: Option<String>,
        /// The write-back did not happen although the value was wrong (a `warn` event).
        #[serde(skip)]
        skipped: bool,
    },
    Reloaded {
        projects: usize,
        added: Vec<String>,
        removed: Vec<String>,
    },
    ReloadFailed {
        error: String,
        file: Option<String>,
        line: Option<usize>,
        column: Option<usize>,
    },
    Stopped {
        reason: String,
    },
}

impl Event {
    /// The event's name, as in the line's `event` field.
    pub fn name(&self) -> &'static str {
        match self {
            Event::Started { .. } => "started",
            Event::Watching { .. } => "watching",
            Event::WatchDegraded { .. } => "watch-degraded",
            Event::Rescan { .. } => "rescan",
            Event::ChangeDetected { .. } => "change-detected",
            Event::CompileStarted { .. } => "compile-started",
            Event::CompileSucceeded { .. } => "compile-succeeded",
            Event::CompileFailed { .. } => "compile-failed",
            Event::WriteBack { .. } => "write-back",
            Event::Reloaded { .. } => "reloaded",
            Event::ReloadFailed { .. } => "reload-failed",
            Event::Stopped { .. } => "stopped",
        }
    }

    /// The event's level.
    pub fn level(&self) -> Level {
        match self {
            Event::WatchDegraded { .. } => Level::Warn,
            Event::Rescan { reason, .. } if reason != "startup" => Level::Warn,
            Event::WriteBack { skipped: true, .. } => Level::Warn,
            Event::CompileFailed { .. } | Event::ReloadFailed { .. } => Level::Error,
            _ => Level::Info,
        }
    }

    /// A `compile-failed` event with one diagnostic of our own (not from the compiler).
    pub fn failed_with(run_id: u64, duration_ms: u64, code: &str, message: String) -> Event {
        Event::CompileFailed {
            run_id,
            duration_ms,
            diagnostics: vec![json!({"severity": "error", "code": code, "message": message})],
        }
    }
}

/// Where events go. Shared by the daemon's tasks.
pub struct EventSink {
    out: Mutex<Box<dyn Write + Send>>,
    seq: AtomicU64,
}

impl EventSink {
    /// Events on stdout.
    pub fn stdout() -> Self {
        Self::to(Box::new(std::io::stdout()))
    }

    /// Events appended to a file (created if missing).
    pub fn append(path: &Path) -> std::io::Result<Self> {
        let f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)?;
        Ok(Self::to(Box::new(f)))
    }

    /// Events into any writer (tests).
    pub fn to(out: Box<dyn Write + Send>) -> Self {
        EventSink {
            out: Mutex::new(out),
            seq: AtomicU64::new(0),
        }
    }

    /// Emits one event: the envelope, then the event's fields (those that are `None` left out).
    pub fn emit(&self, project: Option<&str>, event: Event) {
        let fields = serde_json::to_value(&event).unwrap_or(Value::Null);
        let mut obj = Map::new();
        obj.insert("schema".into(), json!(SCHEMA));
        obj.insert(
            "ts".into(),
            json!(humantime::format_rfc3339_millis(std::time::SystemTime::now()).to_string()),
        );
        // The counter and the write happen under one lock, so `seq` grows line by line.
        let mut out = self.out.lock().unwrap_or_else(|p| p.into_inner());
        obj.insert(
            "seq".into(),
            json!(self.seq.fetch_add(1, Ordering::Relaxed) + 1),
        );
        obj.insert("event".into(), json!(event.name()));
        obj.insert("level".into(), json!(event.level().as_str()));
        if let Some(p) = project {
            obj.insert("project".into(), json!(p));
        }
        if let Value::Object(f) = fields {
            // Absent is clearer than null in a log that people read.
            for (k, v) in f.into_iter().filter(|(k, v)| k != "event" && !v.is_null()) {
                obj.insert(k, v);
            }
        }
        let mut line = serde_json::to_string(&Value::Object(obj)).unwrap_or_default();
        line.push('\n');
        // A failing event stream must not stop the daemon; the error goes to the log.
        if let Err(e) = out.write_all(line.as_bytes()).and_then(|_| out.flush()) {
            tracing::error!("cannot write the event stream: {e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[derive(Clone, Default)]
    struct Buf(Arc<Mutex<Vec<u8>>>);

    impl Write for Buf {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn envelope_and_sequence() {
        let buf = Buf::default();
        let sink = EventSink::to(Box::new(buf.clone()));
        sink.emit(
            None,
            Event::Started {
                version: "x",
                pid: 1,
                config: None,
            },
        );
        sink.emit(Some("A"), Event::failed_with(3, 0, "E101", "gone".into()));
        let text = String::from_utf8(buf.0.lock().unwrap().clone()).unwrap();
        let lines: Vec<Value> = text
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(lines.len(), 2);
        assert_eq!(lines[0]["schema"], SCHEMA);
        assert_eq!(lines[0]["seq"], 1);
        assert_eq!(lines[1]["seq"], 2);
        assert_eq!(lines[0]["event"], "started");
        assert_eq!(lines[0]["version"], "x");
        assert_eq!(lines[1]["event"], "compile-failed");
        assert_eq!(lines[1]["diagnostics"][0]["code"], "E101");
        assert!(lines[0].get("project").is_none());
        assert!(lines[0].get("config").is_none(), "nulls are left out");
        // The envelope comes first.
        assert!(
            text.starts_with("{\"schema\":\"skillpost.event/1\",\"ts\":"),
            "{text}"
        );
        assert_eq!(lines[1]["project"], "A");
        assert_eq!(lines[1]["level"], "error");
        let ts = lines[0]["ts"].as_str().unwrap();
        assert!(ts.ends_with('Z') && ts.len() == 24, "{ts}");
        assert!(humantime::parse_rfc3339(ts).is_ok());
    }
}
