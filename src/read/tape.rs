//! The SFC's XML events as a tape: what [`super::sfc`] needs of each event (kind, place, tag,
//! raw content), copied into batches.
//!
//! Tokenizing the XML and checking its UTF-8 is more than half of reading a large SFC. A [`Producer`] does that part; the SFC reader consumes the batches. For a large file the
//! producer runs on a second thread ([`read`] with [`Pipeline::Threaded`]), so the two halves run
//! side by side on two cores; for a small one it fills a batch whenever the reader asks
//! ([`Pipeline::Inline`]). Both give the same records: the reader cannot tell them apart, and the
//! tests compare the two.
//!
//! Batches are bounded (about [`BATCH_BYTES`] of text each, at most [`QUEUE`] waiting), so the
//! memory a read holds stays flat however large the file; emptied batches go back to the producer
//! to be filled again.

use std::io::BufRead;
use std::ops::Range;
use std::sync::mpsc::{Receiver, SyncSender};

use quick_xml::events::Event;

use super::sfc::Tag;

/// The text a batch holds before it is handed over (one event may make it longer).
pub const BATCH_BYTES: usize = 128 * 1024;
/// Records a batch holds before it is handed over.
const BATCH_RECORDS: usize = 4096;
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
}

/// One event. Ranges are into [`Batch::text`]; `at` and `end` are the file offsets before and
/// after the event.
#[derive(Debug, Clone)]
pub(crate) struct Rec {
    pub kind: Kind,
    /// Of a start tag: its local name's tag.
    pub tag: Tag,
    pub at: usize,
    pub end: usize,
    /// Start and empty tags: the tag's content (name and attributes, as the parser hands them
    /// out); text, CDATA, references: the raw content.
    pub text: Range<usize>,
    /// Start and empty tags: the qualified name, the start of `text`, and where in it the
    /// local name starts.
    pub name: Range<usize>,
}

/// Why the events stopped before the end of the file.
#[derive(Debug)]
pub(crate) enum Stop {
    NotUtf8,
    Io(std::io::Error),
    /// Not well-formed XML: where, and the parser's words.
    Syntax(usize, String),
}

/// Events, in file order.
#[derive(Debug, Default)]
pub(crate) struct Batch {
    pub text: String,
    pub recs: Vec<Rec>,
    /// Set on the last batch when the events stopped early (the records come first).
    pub stop: Option<Stop>,
}

impl Batch {
    fn clear(&mut self) {
        self.text.clear();
        self.recs.clear();
        self.stop = None;
    }

    fn push_text(&mut self, s: &str) -> Range<usize> {
        let start = self.text.len();
        self.text.push_str(s);
        start..self.text.len()
    }

    fn full(&self, batch_bytes: usize) -> bool {
        self.text.len() >= batch_bytes || self.recs.len() >= BATCH_RECORDS
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

/// Tokenizes the XML of one input into batches.
pub(crate) struct Producer<R> {
    reader: quick_xml::Reader<R>,
    buf: Vec<u8>,
    done: bool,
    batch_bytes: usize,
}

impl<R: BufRead> Producer<R> {
    pub fn new(input: R, batch_bytes: usize) -> Self {
        Producer {
            reader: quick_xml::Reader::from_reader(input),
            buf: Vec::with_capacity(4096),
            done: false,
            batch_bytes: batch_bytes.max(1),
        }
    }

    /// Fills `b` (emptied first) with the next events; after the end of the file or a stop,
    /// nothing more.
    fn fill(&mut self, b: &mut Batch) {
        b.clear();
        while !self.done && !b.full(self.batch_bytes) {
            self.one(b);
        }
    }

    fn one(&mut self, b: &mut Batch) {
        let at = self.reader.buffer_position() as usize;
        self.buf.clear();
        let ev = match self.reader.read_event_into(&mut self.buf) {
            Ok(ev) => ev,
            Err(e) => {
                self.done = true;
                b.stop = Some(match e {
                    quick_xml::Error::Encoding(_) => Stop::NotUtf8,
                    quick_xml::Error::Io(e) => {
                        Stop::Io(std::io::Error::new(e.kind(), e.to_string()))
                    }
                    e => Stop::Syntax(self.reader.error_position() as usize, e.to_string()),
                });
                return;
            }
        };
        let end = self.reader.buffer_position() as usize;
        let mut rec = Rec {
            kind: Kind::Eof,
            tag: Tag::Other,
            at,
            end,
            text: 0..0,
            name: 0..0,
        };
        match ev {
            Event::Start(ref e) | Event::Empty(ref e) => {
                rec.kind = if matches!(ev, Event::Start(_)) {
                    Kind::Start
                } else {
                    Kind::Empty
                };
                let content: &str = e;
                // The name is the start of the content.
                let len = e.name().as_ref().len().min(content.len());
                let local = local_part(&content[..len]);
                rec.tag = Tag::of(local);
                rec.text = b.push_text(content);
                rec.name = rec.text.start + (len - local.len())..rec.text.start + len;
            }
            Event::End(_) => rec.kind = Kind::End,
            Event::Text(ref t) => {
                rec.kind = Kind::Text;
                rec.text = b.push_text(t);
            }
            Event::CData(ref t) => {
                rec.kind = Kind::CData;
                rec.text = b.push_text(t);
            }
            Event::GeneralRef(ref r) => {
                rec.kind = Kind::GeneralRef;
                rec.text = b.push_text(r);
            }
            Event::DocType(_) => rec.kind = Kind::DocType,
            Event::Eof => self.done = true,
            // Declarations, comments, processing instructions.
            _ => return,
        }
        b.recs.push(rec);
    }
}

/// Where the reader gets its batches.
pub(crate) trait Tape {
    /// The next batch; `spent` is the one the reader is done with (its buffers are used again).
    fn next(&mut self, spent: Batch) -> Batch;
}

struct Inline<R>(Producer<R>);

impl<R: BufRead> Tape for Inline<R> {
    fn next(&mut self, mut spent: Batch) -> Batch {
        self.0.fill(&mut spent);
        spent
    }
}

struct Threaded {
    filled: Receiver<Batch>,
    spent: SyncSender<Batch>,
}

impl Tape for Threaded {
    fn next(&mut self, spent: Batch) -> Batch {
        // A full return queue drops the batch: the producer allocates another.
        let _ = self.spent.try_send(spent);
        self.filled.recv().unwrap_or_else(|_| Batch {
            stop: Some(Stop::Io(std::io::Error::other(
                "the thread reading the file ended early",
            ))),
            ..Batch::default()
        })
    }
}

/// Runs `consume` over the events of `input`, produced as `pipeline` says. A second thread that
/// cannot be started leaves the work to this one.
pub(crate) fn read<R, T>(
    input: R,
    pipeline: Pipeline,
    batch_bytes: usize,
    consume: impl FnOnce(&mut dyn Tape) -> T,
) -> T
where
    R: BufRead + Send,
{
    let producer = Producer::new(input, batch_bytes);
    if pipeline == Pipeline::Inline {
        return consume(&mut Inline(producer));
    }
    let slot = std::sync::Mutex::new(Some(producer));
    std::thread::scope(|s| {
        let (filled_tx, filled) = std::sync::mpsc::sync_channel::<Batch>(QUEUE);
        let (spent, spent_rx) = std::sync::mpsc::sync_channel::<Batch>(QUEUE + 2);
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
                    // The reader stopped early (its own error): so does this thread.
                    if filled_tx.send(b).is_err() || last {
                        return;
                    }
                }
            });
        match started {
            Ok(_) => consume(&mut Threaded { filled, spent }),
            Err(_) => {
                let producer = slot
                    .lock()
                    .ok()
                    .and_then(|mut g| g.take())
                    .expect("the thread did not start, so it did not take the producer");
                consume(&mut Inline(producer))
            }
        }
    })
}

/// The producer alone, its events counted and dropped (for the bench: how the two halves of a
/// read compare).
#[doc(hidden)]
pub fn tokenize_only<R: BufRead + Send>(input: R, pipeline: Pipeline) -> usize {
    read(input, pipeline, BATCH_BYTES, |t| {
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
