//! The polling backend for directories without change notification (NFS, SMB/CIFS, FUSE, or
//! when inotify runs out): every interval each polled directory is listed and its entries are
//! `stat`ed. A file's contents are read only in a short window after its metadata last changed.
//!
//! Why not notify's `PollWatcher`: it compares write times in whole seconds, so an edit in the
//! same second as the one before is missed unless it also compares contents — and then it reads
//! every file of every polled folder every second (a 78 MB SFC on a share: 78 MB/s of reads,
//! forever).
//!
//! What counts as a change: the entry appeared or disappeared, or its [`Stamp`] (inode, size,
//! modification and status-change times to the nanosecond) differs. That alone misses one case:
//! two same-size writes inside one tick of a coarse file-system clock (FAT: 2 s; some servers:
//! 1 s). Such writes lie at most [`COARSE_CLOCK`] apart, so for that long after the stamp last
//! changed (and after the watch started) the file is also hashed at every scan and a different
//! hash is a change. After that window a new write necessarily gives a new stamp.
//!
//! Events are notify events on the daemon's channel, so routing is the same for both backends:
//! `Create`, `Remove`, and `Modify(Data)` for any other change. The daemon compares contents
//! itself before compiling, so a `touch` still starts nothing. A directory that cannot be read
//! (other than missing) is reported once as an error (the daemon then rescans), not every tick.

use std::collections::HashMap;
use std::ffi::OsString;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use notify::event::{CreateKind, DataChange, ModifyKind, RemoveKind};
use notify::{Event, EventKind};

/// The coarsest file-system clock allowed for (FAT's two seconds), plus a margin.
pub const COARSE_CLOCK: Duration = Duration::from_millis(2500);

/// What a `stat` says about an entry; any difference is a change.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Stamp {
    dev: u64,
    ino: u64,
    size: u64,
    mtime: (i64, i64),
    ctime: (i64, i64),
    dir: bool,
    file: bool,
}

impl Stamp {
    fn of(m: &std::fs::Metadata) -> Self {
        Stamp {
            dev: m.dev(),
            ino: m.ino(),
            size: m.size(),
            mtime: (m.mtime(), m.mtime_nsec()),
            ctime: (m.ctime(), m.ctime_nsec()),
            dir: m.is_dir(),
            file: m.is_file(),
        }
    }
}

#[derive(Debug, Clone)]
struct Entry {
    stamp: Stamp,
    /// The content hash while the entry is in its hashing window.
    hash: Option<u64>,
    /// Until when the contents are hashed at every scan.
    hash_until: Option<Instant>,
}

/// One polled directory.
#[derive(Debug, Clone, Default)]
struct DirState {
    /// `None` while the directory is missing.
    entries: Option<HashMap<OsString, Entry>>,
    /// An error is being reported (so it is reported once).
    failing: bool,
}

type Handler = dyn Fn(notify::Result<Event>) + Send + Sync;

struct Shared {
    dirs: Mutex<HashMap<PathBuf, (u64, DirState)>>,
    handler: Box<Handler>,
}

/// Polls directories with `stat` on a thread of its own; stops when dropped.
pub struct StatPoller {
    shared: Arc<Shared>,
    generation: u64,
    stop: Option<mpsc::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl StatPoller {
    pub fn new(
        handler: impl Fn(notify::Result<Event>) + Send + Sync + 'static,
        interval: Duration,
    ) -> std::io::Result<Self> {
        let shared = Arc::new(Shared {
            dirs: Mutex::new(HashMap::new()),
            handler: Box::new(handler),
        });
        let (stop, stopped) = mpsc::channel::<()>();
        let s = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("skillpost-poll".into())
            .spawn(move || {
                loop {
                    match stopped.recv_timeout(interval) {
                        Err(RecvTimeoutError::Timeout) => s.scan_all(),
                        _ => return,
                    }
                }
            })?;
        Ok(StatPoller {
            shared,
            generation: 0,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// Starts polling `dir`. Its present state is taken now (no events for it), so a change
    /// made after this returns is reported.
    pub fn watch(&mut self, dir: &Path) -> std::io::Result<()> {
        let now = Instant::now();
        let entries = list(dir)?
            .into_iter()
            .map(|(name, stamp)| {
                let entry = self.shared.changed_entry(&dir.join(&name), stamp, now);
                (name, entry)
            })
            .collect();
        let state = DirState {
            entries: Some(entries),
            failing: false,
        };
        self.generation += 1;
        self.shared
            .lock()
            .insert(dir.to_owned(), (self.generation, state));
        Ok(())
    }

    /// Stops polling `dir`.
    pub fn unwatch(&mut self, dir: &Path) {
        self.shared.lock().remove(dir);
    }

    /// Scans every polled directory now (tests; the thread does this every interval).
    #[cfg(test)]
    fn scan_now(&self) {
        self.shared.scan_all();
    }
}

impl Drop for StatPoller {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Shared {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<PathBuf, (u64, DirState)>> {
        // A panic while holding the lock leaves plain data behind; keep polling.
        self.dirs.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The content hash of a regular file (`None` for anything else or an unreadable file).
    fn hash_of(&self, path: &Path, stamp: Stamp) -> Option<u64> {
        if !stamp.file {
            return None;
        }
        // Non-blocking, regular files only, read in pieces, and never past the largest input a
        // configuration can allow (a file growing without end is not hashed for ever).
        crate::load::hash_file(
            path,
            super::config::MAX_FILE_SIZE_MB_RANGE.end() * 1024 * 1024,
        )
        .ok()
    }

    /// The entry of a file seen new or changed at `now`: hashed, and hashed again at every scan
    /// of the next [`COARSE_CLOCK`].
    fn changed_entry(&self, path: &Path, stamp: Stamp, now: Instant) -> Entry {
        Entry {
            stamp,
            hash: self.hash_of(path, stamp),
            hash_until: Some(now + COARSE_CLOCK),
        }
    }

    fn scan_all(&self) {
        // Scan without holding the lock (a share may be slow); keep a result only if the
        // directory was not unwatched or watched again meanwhile.
        let dirs: Vec<(PathBuf, u64, DirState)> = self
            .lock()
            .iter()
            .map(|(d, (g, s))| (d.clone(), *g, s.clone()))
            .collect();
        for (dir, generation, old) in dirs {
            let (new, events) = self.scan(&dir, old);
            {
                let mut map = self.lock();
                match map.get_mut(&dir) {
                    Some((g, s)) if *g == generation => *s = new,
                    _ => continue,
                }
            }
            for e in events {
                (self.handler)(e);
            }
        }
    }

    /// One scan of `dir`: its new state and the events to report.
    fn scan(&self, dir: &Path, old: DirState) -> (DirState, Vec<notify::Result<Event>>) {
        let now = Instant::now();
        let mut events = Vec::new();
        let event = |kind: EventKind, path: PathBuf| Ok(Event::new(kind).add_path(path));
        let listing = match list(dir) {
            Ok(l) => l,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                // Gone: every entry and the directory itself are removed.
                if let Some(entries) = old.entries {
                    for name in entries.into_keys() {
                        events.push(event(EventKind::Remove(RemoveKind::Any), dir.join(name)));
                    }
                    events.push(event(EventKind::Remove(RemoveKind::Folder), dir.to_owned()));
                }
                return (DirState::default(), events);
            }
            Err(e) => {
                if !old.failing {
                    events.push(Err(notify::Error::io(e).add_path(dir.to_owned())));
                }
                return (
                    DirState {
                        failing: true,
                        ..old
                    },
                    events,
                );
            }
        };
        let came_back = old.entries.is_none();
        if came_back {
            events.push(event(EventKind::Create(CreateKind::Folder), dir.to_owned()));
        }
        let mut before = old.entries.unwrap_or_default();
        let mut entries = HashMap::with_capacity(listing.len());
        for (name, stamp) in listing {
            let path = dir.join(&name);
            let entry = match before.remove(&name) {
                None => {
                    events.push(event(EventKind::Create(CreateKind::Any), path.clone()));
                    self.changed_entry(&path, stamp, now)
                }
                Some(e) if e.stamp != stamp => {
                    events.push(event(
                        EventKind::Modify(ModifyKind::Data(DataChange::Any)),
                        path.clone(),
                    ));
                    self.changed_entry(&path, stamp, now)
                }
                Some(e) => match e.hash_until {
                    Some(until) if now <= until => {
                        let hash = self.hash_of(&path, stamp);
                        if hash != e.hash {
                            events.push(event(
                                EventKind::Modify(ModifyKind::Data(DataChange::Content)),
                                path.clone(),
                            ));
                            Entry {
                                stamp,
                                hash,
                                hash_until: Some(now + COARSE_CLOCK),
                            }
                        } else {
                            Entry { hash, ..e }
                        }
                    }
                    // The window is over: a later write changes the stamp.
                    _ => Entry {
                        stamp,
                        hash: None,
                        hash_until: None,
                    },
                },
            };
            entries.insert(name, entry);
        }
        for name in before.into_keys() {
            events.push(event(EventKind::Remove(RemoveKind::Any), dir.join(name)));
        }
        (
            DirState {
                entries: Some(entries),
                failing: false,
            },
            events,
        )
    }
}

/// The entries of `dir` with their stamps (symbolic links not followed; an entry that vanished
/// between listing and `stat` is left out).
fn list(dir: &Path) -> std::io::Result<Vec<(OsString, Stamp)>> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        match entry.metadata() {
            Ok(m) => out.push((entry.file_name(), Stamp::of(&m))),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;
    use std::sync::mpsc::Receiver;

    /// A poller whose thread scans only every hour: scans happen through `scan_now`.
    fn poller() -> (StatPoller, Receiver<notify::Result<Event>>) {
        poller_every(Duration::from_secs(3600))
    }

    fn poller_every(interval: Duration) -> (StatPoller, Receiver<notify::Result<Event>>) {
        let (tx, rx) = mpsc::channel();
        let tx = Mutex::new(tx);
        let p = StatPoller::new(
            move |e| {
                let _ = tx.lock().unwrap().send(e);
            },
            interval,
        )
        .unwrap();
        (p, rx)
    }

    fn drain(rx: &Receiver<notify::Result<Event>>) -> Vec<(EventKind, PathBuf)> {
        rx.try_iter()
            .map(|e| {
                let e = e.expect("no error");
                (e.kind, e.paths[0].clone())
            })
            .collect()
    }

    fn is_create(k: &EventKind) -> bool {
        matches!(k, EventKind::Create(_))
    }
    fn is_remove(k: &EventKind) -> bool {
        matches!(k, EventKind::Remove(_))
    }
    fn is_modify(k: &EventKind) -> bool {
        matches!(k, EventKind::Modify(ModifyKind::Data(_)))
    }

    #[test]
    fn create_modify_remove_and_nothing_else() {
        let t = tempfile::tempdir().unwrap();
        let d = t.path();
        fs::write(d.join("a"), "1").unwrap();
        let (mut p, rx) = poller();
        p.watch(d).unwrap();
        p.scan_now();
        assert!(drain(&rx).is_empty(), "no change, no event");
        fs::write(d.join("b"), "new").unwrap();
        p.scan_now();
        let ev = drain(&rx);
        assert_eq!(ev.len(), 1, "{ev:?}");
        assert!(is_create(&ev[0].0) && ev[0].1 == d.join("b"), "{ev:?}");
        fs::write(d.join("a"), "22").unwrap();
        p.scan_now();
        let ev = drain(&rx);
        assert!(
            ev.len() == 1 && is_modify(&ev[0].0) && ev[0].1 == d.join("a"),
            "{ev:?}"
        );
        fs::remove_file(d.join("b")).unwrap();
        p.scan_now();
        let ev = drain(&rx);
        assert!(
            ev.len() == 1 && is_remove(&ev[0].0) && ev[0].1 == d.join("b"),
            "{ev:?}"
        );
        p.scan_now();
        assert!(drain(&rx).is_empty());
    }

    #[test]
    fn same_size_edit_with_the_same_times_is_found_inside_the_window() {
        // On a coarse file-system clock a second same-size write can keep every time stamp.
        // Here the clock is fine, so the recorded stamp is made equal to the new one instead.
        let t = tempfile::tempdir().unwrap();
        let d = t.path();
        fs::write(d.join("a"), "1111").unwrap();
        let (mut p, rx) = poller();
        p.watch(d).unwrap();
        fs::write(d.join("a"), "2222").unwrap();
        // Pretend the file system's clock did not tick: the recorded stamp is the new one.
        let now = Stamp::of(&fs::metadata(d.join("a")).unwrap());
        for (_, s) in p.shared.lock().values_mut() {
            for e in s.entries.as_mut().unwrap().values_mut() {
                e.stamp = now;
            }
        }
        p.scan_now();
        let ev = drain(&rx);
        assert!(ev.len() == 1 && is_modify(&ev[0].0), "{ev:?}");
        // Outside the window, contents are no longer read.
        for (_, s) in p.shared.lock().values_mut() {
            for e in s.entries.as_mut().unwrap().values_mut() {
                e.hash_until = Some(Instant::now() - Duration::from_secs(1));
            }
        }
        p.scan_now();
        p.scan_now();
        for (_, s) in p.shared.lock().values() {
            for e in s.entries.as_ref().unwrap().values() {
                assert_eq!(e.hash, None, "not hashed after the window");
            }
        }
        assert!(drain(&rx).is_empty());
    }

    #[test]
    fn replace_by_rename_with_the_same_bytes_is_seen() {
        let t = tempfile::tempdir().unwrap();
        let d = t.path();
        fs::write(d.join("a"), "1").unwrap();
        let (mut p, rx) = poller();
        p.watch(d).unwrap();
        // Replacing by rename with the same size and contents: a new inode.
        fs::write(d.join("a.tmp"), "1").unwrap();
        fs::rename(d.join("a.tmp"), d.join("a")).unwrap();
        p.scan_now();
        let ev = drain(&rx);
        assert!(
            ev.iter().any(|(k, f)| is_modify(k) && *f == d.join("a")),
            "{ev:?}"
        );
    }

    #[test]
    fn directory_gone_and_back() {
        let t = tempfile::tempdir().unwrap();
        let d = t.path().join("p");
        fs::create_dir(&d).unwrap();
        fs::write(d.join("a"), "1").unwrap();
        let (mut p, rx) = poller();
        p.watch(&d).unwrap();
        fs::remove_dir_all(&d).unwrap();
        p.scan_now();
        let ev = drain(&rx);
        assert!(
            ev.iter().any(|(k, f)| is_remove(k) && *f == d.join("a")),
            "{ev:?}"
        );
        assert!(ev.iter().any(|(k, f)| is_remove(k) && *f == d), "{ev:?}");
        p.scan_now();
        assert!(drain(&rx).is_empty(), "reported once");
        fs::create_dir(&d).unwrap();
        fs::write(d.join("a"), "2").unwrap();
        p.scan_now();
        let ev = drain(&rx);
        assert!(ev.iter().any(|(k, f)| is_create(k) && *f == d), "{ev:?}");
        assert!(
            ev.iter().any(|(k, f)| is_create(k) && *f == d.join("a")),
            "{ev:?}"
        );
    }

    #[test]
    fn unwatched_directories_report_nothing() {
        let t = tempfile::tempdir().unwrap();
        let d = t.path();
        let (mut p, rx) = poller();
        p.watch(d).unwrap();
        p.unwatch(d);
        fs::write(d.join("a"), "1").unwrap();
        p.scan_now();
        assert!(drain(&rx).is_empty());
    }

    #[test]
    fn the_thread_scans_every_interval_and_stops_on_drop() {
        let t = tempfile::tempdir().unwrap();
        let d = t.path();
        let (mut p, rx) = poller_every(Duration::from_millis(20));
        p.watch(d).unwrap();
        fs::write(d.join("a"), "1").unwrap();
        let e = rx.recv_timeout(Duration::from_secs(5)).unwrap().unwrap();
        assert!(is_create(&e.kind));
        drop(p);
        // The handler (and its sender) went with the thread.
        assert!(matches!(
            rx.recv_timeout(Duration::from_secs(5)),
            Err(RecvTimeoutError::Disconnected)
        ));
    }
}
