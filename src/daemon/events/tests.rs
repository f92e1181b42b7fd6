//! The unit tests of the event types and of the sink.

use super::*;
use std::collections::BTreeSet;
use std::io::Write;
use std::sync::mpsc;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use serde_json::Value;

use super::MemOut as Buf;
use super::sink::{Kind, Output, Plain};

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
    assert_eq!(sink.flush(Duration::from_secs(5)), 0);
    let text = String::from_utf8(buf.0.lock().unwrap().clone()).unwrap();
    let lines: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 2);
    assert_eq!(lines[0]["schema"], SCHEMA);
    assert_eq!(lines[0]["seq"], 1);
    assert_eq!(lines[1]["seq"], 2);
    // One run, one instance; another sink (the next run) has another.
    assert_eq!(lines[0]["instance"], sink.instance());
    assert_eq!(lines[1]["instance"], sink.instance());
    let next = EventSink::to(Box::new(Buf::default()));
    assert_ne!(next.instance(), sink.instance());
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
    let keys: Vec<&str> = lines[1]
        .as_object()
        .unwrap()
        .keys()
        .map(String::as_str)
        .collect();
    assert_eq!(
        keys,
        [
            "schema",
            "ts",
            "seq",
            "instance",
            "event",
            "level",
            "project",
            "run_id",
            "duration_ms",
            "diagnostics"
        ]
    );
    assert_eq!(lines[1]["level"], "error");
    let ts = lines[0]["ts"].as_str().unwrap();
    assert!(ts.ends_with('Z') && ts.len() == 24, "{ts}");
    assert!(humantime::parse_rfc3339(ts).is_ok());
}

fn started() -> Event {
    Event::Started {
        version: "x",
        pid: 1,
        config: None,
    }
}

fn lines_of(bytes: &[u8]) -> Vec<String> {
    String::from_utf8(bytes.to_vec())
        .unwrap()
        .lines()
        .map(str::to_owned)
        .collect()
}

fn json_lines(bytes: &[u8]) -> Vec<Value> {
    lines_of(bytes)
        .iter()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect()
}

/// `seq` grows line by line; every gap is accounted for by `events-dropped` (the sum of
/// their counts equals the sum of the gaps).
fn check_seq(lines: &[Value]) -> u64 {
    let mut gaps = 0;
    let mut reported = 0;
    let mut last = 0;
    for l in lines {
        let seq = l["seq"].as_u64().unwrap();
        assert!(seq > last, "seq {seq} after {last}");
        gaps += seq - last - 1;
        last = seq;
        if l["event"] == "events-dropped" {
            assert_eq!(l["level"], "warn");
            reported += l["count"].as_u64().unwrap();
        }
    }
    assert_eq!(gaps, reported, "gaps in seq = events-dropped counts");
    reported
}

/// A writer that blocks in its first `write` until released (a stalled reader).
struct Gate {
    entered: mpsc::Sender<()>,
    open: Arc<(Mutex<bool>, Condvar)>,
    buf: Buf,
}

impl Write for Gate {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        let _ = self.entered.send(());
        let (m, cv) = &*self.open;
        let mut open = m.lock().unwrap();
        while !*open {
            open = cv.wait(open).unwrap();
        }
        self.buf.write(b)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[test]
fn a_full_queue_drops_counts_and_reports_once_caught_up() {
    let (tx, rx) = mpsc::channel();
    let open = Arc::new((Mutex::new(false), Condvar::new()));
    let buf = Buf::default();
    let gate = Gate {
        entered: tx,
        open: open.clone(),
        buf: buf.clone(),
    };
    let sink = EventSink::start(Box::new(Plain(Box::new(gate))), Kind::Custom, 8);
    // The first event is taken by the writer, which then hangs in `write`.
    sink.emit(None, started());
    rx.recv_timeout(Duration::from_secs(5)).unwrap();
    // 8 fit in the queue, 5 are dropped; emitting never waits.
    let t = Instant::now();
    for i in 0..13 {
        sink.emit(Some(&format!("P{i}")), started());
    }
    assert!(t.elapsed() < Duration::from_secs(1));
    // A stalled writer: flush gives up after its timeout.
    let t = Instant::now();
    assert_eq!(sink.flush(Duration::from_millis(200)), 9);
    assert!(t.elapsed() < Duration::from_secs(2));
    *open.0.lock().unwrap() = true;
    open.1.notify_all();
    assert_eq!(sink.flush(Duration::from_secs(5)), 0);
    let lines = json_lines(&buf.0.lock().unwrap());
    assert_eq!(lines.len(), 1 + 8 + 1, "{lines:?}");
    let dropped: Vec<&Value> = lines
        .iter()
        .filter(|l| l["event"] == "events-dropped")
        .collect();
    assert_eq!(dropped.len(), 1, "{lines:?}");
    assert_eq!(dropped[0]["count"], 5);
    assert_eq!(dropped[0]["reason"], "queue-full");
    assert!(dropped[0].get("project").is_none());
    assert_eq!(check_seq(&lines), 5);
    // The events after the drop follow it.
    sink.emit(None, started());
    assert_eq!(sink.flush(Duration::from_secs(5)), 0);
    let lines = json_lines(&buf.0.lock().unwrap());
    assert_eq!(lines.last().unwrap()["seq"], 16);
    check_seq(&lines);
}

#[test]
fn the_queue_is_bounded_in_bytes_too() {
    let (tx, rx) = mpsc::channel();
    let open = Arc::new((Mutex::new(false), Condvar::new()));
    let buf = Buf::default();
    let gate = Gate {
        entered: tx,
        open: open.clone(),
        buf: buf.clone(),
    };
    let sink = EventSink::start(Box::new(Plain(Box::new(gate))), Kind::Custom, 100);
    sink.emit(None, started());
    rx.recv_timeout(Duration::from_secs(5)).unwrap();
    let big = || Event::failed_with(1, 0, "E000", "x".repeat(MAX_QUEUE_BYTES / 2 + 1));
    sink.emit(Some("big1"), big());
    // Over the byte bound with the first one queued: dropped.
    sink.emit(Some("big2"), big());
    sink.emit(Some("small"), started());
    *open.0.lock().unwrap() = true;
    open.1.notify_all();
    assert_eq!(sink.flush(Duration::from_secs(5)), 0);
    let lines = json_lines(&buf.0.lock().unwrap());
    let projects: Vec<&str> = lines
        .iter()
        .map(|l| l["project"].as_str().unwrap_or("-"))
        .collect();
    assert_eq!(projects, ["-", "big1", "small", "-"]);
    assert_eq!(check_seq(&lines), 1);
}

/// A file-like output that fails on one write after accepting half of it, and can take
/// bytes back (like a file on a full disk).
struct HalfThenFail {
    buf: Buf,
    /// Which write (counting from 0) accepts half and then fails.
    fail_at: Vec<usize>,
    writes: usize,
    failing: bool,
    truncatable: bool,
}

impl Output for HalfThenFail {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        if self.failing {
            self.failing = false;
            return Err(std::io::Error::other("No space left on device"));
        }
        let n = self.writes;
        self.writes += 1;
        if self.fail_at.contains(&n) {
            // Half now, the error on the next call (as a full disk does).
            self.failing = true;
            let half = b.len() / 2;
            self.buf.0.lock().unwrap().extend_from_slice(&b[..half]);
            return Ok(half);
        }
        self.buf.0.lock().unwrap().extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
    fn unwrite(&mut self, n: u64) -> bool {
        if !self.truncatable {
            return false;
        }
        let mut v = self.buf.0.lock().unwrap();
        let len = v.len() - n as usize;
        v.truncate(len);
        true
    }
}

fn failing_sink(truncatable: bool) -> (EventSink, Buf) {
    let buf = Buf::default();
    let out = HalfThenFail {
        buf: buf.clone(),
        fail_at: vec![1, 3],
        writes: 0,
        failing: false,
        truncatable,
    };
    (
        EventSink::start(Box::new(out), Kind::Custom, DEFAULT_QUEUE),
        buf,
    )
}

#[test]
fn a_failed_write_is_taken_back() {
    let (sink, buf) = failing_sink(true);
    for i in 0..6 {
        sink.emit(Some(&format!("P{i}")), started());
        assert_eq!(sink.flush(Duration::from_secs(5)), 0);
    }
    // Every line whole. Lost: P1, then the first report of it (the 4th write); the second
    // report counts both.
    let lines = json_lines(&buf.0.lock().unwrap());
    assert_eq!(check_seq(&lines), 2);
    assert_eq!(
        lines.iter().filter(|l| l["event"] == "started").count(),
        5,
        "{lines:?}"
    );
    let dropped: Vec<&Value> = lines
        .iter()
        .filter(|l| l["event"] == "events-dropped")
        .collect();
    assert!(dropped.iter().all(|d| d["reason"] == "write-error"));
}

#[test]
fn a_failed_write_that_cannot_be_taken_back_is_ended_by_the_next_line() {
    let (sink, buf) = failing_sink(false);
    for i in 0..6 {
        sink.emit(Some(&format!("P{i}")), started());
        assert_eq!(sink.flush(Duration::from_secs(5)), 0);
    }
    let bytes = buf.0.lock().unwrap().clone();
    let lines = lines_of(&bytes);
    // The half lines stand alone; every other line is a whole event.
    let (whole, broken): (Vec<&String>, Vec<&String>) = lines
        .iter()
        .partition(|l| serde_json::from_str::<Value>(l).is_ok());
    assert_eq!(broken.len(), 2, "{lines:?}");
    assert!(broken.iter().all(|l| l.starts_with("{\"schema\"")));
    let whole: Vec<Value> = whole
        .iter()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(check_seq(&whole), 2);
    assert_eq!(whole.len(), 5 + 1);
    assert!(bytes.ends_with(b"}\n"));
}

#[test]
fn reopen_follows_a_rotated_file() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("ev.jsonl");
    let sink = EventSink::append(&path).unwrap();
    sink.emit(None, started());
    assert_eq!(sink.flush(Duration::from_secs(5)), 0);
    let rotated = tmp.path().join("ev.jsonl.1");
    std::fs::rename(&path, &rotated).unwrap();
    // Until reopened, events go to the moved file.
    sink.emit(None, started());
    assert_eq!(sink.flush(Duration::from_secs(5)), 0);
    sink.reopen(Some(&path)).unwrap();
    sink.emit(None, started());
    assert_eq!(sink.flush(Duration::from_secs(5)), 0);
    let old = json_lines(&std::fs::read(&rotated).unwrap());
    let new = json_lines(&std::fs::read(&path).unwrap());
    assert_eq!(old.len(), 2);
    assert_eq!(new.len(), 1);
    assert_eq!(new[0]["seq"], 3);
    // Deleted: created again.
    std::fs::remove_file(&path).unwrap();
    sink.reopen(Some(&path)).unwrap();
    sink.emit(None, started());
    assert_eq!(sink.flush(Duration::from_secs(5)), 0);
    assert_eq!(json_lines(&std::fs::read(&path).unwrap())[0]["seq"], 4);
    // A folder that does not exist: an error, and the old file is kept.
    assert!(sink.reopen(Some(&tmp.path().join("no/ev.jsonl"))).is_err());
    sink.emit(None, started());
    assert_eq!(sink.flush(Duration::from_secs(5)), 0);
    assert_eq!(json_lines(&std::fs::read(&path).unwrap()).len(), 2);
}

#[test]
fn a_custom_writer_is_kept_on_reopen() {
    let buf = Buf::default();
    let sink = EventSink::to(Box::new(buf.clone()));
    sink.reopen(None).unwrap();
    sink.emit(None, started());
    assert_eq!(sink.flush(Duration::from_secs(5)), 0);
    assert_eq!(json_lines(&buf.0.lock().unwrap()).len(), 1);
}

/// Every variant once, every optional field set.
fn every_event() -> Vec<Event> {
    let s = || Some("x".to_owned());
    vec![
        Event::Started {
            version: "x",
            pid: 1,
            config: s(),
        },
        Event::Watching {
            root: s(),
            blackboard: s(),
            backend: "inotify",
            reason: s(),
            program: s(),
        },
        Event::WatchDegraded {
            root: s(),
            reason: "x".into(),
            backend: Some("poll"),
        },
        Event::Rescan {
            reason: "startup".into(),
            projects: Some(1),
            error: s(),
        },
        Event::ChangeDetected { paths: vec![] },
        Event::CompileStarted {
            run_id: 1,
            trigger: "change",
            changed: vec![],
        },
        Event::CompileSucceeded {
            run_id: 1,
            duration_ms: 1,
            outputs: vec![],
            stale: vec!["x".into()],
            counts: Counts {
                steps: 1,
                warnings: 0,
            },
            warnings: vec![],
        },
        Event::failed_with(1, 1, "E000", "x".into()),
        Event::CompileRetrying {
            run_id: 1,
            duration_ms: 1,
            file: s(),
            attempt: 1,
            reason: s(),
        },
        Event::WriteBack {
            run_id: 1,
            file: "x".into(),
            value: "x".into(),
            values: vec!["x".into()],
            written: true,
            reason: s(),
            waited_ms: Some(1),
            skipped: false,
        },
        Event::DeployStarted {
            run_id: 1,
            program: "x".into(),
            controller: s(),
            argv: vec!["x".into()],
        },
        Event::DeploySucceeded {
            run_id: 1,
            program: "x".into(),
            controller: s(),
            duration_ms: 1,
            stderr: "x".into(),
        },
        Event::DeployFailed {
            run_id: 1,
            program: "x".into(),
            controller: s(),
            duration_ms: 1,
            exit_code: Some(1),
            signal: Some(9),
            timed_out: true,
            reason: "x".into(),
            stderr: "x".into(),
        },
        Event::SimulationSucceeded {
            run_id: 1,
            runs: 1,
            duration_ms: 1,
            cycle_s: Some(1.5),
            never_reached: 0,
        },
        Event::SimulationFailed {
            run_id: 1,
            runs: 1,
            duration_ms: 1,
            cycle_s: None,
            problems: 1,
            kind: "deadlock".into(),
            message: "x".into(),
            controller: s(),
            file: s(),
            line: Some(1),
            column: None,
            local_id: Some(5),
            time_s: Some(2.5),
        },
        Event::Reloaded {
            projects: 1,
            added: vec![],
            removed: vec![],
        },
        Event::ReloadFailed {
            error: "x".into(),
            file: s(),
            line: Some(1),
            column: Some(1),
        },
        Event::Stopped {
            reason: "timeout".into(),
            requested: s(),
            compiling: Some(vec![]),
        },
        Event::EventsDropped {
            count: 1,
            reason: "queue-full",
        },
    ]
}

#[test]
fn every_variant_has_an_example() {
    // A new variant breaks this match: add it to `every_event` (and to docs/DAEMON.md).
    let ordinal = |e: &Event| match e {
        Event::Started { .. } => 0,
        Event::Watching { .. } => 1,
        Event::WatchDegraded { .. } => 2,
        Event::Rescan { .. } => 3,
        Event::ChangeDetected { .. } => 4,
        Event::CompileStarted { .. } => 5,
        Event::CompileSucceeded { .. } => 6,
        Event::CompileFailed { .. } => 7,
        Event::WriteBack { .. } => 8,
        Event::Reloaded { .. } => 9,
        Event::ReloadFailed { .. } => 10,
        Event::Stopped { .. } => 11,
        Event::EventsDropped { .. } => 12,
        Event::CompileRetrying { .. } => 13,
        Event::DeployStarted { .. } => 14,
        Event::DeploySucceeded { .. } => 15,
        Event::DeployFailed { .. } => 16,
        Event::SimulationSucceeded { .. } => 17,
        Event::SimulationFailed { .. } => 18,
    };
    let seen: BTreeSet<usize> = every_event().iter().map(ordinal).collect();
    assert_eq!(seen, (0..19).collect());
}

/// The rows of docs/DAEMON.md's event table: (name, level, fields cell).
fn doc_rows() -> Vec<(String, String, String)> {
    let doc = include_str!("../../../docs/DAEMON.md");
    let mut rows = Vec::new();
    let mut in_table = false;
    for line in doc.lines() {
        if line.starts_with("| event | level | fields |") {
            in_table = true;
            continue;
        }
        if !in_table || line.starts_with("|---") {
            continue;
        }
        if !line.starts_with('|') {
            break;
        }
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        rows.push((
            cells[1].trim_matches('`').to_owned(),
            cells[2].to_owned(),
            cells[3..].join("|"),
        ));
    }
    assert!(!rows.is_empty(), "no event table in docs/DAEMON.md");
    rows
}

#[test]
fn docs_event_table_matches_the_code() {
    let rows = doc_rows();
    let events = every_event();
    for e in &events {
        let name = e.name();
        let row = rows
            .iter()
            .find(|r| r.0 == name)
            .unwrap_or_else(|| panic!("event `{name}` missing from docs/DAEMON.md"));
        assert!(
            row.1.contains(e.level().as_str()),
            "docs/DAEMON.md: `{name}` has level {}, the table says {}",
            e.level().as_str(),
            row.1
        );
        let Value::Object(fields) = serde_json::to_value(e).unwrap() else {
            panic!("{name} is not an object");
        };
        for f in fields.keys().filter(|k| *k != "event") {
            assert!(
                row.2.contains(&format!("`{f}`")),
                "docs/DAEMON.md: field `{f}` of `{name}` missing from its row"
            );
        }
    }
    for r in &rows {
        assert!(
            events.iter().any(|e| e.name() == r.0),
            "docs/DAEMON.md lists an event `{}` that the code does not have",
            r.0
        );
    }
}
