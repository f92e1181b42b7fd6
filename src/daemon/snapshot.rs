//! What a deploy hook ships: a private copy of the bytes a compile wrote, taken when it wrote
//! them (docs/DAEMON.md, "Deploying").
//!
//! The program files in the project folder belong to whoever can write there: a planner's
//! hand-written `P.src` renamed over ours, a folder swapped for a link, or the next compile's
//! `.src` beside this compile's `.dat` would otherwise be what the hook copies to a controller.
//! So `{src}`, `{dat}`, `{mod}`, `{script}`, `{output}` and `{outputs}` name files in a folder
//! of the daemon's own (`<runtime directory>/deploy/deploy-XXXXXX/`, mode 0700, same file names
//! as in the project), written from the compile's bytes in memory. The folder is removed when the
//! hook has ended, or when a newer compile's deploy replaces this one before it ran.

use std::os::unix::fs::{DirBuilderExt as _, MetadataExt as _, OpenOptionsExt as _};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A snapshot: its folder lives as long as the last holder of the `Arc`.
pub type Held = Arc<tempfile::TempDir>;

/// The folder of the snapshots under the runtime directory `runtime`: made if needed, and only
/// used when it is a folder of this user that nobody else can write to (never through a link).
fn base(runtime: &Path) -> std::io::Result<PathBuf> {
    let dir = runtime.join("deploy");
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(&dir)?;
    for d in [runtime, dir.as_path()] {
        let meta = std::fs::symlink_metadata(d)?;
        if !meta.is_dir()
            || meta.uid() != rustix::process::getuid().as_raw()
            || meta.mode() & 0o022 != 0
        {
            return Err(std::io::Error::new(
                std::io::ErrorKind::PermissionDenied,
                format!(
                    "{} is not a folder of this user that only it can write to; set \
                     RUNTIME_DIRECTORY or XDG_RUNTIME_DIR",
                    d.display()
                ),
            ));
        }
    }
    Ok(dir)
}

/// Writes `files` (each the path the compile wrote and its bytes) into a new snapshot folder
/// under `runtime`: the folder and the paths of the copies, in the order given.
pub fn take(runtime: &Path, files: &[(&Path, &[u8])]) -> std::io::Result<(Held, Vec<PathBuf>)> {
    use std::os::unix::fs::PermissionsExt as _;
    let dir = tempfile::Builder::new()
        .prefix("deploy-")
        .permissions(std::fs::Permissions::from_mode(0o700))
        .tempdir_in(base(runtime)?)?;
    let mut copies = Vec::with_capacity(files.len());
    for (path, bytes) in files {
        let name = path.file_name().ok_or_else(|| {
            std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("{} has no file name", path.display()),
            )
        })?;
        let copy = dir.path().join(name);
        // `create_new`: two outputs of one program with one name would be a bug, never a merge.
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .open(&copy)?;
        std::io::Write::write_all(&mut f, bytes)?;
        copies.push(copy);
    }
    Ok((Arc::new(dir), copies))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt as _;

    #[test]
    fn a_snapshot_holds_the_bytes_given_and_goes_with_its_last_holder() {
        let run = tempfile::tempdir().unwrap();
        let (held, copies) = take(
            run.path(),
            &[
                (Path::new("/p/P.src"), b"DEF P()".as_slice()),
                (Path::new("/p/P.dat"), b"DEFDAT P".as_slice()),
            ],
        )
        .unwrap();
        assert_eq!(copies[0].file_name().unwrap(), "P.src");
        assert_eq!(std::fs::read(&copies[1]).unwrap(), b"DEFDAT P");
        let mode = std::fs::metadata(held.path()).unwrap().permissions().mode();
        assert_eq!(mode & 0o077, 0, "{mode:o}");
        let dir = held.path().to_owned();
        drop(held);
        assert!(!dir.exists());
    }

    #[test]
    fn a_runtime_folder_others_can_write_to_is_not_used() {
        let run = tempfile::tempdir().unwrap();
        std::fs::set_permissions(run.path(), std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = take(run.path(), &[(Path::new("/p/P.src"), b"x".as_slice())]).unwrap_err();
        assert!(e.to_string().contains("only it can write"), "{e}");
    }
}
