//! The loading layer: the only place the compiler core touches the file system.
//!
//! The core asks a [`FileSource`] for a file's bytes; [`FsSource`] reads the real file system,
//! tests and the daemon may pass their own. Every file asked for is recorded, so the caller knows
//! exactly which files a compile read (the daemon watches those).

use std::io::Read;
use std::path::{Path, PathBuf};

/// Default limit for one input file (256 MiB): far above any real project, far below memory.
pub const DEFAULT_MAX_FILE_SIZE: u64 = 256 * 1024 * 1024;

/// Where the compiler's input files come from.
pub trait FileSource {
    /// Reads a whole file.
    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>>;

    /// Opens a file to be read as a stream (the SFC: the one input that grows with the product,
    /// so its text is never whole in memory). By default, [`FileSource::read`] into memory.
    fn open(&self, path: &Path) -> std::io::Result<Opened<'_>> {
        let bytes: std::sync::Arc<[u8]> = self.read(path)?.into();
        Ok(Opened {
            len: Some(bytes.len() as u64),
            reader: Box::new(std::io::Cursor::new(Shared(bytes.clone()))),
            at: Some(std::sync::Arc::new(Shared(bytes))),
        })
    }

    /// The path with every symbolic link resolved, if the source knows it (for confining a
    /// project to its folder). `None`: take the path as it is.
    fn real_path(&self, _path: &Path) -> Option<PathBuf> {
        None
    }

    /// Reads a whole file of at most `max` bytes (what is left of [`WHOLE_FILES_BUDGET`]): a
    /// larger one is an `InvalidData` error, read no further than `max + 1` bytes where the
    /// source can tell (the default reads it, then checks).
    fn read_max(&self, path: &Path, max: u64) -> std::io::Result<Vec<u8>> {
        let bytes = self.read(path)?;
        if bytes.len() as u64 > max {
            return Err(over_budget(max));
        }
        Ok(bytes)
    }
}

/// How many bytes the files one compile reads whole (the blackboard, its IRL files, the output
/// template) may have together: 32 MiB. Each is parsed into a tree that takes about 20 bytes
/// of memory per byte of text (a 240 MB blackboard took 4.8 GB), so this bounds one compile's
/// memory to well under 1 GB, whatever a planner saves; the SFC, which grows with the product,
/// is streamed and not counted.
pub const WHOLE_FILES_BUDGET: u64 = 32 * 1024 * 1024;

/// The error of a file that does not fit what is left of [`WHOLE_FILES_BUDGET`].
pub fn over_budget(left: u64) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::InvalidData,
        format!(
            "is larger than the {} bytes left of the {} MiB that the blackboard, its IRL files \
             and the template may take together (they are read whole, and each byte takes about \
             20 in memory)",
            left,
            WHOLE_FILES_BUDGET >> 20
        ),
    )
}

/// A file opened by [`FileSource::open`]: its bytes, and its size if known.
pub struct Opened<'a> {
    pub reader: Box<dyn Read + Send + 'a>,
    pub len: Option<u64>,
    /// The same open file, read at any place (a large SFC is read in two halves at once, the
    /// second through this), if the source offers it. Its bytes are those `reader` gives; the
    /// reader of the halves checks that they were, where the two overlap.
    pub at: Option<std::sync::Arc<dyn ReadAt>>,
}

/// A file read at any place, by several threads at once (`pread`: the file's position is not
/// moved, so it does not disturb a stream over the same open file).
pub trait ReadAt: Send + Sync {
    /// Reads into `buf` from `offset`; 0 at the end of the file.
    fn read_at(&self, buf: &mut [u8], offset: u64) -> std::io::Result<usize>;
}

#[cfg(unix)]
impl ReadAt for std::fs::File {
    fn read_at(&self, buf: &mut [u8], offset: u64) -> std::io::Result<usize> {
        std::os::unix::fs::FileExt::read_at(self, buf, offset)
    }
}

/// Bytes in memory: a `&&[u8]` is a `&dyn ReadAt`.
impl ReadAt for &[u8] {
    fn read_at(&self, buf: &mut [u8], offset: u64) -> std::io::Result<usize> {
        let from = usize::try_from(offset)
            .unwrap_or(usize::MAX)
            .min(self.len());
        let n = buf.len().min(self.len() - from);
        buf[..n].copy_from_slice(&self[from..from + n]);
        Ok(n)
    }
}

/// Bytes in memory, shared by a stream and a [`ReadAt`] over them.
struct Shared(std::sync::Arc<[u8]>);

impl AsRef<[u8]> for Shared {
    fn as_ref(&self) -> &[u8] {
        &self.0
    }
}

impl ReadAt for Shared {
    fn read_at(&self, buf: &mut [u8], offset: u64) -> std::io::Result<usize> {
        (&self.0[..]).read_at(buf, offset)
    }
}

/// Reads at most `max` bytes: one more is an error (the file grew past the limit after its
/// size was checked).
struct Limited<R> {
    inner: R,
    left: u64,
    max: u64,
}

impl<R: Read> Read for Limited<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        // One byte past the limit may be read, to tell "exactly at" from "over".
        let room = (self.left + 1).min(buf.len() as u64) as usize;
        let n = self.inner.read(&mut buf[..room])?;
        if n as u64 > self.left {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("is larger than the limit of {} bytes", self.max),
            ));
        }
        self.left -= n as u64;
        Ok(n)
    }
}

/// Reads regular files from disk, refusing anything else (directories, FIFOs, devices such as
/// `/dev/zero`) and anything larger than `max_file_size`.
#[derive(Debug, Clone)]
pub struct FsSource {
    pub max_file_size: u64,
}

impl Default for FsSource {
    fn default() -> Self {
        FsSource {
            max_file_size: DEFAULT_MAX_FILE_SIZE,
        }
    }
}

/// Opens a regular file for reading, without blocking: opening a FIFO (named by a `refURI`, or
/// sitting in a polled folder) must not wait for a writer. The file type is checked on the open
/// handle, so a rename in between cannot slip another kind of file in.
pub fn open_regular(path: &Path) -> std::io::Result<(std::fs::File, std::fs::Metadata)> {
    use std::io::{Error, ErrorKind};
    use std::os::unix::fs::OpenOptionsExt;
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(rustix::fs::OFlags::NONBLOCK.bits() as i32)
        .open(path)?;
    let meta = file.metadata()?;
    if meta.is_dir() {
        return Err(Error::new(ErrorKind::InvalidInput, "is a directory"));
    }
    if !meta.is_file() {
        return Err(Error::new(ErrorKind::InvalidInput, "is not a regular file"));
    }
    if kernel_interface(&file) {
        // `/proc/kmsg` is a "regular file" whose reading consumes the kernel's log; no file of
        // /proc, /sys and their kin is a planner's (also when a link points there).
        return Err(Error::new(
            ErrorKind::InvalidInput,
            "is a kernel interface (/proc, /sys and the like), not a file",
        ));
    }
    Ok((file, meta))
}

/// Whether the open file lies on one of the kernel's pseudo file systems (procfs, sysfs,
/// debugfs, tracefs, securityfs, cgroup, configfs, bpf, efivarfs, pstore): their "regular
/// files" are interfaces whose reading can change the system's state.
fn kernel_interface(file: &std::fs::File) -> bool {
    const PSEUDO: [u64; 11] = [
        0x9fa0,      // proc
        0x6265_6572, // sysfs
        0x6462_6720, // debugfs
        0x7472_6163, // tracefs
        0x7363_6673, // securityfs
        0x0027_e0eb, // cgroup
        0x6367_7270, // cgroup2
        0x6265_6570, // configfs
        0xcafe_4a11, // bpf
        0xde5e_81e4, // efivarfs
        0x6165_676c, // pstore
    ];
    rustix::fs::fstatfs(file).is_ok_and(|s| PSEUDO.contains(&(s.f_type as u64)))
}

/// Reads a whole regular file of at most `max` bytes, without blocking: the one read of the
/// daemon's (inputs, content hashes, half-written checks, the configuration) and of
/// [`FsSource`]. A FIFO, a device (`/dev/zero`), a directory or a larger file is an error at
/// once; nothing is read past `max + 1` bytes, so a file that grows meanwhile cannot fill memory.
pub fn read_limited(path: &Path, max: u64) -> std::io::Result<Vec<u8>> {
    use std::io::{Error, ErrorKind};
    let (file, meta) = open_within(path, max)?;
    let mut buf = Vec::with_capacity(meta.len() as usize + 1);
    // Read at most one byte past the limit, in case the file grew since the metadata call.
    file.take(max + 1).read_to_end(&mut buf)?;
    if buf.len() as u64 > max {
        return Err(Error::new(
            ErrorKind::InvalidData,
            format!("is larger than the limit of {max} bytes"),
        ));
    }
    Ok(buf)
}

/// [`read_limited`] of a file that must lie inside the folder `root`: a symbolic link that
/// leads out of it is refused. The place checked is the file opened, not its name looked up
/// again (on Linux, what `/proc/self/fd` says the open file is), so a link swapped between a
/// check and the read cannot lead the read out.
pub fn read_limited_inside(path: &Path, max: u64, root: &Path) -> std::io::Result<Vec<u8>> {
    use std::io::{Error, ErrorKind};
    let (mut file, meta) = open_within(path, max)?;
    let real = opened_path(&file).or_else(|| std::fs::canonicalize(path).ok());
    if let (Some(real), Ok(real_root)) = (real, std::fs::canonicalize(root))
        && !real.starts_with(&real_root)
    {
        return Err(Error::new(
            ErrorKind::PermissionDenied,
            "is a symbolic link that leads out of the project folder: not read",
        ));
    }
    let mut buf = Vec::with_capacity(meta.len() as usize + 1);
    (&mut file).take(max + 1).read_to_end(&mut buf)?;
    if buf.len() as u64 > max {
        return Err(Error::new(
            ErrorKind::InvalidData,
            format!("is larger than the limit of {max} bytes"),
        ));
    }
    Ok(buf)
}

/// Where an open file is (Linux: `/proc/self/fd`); `None` elsewhere.
fn opened_path(file: &std::fs::File) -> Option<std::path::PathBuf> {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        std::fs::read_link(format!("/proc/self/fd/{}", file.as_raw_fd())).ok()
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = file;
        None
    }
}

/// The content hash files are compared by (the daemon's "changed since the compile read it",
/// the streamed SFC read again for its diagnostics): of bytes in memory ([`hash_bytes`]), of a
/// file read in pieces ([`hash_file`]) or of a stream ([`ContentHash`]), alike for the same
/// bytes. XXH3 (64 bits): it runs at memory speed (the SFC of 100,000 steps is 78 MB, hashed as
/// it is read); it is not keyed, which is no loss here: whoever could craft a collision can
/// write the project's files anyway.
pub fn hash_bytes(b: &[u8]) -> u64 {
    xxhash_rust::xxh3::xxh3_64(b)
}

/// [`ContentHash`] keeps the hash of every prefix of this many bytes, and of its multiples.
pub const PREFIX_STEP: usize = 1 << 20;

/// [`hash_bytes`] of bytes that come in pieces; also [`hash_bytes`] of each prefix of
/// [`PREFIX_STEP`] bytes and its multiples ([`ContentHash::prefixes`]): a file read again only
/// as far as some lines of it is the same there when that prefix has the same hash.
#[derive(Clone, Default)]
pub struct ContentHash {
    hash: xxhash_rust::xxh3::Xxh3Default,
    len: usize,
    prefixes: Vec<u64>,
}

impl ContentHash {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn update(&mut self, mut bytes: &[u8]) {
        while !bytes.is_empty() {
            let n = (PREFIX_STEP - self.len % PREFIX_STEP).min(bytes.len());
            self.hash.update(&bytes[..n]);
            self.len += n;
            bytes = &bytes[n..];
            if self.len.is_multiple_of(PREFIX_STEP) {
                self.prefixes.push(self.hash.digest());
            }
        }
    }

    /// `prefixes()[k]`: [`hash_bytes`] of the first `(k + 1) * PREFIX_STEP` bytes.
    pub fn prefixes(&self) -> &[u64] {
        &self.prefixes
    }

    pub fn finish(&self) -> u64 {
        self.hash.digest()
    }
}

/// [`hash_bytes`] of a regular file's contents, read in pieces (nothing is held in memory), opened
/// like [`read_limited`] (a FIFO or device is an error at once); a file of more than `max` bytes
/// is an error.
pub fn hash_file(path: &Path, max: u64) -> std::io::Result<u64> {
    use std::io::{Error, ErrorKind};
    let (file, _) = open_regular(path)?;
    let mut file = file.take(max + 1);
    let mut h = ContentHash::new();
    let mut buf = vec![0u8; 64 * 1024];
    let mut total = 0u64;
    loop {
        match file.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                total += n as u64;
                h.update(&buf[..n]);
            }
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    if total > max {
        return Err(Error::new(
            ErrorKind::InvalidData,
            format!("is larger than the limit of {max} bytes"),
        ));
    }
    Ok(h.finish())
}

impl FileSource for FsSource {
    fn real_path(&self, path: &Path) -> Option<PathBuf> {
        std::fs::canonicalize(path).ok()
    }

    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        read_limited(path, self.max_file_size)
    }

    fn read_max(&self, path: &Path, max: u64) -> std::io::Result<Vec<u8>> {
        if max >= self.max_file_size {
            return read_limited(path, self.max_file_size);
        }
        // `read_limited`'s only `InvalidData` is a file over the limit: here, the budget's.
        read_limited(path, max).map_err(|e| {
            if e.kind() == std::io::ErrorKind::InvalidData {
                over_budget(max)
            } else {
                e
            }
        })
    }

    fn open(&self, path: &Path) -> std::io::Result<Opened<'_>> {
        open_limited(path, self.max_file_size)
    }
}

/// [`open_regular`], and an error when the file is larger than `max` bytes.
fn open_within(path: &Path, max: u64) -> std::io::Result<(std::fs::File, std::fs::Metadata)> {
    let (file, meta) = open_regular(path)?;
    if meta.len() > max {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "is {} bytes, more than the limit of {max} bytes",
                meta.len()
            ),
        ));
    }
    Ok((file, meta))
}

/// Opens a regular file of at most `max` bytes to be read as a stream, like [`read_limited`]
/// (a FIFO or device is an error at once; reading past `max` bytes is an error).
pub fn open_limited(path: &Path, max: u64) -> std::io::Result<Opened<'static>> {
    let (file, meta) = open_within(path, max)?;
    #[cfg(unix)]
    let at = file
        .try_clone()
        .ok()
        .map(|f| std::sync::Arc::new(f) as std::sync::Arc<dyn ReadAt>);
    #[cfg(not(unix))]
    let at = None;
    Ok(Opened {
        len: Some(meta.len()),
        at,
        reader: Box::new(Limited {
            inner: file,
            left: max,
            max,
        }),
    })
}

/// An in-memory file source, for tests and fuzzing.
#[derive(Debug, Default, Clone)]
pub struct MemSource {
    pub files: std::collections::HashMap<PathBuf, Vec<u8>>,
}

impl MemSource {
    pub fn insert(&mut self, path: impl Into<PathBuf>, bytes: impl Into<Vec<u8>>) {
        self.files.insert(path.into(), bytes.into());
    }
}

impl FileSource for MemSource {
    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        self.files
            .get(path)
            .cloned()
            .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::NotFound, "not found"))
    }
}

/// Removes a leading UTF-8 byte order mark; whether there was one.
pub fn strip_bom(bytes: &mut Vec<u8>) -> bool {
    let bom = bytes.starts_with(b"\xEF\xBB\xBF");
    if bom {
        bytes.drain(..3);
    }
    bom
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file inside the folder, or a link to one inside, is read; a link that leads out of it
    /// is refused, the file it leads to untouched.
    #[cfg(unix)]
    #[test]
    fn a_read_inside_a_folder_refuses_a_link_that_leads_out() {
        let d = tempfile::tempdir().unwrap();
        let root = d.path().join("project");
        std::fs::create_dir(&root).unwrap();
        std::fs::write(root.join("s.toml"), "inside").unwrap();
        std::fs::write(d.path().join("secret"), "outside").unwrap();
        std::os::unix::fs::symlink(root.join("s.toml"), root.join("in.toml")).unwrap();
        std::os::unix::fs::symlink(d.path().join("secret"), root.join("out.toml")).unwrap();
        let read = |n: &str| read_limited_inside(&root.join(n), 100, &root);
        assert_eq!(read("s.toml").unwrap(), b"inside");
        assert_eq!(read("in.toml").unwrap(), b"inside");
        let e = read("out.toml").unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::PermissionDenied, "{e}");
    }

    /// Each prefix of `PREFIX_STEP` bytes and its multiples has the hash of those bytes,
    /// however the bytes come; the whole has the hash of all of them.
    #[test]
    fn prefix_hashes_are_the_prefixes_hashes() {
        let bytes: Vec<u8> = (0..3 * PREFIX_STEP + 12_345)
            .map(|i| (i * 7 + i / 1000) as u8)
            .collect();
        for piece in [
            1,
            4096,
            PREFIX_STEP - 1,
            PREFIX_STEP,
            PREFIX_STEP + 1,
            bytes.len(),
        ] {
            if piece == 1 && bytes.len() > PREFIX_STEP {
                // One byte at a time over 3 MiB is slow in a debug build: the first 1 MiB + 1.
                let mut h = ContentHash::new();
                for b in bytes[..PREFIX_STEP + 1].chunks(1) {
                    h.update(b);
                }
                assert_eq!(h.prefixes(), [hash_bytes(&bytes[..PREFIX_STEP])]);
                continue;
            }
            let mut h = ContentHash::new();
            for b in bytes.chunks(piece) {
                h.update(b);
            }
            let want: Vec<u64> = (1..=3)
                .map(|k| hash_bytes(&bytes[..k * PREFIX_STEP]))
                .collect();
            assert_eq!(h.prefixes(), want, "pieces of {piece}");
            assert_eq!(h.finish(), hash_bytes(&bytes), "pieces of {piece}");
        }
    }

    #[test]
    fn a_file_hashes_like_its_bytes() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("f");
        // More than one piece, and a piece boundary inside.
        let bytes: Vec<u8> = (0..200_000u32).map(|i| (i % 251) as u8).collect();
        std::fs::write(&p, &bytes).unwrap();
        assert_eq!(hash_file(&p, 1 << 20).unwrap(), hash_bytes(&bytes));
        assert!(hash_file(&p, 1000).is_err());
        assert!(hash_file(Path::new("/dev/zero"), 1 << 20).is_err());
        assert_ne!(hash_bytes(b"a"), hash_bytes(b"b"));
    }

    #[test]
    fn refuses_what_is_not_a_regular_file() {
        let d = tempfile::tempdir().unwrap();
        let fs = FsSource::default();
        let err = |p: &Path| fs.read(p).unwrap_err().to_string();
        assert!(err(d.path()).contains("directory"));
        assert!(err(Path::new("/dev/zero")).contains("not a regular file"));
        // A FIFO without a writer: refused at once, not waited on.
        let fifo = d.path().join("pipe.xml");
        rustix::fs::mknodat(
            rustix::fs::CWD,
            &fifo,
            rustix::fs::FileType::Fifo,
            rustix::fs::Mode::from_raw_mode(0o600),
            0,
        )
        .unwrap();
        let t = std::time::Instant::now();
        assert!(err(&fifo).contains("not a regular file"));
        assert!(t.elapsed() < std::time::Duration::from_secs(1));
        // Size limit.
        let big = d.path().join("big.xml");
        std::fs::write(&big, vec![b'a'; 100]).unwrap();
        let small = FsSource { max_file_size: 10 };
        assert!(small.read(&big).unwrap_err().to_string().contains("limit"));
        assert_eq!(FsSource::default().read(&big).unwrap().len(), 100);
    }
}
