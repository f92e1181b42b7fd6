//! The SFC's text is freed once the model is read (it is the largest input by far) and read
//! again only for diagnostics that point into it (`compile.rs`). Through the library's
//! `compile` with a file source that counts reads and can change the file between them.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use skillpost::compile::{Options, compile};
use skillpost::load::{FileSource, FsSource};

/// Reads from disk, except the SFC: its first reading gets `first` (the file on disk when
/// `None`), later ones `second` (a save in between; `first` again when `None`). The readings of
/// the SFC are counted, and the bytes the later ones took.
#[derive(Default)]
struct Source {
    fs: FsSource,
    first: Option<Vec<u8>>,
    second: Option<Vec<u8>>,
    sfc_reads: Mutex<usize>,
    second_bytes: std::sync::Arc<std::sync::atomic::AtomicUsize>,
}

impl Source {
    fn with(first: Option<Vec<u8>>, second: Option<Vec<u8>>) -> Self {
        Source {
            first,
            second,
            ..Default::default()
        }
    }

    /// The SFC's bytes for its next reading, and whether it is a later one.
    fn sfc(&self, path: &Path) -> std::io::Result<(Vec<u8>, bool)> {
        let mut n = self.sfc_reads.lock().unwrap();
        *n += 1;
        let bytes = match (&self.first, &self.second, *n) {
            (_, Some(b), 2..) | (Some(b), _, _) => b.clone(),
            _ => self.fs.read(path)?,
        };
        Ok((bytes, *n > 1))
    }

    fn second_bytes(&self) -> usize {
        self.second_bytes.load(std::sync::atomic::Ordering::Relaxed)
    }
}

fn is_sfc(path: &Path) -> bool {
    path.file_name().is_some_and(|n| n == "sfc.xml")
}

impl FileSource for Source {
    fn real_path(&self, path: &Path) -> Option<PathBuf> {
        self.fs.real_path(path)
    }

    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        if is_sfc(path) {
            return self.sfc(path).map(|(b, _)| b);
        }
        self.fs.read(path)
    }

    fn open(&self, path: &Path) -> std::io::Result<skillpost::load::Opened<'_>> {
        if !is_sfc(path) {
            return self.fs.open(path);
        }
        let (bytes, later) = self.sfc(path)?;
        let counted = if later {
            self.second_bytes.clone()
        } else {
            std::sync::Arc::default()
        };
        Ok(skillpost::load::Opened {
            len: Some(bytes.len() as u64),
            reader: Box::new(Counting {
                inner: std::io::Cursor::new(bytes),
                n: counted,
            }),
            // Read as one stream: what is counted is what the stream gives.
            at: None,
        })
    }
}

/// A reader that counts what is read through it.
struct Counting<R> {
    inner: R,
    n: std::sync::Arc<std::sync::atomic::AtomicUsize>,
}

impl<R: std::io::Read> std::io::Read for Counting<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.n.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
        Ok(n)
    }
}

/// Compiles from disk; also says how often the SFC was read.
fn compile_counting(blackboard: &Path, opts: &Options) -> (skillpost::compile::Compilation, usize) {
    let src = Source::default();
    let c = compile(&src, blackboard, opts);
    let reads = *src.sfc_reads.lock().unwrap();
    (c, reads)
}

fn case() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/err/e314_missing_variable")
}

/// Compiles the e314 case (program `out`) with its files from `src`.
fn compile_case(src: &dyn FileSource) -> skillpost::compile::Compilation {
    compile(
        src,
        &case().join("Blackboard.aml"),
        &Options {
            program: Some("out".into()),
            ..Default::default()
        },
    )
}

fn run(second: Option<Vec<u8>>) -> (skillpost::compile::Compilation, usize) {
    let src = Source::with(None, second);
    let c = compile_case(&src);
    let n = *src.sfc_reads.lock().unwrap();
    (c, n)
}

#[test]
fn an_sfc_diagnostic_gets_its_line_from_the_text_read_again() {
    let (c, reads) = run(None);
    let d = c
        .diagnostics
        .iter()
        .find(|d| d.code.as_str() == "E314")
        .expect("E314");
    let span = d.span.as_ref().expect("located");
    assert_eq!(c.sources.line_col(span.file, span.range.start).0, 29);
    assert_eq!(reads, 2, "read once for the model, once for the diagnostic");
    // Rendering works on the text put back.
    let text = skillpost::diag::render(
        &c.diagnostics,
        &c.sources,
        skillpost::diag::Format::Short,
        false,
        false,
    );
    assert!(text.contains("sfc.xml:29"), "{text}");
}

#[test]
fn a_compile_without_sfc_diagnostics_reads_the_sfc_once() {
    // The ABB cell: no diagnostic in the SFC (only W211 at the blackboard: its robot has no
    // tool data), so nothing to locate in it.
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/base/abb");
    let (c, reads) = compile_counting(
        &sample.join("Cell.aml"),
        &Options {
            program: Some("out".into()),
            ..Default::default()
        },
    );
    assert!(
        c.diagnostics
            .iter()
            .all(|d| d.code == skillpost::diag::Code::NoToolData),
        "{:?}",
        c.diagnostics
    );
    assert_eq!(reads, 1);
    // The model is freed unless asked for (the listings ask).
    assert!(c.sfc.is_none() && c.plan.is_none());
}

#[test]
fn an_sfc_saved_during_the_compile_loses_the_place_and_says_so() {
    let mut changed = std::fs::read(case().join("sfc.xml")).unwrap();
    changed.splice(0..0, b"<!-- saved meanwhile -->\n".iter().copied());
    let (c, _) = run(Some(changed));
    let d = c
        .diagnostics
        .iter()
        .find(|d| d.code.as_str() == "E314")
        .expect("E314 still reported");
    assert!(
        d.span.is_none(),
        "no line from a text that is not the one compiled"
    );
    assert!(
        d.notes
            .iter()
            .any(|n| n.contains("changed while it was being compiled")),
        "{:?}",
        d.notes
    );
    // It still names the file (the daemon retries a file still being written by this name).
    let at = d.locate(&c.sources);
    assert_eq!(at.file, Some(case().join("sfc.xml").display().to_string()));
    assert_eq!((at.line, at.column), (None, None));
    // And it renders.
    let _ = skillpost::diag::render(
        &c.diagnostics,
        &c.sources,
        skillpost::diag::Format::Short,
        false,
        false,
    );
}

#[test]
fn the_sfc_named_again_later_is_read_with_its_text() {
    // The template named is the SFC itself: it is parsed as what it is (XML is no TOML),
    // not as the empty text left after the SFC was read.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/base/abb");
    let c = compile(
        &FsSource::default(),
        &dir.join("Cell.aml"),
        &Options {
            program: Some("out".into()),
            template: Some(dir.join("sfc.xml")),
            ..Default::default()
        },
    );
    let e603: Vec<&str> = c
        .diagnostics
        .iter()
        .filter(|d| d.code.as_str() == "E603")
        .map(|d| d.message.as_str())
        .collect();
    // One TOML syntax error at the start of the XML, not the complaints about an empty table.
    assert_eq!(e603.len(), 1, "{e603:?}");
    assert!(e603[0].contains("expected `=`"), "{e603:?}");
}

/// The diagnostics of every error fixture render the same from the pieces of the SFC's lines
/// read again (`skillpost::excerpt`) as from its whole text: human, short and JSON, warnings
/// included.
#[test]
fn pieces_of_lines_render_like_the_whole_text() {
    use skillpost::diag::{Format, render};
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/err");
    let mut with_pieces = 0;
    let mut cases: Vec<PathBuf> = std::fs::read_dir(&root)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    cases.sort();
    for case in cases {
        let expect = std::fs::read_to_string(case.join("expect.toml")).unwrap_or_default();
        if expect.contains("base =") {
            // Its files are spread over a base folder and the case.
            continue;
        }
        let Some(bb) = std::fs::read_dir(&case)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.extension().is_some_and(|e| e == "aml"))
        else {
            continue;
        };
        let mut c = compile(
            &FsSource::default(),
            &bb,
            &Options {
                program: Some("out".into()),
                ..Default::default()
            },
        );
        let all = |c: &skillpost::compile::Compilation| {
            [Format::Human, Format::Short, Format::Json]
                .map(|f| render(&c.diagnostics, &c.sources, f, true, false))
        };
        let pieces = all(&c);
        let ids: Vec<usize> = (0..c.sources.iter().count())
            .filter(|&id| c.sources.is_dropped(id))
            .collect();
        if c.diagnostics
            .iter()
            .any(|d| d.span.as_ref().is_some_and(|s| ids.contains(&s.file)))
        {
            with_pieces += 1;
        }
        for id in ids {
            let raw = std::fs::read(&c.sources.get(id).path).unwrap();
            assert!(c.sources.restore_text(id, raw), "{}", case.display());
        }
        let whole = all(&c);
        for (p, w) in pieces.iter().zip(&whole) {
            assert_eq!(p, w, "{}", case.display());
        }
    }
    assert!(
        with_pieces >= 80,
        "only {with_pieces} cases with SFC diagnostics rendered from pieces"
    );
}

/// An SFC written as one long line: its diagnostic shows the part of the line around the place
/// (not the whole file), with the true column.
#[test]
fn a_one_line_sfc_shows_the_part_of_the_line_around_the_place() {
    let dir = tempfile::tempdir().unwrap();
    for entry in std::fs::read_dir(case()).unwrap() {
        let p = entry.unwrap().path();
        std::fs::copy(&p, dir.path().join(p.file_name().unwrap())).unwrap();
    }
    let sfc = std::fs::read_to_string(dir.path().join("sfc.xml")).unwrap();
    // Padding so the step is far from the start of its (only) line.
    let one_line = sfc.replace("\r\n", " ").replace('\n', " ").replacen(
        "<pous>",
        &format!("<pous>{}", " ".repeat(20_000)),
        1,
    );
    std::fs::write(dir.path().join("sfc.xml"), &one_line).unwrap();
    let col = one_line.find("<step localId=\"3\"").unwrap() + 1;
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["--validate", "Blackboard.aml"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains(&format!("sfc.xml:1:{col}")), "{err}");
    let shown = err
        .lines()
        .find(|l| l.starts_with("1 │"))
        .unwrap_or_else(|| panic!("the line is shown: {err}"));
    assert!(shown.contains("<step localId=\"3\""), "{shown}");
    assert!(
        shown.len() < 2 * skillpost::excerpt::WINDOW + 100,
        "{} bytes shown",
        shown.len()
    );
}

/// A run that will not show its warnings (`Options::drop_warnings`: the command line without
/// `--warn`) builds none, so it does not read the SFC again to locate them; a run that keeps them
/// does. The sample's steps carry a variable no skill reads (`W303`).
#[test]
fn warnings_not_kept_are_not_located() {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ok/reference-sample");
    let run = |drop_warnings: bool| {
        compile_counting(
            &sample.join("Blackboard.aml"),
            &Options {
                program: Some("out".into()),
                drop_warnings,
                ..Default::default()
            },
        )
    };
    let (kept, reads) = run(false);
    assert!(kept.diagnostics.iter().any(|d| d.code.as_str() == "W303"));
    assert_eq!(reads, 2, "read again for the warnings' lines");
    let (dropped, reads) = run(true);
    assert!(dropped.diagnostics.is_empty(), "{:?}", dropped.diagnostics);
    assert_eq!(reads, 1, "read once: nothing to locate");
    // The same program either way.
    let texts = |c: &skillpost::compile::Compilation| {
        c.outputs
            .iter()
            .map(|(p, f)| (p.clone(), f.text.clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(texts(&kept), texts(&dropped));
    assert!(!texts(&kept).is_empty());
}

/// The e314 case's SFC made large: a comment of 3 MiB after the root element.
fn large_sfc() -> Vec<u8> {
    let mut sfc = std::fs::read(case().join("sfc.xml")).unwrap();
    sfc.extend_from_slice(b"\n<!--");
    sfc.extend(std::iter::repeat_n(b'x', 3 << 20));
    sfc.extend_from_slice(b"-->\n");
    sfc
}

/// Compiles the e314 case with the large SFC; the E314 diagnostic and the bytes the second
/// reading took.
fn run_large(second: Option<Vec<u8>>) -> (skillpost::diag::Diagnostic, usize) {
    let src = Source::with(Some(large_sfc()), second);
    let c = compile_case(&src);
    let d = c
        .diagnostics
        .iter()
        .find(|d| d.code.as_str() == "E314")
        .expect("E314")
        .clone();
    if let Some(s) = &d.span {
        assert_eq!(c.sources.line_col(s.file, s.range.start).0, 29);
    }
    (d, src.second_bytes())
}

#[test]
fn a_large_sfc_is_read_again_only_as_far_as_its_diagnostics_lines() {
    let len = large_sfc().len();
    let (d, read_again) = run_large(None);
    assert!(d.span.is_some(), "{d:?}");
    // The first MiB holds line 29; it is read in 64 KiB pieces.
    let step = skillpost::load::PREFIX_STEP;
    assert!(
        read_again >= step && read_again <= step + 64 * 1024,
        "{read_again} of {len} bytes read again"
    );
}

#[test]
fn a_large_sfc_changed_after_its_diagnostics_lines_keeps_their_place() {
    // A save that changed the comment 2 MiB on: the lines shown are still those compiled.
    let mut changed = large_sfc();
    changed[2 << 20] = b'y';
    let (d, _) = run_large(Some(changed));
    assert!(d.span.is_some(), "{d:?}");
    assert!(
        d.notes.iter().all(|n| !n.contains("changed")),
        "{:?}",
        d.notes
    );
}

#[test]
fn a_large_sfc_changed_before_its_diagnostics_lines_loses_their_place() {
    // A save that changed the first MiB (the comment, after line 29 but inside the prefix that
    // is checked): the place is not trusted.
    let mut changed = large_sfc();
    let at = changed.len() - (3 << 20) + 1000;
    assert!(at < skillpost::load::PREFIX_STEP);
    changed[at] = b'y';
    let (d, read_again) = run_large(Some(changed));
    assert!(d.span.is_none(), "{d:?}");
    assert!(
        d.notes
            .iter()
            .any(|n| n.contains("changed while it was being compiled")),
        "{:?}",
        d.notes
    );
    assert!(read_again < large_sfc().len());
}
