//! The SFC's XML events as a tape: what [`super::sfc`] needs of each event (kind, place, tag,
//! raw content), copied into batches.
//!
//! Tokenizing the XML and checking its UTF-8 is more than half of reading a large SFC. A `Producer` does that part; the SFC reader consumes the batches. For a large file the
//! producer runs on a second thread (`read` with [`Pipeline::Threaded`]), so the two halves run
//! side by side on two cores; for a small one it fills a batch whenever the reader asks
//! ([`Pipeline::Inline`]). Both give the same records: the reader cannot tell them apart, and the
//! tests compare the two.
//!
//! Batches are bounded (about [`BATCH_BYTES`] of text each, at most `QUEUE` waiting), so the
//! memory a read holds stays flat however large the file; emptied batches go back to the producer
//! to be filled again.
//!
//! Here: the records and batches, and the pipeline that runs the producer. `producer`: the
//! producer (a file's pieces, their UTF-8, their events). `attributes`: a tag's attributes, read
//! for the reader. `reference`: the records as text beside quick-xml's over the whole input,
//! for the tests and the fuzz target.

use std::io::BufRead;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender};

use super::sfc::Tag;

mod attributes;
mod producer;
mod reference;

pub use attributes::compare_attributes;
pub(crate) use attributes::each_attribute;
use producer::Producer;
pub use reference::{records_text, reference_text};

/// The text a batch holds before it is handed over (one event may make it longer).
pub const BATCH_BYTES: usize = 128 * 1024;
/// Filled batches waiting for the reader.
const QUEUE: usize = 4;
/// Files from this size on are tokenized on a second thread ([`Pipeline::choose`]).
pub const THREAD_FROM: u64 = 1 << 20;

/// How the events are produced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pipeline {
    /// In the reader's thread, a batch at a time.
    Inline,
    /// On a second thread, while the reader works on the batch before.
    Threaded,
}

impl Pipeline {
    /// Threaded for a file of [`THREAD_FROM`] bytes or more: below that, starting a thread costs
    /// more than it saves.
    pub fn choose(len_hint: u64) -> Pipeline {
        if len_hint >= THREAD_FROM {
            Pipeline::Threaded
        } else {
            Pipeline::Inline
        }
    }
}

/// The kinds of events the reader looks at (declarations, comments and processing instructions
/// are left out).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    Start,
    Empty,
    End,
    Text,
    CData,
    GeneralRef,
    DocType,
    Eof,
    /// The second half of a split reading ends here: at the end tag of an element opened
    /// before it.
    PartEnd,
}

/// One event, 24 bytes: the reader touches every record once, on the other core, so a record is
/// kept small. Offsets are into [`Batch::text`] (a piece is shorter than 4 GiB: `fill`); the
/// [`Batch`] turns them into file offsets and text.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Rec {
    pub kind: Kind,
    /// Of a start tag: its local name's tag.
    pub tag: Tag,
    /// Start and empty tags: where the local name starts in the qualified name (`u16::MAX`: not
    /// kept, a prefix that long is looked for again).
    local: u16,
    /// Where the event starts and ends in the piece.
    at: u32,
    end: u32,
    /// Start and empty tags: the tag's content (name and attributes, as the parser hands them
    /// out); text, CDATA, references: the raw content.
    text: u32,
    text_end: u32,
    /// Start and empty tags: the length of the qualified name, the start of the content.
    name_len: u32,
}

/// Why the events stopped before the end of the file.
#[derive(Debug)]
pub(crate) enum Stop {
    NotUtf8,
    Io(std::io::Error),
    /// Not well-formed XML: where, and the parser's words.
    Syntax(usize, String),
    /// The text starts with a byte-order mark: the caller strips one (the loader's), so this is
    /// a second one, which quick-xml would skip silently, shifting every place it reports.
    SecondBom,
}

/// Events, in file order.
#[derive(Debug, Default)]
pub(crate) struct Batch {
    pub text: String,
    /// The file offset of `text`'s first byte.
    base: usize,
    pub recs: Vec<Rec>,
    /// Set on the last batch when the events stopped early (the records come first).
    pub stop: Option<Stop>,
    /// The batch ends at the split place ([`Decision`]), between two events, where no open
    /// element keeps text: the reader says how to go on ([`Tape::decide`]) before it asks for
    /// the next batch.
    pub split: bool,
}

impl Batch {
    fn clear(&mut self) {
        self.text.clear();
        self.recs.clear();
        self.stop = None;
        self.split = false;
    }

    /// The file offset where `r` starts.
    #[inline]
    pub fn at(&self, r: &Rec) -> usize {
        self.base + r.at as usize
    }

    /// The file offset after `r`.
    #[inline]
    pub fn end(&self, r: &Rec) -> usize {
        self.base + r.end as usize
    }

    /// The raw content of `r` (see [`Rec`]).
    #[inline]
    pub fn text(&self, r: &Rec) -> &str {
        self.text
            .get(r.text as usize..r.text_end as usize)
            .unwrap_or_default()
    }

    /// Of a start or empty tag: its qualified name, its local name and its content.
    #[inline]
    pub fn names_and_content(&self, r: &Rec) -> (&str, &str, &str) {
        let content = self.text(r);
        let name = content.get(..r.name_len as usize).unwrap_or_default();
        let local = match name.get(r.local as usize..) {
            Some(local) if r.local != u16::MAX => local,
            _ => local_part(name),
        };
        (name, local, content)
    }
}

/// The part of a qualified name after its prefix (`xhtml:p` → `p`). Names are short: a byte
/// loop, not a `char` search.
pub(crate) fn local_part(name: &str) -> &str {
    match name.as_bytes().iter().rposition(|&b| b == b':') {
        // `:` is ASCII: the next byte starts a character.
        Some(i) => &name[i + 1..],
        None => name,
    }
}

/// How the events go on after a batch that ends at the split place ([`Batch::split`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Decision {
    /// From the split place.
    GoOn,
    /// From `to`: the other half read the bytes in between, whose hash was `digest`.
    Skip { to: usize, digest: u64 },
}

/// Where the reader gets its batches.
pub(crate) trait Tape {
    /// The next batch; `spent` is the one the reader is done with (its buffers are used again).
    /// After a batch that ends at the split place, without a decision: [`Decision::GoOn`].
    fn next(&mut self, spent: Batch) -> Batch;

    /// How to go on after the batch that ends at the split place (nothing at any other time).
    fn decide(&mut self, decision: Decision);
}

struct Inline<R> {
    producer: Producer<R>,
    awaiting: bool,
}

impl<R: std::io::Read> Tape for Inline<R> {
    fn next(&mut self, mut spent: Batch) -> Batch {
        self.awaiting = false;
        self.producer.fill(&mut spent);
        self.awaiting = spent.split;
        spent
    }

    fn decide(&mut self, decision: Decision) {
        if std::mem::take(&mut self.awaiting)
            && let Decision::Skip { to, digest } = decision
        {
            self.producer.skip(to, digest);
        }
    }
}

struct Threaded {
    filled: Receiver<Batch>,
    spent: SyncSender<Batch>,
    /// To the producer, which waits for it after a batch that ends at the split place.
    decisions: SyncSender<Decision>,
    awaiting: bool,
}

impl Tape for Threaded {
    fn next(&mut self, spent: Batch) -> Batch {
        self.decide(Decision::GoOn);
        // A full return queue drops the batch: the producer allocates another.
        let _ = self.spent.try_send(spent);
        let b = self.filled.recv().unwrap_or_else(|_| Batch {
            stop: Some(Stop::Io(std::io::Error::other(
                "the thread reading the file ended early",
            ))),
            ..Batch::default()
        });
        self.awaiting = b.split;
        b
    }

    fn decide(&mut self, decision: Decision) {
        if std::mem::take(&mut self.awaiting) {
            // (A producer that has ended has nothing to be told.)
            let _ = self.decisions.send(decision);
        }
    }
}

/// Runs `consume` over the events of `input`, produced as `pipeline` says. A second thread that
/// cannot be started leaves the work to this one.
/// `split`: the place where the batches end once, if it is between two events
/// ([`Batch::split`]).
pub(crate) fn read<R, T>(
    input: R,
    pipeline: Pipeline,
    batch_bytes: usize,
    split: Option<usize>,
    consume: impl FnOnce(&mut dyn Tape) -> T,
) -> T
where
    R: BufRead + Send,
{
    run(
        Producer::split_at(input, batch_bytes, split),
        pipeline,
        consume,
    )
}

/// Runs `consume` over the events of `producer`, made as `pipeline` says.
fn run<R, T>(
    producer: Producer<R>,
    pipeline: Pipeline,
    consume: impl FnOnce(&mut dyn Tape) -> T,
) -> T
where
    R: std::io::Read + Send,
{
    if pipeline == Pipeline::Inline {
        return consume(&mut Inline {
            producer,
            awaiting: false,
        });
    }
    let slot = std::sync::Mutex::new(Some(producer));
    std::thread::scope(|s| {
        let (filled_tx, filled) = std::sync::mpsc::sync_channel::<Batch>(QUEUE);
        let (spent, spent_rx) = std::sync::mpsc::sync_channel::<Batch>(QUEUE + 2);
        let (decisions, decisions_rx) = std::sync::mpsc::sync_channel::<Decision>(1);
        let slot_ref = &slot;
        let started = std::thread::Builder::new()
            .name("skillpost-sfc".into())
            .spawn_scoped(s, move || {
                let Some(mut p) = slot_ref.lock().ok().and_then(|mut g| g.take()) else {
                    return;
                };
                loop {
                    let mut b = spent_rx.try_recv().unwrap_or_default();
                    p.fill(&mut b);
                    let last = p.done;
                    let split = b.split;
                    // The reader stopped early (its own error): so does this thread.
                    if filled_tx.send(b).is_err() || last {
                        return;
                    }
                    if split {
                        // Nothing more until the reader has seen the batch and said how.
                        match decisions_rx.recv() {
                            Ok(Decision::Skip { to, digest }) => p.skip(to, digest),
                            Ok(Decision::GoOn) => {}
                            Err(_) => return,
                        }
                    }
                }
            });
        match started {
            Ok(producer) => {
                // (The `Threaded`, and with it the receiver, is dropped at the end of this
                // statement: a producer still sending stops, as the reader stopped early.)
                let out = consume(&mut Threaded {
                    filled,
                    spent,
                    decisions,
                    awaiting: false,
                });
                // The scope's own join waits only for the closure; joining the thread waits
                // for its end, thread-local storage and all, so nothing of it outlives the
                // reading (LeakSanitizer found its channel context still allocated).
                if let Err(panic) = producer.join() {
                    std::panic::resume_unwind(panic);
                }
                out
            }
            Err(_) => {
                let producer = slot
                    .lock()
                    .ok()
                    .and_then(|mut g| g.take())
                    .expect("the thread did not start, so it did not take the producer");
                consume(&mut Inline {
                    producer,
                    awaiting: false,
                })
            }
        }
    })
}

/// The producer alone, its events counted and dropped (for the bench: how the two halves of a
/// read compare).
#[doc(hidden)]
pub fn tokenize_only<R: BufRead + Send>(input: R, pipeline: Pipeline) -> usize {
    read(input, pipeline, BATCH_BYTES, None, |t| {
        let mut n = 0;
        let mut b = Batch::default();
        loop {
            b = t.next(b);
            n += b.recs.len();
            if b.stop.is_some() || b.recs.last().is_some_and(|r| r.kind == Kind::Eof) {
                return n;
            }
        }
    })
}

/// The second half of a split reading: the file's bytes from `from` (a file offset, counted
/// after a byte-order mark of `skipped` bytes) to its `len`, read at their places from `source`
/// (another reader of the same open file), in this thread. Its events end at the first end tag
/// that closes an element opened before `from` ([`Kind::PartEnd`]). Besides what `consume`
/// gives: where that end tag starts and the hash of the bytes before it, if the events got
/// there. `cancel`: the first half no longer wants this (the events stop at the next batch).
#[allow(clippy::too_many_arguments)]
pub(crate) fn read_part<T>(
    source: &dyn crate::load::ReadAt,
    skipped: u64,
    from: usize,
    len: usize,
    batch_bytes: usize,
    pipeline: Pipeline,
    cancel: &AtomicBool,
    consume: impl FnOnce(&mut dyn Tape) -> T,
) -> (T, Option<(usize, u64)>) {
    let input = AtReader {
        source,
        pos: skipped + from as u64,
        end: skipped + len as u64,
    };
    run(
        Producer::part(input, batch_bytes, from),
        pipeline,
        |inner| {
            let mut tape = Part {
                inner,
                hash: xxhash_rust::xxh3::Xxh3Default::new(),
                cancel,
                end: None,
            };
            let out = consume(&mut tape);
            let end = tape.end.map(|e| (e, tape.hash.digest()));
            (out, end)
        },
    )
}

/// Reads `source` from `pos` up to `end`.
struct AtReader<'a> {
    source: &'a dyn crate::load::ReadAt,
    pos: u64,
    end: u64,
}

impl std::io::Read for AtReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let left = usize::try_from(self.end.saturating_sub(self.pos)).unwrap_or(usize::MAX);
        let n = buf.len().min(left);
        if n == 0 {
            return Ok(0);
        }
        let got = self.source.read_at(&mut buf[..n], self.pos)?;
        self.pos += got as u64;
        Ok(got)
    }
}

/// The second half's tape: hashes the bytes its events come from, up to their end.
struct Part<'a> {
    inner: &'a mut dyn Tape,
    hash: xxhash_rust::xxh3::Xxh3Default,
    cancel: &'a AtomicBool,
    end: Option<usize>,
}

impl Tape for Part<'_> {
    fn next(&mut self, spent: Batch) -> Batch {
        if self.cancel.load(Ordering::Relaxed) {
            return Batch {
                stop: Some(Stop::Io(std::io::Error::other("not wanted"))),
                ..Batch::default()
            };
        }
        let b = self.inner.next(spent);
        match b.recs.last() {
            Some(r) if r.kind == Kind::PartEnd => {
                self.hash.update(&b.text.as_bytes()[..r.at as usize]);
                self.end = Some(b.at(r));
            }
            _ => self.hash.update(b.text.as_bytes()),
        }
        b
    }

    fn decide(&mut self, _: Decision) {}
}
