//! Directory watches: notify's native backend (inotify) where the file system reports changes,
//! polling ([`StatPoller`]) where it does not (NFS, SMB/CIFS, FUSE, or when inotify runs out).
//!
//! Every watch is a non-recursive watch on a directory, counted per user, so a directory shared
//! by several projects (a common IRL folder) is watched once. Events and errors arrive on one
//! channel as [`WatchMsg`].

use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::time::Duration;

use notify::{RecommendedWatcher, RecursiveMode, Watcher};

use super::poll::StatPoller;
use tokio::sync::mpsc::UnboundedSender;

/// What the watchers report.
#[derive(Debug)]
pub enum WatchMsg {
    Event(notify::Event),
    Error(notify::Error),
}

/// How a directory is watched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    Native,
    Poll,
}

impl Backend {
    pub fn as_str(self) -> &'static str {
        match self {
            Backend::Native => "inotify",
            Backend::Poll => "poll",
        }
    }
}

/// Why a directory could not be watched natively, or not at all.
#[derive(Debug)]
pub enum WatchFailure {
    /// The directory does not exist (yet).
    Missing,
    /// Another error (permissions, ...).
    Other(String),
}

/// The file-system kinds without (reliable) change notification, by `statfs` magic number.
pub fn needs_polling(dir: &Path) -> Option<&'static str> {
    let st = rustix::fs::statfs(dir).ok()?;
    // `f_type` is signed on some targets; compare as u32 bit patterns.
    match st.f_type as u32 {
        0x6969 => Some("nfs"),
        0x517B => Some("smb"),
        0xFF53_4D42 => Some("cifs"),
        0xFE53_4D42 => Some("smb2"),
        0x6573_5546 => Some("fuse"),
        0x0102_1997 => Some("9p"),
        0x7366_746E | 0x5346_414F => Some("afs"),
        _ => None,
    }
}

/// The daemon's watches.
///
/// Watches are keyed by the directory's canonical path: inotify gives one watch per inode, so two
/// paths to one folder (a symbolic-link alias of a project) would share it, and removing one
/// would remove it for both. Each path asked for is counted by name and mapped to its canonical
/// directory, which is watched once; [`Watchers::expand`] gives an event's path under every name
/// it was asked for, so routing by the names works as before.
pub struct Watchers {
    tx: UnboundedSender<WatchMsg>,
    native: Option<RecommendedWatcher>,
    poll: Option<StatPoller>,
    poll_interval: Duration,
    /// Canonical directory → (users, backend).
    dirs: HashMap<PathBuf, (usize, Backend)>,
    /// Directory as asked for → (users, its canonical directory).
    names: HashMap<PathBuf, (usize, PathBuf)>,
    /// Canonical directory → the names it was asked for by, where one differs from it.
    aliases: HashMap<PathBuf, BTreeSet<PathBuf>>,
}

impl Watchers {
    pub fn new(tx: UnboundedSender<WatchMsg>, poll_interval: Duration) -> Self {
        let native = RecommendedWatcher::new(forward(tx.clone()), notify::Config::default())
            .map_err(|e| tracing::warn!("native file watching unavailable, polling instead: {e}"))
            .ok();
        Watchers {
            tx,
            native,
            poll: None,
            poll_interval,
            dirs: HashMap::new(),
            names: HashMap::new(),
            aliases: HashMap::new(),
        }
    }

    fn poller(&mut self) -> Result<&mut StatPoller, WatchFailure> {
        if self.poll.is_none() {
            let w = StatPoller::new(forward(self.tx.clone()), self.poll_interval)
                .map_err(|e| WatchFailure::Other(e.to_string()))?;
            self.poll = Some(w);
        }
        Ok(self.poll.as_mut().expect("just set"))
    }

    /// Watches `dir` for one more user. `poll` forces polling. Returns the backend used, and the
    /// reason when that is polling although native watching was asked for.
    pub fn add(
        &mut self,
        dir: &Path,
        poll: bool,
    ) -> Result<(Backend, Option<String>), WatchFailure> {
        if let Some((n, canonical)) = self.names.get_mut(dir)
            && let Some((m, b)) = self.dirs.get_mut(canonical)
        {
            *n += 1;
            *m += 1;
            return Ok((*b, None));
        }
        if !dir.is_dir() {
            return Err(WatchFailure::Missing);
        }
        let canonical = std::fs::canonicalize(dir).map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                WatchFailure::Missing
            } else {
                WatchFailure::Other(e.to_string())
            }
        })?;
        let result = match self.dirs.get_mut(&canonical) {
            Some((m, b)) => {
                *m += 1;
                (*b, None)
            }
            None => {
                let (backend, why) = self.start(&canonical, poll)?;
                self.dirs.insert(canonical.clone(), (1, backend));
                (backend, why)
            }
        };
        self.name(dir, canonical);
        Ok(result)
    }

    /// Counts one user of `dir` by name (its watch is already counted).
    fn name(&mut self, dir: &Path, canonical: PathBuf) {
        if canonical != dir {
            self.aliases
                .entry(canonical.clone())
                .or_default()
                .insert(dir.to_owned());
        }
        self.names
            .entry(dir.to_owned())
            .and_modify(|(n, _)| *n += 1)
            .or_insert((1, canonical));
    }

    /// Watches `dir` for one more user, renewing the watch if it exists already (the directory
    /// may have been deleted and created again, which ends the kernel's watch).
    pub fn add_renewed(
        &mut self,
        dir: &Path,
        poll: bool,
    ) -> Result<(Backend, Option<String>), WatchFailure> {
        if self.names.contains_key(dir) {
            self.renew(dir, poll)?;
        }
        self.add(dir, poll)
    }

    /// An event's path under every name its directory (or, for a watched directory itself, the
    /// directory) was asked for: the path itself first.
    pub fn expand(&self, path: &Path) -> Vec<PathBuf> {
        let mut out = vec![path.to_owned()];
        if let Some(names) = self.aliases.get(path) {
            out.extend(names.iter().cloned());
        }
        if let (Some(parent), Some(file)) = (path.parent(), path.file_name())
            && let Some(names) = self.aliases.get(parent)
        {
            out.extend(names.iter().map(|n| n.join(file)));
        }
        out
    }

    fn start(&mut self, dir: &Path, poll: bool) -> Result<(Backend, Option<String>), WatchFailure> {
        let mut why = if poll {
            Some("polling requested".to_owned())
        } else {
            needs_polling(dir).map(|fs| format!("{fs} file system: no change notification"))
        };
        if why.is_none() {
            match self.native.as_mut() {
                Some(w) => match w.watch(dir, RecursiveMode::NonRecursive) {
                    Ok(()) => return Ok((Backend::Native, None)),
                    Err(e) => match e.kind {
                        notify::ErrorKind::MaxFilesWatch => {
                            why = Some(
                                "inotify watches exhausted (fs.inotify.max_user_watches)".into(),
                            )
                        }
                        notify::ErrorKind::PathNotFound => return Err(WatchFailure::Missing),
                        notify::ErrorKind::Io(ref io)
                            if io.kind() == std::io::ErrorKind::NotFound =>
                        {
                            return Err(WatchFailure::Missing);
                        }
                        _ => why = Some(format!("native watch failed: {e}")),
                    },
                },
                None => why = Some("native file watching unavailable".into()),
            }
        }
        self.poller()?.watch(dir).map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                WatchFailure::Missing
            } else {
                WatchFailure::Other(e.to_string())
            }
        })?;
        Ok((Backend::Poll, why))
    }

    /// One user fewer; the watch ends with the last one.
    pub fn remove(&mut self, dir: &Path) {
        let Some((n, canonical)) = self.names.get_mut(dir) else {
            return;
        };
        *n -= 1;
        let canonical = canonical.clone();
        if *n == 0 {
            self.names.remove(dir);
            if let Some(set) = self.aliases.get_mut(&canonical) {
                set.remove(dir);
                if set.is_empty() {
                    self.aliases.remove(&canonical);
                }
            }
        }
        let Some((m, b)) = self.dirs.get_mut(&canonical) else {
            return;
        };
        *m -= 1;
        if *m > 0 {
            return;
        }
        let b = *b;
        self.dirs.remove(&canonical);
        self.unwatch(&canonical, b);
    }

    /// Renews the watch of a directory that was deleted and created again (the kernel dropped
    /// the old watch with the old directory). Its users and names are kept; the new directory
    /// may resolve elsewhere (a link pointed to another folder meanwhile).
    pub fn renew(&mut self, dir: &Path, poll: bool) -> Result<Backend, WatchFailure> {
        let Some((n, old)) = self.names.get(dir).cloned() else {
            return self.add(dir, poll).map(|(b, _)| b);
        };
        if let Some(&(_, b)) = self.dirs.get(&old) {
            self.unwatch(&old, b);
        }
        let canonical = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_owned());
        if canonical == old {
            let (backend, _) = self.start(&old, poll).inspect_err(|_| {
                // Gone again: counted, not watched; the next renewal starts it.
                self.dirs.entry(old.clone()).or_insert((n, Backend::Native));
            })?;
            self.dirs.entry(old).or_insert((n, backend)).1 = backend;
            return Ok(backend);
        }
        // Move this name's users from the old directory to the new one.
        for _ in 0..n {
            self.remove(dir);
        }
        if self.dirs.contains_key(&old)
            && let Ok((b, _)) = self.start(&old, poll)
        {
            // Still used by other names: watch the old directory again.
            self.dirs.get_mut(&old).expect("present").1 = b;
        }
        let (backend, _) = self.add(dir, poll)?;
        for _ in 1..n {
            let _ = self.add(dir, poll);
        }
        Ok(backend)
    }

    /// Ends the watch of `dir` by the backend that has it (errors ignored: the watch may be gone
    /// with the directory).
    fn unwatch(&mut self, dir: &Path, backend: Backend) {
        match backend {
            Backend::Native => {
                if let Some(w) = self.native.as_mut() {
                    let _ = w.unwatch(dir);
                }
            }
            Backend::Poll => {
                if let Some(w) = self.poll.as_mut() {
                    w.unwatch(dir);
                }
            }
        }
    }

    /// The backend watching `dir` (by the name it was asked for).
    pub fn backend_of(&self, dir: &Path) -> Option<Backend> {
        let (_, canonical) = self.names.get(dir)?;
        self.dirs.get(canonical).map(|(_, b)| *b)
    }

    /// The number of directories watched.
    #[allow(clippy::len_without_is_empty)]
    pub fn len(&self) -> usize {
        self.dirs.len()
    }
}

/// The event handler of both backends: every event and error onto the daemon's channel.
fn forward(
    tx: UnboundedSender<WatchMsg>,
) -> impl Fn(notify::Result<notify::Event>) + Send + Sync + 'static {
    move |r| {
        let _ = tx.send(match r {
            Ok(e) => WatchMsg::Event(e),
            Err(e) => WatchMsg::Error(e),
        });
    }
}

/// Files that never start a compile: our own temporary files and editors' backup, swap and
/// temporary files. (A save by rename still reports the final name, which is what counts.)
pub fn is_noise(path: &Path) -> bool {
    let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
        return false;
    };
    crate::write::is_temporary(name)
        || name.ends_with('~')
        || name.starts_with(".#")
        || (name.starts_with('#') && name.ends_with('#'))
        || name.ends_with(".swp")
        || name.ends_with(".swx")
        || name.ends_with(".swo")
        || name == "4913"
        || name.ends_with("___jb_tmp___")
        || name.ends_with("___jb_old___")
        || name.ends_with(".tmp")
        || name.ends_with(".bak")
        || name.ends_with(".orig")
        || name.starts_with(".goutputstream-")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise() {
        for n in [
            ".skillpost-ab12cd.tmp",
            "sfc.xml~",
            ".sfc.xml.swp",
            "4913",
            ".#sfc.xml",
            "sfc.xml___jb_tmp___",
            "sfc.xml.tmp",
        ] {
            assert!(is_noise(Path::new(n)), "{n}");
        }
        for n in ["sfc.xml", "Zelle_A.aml", "kr15-2.irl", "tmp.xml"] {
            assert!(!is_noise(Path::new(n)), "{n}");
        }
    }

    #[test]
    fn two_names_of_one_folder_share_one_watch_and_removing_one_keeps_it() {
        let d = tempfile::tempdir().unwrap();
        let real = d.path().canonicalize().unwrap().join("real");
        std::fs::create_dir(&real).unwrap();
        let alias = real.with_file_name("alias");
        std::os::unix::fs::symlink(&real, &alias).unwrap();
        let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel();
        let mut w = Watchers::new(tx, Duration::from_millis(200));
        w.add(&real, false).unwrap();
        w.add(&alias, false).unwrap();
        assert_eq!(w.len(), 1, "one inode, one watch");
        assert_eq!(
            w.expand(&real.join("sfc.xml")),
            vec![real.join("sfc.xml"), alias.join("sfc.xml")]
        );
        // Dropping the alias (a reload) must not end the real folder's watch.
        w.remove(&alias);
        assert_eq!(w.len(), 1);
        assert_eq!(w.expand(&real.join("sfc.xml")), vec![real.join("sfc.xml")]);
        std::fs::write(real.join("sfc.xml"), "x").unwrap();
        let deadline = std::time::Instant::now() + Duration::from_secs(5);
        let mut seen = false;
        while !seen && std::time::Instant::now() < deadline {
            match rx.try_recv() {
                Ok(WatchMsg::Event(e)) => seen = e.paths.contains(&real.join("sfc.xml")),
                Ok(WatchMsg::Error(e)) => panic!("{e}"),
                Err(_) => std::thread::sleep(Duration::from_millis(10)),
            }
        }
        assert!(seen, "the real folder is still watched");
        w.remove(&real);
        assert_eq!(w.len(), 0);
    }

    #[test]
    fn local_folders_are_watched_natively() {
        let d = tempfile::tempdir().unwrap();
        assert_eq!(needs_polling(d.path()), None);
        let (tx, _rx) = tokio::sync::mpsc::unbounded_channel();
        let mut w = Watchers::new(tx, Duration::from_millis(200));
        assert_eq!(w.add(d.path(), false).unwrap().0, Backend::Native);
        assert_eq!(w.add(d.path(), false).unwrap().0, Backend::Native);
        assert_eq!(w.len(), 1);
        w.remove(d.path());
        assert_eq!(w.len(), 1);
        w.remove(d.path());
        assert_eq!(w.len(), 0);
        let (b, why) = w.add(d.path(), true).unwrap();
        assert_eq!(b, Backend::Poll);
        assert!(why.is_some());
        assert!(matches!(
            w.add(&d.path().join("missing"), false),
            Err(WatchFailure::Missing)
        ));
    }
}
