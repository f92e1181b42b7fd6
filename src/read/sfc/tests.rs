use super::*;
use crate::model::ElementKind;

fn read(text: &str) -> (Option<Sfc>, Vec<Diagnostic>) {
    let mut sources = Sources::default();
    let f = sources.add("s.xml".into(), "s.xml".into(), text.to_owned(), false);
    let mut d = Diagnostics::default();
    let sfc = read_sfc(&sources, f, &mut d);
    (sfc, d.into_vec())
}

/// Syntax errors at the end of the text (or in an empty one) point inside it: the stream
/// places them one byte on, the text-based entry puts them back (fuzz finding).
#[test]
fn places_at_the_end_stay_inside_the_text() {
    for text in ["", "<project", "<project>", "<project>\u{e4}"] {
        let (sfc, d) = read(text);
        assert!(sfc.is_none());
        let s = d[0].span.as_ref().expect("located");
        assert!(
            s.range.start <= s.range.end && s.range.end <= text.len(),
            "{text:?}: {:?}",
            s.range
        );
        assert!(text.is_char_boundary(s.range.start), "{text:?}");
    }
}

#[test]
fn transition_conditions() {
    let doc = |cond: &str| {
        format!(
            "<project xmlns=\"http://www.plcopen.org/xml/tc6_0201\"><types><pous><pou name=\"P\" pouType=\"program\"><body><SFC>\
             <transition localId=\"2\"><condition>{cond}</condition></transition>\
             </SFC></body></pou></pous></types></project>"
        )
    };
    let (sfc, d) = read(&doc(
        "<inline name=\"\"><ST><xhtml:p xmlns:xhtml=\"x\"> TRUE </xhtml:p></ST></inline>",
    ));
    assert_eq!(sfc.unwrap().elements.len(), 1);
    assert!(d.is_empty(), "{d:?}");
    // Entities and CDATA: the error is located in the file.
    let text = doc("<inline><ST>a &lt; b<![CDATA[ && c]]></ST></inline>");
    let (sfc, d) = read(&text);
    assert_eq!(d.len(), 1, "{d:?}");
    assert_eq!(d[0].code, Code::BadCondition);
    assert!(
        d[0].message.contains("condition `a < b && c`"),
        "{}",
        d[0].message
    );
    // The second `&` of `&&` (the first is a complete AND, the second lacks an operand).
    let at = d[0].span.as_ref().unwrap().range.start;
    assert_eq!(&text[at..at + 1], "&");
    assert_eq!(&text[at - 1..at + 3], "&& c");
    assert!(sfc.unwrap().elements.len() == 1);
    // A parsed condition keeps file spans.
    let text =
        doc("<inline><ST><xhtml:p xmlns:xhtml=\"x\">Part_OK AND NOT Stop</xhtml:p></ST></inline>");
    let (sfc, d) = read(&text);
    assert!(d.is_empty(), "{d:?}");
    let sfc = sfc.unwrap();
    let ElementKind::Transition(Some(c)) = &sfc.elements[0].kind else {
        panic!("no condition")
    };
    let names = c.expr.names();
    assert_eq!(&text[names[1].1.clone()], "Stop");
    // A reference is one name.
    let text = doc("<reference name=\"Cond1\"/>");
    let (sfc, d) = read(&text);
    assert!(d.is_empty(), "{d:?}");
    let ElementKind::Transition(Some(c)) = &sfc.unwrap().elements[0].kind else {
        panic!("no condition")
    };
    assert!(c.reference);
    assert_eq!(&text[c.expr.span.clone()], "Cond1");
    let (_, d) = read(&doc("<reference name=\"a b\"/>"));
    assert!(d[0].message.contains("is not one name"), "{}", d[0].message);
    // A wired condition whose connection leads nowhere in the body.
    let (_, d) = read(&doc(
        "<connectionPointIn><connection refLocalId=\"9\"/></connectionPointIn>",
    ));
    assert_eq!(d[0].code, Code::BadCondition);
    assert!(d[0].message.contains("localId 9"), "{}", d[0].message);
}

/// The reader's shortcut for `TRUE` gives what the parser gives: no condition exactly where
/// the parser reads the literal `TRUE`, and the same diagnostics otherwise.
#[test]
fn true_conditions_as_the_parser_reads_them() {
    let doc = |cond: &str| {
        format!(
            "<project xmlns=\"http://www.plcopen.org/xml/tc6_0201\"><types><pous><pou name=\"P\" pouType=\"program\"><body><SFC>\
             <transition localId=\"2\"><condition><inline><ST>{cond}</ST></inline></condition></transition>\
             </SFC></body></pou></pous></types></project>"
        )
    };
    for text in [
        "TRUE",
        "true",
        " True ",
        "\tTRUE\r\n",
        "&#12;TRUE",
        "\u{a0}TRUE",
        "TRUE\u{2003}",
        "TRUEX",
        "TRU",
        "(TRUE)",
        "NOT FALSE",
        "TRUE TRUE",
        "(* c *) TRUE",
        "",
        "  ",
    ] {
        let (sfc, d) = read(&doc(text));
        let sfc = sfc.unwrap();
        let unescaped = text.replace("&#12;", "\u{c}");
        let parsed = crate::cond::parse(&unescaped, &|o| o);
        let fires = matches!(&parsed, Ok(e) if e.is_true());
        let none = matches!(sfc.elements[0].kind, ElementKind::Transition(None));
        // A condition the parser refuses is reported and left out.
        assert_eq!(parsed.is_err(), !d.is_empty(), "{text:?}: {d:?}");
        assert_eq!(none, fires || parsed.is_err(), "{text:?}: {d:?}");
    }
}

#[test]
fn second_bom_is_a_located_syntax_error() {
    // Found by fuzzing: two byte-order marks, then garbage.
    let (sfc, d) = read("\u{feff}]]<essoe\u{16}reso");
    assert!(sfc.is_none());
    assert_eq!(d.len(), 1);
    assert_eq!(d[0].code, Code::XmlSyntax);
    assert_eq!(d[0].span.as_ref().unwrap().range, 0..3);
}

/// A reader that hands out a byte at a time shows the producer a second byte-order mark
/// only after three reads: it is reported the same.
#[test]
fn second_bom_read_a_byte_at_a_time() {
    let text = "\u{feff}<project/>";
    for pipeline in [Pipeline::Inline, Pipeline::Threaded] {
        let input = std::io::BufReader::with_capacity(1, text.as_bytes());
        let mut d = Diagnostics::default();
        let sfc = read_sfc_stream_with(input, 0, text.len() as u64, None, &mut d, pipeline, 1);
        let d = d.into_vec();
        assert!(matches!(sfc, Ok(None)), "{pipeline:?}");
        assert_eq!(d.len(), 1, "{pipeline:?}: {d:?}");
        assert_eq!(d[0].code, Code::XmlSyntax);
        assert_eq!(d[0].span.as_ref().unwrap().range, 0..3);
    }
}

#[test]
fn truncated_file_is_a_syntax_error() {
    let (sfc, d) =
        read("<project><types><pous><pou name=\"P\"><body><SFC><step localId=\"1\" name=\"S\"/>");
    assert!(sfc.is_none());
    assert_eq!(d.len(), 1);
    assert_eq!(d[0].code, Code::XmlSyntax);
    assert!(
        d[0].message.contains("ends inside `<SFC>`"),
        "{}",
        d[0].message
    );
}

/// A named transition's ST body takes the characters its references stand for, each located at
/// its reference in the file (as the inline conditions of `transition_conditions`).
#[test]
fn a_named_transitions_body_takes_its_references() {
    let text = "<project xmlns=\"http://www.plcopen.org/xml/tc6_0201\"><types><pous><pou name=\"P\" pouType=\"program\">\
         <transitions><transition name=\"T\"><body><ST><xhtml:p xmlns:xhtml=\"x\">a &lt; b &amp;&#x26; c</xhtml:p></ST></body></transition></transitions>\
         <body><SFC><transition localId=\"2\"><condition><reference name=\"T\"/></condition></transition>\
         </SFC></body></pou></pous></types></project>";
    let (sfc, d) = read(text);
    assert!(sfc.is_some());
    assert_eq!(d.len(), 1, "{d:?}");
    assert_eq!(d[0].code, Code::BadCondition);
    assert!(d[0].message.contains("`a < b && c`"), "{}", d[0].message);
    // The second `&` (the first is a complete AND, the second lacks an operand): `&#x26;`.
    let at = d[0].span.as_ref().unwrap().range.start;
    assert!(text[at..].starts_with("&#x26; c"), "{:?}", &text[at..]);
}

/// White space between two pieces of a condition's text is part of the condition, wherever the
/// reader takes text (an inline condition, a named transition's ST body, a wired network's
/// `expression`), though the reader's tape leaves out white space elsewhere: `NOT Stop` is not
/// the name `NOTStop`.
#[test]
fn white_space_between_pieces_of_a_condition_is_kept() {
    let pieces = "<![CDATA[NOT]]> <![CDATA[Stop]]>";
    let pou = |transitions: &str, sfc: &str| {
        format!(
            "<project xmlns=\"http://www.plcopen.org/xml/tc6_0201\">\n <types>\n  <pous>\n   <pou name=\"P\" pouType=\"program\">\n    {transitions}\n    <body>\n     <SFC>\n      {sfc}\n     </SFC>\n    </body>\n   </pou>\n  </pous>\n </types>\n</project>\n"
        )
    };
    let names = |text: &str| {
        let (sfc, d) = read(text);
        assert!(d.is_empty(), "{d:?}");
        let sfc = sfc.expect("read");
        let c = sfc
            .elements
            .iter()
            .find_map(|e| match &e.kind {
                ElementKind::Transition(Some(c)) => Some(c),
                _ => None,
            })
            .expect("a condition");
        c.expr
            .names()
            .iter()
            .map(|(n, _)| n.to_string())
            .collect::<Vec<_>>()
    };
    let inline = pou(
        "",
        &format!(
            "<transition localId=\"2\">\n       <condition>\n        <inline>\n         <ST> {pieces} </ST>\n        </inline>\n       </condition>\n      </transition>"
        ),
    );
    let named = pou(
        &format!(
            "<transitions>\n     <transition name=\"T\">\n      <body>\n       <ST> {pieces} </ST>\n      </body>\n     </transition>\n    </transitions>"
        ),
        "<transition localId=\"2\">\n       <condition>\n        <reference name=\"T\"/>\n       </condition>\n      </transition>",
    );
    let wired = pou(
        "",
        &format!(
            "<transition localId=\"2\">\n       <condition>\n        <connectionPointIn><connection refLocalId=\"13\"/></connectionPointIn>\n       </condition>\n      </transition>\n      <inVariable localId=\"13\">\n       <connectionPointOut/>\n       <expression> {pieces} </expression>\n      </inVariable>"
        ),
    );
    for (what, text) in [("inline", inline), ("named", named), ("wired", wired)] {
        assert_eq!(names(&text), ["Stop"], "{what}:\n{text}");
    }
    // A contact's `variable` holds one name: `Part OK` is not one, `PartOK` would be.
    let contact = pou(
        "",
        "<transition localId=\"2\">\n       <condition>\n        <connectionPointIn><connection refLocalId=\"12\"/></connectionPointIn>\n       </condition>\n      </transition>\n      <leftPowerRail localId=\"11\">\n       <connectionPointOut formalParameter=\"\"/>\n      </leftPowerRail>\n      <contact localId=\"12\">\n       <connectionPointIn><connection refLocalId=\"11\"/></connectionPointIn>\n       <variable><![CDATA[Part]]> <![CDATA[OK]]></variable>\n      </contact>",
    );
    let (_, d) = read(&contact);
    assert!(
        d.iter().any(|d| d.message.contains("Part OK")),
        "{d:?}\n{contact}"
    );
}
