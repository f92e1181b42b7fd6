//! Atomic output files: a temporary file in the target's folder, `fsync`, `rename`, and the
//! `.src`/`.dat` pair as one change.
//!
//! Outputs are files skillpost owns: it refuses to write through a symbolic link (the link's
//! target may be anything, anywhere), onto anything but a regular file, and over a read-only
//! file (no write permission bit at all: someone froze it on purpose, and root would otherwise
//! replace it anyway). The blackboard is not an output; its write-back is in
//! [`super::writeback`].

use std::fs;
use std::io::{self, Write as _};
use std::path::{Path, PathBuf};

/// What happened to one output file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WriteOutcome {
    /// The file was created or replaced.
    Written,
    /// The file already held exactly these bytes; nothing was touched.
    Unchanged,
}

/// Writes `bytes` to `path` atomically unless the file already holds exactly these bytes (then
/// nothing is touched, not even the mtime).
///
/// The data goes to a temporary file `.skillpost-<random>.tmp` in the target's folder, is
/// flushed with `sync_all` and then renamed over the target; on Unix the folder is fsynced after
/// the rename (best effort: once the rename has happened the write has happened, so an error of
/// that fsync is not reported). On any error before the rename the temporary file is removed and
/// the target is untouched.
///
/// - **Permissions:** an existing target keeps its permission bits (Unix: the whole mode
///   including setuid/setgid/sticky; elsewhere: the read-only flag). A new file gets `0o666`
///   less the process umask on Unix, like any program's new file (`0o664` under the service's
///   `UMask=0002`, so planners in the group can write it): the temporary file is created with
///   mode `0o666`, which the kernel narrows by the umask, or by the folder's default ACL where it
///   has one, as for `cp` or an editor. A replacing temporary file is created `0o600` and then
///   given the mode of the file it replaces.
/// - **Ownership (Unix):** an existing target's owner and group are copied to the new file where
///   the process may do so (as root, or a group the user belongs to); failures are ignored, the
///   file then belongs to the writing user.
/// - **Refused** (an error, nothing written, nothing touched), unless the file already holds
///   exactly these bytes:
///   - `path` is a symbolic link (`InvalidInput`): an output is never written through a link, so
///     a link planted as `Prog.src` cannot make skillpost replace a file elsewhere;
///   - `path` exists and is not a regular file, a folder or a device (`InvalidInput`);
///   - `path` is read-only, its mode has no write bit at all (`PermissionDenied`), even for
///     root, who could replace it.
pub fn write_if_changed(path: &Path, bytes: &[u8]) -> io::Result<WriteOutcome> {
    match stage(path, bytes)? {
        None => Ok(WriteOutcome::Unchanged),
        Some(staged) => {
            staged.commit()?;
            Ok(WriteOutcome::Written)
        }
    }
}

/// New bytes for a file, written and synced to a temporary file in the target's folder, ready
/// to be renamed over it. Dropping it removes the temporary file.
struct Staged {
    /// The file to replace.
    target: PathBuf,
    dir: PathBuf,
    /// Whether the target exists (and is a regular file).
    existed: bool,
    tmp: tempfile::NamedTempFile,
}

/// Stages `bytes` for `path`; `None` when the file already holds exactly these bytes. Refuses
/// links, non-regular files and read-only files (see [`write_if_changed`]).
fn stage(path: &Path, bytes: &[u8]) -> io::Result<Option<Staged>> {
    let target = path.to_path_buf();
    let existing = match fs::symlink_metadata(&target) {
        Ok(m) => Some(m),
        Err(e) if e.kind() == io::ErrorKind::NotFound => None,
        Err(e) => return Err(e),
    };
    if let Some(m) = &existing {
        if m.file_type().is_symlink() {
            return Err(link_refused(&target));
        }
        if !m.is_file() {
            return Err(not_regular(&target));
        }
        if m.len() == bytes.len() as u64 && holds_exactly(&target, bytes)? {
            return Ok(None);
        }
        if read_only(m) {
            return Err(io::Error::new(
                io::ErrorKind::PermissionDenied,
                format!(
                    "{} is read-only (mode {:04o}); it is not replaced (make it writable to let skillpost write it)",
                    target.display(),
                    mode_of(m)
                ),
            ));
        }
    }
    let dir = parent_dir(&target);
    let tmp = stage_in(&dir, bytes, existing.as_ref())?;
    Ok(Some(Staged {
        target,
        dir,
        existed: existing.is_some(),
        tmp,
    }))
}

/// Whether the regular file at `path` holds exactly `bytes`, compared a piece at a time: an
/// output of 100,000 steps is 13 MB, and it is not read into memory a second time.
///
/// The caller checked the path's kind before; a file swapped in since then is not trusted. The
/// file is opened without following a link and without blocking, and its kind is checked on the
/// open handle: a symbolic link (say, to `/dev/zero`) is refused as [`stage`] refuses one, a FIFO
/// or a device is refused as not a regular file, and nothing is read past `bytes.len() + 1`
/// bytes (a file that grows meanwhile). A file gone meanwhile holds nothing.
fn holds_exactly(path: &Path, bytes: &[u8]) -> io::Result<bool> {
    use std::os::unix::fs::OpenOptionsExt as _;
    let flags = rustix::fs::OFlags::NOFOLLOW | rustix::fs::OFlags::NONBLOCK;
    let file = match fs::File::options()
        .read(true)
        .custom_flags(flags.bits() as i32)
        .open(path)
    {
        Ok(f) => f,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(false),
        Err(e) if e.raw_os_error() == Some(rustix::io::Errno::LOOP.raw_os_error()) => {
            return Err(link_refused(path));
        }
        Err(e) => return Err(e),
    };
    if !file.metadata()?.is_file() {
        return Err(not_regular(path));
    }
    super::holds(&file, bytes)
}

fn link_refused(path: &Path) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!(
            "{} is a symbolic link; an output is never written through a link (remove the link)",
            path.display()
        ),
    )
}

fn not_regular(path: &Path) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("{} exists and is not a regular file", path.display()),
    )
}

/// The folder a file is in (`.` for a bare name).
pub(super) fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// A temporary file `.skillpost-<random>.tmp` in `dir` holding `bytes`, with the permissions (and
/// owner, best effort) of `existing`, or a new file's (`0o666` less the umask), synced. Dropping
/// it removes it.
pub(super) fn stage_in(
    dir: &Path,
    bytes: &[u8],
    existing: Option<&fs::Metadata>,
) -> io::Result<tempfile::NamedTempFile> {
    // Dropping `tmp` (every early return below) removes the temporary file.
    let mut tmp = match existing {
        Some(_) => temp_builder().tempfile_in(dir)?,
        None => new_file_builder().tempfile_in(dir)?,
    };
    tmp.as_file_mut().write_all(bytes)?;
    if let Some(m) = existing {
        set_metadata(tmp.as_file(), m)?;
    }
    tmp.as_file().sync_all()?;
    Ok(tmp)
}

/// Whether no write permission bit is set (Unix); the read-only flag elsewhere.
fn read_only(m: &fs::Metadata) -> bool {
    #[cfg(unix)]
    {
        mode_of(m) & 0o222 == 0
    }
    #[cfg(not(unix))]
    {
        m.permissions().readonly()
    }
}

fn mode_of(m: &fs::Metadata) -> u32 {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        m.permissions().mode() & 0o7777
    }
    #[cfg(not(unix))]
    {
        if m.permissions().readonly() {
            0o444
        } else {
            0o644
        }
    }
}

impl Staged {
    /// Renames the temporary file over the target. On failure the temporary file is removed.
    fn commit(self) -> io::Result<()> {
        // On failure the `PersistError` hands the temporary file back; dropping it removes it.
        self.tmp.persist(&self.target).map_err(|e| e.error)?;
        sync_dir(&self.dir);
        Ok(())
    }
}

const TEMP_PREFIX: &str = ".skillpost-";
const TEMP_SUFFIX: &str = ".tmp";

/// Names our temporary files `.skillpost-<random>.tmp`: the daemon removes stale ones by that
/// pattern ([`is_temporary`]), and its watchers ignore them.
pub(super) fn temp_builder() -> tempfile::Builder<'static, 'static> {
    let mut b = tempfile::Builder::new();
    b.prefix(TEMP_PREFIX)
        .suffix(TEMP_SUFFIX)
        .rand_bytes(TEMP_RANDOM);
    b
}

/// [`temp_builder`] for a new file: created with mode `0o666`, which the kernel narrows as it
/// does for any program's new file (the umask, or a folder's default ACL), so the file needs no
/// `chmod` after.
fn new_file_builder() -> tempfile::Builder<'static, 'static> {
    let mut b = temp_builder();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        b.permissions(fs::Permissions::from_mode(0o666));
    }
    b
}

/// How many random letters and digits `tempfile` puts between prefix and suffix.
const TEMP_RANDOM: usize = 6;

/// Whether a file name is shaped exactly as our temporary files are (see `temp_builder`):
/// `.skillpost-`, six ASCII letters or digits, `.tmp`. The name alone does not make a file
/// ours: the daemon also checks that no project reads it before it removes one.
pub fn is_temporary(name: &str) -> bool {
    name.len() == TEMP_PREFIX.len() + TEMP_RANDOM + TEMP_SUFFIX.len()
        && name.starts_with(TEMP_PREFIX)
        && name.ends_with(TEMP_SUFFIX)
        && name[TEMP_PREFIX.len()..TEMP_PREFIX.len() + TEMP_RANDOM]
            .bytes()
            .all(|b| b.is_ascii_alphanumeric())
}

/// Best effort, see the doc comment of [`write_if_changed`].
pub(super) fn sync_dir(dir: &Path) {
    #[cfg(unix)]
    if let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
    #[cfg(not(unix))]
    let _ = dir;
}

/// Writes several files as one change (a program's `.src` and `.dat`, which only work as a
/// pair): each file is written like [`write_if_changed`] does, and either every changed file is
/// replaced or none is.
///
/// 1. Every file's new bytes are staged (temporary file written and synced); files that already
///    hold their bytes are left out. Any error: the temporary files are removed, nothing else
///    was touched.
/// 2. Every file about to be replaced gets a second name, `.skillpost-<random>.tmp` in its
///    folder (a hard link, or a copy where links are refused), to put it back with. Any error:
///    as in 1.
/// 3. The renames, in the order given. If one fails, the files already renamed are put back
///    (their second name renamed over them; a file that did not exist before is removed), and
///    the error says so. Only if putting one back fails too does the error name the file that
///    still holds the previous version.
///
/// A crash (`kill -9`, power loss) between two renames of step 3 can still leave one new and
/// one old file, each whole; the daemon compiles every project when it starts and writes the
/// pair again, as does the next command-line run. Stale second names are temporary files and are
/// removed like those.
///
/// Errors name the file they concern.
pub fn write_all_if_changed(files: &[(&Path, &[u8])]) -> io::Result<Vec<WriteOutcome>> {
    write_all_with_hook(files, &mut |_| {})
}

/// [`write_all_if_changed`] with a hook run before each rename of step 3 (tests use it to make a
/// rename fail).
fn write_all_with_hook(
    files: &[(&Path, &[u8])],
    before_rename: &mut dyn FnMut(&Path),
) -> io::Result<Vec<WriteOutcome>> {
    let named =
        |path: &Path, e: io::Error| io::Error::new(e.kind(), format!("{}: {e}", path.display()));
    let mut outcomes = Vec::with_capacity(files.len());
    let mut staged = Vec::new();
    for ((path, _), s) in files.iter().zip(stage_all(files)) {
        let s = s.map_err(|e| named(path, e))?;
        outcomes.push(if s.is_some() {
            WriteOutcome::Written
        } else {
            WriteOutcome::Unchanged
        });
        staged.extend(s);
    }
    let mut backups = Vec::with_capacity(staged.len());
    for s in &staged {
        backups.push(if s.existed {
            Some(second_name(&s.target, &s.dir).map_err(|e| named(&s.target, e))?)
        } else {
            None
        });
    }
    let targets: Vec<(PathBuf, PathBuf)> = staged
        .iter()
        .map(|s| (s.target.clone(), s.dir.clone()))
        .collect();
    for (k, s) in staged.into_iter().enumerate() {
        before_rename(&s.target);
        if let Err(e) = s.tmp.persist(&s.target).map_err(|e| e.error) {
            let mut msg = format!("{}: {e}", targets[k].0.display());
            for j in (0..k).rev() {
                let (target, dir) = &targets[j];
                match put_back(backups[j].take(), target) {
                    Ok(()) => {
                        msg.push_str(&format!("; {} was put back as it was", target.display()))
                    }
                    Err(why) => msg.push_str(&format!(
                        "; {} could not be put back: {why}",
                        target.display()
                    )),
                }
                sync_dir(dir);
            }
            return Err(io::Error::new(e.kind(), msg));
        }
    }
    // The second names go first (they are only needed until the last rename), then the
    // folders are synced once each.
    drop(backups);
    let mut dirs: Vec<&PathBuf> = targets.iter().map(|(_, d)| d).collect();
    dirs.sort();
    dirs.dedup();
    for d in dirs {
        sync_dir(d);
    }
    Ok(outcomes)
}

/// Files from this many on are staged by several threads.
const STAGED_TOGETHER: usize = 8;

/// The threads that stage files at once. Staging waits on the disk (creating the temporary
/// file, `fsync`) more than it computes, so more threads than cores help: 145 new files of a
/// split 100,000-step program took 70 ms on one thread, 55 on four, 57 on eight (2 cores).
const STAGING_THREADS: usize = 4;

/// Every file of `files` staged ([`stage`]), in order: a split program's 145 files are written
/// and synced on [`STAGING_THREADS`] threads at once. The results of the files before the first that
/// failed, that one's error, and then nothing: once a file fails, no thread takes another (the
/// files are taken in order, so every file before the failed one is staged, and the error is
/// the one staging them one by one would have met first).
fn stage_all(files: &[(&Path, &[u8])]) -> Vec<io::Result<Option<Staged>>> {
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    let threads = if files.len() < STAGED_TOGETHER {
        1
    } else {
        STAGING_THREADS
    };
    let next = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let work = || {
        let mut done = Vec::new();
        while !failed.load(Ordering::Relaxed) {
            let k = next.fetch_add(1, Ordering::Relaxed);
            let Some((path, bytes)) = files.get(k) else {
                break;
            };
            let r = stage(path, bytes);
            if r.is_err() {
                failed.store(true, Ordering::Relaxed);
            }
            done.push((k, r));
        }
        done
    };
    let mut done = std::thread::scope(|s| {
        // A thread that cannot be started leaves its files to the others; this one works too.
        let helpers: Vec<_> = (1..threads)
            .filter_map(|_| {
                std::thread::Builder::new()
                    .name("skillpost-write".into())
                    .spawn_scoped(s, work)
                    .ok()
            })
            .collect();
        let mut done = work();
        for h in helpers {
            match h.join() {
                Ok(d) => done.extend(d),
                Err(panic) => std::panic::resume_unwind(panic),
            }
        }
        done
    });
    done.sort_unstable_by_key(|(k, _)| *k);
    let mut results = Vec::with_capacity(done.len());
    for (_, r) in done {
        let stop = r.is_err();
        results.push(r);
        if stop {
            break;
        }
    }
    results
}

/// Undoes the rename over `target`: its second name goes back (or, when it had none because it
/// did not exist, the new file is removed). The error says where the previous version is kept.
fn put_back(second: Option<tempfile::TempPath>, target: &Path) -> Result<(), String> {
    let Some(second) = second else {
        return fs::remove_file(target).map_err(|e| e.to_string());
    };
    // From here the second name is no longer removed on drop: it may be all that is left.
    let second = second.keep().map_err(|e| e.error.to_string())?;
    fs::rename(&second, target)
        .map_err(|e| format!("{e}; the previous version is kept as {}", second.display()))
}

/// A second name for `target` in `dir`, removed when dropped: a hard link, or a copy where the
/// file system or the kernel (`fs.protected_hardlinks`) refuses the link.
fn second_name(target: &Path, dir: &Path) -> io::Result<tempfile::TempPath> {
    second_name_with(target, dir, &|from, to| fs::hard_link(from, to))
}

/// [`second_name`] with the link operation given (tests make it fail).
fn second_name_with(
    target: &Path,
    dir: &Path,
    link: &dyn Fn(&Path, &Path) -> io::Result<()>,
) -> io::Result<tempfile::TempPath> {
    let builder = temp_builder();
    match builder.make_in(dir, |p| link(target, p)) {
        Ok(f) => Ok(f.into_temp_path()),
        Err(_) => {
            let mut copy = builder.tempfile_in(dir)?;
            let mut from = fs::File::open(target)?;
            io::copy(&mut from, copy.as_file_mut())?;
            set_metadata(copy.as_file(), &from.metadata()?)?;
            copy.as_file().sync_all()?;
            Ok(copy.into_temp_path())
        }
    }
}

/// Gives the temporary file the permissions (and on Unix, best effort, the owner) of the file it
/// replaces (a new file got its mode when it was created: [`new_file_builder`]).
#[cfg(unix)]
fn set_metadata(file: &fs::File, m: &fs::Metadata) -> io::Result<()> {
    use std::os::unix::fs::{MetadataExt as _, PermissionsExt as _};
    let mode = m.permissions().mode() & 0o7777;
    // The mode first, while the file is still ours: once it belongs to another user (a
    // service with CAP_CHOWN keeping a planner's blackboard theirs) we may not chmod it.
    file.set_permissions(fs::Permissions::from_mode(mode))?;
    let own = file.metadata()?;
    if own.uid() != m.uid() || own.gid() != m.gid() {
        // Not allowed to give the file away (no CAP_CHOWN): keep at least the group (a group
        // we are in).
        if std::os::unix::fs::fchown(file, Some(m.uid()), Some(m.gid())).is_err() {
            let _ = std::os::unix::fs::fchown(file, None, Some(m.gid()));
        }
        if mode & 0o6000 != 0 {
            // A chown clears setuid/setgid bits: put them back where we still may.
            let _ = file.set_permissions(fs::Permissions::from_mode(mode));
        }
    }
    Ok(())
}

#[cfg(not(unix))]
fn set_metadata(file: &fs::File, m: &fs::Metadata) -> io::Result<()> {
    file.set_permissions(m.permissions())
}

#[cfg(test)]
mod tests {
    use super::*;

    // ---- files ---------------------------------------------------------------------------------

    use crate::write::temp_leftovers;

    fn old_time() -> std::time::SystemTime {
        std::time::UNIX_EPOCH + std::time::Duration::from_secs(1_000_000_000)
    }

    fn set_old_mtime(p: &Path) {
        fs::File::options()
            .write(true)
            .open(p)
            .unwrap()
            .set_modified(old_time())
            .unwrap();
        assert_eq!(fs::metadata(p).unwrap().modified().unwrap(), old_time());
    }

    #[cfg(unix)]
    fn mode(p: &Path) -> u32 {
        use std::os::unix::fs::PermissionsExt as _;
        fs::metadata(p).unwrap().permissions().mode() & 0o7777
    }

    /// The process's umask, as Linux shows it in `/proc/self/status` (reading it with `umask(2)`
    /// would change it).
    #[cfg(unix)]
    fn umask() -> u32 {
        let status = fs::read_to_string("/proc/self/status").unwrap();
        let line = status.lines().find(|l| l.starts_with("Umask:")).unwrap();
        u32::from_str_radix(line["Umask:".len()..].trim(), 8).unwrap()
    }

    #[cfg(unix)]
    fn set_mode(p: &Path, m: u32) {
        use std::os::unix::fs::PermissionsExt as _;
        fs::set_permissions(p, fs::Permissions::from_mode(m)).unwrap();
    }

    #[test]
    fn new_file_is_written() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("out.src");
        assert_eq!(
            write_if_changed(&p, b"DEF x()\n").unwrap(),
            WriteOutcome::Written
        );
        assert_eq!(fs::read(&p).unwrap(), b"DEF x()\n");
        #[cfg(unix)]
        assert_eq!(mode(&p), 0o666 & !umask());
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[test]
    fn unchanged_file_keeps_its_mtime() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("out.src");
        fs::write(&p, b"same").unwrap();
        set_old_mtime(&p);
        assert_eq!(
            write_if_changed(&p, b"same").unwrap(),
            WriteOutcome::Unchanged
        );
        assert_eq!(fs::metadata(&p).unwrap().modified().unwrap(), old_time());
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[test]
    fn an_output_is_compared_piece_by_piece() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("out.src");
        // Longer than one piece (64 KiB), differing only in the last byte or past it.
        let mut same: Vec<u8> = (0..200_000u32).map(|i| b'a' + (i % 26) as u8).collect();
        fs::write(&p, &same).unwrap();
        assert!(holds_exactly(&p, &same).unwrap());
        *same.last_mut().unwrap() = b'!';
        assert!(!holds_exactly(&p, &same).unwrap());
        same.pop();
        assert!(!holds_exactly(&p, &same).unwrap());
        assert!(!holds_exactly(&p, b"").unwrap());
        fs::write(&p, b"").unwrap();
        assert!(holds_exactly(&p, b"").unwrap());
        assert!(!holds_exactly(&p, b"x").unwrap());
        fs::remove_file(&p).unwrap();
        assert!(!holds_exactly(&p, b"").unwrap());
    }

    /// `holds_exactly` on `path` in a thread: its answer within 10 s, or `None` (it hangs).
    #[cfg(unix)]
    fn compared_in_time(path: &Path, bytes: &'static [u8]) -> Option<io::Result<bool>> {
        let (tx, rx) = std::sync::mpsc::channel();
        let path = path.to_path_buf();
        std::thread::spawn(move || {
            let _ = tx.send(holds_exactly(&path, bytes));
        });
        rx.recv_timeout(std::time::Duration::from_secs(10)).ok()
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_or_link_swapped_in_before_the_comparison_is_refused_not_read() {
        // `stage` checked the path was a regular file; someone then replaced it. A FIFO must not
        // make the comparison wait for a writer, a link to `/dev/zero` must not be followed and
        // read without end.
        let d = tempfile::tempdir().unwrap();
        let fifo = d.path().join("fifo.src");
        let st = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(st.success());
        let e = compared_in_time(&fifo, b"DEF x()\n")
            .expect("the comparison waited on a FIFO")
            .unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert!(e.to_string().contains("not a regular file"), "{e}");
        let link = d.path().join("zero.src");
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        let e = compared_in_time(&link, b"DEF x()\n")
            .expect("the comparison read through a link")
            .unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert!(e.to_string().contains("symbolic link"), "{e}");
    }

    #[test]
    fn changed_file_is_replaced_and_keeps_permissions() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("out.src");
        fs::write(&p, b"aaaa").unwrap();
        #[cfg(unix)]
        set_mode(&p, 0o640);
        set_old_mtime(&p);
        // Same length, other bytes: the length shortcut must not take it for unchanged.
        assert_eq!(
            write_if_changed(&p, b"bbbb").unwrap(),
            WriteOutcome::Written
        );
        assert_eq!(fs::read(&p).unwrap(), b"bbbb");
        assert_ne!(fs::metadata(&p).unwrap().modified().unwrap(), old_time());
        assert_eq!(
            write_if_changed(&p, b"longer").unwrap(),
            WriteOutcome::Written
        );
        assert_eq!(fs::read(&p).unwrap(), b"longer");
        #[cfg(unix)]
        {
            assert_eq!(mode(&p), 0o640);
            // Read-only: refused, even for root; bytes and mode stay. The same bytes again are
            // no write at all, so no error.
            set_mode(&p, 0o444);
            let e = write_if_changed(&p, b"ro").unwrap_err();
            assert_eq!(e.kind(), io::ErrorKind::PermissionDenied);
            assert!(e.to_string().contains("read-only (mode 0444)"), "{e}");
            assert_eq!(fs::read(&p).unwrap(), b"longer");
            assert_eq!(mode(&p), 0o444);
            assert_eq!(
                write_if_changed(&p, b"longer").unwrap(),
                WriteOutcome::Unchanged
            );
        }
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[cfg(unix)]
    #[test]
    fn symlink_output_is_refused_and_its_target_untouched() {
        // An output name that is a link (`Blackboard.src` -> `../outside/precious.txt`) must
        // not make the program replace the link's target.
        let d = tempfile::tempdir().unwrap();
        let outside = d.path().join("outside");
        fs::create_dir(&outside).unwrap();
        let precious = outside.join("precious.txt");
        fs::write(&precious, b"precious").unwrap();
        let proj = d.path().join("proj");
        fs::create_dir(&proj).unwrap();
        let link = proj.join("Blackboard.src");
        std::os::unix::fs::symlink("../outside/precious.txt", &link).unwrap();
        let e = write_if_changed(&link, b"DEF x()").unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert!(e.to_string().contains("symbolic link"), "{e}");
        assert_eq!(fs::read(&precious).unwrap(), b"precious");
        assert!(
            fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        // In a pair: nothing of the pair is written either.
        let dat = proj.join("Blackboard.dat");
        let e = write_all_if_changed(&[(&dat, b"DEFDAT"), (&link, b"DEF x()")]).unwrap_err();
        assert!(e.to_string().contains("symbolic link"), "{e}");
        assert!(!dat.exists());
        assert_eq!(fs::read(&precious).unwrap(), b"precious");
        // A dangling link is refused the same way, and not created through.
        fs::remove_file(&precious).unwrap();
        assert!(write_if_changed(&link, b"x").is_err());
        assert!(!precious.exists());
        assert!(temp_leftovers(&proj).is_empty());
    }

    #[cfg(unix)]
    #[test]
    fn read_only_output_in_a_pair_stops_the_pair() {
        let (t, src, dat) = pair();
        set_mode(&dat, 0o444);
        let e = write_all_if_changed(&[(&src, b"new src"), (&dat, b"new dat")]).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::PermissionDenied);
        assert_eq!(fs::read_to_string(&src).unwrap(), "old src");
        assert_eq!(fs::read_to_string(&dat).unwrap(), "old dat");
        assert_eq!(mode(&dat), 0o444);
        assert!(temp_leftovers(t.path()).is_empty());
    }

    #[test]
    fn missing_directory_is_an_error_and_creates_nothing() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("missing").join("out.src");
        assert!(write_if_changed(&p, b"x").is_err());
        assert!(!d.path().join("missing").exists());
        assert_eq!(fs::read_dir(d.path()).unwrap().count(), 0);
    }

    #[test]
    fn directory_target_is_an_error_and_leaves_no_temp() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("out.src");
        fs::create_dir(&p).unwrap();
        fs::write(p.join("inside"), b"keep").unwrap();
        assert!(write_if_changed(&p, b"x").is_err());
        assert!(p.is_dir());
        assert_eq!(fs::read(p.join("inside")).unwrap(), b"keep");
        assert!(temp_leftovers(d.path()).is_empty());
    }

    // ---- several files as one change ---------------------------------------------------------

    /// A folder with `a.src` and `a.dat` holding "old src" and "old dat".
    fn pair() -> (tempfile::TempDir, PathBuf, PathBuf) {
        let t = tempfile::tempdir().unwrap();
        let (src, dat) = (t.path().join("a.src"), t.path().join("a.dat"));
        fs::write(&src, "old src").unwrap();
        fs::write(&dat, "old dat").unwrap();
        (t, src, dat)
    }

    /// A hook that replaces `victim` by a folder right before its rename, so the rename fails.
    fn sabotage(victim: PathBuf) -> impl FnMut(&Path) {
        move |p: &Path| {
            if p == victim {
                let _ = fs::remove_file(p);
                fs::create_dir(p).unwrap();
                fs::write(p.join("x"), "x").unwrap();
            }
        }
    }

    #[test]
    fn pair_written_together_and_unchanged_left_alone() {
        let (t, src, dat) = pair();
        let out = write_all_if_changed(&[(&src, b"new src"), (&dat, b"old dat")]).unwrap();
        assert_eq!(out, [WriteOutcome::Written, WriteOutcome::Unchanged]);
        assert_eq!(fs::read_to_string(&src).unwrap(), "new src");
        assert_eq!(fs::read_to_string(&dat).unwrap(), "old dat");
        let out = write_all_if_changed(&[(&src, b"new src"), (&dat, b"new dat")]).unwrap();
        assert_eq!(out, [WriteOutcome::Unchanged, WriteOutcome::Written]);
        assert!(temp_leftovers(t.path()).is_empty(), "no second names left");
    }

    #[test]
    fn many_files_staged_together_are_each_written_or_none_is() {
        let t = tempfile::tempdir().unwrap();
        let paths: Vec<PathBuf> = (0..3 * STAGED_TOGETHER)
            .map(|k| t.path().join(format!("p_{k}.src")))
            .collect();
        let texts: Vec<String> = (0..paths.len()).map(|k| format!("part {k}\n")).collect();
        fn files<'a>(paths: &'a [PathBuf], texts: &'a [String]) -> Vec<(&'a Path, &'a [u8])> {
            paths
                .iter()
                .zip(texts)
                .map(|(p, t)| (p.as_path(), t.as_bytes()))
                .collect()
        }
        let out = write_all_if_changed(&files(&paths, &texts)).unwrap();
        assert!(out.iter().all(|o| *o == WriteOutcome::Written));
        for (p, text) in paths.iter().zip(&texts) {
            assert_eq!(&fs::read_to_string(p).unwrap(), text, "{}", p.display());
        }
        // Two files that cannot be written, one early, one late: the error is the first's
        // (as written one by one), and no file changes, no temporary file is left.
        let new: Vec<String> = (0..paths.len()).map(|k| format!("new {k}\n")).collect();
        for k in [5, paths.len() - 2] {
            fs::remove_file(&paths[k]).unwrap();
            fs::create_dir(&paths[k]).unwrap();
        }
        let err = write_all_if_changed(&files(&paths, &new)).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.starts_with(&format!("{}: ", paths[5].display())),
            "{msg}"
        );
        for (k, (p, text)) in paths.iter().zip(&texts).enumerate() {
            if k != 5 && k != paths.len() - 2 {
                assert_eq!(&fs::read_to_string(p).unwrap(), text, "{}", p.display());
            }
        }
        assert!(
            temp_leftovers(t.path()).is_empty(),
            "{:?}",
            temp_leftovers(t.path())
        );
    }

    #[test]
    fn a_failed_second_rename_puts_the_first_file_back() {
        let (t, src, dat) = pair();
        #[cfg(unix)]
        set_mode(&src, 0o640);
        let err = write_all_with_hook(
            &[(&src, b"new src"), (&dat, b"new dat")],
            &mut sabotage(dat.clone()),
        )
        .unwrap_err();
        let msg = err.to_string();
        assert!(msg.starts_with(&format!("{}: ", dat.display())), "{msg}");
        assert!(msg.contains("a.src was put back as it was"), "{msg}");
        assert_eq!(fs::read_to_string(&src).unwrap(), "old src");
        #[cfg(unix)]
        assert_eq!(mode(&src), 0o640, "the same file, mode and all");
        assert!(
            temp_leftovers(t.path()).is_empty(),
            "{:?}",
            temp_leftovers(t.path())
        );
    }

    #[test]
    fn a_failed_second_rename_removes_a_first_file_that_was_new() {
        let t = tempfile::tempdir().unwrap();
        let (src, dat) = (t.path().join("a.src"), t.path().join("a.dat"));
        let err = write_all_with_hook(
            &[(&src, b"new src"), (&dat, b"new dat")],
            &mut sabotage(dat.clone()),
        )
        .unwrap_err();
        assert!(err.to_string().contains("put back"), "{err}");
        assert!(!src.exists(), "the new file is gone again");
        assert!(temp_leftovers(t.path()).is_empty());
    }

    #[test]
    fn a_second_file_that_cannot_be_staged_leaves_the_first_untouched() {
        let (t, src, dat) = pair();
        fs::remove_file(&dat).unwrap();
        fs::create_dir(&dat).unwrap();
        let err = write_all_if_changed(&[(&src, b"new src"), (&dat, b"new dat")]).unwrap_err();
        assert!(err.to_string().contains("not a regular file"), "{err}");
        assert_eq!(fs::read_to_string(&src).unwrap(), "old src");
        assert!(temp_leftovers(t.path()).is_empty());
    }

    #[test]
    fn second_name_is_a_copy_with_the_mode_where_links_fail() {
        let (t, src, _) = pair();
        #[cfg(unix)]
        set_mode(&src, 0o604);
        let refuse = |_: &Path, _: &Path| Err(io::Error::from(io::ErrorKind::PermissionDenied));
        let second = second_name_with(&src, t.path(), &refuse).unwrap();
        assert_eq!(fs::metadata(&second).unwrap().len(), 7);
        fs::write(&src, "changed").unwrap();
        assert_eq!(fs::read_to_string(&second).unwrap(), "old src");
        #[cfg(unix)]
        assert_eq!(mode(&second), 0o604);
        drop(second);
        assert!(temp_leftovers(t.path()).is_empty());
    }
}
