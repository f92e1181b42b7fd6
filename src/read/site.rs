//! Where the write-back's value goes: [`SpliceSite::of`] records, from the write-back target's
//! `Attribute` node as the blackboard reader parsed it (roxmltree, with byte ranges), the bytes
//! to replace, the markup around the new value and the value as the reader reads it. The
//! `write` stage's `splice_at` then only replaces bytes.

use roxmltree::Node;

use crate::model::SpliceSite;

impl SpliceSite {
    /// The site of the refURI `Attribute` element `attr`. The `Value` is its first *direct*
    /// child element whose local name is `Value` (any prefix; a nested `Attribute`'s `Value`
    /// and a `DefaultValue` do not count):
    ///
    /// - `<Value>old</Value>`: the whole content between the tags is replaced (text, entities,
    ///   CDATA, comments, processing instructions and child elements alike);
    /// - `<Value></Value>`: the value is inserted between the tags;
    /// - `<Value/>`, `<Value />`: the element becomes `<Value>value</Value>` (attributes it has
    ///   are kept, the space before `/>` goes);
    /// - no `Value`: `<Value>value</Value>` (with the `Attribute`'s prefix, if any) is inserted
    ///   where the CAEX schemas (2.15 and 3.0) put it: right before the first direct child
    ///   `RefSemantic`, `Constraint` or `Attribute`, else right before `</Attribute>`;
    /// - a self-closing `<Attribute .../>` becomes
    ///   `<Attribute ...><Value>value</Value></Attribute>`.
    ///
    /// `None` when `attr` is not an element named `Attribute`.
    pub fn of(attr: Node) -> Option<SpliceSite> {
        if !attr.is_element() || attr.tag_name().name() != "Attribute" {
            return None;
        }
        let text = attr.document().input_text();
        let attr_qname = qname(text, attr);
        let prefix = prefix_of(attr_qname);
        let value = attr
            .children()
            .find(|c| c.is_element() && c.tag_name().name() == "Value");
        let Some(v) = value else {
            let head = format!("<{prefix}Value>");
            let tail = format!("</{prefix}Value>");
            if self_closing(text, attr) {
                let body_end = tag_body_end(text, attr);
                return Some(SpliceSite {
                    replace: body_end..attr.range().end,
                    head: format!(">{head}"),
                    tail: format!("{tail}</{attr_qname}>"),
                    current: String::new(),
                });
            }
            let at = attr
                .children()
                .find(|c| {
                    c.is_element()
                        && matches!(
                            c.tag_name().name(),
                            "RefSemantic" | "Constraint" | "Attribute"
                        )
                })
                .map(|c| c.range().start)
                .unwrap_or_else(|| end_tag_start(text, attr));
            return Some(SpliceSite {
                replace: at..at,
                head,
                tail,
                current: String::new(),
            });
        };
        let current: String = v
            .children()
            .filter(|c| c.is_text())
            .filter_map(|c| c.text())
            .collect();
        let current = current.trim().to_owned();
        if self_closing(text, v) {
            return Some(SpliceSite {
                replace: tag_body_end(text, v)..v.range().end,
                head: ">".to_owned(),
                tail: format!("</{}>", qname(text, v)),
                current,
            });
        }
        Some(SpliceSite {
            replace: start_tag_end(text, v)..end_tag_start(text, v),
            head: String::new(),
            tail: String::new(),
            current,
        })
    }
}

/// The element's qualified name as written (`c:Attribute`).
fn qname<'a>(text: &'a str, e: Node) -> &'a str {
    let start = e.range().start + 1;
    let rest = &text[start..e.range().end];
    let len = rest
        .find([' ', '\t', '\r', '\n', '/', '>'])
        .unwrap_or(rest.len());
    &rest[..len]
}

/// `x:` for `x:Attribute`, empty for `Attribute`.
fn prefix_of(qname: &str) -> &str {
    match qname.rfind(':') {
        Some(i) => &qname[..=i],
        None => "",
    }
}

/// The index of the `>` that closes the element's start tag: the first one after the name
/// outside a quoted attribute value (values may hold `>` and `/`). The parser has checked the
/// tag, so this only steps over quotes.
fn start_tag_close(text: &str, e: Node) -> usize {
    let b = text.as_bytes();
    let end = e.range().end;
    let mut i = e.range().start + 1 + qname(text, e).len();
    let mut quote = None;
    while i < end {
        match (quote, b[i]) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), _) => {}
            (None, c @ (b'"' | b'\'')) => quote = Some(c),
            (None, b'>') => return i,
            _ => {}
        }
        i += 1;
    }
    end.saturating_sub(1)
}

/// Just after the start tag's `>`.
fn start_tag_end(text: &str, e: Node) -> usize {
    start_tag_close(text, e) + 1
}

/// Whether the element is written `<x/>` (an end tag never ends with `/>`).
fn self_closing(text: &str, e: Node) -> bool {
    text[e.range()].ends_with("/>")
}

/// For a self-closing element: where the whitespace before `/>` starts.
fn tag_body_end(text: &str, e: Node) -> usize {
    // The start tag is the whole element: `/` is the byte before its closing `>`.
    let start = e.range().start;
    let slash = start_tag_close(text, e).saturating_sub(1).max(start);
    start
        + text[start..slash]
            .trim_end_matches([' ', '\t', '\r', '\n'])
            .len()
}

/// The `<` of the end tag (an end tag holds no `<`).
fn end_tag_start(text: &str, e: Node) -> usize {
    let r = e.range();
    text[r.clone()].rfind('<').map_or(r.end, |p| r.start + p)
}
