//! The event stream (SPEC.md section 7, "Events"): one JSON object per line, flushed per line,
//! on stdout or appended to a file. Every event carries the envelope `schema`, `ts` (RFC 3339,
//! UTC), `seq` (per-process counter), `event`, `level`, and `project` where one applies.

use std::io::Write;
use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

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

    /// Emits one event. `fields` must be a JSON object (or null); its keys follow the envelope.
    pub fn emit(&self, event: &str, level: Level, project: Option<&str>, fields: Value) {
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
        obj.insert("event".into(), json!(event));
        obj.insert("level".into(), json!(level.as_str()));
        if let Some(p) = project {
            obj.insert("project".into(), json!(p));
        }
        if let Value::Object(f) = fields {
            // Absent is clearer than null in a log that people read.
            for (k, v) in f.into_iter().filter(|(_, v)| !v.is_null()) {
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
            "started",
            Level::Info,
            None,
            json!({"version": "x", "config": null}),
        );
        sink.emit(
            "compile-failed",
            Level::Error,
            Some("A"),
            json!({"run_id": 3}),
        );
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
