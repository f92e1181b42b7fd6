//! The lines of a file whose text is not kept (the streamed SFC: 78 MB for 100,000 steps) that
//! diagnostics point into, collected by reading the file once more as a stream.
//!
//! [`Collector`] is fed the file's bytes in pieces of any size and keeps, for every place asked
//! for, the part of its line around it (at most [`WINDOW`] bytes either side, so a file that is
//! one long line costs no more) and the start of the line after it (the renderer shows a single
//! line between two places rather than `...`). Everything else passes through counted, never
//! held: lines, the characters of the line being read (for columns), the length and the hash
//! ([`crate::load::hash_bytes`]) that tell whether the bytes are still those the compile read.
//!
//! Offsets are the file's, after its byte-order mark, like every [`crate::diag::Span`].

/// Bytes kept on either side of a place on its line.
pub const WINDOW: usize = 512;

/// A piece of a line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Excerpt {
    /// 0-based line number.
    pub line: usize,
    /// File offset of the first byte of `text`.
    pub start: usize,
    /// Characters on the line before `text` (0 unless a long line was cut).
    pub col0: usize,
    /// The bytes kept, without the line break; bytes that are not UTF-8 read as `?` each, so
    /// offsets into the text are offsets into the file.
    pub text: String,
}

/// The pieces of a file's lines that were kept, in file order, not overlapping.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Excerpts {
    pieces: Vec<Excerpt>,
}

impl Excerpts {
    /// The piece that holds `offset` (its end included: a place may be the line break, or the
    /// end of the file).
    pub fn find(&self, offset: usize) -> Option<&Excerpt> {
        self.find_index(offset).map(|i| &self.pieces[i])
    }

    /// The index in [`Excerpts::pieces`] of the piece that holds `offset`.
    pub fn find_index(&self, offset: usize) -> Option<usize> {
        let i = self
            .pieces
            .partition_point(|e| e.start <= offset)
            .checked_sub(1)?;
        let e = &self.pieces[i];
        (offset <= e.start + e.text.len()).then_some(i)
    }

    /// All pieces, in file order (a long line may have more than one).
    pub fn pieces(&self) -> &[Excerpt] {
        &self.pieces
    }

    /// All pieces, in file order.
    pub fn iter(&self) -> impl Iterator<Item = &Excerpt> {
        self.pieces.iter()
    }

    /// The first piece of line `line` (0-based), if one was kept.
    pub fn of_line(&self, line: usize) -> Option<&Excerpt> {
        let i = self.pieces.partition_point(|e| e.line < line);
        self.pieces.get(i).filter(|e| e.line == line)
    }

    /// 1-based line and column (in characters) of `offset`, if a piece holds it.
    pub fn line_col(&self, offset: usize) -> Option<(usize, usize)> {
        let e = self.find(offset)?;
        let before = e.text.get(..offset - e.start)?;
        Some((e.line + 1, e.col0 + before.chars().count() + 1))
    }
}

/// The window being kept.
struct Window {
    line: usize,
    start: usize,
    col0: usize,
    bytes: Vec<u8>,
    /// Where it ends at the latest (exclusive), unless a place inside moves it on.
    until: usize,
    /// It is wanted: it holds a place, or it is the line after one.
    keep: bool,
    holds_place: bool,
}

/// Reads a file's bytes (as they come, the mark included) and keeps the pieces of the lines
/// around `places`.
pub struct Collector {
    places: Vec<usize>,
    /// The next place not yet inside a window.
    next: usize,
    bom: bool,
    /// Bytes seen, the mark included.
    raw_len: usize,
    hash: crate::load::ContentHash,
    /// File offset (after the mark) of the next byte.
    pos: usize,
    line: usize,
    /// Characters of the current line before `pos`.
    chars: usize,
    at_line_start: bool,
    want_next_line: bool,
    window: Option<Window>,
    /// The mark's bytes seen so far (it may come in pieces).
    head: Vec<u8>,
    /// The buffer of the window being kept, between windows.
    spare: Vec<u8>,
    out: Vec<Excerpt>,
}

/// What [`Collector::finish`] found: the pieces, and the length and hash of all bytes.
pub struct Collected {
    pub excerpts: Excerpts,
    pub len: usize,
    pub hash: u64,
}

impl Collector {
    /// `places`: file offsets (after the mark) to keep; `bom`: whether the file had a
    /// byte-order mark (its first three bytes are then not counted as text).
    pub fn new(mut places: Vec<usize>, bom: bool) -> Self {
        places.sort_unstable();
        places.dedup();
        Collector {
            places,
            next: 0,
            bom,
            raw_len: 0,
            hash: crate::load::ContentHash::new(),
            pos: 0,
            line: 0,
            chars: 0,
            at_line_start: true,
            want_next_line: false,
            window: None,
            head: Vec::new(),
            spare: Vec::new(),
            out: Vec::new(),
        }
    }

    /// The next bytes of the file.
    pub fn feed(&mut self, mut bytes: &[u8]) {
        self.raw_len += bytes.len();
        self.hash.update(bytes);
        if self.bom && self.head.len() < 3 {
            let n = (3 - self.head.len()).min(bytes.len());
            self.head.extend_from_slice(&bytes[..n]);
            bytes = &bytes[n..];
        }
        while !bytes.is_empty() {
            let n = self.step(bytes);
            bytes = &bytes[n..];
        }
    }

    /// Whether every place's lines are kept: the bytes after change nothing kept.
    pub fn done(&self) -> bool {
        self.next >= self.places.len() && self.window.is_none() && !self.want_next_line
    }

    /// The bytes fed so far, the mark included.
    pub fn fed(&self) -> usize {
        self.raw_len
    }

    /// [`crate::load::ContentHash::prefixes`] of the bytes fed so far.
    pub fn prefixes(&self) -> &[u64] {
        self.hash.prefixes()
    }

    /// The end of the file.
    pub fn finish(mut self) -> Collected {
        // The line after a place's line may be the empty one after a final line break.
        if self.window.is_none() && self.want_next_line && self.at_line_start {
            self.open(0, true);
        }
        // Places at the very end (or past it) belong to the last line.
        if self.next < self.places.len() {
            if self.window.is_none() {
                self.open(WINDOW, false);
            }
            let w = self.window.as_mut().expect("opened");
            w.keep = true;
            w.holds_place = true;
            self.next = self.places.len();
        }
        self.close();
        Collected {
            excerpts: Excerpts { pieces: self.out },
            len: self.raw_len,
            hash: self.hash.finish(),
        }
    }

    /// Reads from the start of `bytes` up to the next thing to do; returns how many bytes it
    /// took (at least one).
    fn step(&mut self, bytes: &[u8]) -> usize {
        if self.at_line_start && self.want_next_line && self.window.is_none() {
            self.want_next_line = false;
            self.open(2 * WINDOW, true);
        }
        if self.window.is_none() {
            // Where the next place's window opens: `WINDOW` before it, not before its line.
            let Some(&place) = self.places.get(self.next) else {
                if !self.want_next_line {
                    // Nothing more to keep: the rest only counts for the length and hash.
                    self.pos += bytes.len();
                    return bytes.len();
                }
                return self.skip(bytes, bytes.len());
            };
            let open_at = place.saturating_sub(WINDOW);
            if self.pos < open_at {
                return self.skip(bytes, open_at - self.pos);
            }
            if is_continuation(bytes[0]) {
                // Not in the middle of a character.
                return self.skip(bytes, 1);
            }
            self.open(WINDOW, false);
        }
        self.keep_bytes(bytes)
    }

    /// Passes over at most `n` bytes (stopping after a line break when the line after one is
    /// wanted), counting lines and characters.
    fn skip(&mut self, bytes: &[u8], n: usize) -> usize {
        let mut seg = &bytes[..n.min(bytes.len())];
        if self.want_next_line
            && let Some(i) = seg.iter().position(|&b| b == b'\n')
        {
            seg = &seg[..=i];
        }
        match seg.iter().rposition(|&b| b == b'\n') {
            Some(last) => {
                self.line += seg[..=last].iter().filter(|&&b| b == b'\n').count();
                self.chars = count_chars(&seg[last + 1..]);
                self.at_line_start = last + 1 == seg.len();
            }
            None => {
                self.chars += count_chars(seg);
                self.at_line_start = false;
            }
        }
        self.pos += seg.len();
        seg.len()
    }

    fn open(&mut self, len: usize, keep: bool) {
        self.window = Some(Window {
            line: self.line,
            start: self.pos,
            col0: self.chars,
            // One buffer for every window: a piece's text is then allocated once, at its size.
            bytes: std::mem::take(&mut self.spare),
            until: self.pos + len,
            keep,
            holds_place: false,
        });
    }

    /// Adds bytes to the open window up to its end, the end of the line or of `bytes`; in runs
    /// up to the next place, the window's end or a line break, not byte by byte.
    fn keep_bytes(&mut self, bytes: &[u8]) -> usize {
        let w = self.window.as_mut().expect("a window is open");
        let mut taken = 0;
        loop {
            // The places at or before the next byte are inside the window.
            while let Some(&p) = self.places.get(self.next)
                && p <= self.pos
            {
                w.until = w.until.max(p + WINDOW);
                w.keep = true;
                w.holds_place = true;
                self.next += 1;
            }
            let rest = &bytes[taken..];
            let Some(&first) = rest.first() else {
                return taken;
            };
            let mut run = rest.len().min(w.until.saturating_sub(self.pos));
            if let Some(&p) = self.places.get(self.next) {
                run = run.min(p - self.pos);
            }
            if run == 0 {
                // The window's end: at the line break, else on a character's first byte.
                if first != b'\n' && !is_continuation(first) {
                    self.close();
                    return taken;
                }
                run = 1;
            }
            let seg = &rest[..run];
            match seg.iter().position(|&b| b == b'\n') {
                Some(i) => {
                    w.bytes.extend_from_slice(&seg[..i]);
                    taken += i + 1;
                    self.pos += i + 1;
                    self.line += 1;
                    self.chars = 0;
                    self.at_line_start = true;
                    self.close();
                    return taken;
                }
                None => {
                    w.bytes.extend_from_slice(seg);
                    taken += run;
                    self.pos += run;
                    self.chars += count_chars(seg);
                    self.at_line_start = false;
                }
            }
        }
    }

    fn close(&mut self) {
        let Some(mut w) = self.window.take() else {
            return;
        };
        if w.holds_place {
            self.want_next_line = true;
        }
        if w.keep {
            self.out.push(Excerpt {
                line: w.line,
                start: w.start,
                col0: w.col0,
                text: text_keeping_offsets(w.bytes.to_vec()),
            });
        }
        w.bytes.clear();
        self.spare = w.bytes;
    }
}

fn is_continuation(b: u8) -> bool {
    b & 0xC0 == 0x80
}

fn count_chars(b: &[u8]) -> usize {
    b.iter().filter(|&&b| !is_continuation(b)).count()
}

/// The bytes as text, each byte of an invalid sequence read as `?` (so offsets stay).
fn text_keeping_offsets(mut bytes: Vec<u8>) -> String {
    let mut from = 0;
    loop {
        match std::str::from_utf8(&bytes[from..]) {
            Ok(_) => break,
            Err(e) => {
                let bad = from + e.valid_up_to();
                let n = e.error_len().unwrap_or(bytes.len() - bad);
                for b in &mut bytes[bad..bad + n] {
                    *b = b'?';
                }
                from = bad + n;
            }
        }
    }
    String::from_utf8(bytes).expect("every invalid byte replaced")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Collects `text` fed in pieces of `piece` bytes.
    fn collect(text: &[u8], places: &[usize], bom: bool, piece: usize) -> Collected {
        let mut c = Collector::new(places.to_vec(), bom);
        for chunk in text.chunks(piece.max(1)) {
            c.feed(chunk);
        }
        c.finish()
    }

    fn lines(c: &Collected) -> Vec<(usize, usize, usize, &str)> {
        c.excerpts
            .iter()
            .map(|e| (e.line, e.start, e.col0, e.text.as_str()))
            .collect()
    }

    #[test]
    fn keeps_the_lines_of_the_places_and_the_line_after() {
        let text = b"zero\none\ntwo\nthree\nfour\n";
        for piece in [1, 2, 3, 7, 100] {
            let c = collect(text, &[10], false, piece);
            assert_eq!(
                lines(&c),
                vec![(2, 9, 0, "two"), (3, 13, 0, "three")],
                "piece {piece}"
            );
            assert_eq!(c.excerpts.line_col(10), Some((3, 2)));
            assert_eq!(c.len, text.len());
            assert_eq!(c.hash, crate::load::hash_bytes(text));
        }
    }

    #[test]
    fn places_on_neighbouring_lines_share_pieces() {
        let text = b"a\nb\nc\nd\ne";
        let c = collect(text, &[0, 4, 8], false, 3);
        assert_eq!(
            lines(&c),
            vec![
                (0, 0, 0, "a"),
                (1, 2, 0, "b"),
                (2, 4, 0, "c"),
                (3, 6, 0, "d"),
                (4, 8, 0, "e")
            ]
        );
    }

    #[test]
    fn a_place_at_the_end_of_the_file() {
        let c = collect(b"ab\ncd", &[5], false, 2);
        assert_eq!(lines(&c), vec![(1, 3, 0, "cd")]);
        assert_eq!(c.excerpts.line_col(5), Some((2, 3)));
        // After a final line break: the empty last line.
        let c = collect(b"ab\n", &[3], false, 1);
        assert_eq!(lines(&c), vec![(1, 3, 0, "")]);
        assert_eq!(c.excerpts.line_col(3), Some((2, 1)));
        // A place on a line break belongs to its line.
        let c = collect(b"ab\ncd\n", &[2], false, 4);
        assert_eq!(c.excerpts.line_col(2), Some((1, 3)));
    }

    #[test]
    fn a_long_line_is_cut_around_the_place_on_character_boundaries() {
        let mut text = "ä".repeat(2000).into_bytes();
        text.extend_from_slice(b"X\nnext");
        let place = 4000;
        for piece in [1, 5, 4096] {
            let c = collect(&text, &[place], false, piece);
            let e = c.excerpts.find(place).expect("kept");
            assert!(e.text.len() <= 2 * WINDOW + 4, "{}", e.text.len());
            assert!(e.start > 0 && e.start <= place - WINDOW + 1);
            assert_eq!(c.excerpts.line_col(place), Some((1, 2001)), "piece {piece}");
            // The line after is there too.
            assert_eq!(c.excerpts.of_line(1).map(|e| e.text.as_str()), Some("next"));
        }
    }

    #[test]
    fn the_mark_is_hashed_but_not_counted() {
        let text = b"\xEF\xBB\xBFab\ncd";
        for piece in [1, 2, 10] {
            let c = collect(text, &[3], true, piece);
            assert_eq!(lines(&c), vec![(1, 3, 0, "cd")], "piece {piece}");
            assert_eq!(c.len, text.len());
            assert_eq!(c.hash, crate::load::hash_bytes(text));
        }
    }

    #[test]
    fn bytes_that_are_not_utf8_keep_their_offsets() {
        let c = collect(b"a\xFF\xFEb\n", &[3], false, 2);
        // With the (empty) line after it.
        assert_eq!(lines(&c), vec![(0, 0, 0, "a??b"), (1, 5, 0, "")]);
        assert_eq!(c.excerpts.line_col(3), Some((1, 4)));
    }

    use proptest::prelude::*;

    proptest! {
        /// Against the whole text: every place is in a piece, with the line and column counted
        /// over the whole text; every piece is the text at its offsets; the line after a place's
        /// line is there (its start); the length and hash are the whole text's. Texts of a few
        /// bytes (line breaks, multi-byte and invalid bytes) and long lines, fed in pieces of
        /// any size.
        #[test]
        fn pieces_agree_with_the_whole_text(
            parts in proptest::collection::vec(
                prop_oneof![
                    Just("\n".to_owned()),
                    Just("ä".to_owned()),
                    Just("\u{1F600}".to_owned()),
                    "[a-c]{1,3}",
                    (1usize..1500).prop_map(|n| "x".repeat(n)),
                ],
                0..40,
            ),
            bad in proptest::option::of(0usize..1000),
            places in proptest::collection::vec(0usize..4000, 0..6),
            piece in 1usize..300,
        ) {
            let mut text: Vec<u8> = parts.concat().into_bytes();
            if let Some(b) = bad.filter(|&b| b < text.len()) {
                text[b] = 0xFF;
            }
            let len = text.len();
            let places: Vec<usize> = places.into_iter().map(|p| p.min(len)).collect();
            let c = collect(&text, &places, false, piece);
            prop_assert_eq!(c.len, len);
            prop_assert_eq!(c.hash, crate::load::hash_bytes(&text));
            let shown = text_keeping_offsets(text.clone());
            for e in c.excerpts.iter() {
                prop_assert_eq!(&shown[e.start..e.start + e.text.len()], e.text.as_str());
                prop_assert!(!e.text.contains('\n'));
            }
            for &p in &places {
                // Where the place starts a character (the stream may name any byte).
                let p = (0..=p).rev().find(|&q| shown.is_char_boundary(q)).unwrap_or(0);
                let line = shown[..p].matches('\n').count();
                let line_start = shown[..p].rfind('\n').map_or(0, |i| i + 1);
                let col = shown[line_start..p].chars().count();
                let got = c.excerpts.line_col(p);
                prop_assert_eq!(got.map(|g| g.0), Some(line + 1), "place {}", p);
                // Columns count characters; after bytes that are not UTF-8 on the same line
                // they are approximate (such a file is refused whole, E101, and its text kept).
                if std::str::from_utf8(&text).is_ok() {
                    prop_assert_eq!(got, Some((line + 1, col + 1)), "place {}", p);
                }
                if let Some(next) = shown[p..].find('\n').map(|i| p + i + 1) {
                    let e = c.excerpts.find(next);
                    prop_assert!(e.is_some_and(|e| e.line == line + 1), "line after {}", p);
                }
            }
        }
    }

    #[test]
    fn no_places_no_pieces() {
        let c = collect(b"abc\ndef", &[], false, 2);
        assert!(c.excerpts.iter().next().is_none());
        assert_eq!(c.len, 7);
    }
}
