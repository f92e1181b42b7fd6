//! Reading a project's files for one compile: every file through the [`FileSource`], recorded
//! (what the daemon watches) and held to the whole-files budget; `refURI`s resolved and kept
//! inside the project; the SFC streamed; a file read again for the lines a diagnostic shows.

use super::*;

/// Records every path asked for, and keeps the files read whole within
/// [`crate::load::WHOLE_FILES_BUDGET`] together.
pub(super) struct Recorder<'a> {
    pub(super) fs: &'a dyn FileSource,
    /// The paths asked for, in the order first asked.
    pub(super) read: std::cell::RefCell<Vec<PathBuf>>,
    /// The same paths as a set: a project of thousands of IRL files must not search the list
    /// once per read.
    pub(super) seen: std::cell::RefCell<std::collections::HashSet<PathBuf>>,
    /// Bytes read whole so far.
    pub(super) whole: std::cell::Cell<u64>,
}

impl FileSource for Recorder<'_> {
    fn real_path(&self, path: &Path) -> Option<PathBuf> {
        self.fs.real_path(path)
    }

    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        self.record(path);
        let left = crate::load::WHOLE_FILES_BUDGET.saturating_sub(self.whole.get());
        let bytes = self.fs.read_max(path, left)?;
        self.whole.set(self.whole.get() + bytes.len() as u64);
        Ok(bytes)
    }

    fn open(&self, path: &Path) -> std::io::Result<crate::load::Opened<'_>> {
        self.record(path);
        self.fs.open(path)
    }
}

impl Recorder<'_> {
    pub(super) fn record(&self, path: &Path) {
        let mut seen = self.seen.borrow_mut();
        if !seen.contains(path) {
            seen.insert(path.to_owned());
            self.read.borrow_mut().push(path.to_owned());
        }
    }
}

pub(super) struct Ctx<'a> {
    pub(super) fs: Recorder<'a>,
    pub(super) sources: Sources,
    pub(super) diags: Diagnostics,
    pub(super) base: PathBuf,
    pub(super) confine: Option<PathBuf>,
    /// Every file a `refURI` named, with the reference (for [`check_outputs`]).
    pub(super) refs: Vec<(PathBuf, Span)>,
}

impl<'a> Ctx<'a> {
    pub(super) fn new(fs: &'a dyn FileSource, base: PathBuf, confine: Option<PathBuf>) -> Self {
        Ctx {
            fs: Recorder {
                fs,
                read: Default::default(),
                seen: Default::default(),
                whole: Default::default(),
            },
            sources: Sources::default(),
            diags: Diagnostics::default(),
            base,
            confine,
            refs: Vec::new(),
        }
    }

    /// Loads a file the command names (the blackboard, the SFC with `--sfc`, the template). When it
    /// cannot be read at all, that is an I/O failure (exit status 2), not an input error.
    pub(super) fn load_top(
        &mut self,
        path: &Path,
        out: &mut Compilation,
    ) -> Option<crate::diag::FileId> {
        let file = xml::load(
            &self.fs,
            path,
            path.display().to_string(),
            None,
            &mut self.sources,
            &mut self.diags,
        );
        if file.is_none() {
            out.io_failure = self.sources.find(path).is_none();
        }
        self.with_text(file?, None)
    }

    /// Whether `path` stays inside `root`: by its text, and, where the file system can tell,
    /// with symbolic links resolved (a link inside the folder pointing out of it leaves it).
    pub(super) fn inside(&self, path: &Path, root: &Path) -> bool {
        paths::stays_inside(path, root, |p| self.fs.real_path(p))
    }

    /// Resolves a `refURI` and loads the file; errors are located at the reference.
    pub(super) fn load_ref(&mut self, value: &str, at: &Span) -> Option<crate::diag::FileId> {
        let path = self.ref_path(value, at)?;
        let display = path.display().to_string();
        let file = xml::load(
            &self.fs,
            &path,
            display,
            Some(at.clone()),
            &mut self.sources,
            &mut self.diags,
        )?;
        self.with_text(file, Some(at))
    }

    /// The file a `refURI` names, recorded as an input; `None` (reported) when it is malformed
    /// or leaves the project folder.
    pub(super) fn ref_path(&mut self, value: &str, at: &Span) -> Option<PathBuf> {
        let path = match paths::resolve_ref(&self.base, value) {
            Ok(p) => p,
            Err(why) => {
                self.diags.push(
                    Diagnostic::error(Code::BadRefUri, format!("bad refURI: {why}")).at(at.clone()),
                );
                return None;
            }
        };
        if let Some(root) = &self.confine
            && !self.inside(&path, root)
        {
            self.diags.push(
                Diagnostic::error(
                    Code::BadRefUri,
                    format!(
                        "refURI `{value}` leaves the project folder `{}`; the configuration does not allow that",
                        root.display()
                    ),
                )
                .at(at.clone()),
            );
            return None;
        }
        self.refs.push((path.clone(), at.clone()));
        Some(path)
    }

    /// Reads the SFC at `path` as a stream: its text is never whole in memory (100,000 steps
    /// make 78 MB), only the model is kept. `origin`: the `refURI` naming it. The file's length
    /// and hash are kept, so its text can be read again, and checked to be the same, for the
    /// diagnostics that point into it. A file already read (named before as another input) is
    /// read from its text.
    pub(super) fn read_sfc(
        &mut self,
        path: &Path,
        origin: Option<&Span>,
        pou: Option<&str>,
        out: &mut Compilation,
    ) -> (Option<crate::diag::FileId>, Option<Sfc>) {
        use std::io::BufRead as _;
        if let Some(file) = self.sources.find(path) {
            let Some(file) = self.with_text(file, origin) else {
                return (None, None);
            };
            return (
                Some(file),
                read_sfc_pou(&self.sources, file, pou, &mut self.diags),
            );
        }
        let display = path.display().to_string();
        let opened = match self.fs.open(path) {
            Ok(o) => o,
            Err(e) => {
                self.diags
                    .push(xml::unreadable(&display, path, origin.cloned(), &e));
                out.io_failure = origin.is_none();
                return (None, None);
            }
        };
        let file = self.sources.add_streamed(path.to_owned(), display.clone());
        /// Counts and hashes the bytes as they pass.
        struct Fingerprint<R> {
            inner: R,
            len: usize,
            hash: crate::load::ContentHash,
        }
        impl<R: std::io::Read> std::io::Read for Fingerprint<R> {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                let n = self.inner.read(buf)?;
                self.len += n;
                self.hash.update(&buf[..n]);
                Ok(n)
            }
        }
        let (read, rest, bom) = {
            let mut fp = Fingerprint {
                inner: opened.reader,
                len: 0,
                hash: crate::load::ContentHash::new(),
            };
            let mut input = std::io::BufReader::with_capacity(64 * 1024, &mut fp);
            let bom = match input.fill_buf() {
                Ok(head) => head.starts_with(b"\xEF\xBB\xBF"),
                Err(_) => false,
            };
            if bom {
                input.consume(3);
            }
            let len_hint = opened
                .len
                .unwrap_or(0)
                .saturating_sub(if bom { 3 } else { 0 });
            // A large file is read in two halves at once, the second through a reader of the
            // same open file (`read/sfc/split.rs`).
            let at = opened.at.as_deref().map(|a| (a, if bom { 3 } else { 0 }));
            let read = crate::read::sfc::read_sfc_file(
                &mut input,
                at,
                file,
                len_hint,
                pou,
                &mut self.diags,
            );
            // The rest of the file, so its length and hash are the whole file's (the reader
            // stops at a syntax error; the daemon's hash of an input is taken at its end).
            let rest = std::io::copy(&mut input, &mut std::io::sink());
            drop(input);
            let prefixes = fp.hash.prefixes().to_vec();
            self.sources
                .streamed(file, bom, fp.len, fp.hash.finish(), prefixes);
            (read, rest, bom)
        };
        let failed = match (read, rest) {
            (Ok(sfc), Ok(_)) => return (Some(file), sfc),
            (Err(crate::read::sfc::StreamError::NotUtf8), Ok(_)) => None,
            (Err(crate::read::sfc::StreamError::Io(e)), _) | (_, Err(e)) => Some(e),
        };
        match failed {
            Some(e) => {
                self.diags
                    .push(xml::unreadable(&display, path, origin.cloned(), &e));
            }
            None => {
                // Not UTF-8: located like the loader does, at the first bad byte of the text
                // read again (when it is still the same).
                let at = self.fs.read(path).ok().and_then(|raw| {
                    let skip = if bom { 3 } else { 0 };
                    let valid = std::str::from_utf8(raw.get(skip..)?)
                        .err()
                        .map(|e| e.valid_up_to());
                    self.sources
                        .restore_text(file, raw)
                        .then_some(valid)
                        .flatten()
                });
                self.diags.push(xml::not_utf8(&display, file, at));
            }
        }
        (Some(file), None)
    }

    /// `file` with its text: a file read before whose text was dropped (the SFC named again,
    /// as an IRL file or the template) is read again, or is an error when it changed meanwhile.
    pub(super) fn with_text(
        &mut self,
        file: crate::diag::FileId,
        at: Option<&Span>,
    ) -> Option<crate::diag::FileId> {
        if self.sources.is_dropped(file) && !self.reload(file) {
            self.diags.push(
                Diagnostic::error(
                    Code::FileUnreadable,
                    format!(
                        "`{}` changed while it was being compiled; run again",
                        self.sources.get(file).display
                    ),
                )
                .at_opt(at.cloned()),
            );
            return None;
        }
        Some(file)
    }

    /// Reads a file whose text was not kept again and puts the text back if it is the same.
    pub(super) fn reload(&mut self, file: crate::diag::FileId) -> bool {
        let path = self.sources.get(file).path.clone();
        match self.fs.read(&path) {
            Ok(bytes) => self.sources.restore_text(file, bytes),
            Err(_) => false,
        }
    }

    /// Reads again the lines of every file whose text was not kept (the SFC) that a diagnostic
    /// points into ([`crate::excerpt`]: only those lines are kept, never the whole text), so the
    /// diagnostics render with their lines. When a file changed meanwhile (another length or
    /// hash), its diagnostics lose their place and say so.
    pub(super) fn restore_for_diagnostics(&mut self) {
        let mut places: Vec<(crate::diag::FileId, usize)> = self
            .diags
            .iter()
            .flat_map(|d| d.span.iter().chain(d.related.iter().map(|(s, _)| s)))
            .filter(|s| self.sources.needs_lines(s.file))
            .map(|s| (s.file, s.range.start))
            .collect();
        places.sort_unstable();
        for group in places.chunk_by(|a, b| a.0 == b.0) {
            let f = group[0].0;
            let offsets = group.iter().map(|p| p.1).collect();
            if !self.read_lines(f, offsets) {
                let file = self.sources.get(f);
                self.diags.forget_file(f, &file.path, &file.display);
            }
        }
    }

    /// Reads file `f` again as a stream, keeping the lines around `places`; `false` when it
    /// cannot be read or is not the same as the first time. It reads only as far as the lines
    /// and up to the next whole MiB ([`crate::load::PREFIX_STEP`]) when that prefix is the one
    /// compiled (its hash): a diagnostic near the start of a 78 MB SFC does not read it all.
    pub(super) fn read_lines(&mut self, f: crate::diag::FileId, places: Vec<usize>) -> bool {
        use crate::load::PREFIX_STEP;
        let path = self.sources.get(f).path.clone();
        let Ok(opened) = self.fs.open(&path) else {
            return false;
        };
        let mut reader = opened.reader;
        let mut collector = crate::excerpt::Collector::new(places, self.sources.bom(f));
        let mut buf = vec![0u8; 64 * 1024];
        // Once the lines are kept: how many prefixes of `PREFIX_STEP` bytes cover them.
        let mut need: Option<usize> = None;
        loop {
            match reader.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => collector.feed(&buf[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(_) => return false,
            }
            if need.is_none() && collector.done() {
                need = Some(collector.fed().div_ceil(PREFIX_STEP).max(1));
            }
            if let Some(k) = need
                && let Some(&prefix) = collector.prefixes().get(k - 1)
            {
                let c = collector.finish();
                return self.sources.set_excerpts_prefix(f, c.excerpts, k, prefix);
            }
        }
        self.sources.set_excerpts(f, collector.finish())
    }
}
