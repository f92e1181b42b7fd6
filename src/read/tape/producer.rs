//! The producer: a file's pieces, their UTF-8 checked once, made into records of events.

use std::io::Read;
use std::ops::Range;

use quick_xml::events::Event;
use quick_xml::utils::is_whitespace;

use super::{Batch, Kind, Rec, Stop, Tag, local_part};

/// Tokenizes the XML of one input into batches.
///
/// A batch's text is a piece of the file itself, read straight into it: the events are parsed
/// where they lie (quick-xml's reader over a string slice), so an event's bytes are copied once,
/// from the file, and its UTF-8 is checked with the whole piece. A piece ends before its last
/// `<`: everything before that is whole events, except where the `<` is inside a comment, CDATA
/// section or other markup that began earlier. Such an event is cut by the end of the piece; it
/// goes, with the bytes after it, to the start of the next piece (`carry`), which is read longer
/// until the event fits.
///
/// Each piece has a reader of its own, so quick-xml cannot match an end tag with a start tag in
/// an earlier piece: the producer does that itself (`open`), with quick-xml's words and place.
pub(crate) struct Producer<R> {
    input: R,
    /// Bytes read and not yet made into events: an event cut by the end of the last piece, the
    /// bytes after it, and the first bytes of a character cut by it.
    carry: Vec<u8>,
    /// The file offset of `carry[0]`.
    base: usize,
    /// The input has nothing more (or failed: `failed`).
    eof: bool,
    failed: Option<std::io::Error>,
    pub(super) done: bool,
    batch_bytes: usize,
    /// The names of the open elements, one after another, and where each starts, with whether
    /// it keeps text ([`Tag::keeps_text`]).
    open: String,
    open_starts: Vec<(usize, bool)>,
    /// How many open elements keep text: while none does, text that is only white space is not
    /// recorded.
    keeping: usize,
    /// The first bytes were looked at (for a byte-order mark).
    started: bool,
    /// Where a piece is to end, if it can (the reading split in two, [`super::Decision`]): the
    /// batch that ends there is marked (`Batch::split`) when that place is between two events
    /// and no open element keeps text.
    split: Option<usize>,
    /// The second half of a split reading: its events end at the first end tag that closes an
    /// element opened before them (a [`Kind::PartEnd`] record).
    part: bool,
    /// Why the next batch stops (a skipped range that was not what the other half read).
    pending: Option<Stop>,
}

/// A UTF-8 byte-order mark.
pub(super) const BOM: &[u8] = b"\xEF\xBB\xBF";

/// How a piece's parse ended.
enum Piece {
    /// Every event up to the cut was made (or a stop was set).
    Parsed,
    /// The event starting at this offset of the piece is cut by its end.
    Cut(usize),
}

impl<R: Read> Producer<R> {
    pub fn new(input: R, batch_bytes: usize) -> Self {
        Producer {
            input,
            carry: Vec::new(),
            base: 0,
            eof: false,
            failed: None,
            done: false,
            batch_bytes: batch_bytes.max(1),
            open: String::new(),
            open_starts: Vec::new(),
            keeping: 0,
            started: false,
            split: None,
            part: false,
            pending: None,
        }
    }

    /// A producer whose pieces end at `at` if they can (see `split`).
    pub fn split_at(input: R, batch_bytes: usize, at: Option<usize>) -> Self {
        Producer {
            split: at,
            ..Producer::new(input, batch_bytes)
        }
    }

    /// The producer of the second half of a split reading: `input` starts at file offset
    /// `base`, inside elements opened before it (none of which keeps text).
    pub fn part(input: R, batch_bytes: usize, base: usize) -> Self {
        Producer {
            base,
            started: true,
            part: true,
            ..Producer::new(input, batch_bytes)
        }
    }

    /// Goes on at `to` instead of where the last batch ended (the split place): the bytes in
    /// between, which the other half read, are read here too and dropped, so whatever counts or
    /// hashes the input sees them all. Their hash must be `digest` (the other half's): else the
    /// file changed between the two readings, and the next batch stops with that.
    pub(super) fn skip(&mut self, to: usize, digest: u64) {
        if self.done {
            return;
        }
        if to < self.base {
            // (The second half starts at the split place, where this one stopped: never.) The
            // reader has taken its elements, so reading on from here would read them twice.
            self.pending = Some(Stop::Io(std::io::Error::other(
                "the second half of the reading ended before it began",
            )));
            return;
        }
        let mut left = to - self.base;
        let mut hash = xxhash_rust::xxh3::Xxh3Default::new();
        let from_carry = left.min(self.carry.len());
        hash.update(&self.carry[..from_carry]);
        self.carry.drain(..from_carry);
        left -= from_carry;
        let mut buf = vec![0u8; left.min(256 * 1024)];
        while left > 0 {
            let want = left.min(buf.len());
            match self.input.read(&mut buf[..want]) {
                Ok(0) => break,
                Ok(n) => {
                    hash.update(&buf[..n]);
                    left -= n;
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    self.pending = Some(Stop::Io(e));
                    return;
                }
            }
        }
        self.base = to;
        if left > 0 || hash.digest() != digest {
            self.pending = Some(Stop::Io(std::io::Error::other(
                "it changed while it was being read; run again",
            )));
        }
    }

    /// Appends up to `n` bytes of the input to `buf`; sets `eof` at the end of the input or a
    /// read error (kept in `failed`).
    fn read_more(&mut self, buf: &mut Vec<u8>, n: usize) {
        if self.eof {
            return;
        }
        buf.reserve(n.min(1 << 20));
        let want = u64::try_from(n).unwrap_or(u64::MAX);
        match (&mut self.input).take(want).read_to_end(buf) {
            Ok(got) if (got as u64) < want => self.eof = true,
            Ok(_) => {}
            Err(e) => {
                self.eof = true;
                self.failed = Some(e);
            }
        }
    }

    /// Fills `b` (emptied first) with the next events; after the end of the file or a stop,
    /// nothing more.
    pub(super) fn fill(&mut self, b: &mut Batch) {
        b.clear();
        if self.done {
            return;
        }
        if let Some(stop) = self.pending.take() {
            self.done = true;
            b.stop = Some(stop);
            return;
        }
        let mut bytes = std::mem::take(&mut b.text).into_bytes();
        bytes.clear();
        bytes.append(&mut self.carry);
        let mut want = self.batch_bytes;
        loop {
            if bytes.len() < want {
                let n = want - bytes.len();
                self.read_more(&mut bytes, n);
            }
            if !self.started {
                if bytes.len() < BOM.len() && !self.eof {
                    want = want.max(bytes.len()).saturating_mul(2);
                    continue;
                }
                self.started = true;
                if bytes.starts_with(BOM) {
                    self.done = true;
                    b.stop = Some(Stop::SecondBom);
                    return;
                }
            }
            // Where the piece is cut: at the end of the file, or before the last `<` (ASCII:
            // never inside a character).
            let mut cut = if self.eof {
                bytes.len()
            } else {
                match bytes.iter().rposition(|&c| c == b'<') {
                    Some(cut) if cut > 0 => cut,
                    _ => {
                        // Not one whole event yet.
                        want = want.max(bytes.len()).saturating_mul(2);
                        continue;
                    }
                }
            };
            // The split place, if this piece reaches it and it is a `<` (else it is not between
            // two events): the piece ends there.
            let mut forced = false;
            if let Some(s) = self.split {
                if s <= self.base || self.base + bytes.len() <= s {
                    if s <= self.base {
                        self.split = None;
                    }
                } else if s - self.base <= cut {
                    if bytes[s - self.base] == b'<' {
                        cut = s - self.base;
                        forced = true;
                    } else {
                        self.split = None;
                    }
                }
            }
            if u32::try_from(cut).is_err() {
                // Records keep offsets into the piece as `u32`; a piece this long is one event
                // of 4 GiB (a file may be that large only where its limit was raised).
                self.done = true;
                b.stop = Some(Stop::Syntax(
                    self.base,
                    "one XML event is 4 GiB or longer".to_owned(),
                ));
                return;
            }
            let mut tail = bytes.split_off(cut);
            // The UTF-8 is checked once, for the whole piece.
            let (final_piece, stop) = match String::from_utf8(bytes) {
                Ok(text) => {
                    b.text = text;
                    if forced {
                        (false, None)
                    } else {
                        (self.eof, self.failed.take().map(Stop::Io))
                    }
                }
                Err(e) => {
                    // The events end at the first byte that is not UTF-8, or at a character
                    // cut by the end of the file (not UTF-8) or by a read error (not known to
                    // be wrong: the read error is the reason).
                    let err = e.utf8_error();
                    let mut valid = e.into_bytes();
                    valid.truncate(err.valid_up_to());
                    b.text = String::from_utf8(valid).unwrap_or_default();
                    let stop = match self.failed.take() {
                        Some(io) if err.error_len().is_none() => Stop::Io(io),
                        _ => Stop::NotUtf8,
                    };
                    (true, Some(stop))
                }
            };
            match self.parse(b, final_piece, stop) {
                Piece::Parsed => {
                    if !self.done {
                        self.base += b.text.len();
                        self.carry = tail;
                        if forced {
                            // Between two events: marked if no open element keeps text (the
                            // other half starts without).
                            b.split = self.keeping == 0 && b.stop.is_none();
                            self.split = None;
                        }
                    }
                    return;
                }
                Piece::Cut(at) if at > 0 => {
                    if forced {
                        // Inside an event: no split.
                        self.split = None;
                    }
                    // Some events were made; the cut one goes to the next piece.
                    let mut carry = b.text.as_bytes()[at..].to_vec();
                    carry.append(&mut tail);
                    b.text.truncate(at);
                    self.base += at;
                    self.carry = carry;
                    return;
                }
                Piece::Cut(_) => {
                    if forced {
                        self.split = None;
                    }
                    // Not one whole event yet: read more (twice as much each time, so an event
                    // of any length is parsed a bounded number of times).
                    bytes = std::mem::take(&mut b.text).into_bytes();
                    bytes.append(&mut tail);
                    b.recs.clear();
                    want = want.max(bytes.len()).saturating_mul(2);
                }
            }
        }
    }

    /// Makes the events of `b.text`, a piece starting at `self.base`. In the last piece of the
    /// file (`final_piece`) the end of the text is the end of the events, with `stop` the
    /// reason if they stopped early.
    fn parse(&mut self, b: &mut Batch, final_piece: bool, stop: Option<Stop>) -> Piece {
        let text = b.text.as_str();
        let base = self.base;
        b.base = base;
        // Offsets into the piece: it is shorter than 4 GiB (`fill`).
        debug_assert!(u32::try_from(text.len()).is_ok());
        let off = |i: usize| i as u32;
        let mut stop = stop;
        // Where the next event starts.
        let mut pos = 0;
        loop {
            let at = pos;
            if self.keeping == 0 {
                // White space up to the next markup, reference or end, where no open element
                // keeps text: not recorded (the reader would pass over it). A byte loop, as for
                // an end tag's name below: quick-xml's `trim_xml_start`/`_end` over a slice cost
                // more (docs/PERFORMANCE.md, "What was tried and not kept").
                let bytes = text.as_bytes();
                let mut i = at;
                while i < bytes.len() && is_whitespace(bytes[i]) {
                    i += 1;
                }
                if i > at && bytes.get(i).is_none_or(|&c| c == b'<' || c == b'&') {
                    pos = i;
                    continue;
                }
            }
            let (ev, end) = match plain_event(text, at) {
                Some(plain) => plain,
                None => {
                    // Anything else is quick-xml's, one event from its `<` or `&`.
                    let mut reader = quick_xml::Reader::from_str(&text[at..]);
                    let config = reader.config_mut();
                    config.check_end_names = false;
                    config.allow_unmatched_ends = true;
                    let ev = reader.read_event();
                    let end = at + reader.buffer_position() as usize;
                    match ev {
                        Ok(ev) => (Ev::of(&ev, text), end),
                        Err(e) => {
                            // An event that runs to the end of the piece.
                            let at_cut = runs_to_end(
                                &e,
                                at,
                                end,
                                text.len(),
                                matches!(stop, Some(Stop::NotUtf8)),
                            );
                            if at_cut && !final_piece {
                                return Piece::Cut(at);
                            }
                            self.done = true;
                            b.stop = if at_cut && stop.is_some() {
                                // The file stops being UTF-8 or readable inside this event.
                                stop.take()
                            } else {
                                let error_at = at + reader.error_position() as usize;
                                Some(match e {
                                    quick_xml::Error::Io(e) => {
                                        Stop::Io(std::io::Error::new(e.kind(), e.to_string()))
                                    }
                                    e => Stop::Syntax(base + error_at, e.to_string()),
                                })
                            };
                            return Piece::Parsed;
                        }
                    }
                }
            };
            pos = end;
            let mut rec = Rec {
                kind: Kind::Eof,
                tag: Tag::Other,
                local: 0,
                at: off(at),
                end: off(end),
                text: 0,
                text_end: 0,
                name_len: 0,
            };
            match ev {
                Ev::Tag {
                    empty,
                    content,
                    name_len,
                    local,
                } => {
                    let name = &text[content.start..content.start + name_len];
                    let local = match local {
                        Some(l) => l,
                        None => name_len - local_part(name).len(),
                    };
                    rec.tag = Tag::of(&name[local..]);
                    (rec.text, rec.text_end) = (off(content.start), off(content.end));
                    rec.name_len = off(name_len);
                    rec.local = u16::try_from(local).unwrap_or(u16::MAX);
                    if empty {
                        rec.kind = Kind::Empty;
                    } else {
                        rec.kind = Kind::Start;
                        let keeps = rec.tag.keeps_text();
                        self.keeping += usize::from(keeps);
                        self.open_starts.push((self.open.len(), keeps));
                        self.open.push_str(name);
                    }
                }
                Ev::End(name) => {
                    rec.kind = Kind::End;
                    let found = &text[name];
                    let err = match self.open_starts.pop() {
                        Some((start, keeps)) => {
                            self.keeping -= usize::from(keeps);
                            let expected = &self.open[start..];
                            let err = (expected != found).then(|| {
                                quick_xml::errors::IllFormedError::MismatchedEndTag {
                                    expected: expected.to_owned(),
                                    found: found.to_owned(),
                                }
                            });
                            self.open.truncate(start);
                            err
                        }
                        None if self.part => {
                            // The end of the second half's elements: where the first half
                            // goes on.
                            rec.kind = Kind::PartEnd;
                            self.done = true;
                            b.recs.push(rec);
                            return Piece::Parsed;
                        }
                        None => Some(quick_xml::errors::IllFormedError::UnmatchedEndTag(
                            found.to_owned(),
                        )),
                    };
                    if let Some(err) = err {
                        // At the `<` of the end tag, as quick-xml reports it.
                        self.done = true;
                        b.stop = Some(Stop::Syntax(
                            base + at,
                            quick_xml::Error::IllFormed(err).to_string(),
                        ));
                        return Piece::Parsed;
                    }
                }
                // (A text is never cut: it ends at the `<` where the piece is cut.) The file
                // stops being UTF-8 or readable inside this text.
                Ev::Text(_) if end >= text.len() && stop.is_some() => {
                    self.done = true;
                    b.stop = stop.take();
                    return Piece::Parsed;
                }
                Ev::Text(raw) => {
                    rec.kind = Kind::Text;
                    (rec.text, rec.text_end) = (off(raw.start), off(raw.end));
                }
                Ev::CData(raw) => {
                    rec.kind = Kind::CData;
                    (rec.text, rec.text_end) = (off(raw.start), off(raw.end));
                }
                Ev::GeneralRef(raw) => {
                    rec.kind = Kind::GeneralRef;
                    (rec.text, rec.text_end) = (off(raw.start), off(raw.end));
                }
                Ev::DocType => rec.kind = Kind::DocType,
                Ev::Eof if !final_piece => return Piece::Parsed,
                Ev::Eof => {
                    self.done = true;
                    b.stop = stop.take();
                    if b.stop.is_some() {
                        return Piece::Parsed;
                    }
                }
                Ev::Skip => continue,
            }
            debug_assert!(
                rec.text_end as usize <= text.len(),
                "an event outside its piece"
            );
            let last = rec.kind == Kind::Eof;
            b.recs.push(rec);
            if last {
                return Piece::Parsed;
            }
        }
    }
}

/// One event of a piece, as offsets into it.
enum Ev {
    /// A start or empty tag: its content (name and attributes), the length of its name, and
    /// where the local name starts in it (`None`: not known, looked for).
    Tag {
        empty: bool,
        content: Range<usize>,
        name_len: usize,
        local: Option<usize>,
    },
    /// An end tag's name.
    End(Range<usize>),
    /// The raw content of a text, a CDATA section, a reference.
    Text(Range<usize>),
    CData(Range<usize>),
    GeneralRef(Range<usize>),
    DocType,
    Eof,
    /// Declarations, comments, processing instructions.
    Skip,
}

impl Ev {
    /// quick-xml's event `ev`, read from `text` (each part of it lies in `text`).
    fn of(ev: &Event<'_>, text: &str) -> Ev {
        // Where `s`, a part of `text`, lies in it.
        let range = |s: &str| {
            let start = (s.as_ptr() as usize).wrapping_sub(text.as_ptr() as usize);
            start..start + s.len()
        };
        match ev {
            Event::Start(e) | Event::Empty(e) => {
                let content: &str = e;
                Ev::Tag {
                    empty: matches!(ev, Event::Empty(_)),
                    content: range(content),
                    // The name is the start of the content.
                    name_len: e.name().as_ref().len().min(content.len()),
                    local: None,
                }
            }
            Event::End(e) => Ev::End(range(e.name().as_ref())),
            Event::Text(t) => Ev::Text(range(t)),
            Event::CData(t) => Ev::CData(range(t)),
            Event::GeneralRef(r) => Ev::GeneralRef(range(r)),
            Event::DocType(_) => Ev::DocType,
            Event::Eof => Ev::Eof,
            _ => Ev::Skip,
        }
    }
}

/// The event of `text` at `at` as quick-xml reads it (without end-name checks and with
/// unmatched ends allowed), and where it ends, for the events most of an SFC is made of: a
/// start, empty or end tag closed in `text`, a text without references, the end. `None` for
/// everything else (`<!`, `<?`, `&`, a tag not closed): quick-xml reads those.
///
/// quick-xml checks the UTF-8 of every event again, which the producer did once for the whole
/// piece (this was ~15 % of the producer's instructions), and its events are moved and read
/// again for their names; here one pass over a tag finds its name, local name and end.
/// `tests/tape.rs` and the `sfc` fuzz target hold the events to quick-xml's over the whole
/// text.
fn plain_event(text: &str, at: usize) -> Option<(Ev, usize)> {
    let b = text.as_bytes();
    let Some(&first) = b.get(at) else {
        return Some((Ev::Eof, at));
    };
    match first {
        b'<' => {
            let next = *b.get(at + 1)?;
            if next == b'!' || next == b'?' {
                return None;
            }
            // The name, up to white space or the `>` (a quote: below), and the last `:` in it.
            let mut i = at + 1;
            let mut colon = None;
            while let Some(&c) = b.get(i)
                && !is_whitespace(c)
                && !matches!(c, b'>' | b'"' | b'\'')
            {
                if c == b':' {
                    colon = Some(i);
                }
                i += 1;
            }
            let name_end = i;
            // The `>` outside quotes, from there (quick-xml's `ElementParser`, which reads end
            // tags too, and takes a quote anywhere after the `<`). A tag is short: a byte loop
            // outside quotes, and `memchr` for a value's closing quote only past a few bytes.
            let close = loop {
                let c = *b.get(i)?;
                if c == b'>' {
                    break i;
                }
                if c == b'"' || c == b'\'' {
                    let from = i + 1;
                    let head = b.get(from..(from + 8).min(b.len()))?;
                    i = match head.iter().position(|&q| q == c) {
                        Some(k) => from + k,
                        None => from + 8 + memchr::memchr(c, b.get(from + 8..)?)?,
                    };
                }
                i += 1;
            };
            let ev = if next == b'/' {
                // The name without the white space after it.
                let mut last = close;
                while last > at + 2 && is_whitespace(b[last - 1]) {
                    last -= 1;
                }
                Ev::End(at + 2..last)
            } else {
                let empty = close - at >= 2 && b[close - 1] == b'/';
                let content = at + 1..close - usize::from(empty);
                if b[name_end] == b'"' || b[name_end] == b'\'' {
                    // The name ends at the first white space of the content (quick-xml's
                    // `name_len`), after the quote.
                    Ev::Tag {
                        empty,
                        name_len: quick_xml::utils::name_len(&b[content.clone()]),
                        content,
                        local: None,
                    }
                } else {
                    // (Without the `/` of an empty tag, which is not a `:`.)
                    let name_len = (name_end - at - 1).min(content.len());
                    Ev::Tag {
                        empty,
                        content,
                        name_len,
                        local: Some(colon.map_or(0, |c| c - at)),
                    }
                }
            };
            Some((ev, close + 1))
        }
        b'&' => None,
        _ => {
            let end = memchr::memchr2(b'<', b'&', &b[at..]).map_or(b.len(), |i| at + i);
            Some((Ev::Text(at..end), end))
        }
    }
}

/// Whether quick-xml stopped at `e` because its input ended inside the event from `at` (the
/// input is `len` bytes; `end` is where the reader stopped).
/// `next_not_utf8`: the input goes on with a byte that is not UTF-8.
fn runs_to_end(
    e: &quick_xml::Error,
    at: usize,
    end: usize,
    len: usize,
    next_not_utf8: bool,
) -> bool {
    use quick_xml::errors::SyntaxError;
    end >= len
        || match e {
            // `<!` and then the end: the byte that says what it is, is still to come (unless
            // it is known not to be UTF-8, so not one of those quick-xml looks for).
            quick_xml::Error::Syntax(SyntaxError::InvalidBangMarkup) => {
                at + 2 >= len && !next_not_utf8
            }
            // The others: markup not closed before the end of the input.
            quick_xml::Error::Syntax(_) => true,
            _ => false,
        }
}
