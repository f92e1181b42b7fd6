//! One daemon per folder: an advisory lock (`flock`) per watched folder, so a second
//! `skillpost watch` on a folder another one keeps (even with another configuration) is refused
//! instead of deleting the first one's staged files and racing its writes.
//!
//! The lock files live in the runtime directory: `$RUNTIME_DIRECTORY` (systemd's
//! `RuntimeDirectory=`), else `$XDG_RUNTIME_DIR/skillpost`, else `<temp dir>/skillpost-<uid>`.
//! A folder's lock file is named by a hash of its canonical path (plus its last component, for
//! people reading the directory) and holds the pid and path of the daemon that keeps it. The lock
//! is the kernel's: it ends with the process, whatever the way it ends (`kill -9` included), so a
//! stale file never blocks a restart. A released lock's file is removed; a daemon that took the
//! lock on a file removed meanwhile notices (the path names another inode) and tries again.

use std::collections::HashMap;
use std::fs::File;
use std::io::Write;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

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

/// The folder locks this daemon holds.
pub(super) struct Locks {
    dir: PathBuf,
    /// Folder as given → its lock file (two names of one folder share it).
    names: HashMap<PathBuf, PathBuf>,
    /// Lock file → (the names holding it, the open file holding the lock).
    held: HashMap<PathBuf, (usize, File)>,
}

impl Locks {
    pub(super) fn new(dir: PathBuf) -> Self {
        Locks {
            dir,
            names: HashMap::new(),
            held: HashMap::new(),
        }
    }

    pub(super) fn holds(&self, folder: &Path) -> bool {
        self.names.contains_key(folder)
    }

    /// Takes the lock of `folder` (by its canonical path, or the path itself while it does not
    /// exist). Error: the sentence to report (another daemon keeps it, or the lock cannot be
    /// taken).
    pub(super) fn acquire(&mut self, folder: &Path) -> Result<(), String> {
        if self.holds(folder) {
            return Ok(());
        }
        let real = std::fs::canonicalize(folder).unwrap_or_else(|_| folder.to_owned());
        let file = self.dir.join(lock_name(&real));
        if let Some((n, _)) = self.held.get_mut(&file) {
            // The same folder under another name: ours already.
            *n += 1;
            self.names.insert(folder.to_owned(), file);
            return Ok(());
        }
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
        for _ in 0..10 {
            let f = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .mode(0o600)
                .custom_flags(rustix::fs::OFlags::NOFOLLOW.bits() as i32)
                .open(&file)
                .map_err(|e| format!("cannot open the lock file {}: {e}", file.display()))?;
            match rustix::fs::flock(&f, rustix::fs::FlockOperation::NonBlockingLockExclusive) {
                Ok(()) => {}
                Err(rustix::io::Errno::WOULDBLOCK) => {
                    let holder = crate::load::read_limited(&file, 4096)
                        .ok()
                        .and_then(|b| String::from_utf8(b).ok())
                        .and_then(|t| t.lines().next().map(str::to_owned))
                        .unwrap_or_default();
                    let pid = holder
                        .strip_prefix("pid ")
                        .map(|p| format!(" (pid {p})"))
                        .unwrap_or_default();
                    return Err(format!(
                        "another skillpost daemon{pid} already watches {}: one daemon per folder \
                         (lock file {})",
                        real.display(),
                        file.display()
                    ));
                }
                Err(e) => return Err(format!("cannot lock {}: {e}", file.display())),
            }
            // The holder before us may have removed the file between our open and our lock.
            let ours = f.metadata().map(|m| (m.dev(), m.ino())).ok();
            let now = std::fs::metadata(&file).map(|m| (m.dev(), m.ino())).ok();
            if ours.is_none() || ours != now {
                continue;
            }
            let mut f = f;
            let _ = f.set_len(0);
            let _ = writeln!(f, "pid {}\n{}", std::process::id(), real.display());
            self.held.insert(file.clone(), (1, f));
            self.names.insert(folder.to_owned(), file);
            return Ok(());
        }
        Err(format!(
            "cannot lock {}: it keeps being replaced",
            file.display()
        ))
    }

    /// Releases the lock of `folder` (removing its file first, while the lock is still ours).
    pub(super) fn release(&mut self, folder: &Path) {
        let Some(file) = self.names.remove(folder) else {
            return;
        };
        let Some((n, _)) = self.held.get_mut(&file) else {
            return;
        };
        *n -= 1;
        if *n == 0 {
            let _ = std::fs::remove_file(&file);
            self.held.remove(&file);
        }
    }
}

impl Drop for Locks {
    fn drop(&mut self) {
        for file in self.held.keys() {
            let _ = std::fs::remove_file(file);
        }
    }
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
    fn a_lock_directory_others_can_write_to_is_refused() {
        use std::os::unix::fs::PermissionsExt;
        let d = tempfile::tempdir().unwrap();
        let run = d.path().join("run");
        std::fs::create_dir(&run).unwrap();
        std::fs::set_permissions(&run, std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = Locks::new(run).acquire(d.path()).unwrap_err();
        assert!(e.contains("only it can write to"), "{e}");
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
