//! The records as text, and what quick-xml over the whole input gives (for the tests and the
//! fuzz target).

use std::io::BufRead;

use quick_xml::events::Event;
use quick_xml::utils::trim_xml_start;

use super::producer::{BOM, Producer};
use super::{Batch, Kind, Stop, Tag, local_part};

/// The records of `input` read in pieces of about `batch_bytes`, one line each, and the stop (for
/// the tests and the fuzz target, beside [`reference_text`]).
#[doc(hidden)]
pub fn records_text<R: BufRead>(input: R, batch_bytes: usize) -> String {
    let mut p = Producer::new(input, batch_bytes);
    let mut out = String::new();
    let mut b = Batch::default();
    while !p.done {
        p.fill(&mut b);
        for r in &b.recs {
            let (name, text) = match r.kind {
                Kind::Start | Kind::Empty => {
                    let (_, local, content) = b.names_and_content(r);
                    (local, content)
                }
                _ => ("", b.text(r)),
            };
            out.push_str(&record_line(r.kind, r.tag, b.at(r), b.end(r), text, name));
        }
        if let Some(stop) = &b.stop {
            out.push_str(&stop_line(stop));
        }
    }
    out
}

/// What [`records_text`] must give: quick-xml's reader over the whole input at once, with its own
/// checks of end tags. One difference is chosen: where markup runs on to the end of an input that
/// is not UTF-8 (a file cut inside a character, a bad byte in a tag never closed), quick-xml
/// reports the markup not closed and the producer that the input is not UTF-8 (the compile then
/// names the first bad byte); the events before are the same.
#[doc(hidden)]
pub fn reference_text(input: &[u8]) -> String {
    let mut whole = quick_xml_text(input);
    if std::str::from_utf8(input).is_err()
        && let Some(last) = whole.lines().last()
        && last.starts_with("stop: at ")
        && last.contains(": syntax error: ")
        && last.ends_with("not found before end of input")
    {
        whole.truncate(whole.len() - last.len() - 1);
        whole.push_str(&stop_line(&Stop::NotUtf8));
    }
    whole
}

/// quick-xml's events over the whole input, as [`records_text`] writes them.
fn quick_xml_text(input: &[u8]) -> String {
    let mut out = String::new();
    if input.starts_with(BOM) {
        out.push_str(&stop_line(&Stop::SecondBom));
        return out;
    }
    let mut reader = quick_xml::Reader::from_reader(input);
    // Whether each open element keeps text ([`Tag::keeps_text`]).
    let mut open: Vec<bool> = Vec::new();
    loop {
        let at = reader.buffer_position() as usize;
        let ev = match reader.read_event() {
            Ok(ev) => ev,
            Err(e) => {
                out.push_str(&stop_line(&match e {
                    quick_xml::Error::Encoding(_) => Stop::NotUtf8,
                    quick_xml::Error::Io(e) => Stop::Io(std::io::Error::new(e.kind(), "")),
                    e => Stop::Syntax(reader.error_position() as usize, e.to_string()),
                }));
                return out;
            }
        };
        let end = reader.buffer_position() as usize;
        let (kind, text, name): (Kind, &str, &str) = match &ev {
            Event::Start(e) | Event::Empty(e) => {
                let content: &str = e;
                let len = e.name().as_ref().len().min(content.len());
                let kind = if matches!(ev, Event::Start(_)) {
                    Kind::Start
                } else {
                    Kind::Empty
                };
                (kind, content, local_part(&content[..len]))
            }
            Event::End(_) => (Kind::End, "", ""),
            // White space where no open element keeps text is left out.
            Event::Text(t) if !open.contains(&true) && trim_xml_start(t).is_empty() => {
                continue;
            }
            Event::Text(t) => (Kind::Text, t, ""),
            Event::CData(t) => (Kind::CData, t, ""),
            Event::GeneralRef(r) => (Kind::GeneralRef, r, ""),
            Event::DocType(_) => (Kind::DocType, "", ""),
            Event::Eof => (Kind::Eof, "", ""),
            _ => continue,
        };
        let tag = Tag::of(name);
        match kind {
            Kind::Start => open.push(tag.keeps_text()),
            Kind::End => {
                open.pop();
            }
            _ => {}
        }
        out.push_str(&record_line(kind, tag, at, end, text, name));
        if kind == Kind::Eof {
            return out;
        }
    }
}

fn record_line(kind: Kind, tag: Tag, at: usize, end: usize, text: &str, name: &str) -> String {
    format!("{kind:?} {at}..{end} {tag:?} {text:?} {name:?}\n")
}

fn stop_line(stop: &Stop) -> String {
    match stop {
        Stop::NotUtf8 => "stop: not UTF-8\n".to_owned(),
        Stop::SecondBom => "stop: a byte-order mark at the start\n".to_owned(),
        Stop::Io(_) => "stop: read error\n".to_owned(),
        Stop::Syntax(at, msg) => format!("stop: at {at}: {msg}\n"),
    }
}
