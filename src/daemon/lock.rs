//! One daemon per folder: an advisory lock (`flock`) on each watched folder itself, so a second
//! `skillpost watch` on a folder another one keeps is refused instead of deleting the first
//! one's staged files and racing its writes, whatever its user, configuration or runtime
//! directory, and under whatever name (a link, a bind mount: the lock is the folder's inode's).
//!
//! - The lock is taken on the folder opened read-only (`O_DIRECTORY`); it is the kernel's, so it
//!   ends with the process whatever the way it ends (`kill -9` included). Where a file system
//!   has no `flock` on folders (some network file systems), a lock file in the runtime
//!   directory stands in, as before: `$RUNTIME_DIRECTORY` (systemd's `RuntimeDirectory=`), else
//!   `$XDG_RUNTIME_DIR/skillpost`, else `<temp dir>/skillpost-<uid>`.
//! - The refusal names the holder's pid: the kernel's list of locks (`/proc/locks`) says it
//!   whatever the holder's user or runtime directory; where it does not (no `/proc`, another pid
//!   namespace), a note in the runtime directory naming the holder's pid does, for a daemon of
//!   the same runtime directory. Without either, the daemon is refused all the same, without
//!   its pid.
//! - A folder that does not exist holds no lock and no descriptor: it is locked when it
//!   appears (`Locks::ensure`); if another daemon keeps it by then, the project waits.
//! - One descriptor per locked folder, never more than the process may open less
//!   [`RESERVE`]: the compiles always have descriptors left ([`raise_open_file_limit`] lifts
//!   the soft limit to the hard one first). A folder beyond that is refused with the reason.

use std::collections::HashMap;
use std::fs::File;
use std::io::Write;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

/// Descriptors left for everything but the folder locks (compiles, watches, events, state).
pub const RESERVE: u64 = 256;

/// Lifts the soft limit of open files to the hard one (a service may keep thousands of folders;
/// the soft limit is often 1,024). `Locks::new` reads the limit in force afterwards; where it
/// cannot be lifted, the old one stays.
pub fn raise_open_file_limit() {
    use rustix::process::{Resource, getrlimit, setrlimit};
    let mut l = getrlimit(Resource::Nofile);
    if let (Some(cur), max) = (l.current, l.maximum)
        && max.is_none_or(|m| m > cur)
    {
        l.current = max.or(Some(1 << 20));
        let _ = setrlimit(Resource::Nofile, l);
    }
}

/// The directory of the lock files (see the module documentation).
pub fn runtime_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("RUNTIME_DIRECTORY").filter(|d| !d.is_empty()) {
        // systemd gives several directories separated by `:` when several are configured.
        let first = d
            .to_string_lossy()
            .split(':')
            .next()
            .unwrap_or("")
            .to_owned();
        if !first.is_empty() {
            return PathBuf::from(first);
        }
    }
    if let Some(d) = std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        return PathBuf::from(d).join("skillpost");
    }
    std::env::temp_dir().join(format!("skillpost-{}", rustix::process::getuid().as_raw()))
}

/// A folder's identity: device and inode.
type Id = (u64, u64);

/// A lock held: how many names hold it, the open folder (or lock file) holding it, and the note
/// naming our pid.
struct Held {
    names: usize,
    _file: File,
    note: Option<PathBuf>,
}

/// The folder locks this daemon holds.
pub(super) struct Locks {
    dir: PathBuf,
    /// Folder as given → the lock it holds, or `None` while the folder does not exist.
    names: HashMap<PathBuf, Option<Id>>,
    held: HashMap<Id, Held>,
    /// The open-file limit (locks stop [`RESERVE`] and `hooks` below it).
    limit: u64,
    /// Descriptors left for the deploy hooks running at once.
    hooks: u64,
}

impl Locks {
    pub(super) fn new(dir: PathBuf) -> Self {
        Locks {
            dir,
            names: HashMap::new(),
            held: HashMap::new(),
            limit: rustix::process::getrlimit(rustix::process::Resource::Nofile)
                .current
                .unwrap_or(u64::MAX),
            hooks: 0,
        }
    }

    /// Leaves `hooks` descriptors for the deploy hooks besides [`RESERVE`].
    pub(super) fn reserving(mut self, hooks: u64) -> Self {
        self.hooks = hooks;
        self
    }

    /// Takes a new share for the hooks (a reload): folders locked already stay locked.
    pub(super) fn reserve(&mut self, hooks: u64) {
        self.hooks = hooks;
    }

    /// With this open-file limit instead of the process's (tests).
    #[cfg(test)]
    fn with_limit(mut self, limit: u64) -> Self {
        self.limit = limit;
        self
    }

    /// Whether no further folder can be locked (the open-file limit less [`RESERVE`]).
    pub(super) fn at_limit(&self) -> bool {
        self.held.len() as u64 + RESERVE + self.hooks >= self.limit
    }

    pub(super) fn holds(&self, folder: &Path) -> bool {
        self.names.contains_key(folder)
    }

    /// Keeps `folder`: locks it if it exists, else remembers it for [`Locks::ensure`] when it
    /// appears. Error: the sentence to report (another daemon keeps it, or it cannot be locked).
    pub(super) fn acquire(&mut self, folder: &Path) -> Result<(), String> {
        let kept = self.holds(folder);
        if !kept {
            self.names.insert(folder.to_owned(), None);
        }
        match self.lock(folder) {
            Ok(_) => Ok(()),
            // Another program's lock (a planner's `flock`): kept like a missing folder, so only
            // this folder waits; [`Locks::ensure`] says why and takes it once it is let go.
            Err(Refused::Other(_)) => Ok(()),
            Err(Refused::Daemon(why)) => {
                if !kept {
                    self.names.remove(folder);
                }
                Err(why)
            }
        }
    }

    /// Locks `folder` (kept by [`Locks::acquire`]) if it exists now and is not locked yet.
    /// `Ok(true)`: this daemon holds it; `Ok(false)`: it is not there (yet), so nobody may
    /// compile it until a later call returns `true` (a folder that appears right after this
    /// answer is not ours yet).
    pub(super) fn ensure(&mut self, folder: &Path) -> Result<bool, String> {
        self.lock(folder).map_err(Refused::into_sentence)
    }

    fn lock(&mut self, folder: &Path) -> Result<bool, Refused> {
        match self.names.get(folder) {
            Some(Some(id)) => {
                // Still the folder we locked? One deleted (or moved away) and made again under
                // the name is another inode, locked anew.
                match std::fs::metadata(folder) {
                    Ok(m) if (m.dev(), m.ino()) != *id => {
                        self.release(folder);
                        self.names.insert(folder.to_owned(), None);
                    }
                    _ => return Ok(true),
                }
            }
            Some(None) => {}
            None => return Err(Refused::Daemon(format!("{} is not kept", folder.display()))),
        }
        let opened = std::fs::File::options()
            .read(true)
            .custom_flags(
                (rustix::fs::OFlags::DIRECTORY | rustix::fs::OFlags::CLOEXEC).bits() as i32,
            )
            .open(folder);
        let (dir, meta) = match opened {
            Ok(dir) => {
                let meta = dir.metadata().map_err(|e| {
                    Refused::Daemon(format!("cannot lock {}: {e}", folder.display()))
                })?;
                (Some(dir), meta)
            }
            // There, but not to be opened for reading (no read permission): the lock file.
            Err(_) => match std::fs::metadata(folder) {
                Ok(m) if m.is_dir() => (None, m),
                // Not there (yet): locked when it appears.
                _ => return Ok(false),
            },
        };
        let id = (meta.dev(), meta.ino());
        if let Some(h) = self.held.get_mut(&id) {
            // The same folder under another name: ours already.
            h.names += 1;
            self.names.insert(folder.to_owned(), Some(id));
            return Ok(true);
        }
        if self.at_limit() {
            return Err(Refused::Daemon(format!(
                "cannot keep {}: this daemon keeps {} folders, as many as its open-file limit \
                 ({}) allows with {RESERVE} descriptors left for the compiles and {} for the \
                 deploy hooks; raise the limit (systemd: LimitNOFILE=) or split the folders \
                 between services",
                folder.display(),
                self.held.len(),
                self.limit,
                self.hooks
            )));
        }
        let real = std::fs::canonicalize(folder).unwrap_or_else(|_| folder.to_owned());
        let note = self.dir.join(lock_name(&real));
        let file = match dir.map(|d| {
            let r = rustix::fs::flock(&d, rustix::fs::FlockOperation::NonBlockingLockExclusive);
            (d, r)
        }) {
            Some((d, Ok(()))) => d,
            Some((_, Err(rustix::io::Errno::WOULDBLOCK))) => {
                return Err(self.refusal(&real, &note, Some(id)));
            }
            // No flock on folders here (a network file system), or the folder cannot be opened:
            // the lock file instead.
            _ => self.lock_file(&real, &note).map_err(Refused::Daemon)?,
        };
        let note = self.write_note(&note, &real);
        self.held.insert(
            id,
            Held {
                names: 1,
                _file: file,
                note,
            },
        );
        self.names.insert(folder.to_owned(), Some(id));
        Ok(true)
    }

    /// Why `real` (whose locked file is `id`) cannot be locked: another skillpost daemon keeps
    /// it, or another program holds a lock on it. The holder's pid comes from the kernel's list
    /// of locks, else from the note a daemon leaves; a holder the kernel names is a daemon only
    /// when it is a skillpost process ([`not_skillpost`]). Without `/proc`, a daemon.
    fn refusal(&self, real: &Path, note: &Path, id: Option<Id>) -> Refused {
        let from_note = || {
            crate::load::read_limited(note, 4096)
                .ok()
                .and_then(|b| String::from_utf8(b).ok())
                .and_then(|t| {
                    t.lines()
                        .next()
                        .and_then(|l| l.strip_prefix("pid "))
                        .and_then(|p| p.parse::<u32>().ok())
                })
        };
        let holder = id.and_then(holder_pid);
        if let Some(pid) = holder
            && let Some(name) = not_skillpost(pid)
        {
            return Refused::Other(format!(
                "{} is locked by {name} (pid {pid}), a program that is not a skillpost daemon \
                 (a `flock` of someone working there?): this folder waits until the lock is let \
                 go (tried again every 2 s); the other folders are served",
                real.display()
            ));
        }
        let pid = holder
            .or_else(from_note)
            .map(|p| format!(" (pid {p})"))
            .unwrap_or_default();
        Refused::Daemon(format!(
            "another skillpost daemon{pid} already watches {}: one daemon per folder",
            real.display()
        ))
    }

    /// The runtime directory, made if needed: a folder of our own nobody else can write to.
    fn own_dir(&self) -> Result<(), String> {
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(&self.dir)
            .map_err(|e| {
                format!(
                    "cannot create the lock directory {}: {e}",
                    self.dir.display()
                )
            })?;
        // In a shared temporary directory someone else could have made it first: only a folder
        // of our own that nobody else can write to is used (and links are never followed).
        let meta = std::fs::symlink_metadata(&self.dir)
            .map_err(|e| format!("cannot use the lock directory {}: {e}", self.dir.display()))?;
        if !meta.is_dir()
            || meta.uid() != rustix::process::getuid().as_raw()
            || meta.mode() & 0o022 != 0
        {
            return Err(format!(
                "the lock directory {} is not a folder of this user that only it can write to; \
                 set RUNTIME_DIRECTORY or XDG_RUNTIME_DIR",
                self.dir.display()
            ));
        }
        Ok(())
    }

    /// Writes the note naming our pid (best effort: it is only for messages).
    fn write_note(&self, note: &Path, real: &Path) -> Option<PathBuf> {
        self.own_dir().ok()?;
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .mode(0o600)
            .custom_flags(rustix::fs::OFlags::NOFOLLOW.bits() as i32)
            .open(note)
            .ok()?;
        writeln!(f, "pid {}\n{}", std::process::id(), real.display()).ok()?;
        Some(note.to_owned())
    }

    /// The stand-in where folders cannot be locked: a lock file in the runtime directory.
    fn lock_file(&self, real: &Path, file: &Path) -> Result<File, String> {
        self.own_dir()?;
        for _ in 0..10 {
            let f = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .mode(0o600)
                .custom_flags(rustix::fs::OFlags::NOFOLLOW.bits() as i32)
                .open(file)
                .map_err(|e| format!("cannot open the lock file {}: {e}", file.display()))?;
            match rustix::fs::flock(&f, rustix::fs::FlockOperation::NonBlockingLockExclusive) {
                Ok(()) => {}
                Err(rustix::io::Errno::WOULDBLOCK) => {
                    let id = f.metadata().ok().map(|m| (m.dev(), m.ino()));
                    return Err(self.refusal(real, file, id).into_sentence());
                }
                Err(e) => return Err(format!("cannot lock {}: {e}", file.display())),
            }
            // The holder before us may have removed the file between our open and our lock.
            let ours = f.metadata().map(|m| (m.dev(), m.ino())).ok();
            let now = std::fs::metadata(file).map(|m| (m.dev(), m.ino())).ok();
            if ours.is_none() || ours != now {
                continue;
            }
            return Ok(f);
        }
        Err(format!(
            "cannot lock {}: it keeps being replaced",
            file.display()
        ))
    }

    /// Releases the lock of `folder` (removing its note first, while the lock is still ours).
    pub(super) fn release(&mut self, folder: &Path) {
        let Some(Some(id)) = self.names.remove(folder) else {
            return;
        };
        let Some(h) = self.held.get_mut(&id) else {
            return;
        };
        h.names -= 1;
        if h.names == 0 {
            if let Some(note) = &h.note {
                let _ = std::fs::remove_file(note);
            }
            self.held.remove(&id);
        }
    }
}

impl Drop for Locks {
    fn drop(&mut self) {
        for h in self.held.values() {
            if let Some(note) = &h.note {
                let _ = std::fs::remove_file(note);
            }
        }
    }
}

/// Why a folder cannot be locked.
enum Refused {
    /// Another skillpost daemon keeps it, or it cannot be locked at all: refused.
    Daemon(String),
    /// Another program holds a lock on it: this folder waits, the daemon goes on.
    Other(String),
}

impl Refused {
    fn into_sentence(self) -> String {
        match self {
            Refused::Daemon(s) | Refused::Other(s) => s,
        }
    }
}

/// `None` when `pid` is a skillpost process (this one, one whose command is `skillpost`, or one
/// running the same executable); else the program's name as the kernel gives it (`flock`), or
/// a sentence when the process has ended (a child it started may hold the lock on).
fn not_skillpost(pid: u32) -> Option<String> {
    if pid == std::process::id() {
        return None;
    }
    let Ok(comm) = std::fs::read_to_string(format!("/proc/{pid}/comm")) else {
        // Hidden (`hidepid`, another user's process): it may be a daemon.
        let gone = rustix::process::Pid::from_raw(pid as i32)
            .is_some_and(|p| rustix::process::test_kill_process(p) == Err(rustix::io::Errno::SRCH));
        return gone
            .then(|| "a process that has ended (a program it started holds the lock)".into());
    };
    let comm = comm.trim_end_matches('\n');
    if comm == "skillpost" {
        return None;
    }
    let id = |p: &str| std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()));
    if id(&format!("/proc/{pid}/exe")).is_some_and(|e| Some(e) == id("/proc/self/exe")) {
        return None;
    }
    Some(format!("`{comm}`"))
}

/// The pid holding an `flock` on the file `id`, as the kernel's list of locks says
/// (`/proc/locks`, readable by every user: `1: FLOCK  ADVISORY  WRITE 4242 fe:00:1234 0 EOF`,
/// the device's major and minor number in hexadecimal, the inode in decimal).
fn holder_pid((dev, ino): Id) -> Option<u32> {
    let text = std::fs::read_to_string("/proc/locks").ok()?;
    let at = format!(
        "{:02x}:{:02x}:{ino}",
        rustix::fs::major(dev),
        rustix::fs::minor(dev)
    );
    text.lines().find_map(|l| {
        let f: Vec<&str> = l.split_whitespace().collect();
        // A waiter's line reads `1: -> FLOCK ...`: only the holder's has FLOCK second.
        (f.get(1) == Some(&"FLOCK") && f.get(5) == Some(&at.as_str()))
            .then(|| f.get(4)?.parse::<u32>().ok().filter(|p| *p > 0))
            .flatten()
    })
}

/// The lock file name of a canonical folder path: FNV-1a of its bytes (stable across versions
/// and builds, unlike the standard library's hasher) and its last component, made safe.
fn lock_name(real: &Path) -> String {
    use std::os::unix::ffi::OsStrExt;
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in real.as_os_str().as_bytes() {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    let tail: String = real
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .take(40)
        .collect();
    format!("{h:016x}-{tail}.lock")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn second_holder_is_refused_until_the_first_releases() {
        let d = tempfile::tempdir().unwrap();
        let folder = d.path().join("project");
        std::fs::create_dir(&folder).unwrap();
        let mut a = Locks::new(d.path().join("run"));
        let mut b = Locks::new(d.path().join("run"));
        a.acquire(&folder).unwrap();
        a.acquire(&folder).unwrap();
        let e = b.acquire(&folder).unwrap_err();
        assert!(e.contains("another skillpost daemon"), "{e}");
        assert!(e.contains(&format!("pid {}", std::process::id())), "{e}");
        // Another path to the same folder is the same lock.
        let link = d.path().join("alias");
        std::os::unix::fs::symlink(&folder, &link).unwrap();
        assert!(b.acquire(&link).is_err());
        // The holder itself may name it twice (an alias of a project it keeps).
        a.acquire(&link).unwrap();
        a.release(&folder);
        assert!(b.acquire(&link).is_err());
        a.release(&link);
        b.acquire(&link).unwrap();
        assert_eq!(std::fs::read_dir(d.path().join("run")).unwrap().count(), 1);
        drop(b);
        assert_eq!(std::fs::read_dir(d.path().join("run")).unwrap().count(), 0);
    }

    #[test]
    fn daemons_with_other_runtime_directories_meet_at_the_folder() {
        // Issue 27, item 2 (and issue 24, finding 5): the lock is the folder's own, so a
        // daemon with another runtime directory (another user, a hand-started check) is refused.
        let d = tempfile::tempdir().unwrap();
        let folder = d.path().join("project");
        std::fs::create_dir(&folder).unwrap();
        let mut a = Locks::new(d.path().join("run-a"));
        let mut b = Locks::new(d.path().join("run-b"));
        a.acquire(&folder).unwrap();
        let e = b.acquire(&folder).unwrap_err();
        assert!(e.contains("another skillpost daemon"), "{e}");
        // Its pid, though its note is in another runtime directory: the kernel's list of locks.
        if Path::new("/proc/locks").exists() {
            assert!(e.contains(&format!("(pid {})", std::process::id())), "{e}");
        }
        drop(a);
        b.acquire(&folder).unwrap();
    }

    #[test]
    fn a_missing_folder_is_locked_when_it_appears_under_any_name() {
        // Issue 24, finding 5: `real/P` in one daemon, `alias/P` (a linked parent) in another,
        // both missing at startup: whichever locks it first when it appears keeps it.
        let d = tempfile::tempdir().unwrap();
        std::fs::create_dir(d.path().join("real")).unwrap();
        std::os::unix::fs::symlink(d.path().join("real"), d.path().join("alias")).unwrap();
        let (real, alias) = (d.path().join("real/P"), d.path().join("alias/P"));
        let mut a = Locks::new(d.path().join("run-a"));
        let mut b = Locks::new(d.path().join("run-b"));
        a.acquire(&real).unwrap();
        b.acquire(&alias).unwrap();
        assert!(
            a.held.is_empty() && b.held.is_empty(),
            "no descriptor while missing"
        );
        // Missing: kept, but not held, so its caller compiles nothing yet (a folder that
        // appears right after this answer is not ours until a later `ensure` says so).
        assert_eq!(a.ensure(&real), Ok(false));
        std::fs::create_dir(&real).unwrap();
        assert_eq!(a.ensure(&real), Ok(true));
        let e = b.ensure(&alias).unwrap_err();
        assert!(e.contains("another skillpost daemon"), "{e}");
        // The folder made again (a new inode): the lock follows it.
        drop(b);
        std::fs::remove_dir(&real).unwrap();
        std::fs::create_dir(&real).unwrap();
        let mut c = Locks::new(d.path().join("run-c"));
        c.acquire(&alias).unwrap();
        assert!(a.ensure(&real).is_err(), "a kept the old inode's lock only");
        drop(c);
        assert_eq!(a.ensure(&real), Ok(true));
    }

    #[test]
    fn locks_stop_short_of_the_open_file_limit() {
        // Issue 24, finding 7: never more folder descriptors than the limit less the reserve.
        let d = tempfile::tempdir().unwrap();
        let mut a = Locks::new(d.path().join("run")).with_limit(RESERVE + 2);
        let mut errors = Vec::new();
        for i in 0..4 {
            let f = d.path().join(format!("p{i}"));
            std::fs::create_dir(&f).unwrap();
            if let Err(e) = a.acquire(&f) {
                errors.push(e);
            }
        }
        assert_eq!(a.held.len(), 2);
        assert_eq!(errors.len(), 2);
        assert!(errors[0].contains("open-file limit"), "{}", errors[0]);
    }

    #[test]
    fn a_note_is_never_written_where_others_can_write() {
        use std::os::unix::fs::PermissionsExt;
        let d = tempfile::tempdir().unwrap();
        let run = d.path().join("run");
        std::fs::create_dir(&run).unwrap();
        std::fs::set_permissions(&run, std::fs::Permissions::from_mode(0o777)).unwrap();
        let folder = d.path().join("p");
        std::fs::create_dir(&folder).unwrap();
        // The folder's own lock does not need the runtime directory.
        Locks::new(run.clone()).acquire(&folder).unwrap();
        assert_eq!(std::fs::read_dir(&run).unwrap().count(), 0);
    }

    #[test]
    fn names_are_stable() {
        // FNV-1a: the same name in every build and version, so two daemons always meet.
        assert_eq!(
            lock_name(Path::new("/srv/cells/Zelle A")),
            "22beeed842aa1f09-Zelle_A.lock"
        );
    }
}
