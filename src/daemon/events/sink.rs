//! [`EventSink`] and its writer thread: the queue, the outputs (a file, stdout, any writer), and
//! how an [`Event`] becomes its line. How they behave: the [module documentation](super), "The
//! writer".

use std::collections::VecDeque;
use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime};

use serde_json::{Map, Value, json};

use super::{Event, SCHEMA};

/// How many events wait for the writer at most, unless `SKILLPOST_EVENT_QUEUE` says otherwise.
pub const DEFAULT_QUEUE: usize = 4096;

/// How many bytes of lines wait for the writer at most (events with thousands of diagnostics
/// are large); one event is always taken.
pub const MAX_QUEUE_BYTES: usize = 16 << 20;

/// How long the end of the daemon waits for the last events to be written.
pub const FLUSH_TIMEOUT: Duration = Duration::from_secs(2);

/// Where the lines go: a file (which can take back a partial line), or any writer.
pub(super) trait Output: Send {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize>;
    fn flush(&mut self) -> std::io::Result<()>;
    /// Takes back the last `n` bytes written; false where the output cannot (a pipe).
    fn unwrite(&mut self, n: u64) -> bool;
}

impl Output for File {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        Write::write(self, buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
    fn unwrite(&mut self, n: u64) -> bool {
        let Ok(meta) = self.metadata() else {
            return false;
        };
        if !meta.is_file() || meta.len() < n {
            return false;
        }
        let len = meta.len() - n;
        // Not `O_APPEND` (stdout redirected with `>`): the offset must come back too.
        self.set_len(len).is_ok() && self.seek(SeekFrom::Start(len)).is_ok()
    }
}

/// Any writer (tests, or stdout when it cannot be duplicated).
pub(super) struct Plain(pub(super) Box<dyn Write + Send>);

impl Output for Plain {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.0.flush()
    }
    fn unwrite(&mut self, _n: u64) -> bool {
        false
    }
}

/// What kind of output a sink was made for, so that [`EventSink::reopen`] knows what to do.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Kind {
    Stdout,
    File(PathBuf),
    /// A writer given by the caller: never replaced.
    Custom,
}

/// A line waiting for the writer.
struct Pending {
    line: Vec<u8>,
    /// For an `events-dropped` line: its reason and count (put back when the line is lost).
    report: Option<(&'static str, u64)>,
}

struct State {
    queue: VecDeque<Pending>,
    /// The bytes of the lines in the queue.
    bytes: usize,
    seq: u64,
    /// Events dropped because the queue was full / because their write failed, not yet reported.
    dropped_full: u64,
    dropped_failed: u64,
    /// The writer is writing a line (taken from the queue).
    busy: bool,
    /// The output the writer takes before its next line.
    replace: Option<Box<dyn Output>>,
    kind: Kind,
    /// The sink is gone: the writer ends once the queue is empty.
    closed: bool,
    /// When dropping for a full queue was last logged.
    warned_full: Option<Instant>,
}

struct Shared {
    state: Mutex<State>,
    /// To the writer: an event, a new output, or the end.
    work: Condvar,
    /// From the writer: the queue is empty and nothing is being written.
    idle: Condvar,
    capacity: usize,
    /// This run's identity (see [`new_instance`]), after `seq` in every line.
    instance: String,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Where events go. Shared by the daemon's tasks; see the module documentation.
pub struct EventSink {
    shared: Arc<Shared>,
    /// Sees every event as it is emitted: the projects' results (`skillpost status`, systemd's
    /// status line); failures also go to the log ([`crate::daemon::journal`]).
    state: Arc<crate::daemon::state::Tracker>,
    /// Set when the daemon stops: a write-back waiting for another program to close the
    /// blackboard gives up at once instead of holding the stop (`job`).
    stopping: std::sync::atomic::AtomicBool,
}

impl EventSink {
    /// Events on stdout.
    pub fn stdout() -> Self {
        Self::start(stdout_output(), Kind::Stdout, queue_capacity())
    }

    /// Events appended to a file (created if missing).
    pub fn append(path: &Path) -> std::io::Result<Self> {
        let f = open_append(path)?;
        Ok(Self::start(
            Box::new(f),
            Kind::File(path.to_owned()),
            queue_capacity(),
        ))
    }

    /// Events into any writer (tests).
    pub fn to(out: Box<dyn Write + Send>) -> Self {
        Self::start(Box::new(Plain(out)), Kind::Custom, queue_capacity())
    }

    pub(super) fn start(out: Box<dyn Output>, kind: Kind, capacity: usize) -> Self {
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                queue: VecDeque::new(),
                bytes: 0,
                seq: 0,
                dropped_full: 0,
                dropped_failed: 0,
                busy: false,
                replace: None,
                kind,
                closed: false,
                warned_full: None,
            }),
            work: Condvar::new(),
            idle: Condvar::new(),
            capacity: capacity.max(2),
            instance: new_instance(),
        });
        let writer = Writer {
            shared: shared.clone(),
            out,
            dirty: false,
            failing: false,
            logged_failure: false,
            warned_failure: None,
        };
        let spawned = std::thread::Builder::new()
            .name("skillpost-events".into())
            .spawn(move || writer.run());
        if let Err(e) = spawned {
            // Without a writer events only pile up to the queue's bound and are counted.
            tracing::error!("cannot start the event writer thread: {e}");
        }
        EventSink {
            shared,
            state: Arc::new(crate::daemon::state::Tracker::new(None)),
            stopping: Default::default(),
        }
    }

    /// The same sink, writing the projects' results to a state file (`skillpost status`).
    pub fn with_state_file(mut self, path: PathBuf) -> Self {
        self.state = Arc::new(crate::daemon::state::Tracker::new(Some(path)));
        self
    }

    /// The files the daemon writes besides outputs: the events file (when events go to one)
    /// and the state file. A project may not read them (`job`), and they may not lie in a
    /// project's folder (`config::own_files_problem`).
    pub fn own_files(&self) -> Vec<PathBuf> {
        let mut v = Vec::new();
        if let Kind::File(p) = &self.shared.lock().kind {
            v.push(p.clone());
        }
        v.extend(self.state.path().map(Path::to_path_buf));
        v
    }

    /// This run's identity, the `instance` of every event it emits (see `new_instance`).
    pub fn instance(&self) -> &str {
        &self.shared.instance
    }

    /// The daemon stops: running write-backs stop waiting (see [`EventSink::stopping`]).
    pub fn set_stopping(&self) {
        self.stopping
            .store(true, std::sync::atomic::Ordering::Relaxed);
    }

    /// Whether the daemon is stopping.
    pub fn stopping(&self) -> bool {
        self.stopping.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// The projects' results as the events told them.
    pub fn state(&self) -> &crate::daemon::state::Tracker {
        &self.state
    }

    /// Emits one event: numbers it and queues its line for the writer; never waits for the
    /// output. When the queue is full the event is dropped and counted (see `events-dropped`).
    pub fn emit(&self, project: Option<&str>, event: Event) {
        crate::daemon::journal::log(project, &event);
        self.state.observe(project, &event);
        let (head, tail) = render(SystemTime::now(), project, &event);
        let mut st = self.shared.lock();
        st.seq += 1;
        let full = st.queue.len() >= self.shared.capacity
            || (st.bytes + head.len() + tail.len() > MAX_QUEUE_BYTES && !st.queue.is_empty());
        if full {
            if st.dropped_full == 0 && due(&mut st.warned_full) {
                tracing::warn!(
                    "the event stream is not read fast enough: dropping events until it catches up"
                );
            }
            st.dropped_full += 1;
            return;
        }
        let line = with_seq(head, st.seq, &self.shared.instance, &tail);
        st.bytes += line.len();
        st.queue.push_back(Pending { line, report: None });
        drop(st);
        self.shared.work.notify_one();
    }

    /// Opens the output again: the file `events` (created if missing; the same path again after
    /// logrotate moved it away, or a new one), or stdout when `None`. The writer takes it before
    /// its next line. A sink made by [`EventSink::to`] keeps its writer. On error the current
    /// output is kept.
    pub fn reopen(&self, events: Option<&Path>) -> std::io::Result<()> {
        let kind = match events {
            Some(p) => Kind::File(p.to_owned()),
            None => Kind::Stdout,
        };
        {
            let st = self.shared.lock();
            if st.kind == Kind::Custom || (st.kind == Kind::Stdout && kind == Kind::Stdout) {
                return Ok(());
            }
        }
        let out: Box<dyn Output> = match events {
            Some(p) => Box::new(open_append(p)?),
            None => stdout_output(),
        };
        let mut st = self.shared.lock();
        st.replace = Some(out);
        st.kind = kind;
        drop(st);
        self.shared.work.notify_one();
        Ok(())
    }

    /// Waits until every event emitted so far is written (or dropped), at most `timeout`.
    /// Returns how many are still waiting (0: all out).
    pub fn flush(&self, timeout: Duration) -> usize {
        let deadline = Instant::now() + timeout;
        let mut st = self.shared.lock();
        loop {
            let waiting = st.queue.len() + usize::from(st.busy);
            let now = Instant::now();
            if waiting == 0 || now >= deadline {
                return waiting;
            }
            st = self
                .shared
                .idle
                .wait_timeout(st, deadline - now)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }
}

impl Drop for EventSink {
    /// The writer writes what is queued, then ends (it is not waited for).
    fn drop(&mut self) {
        self.shared.lock().closed = true;
        self.shared.work.notify_all();
    }
}

/// Opens the events file for appending, created if missing (mode `0666 & !umask`). Without
/// blocking, and only a regular file or a character device (`/dev/null`): a FIFO would hold the
/// daemon in `open` until a reader came (at startup, or in the event loop at `SIGHUP`), and a
/// reader that stops reading would stall every event.
fn open_append(path: &Path) -> std::io::Result<File> {
    use std::os::unix::fs::{FileTypeExt as _, OpenOptionsExt as _};
    let f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .custom_flags(rustix::fs::OFlags::NONBLOCK.bits() as i32)
        .open(path)
        .map_err(|e| {
            if e.raw_os_error() == Some(rustix::io::Errno::NXIO.raw_os_error()) {
                not_a_file(path, "a FIFO")
            } else {
                e
            }
        })?;
    let kind = f.metadata()?.file_type();
    if kind.is_fifo() {
        return Err(not_a_file(path, "a FIFO"));
    }
    if !kind.is_file() && !kind.is_char_device() {
        return Err(not_a_file(path, "not a regular file"));
    }
    // Writes block as they always did (a full disk is reported by the writer thread).
    rustix::fs::fcntl_setfl(&f, rustix::fs::OFlags::APPEND)?;
    Ok(f)
}

fn not_a_file(path: &Path, what: &str) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!(
            "{} is {what}; the events file must be a regular file (for a program that reads the events as they come, leave out --events and pipe stdout to it)",
            path.display()
        ),
    )
}

/// Stdout as a file of its own (a duplicate descriptor): unbuffered, one `write` per line, and a
/// partial line can be taken back when stdout is a regular file.
fn stdout_output() -> Box<dyn Output> {
    use std::os::fd::AsFd;
    match std::io::stdout().as_fd().try_clone_to_owned() {
        Ok(fd) => Box::new(File::from(fd)),
        Err(_) => Box::new(Plain(Box::new(std::io::stdout()))),
    }
}

/// The queue bound: `SKILLPOST_EVENT_QUEUE`, else [`DEFAULT_QUEUE`].
fn queue_capacity() -> usize {
    std::env::var("SKILLPOST_EVENT_QUEUE")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(DEFAULT_QUEUE)
}

/// The writer thread: takes events from the queue, writes them as lines.
struct Writer {
    shared: Arc<Shared>,
    out: Box<dyn Output>,
    /// The output does not end at a line boundary (a partial line that could not be taken back).
    dirty: bool,
    /// Writing fails.
    failing: bool,
    /// This failure was logged (then its end is logged too).
    logged_failure: bool,
    /// When a failure was last logged.
    warned_failure: Option<Instant>,
}

impl Writer {
    fn run(mut self) {
        loop {
            let pending = {
                let mut st = self.shared.lock();
                loop {
                    if let Some(out) = st.replace.take() {
                        self.out = out;
                        self.dirty = false;
                    }
                    if let Some(p) = st.queue.pop_front() {
                        st.bytes -= p.line.len();
                        st.busy = true;
                        break p;
                    }
                    if st.closed {
                        return;
                    }
                    st = self.shared.work.wait(st).unwrap_or_else(|p| p.into_inner());
                }
            };
            let ok = self.write(&pending.line);
            let mut st = self.shared.lock();
            st.busy = false;
            if !ok {
                st.dropped_failed += 1;
                // A lost report of losses: its count is reported again with the next one.
                match pending.report {
                    Some(("queue-full", count)) => st.dropped_full += count,
                    Some((_, count)) => st.dropped_failed += count,
                    None => {}
                }
            }
            // Caught up: report what was lost, as one more event after those queued.
            let caught_up =
                st.queue.len() <= self.shared.capacity / 2 && st.bytes <= MAX_QUEUE_BYTES / 2;
            let mut report = Vec::new();
            if st.dropped_full > 0 && caught_up {
                report.push(("queue-full", std::mem::take(&mut st.dropped_full)));
            }
            if ok && st.dropped_failed > 0 {
                report.push(("write-error", std::mem::take(&mut st.dropped_failed)));
            }
            for (reason, count) in report {
                st.seq += 1;
                tracing::debug!("{count} events were lost ({reason}); reported in the stream");
                let (head, tail) = render(
                    SystemTime::now(),
                    None,
                    &Event::EventsDropped { count, reason },
                );
                let line = with_seq(head, st.seq, &self.shared.instance, &tail);
                st.bytes += line.len();
                st.queue.push_back(Pending {
                    line,
                    report: Some((reason, count)),
                });
            }
            if st.queue.is_empty() {
                self.shared.idle.notify_all();
            }
        }
    }

    /// Writes one line; true if it is out whole. After a failure no partial line stays behind.
    fn write(&mut self, line: &[u8]) -> bool {
        let pre = usize::from(self.dirty);
        let mut buf = Vec::with_capacity(line.len() + pre);
        if self.dirty {
            buf.push(b'\n');
        }
        buf.extend_from_slice(line);
        let mut done = 0;
        let mut result = Ok(());
        while done < buf.len() {
            match self.out.write(&buf[done..]) {
                Ok(0) => {
                    result = Err(std::io::Error::from(std::io::ErrorKind::WriteZero));
                    break;
                }
                Ok(n) => done += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
        }
        if result.is_ok() {
            result = self.out.flush();
            if result.is_err() {
                // Buffered somewhere: how much of it got out is unknown.
                self.dirty = true;
            } else {
                self.dirty = false;
            }
        } else if done > pre {
            // Part of the line is out: take it back, else end it with the next line's newline.
            let n = (done - pre) as u64;
            self.dirty = !self.out.unwrite(n);
            if self.dirty {
                tracing::debug!("{n} bytes of a line are out; the next line starts a new one");
            } else {
                tracing::debug!("took back {n} bytes of a partial line");
            }
        } else if done == pre {
            self.dirty = false;
        }
        match result {
            Ok(()) => {
                if std::mem::take(&mut self.failing) && std::mem::take(&mut self.logged_failure) {
                    tracing::warn!("the event stream can be written again");
                }
                true
            }
            Err(e) => {
                if !self.failing {
                    self.failing = true;
                    // A disk that is almost full fails and works by turns: logged once a minute.
                    self.logged_failure = due(&mut self.warned_failure);
                    if self.logged_failure {
                        tracing::error!(
                            "cannot write the event stream: {e}; events are lost until it works again"
                        );
                    }
                }
                false
            }
        }
    }
}

/// How often a trouble of the event stream is logged at most.
const LOG_EVERY: Duration = Duration::from_secs(60);

/// Whether a message last logged at `last` is due again; if so, `last` becomes now.
fn due(last: &mut Option<Instant>) -> bool {
    let now = Instant::now();
    if last.is_some_and(|t| now.duration_since(t) < LOG_EVERY) {
        return false;
    }
    *last = Some(now);
    true
}

/// One event as the two parts of its line around `seq`: the envelope up to `ts`, and the rest
/// (`event`, `level`, `project`, then the event's fields, those that are `None` left out).
/// Done before the sink's lock is taken; [`with_seq`] joins them under it.
fn render(ts: SystemTime, project: Option<&str>, event: &Event) -> (Vec<u8>, Vec<u8>) {
    let mut head = Map::new();
    head.insert("schema".into(), json!(SCHEMA));
    head.insert(
        "ts".into(),
        json!(humantime::format_rfc3339_millis(ts).to_string()),
    );
    let mut tail = Map::new();
    tail.insert("event".into(), json!(event.name()));
    tail.insert("level".into(), json!(event.level().as_str()));
    if let Some(p) = project {
        tail.insert("project".into(), json!(p));
    }
    if let Ok(Value::Object(f)) = serde_json::to_value(event) {
        // Absent is clearer than null in a log that people read.
        for (k, v) in f.into_iter().filter(|(k, v)| k != "event" && !v.is_null()) {
            tail.insert(k, v);
        }
    }
    // `{"schema":…,"ts":"…"` and `"event":…}` (both objects are never empty).
    let mut head = serde_json::to_vec(&Value::Object(head)).unwrap_or_default();
    head.pop();
    let mut tail = serde_json::to_vec(&Value::Object(tail)).unwrap_or_default();
    tail.remove(0);
    (head, tail)
}

/// The whole line: `head`, `,"seq":N,"instance":"…",`, `tail`, newline.
fn with_seq(mut head: Vec<u8>, seq: u64, instance: &str, tail: &[u8]) -> Vec<u8> {
    head.reserve(tail.len() + 64);
    head.extend_from_slice(format!(",\"seq\":{seq},\"instance\":\"{instance}\",").as_bytes());
    head.extend_from_slice(tail);
    head.push(b'\n');
    head
}

/// A daemon run's identity, for the `instance` of its events: the start time (milliseconds since
/// 1970, hexadecimal), the pid and 32 random bits, e.g. `19ac35e2f01-1a2b-9f3c0d1e`. Runs of one
/// machine differ by time and pid; the random part separates runs of several machines (or
/// containers with the same pid) appending to one file in the same millisecond. Only letters,
/// digits and `-`: written into the line as it is, without escaping.
fn new_instance() -> String {
    use std::hash::{BuildHasher, Hasher};
    let ms = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis());
    // std's hasher keys are random per process (and per `RandomState` after the first).
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(ms);
    h.write_u32(std::process::id());
    let random = h.finish() as u32;
    format!("{ms:x}-{:x}-{random:08x}", std::process::id())
}

/// An event output in memory, for the unit tests of the daemon's modules.
#[cfg(test)]
#[derive(Clone, Default)]
pub(crate) struct MemOut(pub(crate) Arc<Mutex<Vec<u8>>>);

#[cfg(test)]
impl Write for MemOut {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}
