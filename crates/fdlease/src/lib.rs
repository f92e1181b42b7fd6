//! Linux file leases (`fcntl(F_SETLEASE)`, `fcntl(F_GETLEASE)`) behind a safe API.
//!
//! skillpost's own crates forbid `unsafe` code; neither `rustix` (1.1) nor `nix` (0.31) wraps
//! these two `fcntl` commands, so this crate does, and nothing else. Both calls take a file
//! descriptor borrowed for the call and an integer, and return an integer: no pointer crosses
//! the boundary, so the only obligation is a valid descriptor, which [`BorrowedFd`] guarantees.
//!
//! A lease is held on an open file description and released when it is closed. Breaking one
//! (another process opens or truncates the file) sends the holder `SIGIO` unless `F_SETSIG`
//! says otherwise, and `SIGIO`'s default action terminates the process: a program that takes
//! leases must handle or ignore `SIGIO` first (skillpost installs a handler, see its
//! `write::lease` module). [`get`] shows a break without any signal: the lease then reads as
//! the type the breaker needs it downgraded to.

#![deny(unsafe_op_in_unsafe_fn)]

use std::io;
use std::os::fd::{AsFd, AsRawFd};

/// A lease type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lease {
    /// No lease (`F_UNLCK`); setting it releases the lease.
    None,
    /// A read lease (`F_RDLCK`): broken by an open for writing or a truncation.
    Read,
    /// A write lease (`F_WRLCK`): broken by any open or a truncation. It can only be taken when
    /// no other file descriptor (of any process) has the file open.
    Write,
}

impl Lease {
    fn raw(self) -> libc::c_int {
        match self {
            Lease::None => libc::F_UNLCK,
            Lease::Read => libc::F_RDLCK,
            Lease::Write => libc::F_WRLCK,
        }
    }
}

/// `fcntl(fd, F_SETLEASE, lease)`. Errors as the kernel gives them: `EAGAIN`
/// ([`io::ErrorKind::WouldBlock`]) when the file is open elsewhere (write lease) or open for
/// writing (read lease); `EACCES` when the caller neither owns the file nor has `CAP_LEASE`;
/// `EINVAL` where the file system has no leases (NFS, FUSE, …).
pub fn set(fd: impl AsFd, lease: Lease) -> io::Result<()> {
    let fd = fd.as_fd();
    // SAFETY: `fd` is a valid, open descriptor for the duration of the call (it is borrowed);
    // F_SETLEASE takes an int argument and touches no memory of ours.
    let r = unsafe { libc::fcntl(fd.as_raw_fd(), libc::F_SETLEASE, lease.raw()) };
    if r == -1 {
        Err(io::Error::last_os_error())
    } else {
        Ok(())
    }
}

/// `fcntl(fd, F_GETLEASE)`: the lease held through this descriptor. While a break is pending it
/// is the type the breaker asked for ([`Lease::Read`] for a reader, [`Lease::None`] for a
/// writer or a truncation).
pub fn get(fd: impl AsFd) -> io::Result<Lease> {
    let fd = fd.as_fd();
    // SAFETY: as in `set`; F_GETLEASE takes no argument and returns an int.
    let r = unsafe { libc::fcntl(fd.as_raw_fd(), libc::F_GETLEASE) };
    match r {
        -1 => Err(io::Error::last_os_error()),
        libc::F_UNLCK => Ok(Lease::None),
        libc::F_RDLCK => Ok(Lease::Read),
        libc::F_WRLCK => Ok(Lease::Write),
        other => Err(io::Error::other(format!("F_GETLEASE returned {other}"))),
    }
}
