//! Leases on the blackboard's descriptor, with `SIGIO` made harmless first.

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

impl std::os::fd::AsFd for Unleased {
    fn as_fd(&self) -> std::os::fd::BorrowedFd<'_> {
        self.0.as_fd()
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
/// `WouldBlock` when another descriptor has the file open. Only on an [`Unleased`] file, so
/// no lease of ours outlives our descriptor.
pub fn take(file: &Unleased) -> io::Result<bool> {
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
pub fn retake(file: &Unleased) -> bool {
    intact(file)
        && fdlease::set(file, Lease::None).is_ok()
        && fdlease::set(file, Lease::Write).is_ok()
}

/// Whether this process can take leases on files in `dir` (for the tests of leases here and in
/// the daemon); prints why a test is skipped when not, and fails under
/// `SKILLPOST_STRICT_TESTS=1`.
#[cfg(test)]
pub(crate) fn leases_work(dir: &std::path::Path) -> bool {
    let p = dir.join("lease-probe");
    std::fs::write(&p, "x").unwrap();
    let f = Unleased(std::fs::File::open(&p).unwrap());
    let ok = take(&f).unwrap_or(false);
    drop(f);
    std::fs::remove_file(&p).unwrap();
    if !ok {
        let why = "no file leases here (not the owner and no CAP_LEASE, or no lease support)";
        if std::env::var("SKILLPOST_STRICT_TESTS").as_deref() == Ok("1") {
            panic!("{why} (SKILLPOST_STRICT_TESTS=1)");
        }
        eprintln!("skipped: {why}");
    }
    ok
}
