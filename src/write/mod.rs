//! Writing: atomic output files and the blackboard write-back. The only module that writes;
//! only [`crate::compile::apply`] calls it.
//!
//! - [`atomic`]: [`write_if_changed`] writes a file through a temporary file, `fsync` and a
//!   rename, and leaves a file that already holds the bytes alone (not even its mtime changes);
//!   [`write_all_if_changed`] writes several files (the `.src`/`.dat` pair) as one change. Both
//!   refuse symbolic links, non-regular files and read-only files.
//! - [`splice`]: [`splice_at`] puts the value into the write-back target's `Value` by replacing
//!   only the bytes the reader located ([`SpliceSite`]); pure.
//! - [`folder`]: [`Folder`] holds the project folder open from before the blackboard is read
//!   to the end of the writing; every write goes through it, so outputs land in the folder
//!   whose inputs were read, whatever is put at its name meanwhile.
//! - [`writeback`]: [`write_back`] replaces the blackboard with the spliced text under a lease
//!   and an exchange, so that a newer file is never replaced by an older one.
//!
//! The invariant of the whole module: **a file at a name is only ever replaced by a newer
//! one.** An output is replaced by the new compile's output; the blackboard only when it still
//! holds the bytes the compile read, checked in a way no save can slip past (see
//! [`writeback`]).

pub mod atomic;
pub mod folder;
pub mod splice;
pub mod stale;
pub mod writeback;

pub use atomic::{WriteOutcome, is_temporary, write_all_if_changed, write_if_changed};
pub use folder::Folder;
pub use splice::{SpliceSite, splice_all, splice_at, splice_value};
pub use writeback::{WriteBackOutcome, write_back, write_back_all};

/// Whether the open `file` holds exactly `expected`: its length by `fstat`, then its bytes read
/// through the descriptor from offset 0 (positional reads: the descriptor's own offset is left
/// alone, so a file is checked again and again) and compared a piece of at most 64 KiB at a time
/// (a 13 MB output is not held twice), and nothing after them (a file that grew meanwhile).
pub(crate) fn holds(file: &std::fs::File, expected: &[u8]) -> std::io::Result<bool> {
    use std::os::unix::fs::FileExt as _;
    if file.metadata()?.len() != expected.len() as u64 {
        return Ok(false);
    }
    let mut piece = vec![0u8; expected.len().clamp(1, 64 << 10)];
    let mut at = 0;
    while at < expected.len() {
        let want = piece.len().min(expected.len() - at);
        match file.read_at(&mut piece[..want], at as u64) {
            Ok(0) => return Ok(false),
            Ok(n) if piece[..n] == expected[at..at + n] => at += n,
            Ok(_) => return Ok(false),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    let mut probe = [0u8; 1];
    Ok(file.read_at(&mut probe, at as u64)? == 0)
}

/// The names in `dir` that start like our temporary files (any suffix: a leftover of another
/// shape is one too), for the unit tests of the writers.
#[cfg(test)]
pub(crate) fn temp_leftovers(dir: &std::path::Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".skillpost-"))
        .collect()
}
