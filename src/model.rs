//! The input model: what the readers extract from the blackboard, the SFC and the IRL files.
//!
//! Everything is owned (the XML trees are dropped after reading) and every item keeps the
//! [`Span`] it came from, so later stages can point at it.

use crate::diag::{FileId, Span};
use std::ops::Range;

/// A name as written, with its comparison key ([`crate::names::key`]) and its place.
#[derive(Debug, Clone)]
pub struct Name {
    pub text: String,
    pub key: String,
    pub span: Span,
}

impl Name {
    pub fn new(text: &str, span: Span) -> Self {
        Name {
            text: text.trim().to_owned(),
            key: crate::names::key(text),
            span,
        }
    }
}

/// The blackboard: resources with their skills and functions, and the two references.
#[derive(Debug)]
pub struct Blackboard {
    pub file: FileId,
    pub resources: Vec<Resource>,
    /// The SFC file's `refURI` value.
    pub sfc_ref: Option<RefValue>,
    /// Where the `.src` path is written back.
    pub write_back: Option<WriteBackTarget>,
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
}

#[derive(Debug)]
pub struct Resource {
    pub name: Name,
    /// The CAEX element, described for diagnostics (`InternalElement "KUKA KR15-2" {ID}`).
    pub element: String,
    pub id: Option<String>,
    pub skills: Vec<Skill>,
    pub functions: Vec<Function>,
    /// Keys of functions that are present but malformed (reported): not "unknown".
    pub broken_functions: Vec<String>,
}

impl Resource {
    pub fn skill(&self, key: &str) -> Option<usize> {
        self.skills.iter().position(|s| s.name.key == key)
    }
    pub fn function(&self, key: &str) -> Option<usize> {
        self.functions.iter().position(|f| f.name.key == key)
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
        self.params.iter().position(|p| p.path.key == key)
    }

    /// The SFC variables the skill needs (the top-level parameters' values), deduplicated by key.
    pub fn variables(&self) -> Vec<&str> {
        let mut seen: Vec<&str> = Vec::new();
        let mut out = Vec::new();
        for p in &self.params {
            if p.indices.is_empty()
                && let Some(v) = &p.variable
                && !seen.contains(&v.key.as_str())
            {
                seen.push(&v.key);
                out.push(v.text.as_str());
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
}

/// The value types of SPEC.md 2.1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueType {
    Double,
    Decimal,
    Integer,
    Boolean,
    String,
}

impl ValueType {
    pub fn parse(s: &str) -> Option<Self> {
        let t = s.trim();
        let local = t.rsplit(':').next().unwrap_or(t);
        match local.to_ascii_lowercase().as_str() {
            "double" | "float" => Some(ValueType::Double),
            "decimal" => Some(ValueType::Decimal),
            "integer" | "int" | "long" | "short" => Some(ValueType::Integer),
            "boolean" => Some(ValueType::Boolean),
            "string" | "anyuri" => Some(ValueType::String),
            _ => None,
        }
    }

    pub fn xs_name(self) -> &'static str {
        match self {
            ValueType::Double => "xs:double",
            ValueType::Decimal => "xs:decimal",
            ValueType::Integer => "xs:integer",
            ValueType::Boolean => "xs:boolean",
            ValueType::String => "xs:string",
        }
    }
}

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
    pub inputs: Vec<(u64, Range<usize>)>,
}

#[derive(Debug)]
pub enum ElementKind {
    Step(Box<Step>),
    Transition,
    SimultaneousDivergence,
    SimultaneousConvergence,
    SelectionDivergence,
    SelectionConvergence,
    JumpStep,
    MacroStep,
}

impl ElementKind {
    pub fn tag(&self) -> &'static str {
        match self {
            ElementKind::Step(_) => "step",
            ElementKind::Transition => "transition",
            ElementKind::SimultaneousDivergence => "simultaneousDivergence",
            ElementKind::SimultaneousConvergence => "simultaneousConvergence",
            ElementKind::SelectionDivergence => "selectionDivergence",
            ElementKind::SelectionConvergence => "selectionConvergence",
            ElementKind::JumpStep => "jumpStep",
            ElementKind::MacroStep => "macroStep",
        }
    }

    pub fn is_step(&self) -> bool {
        matches!(self, ElementKind::Step(_))
    }
}

#[derive(Debug)]
pub struct Step {
    /// The step's `name`: its step type (`P2P`), informative.
    pub name: String,
    pub initial: bool,
    pub resource: Option<Name>,
    pub skill: Option<Name>,
    /// `time@duration` in seconds.
    pub duration: Option<f64>,
    pub variables: Vec<Variable>,
    /// Keys of variables that are present but malformed (reported): not "missing".
    pub invalid_variables: Vec<String>,
}

#[derive(Debug)]
pub struct Variable {
    pub name: Name,
    pub value: Value,
    /// The `Value` attribute's value.
    pub value_span: Span,
}

/// An SFC variable's value: `(a, (b, c))` nests lists, anything else is one trimmed value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Scalar(String),
    List(Vec<Value>),
}

/// An IRL file.
#[derive(Debug)]
pub struct Irl {
    pub file: FileId,
    pub info: Option<String>,
    pub calls: Vec<IrlCall>,
    pub definitions: Vec<IrlDefinition>,
}

/// A `function-call` template.
#[derive(Debug)]
pub struct IrlCall {
    pub name: Name,
    /// The declared parameters (or those taken from the first bracket group).
    pub params: Vec<Name>,
    pub template: crate::template::Template,
    /// The element's start tag.
    pub span: Span,
}

/// A `def/definition`, emitted once after the program.
#[derive(Debug)]
pub struct IrlDefinition {
    pub name: Name,
    /// The text, common indentation removed, lines without their endings.
    pub lines: Vec<String>,
    pub span: Span,
}
