//! The compile's file source in the daemon: it reads like [`FsSource`], keeps the hash of
//! every file's bytes (what the next change is compared with), and refuses the daemon's own
//! files.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::hash_file;
use crate::load::{FileSource, FsSource, hash_bytes};

/// Reads files like [`FsSource`] and keeps the hash of every file's bytes. The daemon's own
/// files (`own`: the events and state files, canonical) are never read: a blackboard naming
/// one gets an error at that reference, not a compile that starts again at every event.
pub(super) struct Hashing {
    pub(super) fs: FsSource,
    pub(super) seen: std::sync::Mutex<HashMap<PathBuf, Option<u64>>>,
    pub(super) own: Vec<PathBuf>,
}

impl Hashing {
    fn refuse_own(&self, path: &Path) -> std::io::Result<()> {
        if self.own.is_empty() {
            return Ok(());
        }
        let real = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
        if self.own.contains(&real) {
            return Err(std::io::Error::new(
                std::io::ErrorKind::PermissionDenied,
                "this is the daemon's own events or state file, which no project may read",
            ));
        }
        Ok(())
    }
}

impl FileSource for Hashing {
    fn real_path(&self, path: &Path) -> Option<PathBuf> {
        self.fs.real_path(path)
    }

    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        self.read_max(path, u64::MAX)
    }

    fn read_max(&self, path: &Path, max: u64) -> std::io::Result<Vec<u8>> {
        self.refuse_own(path)?;
        let r = self.fs.read_max(path, max);
        let hash = match &r {
            Ok(b) => Some(hash_bytes(b)),
            // Too large: a whole file nonetheless, whose hash tells a later save from it (else
            // the failure looked like a file still being written, retried for ever).
            Err(e) if e.kind() == std::io::ErrorKind::InvalidData => hash_file(path),
            Err(_) => None,
        };
        self.saw(path, hash);
        r
    }

    fn open(&self, path: &Path) -> std::io::Result<crate::load::Opened<'_>> {
        self.refuse_own(path)?;
        match self.fs.open(path) {
            Ok(o) => Ok(crate::load::Opened {
                len: o.len,
                at: o.at,
                reader: Box::new(HashingReader {
                    inner: o.reader,
                    hash: Some(crate::load::ContentHash::new()),
                    path: path.to_owned(),
                    to: self,
                }),
            }),
            Err(e) => {
                self.saw(path, None);
                Err(e)
            }
        }
    }
}

impl Hashing {
    /// Records a file's hash. The first read is what the compile used: a second one (the SFC
    /// read again for a diagnostic's line) must not hide a save made in between from the check
    /// after the compile.
    fn saw(&self, path: &Path, hash: Option<u64>) {
        self.seen
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .entry(path.to_owned())
            .or_insert(hash);
    }
}

/// Hashes a streamed file as it is read ([`crate::load::hash_bytes`] of its bytes), recorded at
/// its end; a stream that fails or is left before its end records no hash (the file is then
/// compiled again).
struct HashingReader<'a> {
    inner: Box<dyn std::io::Read + Send + 'a>,
    hash: Option<crate::load::ContentHash>,
    path: PathBuf,
    to: &'a Hashing,
}

impl std::io::Read for HashingReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match self.inner.read(buf) {
            Ok(0) if !buf.is_empty() => {
                if let Some(h) = self.hash.take() {
                    self.to.saw(&self.path, Some(h.finish()));
                }
                Ok(0)
            }
            Ok(n) => {
                if let Some(h) = &mut self.hash {
                    h.update(&buf[..n]);
                }
                Ok(n)
            }
            Err(e) => {
                if self.hash.take().is_some() {
                    self.to.saw(&self.path, None);
                }
                Err(e)
            }
        }
    }
}

impl Drop for HashingReader<'_> {
    fn drop(&mut self) {
        if self.hash.take().is_some() {
            self.to.saw(&self.path, None);
        }
    }
}
