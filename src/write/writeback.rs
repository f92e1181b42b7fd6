//! The blackboard write-back: the new value goes into the planner's file without ever replacing
//! a newer file with an older one, whatever another program does to the file meanwhile.
//!
//! # Why this is hard
//!
//! Planners' editors save the blackboard while the daemon writes the value back. They save in
//! one of three ways: by rename (write a new file, rename it over the name), in place (open with
//! `O_TRUNC` and write into the same inode), or by keeping the file open and writing later. A
//! check "the file still holds what the compile read" followed by a rename leaves a window in
//! which a save is replaced by the older text plus the new value: a lost edit. The old code had
//! that window and lost 9 of 1,431 rename saves and 9 of 1,156 in-place saves made 0–2 ms after
//! the write-back staged its file.
//!
//! # The design
//!
//! 1. Stage the new bytes in `.skillpost-<random>.tmp` in the same folder (mode and owner of
//!    the blackboard), `fsync`: before the blackboard is touched, so the lease below is held
//!    for microseconds, never for an `fsync`.
//! 2. Open the blackboard read-only (the inode the staged file took its mode from, else skip)
//!    and take a Linux **write lease** on it (`F_SETLEASE F_WRLCK`, [`fdlease`]). The kernel
//!    grants it only when no other descriptor has the file open: a program that has it open
//!    (an editor about to write into it) makes the write-back *skip*
//!    ([`WriteBackOutcome::SkippedInUse`]; `compile::apply` tries a few times first). While we
//!    hold it, any other `open` or `truncate` of the file *breaks* it: the opener is blocked in
//!    `open` until we release the lease, and `F_GETLEASE` shows the break, so no write can
//!    reach the file unseen.
//! 3. Read the bytes **through that descriptor** and compare them with what the compile read;
//!    different: skip ([`WriteBackOutcome::SkippedChangedOnDisk`]).
//! 4. Lease broken meanwhile: skip. Otherwise **exchange** the staged file and the blackboard
//!    (`renameat2(RENAME_EXCHANGE)`): the name now holds the new file, the temporary name holds
//!    whatever held the name an instant before, which is still a whole file.
//! 5. **Check what was swapped out**: the inode we leased and read (a rename save meanwhile
//!    would have put another one there); the lease released and taken again at once (taking it
//!    fails if anyone opened the old file, for instance a writer that was blocked in `open`
//!    by the lease); and still the expected bytes, read through our descriptor.
//! 6. All good: remove the old file, close (which drops the lease), `fsync` the folder.
//!    Otherwise **swap back**: exchange again, so the name holds what we took away. If what
//!    comes back is not our new file, a writer replaced it with a newer save meanwhile: that
//!    one is put at the name (exchange once more), and so on, until what comes back is the file
//!    we had put there last, which is then older than the one at the name. The name never keeps
//!    an older file than one a writer saved; a writer that opened the old inode writes into the
//!    file at the name. The write-back is reported skipped, and the daemon compiles again.
//!
//! # Hard links
//!
//! A blackboard with more than one name (`nlink > 1`) is not written: an exchange or rename
//! gives the name a new inode and splits it from the other names, and writing in place is not
//! atomic (a crash would leave a torn blackboard). Reported as
//! [`WriteBackOutcome::SkippedHardLinked`], not retried.
//!
//! # Fallbacks
//!
//! - **No lease** (the process neither owns the file nor has `CAP_LEASE`, or the file system
//!   has no leases: NFS, SMB, FUSE): the same steps without the lease. Rename saves are still
//!   never lost (step 5 compares inodes). A writer that truncates on `open` is caught when its
//!   truncation lands before the re-read of step 5; one that resolved the name before the
//!   exchange and truncates after that re-read writes into the removed file: that window is one
//!   `pread` and one `unlink` long (microseconds). A program that keeps the file open and
//!   writes into it later without truncating is not seen at all. The systemd unit grants
//!   `CAP_LEASE` so the daemon always has leases on local file systems.
//! - **No `RENAME_EXCHANGE`** (`EINVAL`: some FUSE and network file systems): the lease (if
//!   any) and the inode and bytes are checked right before a plain `rename`; a rename save in
//!   the microseconds between that check and the `rename` is lost.
//!
//! # What remains with a lease and the exchange
//!
//! A writer whose `open` looked the name up *before* the exchange but registers as an opener
//! of the old file only *after* step 5's lease is taken again (the kernel counts an opener a
//! few instructions after the path lookup) opens the removed file. That needs the writer to be
//! descheduled inside `open` for the whole of steps 4–6 after the exchange (one `statx`, two
//! `fcntl`, one `pread`: median 4.5 µs, p99 16 µs, max 96 µs over 2,000 write-backs, debug
//! build; the ignored test `window` measures it). The race test never hit it (see
//! docs/RELIABILITY.md).
//!
//! A crash (`kill -9`, power loss) between the exchange and the swap back of a raced save
//! leaves that save under the temporary name, which the daemon removes as stale when it starts:
//! a window of microseconds that needs a crash and a save at once.
//!
//! # `SIGIO`
//!
//! A lease break sends the holder `SIGIO`, whose default action terminates the process. Before
//! the first lease, `lease` installs a handler that only sets a flag (`signal-hook`, once per
//! process), so a break can never kill skillpost; the break is read with `F_GETLEASE`.

use std::fs;
use std::io;
use std::os::unix::fs::{MetadataExt as _, OpenOptionsExt as _};
use std::path::{Path, PathBuf};

use super::atomic::{parent_dir, stage_in, sync_dir};
use super::holds;
use super::splice::{SpliceSite, splice_all};

/// The UTF-8 byte order mark.
const BOM: &[u8] = b"\xEF\xBB\xBF";

/// How many times the swap back follows newer saves before it gives up (keeping every file).
const MAX_SWAPS: usize = 64;

/// What happened to the blackboard in [`write_back`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WriteBackOutcome {
    /// The new value was written.
    Written,
    /// The value was already right (as the reader reads it); nothing was touched.
    AlreadyRight,
    /// The file on disk no longer holds the bytes the compile read (edited, replaced or
    /// deleted meanwhile, or saved during the write-back, which then put the save back);
    /// nothing was written. Compile again.
    SkippedChangedOnDisk,
    /// Another program has the blackboard open (the lease was refused, or broken by an `open`
    /// during the write-back); nothing was written. Try again later.
    SkippedInUse,
    /// The blackboard has more than one name (hard links); replacing it would split them.
    /// Nothing was written; not retried.
    SkippedHardLinked,
    /// The blackboard is read-only (no write permission bit): its owner keeps it from being
    /// changed, so skillpost does not change it either. Nothing was written; not retried.
    SkippedReadOnly,
    /// The new file could not be given the blackboard's owner and group (a service without
    /// `CAP_CHOWN` writing back another user's file): replacing it would hand the planner's
    /// file to the service's user. Nothing was written; not retried.
    SkippedOwner,
}

impl WriteBackOutcome {
    /// Why nothing was written, for reports; `None` for a write.
    pub fn reason(&self) -> Option<&'static str> {
        match self {
            WriteBackOutcome::Written => None,
            WriteBackOutcome::AlreadyRight => Some("already right"),
            WriteBackOutcome::SkippedChangedOnDisk => {
                Some("the blackboard changed on disk since it was read; compiling again")
            }
            WriteBackOutcome::SkippedInUse => Some(
                "another program has the blackboard open; not written (the next compile tries again)",
            ),
            WriteBackOutcome::SkippedHardLinked => Some(
                "the blackboard has several names (hard links); writing it would split them, so the value is not written",
            ),
            WriteBackOutcome::SkippedReadOnly => Some(
                "the blackboard is read-only (no write permission); the value is not written (make it writable to get it)",
            ),
            WriteBackOutcome::SkippedOwner => Some(
                "the blackboard's owner could not be kept (writing it would make it the service user's file; the service needs CAP_CHOWN); the value is not written",
            ),
        }
    }
}

/// Writes the new blackboard if `path` still holds `expected` (the bytes read at the start of
/// the compile), as the module documentation describes; never replaces a newer file with an
/// older one.
///
/// `expected` is the whole file as read, a BOM included; `bom` says whether it starts with a
/// UTF-8 BOM (as [`crate::diag::SourceFile::bom`] records it; a disagreement is an
/// `InvalidInput` error). `site` is where the value goes in the text *after* the BOM, as the
/// reader found it. The new text is [`super::splice_at`] of that text, the BOM is put back; the new
/// file gets the blackboard's mode and (best effort) owner. A blackboard that is a symbolic
/// link: the file it points to is written, the link stays.
///
/// - When the value is already right in `expected`, nothing is read or written:
///   [`WriteBackOutcome::AlreadyRight`].
/// - Errors: the file cannot be read or written (`io::Error` of the operation), `expected` after
///   the BOM is not UTF-8 (`InvalidData`), `site` does not fit the text or `value` holds a
///   character XML cannot carry (`InvalidInput`).
pub fn write_back(
    path: &Path,
    expected: &[u8],
    bom: bool,
    site: &SpliceSite,
    value: &str,
) -> io::Result<WriteBackOutcome> {
    write_back_all(path, expected, bom, &[(site, value)])
}

/// [`write_back`] of several values at once, in one new file ([`splice_all`]): a cell's
/// programs (docs/CELLS.md).
pub fn write_back_all(
    path: &Path,
    expected: &[u8],
    bom: bool,
    splices: &[(&SpliceSite, &str)],
) -> io::Result<WriteBackOutcome> {
    write_back_with(path, expected, bom, splices, &Opts::default(), &mut |_| {})
}

/// Test switches.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Opts {
    /// Take a lease (tests turn it off to exercise the fallback).
    pub lease: bool,
    /// Exchange (tests turn it off to exercise the plain-rename fallback).
    pub exchange: bool,
}

impl Default for Opts {
    fn default() -> Self {
        Opts {
            lease: true,
            exchange: true,
        }
    }
}

/// Where [`write_back_with`] calls its hook (tests change the file there).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Point<'a> {
    /// The new file is staged and synced; the blackboard, found a regular file, is opened next.
    Staged,
    /// The new file is staged and synced, the blackboard open, leased (if possible) and read.
    Read,
    /// Right before the last lease check and the exchange.
    BeforeExchange,
    /// Right after the exchange; the argument is the temporary name, now the old file.
    AfterExchange(&'a Path),
    /// Before each exchange of the swap back.
    SwapBack(&'a Path),
    /// The checks of what the exchange took out are done (the end of the window the module
    /// documentation describes).
    Checked,
    /// The file the exchange took is leased by us and nobody else has it open; its bytes go
    /// into ours next.
    Adopt,
}

/// [`write_back`] with switches and a hook.
pub(crate) fn write_back_with(
    path: &Path,
    expected: &[u8],
    bom: bool,
    splices: &[(&SpliceSite, &str)],
    opts: &Opts,
    hook: &mut dyn FnMut(Point),
) -> io::Result<WriteBackOutcome> {
    let has_bom = expected.starts_with(BOM);
    if has_bom != bom {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "write-back: the bytes read {} a BOM, but `bom` is {bom}",
                if has_bom {
                    "start with"
                } else {
                    "do not start with"
                }
            ),
        ));
    }
    let body = if bom {
        &expected[BOM.len()..]
    } else {
        expected
    };
    let text = std::str::from_utf8(body).map_err(|e| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("write-back: the blackboard is not UTF-8: {e}"),
        )
    })?;
    let new_text = match splice_all(text, splices) {
        Ok(Some(t)) => t,
        Ok(None) => return Ok(WriteBackOutcome::AlreadyRight),
        Err(e) => return Err(io::Error::new(io::ErrorKind::InvalidInput, e)),
    };
    let mut new_bytes = Vec::with_capacity(new_text.len() + BOM.len());
    if bom {
        new_bytes.extend_from_slice(BOM);
    }
    new_bytes.extend_from_slice(new_text.as_bytes());

    let target = resolve_link(path)?;
    let dir = parent_dir(&target);
    let before = match fs::symlink_metadata(&target) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => {
            return Ok(WriteBackOutcome::SkippedChangedOnDisk);
        }
        Err(e) => return Err(e),
    };
    if before.file_type().is_symlink() {
        // A link swapped in since it was resolved.
        return Ok(WriteBackOutcome::SkippedChangedOnDisk);
    }
    if !before.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{} is not a regular file", target.display()),
        ));
    }
    if before.nlink() > 1 {
        return Ok(WriteBackOutcome::SkippedHardLinked);
    }
    if before.mode() & 0o222 == 0 {
        // Read-only: outputs that are read-only are refused (E604); the blackboard, the
        // planner's file, is left alone and reported.
        return Ok(WriteBackOutcome::SkippedReadOnly);
    }
    // Staged (written and synced) before the lease, so the lease is held for microseconds, not
    // for an `fsync`: an editor opening the file meanwhile waits that long at most.
    let tmp = stage_in(&dir, &new_bytes, Some(&before))?;
    let staged = tmp.as_file().metadata()?;
    if (staged.uid(), staged.gid()) != (before.uid(), before.gid()) {
        // Not allowed to give the new file the blackboard's owner (no CAP_CHOWN): the
        // planner's file would become ours. Dropping `tmp` removes it.
        return Ok(WriteBackOutcome::SkippedOwner);
    }
    let new_id = id(&staged);
    let old_id = id(&before);
    // A lease on the new file too: from the exchange on it stands at the name, and whoever
    // opens the name then (a planner's save through a descriptor) must not get a file that is
    // then taken away unseen. The opener waits in `open` until this lease goes; by then the
    // name holds what it must (see `adopt`).
    let (new_file, tmp) = tmp.into_parts();
    let new_file = lease::Unleased(new_file);
    let new_leased = opts.lease && matches!(lease::take(&new_file), Ok(true));
    hook(Point::Staged);
    // Never through a link swapped in meanwhile: `target` is the resolved file. Without
    // blocking: a FIFO swapped in meanwhile opens at once (and is not the file `before` saw),
    // instead of holding the compile until something writes to it.
    let flags = rustix::fs::OFlags::NOFOLLOW | rustix::fs::OFlags::NONBLOCK;
    let file = match fs::File::options()
        .read(true)
        .custom_flags(flags.bits() as i32)
        .open(&target)
    {
        Ok(f) => lease::Unleased(f),
        Err(e) if e.kind() == io::ErrorKind::NotFound => {
            return Ok(WriteBackOutcome::SkippedChangedOnDisk);
        }
        Err(e) if e.raw_os_error() == Some(rustix::io::Errno::LOOP.raw_os_error()) => {
            return Ok(WriteBackOutcome::SkippedChangedOnDisk);
        }
        Err(e) => return Err(e),
    };
    let meta = file.metadata()?;
    if id(&meta) != old_id {
        // Replaced since the staged file took its mode and owner: a save.
        return Ok(WriteBackOutcome::SkippedChangedOnDisk);
    }
    let leased = if opts.lease {
        match lease::take(&file) {
            Ok(held) => held,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                return Ok(WriteBackOutcome::SkippedInUse);
            }
            Err(e) => return Err(e),
        }
    } else {
        false
    };
    if !holds(&file, expected)? {
        return Ok(WriteBackOutcome::SkippedChangedOnDisk);
    }
    if meta.nlink() > 1 {
        return Ok(WriteBackOutcome::SkippedHardLinked);
    }
    hook(Point::Read);
    hook(Point::BeforeExchange);
    if leased && !lease::intact(&file) {
        return Ok(WriteBackOutcome::SkippedInUse);
    }
    let exchanged = if opts.exchange {
        exchange(&tmp, &target)
    } else {
        Err(rustix::io::Errno::INVAL.into())
    };
    match exchanged {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::NotFound => {
            // Renamed away or deleted meanwhile: not created again.
            return Ok(WriteBackOutcome::SkippedChangedOnDisk);
        }
        Err(e) if e.raw_os_error() == Some(rustix::io::Errno::INVAL.raw_os_error()) => {
            // No RENAME_EXCHANGE here: check, then a plain rename (see the module docs).
            if leased && !lease::intact(&file) {
                return Ok(WriteBackOutcome::SkippedInUse);
            }
            let same = fs::symlink_metadata(&target).is_ok_and(|m| id(&m) == old_id);
            if !same || !holds(&file, expected)? {
                return Ok(WriteBackOutcome::SkippedChangedOnDisk);
            }
            tmp.persist(&target).map_err(|e| e.error)?;
            sync_dir(&dir);
            return Ok(WriteBackOutcome::Written);
        }
        Err(e) => return Err(e),
    }
    hook(Point::AfterExchange(&tmp));
    let out_id = fs::symlink_metadata(&tmp).ok().map(|m| id(&m));
    let mut ok = out_id == Some(old_id);
    if ok && leased {
        // Anyone blocked in `open` by the lease gets the old file now: taking the lease again
        // fails while they have it open.
        ok = lease::retake(&file);
    }
    ok = ok && holds(&file, expected)?;
    hook(Point::Checked);
    if ok {
        // `tmp` names the old file: dropping it removes it. Then the leases go (closing the
        // files), then the folder is synced.
        drop(tmp);
        drop(file);
        drop(new_file);
        sync_dir(&dir);
        return Ok(WriteBackOutcome::Written);
    }
    // The name must get back what the exchange took (a save). Anyone who opened the name since
    // the exchange holds our new file and waits for its lease: the taken file's bytes go into
    // the new file, which stays at the name, once nobody else has the taken file open.
    if new_leased && let Some(taken) = out_id {
        let held = (leased && taken == old_id).then_some(&*file);
        let adopted = adopt(&new_file, &tmp, taken, held, expected, hook)?;
        if adopted != Adopted::No {
            drop(tmp);
            drop(file);
            drop(new_file);
            sync_dir(&dir);
            return Ok(if adopted == Adopted::Ours {
                WriteBackOutcome::Written
            } else {
                WriteBackOutcome::SkippedChangedOnDisk
            });
        }
    }
    swap_back(&tmp, &target, new_id, out_id, hook)?;
    let ours_at_tmp = fs::symlink_metadata(&tmp).is_ok_and(|m| id(&m) == new_id);
    if new_leased && ours_at_tmp && !lease::intact(&new_file) {
        // Someone opened the name while our file stood there, and the taken file stayed open
        // in another program for all of `ADOPT_WAIT`: both files have a writer and only one can
        // have the name. Ours, with whatever its opener writes, is kept beside it.
        let kept = keep_beside(&tmp, &target)?;
        drop(file);
        drop(new_file);
        sync_dir(&dir);
        return Err(io::Error::other(format!(
            "a program opened the blackboard while the write-back put a save back; what it writes goes to {} (compare it with the blackboard)",
            kept.display()
        )));
    }
    drop(tmp);
    // Only now: a writer held in `open` by the lease gets the file that is at the name again.
    drop(file);
    drop(new_file);
    sync_dir(&dir);
    Ok(WriteBackOutcome::SkippedChangedOnDisk)
}

/// How long [`adopt`] waits for other programs to close the file the exchange took from the
/// name (an editor finishing its save) while openers of the name wait for our lease.
const ADOPT_WAIT: std::time::Duration = std::time::Duration::from_secs(1);

/// After an exchange that took a file other than the one the compile read (`taken`, now at
/// `tmp`: a save), or took that one while someone had it open: puts that file's bytes, mode
/// and owner into `new_file`, which stands at the name under our lease, and returns `true`; the
/// caller then removes `tmp`. A program that opened the name since the exchange (it waits in
/// `open` for our lease) gets the save's bytes at the name, and what it writes stays there.
///
/// First waits (at most [`ADOPT_WAIT`]) until nobody else has the taken file open, shown by a
/// write lease on it: a writer that opened it (under the name, before the exchange) finishes,
/// and what it wrote is taken along. `held` is our descriptor of the taken file when it is the
/// file the compile read (its lease is released for the wait, so a writer blocked by it goes
/// on). `false` (nothing taken over) when it stays open, no lease can be had on it, or its
/// owner cannot be given to the new file: the caller swaps back instead.
/// What [`adopt`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Adopted {
    /// Nothing: the caller swaps back.
    No,
    /// The taken file's bytes are now in ours, at the name.
    Theirs,
    /// The taken file was the one the compile read and is unchanged after its opener (a
    /// reader) let go: our new file stays at the name as it is, and the write-back is done.
    Ours,
}

fn adopt(
    new_file: &fs::File,
    tmp: &Path,
    taken: Id,
    held: Option<&fs::File>,
    expected: &[u8],
    hook: &mut dyn FnMut(Point),
) -> io::Result<Adopted> {
    use std::os::unix::fs::FileExt as _;
    let opened;
    let old = match held {
        Some(f) => {
            // Let a writer blocked by our lease go on: it must be done before we read.
            let _ = fdlease::set(f, fdlease::Lease::None);
            f
        }
        None => {
            let flags = rustix::fs::OFlags::NOFOLLOW | rustix::fs::OFlags::NONBLOCK;
            opened = match fs::File::options()
                .read(true)
                .custom_flags(flags.bits() as i32)
                .open(tmp)
            {
                Ok(f) => lease::Unleased(f),
                Err(_) => return Ok(Adopted::No),
            };
            &opened.0
        }
    };
    let meta = old.metadata()?;
    if id(&meta) != taken || !meta.is_file() || meta.nlink() != 1 {
        return Ok(Adopted::No);
    }
    let until = std::time::Instant::now() + ADOPT_WAIT;
    loop {
        match lease::take(old) {
            Ok(true) => break,
            Ok(false) => return Ok(Adopted::No),
            Err(_) if std::time::Instant::now() < until => {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            Err(_) => return Ok(Adopted::No),
        }
    }
    hook(Point::Adopt);
    // Nobody else has it open now, and a new opener would break the lease. The file the compile
    // read, still as it was (its opener only read it): the write-back stands.
    if held.is_some() && holds(old, expected)? && lease::intact(old) {
        return Ok(Adopted::Ours);
    }
    let meta = old.metadata()?;
    let ours = new_file.metadata()?;
    if (ours.uid(), ours.gid()) != (meta.uid(), meta.gid())
        && std::os::unix::fs::fchown(new_file, Some(meta.uid()), Some(meta.gid())).is_err()
    {
        return Ok(Adopted::No);
    }
    new_file.set_permissions(meta.permissions())?;
    let mut piece = vec![0u8; 64 << 10];
    let mut at = 0u64;
    loop {
        let n = match old.read_at(&mut piece, at) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        new_file.write_all_at(&piece[..n], at)?;
        at += n as u64;
    }
    new_file.set_len(at)?;
    new_file.sync_all()?;
    // Opened by someone meanwhile (a descriptor that looked the name up before the exchange):
    // that file must go back to the name after all; what we wrote into ours is only a copy.
    Ok(if lease::intact(old) {
        Adopted::Theirs
    } else {
        Adopted::No
    })
}

/// Renames the file at `tmp` (ours, after a swap back, with an opener) to a free name beside
/// `target` that the daemon never removes: `<name>.skillpost-kept-<n>`.
fn keep_beside(tmp: &tempfile::TempPath, target: &Path) -> io::Result<PathBuf> {
    let name = target.file_name().unwrap_or_default().to_string_lossy();
    for n in 1..1000 {
        let kept = target.with_file_name(format!("{name}.skillpost-kept-{n}"));
        match rustix::fs::renameat_with(
            rustix::fs::CWD,
            tmp.as_os_str(),
            rustix::fs::CWD,
            kept.as_os_str(),
            rustix::fs::RenameFlags::NOREPLACE,
        ) {
            Ok(()) => return Ok(kept),
            Err(rustix::io::Errno::EXIST) => continue,
            Err(e) => return Err(e.into()),
        }
    }
    Err(io::Error::other(
        "no free name to keep a file beside the blackboard",
    ))
}

/// Puts the file at `tmp` (what the exchange took from the name, `taken`) back at `target`,
/// following newer saves: see the module documentation. On return `tmp` names a file older
/// than the one at `target` (or nothing), to be removed. On an error the file at `tmp` is kept
/// (its name is in the error).
fn swap_back(
    tmp: &tempfile::TempPath,
    target: &Path,
    ours: Id,
    taken: Option<Id>,
    hook: &mut dyn FnMut(Point),
) -> io::Result<()> {
    let keep = |e: io::Error| {
        io::Error::new(
            e.kind(),
            format!(
                "{}: putting back a file saved during the write-back failed ({e}); it is kept as {}",
                target.display(),
                tmp.display()
            ),
        )
    };
    // What we expect to come back: the file we put at the name last.
    let mut expect = ours;
    let mut put = taken;
    for _ in 0..MAX_SWAPS {
        if put.is_none() {
            // The exchange took nothing we can name (gone meanwhile): nothing to put back.
            return Ok(());
        }
        hook(Point::SwapBack(tmp));
        match exchange(tmp, target) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                // The name is gone (the file was deleted or renamed away after our exchange):
                // the file we took goes back, unless something appears at the name meanwhile.
                match rustix::fs::renameat_with(
                    rustix::fs::CWD,
                    tmp.as_os_str(),
                    rustix::fs::CWD,
                    target.as_os_str(),
                    rustix::fs::RenameFlags::NOREPLACE,
                ) {
                    Ok(()) => return Ok(()),
                    Err(rustix::io::Errno::EXIST) => continue,
                    Err(e) => return Err(keep(e.into())),
                }
            }
            Err(e) => return Err(keep(e)),
        }
        let back = fs::symlink_metadata(tmp).ok().map(|m| id(&m));
        if back == Some(expect) || back.is_none() {
            return Ok(());
        }
        // A writer replaced the file we had put at the name with a newer save, which is now at
        // `tmp`: it goes to the name next.
        expect = put.expect("checked above");
        put = back;
    }
    Err(keep(io::Error::other(format!(
        "the file changed {MAX_SWAPS} times while it was put back"
    ))))
}

/// An inode: device and number.
type Id = (u64, u64);

fn id(m: &fs::Metadata) -> Id {
    (m.dev(), m.ino())
}

/// `renameat2(from, to, RENAME_EXCHANGE)`.
fn exchange(from: &Path, to: &Path) -> io::Result<()> {
    rustix::fs::renameat_with(
        rustix::fs::CWD,
        from,
        rustix::fs::CWD,
        to,
        rustix::fs::RenameFlags::EXCHANGE,
    )
    .map_err(io::Error::from)
}

/// The file a symbolic link finally points to; any other path as it is.
fn resolve_link(path: &Path) -> io::Result<PathBuf> {
    match fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => fs::canonicalize(path),
        _ => Ok(path.to_path_buf()),
    }
}

/// Leases on the blackboard's descriptor, with `SIGIO` made harmless first.
pub(crate) mod lease {
    use std::fs::File;
    use std::io;
    use std::sync::atomic::AtomicBool;
    use std::sync::{Arc, OnceLock};

    use fdlease::Lease;

    /// An open file whose lease, if we took one, goes when it is closed. A lease belongs to the
    /// open file, not to one descriptor of it: a hook being started holds a copy of every
    /// descriptor of the daemon until its `exec` (`posix_spawn`, `fork`), and a lease left to
    /// go with our descriptor outlived it there. Our own next `open` of the blackboard (the
    /// check for a save racing the write-back, the next hash check) then failed with
    /// `EWOULDBLOCK`, was taken for a change, and the project compiled a second time.
    pub struct Unleased(pub File);

    impl std::ops::Deref for Unleased {
        type Target = File;
        fn deref(&self) -> &File {
            &self.0
        }
    }

    impl Drop for Unleased {
        fn drop(&mut self) {
            // Whichever copies of the open file live on, the lease goes now (an error: none).
            let _ = fdlease::set(&self.0, Lease::None);
        }
    }

    /// Installs, once per process, a `SIGIO` handler that only sets a flag: a lease break sends
    /// `SIGIO`, whose default action would terminate the process. `Err` when it cannot be
    /// installed (then no lease is taken).
    pub fn guard_sigio() -> Result<(), String> {
        static GUARD: OnceLock<Result<(), String>> = OnceLock::new();
        GUARD
            .get_or_init(|| {
                let flag = Arc::new(AtomicBool::new(false));
                signal_hook::flag::register(signal_hook::consts::SIGIO, flag)
                    .map(|_| ())
                    .map_err(|e| e.to_string())
            })
            .clone()
    }

    /// Takes a write lease: `Ok(true)` held; `Ok(false)` leases are not available here (no
    /// ownership or `CAP_LEASE`, a file system without leases, no `SIGIO` guard); `Err` with
    /// `WouldBlock` when another descriptor has the file open.
    pub fn take(file: &File) -> io::Result<bool> {
        if let Err(why) = guard_sigio() {
            tracing::warn!("no SIGIO handler ({why}); writing back without a lease");
            return Ok(false);
        }
        match fdlease::set(file, Lease::Write) {
            Ok(()) => Ok(true),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => Err(e),
            Err(e) => {
                tracing::debug!("no lease on the blackboard ({e}); writing back without one");
                Ok(false)
            }
        }
    }

    /// Whether another program has the file at `path` open for writing right now (a save in
    /// progress): a read lease is refused exactly then. `None` where leases cannot tell (not
    /// the owner and no `CAP_LEASE`, no lease support, not a regular file). The lease, when
    /// granted, is released at once.
    pub fn open_for_writing(path: &std::path::Path) -> Option<bool> {
        use std::os::unix::fs::OpenOptionsExt as _;
        guard_sigio().ok()?;
        let flags = rustix::fs::OFlags::NONBLOCK | rustix::fs::OFlags::NOFOLLOW;
        let f = File::options()
            .read(true)
            .custom_flags(flags.bits() as i32)
            .open(path)
            .ok()?;
        if !f.metadata().ok()?.is_file() {
            return None;
        }
        match fdlease::set(&f, Lease::Read) {
            Ok(()) => {
                let _ = fdlease::set(&f, Lease::None);
                Some(false)
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => Some(true),
            Err(_) => None,
        }
    }

    /// Whether the write lease is still held unbroken.
    pub fn intact(file: &File) -> bool {
        matches!(fdlease::get(file), Ok(Lease::Write))
    }

    /// Releases the lease and takes it again at once: `false` when anyone has the file open
    /// now (such as a writer that was blocked in `open` by the lease) or it was broken.
    pub fn retake(file: &File) -> bool {
        intact(file)
            && fdlease::set(file, Lease::None).is_ok()
            && fdlease::set(file, Lease::Write).is_ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write as _;
    use std::time::Duration;

    /// The end of the original sample blackboard (lines 1-2 and 95-106).
    const SAMPLE: &str = r#"<?xml version="1.0" encoding="utf-8"?>
<CAEXFile FileName="Blackboard.aml" SchemaVersion="2.15">
  <InstanceHierarchy Name="Blackboard">
    <InternalElement Name="Code" ID="{00000000-0000-0000-0000-000000000018}">
      <ExternalInterface Name="KRL code" ID="{00000000-0000-0000-0000-000000000019}">
        <Attribute Name="refURI" AttributeDataType="xs:anyURI"><Value>none</Value></Attribute>
      </ExternalInterface>
    </InternalElement>
  </InstanceHierarchy>
</CAEXFile>
"#;

    /// The site of the refURI attribute, as the reader finds it.
    fn site(text: &str) -> SpliceSite {
        let d = roxmltree::Document::parse(text).unwrap();
        let a = d
            .descendants()
            .find(|n| n.tag_name().name() == "Attribute")
            .unwrap();
        SpliceSite::of(a).unwrap()
    }

    fn written(text: &str) -> String {
        text.replace(">none<", ">x.src<")
    }

    /// A folder with `Blackboard.aml` holding `SAMPLE`.
    fn project() -> (tempfile::TempDir, PathBuf) {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("Blackboard.aml");
        fs::write(&p, SAMPLE).unwrap();
        (d, p)
    }

    fn run(p: &Path, opts: Opts, hook: &mut dyn FnMut(Point)) -> WriteBackOutcome {
        write_back_with(
            p,
            SAMPLE.as_bytes(),
            false,
            &[(&site(SAMPLE), "x.src")],
            &opts,
            hook,
        )
        .unwrap()
    }

    use crate::write::temp_leftovers;

    /// A rename save: a new file renamed over the name.
    fn rename_save(p: &Path, text: &str) {
        let tmp = p.with_file_name(format!("save-{}.tmp", std::process::id()));
        fs::write(&tmp, text).unwrap();
        fs::rename(&tmp, p).unwrap();
    }

    /// Waits until `/proc/locks` lists a lease on inode `ino` that is being broken (a process
    /// blocked in `open` by it).
    fn lease_breaking(ino: u64, timeout: Duration) -> bool {
        let end = std::time::Instant::now() + timeout;
        let suffix = format!(":{ino}");
        while std::time::Instant::now() < end {
            let locks = fs::read_to_string("/proc/locks").unwrap_or_default();
            if locks.lines().any(|l| {
                l.contains("LEASE")
                    && l.contains("BREAK")
                    && l.split_whitespace().any(|w| w.ends_with(&suffix))
            }) {
                return true;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        false
    }

    /// Whether this process can take leases on files in `dir`; prints why a test is skipped
    /// when not, and fails under `SKILLPOST_STRICT_TESTS=1`.
    fn leases_work(dir: &Path) -> bool {
        let p = dir.join("lease-probe");
        fs::write(&p, "x").unwrap();
        let f = fs::File::open(&p).unwrap();
        let ok = lease::take(&f).unwrap_or(false);
        drop(f);
        fs::remove_file(&p).unwrap();
        if !ok {
            let why = "no file leases here (not the owner and no CAP_LEASE, or no lease support)";
            if std::env::var("SKILLPOST_STRICT_TESTS").as_deref() == Ok("1") {
                panic!("{why} (SKILLPOST_STRICT_TESTS=1)");
            }
            eprintln!("skipped: {why}");
        }
        ok
    }

    #[test]
    fn writes_only_the_value_and_keeps_bom_mode_and_link() {
        let (d, p) = project();
        let mut bytes = BOM.to_vec();
        bytes.extend_from_slice(SAMPLE.replace('\n', "\r\n").as_bytes());
        fs::write(&p, &bytes).unwrap();
        fs::set_permissions(&p, std::os::unix::fs::PermissionsExt::from_mode(0o640)).unwrap();
        let link = d.path().join("Link.aml");
        std::os::unix::fs::symlink("Blackboard.aml", &link).unwrap();
        let text = std::str::from_utf8(&bytes[3..]).unwrap();
        let out = write_back(&link, &bytes, true, &site(text), "x.src").unwrap();
        assert_eq!(out, WriteBackOutcome::Written);
        let mut want = BOM.to_vec();
        want.extend_from_slice(written(text).as_bytes());
        assert_eq!(fs::read(&p).unwrap(), want);
        assert!(
            fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(fs::metadata(&p).unwrap().mode() & 0o7777, 0o640);
        assert!(temp_leftovers(d.path()).is_empty());
        // Again: already right, nothing touched.
        let text2 = std::str::from_utf8(&want[3..]).unwrap();
        let before = fs::metadata(&p).unwrap().modified().unwrap();
        assert_eq!(
            write_back(&p, &want, true, &site(text2), "x.src").unwrap(),
            WriteBackOutcome::AlreadyRight
        );
        assert_eq!(fs::metadata(&p).unwrap().modified().unwrap(), before);
    }

    #[test]
    fn changed_or_deleted_after_reading_is_skipped() {
        let (d, p) = project();
        let edited = SAMPLE.replace("Blackboard\"", "Blackboard2\"");
        fs::write(&p, &edited).unwrap();
        assert_eq!(
            run(&p, Opts::default(), &mut |_| {}),
            WriteBackOutcome::SkippedChangedOnDisk
        );
        assert_eq!(fs::read_to_string(&p).unwrap(), edited);
        fs::remove_file(&p).unwrap();
        assert_eq!(
            run(&p, Opts::default(), &mut |_| {}),
            WriteBackOutcome::SkippedChangedOnDisk
        );
        assert!(!p.exists());
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[test]
    fn a_fifo_swapped_in_before_the_open_is_skipped_at_once() {
        // The blackboard was a regular file when checked; a FIFO replaces it before it is
        // opened. Opening it must not wait for a writer (the compile would hang for ever).
        let (d, p) = project();
        let (tx, rx) = std::sync::mpsc::channel();
        let path = p.clone();
        std::thread::spawn(move || {
            let out = run(&path, Opts::default(), &mut |pt| {
                if matches!(pt, Point::Staged) {
                    fs::remove_file(&path).unwrap();
                    let st = std::process::Command::new("mkfifo")
                        .arg(&path)
                        .status()
                        .unwrap();
                    assert!(st.success());
                }
            });
            let _ = tx.send(out);
        });
        let out = rx
            .recv_timeout(Duration::from_secs(10))
            .expect("the write-back waited on a FIFO");
        assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk);
        use std::os::unix::fs::FileTypeExt as _;
        assert!(fs::symlink_metadata(&p).unwrap().file_type().is_fifo());
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[test]
    fn caller_bugs_are_errors() {
        let (_d, p) = project();
        let e = write_back(&p, SAMPLE.as_bytes(), true, &site(SAMPLE), "x").unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        let bad = SpliceSite {
            replace: 0..SAMPLE.len() + 1,
            ..SpliceSite::default()
        };
        let e = write_back(&p, SAMPLE.as_bytes(), false, &bad, "x").unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert_eq!(fs::read_to_string(&p).unwrap(), SAMPLE);
    }

    /// Every combination of lease and exchange that the machine offers.
    fn modes(dir: &Path) -> Vec<Opts> {
        let mut v = vec![Opts {
            lease: false,
            exchange: true,
        }];
        if leases_work(dir) {
            v.push(Opts::default());
        }
        v
    }

    #[test]
    fn rename_save_before_the_exchange_survives() {
        let (d, p) = project();
        for opts in modes(d.path()).into_iter().chain([Opts {
            lease: true,
            exchange: false,
        }]) {
            fs::write(&p, SAMPLE).unwrap();
            let save = SAMPLE.replace("<InstanceHierarchy", "<!-- save 1 --><InstanceHierarchy");
            let out = run(&p, opts, &mut |pt| {
                if pt == Point::BeforeExchange {
                    rename_save(&p, &save);
                }
            });
            assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk, "{opts:?}");
            assert_eq!(fs::read_to_string(&p).unwrap(), save, "{opts:?}");
            assert!(temp_leftovers(d.path()).is_empty());
        }
    }

    #[test]
    fn rename_save_right_after_the_exchange_stays() {
        let (d, p) = project();
        for opts in modes(d.path()) {
            fs::write(&p, SAMPLE).unwrap();
            let save = SAMPLE.replace("<InstanceHierarchy", "<!-- save 2 --><InstanceHierarchy");
            let out = run(&p, opts, &mut |pt| {
                if let Point::AfterExchange(_) = pt {
                    rename_save(&p, &save);
                }
            });
            // Our write happened, and the newer save replaced it, as saves do.
            assert_eq!(out, WriteBackOutcome::Written, "{opts:?}");
            assert_eq!(fs::read_to_string(&p).unwrap(), save, "{opts:?}");
            assert!(temp_leftovers(d.path()).is_empty());
        }
    }

    #[test]
    fn saves_during_the_swap_back_end_with_the_newest() {
        // With a lease on our file the save the exchange took is taken over in place (below)
        // unless another program holds it open: `held` keeps it open (a reader) for the whole
        // wait, so the swap back runs.
        let (d, p) = project();
        for opts in modes(d.path()) {
            fs::write(&p, SAMPLE).unwrap();
            let mut n = 0;
            let mut held = None;
            let out = run(&p, opts, &mut |pt| match pt {
                Point::BeforeExchange => {
                    rename_save(&p, "save A");
                    held = Some(fs::File::open(&p).unwrap());
                }
                Point::SwapBack(_) if n < 3 => {
                    n += 1;
                    rename_save(&p, &format!("save B{n}"));
                }
                _ => {}
            });
            assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk);
            assert_eq!(fs::read_to_string(&p).unwrap(), "save B3", "{opts:?}");
            assert!(temp_leftovers(d.path()).is_empty());
            drop(held);
        }
    }

    #[test]
    fn a_save_while_the_taken_save_is_copied_stays() {
        let (d, p) = project();
        if !leases_work(d.path()) {
            return;
        }
        let out = run(&p, Opts::default(), &mut |pt| match pt {
            Point::BeforeExchange => rename_save(&p, "save A"),
            Point::Adopt => rename_save(&p, "save B"),
            _ => {}
        });
        assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk);
        assert_eq!(fs::read_to_string(&p).unwrap(), "save B");
        assert!(temp_leftovers(d.path()).is_empty());
    }

    /// Our lease goes with our descriptor, also while a copy of the open file lives on: a hook
    /// being started holds one of every descriptor until its `exec`. Then our own next open of
    /// the blackboard (without blocking, as the hash check opens it) was refused as long as the
    /// copy lived, and taken for a change: a second, forced compile (seen in CI: 601 of 600).
    #[test]
    fn our_lease_goes_with_our_descriptor_while_a_copy_lives_on() {
        let (d, p) = project();
        if !leases_work(d.path()) {
            return;
        }
        let f = lease::Unleased(fs::File::open(&p).unwrap());
        assert!(matches!(lease::take(&f), Ok(true)));
        // What a hook being started holds: the same open file.
        let copy = f.try_clone().unwrap();
        drop(f);
        // The daemon's hash check (after a write-back, and before a compile).
        let hashed = crate::load::hash_file(&p, 1 << 20);
        assert!(hashed.is_ok(), "refused: {:?}", hashed.err());
        drop(copy);
    }

    /// A writer in another thread: opens `p` for writing (without truncating) when started,
    /// says so, and writes `text` over the whole file through that descriptor when told.
    fn descriptor_writer(
        p: &Path,
        text: &'static str,
    ) -> (
        std::sync::mpsc::Receiver<()>,
        std::sync::mpsc::Sender<()>,
        std::thread::JoinHandle<()>,
    ) {
        let (opened_tx, opened) = std::sync::mpsc::channel();
        let (go, go_rx) = std::sync::mpsc::channel::<()>();
        let p = p.to_owned();
        let t = std::thread::spawn(move || {
            let mut f = fs::File::options().read(true).write(true).open(&p).unwrap();
            opened_tx.send(()).unwrap();
            go_rx.recv().unwrap();
            f.set_len(0).unwrap();
            f.write_all(text.as_bytes()).unwrap();
        });
        (opened, go, t)
    }

    #[test]
    fn a_save_through_a_descriptor_opened_after_the_exchange_ends_at_the_name() {
        // Issue 24, finding 1: the planner saves by rename (before our exchange, so the
        // exchange takes the save), opens the name at once and writes through that descriptor a
        // moment later. Its `open` lands while our new file stands at the name; the write must
        // end up at the name, not in a file the write-back then removes.
        let (d, p) = project();
        if !leases_work(d.path()) {
            return;
        }
        let mut writer = None;
        let out = run(&p, Opts::default(), &mut |pt| match pt {
            Point::BeforeExchange => rename_save(&p, "save 1"),
            Point::AfterExchange(_) => {
                let ino = fs::metadata(&p).unwrap().ino();
                let w = descriptor_writer(&p, "save 2 through the descriptor");
                // Its open is blocked by the lease on our file (now at the name).
                assert!(lease_breaking(ino, Duration::from_secs(10)));
                writer = Some(w);
            }
            _ => {}
        });
        assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk);
        let (opened, go, t) = writer.unwrap();
        opened.recv_timeout(Duration::from_secs(10)).unwrap();
        // Meanwhile the name holds the save the exchange took.
        assert_eq!(fs::read_to_string(&p).unwrap(), "save 1");
        go.send(()).unwrap();
        t.join().unwrap();
        assert_eq!(
            fs::read_to_string(&p).unwrap(),
            "save 2 through the descriptor"
        );
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[test]
    fn a_save_through_a_descriptor_opened_before_the_exchange_ends_at_the_name() {
        // The same planner, faster: its open lands before the exchange and gets its rename
        // save, which the exchange then takes away. Taking it over waits until the writer is
        // done with it, so its write is in what goes back to the name.
        let (d, p) = project();
        if !leases_work(d.path()) {
            return;
        }
        let mut writer = None;
        let out = run(&p, Opts::default(), &mut |pt| {
            if pt == Point::BeforeExchange {
                rename_save(&p, "save 1");
                let w = descriptor_writer(&p, "save 2 through the descriptor");
                w.0.recv_timeout(Duration::from_secs(10)).unwrap();
                w.1.send(()).unwrap();
                writer = Some(w.2);
            }
        });
        writer.unwrap().join().unwrap();
        assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk);
        assert_eq!(
            fs::read_to_string(&p).unwrap(),
            "save 2 through the descriptor"
        );
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[test]
    fn a_reader_of_the_old_file_after_the_exchange_leaves_the_write_back_standing() {
        // A reader that looked the name up before the exchange opens the old file (blocked by
        // our lease), reads it and closes it: nothing changed, so the new file stays.
        let (d, p) = project();
        if !leases_work(d.path()) {
            return;
        }
        let mut reader = None;
        let out = run(&p, Opts::default(), &mut |pt| {
            if let Point::AfterExchange(old) = pt {
                let ino = fs::metadata(old).unwrap().ino();
                let old = old.to_owned();
                reader = Some(std::thread::spawn(move || {
                    fs::read_to_string(&old).unwrap()
                }));
                assert!(lease_breaking(ino, Duration::from_secs(10)));
            }
        });
        assert_eq!(reader.unwrap().join().unwrap(), SAMPLE);
        assert_eq!(out, WriteBackOutcome::Written);
        assert_eq!(fs::read_to_string(&p).unwrap(), written(SAMPLE));
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[test]
    fn a_double_race_keeps_both_files() {
        // The exchange takes a save that another program keeps open (for the whole wait), and a
        // writer opens the name while our file stands there: only one can have the name. The
        // save goes back; ours is kept beside it, with what the writer writes, and the
        // write-back is an error naming it: nothing is lost silently.
        let (d, p) = project();
        if !leases_work(d.path()) {
            return;
        }
        let mut reader = None;
        let mut writer = None;
        let r = write_back_with(
            &p,
            SAMPLE.as_bytes(),
            false,
            &[(&site(SAMPLE), "x.src")],
            &Opts::default(),
            &mut |pt| match pt {
                Point::BeforeExchange => {
                    rename_save(&p, "save 1");
                    reader = Some(fs::File::open(&p).unwrap());
                }
                Point::AfterExchange(_) => {
                    let ino = fs::metadata(&p).unwrap().ino();
                    let w = descriptor_writer(&p, "through the descriptor");
                    assert!(lease_breaking(ino, Duration::from_secs(10)));
                    writer = Some(w);
                }
                _ => {}
            },
        );
        let e = r.unwrap_err().to_string();
        let kept = d.path().join("Blackboard.aml.skillpost-kept-1");
        assert!(e.contains(&kept.display().to_string()), "{e}");
        let (opened, go, t) = writer.unwrap();
        opened.recv_timeout(Duration::from_secs(10)).unwrap();
        go.send(()).unwrap();
        t.join().unwrap();
        drop(reader);
        assert_eq!(fs::read_to_string(&p).unwrap(), "save 1");
        assert_eq!(fs::read_to_string(&kept).unwrap(), "through the descriptor");
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[test]
    fn a_read_only_blackboard_is_not_replaced() {
        let (d, p) = project();
        fs::set_permissions(&p, std::os::unix::fs::PermissionsExt::from_mode(0o444)).unwrap();
        let ino = fs::metadata(&p).unwrap().ino();
        for opts in modes(d.path()) {
            assert_eq!(
                run(&p, opts, &mut |_| {}),
                WriteBackOutcome::SkippedReadOnly
            );
        }
        assert_eq!(fs::read_to_string(&p).unwrap(), SAMPLE);
        assert_eq!(fs::metadata(&p).unwrap().ino(), ino);
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[test]
    fn writer_into_the_old_file_after_the_exchange_is_put_back() {
        // A writer that resolved the name before the exchange writes into the old inode, which
        // the exchange moved to the temporary name: it must end up at the name.
        let (d, p) = project();
        for opts in modes(d.path()) {
            fs::write(&p, SAMPLE).unwrap();
            let mut writer = None;
            let out = run(&p, opts, &mut |pt| {
                if let Point::AfterExchange(old) = pt {
                    let ino = fs::metadata(old).unwrap().ino();
                    let old = old.to_owned();
                    // Another thread: with a lease, its `open` blocks until the lease goes.
                    let w = std::thread::spawn(move || {
                        let mut f = fs::File::options()
                            .write(true)
                            .truncate(true)
                            .open(&old)
                            .unwrap();
                        f.write_all(b"in place").unwrap();
                    });
                    if opts.lease {
                        // Go on once the writer is blocked in `open` (not after a guessed sleep).
                        assert!(lease_breaking(ino, Duration::from_secs(10)), "{opts:?}");
                        writer = Some(w);
                    } else {
                        // Nothing blocks it: its write has happened before the checks go on.
                        w.join().unwrap();
                    }
                }
            });
            if let Some(w) = writer {
                w.join().unwrap();
            }
            assert_eq!(out, WriteBackOutcome::SkippedChangedOnDisk, "{opts:?}");
            assert_eq!(fs::read_to_string(&p).unwrap(), "in place", "{opts:?}");
            assert!(temp_leftovers(d.path()).is_empty());
        }
    }

    #[test]
    fn writer_that_opened_before_is_waited_for() {
        let (d, p) = project();
        if !leases_work(d.path()) {
            return;
        }
        // Opened before the write-back (an editor about to write): the lease is refused.
        let mut f = fs::File::options().write(true).open(&p).unwrap();
        assert_eq!(
            run(&p, Opts::default(), &mut |_| {}),
            WriteBackOutcome::SkippedInUse
        );
        f.set_len(0).unwrap();
        f.write_all(b"editor").unwrap();
        drop(f);
        assert_eq!(fs::read_to_string(&p).unwrap(), "editor");
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[test]
    fn writer_opening_during_the_lease_is_blocked_then_wins() {
        let (d, p) = project();
        if !leases_work(d.path()) {
            return;
        }
        let mut writer = None;
        let out = run(&p, Opts::default(), &mut |pt| {
            if pt == Point::Read {
                let ino = fs::metadata(&p).unwrap().ino();
                let p = p.clone();
                writer = Some(std::thread::spawn(move || {
                    let mut f = fs::File::options()
                        .write(true)
                        .truncate(true)
                        .open(&p)
                        .unwrap();
                    f.write_all(b"in place").unwrap();
                }));
                // Go on only once the writer is blocked in `open` by our lease (a sleep is not
                // enough on a loaded machine): the kernel lists the lease as breaking.
                assert!(
                    lease_breaking(ino, Duration::from_secs(10)),
                    "the writer's open did not break the lease"
                );
            }
        });
        writer.unwrap().join().unwrap();
        assert_eq!(out, WriteBackOutcome::SkippedInUse);
        assert_eq!(fs::read_to_string(&p).unwrap(), "in place");
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[test]
    fn hard_linked_blackboard_is_not_split() {
        let (d, p) = project();
        let other = d.path().join("Other.aml");
        fs::hard_link(&p, &other).unwrap();
        for opts in modes(d.path()) {
            assert_eq!(
                run(&p, opts, &mut |_| {}),
                WriteBackOutcome::SkippedHardLinked
            );
        }
        assert_eq!(fs::read_to_string(&p).unwrap(), SAMPLE);
        assert_eq!(
            fs::metadata(&p).unwrap().ino(),
            fs::metadata(&other).unwrap().ino()
        );
        assert!(temp_leftovers(d.path()).is_empty());
    }

    #[test]
    fn fallbacks_write_when_nothing_races() {
        let (d, p) = project();
        for opts in [
            Opts {
                lease: false,
                exchange: false,
            },
            Opts {
                lease: false,
                exchange: true,
            },
            Opts {
                lease: true,
                exchange: false,
            },
            Opts::default(),
        ] {
            fs::write(&p, SAMPLE).unwrap();
            assert_eq!(run(&p, opts, &mut |_| {}), WriteBackOutcome::Written);
            assert_eq!(fs::read_to_string(&p).unwrap(), written(SAMPLE));
            assert!(temp_leftovers(d.path()).is_empty());
        }
    }

    #[test]
    fn a_lease_break_does_not_kill_the_process() {
        // Another process opens the leased file: the kernel sends SIGIO, whose default action
        // would end this test process. The handler makes it harmless; the break shows in
        // F_GETLEASE, and the opener goes on once the lease is released.
        let (d, p) = project();
        if !leases_work(d.path()) {
            return;
        }
        let f = fs::File::open(&p).unwrap();
        assert!(lease::take(&f).unwrap());
        let cat = std::process::Command::new("cat")
            .arg(&p)
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let start = std::time::Instant::now();
        while lease::intact(&f) {
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "no lease break seen"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        std::thread::sleep(Duration::from_millis(50));
        drop(f);
        let out = cat.wait_with_output().unwrap();
        assert!(out.status.success());
        assert_eq!(out.stdout, SAMPLE.as_bytes());
    }

    /// The window that remains with a lease and the exchange: from the exchange to the end of
    /// the checks (`cargo test --release --lib window -- --ignored --nocapture`).
    #[test]
    #[ignore]
    fn window() {
        let (d, p) = project();
        if !leases_work(d.path()) {
            return;
        }
        let mut times = Vec::new();
        for _ in 0..2000 {
            fs::write(&p, SAMPLE).unwrap();
            let mut at = None;
            run(&p, Opts::default(), &mut |pt| match pt {
                Point::AfterExchange(_) => at = Some(std::time::Instant::now()),
                Point::Checked => times.push(at.unwrap().elapsed()),
                _ => {}
            });
        }
        times.sort();
        let q = |f: f64| times[((times.len() - 1) as f64 * f) as usize];
        eprintln!(
            "window: median {:?}, p99 {:?}, max {:?} ({} runs)",
            q(0.5),
            q(0.99),
            q(1.0),
            times.len()
        );
    }
}
