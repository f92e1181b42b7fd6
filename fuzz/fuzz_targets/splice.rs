//! The write-back splice (`write::splice_value`).
//!
//! Input: one selector byte, the value, a NUL byte, the document. Selector bit 0 set: the
//! document part is the `Attribute` element and is wrapped into a CAEX blackboard skeleton
//! (the fuzzer then works on attribute shapes); clear: it is the whole document.
//!
//! When the document is well-formed XML (roxmltree, no DTD, as the reader parses) and has
//! `Attribute` elements, the splice gets the range of one of them (chosen by the selector), as
//! `compile` gives it the reader's write-back target. Then:
//! - it is `Err` exactly when the value holds a character XML cannot carry;
//! - it is `Ok(None)` exactly when the reader already reads the value (`Value` text, trimmed);
//! - `Ok(Some(new))`: `new` is well-formed; only bytes inside the `Attribute`'s range changed;
//!   the `Attribute` (same start) reads the value back (trimmed); its other child elements and
//!   attributes are as before; a new `Value` stands where the CAEX schema puts it; and a second
//!   splice of the same value is `Ok(None)`.
//!
//! Otherwise the range runs from one `<` to after a later `>` (chosen by the selector): the
//! splice must not panic, and whatever it returns changes nothing outside the range.
#![no_main]

mod common;

use std::ops::Range;

use libfuzzer_sys::fuzz_target;
use skillpost::write::splice_value;

fuzz_target!(|data: &[u8]| {
    let Some((&sel, rest)) = data.split_first() else {
        return;
    };
    let Ok(rest) = std::str::from_utf8(rest) else {
        return;
    };
    let Some((value, part)) = rest.split_once('\0') else {
        return;
    };
    let doc = if sel & 1 == 1 {
        wrap(part)
    } else {
        part.to_owned()
    };
    let pick = (sel >> 1) as usize;

    if let Some(xml) = common::parse_xml(&doc) {
        let attrs: Vec<roxmltree::Node> = xml
            .descendants()
            .filter(|n| n.is_element() && n.tag_name().name() == "Attribute")
            .collect();
        if !attrs.is_empty() {
            let attr = attrs[pick % attrs.len()];
            well_formed(&doc, attr, value);
            return;
        }
    }
    any_range(&doc, pick, value);
});

fn wrap(attr: &str) -> String {
    format!(
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<CAEXFile FileName=\"B.aml\" SchemaVersion=\"2.15\" xmlns:x=\"urn:x\">\n  <InstanceHierarchy Name=\"Blackboard\">\n    <InternalElement Name=\"Code\" ID=\"{{18}}\">\n      <ExternalInterface Name=\"KRL code\" ID=\"{{19}}\">\n        {attr}\n      </ExternalInterface>\n    </InternalElement>\n  </InstanceHierarchy>\n</CAEXFile>\n"
    )
}

fn representable(value: &str) -> bool {
    value.chars().all(|c| {
        !(((c as u32) < 0x20 && !matches!(c, '\t' | '\n' | '\r'))
            || c == '\u{FFFE}'
            || c == '\u{FFFF}')
    })
}

/// Names of the element children other than the first `Value`, and where the first `Value` is.
fn shape(attr: roxmltree::Node) -> (Vec<String>, Option<usize>) {
    let mut names = Vec::new();
    let mut value_at = None;
    for (i, c) in attr.children().filter(|c| c.is_element()).enumerate() {
        if value_at.is_none() && c.tag_name().name() == "Value" {
            value_at = Some(i);
        } else {
            names.push(format!("{:?}", c.tag_name()));
        }
    }
    (names, value_at)
}

fn attributes(node: roxmltree::Node) -> Vec<(String, String)> {
    node.attributes()
        .map(|a| {
            (
                format!("{:?}", a.namespace()) + a.name(),
                a.value().to_owned(),
            )
        })
        .collect()
}

fn well_formed(doc: &str, attr: roxmltree::Node, value: &str) {
    let range = attr.range();
    let result = splice_value(doc, range.clone(), value);
    let before = common::reader_value(attr);
    let want = value.trim();
    let new = match result {
        Err(e) => {
            assert!(
                !representable(value),
                "the splice refuses a real Attribute element and a representable value: {e}"
            );
            return;
        }
        Ok(_) if !representable(value) => panic!("an unrepresentable value was accepted"),
        Ok(None) => {
            assert_eq!(before, want, "Ok(None), but the reader reads another value");
            return;
        }
        Ok(Some(new)) => new,
    };
    assert_ne!(
        before, want,
        "rewrote a value the reader already reads as right"
    );
    outside_unchanged(doc, &new, &range);
    let Some(xml) = common::parse_xml(&new) else {
        panic!("the spliced document is not well-formed:\n{new}");
    };
    let Some(a2) = xml
        .descendants()
        .find(|n| n.is_element() && n.range().start == range.start)
    else {
        panic!("no element at the Attribute's start after the splice:\n{new}");
    };
    assert_eq!(a2.tag_name(), attr.tag_name());
    assert_eq!(
        attributes(a2),
        attributes(attr),
        "the Attribute's attributes changed"
    );
    assert_eq!(
        common::reader_value(a2),
        want,
        "the value does not read back:\n{new}"
    );
    let (names1, value1) = shape(attr);
    let (names2, value2) = shape(a2);
    assert_eq!(
        names1, names2,
        "the Attribute's other children changed:\n{new}"
    );
    let value2 = value2.expect("a Value after the splice");
    match value1 {
        Some(i) => assert_eq!(value2, i, "the Value moved"),
        None => {
            // Before the first RefSemantic, Constraint or Attribute, else last.
            let expected = attr
                .children()
                .filter(|c| c.is_element())
                .position(|c| {
                    matches!(
                        c.tag_name().name(),
                        "RefSemantic" | "Constraint" | "Attribute"
                    )
                })
                .unwrap_or(names1.len());
            assert_eq!(value2, expected, "the new Value is out of place:\n{new}");
        }
    }
    assert_eq!(
        splice_value(&new, a2.range(), value),
        Ok(None),
        "a second splice of the same value changes something:\n{new}"
    );
}

/// The bytes before `range.start` and after `range.end` are the same in `new`.
fn outside_unchanged(doc: &str, new: &str, range: &Range<usize>) {
    let (d, n) = (doc.as_bytes(), new.as_bytes());
    let tail = d.len() - range.end;
    assert!(n.len() >= range.start + tail, "the result is too short");
    assert_eq!(
        &n[..range.start],
        &d[..range.start],
        "bytes before the range changed"
    );
    assert_eq!(
        &n[n.len() - tail..],
        &d[range.end..],
        "bytes after the range changed"
    );
}

fn any_range(doc: &str, pick: usize, value: &str) {
    let opens: Vec<usize> = doc.match_indices('<').map(|(i, _)| i).collect();
    if opens.is_empty() {
        let _ = splice_value(doc, 0..doc.len(), value);
        return;
    }
    let start = opens[pick % 8 % opens.len()];
    let closes: Vec<usize> = doc[start..]
        .match_indices('>')
        .map(|(i, _)| start + i + 1)
        .collect();
    let end = match closes.len() {
        0 => doc.len(),
        n => closes[(pick / 8) % n],
    };
    if let Ok(Some(new)) = splice_value(doc, start..end, value) {
        outside_unchanged(doc, &new, &(start..end));
    }
}
