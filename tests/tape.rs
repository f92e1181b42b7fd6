//! The SFC reader's events come from pieces of the file, each parsed where it lies
//! (`skillpost::read::tape`). Every way of cutting a file into pieces must give the events, the
//! places and the stop that quick-xml gives for the whole file at once: compared over every XML
//! fixture, and over small documents with every kind of markup — each of their prefixes (a file
//! that ends anywhere), each with a byte that is not UTF-8 or a multi-byte character put in at
//! every place, and read with errors from the input at every place.

use skillpost::read::tape::{records_text, reference_text};

mod common;

const PIECES: [usize; 10] = [1, 2, 3, 5, 8, 13, 64, 1000, 4096, usize::MAX];

fn same_as_whole(name: &str, text: &[u8]) {
    let whole = reference_text(text);
    for n in PIECES {
        let got = records_text(text, n);
        assert!(
            got == whole,
            "{name}: in pieces of {n} bytes:\n{got}\nquick-xml over the whole text:\n{whole}"
        );
    }
}

#[test]
fn every_fixture_reads_as_one_piece_does() {
    for (name, text) in common::fixture_xml() {
        same_as_whole(&name, &text);
    }
}

/// Every kind of markup, `<` inside comments, CDATA, processing instructions, a DTD's internal
/// subset and an attribute value, references, prefixed names, multi-byte characters.
const GOOD: &str = r#"<?xml version="1.0" encoding="utf-8"?>
<!-- a comment with < and > and <tags> -->
<project xmlns="http://www.plcopen.org/xml/tc6_0201" a='1' b="x>y">
  <?pi with < inside?>
  <fileHeader companyName="A &amp; B"/>
  <x:step xmlns:x="u" name="é€𝄞">text &lt; &#x41; &bogus; more é</x:step>
  <![CDATA[ cdata with < and ]] and > ]]>
  <a><b></b ></a><c/>text at the end&amp;
</project>
<!-- trailing -->
"#;

/// Documents quick-xml stops in, at different places.
const BAD: [&str; 12] = [
    "\u{FEFF}<p/>",
    "<p a=\"1\" a=\"2\" b=\"3\"/>",
    "<p a=1 b=\"2\"></p>",
    "<p x:a=\"&amp;\n\" b c=\"3\"/>",
    "<p><a></b></p>",
    "<p></p></z>",
    "<p><a b=\"x<y\">t</a></p>",
    "<p><!x></p>",
    "<p><!<</p>",
    "<!DOCTYPE x [ <!ENTITY e \"<v>\"> ]><x/>",
    "<p>&amp</p>",
    "<p><a></a ><a></ a></p>",
];

#[test]
fn small_documents_cut_anywhere_read_as_one_piece_does() {
    for (k, doc) in std::iter::once(GOOD).chain(BAD).enumerate() {
        let bytes = doc.as_bytes();
        for end in 0..=bytes.len() {
            same_as_whole(&format!("document {k} cut at {end}"), &bytes[..end]);
        }
    }
}

#[test]
fn bytes_not_utf8_and_multi_byte_characters_anywhere() {
    let bytes = GOOD.as_bytes();
    for at in 0..=bytes.len() {
        for insert in [&b"\xFF"[..], b"\xE2\x82", "€".as_bytes(), "𝄞".as_bytes()] {
            let mut t = bytes[..at].to_vec();
            t.extend_from_slice(insert);
            t.extend_from_slice(&bytes[at..]);
            same_as_whole(&format!("{insert:?} at {at}"), &t);
        }
    }
}

/// Reads `text`, then fails.
struct FailsAfter<'a>(&'a [u8]);

impl std::io::Read for FailsAfter<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.0.is_empty() {
            return Err(std::io::Error::other("the disk went away"));
        }
        let n = buf.len().min(self.0.len());
        buf[..n].copy_from_slice(&self.0[..n]);
        self.0 = &self.0[n..];
        Ok(n)
    }
}

#[test]
fn a_read_error_stops_after_the_whole_events_before_it() {
    let bytes = GOOD.as_bytes();
    for at in 0..bytes.len() {
        // quick-xml over the bytes before the error: the same events, except the one the error
        // cuts (a text or markup running to that place) and the end of the file.
        let whole = reference_text(&bytes[..at]);
        let mut lines: Vec<&str> = whole.lines().collect();
        let cut = |l: &str| {
            l.starts_with("stop:")
                || l.starts_with("Eof")
                || (l.starts_with("Text") && l.contains(&format!("..{at} ")))
        };
        while lines.last().is_some_and(|l| cut(l)) {
            lines.pop();
        }
        let mut expected: String = lines.iter().map(|l| format!("{l}\n")).collect();
        expected.push_str("stop: read error\n");
        for n in PIECES {
            let input = std::io::BufReader::with_capacity(7, FailsAfter(&bytes[..at]));
            let got = records_text(input, n);
            assert!(
                got == expected,
                "error at {at}, pieces of {n}:\n{got}\nexpected:\n{expected}"
            );
        }
    }
}

/// The reader reads a tag's attributes itself where quick-xml would read them without an error
/// (`read::tape::each_attribute`), and leaves the others to quick-xml: the same attributes every
/// time, and every tag quick-xml has words for left to it.
#[test]
fn attributes_read_as_quick_xml_reads_them() {
    let mut tags: Vec<String> = Vec::new();
    for (_, bytes) in common::fixture_xml() {
        let text = String::from_utf8_lossy(&bytes);
        let mut reader = quick_xml::Reader::from_str(&text);
        while let Ok(ev) = reader.read_event() {
            match ev {
                quick_xml::events::Event::Start(e) | quick_xml::events::Event::Empty(e) => {
                    let content: &str = &e;
                    tags.push(content.to_owned());
                }
                quick_xml::events::Event::Eof => break,
                _ => {}
            }
        }
    }
    assert!(tags.len() > 1000, "tags found: {}", tags.len());
    let many: String = (0..17).map(|k| format!(" a{k}=\"{k}\"")).collect();
    let odd = [
        "a b=\"1\"c='2'",
        "a b = \"1\" \t\r\n c\n=\n'2' ",
        "a b",
        "a b ",
        "a b=",
        "a b= ",
        "a b=1",
        "a b=\"1",
        "a b='1\"",
        "a b=\"1\" b=\"2\"",
        "a b=\"1\" b",
        "a x:b=\"1\" y:b=\"2\"",
        "a b=\"<>&amp;'\" c='\"'",
        "a é=\"€\" 𝄞='x'",
        "a =\"1\"",
        "a b==\"1\"",
        "a\tb=\"1\"/",
        &many,
        &many[..many.len() - 8],
    ];
    for t in tags.iter().map(String::as_str).chain(odd) {
        if let Err(e) = skillpost::read::tape::compare_attributes(t) {
            panic!("{e}");
        }
    }
    // Every prefix of a tag with every kind of spacing and quoting.
    let rich = "step localId = \"1\" name='a \"b\"' x:y=\"&lt;\"\tz\n=\n'' w=\"1\" w";
    for end in 0..=rich.len() {
        if let Err(e) = skillpost::read::tape::compare_attributes(&rich[..end]) {
            panic!("{e}");
        }
    }
}
