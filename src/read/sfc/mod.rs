//! The SFC (PLCopen TC6 XML 2.01, 2.00 or 1.0; namespaces ignored): the program's elements,
//! their connections, and the skill steps' data (docs/INPUTS.md).
//!
//! The SFC is the one input that grows with the product (100,000 steps make 78 MB), so it is read
//! as a stream ([`read_sfc_stream`], `quick-xml` over any [`BufRead`]): the compile hands it the
//! file itself, so the text is never whole in memory, and no document tree is built. The model is
//! all that is kept. Byte positions come from the reader's position and from where the attribute
//! slices sit in the event's buffer. The graph rules are checked by [`crate::plan`].
//!
//! Layout:
//! - `mod.rs`: the public API, the reader's state (`Stream`) and its pass over the events
//!   (`run`), the text inside an element routed to it.
//! - `pick.rs`: the attributes the reader wants, picked from a start tag.
//! - `tag.rs`: the tags the reader knows (`Tag`), the stack of open elements (`Open`) and
//!   where an element stands in the document (`PathKind`).
//! - `element.rs`: the element being built (`Building`, its attribute values and variables,
//!   the start tag `Tagged`): begun from its start tag, finished into the model; a step's
//!   data and a transition's condition made from it, the text gathered into it, the POU
//!   chosen at the end and the ignored elements reported.
//! - `inside.rs`: the descendants of the element being built, picked by where they stand
//!   below it (a step's position, connections, variables and data; a condition's parts).
//! - `named.rs`: named transitions (their bodies, the ST text gathered and its expression),
//!   the places of text assembled from pieces, and the limit on derived condition text.
//! - `wired.rs`: conditions wired from FBD/LD elements (`WireNode`, `Wiring`), made
//!   expressions at the body's end or from a named transition's LD/FBD body.
//! - `split.rs`: a large file read in two halves at once.
//! - `tests.rs`: the unit tests.

use std::collections::HashMap;
use std::io::BufRead;
use std::ops::Range;

use quick_xml::events::{BytesCData, BytesRef, BytesText};

use super::tape::{self, Batch, Kind, Pipeline, Stop, Tape};

use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::model::{Element, FileHeader, Interner, Sfc, Variable};

mod element;
mod inside;
mod named;
mod pick;
mod split;
mod tag;
mod wired;

use element::{Building, Tagged, Val, end_inside, inline_text, report_ignored};
use named::{Named, Outer, ReadingNamed, named_text};
pub(crate) use tag::Tag;
use tag::{Open, PathKind};
use wired::{PendingWired, WireNode};

pub use crate::value::MAX_LIST_DEPTH;
pub use split::{SPLIT_FROM, SplitSource, read_sfc_file};

/// Why a streamed read stopped before it could judge the file: the caller reports these (it has
/// the file's bytes, or knows why it has none).
#[derive(Debug)]
pub enum StreamError {
    /// The bytes are not UTF-8 (the reader names no place: the caller's loader locates it).
    NotUtf8,
    /// Reading the input failed.
    Io(std::io::Error),
}

/// Reads the SFC file's text as [`Sources`] holds it. `None` when the file is not well-formed or
/// has no usable program body.
pub fn read_sfc(sources: &Sources, file: FileId, diags: &mut Diagnostics) -> Option<Sfc> {
    read_sfc_pou(sources, file, None, diags)
}

/// Reads the SFC file's POU named `pou` (`--pou`, or the reference's `#fragment`); without a
/// name, the first program with an SFC body, else the first POU with one (docs/INPUTS.md). When
/// several POUs have an SFC body and none was named, a warning names the one used and the
/// others.
pub fn read_sfc_pou(
    sources: &Sources,
    file: FileId,
    pou: Option<&str>,
    diags: &mut Diagnostics,
) -> Option<Sfc> {
    let text = sources.get(file).text.as_bytes();
    // The text is a `str`: it cannot fail to be UTF-8, and memory cannot fail to be read.
    let sfc = read_sfc_stream(text, file, text.len() as u64, pou, diags).unwrap_or(None);
    // The stream's places are bytes; with the text at hand they go on its characters.
    diags.snap(sources);
    sfc
}

/// [`read_sfc_pou`] from a stream of the file's bytes after its byte-order mark (positions count
/// from there, as in [`Sources`]). `len_hint`: the file's size, if known (sizes the element
/// vector). Diagnostics are located by byte ranges only; their lines need the text, read again
/// when they are rendered.
pub fn read_sfc_stream<R: BufRead + Send>(
    input: R,
    file: FileId,
    len_hint: u64,
    pou: Option<&str>,
    diags: &mut Diagnostics,
) -> Result<Option<Sfc>, StreamError> {
    let pipeline = Pipeline::choose(len_hint);
    read_sfc_stream_with(
        input,
        file,
        len_hint,
        pou,
        diags,
        pipeline,
        tape::BATCH_BYTES,
    )
}

/// [`read_sfc_stream`] with the events produced as `pipeline` says, in batches of about
/// `batch_bytes` of text (the tests compare the ways; the result is the same).
#[doc(hidden)]
pub fn read_sfc_stream_with<R: BufRead + Send>(
    input: R,
    file: FileId,
    len_hint: u64,
    pou: Option<&str>,
    diags: &mut Diagnostics,
    pipeline: Pipeline,
    batch_bytes: usize,
) -> Result<Option<Sfc>, StreamError> {
    read_sfc_stream_split(
        input,
        file,
        len_hint,
        pou,
        diags,
        pipeline,
        batch_bytes,
        None,
    )
}

/// [`read_sfc_stream_with`], the file read in two halves at once when `split` offers a second
/// reader of it (see `split.rs`; the result is the same).
#[doc(hidden)]
#[allow(clippy::too_many_arguments)]
pub fn read_sfc_stream_split<R: BufRead + Send>(
    input: R,
    file: FileId,
    len_hint: u64,
    pou: Option<&str>,
    diags: &mut Diagnostics,
    pipeline: Pipeline,
    batch_bytes: usize,
    split: Option<SplitSource<'_>>,
) -> Result<Option<Sfc>, StreamError> {
    let mut r = Stream::new(
        file,
        pou.map(|p| p.trim().to_owned()).filter(|p| !p.is_empty()),
        usize::try_from(len_hint).unwrap_or(usize::MAX),
    );
    let mut local = Diagnostics::default();
    let outcome = split::read_halves(
        &mut r,
        input,
        len_hint,
        pipeline,
        batch_bytes,
        split,
        |r, t| r.run(t, &mut local),
    )?;
    Ok(match outcome {
        Err(d) => {
            // Not well-formed: only the syntax error counts (the rest may be an artefact of it).
            diags.push(*d);
            None
        }
        Ok(Outcome::Part(_)) => None,
        Ok(Outcome::WrongRoot(span, name)) => {
            diags.push(
                Diagnostic::error(
                    Code::XmlWrongRoot,
                    format!("not a PLCopen XML file: the root element is `{name}`, not `project`"),
                )
                .at(span),
            );
            None
        }
        Ok(Outcome::Done {
            header,
            root,
            first_pou,
        }) => {
            for d in local.into_vec() {
                diags.push(d);
            }
            report_ignored(&r.ignored, diags);
            r.choose(header, root, first_pou, diags)
        }
    })
}

enum Outcome {
    WrongRoot(Span, String),
    /// The second half of a split reading: its elements.
    Part(Vec<Element>),
    Done {
        header: FileHeader,
        /// The root element's tag.
        root: Span,
        /// The first pou's tag and name (for "no SFC body").
        first_pou: Option<(Span, String)>,
    },
}

/// A pou whose SFC body was read.
struct Pou {
    name: Option<String>,
    program: bool,
    sfc_span: Span,
    elements: Vec<Element>,
    macros: Vec<crate::model::MacroBody>,
}

/// A macroStep whose body is being read: the depths of its `body` and of the body's `SFC`, the
/// macroStep's element and the body's first.
struct OpenMacro {
    body_depth: usize,
    sfc_depth: Option<usize>,
    step: usize,
    first: usize,
}

impl Pou {
    /// An action's chart (`POU.ACTION`: a POU's name has no `.`).
    fn is_action(&self) -> bool {
        self.name.as_deref().is_some_and(|n| n.contains('.'))
    }
}

struct Stream {
    file: FileId,
    /// The file's size, if known (0: unknown).
    len_hint: usize,
    names: Interner,
    found: Vec<Pou>,
    /// Elements of the SFC body that are ignored: tag, place, label.
    ignored: Vec<(String, Span, String)>,
    /// The POU asked for by name.
    wanted: Option<String>,
    /// Every POU: name, whether it has an SFC body.
    pous: Vec<(String, bool)>,
    /// Every step's variables and their values' texts ([`Sfc::variables`], [`Sfc::values`]).
    variables: Vec<Variable>,
    values: String,
    /// The named transitions of the POU being read, by key (docs/INPUTS.md): read before its
    /// body (the schema puts `transitions` first).
    named: HashMap<String, Named>,
    /// The FBD/LD elements of the SFC body being read, and its transitions whose conditions
    /// are wired from them (made expressions at the body's end).
    wire_nodes: Vec<WireNode>,
    pending_wired: Vec<PendingWired>,
    /// The bytes of condition text transitions took from named transitions and wired networks
    /// so far ([`MAX_DERIVED_TEXT`]), and whether that was refused.
    derived_text: usize,
    derived_refused: bool,
    /// Reading the second half of a split reading (`split.rs`): it starts inside the SFC.
    is_part: bool,
    /// Reading the first half: where the second half's result comes.
    part: Option<split::Link>,
    /// The second half's result was taken.
    part_joined: bool,
}

/// How much condition text (in bytes of ST) the transitions of a file may take from named
/// transitions and wired networks together: 16 MiB. Such a condition is written once and used
/// by any number of transitions, and a wired network's paths multiply (docs/INPUTS.md), while
/// every transition gets a copy of it in the model and in the program; the text written in the
/// file is paid by the file's size. 20,000 transitions wired to one 512-path network took
/// 2.78 GB and wrote a 279 MB `.src`.
pub const MAX_DERIVED_TEXT: usize = 16 * 1024 * 1024;

impl Stream {
    fn new(file: FileId, wanted: Option<String>, len_hint: usize) -> Self {
        Stream {
            wanted,
            pous: Vec::new(),
            named: HashMap::new(),
            wire_nodes: Vec::new(),
            pending_wired: Vec::new(),
            derived_text: 0,
            derived_refused: false,
            len_hint,
            file,
            names: Interner::default(),
            found: Vec::new(),
            ignored: Vec::new(),
            variables: Vec::new(),
            values: String::new(),
            is_part: false,
            part: None,
            part_joined: false,
        }
    }

    fn span(&self, r: Range<usize>) -> Span {
        Span::new(self.file, r)
    }

    fn syntax_error(&self, at: usize, msg: String) -> Box<Diagnostic> {
        // A position inside a multi-byte character is moved to its start when the diagnostic
        // gets its text (`Diagnostics::snap`).
        Box::new(
            Diagnostic::error(Code::XmlSyntax, format!("not well-formed XML: {msg}"))
                .at(self.span(at..at + 1)),
        )
    }

    fn run(
        &mut self,
        tape: &mut dyn Tape,
        diags: &mut Diagnostics,
    ) -> Result<Result<Outcome, Box<Diagnostic>>, StreamError> {
        let mut stack = Open::default();
        let mut header = FileHeader::default();
        let mut root = self.span(0..0);
        let mut first_pou: Option<(Span, String)> = None;
        // The pou being read, if its SFC is wanted: (name, program, pou depth).
        let mut pou: Option<(Option<String>, bool, usize)> = None;
        let mut want_pou = false;
        let mut body_seen = false;
        let mut sfc: Option<(Span, usize, Vec<Element>)> = None;
        let mut sfc_done = false;
        // Macro steps whose bodies are open (they nest), and those read.
        let mut open_macros: Vec<OpenMacro> = Vec::new();
        let mut macros: Vec<crate::model::MacroBody> = Vec::new();
        // The element being built, and whether one is.
        let mut b = Building::new(self.file);
        let mut building = false;
        let mut named: Option<ReadingNamed> = None;
        // The POU being read (its name, wanted or not), its entry in `self.pous`, and while one
        // of its actions is read, the POU's state to go back to when the action ends.
        let mut current_pou: Option<String> = None;
        let mut pous_at: Option<usize> = None;
        let mut outer: Option<Outer> = None;
        let mut seen_root = false;
        let mut scratch = String::new();
        let mut batch = Batch::default();
        if self.is_part {
            // Inside the SFC body of the POU being read (the first half checks that it was).
            for (tag, name) in split::ASSUMED {
                stack.push(tag, name);
            }
            seen_root = true;
            pou = Some((None, false, 4));
            want_pou = true;
            body_seen = true;
            sfc = Some((
                self.span(0..0),
                split::ASSUMED.len(),
                Vec::with_capacity((self.len_hint / 320).min(1 << 24)),
            ));
        }
        loop {
            batch = tape.next(batch);
            for rec in &batch.recs {
                let at = batch.at(rec);
                let empty = match rec.kind {
                    Kind::Start => false,
                    Kind::Empty => true,
                    Kind::End => {
                        let depth = stack.len();
                        stack.pop();
                        if building && depth == b.depth {
                            building = false;
                            if let Some(el) = self.finish(&mut b, diags)
                                && let Some((_, _, els)) = &mut sfc
                            {
                                els.push(el);
                            }
                        } else if building {
                            end_inside(&mut b, &stack);
                        } else if open_macros.last().is_some_and(|m| m.body_depth == depth) {
                            // A macro step's `</body>`: its elements are complete.
                            let m = open_macros.pop().expect("checked");
                            let end = sfc.as_ref().map_or(m.first, |s| s.2.len());
                            macros.push(crate::model::MacroBody {
                                step: m.step,
                                body: m.first..end,
                            });
                        } else if outer.as_ref().is_some_and(|o| o.depth == depth) {
                            // `</action>`: back to its POU.
                            let o = outer.take().expect("checked");
                            pou = o.pou;
                            want_pou = o.want_pou;
                            body_seen = o.body_seen;
                            sfc_done = o.sfc_done;
                            pous_at = o.pous_at;
                        } else if named.as_ref().is_some_and(|n| n.depth == depth) {
                            // `</transition>` of a named transition.
                            let n = named.take().expect("checked");
                            let nodes = std::mem::take(&mut self.wire_nodes);
                            let body = match (n.st, n.other) {
                                (Some((_, text, map)), _) => Named::St { text, map },
                                (None, Some(language)) if language == "LD" || language == "FBD" => {
                                    Named::Wired(self.named_network(&nodes, &n.name, &n.at))
                                }
                                (None, Some(language)) => Named::Other { language, at: n.at },
                                (None, None) => Named::St {
                                    text: String::new(),
                                    map: Vec::new(),
                                },
                            };
                            self.named.entry(crate::names::key(&n.name)).or_insert(body);
                        } else if let Some((_, d, _)) = &sfc
                            && depth == *d
                        {
                            // `</SFC>`
                            let (name, program, _) = pou.clone().unwrap_or((None, false, 0));
                            let (span, _, mut els) = sfc.take().expect("checked");
                            self.resolve_wired(&mut els, diags);
                            els.shrink_to_fit();
                            self.found.push(Pou {
                                name,
                                program,
                                sfc_span: span,
                                elements: els,
                                macros: std::mem::take(&mut macros),
                            });
                            sfc_done = true;
                        } else if let Some((_, _, d)) = &pou
                            && depth == *d
                        {
                            pou = None;
                            want_pou = false;
                        }
                        continue;
                    }
                    Kind::Text => {
                        let raw = batch.text(rec);
                        let text = || {
                            BytesText::from_escaped(raw)
                                .xml_content(quick_xml::XmlVersion::Implicit1_0)
                        };
                        if building {
                            inline_text(&mut b, &stack, at..batch.end(rec), text);
                        } else {
                            named_text(&mut named, &stack, at..batch.end(rec), text);
                        }
                        continue;
                    }
                    Kind::CData => {
                        // `<![CDATA[` … `]]>`
                        let end = batch.end(rec).saturating_sub(3);
                        let raw = batch.text(rec);
                        let text =
                            || BytesCData::new(raw).xml_content(quick_xml::XmlVersion::Implicit1_0);
                        if building {
                            inline_text(&mut b, &stack, (at + 9).min(end)..end, text);
                        } else {
                            named_text(&mut named, &stack, (at + 9).min(end)..end, text);
                        }
                        continue;
                    }
                    Kind::GeneralRef => {
                        let raw = batch.text(rec);
                        let ch = match BytesRef::new(raw).resolve_char_ref() {
                            Ok(Some(c)) => Some(c),
                            Ok(None) => match raw {
                                "lt" => Some('<'),
                                "gt" => Some('>'),
                                "amp" => Some('&'),
                                "apos" => Some('\''),
                                "quot" => Some('"'),
                                other => {
                                    return Ok(Err(self.syntax_error(
                                        at,
                                        format!("unknown entity reference `&{other};`"),
                                    )));
                                }
                            },
                            Err(e) => return Ok(Err(self.syntax_error(at, e.to_string()))),
                        };
                        // A character given by reference: a piece of the text it stands in,
                        // as a text would be.
                        if let Some(c) = ch {
                            let mut buf = [0u8; 4];
                            let piece: &str = c.encode_utf8(&mut buf);
                            let text = || std::borrow::Cow::Borrowed(piece);
                            if building {
                                inline_text(&mut b, &stack, at..batch.end(rec), text);
                            } else {
                                named_text(&mut named, &stack, at..batch.end(rec), text);
                            }
                        }
                        continue;
                    }
                    Kind::DocType => {
                        return Ok(Err(Box::new(
                        Diagnostic::error(
                            Code::XmlSyntax,
                            "a document type declaration (DTD) is not accepted: entity definitions could expand without bound",
                        )
                        .at(self.span(at..at + 9)),
                    )));
                    }
                    Kind::PartEnd => {
                        // The second half's end: at the end tag of the assumed SFC, with
                        // nothing of its own open.
                        return Ok(match sfc.take() {
                            Some((_, d, els))
                                if self.is_part
                                    && stack.len() == d
                                    && !building
                                    && named.is_none()
                                    && open_macros.is_empty()
                                    && macros.is_empty() =>
                            {
                                Ok(Outcome::Part(els))
                            }
                            _ => Err(self.syntax_error(at, "not the end of a part".to_owned())),
                        });
                    }
                    Kind::Eof => {
                        let end = batch.end(rec);
                        if let Some(open) = stack.last_name() {
                            return Ok(Err(
                                self.syntax_error(end, format!("the file ends inside `<{open}>`"))
                            ));
                        }
                        if !seen_root {
                            return Ok(Err(self.syntax_error(0, "no root element".to_owned())));
                        }
                        return Ok(Ok(Outcome::Done {
                            header,
                            root,
                            first_pou,
                        }));
                    }
                };
                let t = Tagged::new(rec, &batch);
                let name = t.local_name();
                let tag = rec.tag;
                let tag_span = self.span(at..at + 1 + name.len());
                if stack.len() == 0 {
                    if seen_root {
                        return Ok(Err(
                            self.syntax_error(at, "a second root element".to_owned())
                        ));
                    }
                    seen_root = true;
                    root = tag_span.clone();
                    if tag != Tag::Project {
                        // Read no further: the caller reports E103 (the rest may be any XML).
                        return Ok(Ok(Outcome::WrongRoot(tag_span, name.to_owned())));
                    }
                }
                let depth = stack.len() + 1;
                if building
                    && b.tag == Tag::MacroStep
                    && tag == Tag::Body
                    && depth == b.depth + 1
                    && !empty
                {
                    // A macro step's body (docs/INPUTS.md): the step is complete, and its body's
                    // chart is read as elements of this one.
                    building = false;
                    if let Some(el) = self.finish(&mut b, diags)
                        && let Some((_, _, els)) = &mut sfc
                    {
                        if open_macros.len() == crate::model::MAX_NESTING {
                            // Refused here, as it is read: what the planner does with nested
                            // bodies grows with their depth times their size.
                            return Ok(Err(Box::new(
                                Diagnostic::error(
                                    Code::Unsupported,
                                    format!(
                                        "macro steps nested deeper than {} levels",
                                        crate::model::MAX_NESTING
                                    ),
                                )
                                .at(el.span.clone())
                                .element(format!("localId {}", el.local_id)),
                            )));
                        }
                        els.push(el);
                        open_macros.push(OpenMacro {
                            body_depth: depth,
                            sfc_depth: None,
                            step: els.len() - 1,
                            first: els.len(),
                        });
                    }
                    stack.push(tag, name);
                    continue;
                }
                if building {
                    if let Err(d) = self.inside(&mut b, &stack, tag, tag_span, &t) {
                        return Ok(Err(d));
                    }
                    if empty {
                        end_inside(&mut b, &stack);
                    } else {
                        stack.push(tag, name);
                    }
                    continue;
                }
                // A named transition of the POU being read (docs/INPUTS.md): its name, then its
                // body's language; its ST text is gathered by `named_text`.
                if let Some(n) = &mut named {
                    if depth == n.depth + 2
                        && stack.tags.last().map(|t| t.0) == Some(Tag::Body)
                        && n.st.is_none()
                        && n.other.is_none()
                    {
                        if name == "ST" {
                            n.st = Some((depth, String::new(), Vec::new()));
                        } else {
                            n.other = Some(name.to_owned());
                        }
                    } else if depth == n.depth + 3
                        && matches!(n.other.as_deref(), Some("LD" | "FBD"))
                    {
                        // An element of an LD/FBD body: read as a wired condition's parts.
                        if let Err(d) = self.begin(&mut b, &t, tag, name, tag_span.clone(), depth) {
                            return Ok(Err(d));
                        }
                        if empty {
                            self.finish(&mut b, diags);
                        } else {
                            building = true;
                            stack.push(tag, name);
                        }
                        continue;
                    }
                } else if tag == Tag::Transition
                    && !empty
                    && want_pou
                    && pou.is_some()
                    && stack.len() >= 2
                    && stack.tags[stack.len() - 1].0 == Tag::Transitions
                    && stack.tags[stack.len() - 2].0 == Tag::Pou
                {
                    let mark = scratch.len();
                    let [n] = match self.pick(&t, ["name"], &mut scratch) {
                        Ok(p) => p,
                        Err(d) => return Ok(Err(d)),
                    };
                    if let Some(n) = n {
                        named = Some(ReadingNamed {
                            name: n.get(&scratch).to_owned(),
                            depth,
                            at: tag_span.clone(),
                            st: None,
                            other: None,
                        });
                    }
                    scratch.truncate(mark);
                }
                // The element's place, relative to the document.
                let path = PathKind::of(&stack, tag);
                if matches!(path, PathKind::Sfc)
                    && let Some(p) = pous_at.and_then(|i| self.pous.get_mut(i))
                {
                    p.1 = true;
                }
                match path {
                    PathKind::FileHeader => {
                        scratch.clear();
                        let picked = self.pick(
                            &t,
                            [
                                "companyName",
                                "productName",
                                "productVersion",
                                "creationDateTime",
                            ],
                            &mut scratch,
                        );
                        let [company, product, version, time] = match picked {
                            Ok(p) => p,
                            Err(d) => return Ok(Err(d)),
                        };
                        let v = |a: Option<Val>| a.map(|a| a.get(&scratch).to_owned());
                        header.company_name = v(company);
                        header.product_name = v(product);
                        header.product_version = v(version);
                        header.creation_date_time = v(time);
                    }
                    PathKind::Pou => {
                        scratch.clear();
                        let [pou_name, pou_type] =
                            match self.pick(&t, ["name", "pouType"], &mut scratch) {
                                Ok(p) => p,
                                Err(d) => return Ok(Err(d)),
                            };
                        let pname = pou_name.map(|a| a.get(&scratch).to_owned());
                        let program = pou_type.is_some_and(|a| a.get(&scratch) == "program");
                        if first_pou.is_none() {
                            first_pou = Some((tag_span.clone(), pname.clone().unwrap_or_default()));
                        }
                        self.pous.push((pname.clone().unwrap_or_default(), false));
                        pous_at = Some(self.pous.len() - 1);
                        current_pou = pname.clone();
                        self.named.clear();
                        let have_program = self.found.iter().any(|p| p.program);
                        // An action's chart found so far gives way to a POU's.
                        let only_actions = self.found.iter().all(Pou::is_action);
                        want_pou = match &self.wanted {
                            Some(w) => {
                                self.found.is_empty()
                                    && pname.as_deref().is_some_and(|n| crate::names::eq(n, w))
                            }
                            None => !have_program && (program || only_actions),
                        };
                        if want_pou && !empty {
                            pou = Some((pname, program, depth));
                            body_seen = false;
                            sfc_done = false;
                        }
                    }
                    PathKind::Action if !empty && outer.is_none() => {
                        let mark = scratch.len();
                        let [a] = match self.pick(&t, ["name"], &mut scratch) {
                            Ok(p) => p,
                            Err(d) => return Ok(Err(d)),
                        };
                        let action = a.map(|a| a.get(&scratch).to_owned()).unwrap_or_default();
                        scratch.truncate(mark);
                        let full = format!("{}.{action}", current_pou.as_deref().unwrap_or(""));
                        self.pous.push((full.clone(), false));
                        // An action's chart is used when named, or when no POU has one.
                        let want = match &self.wanted {
                            Some(w) => self.found.is_empty() && crate::names::eq(&full, w),
                            None => self.found.is_empty(),
                        };
                        outer = Some(Outer {
                            pou: pou.take(),
                            want_pou,
                            body_seen,
                            sfc_done,
                            pous_at,
                            depth,
                        });
                        pous_at = Some(self.pous.len() - 1);
                        want_pou = want;
                        if want {
                            pou = Some((Some(full), false, depth));
                            body_seen = false;
                            sfc_done = false;
                        }
                    }
                    PathKind::Body if want_pou && pou.is_some() => {
                        if body_seen {
                            // Only the first body counts.
                            want_pou = false;
                        }
                        body_seen = true;
                    }
                    PathKind::Sfc if want_pou && pou.is_some() && !sfc_done && sfc.is_none() => {
                        if empty {
                            let (pname, program, _) = pou.clone().expect("checked");
                            self.found.push(Pou {
                                name: pname,
                                program,
                                sfc_span: tag_span,
                                elements: Vec::new(),
                                macros: Vec::new(),
                            });
                            sfc_done = true;
                        } else {
                            // Sized from the bytes left (an element takes about 300-400 bytes):
                            // growing by doubling would hold the old and the new vector at once.
                            let left = self.len_hint.saturating_sub(tag_span.range.end);
                            sfc = Some((
                                tag_span,
                                depth,
                                Vec::with_capacity((left / 320).min(1 << 24)),
                            ));
                        }
                    }
                    _ => {
                        if tag == Tag::Sfc
                            && let Some(m) = open_macros.last_mut()
                            && m.body_depth + 1 == depth
                            && m.sfc_depth.is_none()
                        {
                            m.sfc_depth = Some(depth);
                        }
                        let in_macro = open_macros
                            .last()
                            .and_then(|m| m.sfc_depth)
                            .is_some_and(|s| depth == s + 1);
                        if let Some((_, d, els)) = &mut sfc
                            && (depth == *d + 1 || in_macro)
                        {
                            if let Err(d) = self.begin(&mut b, &t, tag, name, tag_span, depth) {
                                return Ok(Err(d));
                            }
                            if empty {
                                if let Some(el) = self.finish(&mut b, diags) {
                                    els.push(el);
                                }
                            } else {
                                building = true;
                            }
                        }
                    }
                }
                if !empty {
                    stack.push(tag, name);
                }
            }
            if batch.split {
                // The split place: the second half's elements come next, if it read them as
                // this reading would have.
                let at_sfc = !building
                    && named.is_none()
                    && outer.is_none()
                    && open_macros.is_empty()
                    && want_pou
                    && pou.is_some()
                    && !sfc_done
                    && sfc.as_ref().is_some_and(|s| s.1 == stack.len())
                    && stack
                        .tags
                        .iter()
                        .map(|t| t.0)
                        .eq(split::ASSUMED.map(|a| a.0));
                let (decision, part) = self.take_part(at_sfc);
                tape.decide(decision);
                if let (Some(part), Some((_, _, els))) = (part, &mut sfc) {
                    self.append_part(part, els, diags);
                }
            }
            match batch.stop.take() {
                None => {}
                Some(Stop::NotUtf8) => return Err(StreamError::NotUtf8),
                Some(Stop::Io(e)) => return Err(StreamError::Io(e)),
                Some(Stop::Syntax(at, msg)) => return Ok(Err(self.syntax_error(at, msg))),
                Some(Stop::SecondBom) => {
                    return Ok(Err(Box::new(
                        Diagnostic::error(
                            Code::XmlSyntax,
                            "not well-formed XML: a second byte-order mark at the start of the file",
                        )
                        .at(self.span(0..3)),
                    )));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
