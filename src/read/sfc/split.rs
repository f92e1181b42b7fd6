//! A large SFC read in two halves at once.
//!
//! Reading is the longest stage of a large compile, and its reader (the model built from the
//! events) keeps one core busy while the producer (the events made from the text) leaves
//! part of the other idle. So a file of [`SPLIT_FROM`] bytes or more is read in two halves at
//! once, each on its own thread:
//!
//! - The split place `S` is the first `<step` or `<transition` start tag from [`SHARE`] of
//!   the file on, found by reading a little there ([`choose`]).
//! - The second half is read from `S` on its own thread (`read_part`), through a second reader
//!   of the same open file ([`crate::load::ReadAt`]). It assumes it starts directly inside the
//!   SFC body of a POU (`project/types/pous/pou/body/SFC`, [`ASSUMED`]), with no element open
//!   that keeps text, and its events end at the end tag that closes that SFC (`E`). It gives up
//!   (its result is dropped) on anything it cannot read alone: a syntax error or a DTD, a
//!   macro step's body, an element the reader ignores or keeps for a wired condition, a wired
//!   condition. A condition that names a transition is read as the name of a signal, as it is
//!   in a POU without named transitions: the first half takes the result only if its POU has
//!   none.
//! - The first half is the reading as it would be, with its batches ending at `S`
//!   (`Batch::split`: only if `S` is between two events and no open element keeps text). There
//!   the reader takes the second half's result only if it is where the second half assumed it
//!   started: directly inside the SFC body of the POU it reads, not inside an element, a macro
//!   step's body or an action. Then the second half's elements, their variables and diagnostics
//!   are appended to its own, and the producer goes on at `E`, reading the bytes in between
//!   (so whatever counts and hashes the input sees the whole file) and checking that their
//!   hash is the second half's: else the file changed between the two readings, and the
//!   reading stops with that error. In every other case it reads on from `S` itself.
//!
//! The end tag at `E` is the one a reading from the start would find there: the second half's
//! events are balanced, so the elements open at `E` are those open at `S`. The first half's
//! producer checks its name as it always does. The model and the diagnostics are the same
//! either way (`tests/sfc_split.rs` compares them with `S` at every place of files that
//! exercise all of the above; the `sfc` fuzz target with `S` anywhere).

use std::io::BufRead;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Receiver;

use super::tape::{self, Decision, Pipeline, Tape};
use super::{Outcome, Stream, StreamError, Tag};

use crate::diag::{Diagnostic, Diagnostics, FileId};
use crate::load::ReadAt;
use crate::model::{Element, ElementKind, Sfc, Variable};

/// Files from this size on are read in two halves (when the file can be read at any place).
pub const SPLIT_FROM: u64 = 8 << 20;

/// Where, in percent of the file, the second half begins. The first half's producer and reader
/// run on two threads and the second half's on one, so the first gets a little more.
pub const SHARE: u64 = 50;

/// How far from [`SHARE`] the split place is looked for.
const LOOK: usize = 64 * 1024;

/// The elements the second half assumes open where it starts.
pub(super) const ASSUMED: [(Tag, &str); 6] = [
    (Tag::Project, "project"),
    (Tag::Types, "types"),
    (Tag::Pous, "pous"),
    (Tag::Pou, "pou"),
    (Tag::Body, "body"),
    (Tag::Sfc, "SFC"),
];

/// A second reader of the SFC's file, for reading it in two halves.
#[doc(hidden)]
pub struct SplitSource<'a> {
    pub source: &'a dyn ReadAt,
    /// The bytes before the stream's first (a byte-order mark).
    pub skipped: u64,
    /// The split place (a stream offset); `None`: chosen ([`choose`]) for a file of
    /// [`SPLIT_FROM`] bytes or more.
    pub at: Option<usize>,
    /// Set when the second half's result was taken (for the tests).
    pub joined: Option<&'a AtomicBool>,
}

/// Reads the SFC from `input` as the compile does: on two threads from 1 MiB, in two halves
/// from [`SPLIT_FROM`] when `at` (a second reader of the same open file, and the bytes before
/// the stream's first) is given. See [`super::read_sfc_stream`].
pub fn read_sfc_file<R: BufRead + Send>(
    input: R,
    at: Option<(&dyn ReadAt, u64)>,
    file: FileId,
    len_hint: u64,
    pou: Option<&str>,
    diags: &mut Diagnostics,
) -> Result<Option<Sfc>, StreamError> {
    let split = at.map(|(source, skipped)| SplitSource {
        source,
        skipped,
        at: None,
        joined: None,
    });
    super::read_sfc_stream_split(
        input,
        file,
        len_hint,
        pou,
        diags,
        Pipeline::choose(len_hint),
        tape::BATCH_BYTES,
        split,
    )
}

/// The split place for a file of `len` bytes (a stream offset), if it is large enough and one
/// is found near [`SHARE`] of it.
fn choose(source: &dyn ReadAt, skipped: u64, len: u64) -> Option<usize> {
    if len < SPLIT_FROM {
        return None;
    }
    let from = len / 100 * SHARE;
    let mut buf = vec![0u8; LOOK];
    let mut got = 0;
    while got < buf.len() {
        match source.read_at(&mut buf[got..], skipped + from + got as u64) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(_) => return None,
        }
    }
    let buf = &buf[..got];
    let start = |i: usize, tag: &[u8]| {
        buf[i..].starts_with(tag)
            && buf
                .get(i + tag.len())
                .is_some_and(|&c| quick_xml::utils::is_whitespace(c))
    };
    let i =
        memchr::memchr_iter(b'<', buf).find(|&i| start(i, b"<step") || start(i, b"<transition"))?;
    usize::try_from(from).ok()?.checked_add(i)
}

/// Where the first half gets the second half's result.
pub(super) struct Link {
    result: Receiver<Option<Part>>,
    cancel: Arc<AtomicBool>,
}

/// The second half's reading.
pub(super) struct Part {
    elements: Vec<Element>,
    variables: Vec<Variable>,
    values: String,
    diags: Vec<Diagnostic>,
    /// Where its events ended (the end tag of the SFC), and the hash of its bytes.
    end: usize,
    digest: u64,
}

/// Runs `consume` (the first half's reading by `r`) over the events of `input`, and when
/// `split` says so the second half on a thread of its own.
pub(super) fn read_halves<R: BufRead + Send, T>(
    r: &mut Stream,
    input: R,
    len_hint: u64,
    pipeline: Pipeline,
    batch_bytes: usize,
    split: Option<SplitSource<'_>>,
    consume: impl FnOnce(&mut Stream, &mut dyn Tape) -> T,
) -> T {
    let Some((split, at)) = split.and_then(|s| {
        let at = s.at.or_else(|| choose(s.source, s.skipped, len_hint))?;
        Some((s, at))
    }) else {
        return tape::read(input, pipeline, batch_bytes, None, |t| consume(r, t));
    };
    let len = usize::try_from(len_hint).unwrap_or(usize::MAX);
    let cancel = Arc::new(AtomicBool::new(false));
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    let file = r.file;
    let split_joined = split.joined;
    std::thread::scope(|s| {
        let stop = cancel.clone();
        let started = std::thread::Builder::new()
            .name("skillpost-sfc-half".into())
            .spawn_scoped(s, move || {
                let part = read_part(&split, at, len, batch_bytes, file, &stop);
                let _ = tx.send(part);
            });
        let at = match started {
            Ok(_) => {
                r.part = Some(Link {
                    result: rx,
                    cancel: cancel.clone(),
                });
                Some(at)
            }
            Err(_) => None,
        };
        let out = tape::read(input, pipeline, batch_bytes, at, |t| consume(r, t));
        // Done (or stopped before the split place): the second half is not wanted any more.
        cancel.store(true, Ordering::Relaxed);
        r.part = None;
        if let Some(j) = split_joined {
            j.store(r.part_joined, Ordering::Relaxed);
        }
        out
    })
}

/// The second half, from `at` to the end tag of the SFC it starts in.
fn read_part(
    split: &SplitSource<'_>,
    at: usize,
    len: usize,
    batch_bytes: usize,
    file: FileId,
    cancel: &AtomicBool,
) -> Option<Part> {
    let mut r = Stream::new(file, None, len.saturating_sub(at));
    r.is_part = true;
    let mut local = Diagnostics::default();
    let (outcome, end) = tape::read_part(
        split.source,
        split.skipped,
        at,
        len,
        batch_bytes,
        Pipeline::Threaded,
        cancel,
        |t| r.run(t, &mut local),
    );
    let Ok(Ok(Outcome::Part(elements))) = outcome else {
        return None;
    };
    let (end, digest) = end?;
    // What it cannot have read as the first half would have.
    let alone = r.wire_nodes.is_empty()
        && r.pending_wired.is_empty()
        && r.ignored.is_empty()
        && r.derived_text == 0
        && !r.derived_refused
        && r.named.is_empty();
    alone.then(|| Part {
        elements,
        variables: std::mem::take(&mut r.variables),
        values: std::mem::take(&mut r.values),
        diags: local.into_vec(),
        end,
        digest,
    })
}

impl Stream {
    /// At the split place: the second half's result, if the first half is where the second
    /// assumed it started (`at_sfc`: directly inside the SFC body of the POU it reads) and its
    /// POU has no named transitions; then how the events go on (said before the result is
    /// appended, so the producer goes on meanwhile).
    pub(super) fn take_part(&mut self, at_sfc: bool) -> (Decision, Option<Part>) {
        let Some(link) = self.part.take() else {
            return (Decision::GoOn, None);
        };
        if !at_sfc || !self.named.is_empty() {
            link.cancel.store(true, Ordering::Relaxed);
            return (Decision::GoOn, None);
        }
        match link.result.recv() {
            Ok(Some(part)) => {
                self.part_joined = true;
                (
                    Decision::Skip {
                        to: part.end,
                        digest: part.digest,
                    },
                    Some(part),
                )
            }
            _ => (Decision::GoOn, None),
        }
    }

    /// The second half's elements, their variables and diagnostics appended to the first's
    /// (`els`: the SFC body's elements).
    pub(super) fn append_part(
        &mut self,
        part: Part,
        els: &mut Vec<Element>,
        diags: &mut Diagnostics,
    ) {
        let (vars, values) = (self.variables.len(), self.values.len());
        self.values.push_str(&part.values);
        self.variables
            .extend(part.variables.into_iter().map(|mut v| {
                v.raw = v.raw.start + values..v.raw.end + values;
                v
            }));
        els.reserve(part.elements.len());
        for mut el in part.elements {
            if let ElementKind::Step(step) = &mut el.kind {
                step.variables = step.variables.start + vars..step.variables.end + vars;
            }
            els.push(el);
        }
        for d in part.diags {
            diags.push(d);
        }
    }
}
