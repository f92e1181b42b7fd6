//! The texts diagnostics point into: every file a compile read, line and column of a byte
//! offset, and for a file read as a stream the lines that diagnostics need, read again.

use std::path::{Path, PathBuf};

use super::FileId;

/// Every text the compiler read, so diagnostics can point into it.
#[derive(Debug, Default)]
pub struct Sources {
    pub(super) files: Vec<SourceFile>,
    /// The first file read from each path: [`Sources::find`] without a scan of every file (a
    /// project of thousands of IRL files looked each one up in all before).
    pub(super) by_path: std::collections::HashMap<PathBuf, FileId>,
}

/// One file's text as it was read (a UTF-8 byte order mark is stripped, `bom` records it).
#[derive(Debug)]
pub struct SourceFile {
    /// The path the file was read from.
    pub path: PathBuf,
    /// The path as shown in diagnostics (relative to the working directory where possible).
    pub display: String,
    /// The text after the BOM.
    pub text: String,
    /// Whether the file started with a UTF-8 BOM.
    pub bom: bool,
    /// Byte offsets of line starts, computed on the first diagnostic that needs them.
    pub(super) line_starts: std::sync::OnceLock<Vec<usize>>,
    /// Set while the text is not kept (a streamed file): its length and content hash.
    pub(super) dropped: Option<(usize, u64)>,
    /// For a file whose text is not kept: the lines that diagnostics point into.
    pub(super) excerpts: Option<crate::excerpt::Excerpts>,
    /// For a streamed file: [`crate::load::ContentHash::prefixes`] of the bytes read.
    pub(super) prefixes: Vec<u64>,
}

impl SourceFile {
    pub(super) fn line_starts(&self) -> &[usize] {
        self.line_starts.get_or_init(|| {
            std::iter::once(0)
                .chain(memchr::memchr_iter(b'\n', self.text.as_bytes()).map(|i| i + 1))
                .collect()
        })
    }
}

impl Sources {
    /// Adds a file and returns its id.
    pub fn add(&mut self, path: PathBuf, display: String, text: String, bom: bool) -> FileId {
        let id = self.files.len();
        self.by_path.entry(path.clone()).or_insert(id);
        self.files.push(SourceFile {
            path,
            display,
            text,
            bom,
            dropped: None,
            excerpts: None,
            prefixes: Vec::new(),
            line_starts: std::sync::OnceLock::new(),
        });
        self.files.len() - 1
    }

    /// The file with this id.
    pub fn get(&self, id: FileId) -> &SourceFile {
        &self.files[id]
    }

    /// Adds a file whose text is read as a stream and not kept (the SFC): no text until
    /// [`Sources::streamed`] records what was read and [`Sources::restore_text`] puts the same
    /// bytes back for diagnostics that point into it.
    pub fn add_streamed(&mut self, path: PathBuf, display: String) -> FileId {
        let id = self.add(path, display, String::new(), false);
        self.files[id].dropped = Some((0, 0));
        id
    }

    /// A streamed file was read to its end: whether it had a byte-order mark, its length and
    /// [`crate::load::hash_bytes`] of its bytes (the mark included), and of each prefix of
    /// [`crate::load::PREFIX_STEP`] bytes and its multiples.
    pub fn streamed(&mut self, id: FileId, bom: bool, len: usize, hash: u64, prefixes: Vec<u64>) {
        let f = &mut self.files[id];
        f.bom = bom;
        f.dropped = Some((len, hash));
        f.prefixes = prefixes;
    }

    /// Whether the file's text is not there (streamed, or dropped) and not put back.
    pub fn is_dropped(&self, id: FileId) -> bool {
        self.files[id].dropped.is_some()
    }

    /// Whether the file's text is not there and neither are the lines its diagnostics need.
    pub fn needs_lines(&self, id: FileId) -> bool {
        self.files[id].dropped.is_some() && self.files[id].excerpts.is_none()
    }

    /// The pieces of lines kept for a file whose text is not (see [`Sources::set_excerpts`]).
    pub fn excerpts(&self, id: FileId) -> Option<&crate::excerpt::Excerpts> {
        self.files[id].excerpts.as_ref()
    }

    /// Whether the file has the byte-order mark (known once it was read).
    pub fn bom(&self, id: FileId) -> bool {
        self.files[id].bom
    }

    /// Gives a file whose text is not kept the lines its diagnostics point into, read again
    /// ([`crate::excerpt::Collector`]): `true` when the bytes read were the same as the first
    /// time (length and hash), else the file stays without them.
    pub fn set_excerpts(&mut self, id: FileId, c: crate::excerpt::Collected) -> bool {
        let f = &mut self.files[id];
        match f.dropped {
            Some((len, hash)) if c.len == len && c.hash == hash => {
                f.excerpts = Some(c.excerpts);
                true
            }
            _ => false,
        }
    }

    /// Like [`Sources::set_excerpts`] for lines read from only the first `k` prefixes of
    /// [`crate::load::PREFIX_STEP`] bytes, whose hash is `prefix`: `true` when that prefix is
    /// the one read the first time (the file was at least that long and had the same bytes
    /// there), else the file stays without them.
    pub fn set_excerpts_prefix(
        &mut self,
        id: FileId,
        excerpts: crate::excerpt::Excerpts,
        k: usize,
        prefix: u64,
    ) -> bool {
        let f = &mut self.files[id];
        match (f.dropped, k.checked_sub(1).and_then(|i| f.prefixes.get(i))) {
            (Some(_), Some(&h)) if h == prefix => {
                f.excerpts = Some(excerpts);
                true
            }
            _ => false,
        }
    }

    /// Puts a streamed file's text back from the file's bytes `raw`, read again: `true` when
    /// they are the bytes that were read (same length and hash), else the file stays without
    /// text. Bytes that are not UTF-8 are put back with replacement characters (their
    /// diagnostic points at the first bad byte, which keeps its offset).
    pub fn restore_text(&mut self, id: FileId, mut raw: Vec<u8>) -> bool {
        let f = &mut self.files[id];
        match f.dropped {
            Some((len, hash)) if raw.len() == len && crate::load::hash_bytes(&raw) == hash => {
                let bom = crate::load::strip_bom(&mut raw);
                if bom != f.bom {
                    return false;
                }
                f.text = match String::from_utf8(raw) {
                    Ok(t) => t,
                    Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
                };
                f.dropped = None;
                f.excerpts = None;
                f.line_starts = std::sync::OnceLock::new();
                true
            }
            _ => false,
        }
    }

    /// All files, in the order they were read.
    pub fn iter(&self) -> impl Iterator<Item = &SourceFile> {
        self.files.iter()
    }

    /// Finds a file already read from `path`.
    pub fn find(&self, path: &Path) -> Option<FileId> {
        self.by_path.get(path).copied()
    }

    /// `path` as diagnostics show it: the name of the file read from it, else the path itself
    /// (a diagnostic without a place names its file as those with one do).
    pub fn display_of(&self, path: &Path) -> String {
        match self.find(path) {
            Some(id) => self.files[id].display.clone(),
            None => path.display().to_string(),
        }
    }

    /// 1-based line and column (in characters) of a byte offset.
    pub fn line_col(&self, id: FileId, offset: usize) -> (usize, usize) {
        let f = &self.files[id];
        if let Some(x) = &f.excerpts {
            // Every place a diagnostic names was kept (`Diagnostics::snap`).
            return x.line_col(offset).unwrap_or((1, 1));
        }
        let offset = offset.min(f.text.len());
        let starts = f.line_starts();
        let line = match starts.binary_search(&offset) {
            Ok(l) => l,
            Err(l) => l - 1,
        };
        let start = starts[line];
        let col = f
            .text
            .get(start..offset)
            .map(|s| s.chars().count())
            .unwrap_or(offset - start);
        (line + 1, col + 1)
    }

    /// Byte offset of a 1-based line and column (as roxmltree reports them).
    pub fn offset_of(&self, id: FileId, line: usize, col: usize) -> usize {
        let f = &self.files[id];
        let Some(&start) = f.line_starts().get(line.saturating_sub(1)) else {
            return f.text.len();
        };
        let rest = &f.text[start..];
        rest.char_indices()
            .nth(col.saturating_sub(1))
            .map(|(i, _)| start + i)
            .unwrap_or(f.text.len())
    }
}
