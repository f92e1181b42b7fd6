//! The project folder, held open from the start of a compile to the end of its writing, so the
//! outputs land in the folder whose inputs were read.
//!
//! A planner (or an attacker) can move the folder away and put a link to another folder at its
//! name while a compile runs (`mv P P.real; ln -s OUT P`). Writing by path would then put the
//! `.src`/`.dat` (or a rewritten blackboard) into `OUT`. [`Folder::pin`] opens the folder once
//! (`O_PATH`) before the blackboard is read; every write goes through `/proc/self/fd/N/<name>`
//! ([`Folder::route`]), which the kernel resolves to that open folder whatever its name is now;
//! and [`Folder::still_at_its_name`] tells `compile::apply` whether the name still leads to it (a
//! compile whose folder was replaced writes nothing: its inputs may be a mix of both folders).
//! Where `/proc` is not mounted the paths are used as they are (the check still runs).

use std::os::fd::{AsRawFd as _, OwnedFd};
use std::os::unix::fs::MetadataExt as _;
use std::path::{Path, PathBuf};

/// An open project folder (see the module documentation).
#[derive(Debug)]
pub struct Folder {
    /// The folder's name as the compile used it (absolute).
    path: PathBuf,
    fd: OwnedFd,
    /// Device and inode of the open folder.
    id: (u64, u64),
    /// `/proc/self/fd/N`, when it leads to the open folder.
    via: Option<PathBuf>,
}

impl Folder {
    /// Opens the folder `path` (following links, as the compile's reads do). `None` when it
    /// cannot be opened: the compile then reports what it cannot read, and nothing is written.
    pub fn pin(path: &Path) -> Option<Folder> {
        let path = crate::paths::absolute(path);
        let flags =
            rustix::fs::OFlags::PATH | rustix::fs::OFlags::DIRECTORY | rustix::fs::OFlags::CLOEXEC;
        let fd = rustix::fs::open(&path, flags, rustix::fs::Mode::empty()).ok()?;
        let st = rustix::fs::fstat(&fd).ok()?;
        let id = (st.st_dev, st.st_ino);
        let via = PathBuf::from(format!("/proc/self/fd/{}", fd.as_raw_fd()));
        let via = std::fs::metadata(&via)
            .ok()
            .filter(|m| (m.dev(), m.ino()) == id)
            .map(|_| via);
        Some(Folder { path, fd, id, via })
    }

    /// Whether the folder's name still leads to the folder opened (not moved away, not replaced
    /// by another folder or a link to one).
    pub fn still_at_its_name(&self) -> bool {
        std::fs::metadata(&self.path).is_ok_and(|m| (m.dev(), m.ino()) == self.id)
            && rustix::fs::fstat(&self.fd).is_ok_and(|s| s.st_nlink > 0)
    }

    /// The folder's name (for messages).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The path to write `file` by: through the open folder when `file` lies directly in it,
    /// else `file` itself.
    pub fn route(&self, file: &Path) -> PathBuf {
        let abs = crate::paths::absolute(file);
        match (&self.via, abs.parent(), abs.file_name()) {
            (Some(via), Some(dir), Some(name)) if dir == self.path => via.join(name),
            _ => file.to_path_buf(),
        }
    }

    /// `message` with the routed prefix (`/proc/self/fd/N`) named as the folder again.
    pub fn unroute(&self, message: &str) -> String {
        match &self.via {
            Some(via) => message.replace(&*via.to_string_lossy(), &self.path.to_string_lossy()),
            None => message.to_owned(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_follow_the_folder_when_its_name_is_taken_by_a_link() {
        let t = tempfile::tempdir().unwrap();
        let p = t.path().join("P");
        let out = t.path().join("OUT");
        std::fs::create_dir(&p).unwrap();
        std::fs::create_dir(&out).unwrap();
        let f = Folder::pin(&p).unwrap();
        assert!(f.still_at_its_name());
        std::fs::rename(&p, t.path().join("P.real")).unwrap();
        std::os::unix::fs::symlink(&out, &p).unwrap();
        assert!(!f.still_at_its_name());
        let routed = f.route(&p.join("x.src"));
        std::fs::write(&routed, "x").unwrap();
        assert!(t.path().join("P.real/x.src").exists());
        assert_eq!(std::fs::read_dir(&out).unwrap().count(), 0);
        assert_eq!(f.route(&out.join("y")), out.join("y"));
        assert_eq!(
            f.unroute(&format!("cannot write {}", routed.display())),
            format!("cannot write {}", p.join("x.src").display())
        );
    }
}
