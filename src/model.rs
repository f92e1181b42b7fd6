//! The input model: what the readers extract from the blackboard, the SFC and the IRL files.
//!
//! Everything is owned (the XML trees are dropped after reading) and every item keeps the
//! [`Span`] it came from, so later stages can point at it.

use crate::diag::{FileId, Span};
use std::ops::Range;
use std::sync::Arc;

/// Branches, loops and macro steps nest at most this deep (docs/INPUTS.md): the SFC reader
/// refuses a macro step deeper than this when it reads its body (`E313`), before anything
/// grows with the depth; the planner refuses deeper branches and loops.
pub const MAX_NESTING: usize = 128;

/// A name as written, with its comparison key ([`crate::names::key`]) and its place. The strings
/// are shared (`Arc`), so a name repeated 100,000 times in an SFC is stored once.
#[derive(Debug, Clone)]
pub struct Name {
    pub text: Arc<str>,
    pub key: Arc<str>,
    pub span: Span,
}

impl Name {
    pub fn new(text: &str, span: Span) -> Self {
        Name {
            text: Arc::from(text.trim()),
            key: Arc::from(crate::names::key(text)),
            span,
        }
    }
}

/// Shares the strings of names read many times (step types, resources, skills, variables).
///
/// Each name is hashed once (SipHash with a random key, as `std`'s maps: a crafted file cannot
/// make names collide) and its hash kept, so growing the table does not hash every name again.
///
/// In front of the table, the names found in it last (`recent`: a slot chosen by the length and
/// the last byte holds the last two names found of its slot): a plan repeats a handful of names
/// (variables, resources, skills) in every step, and a hit costs a comparison or two instead of a
/// hash. Two per slot, as names of the same length and last letter come together (`R1`…`R4`,
/// `P2P`, `Frame` and `R2`). A name seen once (100,000 distinct variables) only costs those
/// comparisons.
#[derive(Debug, Default)]
pub struct Interner {
    table: hashbrown::HashTable<Interned>,
    hasher: std::hash::RandomState,
    /// Per slot the name found last, then the one before.
    recent: [[Option<Recent>; 2]; RECENT],
}

/// Slots of [`Interner::recent`].
const RECENT: usize = 16;

#[derive(Debug, Clone)]
struct Recent {
    raw: Arc<str>,
    text: Arc<str>,
    key: Arc<str>,
}

#[derive(Debug)]
struct Interned {
    hash: u64,
    /// The name as written (the trimmed text's string when it has no surrounding spaces).
    raw: Arc<str>,
    text: Arc<str>,
    key: Arc<str>,
}

impl Interner {
    /// A [`Name`] for `raw` (as written) at `span`, its strings shared with earlier ones.
    pub fn name(&mut self, raw: &str, span: Span) -> Name {
        let (text, key) = self.strings(raw);
        Name { text, key, span }
    }

    /// The shared trimmed text and key of `raw`.
    pub fn strings(&mut self, raw: &str) -> (Arc<str>, Arc<str>) {
        use std::hash::BuildHasher as _;
        let slot = (raw.len() ^ usize::from(raw.as_bytes().last().copied().unwrap_or(0))) % RECENT;
        let recent = &mut self.recent[slot];
        if let Some(r) = &recent[0]
            && *r.raw == *raw
        {
            return (r.text.clone(), r.key.clone());
        }
        if let Some(r) = &recent[1]
            && *r.raw == *raw
        {
            let found = (r.text.clone(), r.key.clone());
            recent.swap(0, 1);
            return found;
        }
        let hash = self.hasher.hash_one(raw);
        if let Some(e) = self.table.find(hash, |e| *e.raw == *raw) {
            recent[1] = recent[0].take();
            recent[0] = Some(Recent {
                raw: e.raw.clone(),
                text: e.text.clone(),
                key: e.key.clone(),
            });
            return (e.text.clone(), e.key.clone());
        }
        let trimmed = raw.trim();
        let text: Arc<str> = Arc::from(trimmed);
        // A name already in lower case is its own key: one allocation shared.
        let key = if trimmed.is_ascii() && !trimmed.bytes().any(|b| b.is_ascii_uppercase()) {
            text.clone()
        } else {
            let key = crate::names::key(raw);
            if *key == *text {
                text.clone()
            } else {
                Arc::from(key)
            }
        };
        let raw = if raw.len() == trimmed.len() {
            text.clone()
        } else {
            Arc::from(raw)
        };
        self.table.insert_unique(
            hash,
            Interned {
                hash,
                raw,
                text: text.clone(),
                key: key.clone(),
            },
            |e| e.hash,
        );
        (text, key)
    }
}

/// The blackboard: resources with their skills and functions, and the two references.
#[derive(Debug)]
pub struct Blackboard {
    pub file: FileId,
    pub resources: Vec<Resource>,
    /// Which resource's controller runs each resource (docs/CELLS.md), by resource index: its
    /// `Controller` attribute when that names a resource, else the nearest enclosing resource's
    /// controller, else itself. Empty for a blackboard built by hand (then each is its own).
    pub controllers: Vec<usize>,
    /// The wires between controllers, in document order.
    pub wires: Vec<Wire>,
    /// The SFC file's `refURI` value.
    pub sfc_ref: Option<RefValue>,
    /// Where the `.src` path is written back.
    pub write_back: Option<WriteBackTarget>,
    /// Every `ExternalInterface` of `Code` with a `refURI` value, by its `Name`: where the
    /// programs of a cell's other controllers are written back (docs/CELLS.md).
    pub code_targets: Vec<(String, WriteBackTarget)>,
}

/// A `refURI` attribute's value and where it stands.
#[derive(Debug, Clone)]
pub struct RefValue {
    pub value: String,
    /// The `Value` element (or the `Attribute`, when the value is empty).
    pub span: Span,
}

/// The write-back target: the `refURI` `Attribute` element (its whole byte range in the
/// BOM-stripped text) and its current value.
#[derive(Debug, Clone)]
pub struct WriteBackTarget {
    pub attribute: Span,
    pub current: Option<String>,
    /// Where the value goes: the byte range the splice replaces, found by the reader's parse
    /// (`write::SpliceSite::of`).
    pub site: SpliceSite,
}

#[derive(Debug)]
pub struct Resource {
    pub name: Name,
    /// The `Language` (`Sprache`) attribute: the language and the attribute's value span.
    pub language: Option<(crate::lang::Language, Span)>,
    /// The CAEX element, described for diagnostics (`InternalElement "KUKA KR15-2" {ID}`).
    pub element: String,
    pub id: Option<String>,
    pub skills: Vec<Skill>,
    pub functions: Vec<Function>,
    /// Keys of functions that are present but malformed (reported): not "unknown".
    pub broken_functions: Vec<Arc<str>>,
    /// The I/O signals transition conditions may name (docs/INPUTS.md), in document order.
    pub signals: Vec<Signal>,
    /// Keys of signals that are present but malformed (reported): not "unknown".
    pub broken_signals: Vec<Arc<str>>,
    /// Skills, functions and signals by key, built at the first lookup (after reading): a lookup
    /// per step must not cost the number of skills.
    pub index: std::sync::OnceLock<ResourceIndex>,
    /// The resource this one stands inside (a device mounted on it), by index.
    pub parent: Option<usize>,
    /// The `Controller` (`Steuerung`) attribute's value and the value's span.
    pub controller_attr: Option<(String, Span)>,
    /// The `Program` (`Programm`) attribute's value and span: a controller's program name in a
    /// cell of several controllers (docs/CELLS.md).
    pub program_attr: Option<(String, Span)>,
    /// The `Timers` attribute's value and span: the KRL timers (`$TIMER[n]`) the program may
    /// use for step times (docs/INPUTS.md), `A-B` or `N`.
    pub timers_attr: Option<(String, Span)>,
    /// The `HandshakeTimeout` attribute's value and span: after how many seconds a wait on
    /// another controller of the cell shows on the pendant (docs/CELLS.md).
    pub handshake_timeout_attr: Option<(String, Span)>,
    /// The `Points` attribute's value and span: how the program writes motions to literal
    /// positions (`named`, the default: teachable points; `inline`: as the IRL code wrote them).
    pub points_attr: Option<(String, Span)>,
    /// Its tool, base and load from the blackboard (docs/INPUTS.md, "Tool, base and load").
    pub tooling: Tooling,
    /// Child InternalElements named near a group skillpost reads but not as it (`Skils` for
    /// `Skills`): their name, place and the group's name. Not read; an error about what the
    /// group would hold names them.
    pub misnamed: Vec<(String, Span, &'static str)>,
}

/// A resource's tool, base and load as its attributes give them (docs/INPUTS.md, "Tool, base
/// and load"), each with the span of its attribute; read by `read::tooling`.
#[derive(Debug, Clone, Default)]
pub struct Tooling {
    /// `Tool` (`TCP`): the tool centre point relative to the flange.
    pub tool: Option<(Frame, Span)>,
    /// `ToolNumber`: one of the controller's own tools (KRL's `TOOL_DATA[n]`), 1 to 16.
    pub tool_number: Option<(u8, Span)>,
    /// `Base`: the base (work object) relative to the robot's world.
    pub base: Option<(Frame, Span)>,
    /// `BaseNumber`: one of the controller's own bases (KRL's `BASE_DATA[n]`), 1 to 32.
    pub base_number: Option<(u8, Span)>,
    /// `Load`: what the resource's tool weighs on the flange, in kg (a robot's `Payload` is its
    /// rated payload, not read).
    pub load: Option<(f64, Span)>,
    /// `Mass`: what the resource weighs, in kg; a device's is its load when it has no `Load`
    /// (a robot's is its own weight, not a load).
    pub mass: Option<(f64, Span)>,
    /// `CenterOfMass`: where the load's centre of mass is relative to the flange, in mm.
    pub center: Option<([f64; 3], Span)>,
}

impl Tooling {
    /// Whether it gives anything at all.
    pub fn is_empty(&self) -> bool {
        self.tool.is_none()
            && self.tool_number.is_none()
            && self.base.is_none()
            && self.base_number.is_none()
            && self.load.is_none()
            && self.mass.is_none()
            && self.center.is_none()
    }
}

/// A frame in the plan's terms: `x, y, z` in mm, `a, b, c` in degrees (KUKA's A about Z, then B
/// about the new Y, then C about the new X).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    pub xyz: [f64; 3],
    pub abc: [f64; 3],
}

/// A load: its mass in kg and its centre of mass relative to the flange in mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Load {
    pub mass: f64,
    pub center: [f64; 3],
}

/// Key → index of the first skill, function and signal of that key.
#[derive(Debug, Default)]
pub struct ResourceIndex {
    skills: std::collections::HashMap<Arc<str>, usize>,
    functions: std::collections::HashMap<Arc<str>, usize>,
    signals: std::collections::HashMap<Arc<str>, usize>,
}

impl Blackboard {
    /// The resource whose controller runs resource `r` (itself when none is recorded).
    pub fn controller_of(&self, r: usize) -> usize {
        self.controllers.get(r).copied().unwrap_or(r)
    }
}

impl Resource {
    /// Up to this many entries a scan is cheaper than building the index.
    const SCAN: usize = 8;

    fn index(&self) -> &ResourceIndex {
        self.index.get_or_init(|| {
            fn by_key<'a>(
                keys: impl Iterator<Item = &'a Arc<str>>,
            ) -> std::collections::HashMap<Arc<str>, usize> {
                let mut m = std::collections::HashMap::new();
                for (i, k) in keys.enumerate() {
                    m.entry(k.clone()).or_insert(i);
                }
                m
            }
            ResourceIndex {
                skills: by_key(self.skills.iter().map(|s| &s.name.key)),
                functions: by_key(self.functions.iter().map(|f| &f.name.key)),
                signals: by_key(self.signals.iter().map(|s| &s.name.key)),
            }
        })
    }

    pub fn skill(&self, key: &str) -> Option<usize> {
        if self.skills.len() <= Self::SCAN {
            return self.skills.iter().position(|s| &*s.name.key == key);
        }
        self.index().skills.get(key).copied()
    }
    pub fn function(&self, key: &str) -> Option<usize> {
        if self.functions.len() <= Self::SCAN {
            return self.functions.iter().position(|f| &*f.name.key == key);
        }
        self.index().functions.get(key).copied()
    }
    pub fn signal(&self, key: &str) -> Option<usize> {
        if self.signals.len() <= Self::SCAN {
            return self.signals.iter().position(|s| &*s.name.key == key);
        }
        self.index().signals.get(key).copied()
    }
}

/// An I/O signal of a resource: an `ExternalInterface` whose `RefBaseClassPath` ends in
/// `SignalInterface` or `Channel` (docs/INPUTS.md).
#[derive(Debug, Clone)]
pub struct Signal {
    pub name: Name,
    /// The CAEX element, described for diagnostics.
    pub element: String,
    /// `IoType` `Output` (else an input).
    pub output: bool,
    pub kind: SignalKind,
    /// The `ID` of the element the interface stands in (the resource, or its `Signals`
    /// element): with the name, what an `InternalLink` partner names (`<ID>:<name>`).
    pub holder: Option<String>,
}

/// A wire between two controllers (docs/CELLS.md): an `InternalLink` from an `Output` signal of one
/// controller's resources to an `Input` signal of another's.
#[derive(Debug, Clone)]
pub struct Wire {
    /// `(resource, signal)` of the output that drives it.
    pub from: (usize, usize),
    /// `(resource, signal)` of the input it drives.
    pub to: (usize, usize),
    /// The link's `Name`.
    pub name: String,
    /// The `InternalLink` element.
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SignalKind {
    /// One bit: the I/O index `Number` (1-based, as KRL counts).
    Bit(u32),
    /// An integer of `length` bits from index `number` on, least significant first.
    Group { number: u32, length: u32 },
    /// A robot-language expression used as it stands (one safe token); `integer` per `Type`.
    Address { text: String, integer: bool },
}

impl Signal {
    /// Whether conditions see an integer (else a boolean).
    pub fn is_integer(&self) -> bool {
        matches!(
            self.kind,
            SignalKind::Group { .. } | SignalKind::Address { integer: true, .. }
        )
    }
}

#[derive(Debug)]
pub struct Skill {
    pub name: Name,
    /// The CAEX element, described for diagnostics.
    pub element: String,
    pub id: Option<String>,
    /// Every parameter, nested ones included, in document order.
    pub params: Vec<Param>,
    /// Function mappings, sorted by order (stable: equal orders keep document order).
    pub mappings: Vec<FunctionMapping>,
    /// Problems that make the skill unusable; reported (once) when a step uses it.
    pub defects: Vec<crate::diag::Diagnostic>,
}

impl Skill {
    pub fn param(&self, key: &str) -> Option<usize> {
        self.params.iter().position(|p| &*p.path.key == key)
    }

    /// The SFC variables the skill needs (the top-level parameters' values), deduplicated by key.
    pub fn variables(&self) -> Vec<&str> {
        let mut seen: Vec<&str> = Vec::new();
        let mut out = Vec::new();
        for p in &self.params {
            if p.indices.is_empty()
                && let Some(v) = &p.variable
                && !seen.contains(&&*v.key)
            {
                seen.push(&v.key);
                out.push(&*v.text);
            }
        }
        out
    }
}

/// A skill parameter: `End Position.x` reads SFC variable `Frame` at index `[0]`.
#[derive(Debug, Clone)]
pub struct Param {
    /// The joined path (`End Position.x`); its span is the `Attribute` element's name.
    pub path: Name,
    /// The SFC variable (the top-level attribute's `Value`); `None` when that is unusable.
    pub variable: Option<Name>,
    /// Indexes into the variable's list, one per nesting level below the top.
    pub indices: Vec<usize>,
    /// The checked type of a leaf parameter.
    pub ty: Option<ValueType>,
    /// Whether the attribute has no nested attributes.
    pub leaf: bool,
    /// What the blackboard allows its values to be (CAEX `Constraint`s of a leaf parameter).
    pub constraints: Vec<Constraint>,
}

/// A CAEX `Constraint` on a skill parameter: `OrdinalScaledType` bounds
/// (`RequiredMinValue`/`RequiredMaxValue`, numbers, inclusive) and required values
/// (`RequiredValue`, of `OrdinalScaledType` or, several, of `NominalScaledType`: the value must be
/// one of them).
#[derive(Debug, Clone)]
pub struct Constraint {
    /// Its `Name`.
    pub name: String,
    /// The `Constraint` element's start tag.
    pub span: Span,
    /// The least value allowed, and as written.
    pub min: Option<(f64, String)>,
    pub max: Option<(f64, String)>,
    /// The values allowed (empty: any).
    pub one_of: Vec<String>,
}

pub use crate::value::{Value, ValueType};

/// One mapped function call of a skill.
#[derive(Debug, Clone)]
pub struct FunctionMapping {
    /// The function's name (`Attribute Name` → `Value`).
    pub function: Name,
    /// The CAEX `ExternalInterface`, described for diagnostics.
    pub element: String,
    pub order: i64,
    /// Skill parameter (joined path) → function parameter.
    pub args: Vec<MappedArg>,
    /// The `ExternalInterface` element.
    pub span: Span,
}

#[derive(Debug, Clone)]
pub struct MappedArg {
    /// The skill parameter's joined path, as written in the mapping.
    pub skill_param: Name,
    /// The function (IRL template) parameter it fills.
    pub function_param: Name,
}

#[derive(Debug, Clone)]
pub struct Function {
    pub name: Name,
    /// The CAEX element, described for diagnostics.
    pub element: String,
    pub id: Option<String>,
    /// The command's name in the IRL file (`Attribute Name` of the data interface).
    pub command: Name,
    /// The IRL file.
    pub irl: RefValue,
}

/// The SFC: the program's elements in document order, and the file header.
#[derive(Debug, Default)]
pub struct Sfc {
    pub file: FileId,
    pub header: FileHeader,
    pub pou_name: Option<String>,
    pub elements: Vec<Element>,
    /// The `SFC` element.
    pub span: Option<Span>,
    /// Every step's variables one after another, and their values' texts: two allocations
    /// for all steps (not two per step), so freeing them ([`Sfc::take_variables`]) gives the
    /// memory back rather than leaving holes between the steps.
    pub variables: Vec<Variable>,
    pub values: String,
    /// Connections back to an earlier step, made loops (`plan::close_circles`): each became a
    /// jumpStep element appended to `elements`.
    pub closed: Vec<Closed>,
    /// The macro steps with a body (docs/INPUTS.md): the body's elements follow the macroStep in
    /// `elements`, ascending.
    pub macros: Vec<MacroBody>,
}

/// A macroStep and its body's chart: the elements `body` (which run in the macro step's place).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MacroBody {
    pub step: usize,
    pub body: std::ops::Range<usize>,
}

/// A connection back to an earlier step (a chart drawn as a closed circle), made a jump.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Closed {
    /// The jumpStep element added for it.
    pub jump: usize,
    /// The step it leads back to.
    pub target: usize,
    /// The element the connection comes from.
    pub from: usize,
}

impl Sfc {
    /// How a jump is named in listings and comments: `jump localId 57`, or for a connection
    /// back to an earlier step, `connection back from localId 12`.
    pub fn jump_label(&self, jump: usize) -> String {
        match self.closed.iter().find(|c| c.jump == jump) {
            Some(c) => format!(
                "connection back from localId {}",
                self.elements[c.from].local_id
            ),
            None => format!("jump localId {}", self.elements[jump].local_id),
        }
    }

    /// A step's variables (none once [`Sfc::take_variables`] ran).
    pub fn variables_of(&self, step: &Step) -> &[Variable] {
        self.variables.get(step.variables.clone()).unwrap_or(&[])
    }

    /// A variable's value as written, trimmed.
    pub fn raw(&self, v: &Variable) -> &str {
        self.values.get(v.raw.clone()).unwrap_or("")
    }

    /// A variable's value as a tree (for listings).
    pub fn value_of(&self, v: &Variable) -> Value {
        let raw = self.raw(v);
        crate::value::parse_value(raw).unwrap_or_else(|_| Value::Scalar(raw.to_owned()))
    }

    /// Takes out what only the binder reads, the steps' variables, once it is done, for the
    /// caller to free (a large model's on another thread): the writers need the rest (names,
    /// ids, conditions). With 100,000 steps the variables are a third of the model, and the
    /// steps block the writer makes comes after them.
    pub fn take_variables(&mut self) -> (Vec<Variable>, String) {
        (
            std::mem::take(&mut self.variables),
            std::mem::take(&mut self.values),
        )
    }
}

#[derive(Debug, Default, Clone)]
pub struct FileHeader {
    pub company_name: Option<String>,
    pub product_name: Option<String>,
    pub product_version: Option<String>,
    pub creation_date_time: Option<String>,
}

/// One element of the SFC body.
#[derive(Debug)]
pub struct Element {
    pub local_id: u64,
    pub kind: ElementKind,
    /// The element's start tag.
    pub span: Span,
    /// `position@x`, 0 when absent.
    pub x: f64,
    /// `connectionPointIn/connection@refLocalId`, in document order, with their places.
    pub inputs: Inputs,
}

/// An element's inputs: `(refLocalId, its place)`, read as a slice. Nearly every element has
/// exactly one, kept in place: 100,000 elements made 100,000 small allocations, each freshly
/// touched memory while the reader (the pace-setter of the reading) built the model.
#[derive(Clone, Default, PartialEq)]
pub enum Inputs {
    #[default]
    None,
    One((u64, Range<usize>)),
    Many(Vec<(u64, Range<usize>)>),
}

impl From<&[(u64, Range<usize>)]> for Inputs {
    fn from(inputs: &[(u64, Range<usize>)]) -> Self {
        match inputs {
            [] => Inputs::None,
            [one] => Inputs::One(one.clone()),
            _ => Inputs::Many(inputs.to_vec()),
        }
    }
}

impl std::ops::Deref for Inputs {
    type Target = [(u64, Range<usize>)];

    fn deref(&self) -> &Self::Target {
        match self {
            Inputs::None => &[],
            Inputs::One(one) => std::slice::from_ref(one),
            Inputs::Many(many) => many,
        }
    }
}

impl<'a> IntoIterator for &'a Inputs {
    type Item = &'a (u64, Range<usize>);
    type IntoIter = std::slice::Iter<'a, (u64, Range<usize>)>;

    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

/// As the list it stands for (as a `Vec` printed before).
impl std::fmt::Debug for Inputs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

#[derive(Debug)]
pub enum ElementKind {
    Step(Box<Step>),
    /// A transition and its condition; `None` when it always fires (absent or `TRUE`).
    Transition(Option<Box<Condition>>),
    SimultaneousDivergence,
    SimultaneousConvergence,
    SelectionDivergence,
    SelectionConvergence,
    /// A jump to the step named `targetName` (`None` when the attribute is missing or empty).
    JumpStep(Option<Box<Name>>),
    MacroStep,
}

impl ElementKind {
    pub fn tag(&self) -> &'static str {
        match self {
            ElementKind::Step(_) => "step",
            ElementKind::Transition(_) => "transition",
            ElementKind::SimultaneousDivergence => "simultaneousDivergence",
            ElementKind::SimultaneousConvergence => "simultaneousConvergence",
            ElementKind::SelectionDivergence => "selectionDivergence",
            ElementKind::SelectionConvergence => "selectionConvergence",
            ElementKind::JumpStep(_) => "jumpStep",
            ElementKind::MacroStep => "macroStep",
        }
    }

    pub fn is_step(&self) -> bool {
        matches!(self, ElementKind::Step(_))
    }
}

/// A transition's condition (docs/INPUTS.md), parsed.
#[derive(Debug)]
pub struct Condition {
    /// The inline ST text as written (trimmed), or the reference's name.
    pub text: String,
    pub expr: crate::cond::Expr,
    /// The `condition` element's start tag.
    pub span: Span,
    /// Whether it was `condition/reference@name`.
    pub reference: bool,
}

#[derive(Debug)]
pub struct Step {
    /// The step's `name`: its step type (`P2P`), informative.
    pub name: Arc<str>,
    pub initial: bool,
    pub resource: Option<Name>,
    pub skill: Option<Name>,
    /// `time@duration` in seconds.
    pub duration: Option<f64>,
    /// This step's variables: a range of [`Sfc::variables`] (see [`Sfc::variables_of`]).
    pub variables: Range<usize>,
    /// Keys of variables that are present but malformed (reported): not "missing".
    pub invalid_variables: Vec<Arc<str>>,
}

#[derive(Debug)]
pub struct Variable {
    pub name: Name,
    /// The value as written, trimmed: a range of [`Sfc::values`] (see [`Sfc::raw`]); its
    /// syntax was checked by the reader. Items are looked up without building a tree
    /// ([`crate::value::lookup`]); [`Sfc::value_of`] builds one.
    pub raw: Range<usize>,
    /// The `Value` attribute's value, in the file of the name (the SFC).
    pub value_range: Range<usize>,
}

impl Variable {
    /// The `Value` attribute's value.
    pub fn value_span(&self) -> Span {
        Span::new(self.name.span.file, self.value_range.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An element's inputs read back as the list they were made from, none, one or several, and
    /// print as that list did when it was a `Vec` (the pipeline tests compare printed models).
    #[test]
    fn inputs_are_the_list_they_were_made_from() {
        let list = [(3, 10..12), (7, 20..21), (9, 30..35)];
        for n in 0..=list.len() {
            let inputs = Inputs::from(&list[..n]);
            assert_eq!(&*inputs, &list[..n]);
            assert_eq!(inputs.len(), n);
            assert_eq!((&inputs).into_iter().count(), n);
            assert_eq!(format!("{inputs:?}"), format!("{:?}", list[..n].to_vec()));
            assert_eq!(format!("{inputs:#?}"), format!("{:#?}", list[..n].to_vec()));
        }
        assert!(matches!(Inputs::from(&list[..1]), Inputs::One(_)));
    }

    /// Names sharing a slot of the recent cache (same length, same last byte) keep their own
    /// strings; a name met again shares the strings of its first reading, cache hit or not.
    #[test]
    fn interner_recent_slots_do_not_mix_names() {
        let mut names = Interner::default();
        let words = [
            "Frame", "Grame", " Frame", "frame", "FRAME", "Frame", "Grame",
        ];
        let mut first: Vec<(&str, Arc<str>, Arc<str>)> = Vec::new();
        for _ in 0..3 {
            for w in words {
                let (text, key) = names.strings(w);
                assert_eq!(&*text, w.trim(), "{w:?}");
                assert_eq!(&*key, w.trim().to_ascii_lowercase(), "{w:?}");
                match first.iter().find(|(r, ..)| *r == w) {
                    Some((_, t, k)) => {
                        assert!(Arc::ptr_eq(t, &text) && Arc::ptr_eq(k, &key), "{w:?}");
                    }
                    None => first.push((w, text, key)),
                }
            }
        }
        // "Frame" and "frame" are different names as written, with the same key.
        assert_eq!(first.len(), 5);
    }
}

/// Where a value goes into a blackboard's text (without its BOM), found by `SpliceSite::of` (`read::site`).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SpliceSite {
    /// The bytes replaced by `head` + the escaped value + `tail`.
    pub replace: Range<usize>,
    /// Markup before the value (`<Value>` for a missing `Value`, `>` for a self-closing one).
    pub head: String,
    /// Markup after the value (`</Value>`, `</Value></Attribute>`, …).
    pub tail: String,
    /// The value as the reader reads it (`read::xml::caex_value`): the `Value`'s direct text,
    /// trimmed; empty for a missing, empty or self-closing `Value`.
    pub current: String,
}
