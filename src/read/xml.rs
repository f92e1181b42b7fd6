//! Shared XML plumbing for the readers: loading a file into [`Sources`], parsing it with
//! roxmltree under safe limits, and small lookups (elements by local name, CAEX attributes).

use std::path::Path;

use roxmltree::{Document, Node, ParsingOptions};

use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::load::FileSource;

/// At most this many XML nodes per document (about 40 bytes of input each at the very least, so
/// this only bites far beyond the file-size limit).
pub const NODES_LIMIT: u32 = 50_000_000;

/// Maximum nesting of CAEX attributes (the only element nesting the readers recurse into;
/// roxmltree itself parses iteratively, so deep documents cannot overflow the stack).
pub const MAX_DEPTH: usize = 64;

/// Reads a file through `fs` into `sources`. On failure pushes an `E101` diagnostic located at
/// `origin` (the `refURI` that named the file), or naming the path when there is no origin.
pub fn load(
    fs: &dyn FileSource,
    path: &Path,
    display: String,
    origin: Option<Span>,
    sources: &mut Sources,
    diags: &mut Diagnostics,
) -> Option<FileId> {
    if let Some(id) = sources.find(path) {
        return Some(id);
    }
    let bytes = match fs.read(path) {
        Ok(b) => b,
        Err(e) => {
            diags.push(unreadable(&display, path, origin, &e));
            return None;
        }
    };
    let mut bytes = bytes;
    let bom = strip_bom(&mut bytes);
    match String::from_utf8(bytes) {
        Ok(text) => Some(sources.add(path.to_owned(), display, text, bom)),
        Err(e) => {
            let valid = e.utf8_error().valid_up_to();
            let lossy = String::from_utf8_lossy(e.as_bytes()).into_owned();
            let id = sources.add(path.to_owned(), display.clone(), lossy, bom);
            // The lossy text has the same bytes up to `valid`, so the offset holds.
            diags.push(not_utf8(&display, id, Some(valid)));
            None
        }
    }
}

/// `E101` for a file that cannot be read, located at `origin` (the `refURI` that named it) or
/// naming the path.
pub fn unreadable(
    display: &str,
    path: &Path,
    origin: Option<Span>,
    e: &std::io::Error,
) -> Diagnostic {
    let why = match e.kind() {
        std::io::ErrorKind::NotFound => "no such file".to_owned(),
        _ => e.to_string(),
    };
    Diagnostic::error(
        Code::FileUnreadable,
        format!("cannot read `{display}`: {why}"),
    )
    .at_opt(origin)
    .path(path)
}

/// `E101` for a file that is not UTF-8, at its first bad byte (`at`; `None`: not known).
pub fn not_utf8(display: &str, file: FileId, at: Option<usize>) -> Diagnostic {
    let d = Diagnostic::error(
        Code::FileUnreadable,
        format!("`{display}` is not UTF-8 text (only UTF-8 is read)"),
    );
    match at {
        Some(at) => d.at(Span::new(file, at..at + 1)),
        None => d,
    }
}

pub use crate::load::strip_bom;

/// Parses a file's text as XML, without DTDs (no entity expansion attacks, no external
/// entities). A syntax error becomes `E102` at its line and column.
pub fn parse<'a>(
    sources: &'a Sources,
    file: FileId,
    diags: &mut Diagnostics,
) -> Option<Document<'a>> {
    let text = sources.get(file).text.as_ref();
    let opts = ParsingOptions {
        allow_dtd: false,
        nodes_limit: NODES_LIMIT,
        ..ParsingOptions::default()
    };
    match Document::parse_with_options(text, opts) {
        Ok(doc) => Some(doc),
        Err(e) => {
            let pos = e.pos();
            let off = match e {
                // roxmltree has no position for this one: point at the declaration.
                roxmltree::Error::DtdDetected => text.find("<!DOCTYPE").unwrap_or(0),
                _ => sources.offset_of(file, pos.row as usize, pos.col as usize),
            };
            let end = (off + 1).min(text.len()).max(off);
            diags.push(
                Diagnostic::error(
                    Code::XmlSyntax,
                    match e {
                        roxmltree::Error::DtdDetected => {
                            "a document type declaration (DTD) is not accepted: entity definitions could expand without bound".to_owned()
                        }
                        _ => format!("not well-formed XML: {e}"),
                    },
                )
                .at(Span::new(file, off..end)),
            );
            None
        }
    }
}

/// Element children with this local name.
pub fn children<'a, 'i: 'a>(
    node: Node<'a, 'i>,
    local: &'static str,
) -> impl Iterator<Item = Node<'a, 'i>> + 'a {
    node.children()
        .filter(move |c| c.is_element() && c.tag_name().name() == local)
}

/// The first element child with this local name.
pub fn child<'a, 'i: 'a>(node: Node<'a, 'i>, local: &'static str) -> Option<Node<'a, 'i>> {
    children(node, local).next()
}

/// Span of an element's start tag name (a short, precise marker for diagnostics).
pub fn tag_span(file: FileId, node: Node) -> Span {
    let start = node.range().start;
    let name_len = node.tag_name().name().len() + 1;
    let end = (start + name_len).min(node.range().end);
    Span::new(file, start..end)
}

/// Span of an attribute's value, or of the element's tag when the attribute is absent.
pub fn attr_span(file: FileId, node: Node, name: &str) -> Span {
    match node.attribute_node(name) {
        Some(a) => Span::new(file, a.range_value()),
        None => tag_span(file, node),
    }
}

/// The element's `Name` attribute (CAEX).
pub fn caex_name<'a>(node: Node<'a, '_>) -> Option<&'a str> {
    node.attribute("Name")
}

/// CAEX `Attribute` children whose `Name` matches (case-insensitively, trimmed).
pub fn caex_attr<'a, 'i: 'a>(node: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    children(node, "Attribute").find(|a| caex_name(*a).is_some_and(|n| crate::names::eq(n, name)))
}

/// A CAEX `Attribute`'s `Value` text, trimmed, with the span of the `Value` element; `None` when
/// there is no `Value` element. An empty `Value` gives an empty string.
pub fn caex_value(file: FileId, attr: Node) -> Option<(String, Span)> {
    let v = child(attr, "Value")?;
    let text: String = v
        .children()
        .filter(|c| c.is_text())
        .filter_map(|c| c.text())
        .collect();
    Some((text.trim().to_owned(), Span::new(file, v.range())))
}

/// Describes a CAEX element for diagnostics: `InternalElement "Move PTP" {ID}`.
pub fn caex_element(node: Node) -> String {
    let mut s = node.tag_name().name().to_owned();
    if let Some(n) = caex_name(node) {
        s.push_str(&format!(" \"{n}\""));
    }
    if let Some(id) = node.attribute("ID") {
        s.push_str(&format!(" {id}"));
    }
    s
}
