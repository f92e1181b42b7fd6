//! Property tests of the write-back splice: any value, written into any shape of the target
//! `Value`, changes only the bytes of that value and reads back equal.

use proptest::prelude::*;
use skillpost::write::splice_value;

/// The shapes a refURI attribute's value can have.
fn attribute(shape: usize, old: &str, prefix: &str) -> String {
    let a = format!("<{prefix}Attribute Name=\"refURI\" AttributeDataType=\"xs:anyURI\"");
    match shape {
        0 => format!("{a}><{prefix}Value>{old}</{prefix}Value></{prefix}Attribute>"),
        1 => format!("{a}><{prefix}Value></{prefix}Value></{prefix}Attribute>"),
        2 => format!("{a}><{prefix}Value/></{prefix}Attribute>"),
        3 => format!(
            "{a}>\r\n  <{prefix}Description>d</{prefix}Description>\r\n</{prefix}Attribute>"
        ),
        4 => format!("{a}/>"),
        _ => format!(
            "{a}><{prefix}Value> {old} </{prefix}Value><{prefix}Attribute Name=\"x\"><{prefix}Value>inner</{prefix}Value></{prefix}Attribute></{prefix}Attribute>"
        ),
    }
}

/// The text of the attribute's direct `Value` child, as a reader sees it (trimmed).
fn read_back(doc: &str) -> Option<String> {
    let d = roxmltree::Document::parse(doc).ok()?;
    let attr = d
        .descendants()
        .find(|n| n.tag_name().name() == "Attribute" && n.attribute("Name") == Some("refURI"))?;
    let v = attr
        .children()
        .find(|c| c.is_element() && c.tag_name().name() == "Value");
    Some(
        v.map(|v| {
            v.children()
                .filter(|c| c.is_text())
                .filter_map(|c| c.text())
                .collect::<String>()
        })
        .unwrap_or_default()
        .trim()
        .to_owned(),
    )
}

/// XML 1.0 characters (what a value can hold at all), including `&`, `<`, quotes, non-ASCII.
fn xml_text() -> impl Strategy<Value = String> {
    proptest::collection::vec(
        prop_oneof![
            4 => proptest::char::range('!', '~'),
            1 => Just(' '),
            1 => Just('&'),
            1 => Just('<'),
            1 => Just('"'),
            1 => proptest::char::range('\u{a0}', '\u{d7ff}'),
            1 => Just('\u{1F916}'),
        ],
        0..40,
    )
    .prop_map(|v| v.into_iter().collect())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn only_the_value_changes_and_reads_back(
        value in xml_text(),
        shape in 0usize..6,
        ns in prop_oneof![Just(""), Just("c:")],
        crlf in any::<bool>(),
        bom_like_comment in any::<bool>(),
    ) {
        let nl = if crlf { "\r\n" } else { "\n" };
        let xmlns = if ns.is_empty() { String::new() } else { " xmlns:c=\"http://www.dke.de/CAEX\"".to_owned() };
        let comment = if bom_like_comment { format!("<!-- a > b & \"c\" -->{nl}") } else { String::new() };
        let head = format!(
            "<?xml version=\"1.0\" encoding=\"utf-8\"?>{nl}<{ns}CAEXFile{xmlns}>{nl}{comment}  <{ns}InternalElement Name=\"Code\">{nl}    "
        );
        let attr = attribute(shape, "none", ns);
        let tail = format!("{nl}  </{ns}InternalElement>{nl}</{ns}CAEXFile>{nl}");
        let doc = format!("{head}{attr}{tail}");
        let range = head.len()..head.len() + attr.len();

        let before = read_back(&doc).unwrap();
        let out = splice_value(&doc, range, &value).unwrap();
        match out {
            None => {
                // No write: the value already reads as right.
                prop_assert_eq!(before, value.trim());
            }
            Some(new) => {
                // Everything before and after the attribute element is byte for byte the same.
                prop_assert!(new.starts_with(&head));
                prop_assert!(new.ends_with(&tail));
                // Inside it, only the `Value` changed: the attribute's start tag is kept.
                let start_tag_end = attr.find('>').unwrap();
                let kept = if attr[..start_tag_end].ends_with('/') { start_tag_end - 1 } else { start_tag_end };
                prop_assert_eq!(&new[head.len()..head.len() + kept], &attr[..kept]);
                // Well-formed, and the value reads back equal.
                prop_assert_eq!(read_back(&new), Some(value.trim().to_owned()));
                // Nested attributes' values are untouched.
                if shape == 5 {
                    prop_assert!(new.contains("<Value>inner</Value>") || new.contains("<c:Value>inner</c:Value>"));
                }
                // Splicing again is a no-op.
                let range2 = head.len()..new.len() - tail.len();
                prop_assert_eq!(splice_value(&new, range2, &value).unwrap(), None);
            }
        }
    }
}
