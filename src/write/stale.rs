//! Removing the parts of a split program that a later, shorter compile no longer writes
//! (docs/LANGUAGES.md, "Long programs"): only files that name themselves parts of that program
//! by their marker comment (`emit::split::marker`) in their first 4 KiB, regular files reached
//! without following a symbolic link; a file a user wrote under such a name stays.

use std::io::Read as _;
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::{Path, PathBuf};

/// How much of a file is read for its marker.
const HEAD: u64 = 4096;

/// Whether the file at `path` holds `marker` (followed by no name character) near its start.
pub fn holds_marker(path: &Path, marker: &str) -> bool {
    let Ok(meta) = std::fs::symlink_metadata(path) else {
        return false;
    };
    if !meta.file_type().is_file() {
        return false;
    }
    let Ok(f) = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc_flags())
        .open(path)
    else {
        return false;
    };
    let mut head = Vec::new();
    if f.take(HEAD).read_to_end(&mut head).is_err() {
        return false;
    }
    let m = marker.as_bytes();
    head.windows(m.len()).enumerate().any(|(i, w)| {
        w == m
            && head
                .get(i + m.len())
                .is_none_or(|c| !(c.is_ascii_alphanumeric() || *c == b'_'))
    })
}

/// `O_NOFOLLOW | O_NONBLOCK`: a link is not followed, a FIFO does not block.
fn libc_flags() -> i32 {
    (rustix::fs::OFlags::NOFOLLOW | rustix::fs::OFlags::NONBLOCK).bits() as i32
}

/// Removes each of `files` that holds `marker`, when the first one does; `None` when the
/// first one does not (no such part: the caller stops looking). The removed paths are those
/// given (before `route`).
pub fn remove_marked(
    files: &[PathBuf],
    marker: &str,
    route: &dyn Fn(&Path) -> PathBuf,
) -> Option<Vec<PathBuf>> {
    let first = files.first()?;
    if !holds_marker(&route(first), marker) {
        return None;
    }
    let mut removed = Vec::new();
    for f in files {
        let r = route(f);
        if holds_marker(&r, marker) && std::fs::remove_file(&r).is_ok() {
            removed.push(f.clone());
        }
    }
    Some(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_marked_files_are_removed() {
        let t = tempfile::tempdir().unwrap();
        let src = t.path().join("P_2.src");
        let dat = t.path().join("P_2.dat");
        std::fs::write(
            &src,
            "&ACCESS RVP\n;skillpost part 2 of P: P.src calls it\n",
        )
        .unwrap();
        std::fs::write(&dat, "DEFDAT P_2\n;mine\n").unwrap();
        let id = |p: &Path| p.to_path_buf();
        // Part 2 of `P_A`, or part 22, is not part 2 of `P`.
        std::fs::write(
            &dat,
            "DEFDAT P_2\n;skillpost part 2 of P_A\n;skillpost part 22 of P\n",
        )
        .unwrap();
        assert!(!holds_marker(&dat, "skillpost part 2 of P"));
        let removed = remove_marked(&[src.clone(), dat.clone()], "skillpost part 2 of P", &id);
        assert_eq!(removed, Some(vec![src.clone()]));
        assert!(!src.exists() && dat.exists());
        assert_eq!(
            remove_marked(&[src, dat], "skillpost part 2 of P", &id),
            None
        );
    }

    #[test]
    fn a_link_is_not_followed() {
        let t = tempfile::tempdir().unwrap();
        let target = t.path().join("elsewhere.src");
        std::fs::write(&target, ";skillpost part 1 of P\n").unwrap();
        let link = t.path().join("P_1.src");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        assert!(!holds_marker(&link, "skillpost part 1 of P"));
    }
}
