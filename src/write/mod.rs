//! Writing: atomic output files and the blackboard write-back. The only module that writes;
//! only [`crate::compile::apply`] calls it.
//!
//! - [`atomic`]: [`write_if_changed`] writes a file through a temporary file, `fsync` and a
//!   rename, and leaves a file that already holds the bytes alone (not even its mtime changes);
//!   [`write_all_if_changed`] writes several files (the `.src`/`.dat` pair) as one change. Both
//!   refuse symbolic links, non-regular files and read-only files.
//! - [`splice`]: [`splice_at`] puts the value into the write-back target's `Value` by replacing
//!   only the bytes the reader located ([`SpliceSite`]); pure.
//! - [`writeback`]: [`write_back`] replaces the blackboard with the spliced text under a lease
//!   and an exchange, so that a newer file is never replaced by an older one.
//!
//! The invariant of the whole module: **a file at a name is only ever replaced by a newer
//! one.** An output is replaced by the new compile's output; the blackboard only when it still
//! holds the bytes the compile read, checked in a way no save can slip past (see
//! [`writeback`]).

pub mod atomic;
pub mod splice;
pub mod writeback;

pub use atomic::{WriteOutcome, is_temporary, write_all_if_changed, write_if_changed};
pub use splice::{SpliceSite, splice_at, splice_value};
pub use writeback::{WriteBackOutcome, write_back};

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
