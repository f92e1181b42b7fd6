//! The SFC (PLCopen TC6 XML 2.01, 2.00 or 1.0; namespaces ignored): the program's elements,
//! their connections, and the skill steps' data (docs/INPUTS.md).
//!
//! The SFC is the one input that grows with the product (100,000 steps make 78 MB), so it is read
//! as a stream ([`read_sfc_stream`], `quick-xml` over any [`BufRead`]): the compile hands it the
//! file itself, so the text is never whole in memory, and no document tree is built. The model is
//! all that is kept. Byte positions come from the reader's position and from where the attribute
//! slices sit in the event's buffer. The graph rules are checked by [`crate::plan`].

use std::collections::HashMap;
use std::io::BufRead;
use std::ops::Range;

use quick_xml::events::{BytesCData, BytesRef, BytesStart, BytesText};

use super::tape::{self, Batch, Kind, Pipeline, Rec, Stop, Tape};

use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::model::{
    Condition, Element, ElementKind, FileHeader, Interner, Name, Sfc, Step, Variable,
};

pub use crate::value::MAX_LIST_DEPTH;

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
    let mut r = Stream {
        wanted: pou.map(|p| p.trim().to_owned()).filter(|p| !p.is_empty()),
        pous: Vec::new(),
        named: HashMap::new(),
        wire_nodes: Vec::new(),
        pending_wired: Vec::new(),
        derived_text: 0,
        derived_refused: false,
        len_hint: usize::try_from(len_hint).unwrap_or(usize::MAX),
        file,
        names: Interner::default(),
        found: Vec::new(),
        ignored: Vec::new(),
        variables: Vec::new(),
        values: String::new(),
    };
    let mut local = Diagnostics::default();
    let outcome = tape::read(input, pipeline, batch_bytes, |t| r.run(t, &mut local))?;
    Ok(match outcome {
        Err(d) => {
            // Not well-formed: only the syntax error counts (the rest may be an artefact of it).
            diags.push(*d);
            None
        }
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
}

/// How much condition text (in bytes of ST) the transitions of a file may take from named
/// transitions and wired networks together: 16 MiB. Such a condition is written once and used
/// by any number of transitions, and a wired network's paths multiply (docs/INPUTS.md), while
/// every transition gets a copy of it in the model and in the program; the text written in the
/// file is paid by the file's size. 20,000 transitions wired to one 512-path network took
/// 2.78 GB and wrote a 279 MB `.src`.
pub const MAX_DERIVED_TEXT: usize = 16 * 1024 * 1024;

/// An FBD/LD element a wired condition may be drawn from (docs/INPUTS.md).
#[derive(Debug)]
struct WireNode {
    local_id: u64,
    /// `inVariable`, `inOutVariable`, `leftPowerRail`, `contact`, `block`, or another.
    tag: String,
    span: Span,
    /// An `inVariable`'s expression or a `contact`'s variable, with its pieces' places.
    text: Option<(String, PieceMap)>,
    negated: bool,
    /// A contact's `edge` (`rising`, `falling`).
    edge: Option<String>,
    type_name: Option<String>,
    /// Direct inputs (a `contact`'s).
    inputs: Vec<(u64, Range<usize>)>,
    /// A `block`'s inputs by formal parameter.
    formal: Vec<Formal>,
}

/// A `block`'s input: its formal parameter and its connections (refLocalId, place).
type Formal = (String, Vec<(u64, Range<usize>)>);

/// A transition whose condition is wired: its localId, where its condition's connections
/// lead, its condition element.
#[derive(Debug)]
struct PendingWired {
    transition: u64,
    refs: Vec<(u64, Range<usize>)>,
    at: Span,
}

/// Where the pieces of a text assembled from the file stand: (offset in the text, offset in the
/// file, whether the piece is the file's bytes as they are).
type PieceMap = Vec<(usize, usize, bool)>;

/// A named transition's body.
#[derive(Debug)]
enum Named {
    /// ST: its text, and where its pieces stand in the file (as an inline condition's).
    St { text: String, map: PieceMap },
    /// A body in another language (`IL`, `SFC`), at the transition.
    Other { language: String, at: Span },
    /// An LD or FBD body: the expression of what its coil or output variable of the
    /// transition's name is wired from, or why there is none.
    Wired(Result<crate::cond::Expr, Box<Diagnostic>>),
}

/// A POU's reading state, kept while one of its actions is read.
struct Outer {
    pou: Option<(Option<String>, bool, usize)>,
    want_pou: bool,
    body_seen: bool,
    sfc_done: bool,
    pous_at: Option<usize>,
    /// The action element's depth.
    depth: usize,
}

/// A named transition being read: its name, depth and place, its ST text so far (and the depth
/// of its `ST` element), or the language of another body.
struct ReadingNamed {
    name: String,
    depth: usize,
    at: Span,
    st: Option<(usize, String, PieceMap)>,
    other: Option<String>,
}

/// The local names the reader looks for; anything else is `Other`. The stack of open elements
/// holds these, so reading allocates nothing per element.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Tag {
    Project,
    FileHeader,
    Types,
    Pous,
    Pou,
    /// A POU's list of named transitions (docs/INPUTS.md).
    Transitions,
    /// Parts of the FBD/LD elements a wired condition is drawn from (docs/INPUTS.md): an
    /// `inVariable`'s `expression`, a `contact`'s `variable`, a `block`'s `inputVariables`.
    Expression,
    WireVariable,
    InputVariables,
    /// A POU's actions, whose bodies may be SFC charts (`POU.ACTION`, docs/INPUTS.md).
    Actions,
    Action,
    Body,
    Sfc,
    Position,
    ConnectionPointIn,
    Connection,
    Variable,
    AddData,
    Data,
    Iwb,
    /// `ressources` or `resources`.
    Resources,
    /// `ressource` or `resource`.
    Resource,
    Skill,
    Time,
    Condition,
    Inline,
    Reference,
    Step,
    Transition,
    SimultaneousDivergence,
    SimultaneousConvergence,
    SelectionDivergence,
    SelectionConvergence,
    JumpStep,
    MacroStep,
    Other,
}

impl Tag {
    pub(crate) fn of(local: &str) -> Tag {
        match local {
            "project" => Tag::Project,
            "fileHeader" => Tag::FileHeader,
            "types" => Tag::Types,
            "pous" => Tag::Pous,
            "pou" => Tag::Pou,
            "transitions" => Tag::Transitions,
            "expression" => Tag::Expression,
            "variable" => Tag::WireVariable,
            "inputVariables" => Tag::InputVariables,
            "actions" => Tag::Actions,
            "action" => Tag::Action,
            "body" => Tag::Body,
            "SFC" => Tag::Sfc,
            "position" => Tag::Position,
            "connectionPointIn" => Tag::ConnectionPointIn,
            "connection" => Tag::Connection,
            "Variable" => Tag::Variable,
            "addData" => Tag::AddData,
            "data" => Tag::Data,
            "iwb" => Tag::Iwb,
            "ressources" | "resources" => Tag::Resources,
            "ressource" | "resource" => Tag::Resource,
            "skill" => Tag::Skill,
            "time" => Tag::Time,
            "condition" => Tag::Condition,
            "inline" => Tag::Inline,
            "reference" => Tag::Reference,
            "step" => Tag::Step,
            "transition" => Tag::Transition,
            "simultaneousDivergence" => Tag::SimultaneousDivergence,
            "simultaneousConvergence" => Tag::SimultaneousConvergence,
            "selectionDivergence" => Tag::SelectionDivergence,
            "selectionConvergence" => Tag::SelectionConvergence,
            "jumpStep" => Tag::JumpStep,
            "macroStep" => Tag::MacroStep,
            _ => Tag::Other,
        }
    }
}

/// The open elements: their tags, and their local names one after another in `text` (for
/// messages), each tag with where its name starts.
#[derive(Default)]
struct Open {
    tags: Vec<(Tag, usize)>,
    text: String,
}

impl Open {
    fn push(&mut self, tag: Tag, name: &str) {
        self.tags.push((tag, self.text.len()));
        self.text.push_str(name);
    }

    fn pop(&mut self) {
        if let Some((_, at)) = self.tags.pop() {
            self.text.truncate(at);
        }
    }

    fn len(&self) -> usize {
        self.tags.len()
    }

    fn last_name(&self) -> Option<&str> {
        self.tags.last().map(|&(_, at)| &self.text[at..])
    }

    /// The tags from depth `from` on, at most [`Open::PLACES`] + 1 of them: the reader looks at
    /// places at most that deep below an element, so a longer list (cut, it matches none of
    /// them) need not be copied at every start tag of a deeply nested file.
    fn below(&self, from: usize, out: &mut Vec<Tag>) {
        out.clear();
        let below = &self.tags[from.min(self.tags.len())..];
        out.extend(below.iter().take(Self::PLACES + 1).map(|t| t.0));
    }

    /// The deepest place below an SFC element that the reader looks at
    /// (`addData/data/iwb/resources`).
    const PLACES: usize = 4;
}

/// A picked attribute's value, kept in a scratch string: where it is there, its raw value's byte
/// range in the file, and whether the value is the raw bytes one to one (no references or
/// normalized whitespace, so offsets into it are offsets into the file).
#[derive(Debug, Clone)]
struct Val {
    at: Range<usize>,
    range: Range<usize>,
    exact: bool,
}

impl Val {
    fn get<'s>(&self, scratch: &'s str) -> &'s str {
        &scratch[self.at.clone()]
    }
}

/// One `Variable`: its tag and its `name` and `Value`.
#[derive(Clone)]
struct VarAttrs {
    tag: Span,
    name: Option<Val>,
    value: Option<Val>,
    /// Read inside `iwb` (these come after the direct ones).
    iwb: bool,
}

/// The element being read (a direct child of `SFC`), with what its descendants contributed.
/// One is reused for every element, so its buffers are allocated once.
struct Building {
    tag: Tag,
    /// The tag's local name when it is [`Tag::Other`].
    other: String,
    span: Span,
    depth: usize,
    /// Attribute values and variable names and values, one after another.
    scratch: String,
    local_id: Option<Val>,
    name: Option<Val>,
    initial: Option<Val>,
    target: Option<Val>,
    x: Option<f64>,
    inputs: Vec<(u64, Range<usize>)>,
    bad_inputs: Vec<Diagnostic>,
    vars: Vec<VarAttrs>,
    iwb: IwbState,
    resource: Option<Name>,
    resources_seen: bool,
    skill: Option<Name>,
    duration: Option<f64>,
    /// A `time@duration` that is not a number of seconds ≥ 0: as written, and where.
    bad_duration: Option<(String, Range<usize>)>,
    time_seen: bool,
    condition: Option<Span>,
    condition_done: bool,
    inline: Option<String>,
    /// Where each piece of `inline` came from: (offset in `inline`, offset in the file, whether
    /// the piece's bytes are the file's bytes one to one).
    inline_map: Vec<(usize, usize, bool)>,
    /// `condition/reference@name`: the name and its range.
    reference: Option<(String, Range<usize>)>,
    /// `condition/connectionPointIn`: a condition wired from FBD/LD elements.
    wired: bool,
    /// Where a wired condition's connections lead (refLocalId, its place).
    wired_refs: Vec<(u64, Range<usize>)>,
    /// An FBD/LD element's text: an `inVariable`'s `expression`, a `contact`'s `variable`.
    wire_text: Option<(String, PieceMap)>,
    /// A `contact`'s `negated` and `edge` (`rising`/`falling`), a `block`'s `typeName`.
    negated: bool,
    edge: Option<String>,
    type_name: Option<String>,
    /// A `block`'s inputs: formal parameter and its connections.
    formal: Vec<Formal>,
    /// The tags below the element (reused).
    rel: Vec<Tag>,
}

impl Building {
    fn new(file: FileId) -> Self {
        Building {
            tag: Tag::Other,
            other: String::new(),
            span: Span::new(file, 0..0),
            depth: 0,
            scratch: String::new(),
            local_id: None,
            name: None,
            initial: None,
            target: None,
            x: None,
            inputs: Vec::new(),
            bad_inputs: Vec::new(),
            vars: Vec::new(),
            iwb: IwbState::Before,
            resource: None,
            resources_seen: false,
            skill: None,
            duration: None,
            bad_duration: None,
            time_seen: false,
            condition: None,
            condition_done: false,
            inline: None,
            inline_map: Vec::new(),
            reference: None,
            wired: false,
            wired_refs: Vec::new(),
            wire_text: None,
            negated: false,
            edge: None,
            type_name: None,
            formal: Vec::new(),
            rel: Vec::new(),
        }
    }

    /// Ready for the next element, keeping the buffers.
    fn reset(&mut self, tag: Tag, other: &str, span: Span, depth: usize) {
        self.tag = tag;
        self.other.clear();
        if tag == Tag::Other {
            self.other.push_str(other);
        }
        self.span = span;
        self.depth = depth;
        self.scratch.clear();
        self.local_id = None;
        self.name = None;
        self.initial = None;
        self.target = None;
        self.x = None;
        self.inputs.clear();
        self.bad_inputs.clear();
        self.vars.clear();
        self.iwb = IwbState::Before;
        self.resource = None;
        self.resources_seen = false;
        self.skill = None;
        self.duration = None;
        self.bad_duration = None;
        self.time_seen = false;
        self.condition = None;
        self.condition_done = false;
        self.inline = None;
        self.inline_map.clear();
        self.reference = None;
        self.wired = false;
        self.wired_refs.clear();
        self.wire_text = None;
        self.negated = false;
        self.edge = None;
        self.type_name = None;
        self.formal.clear();
    }

    fn val(&self, v: &Option<Val>) -> Option<&str> {
        v.as_ref().map(|v| v.get(&self.scratch))
    }

    /// How diagnostics name the element: `localId N` (`?` without one).
    fn id_label(&self) -> String {
        format!("localId {}", self.val(&self.local_id).unwrap_or("?"))
    }

    /// The element's local name.
    fn tag_name(&self) -> &str {
        match self.tag {
            Tag::Step => "step",
            Tag::Transition => "transition",
            Tag::SimultaneousDivergence => "simultaneousDivergence",
            Tag::SimultaneousConvergence => "simultaneousConvergence",
            Tag::SelectionDivergence => "selectionDivergence",
            Tag::SelectionConvergence => "selectionConvergence",
            Tag::JumpStep => "jumpStep",
            Tag::MacroStep => "macroStep",
            _ => &self.other,
        }
    }
}

#[derive(PartialEq, Eq, Clone, Copy)]
enum IwbState {
    Before,
    Inside,
    Done,
}

/// A start tag's event on the tape, and where its bytes sit in the file: the event's content
/// begins one byte after `at` (the `<`).
struct Tagged<'a> {
    e: BytesStart<'a>,
    /// The local name, a part of the content.
    local: &'a str,
    at: usize,
}

impl<'a> Tagged<'a> {
    fn new(rec: &Rec, batch: &'a Batch) -> Self {
        let (name, local, content) = batch.names_and_content(rec);
        Tagged {
            e: BytesStart::from_content(content, name.len()),
            local,
            at: batch.at(rec),
        }
    }

    /// The file offset of `s`, a slice of the event's bytes (`fallback` if it is not one).
    fn offset_of(&self, s: &str, fallback: usize) -> usize {
        let content: &str = &self.e;
        let base = content.as_ptr() as usize;
        let p = s.as_ptr() as usize;
        if p >= base && p + s.len() <= base + content.len() {
            self.at + 1 + (p - base)
        } else {
            fallback
        }
    }

    /// The local name of the tag.
    fn local_name(&self) -> &'a str {
        self.local
    }
}

impl Stream {
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

    /// The `name` attribute as a [`Name`]; `None` when it is missing or blank.
    fn name_attr(
        &mut self,
        t: &Tagged,
        scratch: &mut String,
    ) -> Result<Option<Name>, Box<Diagnostic>> {
        let mark = scratch.len();
        let [n] = self.pick(t, ["name"], scratch)?;
        let name = n
            .map(|a| {
                self.names
                    .name(a.get(scratch), Span::new(self.file, a.range.clone()))
            })
            .filter(|n| !n.key.is_empty());
        scratch.truncate(mark);
        Ok(name)
    }

    /// The attributes named `names` (local names), in that order, their values appended to
    /// `scratch`; others are skipped (not unescaped).
    fn pick<const N: usize>(
        &self,
        t: &Tagged,
        names: [&str; N],
        scratch: &mut String,
    ) -> Result<[Option<Val>; N], Box<Diagnostic>> {
        let mark = scratch.len();
        let mut out: [Option<Val>; N] = std::array::from_fn(|_| None);
        let content: &str = &t.e;
        let name_len = t.e.name().as_ref().len();
        let quick = tape::each_attribute(content, name_len, |key, raw| {
            self.take(t, key, raw, &names, &mut out, scratch)
        });
        if let Some(done) = quick {
            return done.map(|()| out);
        }
        // Not read there: quick-xml's iterator, for its words about the error.
        scratch.truncate(mark);
        let mut out: [Option<Val>; N] = std::array::from_fn(|_| None);
        for a in t.e.attributes() {
            let a = a.map_err(|err| self.syntax_error(t.at, err.to_string()))?;
            self.take(t, a.key.as_ref(), &a.value, &names, &mut out, scratch)?;
        }
        Ok(out)
    }

    /// One attribute for [`Self::pick`]: its value appended to `scratch` and put in `out` when
    /// its local name is one of `names` and not given before.
    fn take<const N: usize>(
        &self,
        t: &Tagged,
        key: &str,
        raw: &str,
        names: &[&str; N],
        out: &mut [Option<Val>; N],
        scratch: &mut String,
    ) -> Result<(), Box<Diagnostic>> {
        let local = tape::local_part(key);
        let Some(slot) = names.iter().position(|n| *n == local) else {
            return Ok(());
        };
        if out[slot].is_some() {
            return Ok(());
        }
        let raw_at = t.offset_of(raw, t.at);
        let range = raw_at..raw_at + raw.len();
        let start = scratch.len();
        // (A byte loop: a search for any of several `char`s goes a character at a time.)
        let plain = !raw
            .bytes()
            .any(|c| matches!(c, b'&' | b'\t' | b'\n' | b'\r'));
        let exact = if plain {
            scratch.push_str(raw);
            true
        } else {
            let attr = quick_xml::events::attributes::Attribute {
                key: quick_xml::name::QName(key),
                value: std::borrow::Cow::Borrowed(raw),
            };
            let v = attr
                .normalized_value(quick_xml::XmlVersion::Implicit1_0)
                .map_err(|err| self.syntax_error(raw_at, err.to_string()))?;
            scratch.push_str(&v);
            v.len() == range.len()
        };
        out[slot] = Some(Val {
            at: start..scratch.len(),
            range,
            exact,
        });
        Ok(())
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
                        if let Some(c) = ch
                            && !building
                            && let Some(ReadingNamed {
                                st: Some((d, body, map)),
                                ..
                            }) = &mut named
                            && stack.len() >= *d
                        {
                            map.push((body.len(), at, false));
                            body.push(c);
                        }
                        if let Some(c) = ch
                            && building
                            && b.wire_text.is_some()
                            && in_wire_text(&b, &stack)
                            && let Some((w, map)) = &mut b.wire_text
                        {
                            map.push((w.len(), at, false));
                            w.push(c);
                        }
                        if let Some(c) = ch
                            && building
                            && b.inline.is_some()
                            && in_inline(&b, &stack)
                        {
                            let inline = b.inline.as_mut().expect("checked");
                            b.inline_map.push((inline.len(), at, false));
                            inline.push(c);
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

    /// A descendant of the element being built, at `stack` (which ends below the element).
    fn inside(
        &mut self,
        b: &mut Building,
        stack: &Open,
        tag: Tag,
        tag_span: Span,
        t: &Tagged,
    ) -> Result<(), Box<Diagnostic>> {
        let mut rel = std::mem::take(&mut b.rel);
        stack.below(b.depth, &mut rel);
        let r = self.inside_at(b, &rel, tag, tag_span, t);
        b.rel = rel;
        r
    }

    fn inside_at(
        &mut self,
        b: &mut Building,
        rel: &[Tag],
        tag: Tag,
        tag_span: Span,
        t: &Tagged,
    ) -> Result<(), Box<Diagnostic>> {
        use Tag as T;
        let mut scratch = std::mem::take(&mut b.scratch);
        let r = (|| {
            match (rel, tag) {
                ([], T::Position) if b.x.is_none() => {
                    let [x] = self.pick(t, ["x"], &mut scratch)?;
                    b.x = Some(
                        x.and_then(|a| a.get(&scratch).trim().parse::<f64>().ok())
                            .filter(|x| x.is_finite())
                            .unwrap_or(0.0),
                    );
                }
                ([T::ConnectionPointIn], T::Connection) => {
                    let mark = scratch.len();
                    match self.pick(t, ["refLocalId"], &mut scratch)? {
                        [Some(a)] => match a.get(&scratch).trim().parse::<u64>() {
                            Ok(r) => b.inputs.push((r, a.range.clone())),
                            Err(_) => b.bad_inputs.push(
                                Diagnostic::error(
                                    Code::DanglingReference,
                                    format!("refLocalId `{}` is not a number", a.get(&scratch)),
                                )
                                .at(self.span(a.range.clone())),
                            ),
                        },
                        [None] => b.bad_inputs.push(
                            Diagnostic::error(
                                Code::DanglingReference,
                                "connection without refLocalId",
                            )
                            .at(tag_span),
                        ),
                    }
                    scratch.truncate(mark);
                }
                ([], T::Variable) => {
                    let [name, value] = self.pick(t, ["name", "Value"], &mut scratch)?;
                    b.vars.push(VarAttrs {
                        tag: tag_span,
                        name,
                        value,
                        iwb: false,
                    });
                }
                ([T::AddData, T::Data], T::Iwb) if b.iwb == IwbState::Before => {
                    b.iwb = IwbState::Inside;
                }
                ([T::AddData, T::Data, T::Iwb], _) if b.iwb == IwbState::Inside => match tag {
                    T::Resources if !b.resources_seen => b.resources_seen = true,
                    T::Skill if b.skill.is_none() => {
                        b.skill = self.name_attr(t, &mut scratch)?;
                    }
                    T::Time if !b.time_seen => {
                        b.time_seen = true;
                        let mark = scratch.len();
                        let [d] = self.pick(t, ["duration"], &mut scratch)?;
                        b.duration = d
                            .as_ref()
                            .and_then(|a| a.get(&scratch).trim().parse::<f64>().ok())
                            .filter(|d| d.is_finite() && *d >= 0.0);
                        if b.duration.is_none()
                            && let Some(a) = &d
                        {
                            b.bad_duration =
                                Some((a.get(&scratch).trim().to_owned(), a.range.clone()));
                        }
                        scratch.truncate(mark);
                    }
                    T::Variable => {
                        let [name, value] = self.pick(t, ["name", "Value"], &mut scratch)?;
                        b.vars.push(VarAttrs {
                            tag: tag_span,
                            name,
                            value,
                            iwb: true,
                        });
                    }
                    _ => {}
                },
                ([T::AddData, T::Data, T::Iwb, T::Resources], T::Resource)
                    if b.iwb == IwbState::Inside && b.resource.is_none() =>
                {
                    b.resource = self.name_attr(t, &mut scratch)?;
                }
                ([], T::Condition) if b.condition.is_none() && !b.condition_done => {
                    b.condition = Some(tag_span);
                }
                ([T::Condition], T::Inline)
                    if b.condition.is_some() && b.inline.is_none() && b.reference.is_none() =>
                {
                    b.inline = Some(String::new());
                }
                ([T::Condition], T::Reference)
                    if b.condition.is_some() && b.inline.is_none() && b.reference.is_none() =>
                {
                    let mark = scratch.len();
                    let [n] = self.pick(t, ["name"], &mut scratch)?;
                    b.reference = Some(match n {
                        Some(a) => (a.get(&scratch).to_owned(), a.range),
                        None => (String::new(), tag_span.range.clone()),
                    });
                    scratch.truncate(mark);
                }
                ([T::Condition], T::ConnectionPointIn) if b.condition.is_some() => b.wired = true,
                // The wired condition's connections (`condition/connectionPointIn/connection`;
                // older files: `condition/connection`).
                // (Also after a written condition: both at once is an error, `condition`.)
                ([T::Condition, T::ConnectionPointIn], T::Connection)
                | ([T::Condition], T::Connection)
                    if b.condition.is_some() =>
                {
                    b.wired = true;
                    let mark = scratch.len();
                    let [r] = self.pick(t, ["refLocalId"], &mut scratch)?;
                    if let Some(a) = r
                        && let Ok(id) = a.get(&scratch).trim().parse::<u64>()
                    {
                        b.wired_refs.push((id, a.range.clone()));
                    }
                    scratch.truncate(mark);
                }
                ([], T::Expression) | ([], T::WireVariable)
                    if b.tag == T::Other && b.wire_text.is_none() =>
                {
                    b.wire_text = Some((String::new(), Vec::new()));
                }
                ([T::InputVariables], T::WireVariable) => {
                    let mark = scratch.len();
                    let [f] = self.pick(t, ["formalParameter"], &mut scratch)?;
                    let formal = f
                        .map(|a| a.get(&scratch).trim().to_owned())
                        .unwrap_or_default();
                    scratch.truncate(mark);
                    b.formal.push((formal, Vec::new()));
                }
                ([T::InputVariables, T::WireVariable, T::ConnectionPointIn], T::Connection) => {
                    let mark = scratch.len();
                    let [r] = self.pick(t, ["refLocalId"], &mut scratch)?;
                    if let Some(a) = r
                        && let Ok(id) = a.get(&scratch).trim().parse::<u64>()
                        && let Some(f) = b.formal.last_mut()
                    {
                        f.1.push((id, a.range.clone()));
                    }
                    scratch.truncate(mark);
                }
                _ => {}
            }
            Ok(())
        })();
        b.scratch = scratch;
        r
    }

    /// The transitions whose conditions are wired (docs/INPUTS.md) get their expressions, built
    /// from the FBD/LD elements of the body; the body's parts are then forgotten.
    /// Counts a condition a transition takes from a named transition or a wired network
    /// against [`MAX_DERIVED_TEXT`]: past it, `E316` once (at `at`, the transition `element`)
    /// and no condition.
    fn derived(
        &mut self,
        cond: Option<Box<Condition>>,
        at: &Span,
        element: String,
        diags: &mut Diagnostics,
    ) -> Option<Box<Condition>> {
        let c = cond?;
        self.derived_text = self.derived_text.saturating_add(c.text.len());
        if self.derived_text <= MAX_DERIVED_TEXT {
            return Some(c);
        }
        if !self.derived_refused {
            self.derived_refused = true;
            diags.push(
                Diagnostic::error(
                    Code::BadCondition,
                    format!(
                        "the conditions that transitions take from named transitions and wired \
                         networks come to more than {} MiB of text here (each transition gets its \
                         own copy in the program): give a condition many transitions share a \
                         signal of its own, set once, and name that signal in them",
                        MAX_DERIVED_TEXT >> 20
                    ),
                )
                .at(at.clone())
                .element(element),
            );
        }
        None
    }

    fn resolve_wired(&mut self, els: &mut [Element], diags: &mut Diagnostics) {
        let nodes = std::mem::take(&mut self.wire_nodes);
        let pending = std::mem::take(&mut self.pending_wired);
        if pending.is_empty() {
            return;
        }
        let by_id: HashMap<u64, &WireNode> = nodes.iter().map(|n| (n.local_id, n)).collect();
        let at_of: HashMap<u64, usize> = els
            .iter()
            .enumerate()
            .map(|(i, e)| (e.local_id, i))
            .collect();
        for p in pending {
            if self.derived_refused {
                break;
            }
            let w = Wiring {
                file: self.file,
                nodes: &by_id,
                elements: els,
                at_of: &at_of,
                built: std::cell::Cell::new(0),
            };
            let mut visiting = Vec::new();
            match w.any_of(&p.refs, &p.at, &mut visiting) {
                Ok(expr) => {
                    let expr = crate::cond::as_condition(expr);
                    if let Some(&i) = at_of.get(&p.transition) {
                        let cond = if expr.is_true() {
                            None
                        } else {
                            Some(Box::new(Condition {
                                text: expr.to_st(),
                                expr,
                                span: p.at.clone(),
                                reference: false,
                            }))
                        };
                        let label = format!("localId {}", p.transition);
                        let cond = self.derived(cond, &p.at, label, diags);
                        els[i].kind = ElementKind::Transition(cond);
                    }
                }
                Err(d) => diags.push((*d).element(format!("localId {}", p.transition))),
            }
        }
    }

    /// A named transition's LD/FBD body (docs/INPUTS.md): the expression its coil or output
    /// variable of the transition's name is wired from.
    fn named_network(
        &self,
        nodes: &[WireNode],
        name: &str,
        at: &Span,
    ) -> Result<crate::cond::Expr, Box<Diagnostic>> {
        let key = crate::names::key(name);
        let out = nodes.iter().find(|n| {
            matches!(n.tag.as_str(), "coil" | "outVariable")
                && n.text
                    .as_ref()
                    .is_some_and(|(t, _)| crate::names::key(t.trim()) == key)
        });
        let Some(out) = out else {
            return Err(wiring_error(
                at,
                format!(
                    "the named transition `{name}` has no coil or output variable named `{name}`"
                ),
            ));
        };
        let by_id: HashMap<u64, &WireNode> = nodes.iter().map(|n| (n.local_id, n)).collect();
        let w = Wiring {
            file: self.file,
            nodes: &by_id,
            elements: &[],
            at_of: &HashMap::new(),
            built: std::cell::Cell::new(0),
        };
        w.any_of(&out.inputs, &out.span, &mut vec![out.local_id])
            .map(crate::cond::as_condition)
    }

    /// Starts building the element `tag` at `depth`: its attributes.
    fn begin(
        &mut self,
        b: &mut Building,
        t: &Tagged,
        tag: Tag,
        name: &str,
        tag_span: Span,
        depth: usize,
    ) -> Result<(), Box<Diagnostic>> {
        b.reset(tag, name, tag_span, depth);
        let mut scratch = std::mem::take(&mut b.scratch);
        let picked = self.pick(
            t,
            [
                "localId",
                "name",
                "initialStep",
                "targetName",
                "negated",
                "typeName",
                "edge",
            ],
            &mut scratch,
        );
        b.scratch = scratch;
        let [id, n, initial, target, negated, type_name, edge] = picked?;
        b.local_id = id;
        b.name = n;
        b.initial = initial;
        b.target = target;
        b.negated = negated.is_some_and(|a| a.get(&b.scratch).trim() == "true");
        b.type_name = type_name.map(|a| a.get(&b.scratch).trim().to_owned());
        b.edge = edge
            .map(|a| a.get(&b.scratch).trim().to_owned())
            .filter(|e| e != "none" && !e.is_empty());
        Ok(())
    }

    /// The element is complete: check it and turn it into the model.
    fn finish(&mut self, b: &mut Building, diags: &mut Diagnostics) -> Option<Element> {
        let file = self.file;
        let kind = match b.tag {
            Tag::Step => ElementKind::Step(Box::new(self.step(b, diags))),
            Tag::Transition => ElementKind::Transition(self.condition(b, diags)),
            Tag::SimultaneousDivergence => ElementKind::SimultaneousDivergence,
            Tag::SimultaneousConvergence => ElementKind::SimultaneousConvergence,
            Tag::SelectionDivergence => ElementKind::SelectionDivergence,
            Tag::SelectionConvergence => ElementKind::SelectionConvergence,
            Tag::JumpStep => {
                let target = b
                    .target
                    .as_ref()
                    .filter(|a| !a.get(&b.scratch).trim().is_empty())
                    .map(|a| {
                        Box::new(
                            self.names
                                .name(a.get(&b.scratch), Span::new(file, a.range.clone())),
                        )
                    });
                if target.is_none() {
                    diags.push(
                        Diagnostic::error(
                            Code::BadJump,
                            "jumpStep without `targetName`: name the step to jump to",
                        )
                        .at(b.span.clone())
                        .element(b.id_label()),
                    );
                }
                ElementKind::JumpStep(target)
            }
            Tag::MacroStep => ElementKind::MacroStep,
            _ if matches!(
                b.tag_name(),
                "inVariable"
                    | "inOutVariable"
                    | "outVariable"
                    | "leftPowerRail"
                    | "rightPowerRail"
                    | "contact"
                    | "coil"
                    | "block"
            ) =>
            {
                // A part a wired condition may be drawn from (docs/INPUTS.md): kept aside.
                if let Some(Ok(id)) = b.val(&b.local_id).map(|v| v.trim().parse::<u64>()) {
                    self.wire_nodes.push(WireNode {
                        local_id: id,
                        tag: b.tag_name().to_owned(),
                        span: b.span.clone(),
                        text: b.wire_text.take(),
                        negated: b.negated,
                        edge: b.edge.take(),
                        type_name: b.type_name.take(),
                        inputs: std::mem::take(&mut b.inputs),
                        formal: std::mem::take(&mut b.formal),
                    });
                }
                return None;
            }
            _ => {
                // Reported once per kind and chart (see `report_ignored`).
                let tag = b.tag_name();
                let n = self.ignored.iter().filter(|i| i.0 == tag).count() + 1;
                let label = match b.val(&b.local_id) {
                    Some(v) => format!("localId {}", v.trim()),
                    None => format!("{tag} no. {n} of the SFC body"),
                };
                self.ignored.push((tag.to_owned(), b.span.clone(), label));
                return None;
            }
        };
        let local_id = match b
            .local_id
            .as_ref()
            .map(|a| (a.get(&b.scratch).trim().parse::<u64>(), a))
        {
            Some((Ok(id), _)) => id,
            Some((Err(_), a)) => {
                diags.push(
                    Diagnostic::error(
                        Code::BadLocalId,
                        format!(
                            "`{}` has localId `{}`, which is not a number from 0 to {}",
                            b.tag_name(),
                            a.get(&b.scratch),
                            u64::MAX
                        ),
                    )
                    .at(Span::new(file, a.range.clone())),
                );
                return None;
            }
            None => {
                diags.push(
                    Diagnostic::error(
                        Code::BadLocalId,
                        format!("`{}` without localId", b.tag_name()),
                    )
                    .at(b.span.clone()),
                );
                return None;
            }
        };
        for d in b.bad_inputs.drain(..) {
            diags.push(d.element(format!("localId {local_id}")));
        }
        Some(Element {
            local_id,
            kind,
            span: b.span.clone(),
            x: b.x.unwrap_or(0.0),
            inputs: b.inputs.as_slice().into(),
        })
    }

    /// A transition's condition: parsed, syntax errors located in the file. `None` when the
    /// transition always fires (no condition, or `TRUE`).
    fn condition(&mut self, b: &Building, diags: &mut Diagnostics) -> Option<Box<Condition>> {
        let c = b.condition.as_ref()?;
        // Most transitions always fire: `TRUE` alone, between the spaces the condition's lexer
        // skips, is what the parser reads as the literal (no tokens, vector or string made).
        if let Some(inline) = &b.inline
            && inline
                .trim_matches(|c: char| c.is_ascii_whitespace())
                .eq_ignore_ascii_case("TRUE")
        {
            return None;
        }
        let label = || b.id_label();
        let file = self.file;
        if b.wired && !b.wired_refs.is_empty() && (b.inline.is_some() || b.reference.is_some()) {
            diags.push(
                Diagnostic::error(
                    Code::BadCondition,
                    "the condition is both written and wired: keep one",
                )
                .at(c.clone())
                .element(label()),
            );
            return None;
        }
        let (text, parsed, reference) = if let Some(inline) = &b.inline {
            let map = |o: usize| map_offset(&b.inline_map, o);
            (inline.trim(), crate::cond::parse(inline, &map), false)
        } else if let Some((name, _)) = &b.reference
            && let Some(body) = self.named.get(&crate::names::key(name.trim()))
        {
            // A named transition of the POU (docs/INPUTS.md): its body is the condition.
            if self.derived_refused {
                return None;
            }
            let made = match body {
                Named::Wired(Ok(expr)) if expr.is_true() => None,
                Named::Wired(Ok(expr)) => Some(Box::new(Condition {
                    text: expr.to_st(),
                    expr: expr.clone(),
                    span: c.clone(),
                    reference: true,
                })),
                Named::Wired(Err(d)) => {
                    diags.push(
                        (**d)
                            .clone()
                            .element(label())
                            .related(c.clone(), "the condition naming the transition"),
                    );
                    None
                }
                Named::Other { language, at } => {
                    diags.push(
                        Diagnostic::error(
                            Code::Unsupported,
                            format!(
                                "the named transition `{}` has a {language} body: ST (an expression, or `{} := expression`), LD and FBD are supported",
                                name.trim(),
                                name.trim()
                            ),
                        )
                        .at(c.clone())
                        .element(label())
                        .related(at.clone(), "the named transition"),
                    );
                    None
                }
                Named::St { text, map } => {
                    let (from, to) = named_expression(text, name.trim());
                    let map = |o: usize| map_offset(map, from + o);
                    let expr_text = &text[from..to];
                    let one_line = expr_text.split_whitespace().collect::<Vec<_>>().join(" ");
                    match crate::cond::parse(expr_text, &map) {
                        Ok(e) if e.is_true() => None,
                        Ok(expr) => Some(Box::new(Condition {
                            text: one_line,
                            expr,
                            span: c.clone(),
                            reference: true,
                        })),
                        Err(err) => {
                            let s = map(err.at.start);
                            let e = map(err.at.end.saturating_sub(1)) + 1;
                            diags.push(
                                Diagnostic::error(
                                    Code::BadCondition,
                                    format!(
                                        "condition `{one_line}` (the named transition `{}`): {}",
                                        name.trim(),
                                        err.message
                                    ),
                                )
                                .at(Span::new(file, s..e.max(s + 1)))
                                .element(label()),
                            );
                            None
                        }
                    }
                }
            };
            return self.derived(made, c, label(), diags);
        } else if let Some((name, range)) = &b.reference {
            // The name is the condition: one name, nothing else.
            let lead = name.len() - name.trim_start().len();
            let map = |o: usize| (range.start + o).min(range.end);
            let parsed = if range.len() == name.len() {
                crate::cond::parse(name, &map)
            } else {
                crate::cond::parse(name, &|_| range.start)
            };
            let parsed = match parsed {
                Ok(e) if matches!(e.kind, crate::cond::ExprKind::Name(_)) => Ok(e),
                _ if name.trim().is_empty() => Err(crate::cond::SyntaxError {
                    at: 0..name.len(),
                    message: "condition reference without a `name`".to_owned(),
                }),
                _ => Err(crate::cond::SyntaxError {
                    at: lead..name.trim_end().len(),
                    message: format!(
                        "condition reference `{}` is not one name (the name is the condition: a signal)",
                        name.trim()
                    ),
                }),
            };
            (name.trim(), parsed, true)
        } else if b.wired {
            // Made an expression at the body's end, when all its parts are read.
            match b.val(&b.local_id).map(|v| v.trim().parse::<u64>()) {
                Some(Ok(id)) if !b.wired_refs.is_empty() => {
                    self.pending_wired.push(PendingWired {
                        transition: id,
                        refs: b.wired_refs.clone(),
                        at: c.clone(),
                    });
                }
                Some(Ok(_)) => diags.push(
                    Diagnostic::error(
                        Code::BadCondition,
                        "the wired condition has no connection: connect it to the element whose output is the condition",
                    )
                    .at(c.clone())
                    .element(label()),
                ),
                _ => {}
            }
            return None;
        } else {
            diags.push(
                Diagnostic::error(
                    Code::BadCondition,
                    "`condition` holds neither `inline` ST nor a `reference`",
                )
                .at(c.clone())
                .element(label()),
            );
            return None;
        };
        // As written, on one line (for messages, listings and comments).
        let text = text.split_whitespace().collect::<Vec<_>>().join(" ");
        match parsed {
            Ok(e) if e.is_true() => None,
            Ok(expr) => Some(Box::new(Condition {
                text,
                expr,
                span: c.clone(),
                reference,
            })),
            Err(err) => {
                let at = if reference {
                    let r = &b.reference.as_ref().expect("reference").1;
                    if r.len() == text.len() || err.at.end <= r.len() {
                        (r.start + err.at.start).min(r.end)..(r.start + err.at.end).min(r.end)
                    } else {
                        r.clone()
                    }
                } else {
                    let s = map_offset(&b.inline_map, err.at.start);
                    let e = map_offset(&b.inline_map, err.at.end.saturating_sub(1)) + 1;
                    s..e.max(s + 1)
                };
                // On character boundaries of the file once the text is there
                // (`Diagnostics::snap`), whatever the pieces' mapping gave.
                diags.push(
                    Diagnostic::error(
                        Code::BadCondition,
                        format!("condition `{}`: {}", text, err.message),
                    )
                    .at(Span::new(file, at))
                    .element(label()),
                );
                None
            }
        }
    }

    fn step(&mut self, b: &Building, diags: &mut Diagnostics) -> Step {
        let file = self.file;
        let label = || b.id_label();
        let s = &b.scratch;
        let first = self.variables.len();
        let mut invalid_variables = Vec::new();
        // The direct ones first, then those in `iwb`.
        let ordered = b
            .vars
            .iter()
            .filter(|v| !v.iwb)
            .chain(b.vars.iter().filter(|v| v.iwb));
        for v in ordered {
            let Some(name) = &v.name else {
                diags.push(
                    Diagnostic::error(Code::BadVariableSyntax, "Variable without `name`")
                        .at(v.tag.clone())
                        .element(label()),
                );
                continue;
            };
            let name_text = name.get(s);
            let Some(value) = &v.value else {
                diags.push(
                    Diagnostic::error(
                        Code::BadVariableSyntax,
                        format!("Variable `{name_text}` without `Value`"),
                    )
                    .at(v.tag.clone())
                    .element(label()),
                );
                invalid_variables.push(self.names.strings(name_text).1);
                continue;
            };
            let value_text = value.get(s);
            match crate::value::check_value(value_text) {
                Ok(()) => {
                    let at = self.values.len();
                    self.values.push_str(value_text.trim());
                    let name = self
                        .names
                        .name(name_text, Span::new(file, name.range.clone()));
                    self.variables.push(Variable {
                        name,
                        raw: at..self.values.len(),
                        value_range: value.range.clone(),
                    });
                }
                Err((offset, msg)) => {
                    invalid_variables.push(self.names.strings(name_text).1);
                    // Point into the raw value when it has no references (then offsets agree).
                    let raw_len = value.range.len();
                    let at = if value.exact {
                        value.range.start + offset.min(raw_len)
                    } else {
                        value.range.start
                    };
                    diags.push(
                        Diagnostic::error(
                            Code::BadVariableSyntax,
                            format!("variable `{name_text}`: {msg}"),
                        )
                        .at(Span::new(file, at..(at + 1).min(value.range.end.max(at))))
                        .element(label()),
                    );
                }
            }
        }
        if let Some((text, at)) = &b.bad_duration {
            diags.push(
                Diagnostic::warning(
                    Code::BadDuration,
                    format!(
                        "`time@duration` is `{text}`, not a number of seconds of at least 0 \
                         (`2.75`): the step has no time (the picture draws it without one)"
                    ),
                )
                .at(Span::new(file, at.clone()))
                .element(label()),
            );
        }
        Step {
            name: self.names.strings(b.val(&b.name).unwrap_or("")).0,
            initial: b
                .val(&b.initial)
                .is_some_and(|v| v.trim() == "true" || v.trim() == "1"),
            resource: b.resource.clone(),
            skill: b.skill.clone(),
            duration: b.duration,
            variables: first..self.variables.len(),
            invalid_variables,
        }
    }

    /// The POU to use, once the whole file is read.
    fn choose(
        &mut self,
        header: FileHeader,
        root: Span,
        first_pou: Option<(Span, String)>,
        diags: &mut Diagnostics,
    ) -> Option<Sfc> {
        // A program's chart, else any POU's, else an action's (docs/INPUTS.md).
        let chosen = self
            .found
            .iter()
            .position(|p| p.program)
            .or_else(|| self.found.iter().position(|p| !p.is_action()))
            .or(if self.found.is_empty() { None } else { Some(0) });
        let with_sfc: Vec<&str> = self
            .pous
            .iter()
            .filter(|p| p.1)
            .map(|p| p.0.as_str())
            .collect();
        let list = |names: &[&str]| {
            let v: Vec<String> = names.iter().take(12).map(|n| format!("`{n}`")).collect();
            let more = if names.len() > 12 { ", ..." } else { "" };
            format!("{}{more}", v.join(", "))
        };
        let Some(i) = chosen else {
            let all: Vec<&str> = self.pous.iter().map(|p| p.0.as_str()).collect();
            let message = match (&self.wanted, &first_pou) {
                (Some(w), _) if !with_sfc.is_empty() => format!(
                    "no POU named `{w}` with an SFC body; the POUs with one: {}",
                    list(&with_sfc)
                ),
                (Some(w), Some(_)) => format!(
                    "no POU named `{w}` with an SFC body; none of the {} POUs ({}) has one",
                    all.len(),
                    list(&all)
                ),
                (_, None) => {
                    "the SFC file has no `pou` (types/pous/pou, or in an addData/data)".to_owned()
                }
                (None, Some((_, name))) if all.len() == 1 => {
                    format!("pou `{name}` has no SFC body (body/SFC)")
                }
                (None, Some(_)) => format!(
                    "none of the {} POUs ({}) has an SFC body (body/SFC)",
                    all.len(),
                    list(&all)
                ),
            };
            diags.push(
                Diagnostic::error(Code::NoSfcBody, message)
                    .at(first_pou.map(|(s, _)| s).unwrap_or(root)),
            );
            return None;
        };
        if self.wanted.is_none() && with_sfc.len() > 1 {
            let used = self.found[i].name.clone().unwrap_or_default();
            let others: Vec<&str> = with_sfc.iter().copied().filter(|n| *n != used).collect();
            diags.push(
                Diagnostic::warning(
                    Code::SeveralPous,
                    format!(
                        "{} POUs have an SFC body; `{used}` is used ({}), not {}: name the one meant with `--pou NAME` or `#NAME` after the SFC file's name in the blackboard",
                        with_sfc.len(),
                        if self.found[i].program { "the first program" } else { "the first with one" },
                        list(&others)
                    ),
                )
                .at(self.found[i].sfc_span.clone()),
            );
        }
        let pou = self.found.swap_remove(i);
        Some(Sfc {
            file: self.file,
            header,
            pou_name: pou.name,
            elements: pou.elements,
            span: Some(pou.sfc_span),
            variables: std::mem::take(&mut self.variables),
            values: std::mem::take(&mut self.values),
            closed: Vec::new(),
            macros: pou.macros,
        })
    }
}

/// One warning per kind of ignored element (action blocks, unknown elements), naming them.
fn report_ignored(ignored: &[(String, Span, String)], diags: &mut Diagnostics) {
    let mut kinds: Vec<&str> = Vec::new();
    for (tag, _, _) in ignored {
        if !kinds.contains(&tag.as_str()) {
            kinds.push(tag);
        }
    }
    for kind in kinds {
        let all: Vec<&(String, Span, String)> = ignored.iter().filter(|i| i.0 == kind).collect();
        let what = if kind == "actionBlock" {
            "action block".to_owned()
        } else {
            format!("`{kind}` element")
        };
        let labels: Vec<&str> = all.iter().take(8).map(|i| i.2.as_str()).collect();
        let more = if all.len() > 8 { ", ..." } else { "" };
        let msg = if all.len() == 1 {
            format!("{what} ignored")
        } else {
            format!(
                "{} {what}s ignored ({}{more})",
                all.len(),
                labels.join(", ")
            )
        };
        diags.push(
            Diagnostic::warning(Code::Ignored, msg)
                .at(all[0].1.clone())
                .element(all[0].2.clone()),
        );
    }
}

/// Where an element stands in the document, for the parts read outside SFC elements.
enum PathKind {
    FileHeader,
    Pou,
    /// An action of a POU (`pou/actions/action`).
    Action,
    Body,
    Sfc,
    Other,
}

impl PathKind {
    fn of(stack: &Open, tag: Tag) -> Self {
        use Tag as T;
        let n = stack.len();
        let open = |i: usize| stack.tags[i].0;
        match tag {
            T::FileHeader if n == 1 && open(0) == T::Project => PathKind::FileHeader,
            // A POU at `n` (docs/INPUTS.md): in `types/pous`, or kept in an `addData/data` anywhere
            // (CODESYS and TwinCAT exports).
            T::Pou if PathKind::pou_at(stack, n) => PathKind::Pou,
            T::Action if PathKind::action_at(stack, n) => PathKind::Action,
            T::Body if n >= 1 && PathKind::owner_at(stack, n - 1) => PathKind::Body,
            T::Sfc if n >= 2 && open(n - 1) == T::Body && PathKind::owner_at(stack, n - 2) => {
                PathKind::Sfc
            }
            _ => PathKind::Other,
        }
    }

    /// Whether an `action` at depth `k` is a POU's (`pou/actions/action`).
    fn action_at(stack: &Open, k: usize) -> bool {
        let t = |i: usize| stack.tags[i].0;
        k >= 2 && t(k - 1) == Tag::Actions && t(k - 2) == Tag::Pou && PathKind::pou_at(stack, k - 2)
    }

    /// Whether the element at depth `k` (open) is a POU or one of its actions: what a `body`
    /// belongs to.
    fn owner_at(stack: &Open, k: usize) -> bool {
        match stack.tags.get(k).map(|t| t.0) {
            Some(Tag::Pou) => PathKind::pou_at(stack, k),
            Some(Tag::Action) => PathKind::action_at(stack, k),
            _ => false,
        }
    }

    /// Whether a `pou` at depth `k` of `stack` (its parents `stack.tags[..k]`) is a POU:
    /// `project/types/pous/pou`, or a `pou` right inside an `addData/data`.
    fn pou_at(stack: &Open, k: usize) -> bool {
        let t = |i: usize| stack.tags[i].0;
        (k == 3 && [t(0), t(1), t(2)] == [Tag::Project, Tag::Types, Tag::Pous])
            || (k >= 2 && t(k - 1) == Tag::Data && t(k - 2) == Tag::AddData)
    }
}

/// An element inside the one being built closed; `stack` is what remains open.
fn end_inside(b: &mut Building, stack: &Open) {
    let depth = b.depth.min(stack.len());
    let rel = &stack.tags[depth..];
    match rel {
        // `</iwb>` closed: only the first iwb counts.
        [(Tag::AddData, _), (Tag::Data, _)] if b.iwb == IwbState::Inside => b.iwb = IwbState::Done,
        // `</condition>` closed: only the first condition counts.
        [] if b.condition.is_some() => b.condition_done = true,
        _ => {}
    }
}

/// Adds text (read from `raw`, a range of the file) to the element's inline condition when the
/// stack is inside it.
fn inline_text<'s>(
    b: &mut Building,
    stack: &Open,
    raw: Range<usize>,
    text: impl FnOnce() -> std::borrow::Cow<'s, str>,
) {
    if b.inline.is_some() && in_inline(b, stack) {
        let t = text();
        let inline = b.inline.get_or_insert_default();
        b.inline_map
            .push((inline.len(), raw.start, t.len() == raw.len()));
        inline.push_str(&t);
    } else if b.wire_text.is_some() && in_wire_text(b, stack) {
        let t = text();
        if let Some((w, map)) = &mut b.wire_text {
            map.push((w.len(), raw.start, t.len() == raw.len()));
            w.push_str(&t);
        }
    }
}

/// Whether the stack is inside an FBD/LD element's `expression` or `variable`.
fn in_wire_text(b: &Building, stack: &Open) -> bool {
    let rel = &stack.tags[b.depth.min(stack.len())..];
    matches!(rel.first(), Some((Tag::Expression | Tag::WireVariable, _)))
}

/// The expression of a named transition's ST body: the text after `name :=` when it assigns
/// (to its own name) or after a bare `:=`, without a final `;`; as byte offsets of `text`.
fn named_expression(text: &str, name: &str) -> (usize, usize) {
    let mut from = text.len() - text.trim_start().len();
    let rest = &text[from..];
    if rest.len() > name.len()
        && rest.is_char_boundary(name.len())
        && rest[..name.len()].eq_ignore_ascii_case(name)
        && rest[name.len()..].trim_start().starts_with(":=")
    {
        let after = &rest[name.len()..];
        from += name.len() + (after.len() - after.trim_start().len()) + 2;
    } else if rest.starts_with(":=") {
        // IEC 61131-3's textual form `TRANSITION … := expression; END_TRANSITION`, as some
        // tools export the body.
        from += 2;
    }
    // The statement ends at its `;` (outside a `(* comment *)`); what follows is comments.
    let mut to = text.trim_end().len().max(from);
    let b = text.as_bytes();
    let mut i = from;
    while i < to {
        if text[i..].starts_with("(*") {
            i = text[i + 2..].find("*)").map_or(to, |j| i + 2 + j + 2);
            continue;
        }
        if b[i] == b';' {
            to = i;
            break;
        }
        i += 1;
    }
    (from, to)
}

/// Adds text to a named transition's ST body when the stack is inside it.
fn named_text<'s>(
    named: &mut Option<ReadingNamed>,
    stack: &Open,
    raw: Range<usize>,
    text: impl FnOnce() -> std::borrow::Cow<'s, str>,
) {
    if let Some(ReadingNamed {
        st: Some((d, body, map)),
        ..
    }) = named
        && stack.len() >= *d
    {
        let t = text();
        map.push((body.len(), raw.start, t.len() == raw.len()));
        body.push_str(&t);
    }
}

/// The file offset of byte `o` of an inline condition assembled from the pieces of `map`.
fn map_offset(map: &[(usize, usize, bool)], o: usize) -> usize {
    let i = map.partition_point(|&(c, _, _)| c <= o);
    match i.checked_sub(1).map(|i| map[i]) {
        Some((c, f, true)) => f + (o - c),
        Some((_, f, false)) => f,
        None => map.first().map_or(0, |m| m.1),
    }
}

/// Builds a wired condition's expression (docs/INPUTS.md) from the FBD/LD elements of the body.
struct Wiring<'a> {
    file: FileId,
    nodes: &'a HashMap<u64, &'a WireNode>,
    elements: &'a [Element],
    at_of: &'a HashMap<u64, usize>,
    /// Elements made part of the expression so far (an element reached twice counts twice):
    /// at most [`crate::cond::MAX_TOKENS`], as a written condition, so a long chain or a net
    /// that fans in again cannot build a tree the recursive passes over it cannot walk.
    built: std::cell::Cell<usize>,
}

/// The blocks a wired condition may use (docs/INPUTS.md), as messages list them.
const WIRED_BLOCKS: &str = crate::cond::STANDARD_FUNCTIONS;

/// Why a wired condition cannot use a block of type `ty` (upper case) that is not one of
/// [`WIRED_BLOCKS`]: what the block is and what to do instead, said after the block's name.
fn refused_block(ty: &str) -> String {
    let (what, hint) = match ty {
        "TON" | "TOF" | "TP" | "TONR" => (
            " (a timer)",
            "; to wait a time after a step, write the step's time in the condition instead (`Step.t >= T#8s`)",
        ),
        "R_TRIG" | "F_TRIG" => (
            " (an edge detector)",
            "; an edge is not a condition a robot program can wait for (compare the signal's level instead)",
        ),
        "SR" | "RS" => (" (a bistable, which keeps a state)", ""),
        "CTU" | "CTD" | "CTUD" => (" (a counter)", ""),
        "DIV" | "MOD" | "EXPT" => (
            " (arithmetic)",
            "; of arithmetic, ADD, SUB and MUL are (a robot controller's integer division and power differ)",
        ),
        _ => ("", ""),
    };
    format!("{what}: a wired condition may use only the blocks {WIRED_BLOCKS}{hint}")
}

/// A diagnostic of a wired condition, located at `at`.
fn wiring_error(at: &Span, message: String) -> Box<Diagnostic> {
    Box::new(Diagnostic::error(Code::BadCondition, message).at(at.clone()))
}

impl Wiring<'_> {
    fn bin(
        op: crate::cond::BinOp,
        a: crate::cond::Expr,
        b: crate::cond::Expr,
        at: &Span,
    ) -> crate::cond::Expr {
        crate::cond::Expr {
            kind: crate::cond::ExprKind::Bin(op, Box::new(a), Box::new(b)),
            span: at.range.clone(),
        }
    }

    /// Several connections into one input are an OR (as LD draws parallel paths).
    fn any_of(
        &self,
        refs: &[(u64, Range<usize>)],
        at: &Span,
        visiting: &mut Vec<u64>,
    ) -> Result<crate::cond::Expr, Box<Diagnostic>> {
        let mut out: Option<crate::cond::Expr> = None;
        for (r, place) in refs {
            let e = self.node(*r, &Span::new(self.file, place.clone()), visiting)?;
            out = Some(match out {
                None => e,
                Some(prev) => Self::bin(crate::cond::BinOp::Or, prev, e, at),
            });
        }
        out.ok_or_else(|| {
            wiring_error(
                at,
                "an input of the wired condition is not connected".to_owned(),
            )
        })
    }

    /// The value of the element `id` (reached from `from`).
    fn node(
        &self,
        id: u64,
        from: &Span,
        visiting: &mut Vec<u64>,
    ) -> Result<crate::cond::Expr, Box<Diagnostic>> {
        use crate::cond::{BinOp, Expr, ExprKind};
        let Some(n) = self.nodes.get(&id) else {
            return Err(match self.at_of.get(&id) {
                Some(&i) => wiring_error(
                    from,
                    format!(
                        "a wired condition is drawn from a {} (localId {id}): only inVariable, inOutVariable, leftPowerRail, contact and the blocks {WIRED_BLOCKS} give one",
                        self.elements[i].kind.tag()
                    ),
                ),
                None => wiring_error(
                    from,
                    format!(
                        "the wired condition's connection names localId {id}, which is no element of the body"
                    ),
                ),
            });
        };
        // How messages name the element: a block with its type (`block AND localId 5`).
        let named = match (n.tag.as_str(), n.type_name.as_deref().map(str::trim)) {
            ("block", Some(ty)) if !ty.is_empty() => format!("block {ty} localId {id}"),
            ("block", _) => format!("block without typeName localId {id}"),
            (tag, _) => format!("{tag} localId {id}"),
        };
        // Every element on the path being built passed its check below (a block outside the
        // list is refused before its inputs are read), so a loop found here runs through
        // supported elements only.
        if visiting.contains(&id) {
            return Err(wiring_error(
                &n.span,
                format!("the wiring of the condition loops back to {named}"),
            ));
        }
        if visiting.len() >= crate::cond::MAX_DEPTH {
            return Err(wiring_error(
                &n.span,
                format!(
                    "the wired condition is drawn through more than {} elements in a row (at {named})",
                    crate::cond::MAX_DEPTH,
                ),
            ));
        }
        self.built.set(self.built.get() + 1);
        if self.built.get() > crate::cond::MAX_TOKENS {
            return Err(wiring_error(
                &n.span,
                format!(
                    "the wired condition is drawn from more than {} elements (counting each as often as it is reached)",
                    crate::cond::MAX_TOKENS
                ),
            ));
        }
        visiting.push(id);
        let at = &n.span;
        let text = |what: &str| -> Result<Expr, Box<Diagnostic>> {
            let Some((t, map)) = &n.text else {
                return Err(wiring_error(
                    at,
                    format!("{} localId {id} has no {what}", n.tag),
                ));
            };
            let file_map = |o: usize| map_offset(map, o);
            crate::cond::parse_operand(t, &file_map).map_err(|e| {
                let s = map_offset(map, e.at.start);
                let end = map_offset(map, e.at.end.saturating_sub(1)) + 1;
                wiring_error(
                    &Span::new(self.file, s..end.max(s + 1)),
                    format!("{} localId {id}: `{}`: {}", n.tag, t.trim(), e.message),
                )
            })
        };
        let result = match n.tag.as_str() {
            "leftPowerRail" => Ok(Expr {
                kind: ExprKind::Bool(true),
                span: at.range.clone(),
            }),
            "inVariable" | "inOutVariable" => text("expression"),
            "contact" if n.edge.is_some() => Err(wiring_error(
                at,
                format!(
                    "contact localId {id} detects a {} edge: an edge is not a condition a robot program can wait for (compare the signal's level instead)",
                    n.edge.as_deref().unwrap_or_default()
                ),
            )),
            "contact" => {
                let var = text("variable")?;
                let var = if n.negated {
                    Expr {
                        kind: ExprKind::Not(Box::new(var)),
                        span: at.range.clone(),
                    }
                } else {
                    var
                };
                if n.inputs.is_empty() {
                    return Err(wiring_error(
                        at,
                        format!("the input of {named} is not connected"),
                    ));
                }
                let before = self.any_of(&n.inputs, at, visiting)?;
                // Contacts in series are an AND; after the power rail, the contact alone.
                Ok(if before.is_true() {
                    var
                } else {
                    Self::bin(BinOp::And, before, var, at)
                })
            }
            "block" => {
                let ty = n
                    .type_name
                    .as_deref()
                    .unwrap_or_default()
                    .trim()
                    .to_ascii_uppercase();
                // The block's type first: a block outside the list is the error, whatever its
                // inputs are (a TON's `PT`, an SR fed back from the TON's output).
                let Some(function) = crate::cond::Function::named(&ty) else {
                    return Err(wiring_error(
                        at,
                        format!("a wired condition uses {named}{}", refused_block(&ty)),
                    ));
                };
                let mut ins: Vec<(&str, Expr)> = Vec::new();
                for (formal, refs) in &n.formal {
                    // EN is the enable input, not an operand.
                    if formal.eq_ignore_ascii_case("EN") {
                        continue;
                    }
                    if refs.is_empty() {
                        return Err(wiring_error(
                            at,
                            format!("input {formal} of {named} is not connected"),
                        ));
                    }
                    ins.push((formal.as_str(), self.any_of(refs, at, visiting)?));
                }
                // The operands in the function's order: its formal parameters, or all inputs.
                let args: Vec<Expr> = match function.formals() {
                    None => ins.into_iter().map(|(_, e)| e).collect(),
                    Some(formals) => {
                        let mut args = Vec::with_capacity(formals.len());
                        for f in formals {
                            match ins.iter().position(|(n, _)| n.eq_ignore_ascii_case(f)) {
                                Some(k) => args.push(ins.remove(k).1),
                                None => {
                                    return Err(wiring_error(
                                        at,
                                        format!("{named} has no input {f}"),
                                    ));
                                }
                            }
                        }
                        args
                    }
                };
                if args.is_empty() {
                    return Err(wiring_error(at, format!("{named} has no inputs")));
                }
                Ok(function.apply(args, at.range.clone()))
            }
            other => Err(wiring_error(
                at,
                format!(
                    "a wired condition is drawn from {other} localId {id}, which gives no condition"
                ),
            )),
        };
        visiting.pop();
        result
    }
}

/// Whether the stack is inside the element's `condition/inline`.
fn in_inline(b: &Building, stack: &Open) -> bool {
    let rel = &stack.tags[b.depth.min(stack.len())..];
    rel.len() >= 2 && rel[0].0 == Tag::Condition && rel[1].0 == Tag::Inline
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let text = doc(
            "<inline><ST><xhtml:p xmlns:xhtml=\"x\">Part_OK AND NOT Stop</xhtml:p></ST></inline>",
        );
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
        let (sfc, d) = read(
            "<project><types><pous><pou name=\"P\"><body><SFC><step localId=\"1\" name=\"S\"/>",
        );
        assert!(sfc.is_none());
        assert_eq!(d.len(), 1);
        assert_eq!(d[0].code, Code::XmlSyntax);
        assert!(
            d[0].message.contains("ends inside `<SFC>`"),
            "{}",
            d[0].message
        );
    }
}
