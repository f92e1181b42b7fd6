//! Named transitions (docs/INPUTS.md): their bodies and the ST text of a condition taken from
//! one.

use std::ops::Range;

use super::tag::Open;
use super::{MAX_DERIVED_TEXT, Stream};

use crate::diag::{Code, Diagnostic, Diagnostics, Span};
use crate::model::Condition;

/// Where the pieces of a text assembled from the file stand: (offset in the text, offset in the
/// file, whether the piece is the file's bytes as they are).
pub(super) type PieceMap = Vec<(usize, usize, bool)>;

/// A named transition's body.
#[derive(Debug)]
pub(super) enum Named {
    /// ST: its text, and where its pieces stand in the file (as an inline condition's).
    St { text: String, map: PieceMap },
    /// A body in another language (`IL`, `SFC`), at the transition.
    Other { language: String, at: Span },
    /// An LD or FBD body: the expression of what its coil or output variable of the
    /// transition's name is wired from, or why there is none.
    Wired(Result<crate::cond::Expr, Box<Diagnostic>>),
}

/// A POU's reading state, kept while one of its actions is read.
pub(super) struct Outer {
    pub(super) pou: Option<(Option<String>, bool, usize)>,
    pub(super) want_pou: bool,
    pub(super) body_seen: bool,
    pub(super) sfc_done: bool,
    pub(super) pous_at: Option<usize>,
    /// The action element's depth.
    pub(super) depth: usize,
}

/// A named transition being read: its name, depth and place, its ST text so far (and the depth
/// of its `ST` element), or the language of another body.
pub(super) struct ReadingNamed {
    pub(super) name: String,
    pub(super) depth: usize,
    pub(super) at: Span,
    pub(super) st: Option<(usize, String, PieceMap)>,
    pub(super) other: Option<String>,
}

impl Stream {
    /// Counts a condition a transition takes from a named transition or a wired network
    /// against [`MAX_DERIVED_TEXT`]: past it, `E316` once (at `at`, the transition `element`)
    /// and no condition.
    pub(super) fn derived(
        &mut self,
        cond: Option<Box<Condition>>,
        at: &Span,
        element: String,
        diags: &mut Diagnostics,
    ) -> Option<Box<Condition>> {
        let c = cond?;
        self.derived_text = self.derived_text.saturating_add(c.text.len());
        if self.derived_text <= MAX_DERIVED_TEXT {
            return Some(c);
        }
        if !self.derived_refused {
            self.derived_refused = true;
            diags.push(
                Diagnostic::error(
                    Code::BadCondition,
                    format!(
                        "the conditions that transitions take from named transitions and wired \
                         networks come to more than {} MiB of text here (each transition gets its \
                         own copy in the program): give a condition many transitions share a \
                         signal of its own, set once, and name that signal in them",
                        MAX_DERIVED_TEXT >> 20
                    ),
                )
                .at(at.clone())
                .element(element),
            );
        }
        None
    }
}

/// The expression of a named transition's ST body: the text after `name :=` when it assigns
/// (to its own name) or after a bare `:=`, without a final `;`; as byte offsets of `text`.
pub(super) fn named_expression(text: &str, name: &str) -> (usize, usize) {
    let mut from = text.len() - text.trim_start().len();
    let rest = &text[from..];
    if rest.len() > name.len()
        && rest.is_char_boundary(name.len())
        && rest[..name.len()].eq_ignore_ascii_case(name)
        && rest[name.len()..].trim_start().starts_with(":=")
    {
        let after = &rest[name.len()..];
        from += name.len() + (after.len() - after.trim_start().len()) + 2;
    } else if rest.starts_with(":=") {
        // IEC 61131-3's textual form `TRANSITION … := expression; END_TRANSITION`, as some
        // tools export the body.
        from += 2;
    }
    // The statement ends at its `;` (outside a `(* comment *)`); what follows is comments.
    let mut to = text.trim_end().len().max(from);
    let b = text.as_bytes();
    let mut i = from;
    while i < to {
        if text[i..].starts_with("(*") {
            i = text[i + 2..].find("*)").map_or(to, |j| i + 2 + j + 2);
            continue;
        }
        if b[i] == b';' {
            to = i;
            break;
        }
        i += 1;
    }
    (from, to)
}

/// Adds text to a named transition's ST body when the stack is inside it.
pub(super) fn named_text<'s>(
    named: &mut Option<ReadingNamed>,
    stack: &Open,
    raw: Range<usize>,
    text: impl FnOnce() -> std::borrow::Cow<'s, str>,
) {
    if let Some(ReadingNamed {
        st: Some((d, body, map)),
        ..
    }) = named
        && stack.len() >= *d
    {
        super::element::push_piece(body, map, raw, &text());
    }
}

/// The file offset of byte `o` of an inline condition assembled from the pieces of `map`.
pub(super) fn map_offset(map: &[(usize, usize, bool)], o: usize) -> usize {
    let i = map.partition_point(|&(c, _, _)| c <= o);
    match i.checked_sub(1).map(|i| map[i]) {
        Some((c, f, true)) => f + (o - c),
        Some((_, f, false)) => f,
        None => map.first().map_or(0, |m| m.1),
    }
}
