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
        let held = (leased && taken == old_id).then_some(&file);
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
    held: Option<&lease::Unleased>,
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
            &opened
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

pub(crate) mod lease;

#[cfg(test)]
mod tests;
