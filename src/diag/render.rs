//! How diagnostics are shown: `human` (codespan-reporting, with the source line), `short` (one
//! line each) and `json` (one [`Located`] object per line).

use std::fmt::Write as _;
use std::ops::Range;

use serde::Serialize;

use super::{Diagnostic, FileId, Severity, Sources};

/// How diagnostics are printed (`--format`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Format {
    /// `error[CODE]: message`, the place, the source line and a marker.
    #[default]
    Human,
    /// One line each: `file:line:column: error[CODE]: message`.
    Short,
    /// One JSON object per line.
    Json,
}

/// A diagnostic with its place resolved to file name, line and column: what JSON output and the
/// daemon's events carry.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Located {
    pub severity: Severity,
    pub code: &'static str,
    pub message: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub column: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub element: Option<String>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl Diagnostic {
    /// Resolves the place to file, line and column.
    pub fn locate(&self, sources: &Sources) -> Located {
        let (file, line, column) = match &self.span {
            Some(s) => {
                let (l, c) = sources.line_col(s.file, s.range.start);
                (Some(sources.get(s.file).display.clone()), Some(l), Some(c))
            }
            None => (
                self.path.as_ref().map(|p| sources.display_of(p)),
                None,
                None,
            ),
        };
        let mut notes = self.notes.clone();
        for (span, msg) in &self.related {
            let (l, c) = sources.line_col(span.file, span.range.start);
            notes.push(format!(
                "{}:{}:{}: {}",
                sources.get(span.file).display,
                l,
                c,
                msg
            ));
        }
        Located {
            severity: self.severity,
            code: self.code.as_str(),
            message: self.message.clone(),
            file,
            line,
            column,
            element: self.element.clone(),
            notes,
        }
    }
}

/// Renders diagnostics in the chosen format. Warnings are left out unless `warnings` is set.
pub fn render(
    diags: &[Diagnostic],
    sources: &Sources,
    format: Format,
    warnings: bool,
    color: bool,
) -> String {
    let mut out = String::new();
    let shown = diags
        .iter()
        .filter(|d| warnings || d.severity == Severity::Error);
    match format {
        Format::Json => {
            for d in shown {
                let l = d.locate(sources);
                out.push_str(&serde_json::to_string(&l).expect("a Located always serialises"));
                out.push('\n');
            }
        }
        Format::Short => {
            for d in shown {
                let l = d.locate(sources);
                let place = match (&l.file, l.line, l.column) {
                    (Some(f), Some(line), Some(col)) => format!("{f}:{line}:{col}: "),
                    (Some(f), _, _) => format!("{f}: "),
                    _ => String::new(),
                };
                let elem = l
                    .element
                    .as_ref()
                    .map(|e| format!(" [{e}]"))
                    .unwrap_or_default();
                let _ = writeln!(
                    out,
                    "{place}{}[{}]: {}{elem}",
                    severity_word(l.severity),
                    l.code,
                    l.message
                );
            }
        }
        Format::Human => {
            use codespan_reporting::diagnostic as cs;
            use codespan_reporting::term;
            let files = RenderFiles::new(sources);
            let config = term::Config::default();
            let mut buf: Vec<u8> = Vec::new();
            for d in shown {
                let mut c = match d.severity {
                    Severity::Error => cs::Diagnostic::error(),
                    Severity::Warning => cs::Diagnostic::warning(),
                }
                .with_code(d.code.as_str())
                .with_message(&d.message);
                let mut labels = Vec::new();
                if let Some(s) = &d.span {
                    let end = s.range.end.max(s.range.start);
                    let label = cs::Label::primary(s.file, files.range(s.file, s.range.start..end));
                    labels.push(match &d.element {
                        Some(e) => label.with_message(e.clone()),
                        None => label,
                    });
                }
                for (s, m) in &d.related {
                    labels.push(
                        cs::Label::secondary(s.file, files.range(s.file, s.range.clone()))
                            .with_message(m),
                    );
                }
                let mut notes = d.notes.clone();
                if d.span.is_none() {
                    if let Some(p) = &d.path {
                        notes.insert(0, format!("file: {}", sources.display_of(p)));
                    }
                    if let Some(e) = &d.element {
                        notes.push(format!("element: {e}"));
                    }
                }
                c = c.with_labels(labels).with_notes(notes);
                let r = if color {
                    let mut w = term::termcolor::Ansi::new(&mut buf);
                    term::emit_to_write_style(&mut w, &config, &files, &c)
                } else {
                    let mut w = term::termcolor::NoColor::new(&mut buf);
                    term::emit_to_write_style(&mut w, &config, &files, &c)
                };
                if r.is_err() {
                    // A span outside its file (a bug, never input): fall back to the message.
                    use std::io::Write as _;
                    let _ = writeln!(
                        buf,
                        "{}[{}]: {}",
                        severity_word(d.severity),
                        d.code,
                        d.message
                    );
                }
            }
            out.push_str(&String::from_utf8_lossy(&buf));
        }
    }
    out
}

/// The files as the renderer sees them. A file whose text is not kept shows the pieces of its
/// lines that were read again ([`crate::excerpt`]) one after another: to the renderer each piece
/// is a line of its own (a long line may have two), shown with its real line number and
/// columns; offsets into such a file go through [`RenderFiles::range`].
struct RenderFiles<'a> {
    sources: &'a Sources,
    /// Per file with pieces: their texts joined by line breaks, and per piece where it starts
    /// in that text and the line index the renderer knows it by.
    joined: Vec<Option<Joined>>,
}

/// The pieces of a file as one text.
struct Joined {
    text: String,
    starts: Vec<usize>,
    /// Grows by one from a piece to the piece of the next line, and by three across a gap (or
    /// between two pieces of one line), so the renderer marks the gap (`·`) instead of asking
    /// for a line that was not kept.
    index: Vec<usize>,
}

impl<'a> RenderFiles<'a> {
    fn new(sources: &'a Sources) -> Self {
        let joined = sources
            .files
            .iter()
            .map(|f| {
                let x = f.excerpts.as_ref()?;
                let mut j = Joined {
                    text: String::new(),
                    starts: Vec::with_capacity(x.pieces().len()),
                    index: Vec::with_capacity(x.pieces().len()),
                };
                let mut prev: Option<(usize, usize)> = None;
                for e in x.pieces() {
                    j.starts.push(j.text.len());
                    j.text.push_str(&e.text);
                    j.text.push('\n');
                    let index = match prev {
                        None => 0,
                        Some((line, index)) if e.line == line + 1 => index + 1,
                        Some((_, index)) => index + 3,
                    };
                    j.index.push(index);
                    prev = Some((e.line, index));
                }
                Some(j)
            })
            .collect();
        RenderFiles { sources, joined }
    }

    /// The pieces of `file`, if its text is not kept.
    fn pieces(&self, file: FileId) -> Option<(&[crate::excerpt::Excerpt], &Joined)> {
        let x = self.sources.files[file].excerpts.as_ref()?;
        Some((x.pieces(), self.joined[file].as_ref()?))
    }

    /// The piece the renderer knows by line index `index`.
    fn piece_of(&self, file: FileId, index: usize) -> Option<(&crate::excerpt::Excerpt, usize)> {
        let (pieces, j) = self.pieces(file)?;
        let i = j.index.binary_search(&index).ok()?;
        Some((&pieces[i], i))
    }

    /// A range of the file as a range of what [`codespan_reporting::files::Files::source`]
    /// gives (`Diagnostics::snap` put it inside one piece).
    fn range(&self, file: FileId, r: Range<usize>) -> Range<usize> {
        let Some((pieces, j)) = self.pieces(file) else {
            return r;
        };
        let x = self.sources.files[file]
            .excerpts
            .as_ref()
            .expect("has pieces");
        match x.find_index(r.start) {
            Some(i) => {
                let start = j.starts[i] + (r.start - pieces[i].start);
                start..start + (r.end - r.start)
            }
            None => 0..0,
        }
    }
}

impl<'a> codespan_reporting::files::Files<'a> for RenderFiles<'a> {
    type FileId = FileId;
    type Name = &'a str;
    type Source = &'a str;

    fn name(&'a self, id: FileId) -> Result<&'a str, codespan_reporting::files::Error> {
        Ok(self.sources.files[id].display.as_str())
    }

    fn source(&'a self, id: FileId) -> Result<&'a str, codespan_reporting::files::Error> {
        Ok(match &self.joined[id] {
            Some(j) => j.text.as_str(),
            None => self.sources.files[id].text.as_str(),
        })
    }

    /// For a file of pieces: the piece's index.
    fn line_index(
        &'a self,
        id: FileId,
        byte_index: usize,
    ) -> Result<usize, codespan_reporting::files::Error> {
        if let Some((_, j)) = self.pieces(id) {
            let i = j
                .starts
                .partition_point(|&s| s <= byte_index)
                .saturating_sub(1);
            return Ok(j.index.get(i).copied().unwrap_or(0));
        }
        let starts = self.sources.files[id].line_starts();
        Ok(starts
            .partition_point(|&s| s <= byte_index)
            .saturating_sub(1))
    }

    fn line_number(
        &'a self,
        id: FileId,
        line_index: usize,
    ) -> Result<usize, codespan_reporting::files::Error> {
        Ok(match self.pieces(id) {
            Some(_) => self.piece_of(id, line_index).map_or(0, |(e, _)| e.line) + 1,
            None => line_index + 1,
        })
    }

    fn column_number(
        &'a self,
        id: FileId,
        line_index: usize,
        byte_index: usize,
    ) -> Result<usize, codespan_reporting::files::Error> {
        let source = self.source(id)?;
        let range = self.line_range(id, line_index)?;
        let col0 = self.piece_of(id, line_index).map_or(0, |(e, _)| e.col0);
        let before = source
            .get(range.start..byte_index.clamp(range.start, range.end))
            .map_or(0, |s| s.chars().count());
        Ok(col0 + before + 1)
    }

    fn line_range(
        &'a self,
        id: FileId,
        line_index: usize,
    ) -> Result<Range<usize>, codespan_reporting::files::Error> {
        use codespan_reporting::files::Error;
        if let Some((_, j)) = self.pieces(id) {
            let (_, i) = self.piece_of(id, line_index).ok_or(Error::LineTooLarge {
                given: line_index,
                max: j.index.last().copied().unwrap_or(0),
            })?;
            return Ok(j.starts[i]..j.starts.get(i + 1).copied().unwrap_or(j.text.len()));
        }
        let f = &self.sources.files[id];
        let (starts, len) = (f.line_starts(), f.text.len());
        let start = *starts.get(line_index).ok_or(Error::LineTooLarge {
            given: line_index,
            max: starts.len().saturating_sub(1),
        })?;
        Ok(start..starts.get(line_index + 1).copied().unwrap_or(len))
    }
}

fn severity_word(s: Severity) -> &'static str {
    match s {
        Severity::Error => "error",
        Severity::Warning => "warning",
    }
}
