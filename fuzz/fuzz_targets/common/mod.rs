//! Helpers shared by the fuzz targets (each target includes this file as a module).
#![allow(dead_code)]

use std::path::Path;

use skillpost::diag::{self, Diagnostic, Diagnostics, FileId, Format, Sources};
use skillpost::load::MemSource;
use skillpost::read::xml;

/// Loads `bytes` as the file `path` the way the compiler does (BOM stripped, UTF-8 checked).
pub fn load(path: &str, bytes: &[u8]) -> (Sources, Diagnostics, Option<FileId>) {
    let mut fs = MemSource::default();
    fs.insert(path, bytes.to_vec());
    let mut sources = Sources::default();
    let mut diags = Diagnostics::default();
    let file = xml::load(
        &fs,
        Path::new(path),
        path.to_owned(),
        None,
        &mut sources,
        &mut diags,
    );
    (sources, diags, file)
}

/// Every span points into its file and starts on a character boundary (the line/column code
/// relies on it; `diag::render` only falls back silently on a span outside its file). A span's
/// end may cut a character: one-byte markers such as the E101 "not UTF-8" span (one byte of the
/// three-byte U+FFFD in the lossy text) do, and codespan renders them fine.
pub fn check_spans(diags: &[Diagnostic], sources: &Sources) {
    for d in diags {
        let spans = d.span.iter().chain(d.related.iter().map(|(s, _)| s));
        for s in spans {
            if let Some(x) = sources.excerpts(s.file) {
                // A file whose text is not kept (the streamed SFC): inside a piece of a line.
                let piece = x
                    .find(s.range.start)
                    .unwrap_or_else(|| panic!("span {:?} in no piece kept: {d:?}", s.range));
                let (start, end) = (s.range.start - piece.start, s.range.end - piece.start);
                assert!(
                    start <= end && end <= piece.text.len(),
                    "span {:?} outside its piece {piece:?}: {d:?}",
                    s.range
                );
                assert!(piece.text.is_char_boundary(start), "{d:?}");
                continue;
            }
            let text = &sources.get(s.file).text;
            assert!(
                s.range.start <= s.range.end && s.range.end <= text.len(),
                "span {:?} outside its file ({} bytes): {d:?}",
                s.range,
                text.len()
            );
            assert!(
                text.is_char_boundary(s.range.start),
                "span {:?} does not start on a character boundary: {d:?}",
                s.range
            );
        }
    }
}

/// Renders the diagnostics in every format (line/column computation, codespan, JSON).
pub fn render_all(diags: &[Diagnostic], sources: &Sources) {
    check_spans(diags, sources);
    for d in diags {
        let _ = d.locate(sources);
    }
    let _ = diag::render(diags, sources, Format::Human, true, false);
    let _ = diag::render(diags, sources, Format::Short, true, false);
    let json = diag::render(diags, sources, Format::Json, true, false);
    for line in json.lines() {
        assert!(
            line.starts_with('{') && line.ends_with('}'),
            "JSON diagnostics are one object per line: {line}"
        );
    }
}

/// What the blackboard reader reads as a CAEX `Attribute`'s value (`read::xml::caex_value`):
/// the direct text of its first direct `Value` child, trimmed; `""` without one.
pub fn reader_value(attr: roxmltree::Node) -> String {
    attr.children()
        .find(|c| c.is_element() && c.tag_name().name() == "Value")
        .map(|v| {
            v.children()
                .filter(|c| c.is_text())
                .filter_map(|c| c.text())
                .collect::<String>()
        })
        .unwrap_or_default()
        .trim()
        .to_owned()
}

/// roxmltree with the readers' options (no DTD).
pub fn parse_xml(text: &str) -> Option<roxmltree::Document<'_>> {
    let opts = roxmltree::ParsingOptions {
        allow_dtd: false,
        ..roxmltree::ParsingOptions::default()
    };
    roxmltree::Document::parse_with_options(text, opts).ok()
}
