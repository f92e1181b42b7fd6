//! Diagnostics: what went wrong (or looks suspicious), where, and how to show it.
//!
//! A [`Diagnostic`] carries a [`FileId`] and a byte range into that file's text; line and column
//! are computed only when a diagnostic is rendered (see [`Sources::line_col`]). The readers never
//! stop at the first problem: they push into a [`Diagnostics`] sink and go on.
//!
//! Layout: this file holds [`Diagnostic`], the [`Diagnostics`] sink and the [`Code`] list;
//! `sources` the texts diagnostics point into ([`Sources`]: files, line and column, the lines
//! kept of a file read as a stream); `render` how they are shown (human, short,
//! JSON; [`Located`]).

use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Serialize;

mod render;
mod sources;

pub use render::{Format, Located, render};
pub use sources::{SourceFile, Sources};

/// Index of a file in [`Sources`].
pub type FileId = usize;

/// How bad a diagnostic is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    /// The inputs cannot be compiled.
    Error,
    /// Compiled, but something is suspicious (shown with `--warn`).
    Warning,
}

/// A place in a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Span {
    pub file: FileId,
    pub range: Range<usize>,
}

impl Span {
    pub fn new(file: FileId, range: Range<usize>) -> Self {
        Span { file, range }
    }
}

/// One problem found in the inputs.
#[derive(Debug, Clone)]
pub struct Diagnostic {
    pub severity: Severity,
    pub code: Code,
    pub message: String,
    /// Where it is; `None` only for problems that have no place (a file that cannot be read).
    pub span: Option<Span>,
    /// The element concerned: an SFC `localId`, or a CAEX element's name and ID.
    pub element: Option<String>,
    /// Further places (e.g. the IRL line when the blackboard mapping is at fault).
    pub related: Vec<(Span, String)>,
    /// Free-form notes.
    pub notes: Vec<String>,
    /// A path for diagnostics without a span (the file that could not be read).
    pub path: Option<PathBuf>,
}

impl Diagnostic {
    pub fn error(code: Code, message: impl Into<String>) -> Self {
        Diagnostic {
            severity: Severity::Error,
            code,
            message: message.into(),
            span: None,
            element: None,
            related: Vec::new(),
            notes: Vec::new(),
            path: None,
        }
    }

    pub fn warning(code: Code, message: impl Into<String>) -> Self {
        Diagnostic {
            severity: Severity::Warning,
            ..Diagnostic::error(code, message)
        }
    }

    pub fn at(mut self, span: Span) -> Self {
        self.span = Some(span);
        self
    }

    pub fn at_opt(mut self, span: Option<Span>) -> Self {
        self.span = span;
        self
    }

    pub fn element(mut self, element: impl Into<String>) -> Self {
        self.element = Some(element.into());
        self
    }

    pub fn related(mut self, span: Span, message: impl Into<String>) -> Self {
        self.related.push((span, message.into()));
        self
    }

    pub fn note(mut self, note: impl Into<String>) -> Self {
        self.notes.push(note.into());
        self
    }

    pub fn path(mut self, path: impl Into<PathBuf>) -> Self {
        self.path = Some(path.into());
        self
    }
}

/// The diagnostics of one run, in the order they were found.
#[derive(Debug, Default)]
pub struct Diagnostics {
    list: Vec<Diagnostic>,
    /// Warnings are not kept ([`Diagnostics::drop_warnings`]).
    no_warnings: bool,
    /// Warnings not kept, counted (the run says how many it does not show).
    dropped: usize,
}

impl Diagnostics {
    /// Keeps no warnings from now on (and drops those kept): for a run that will not show them,
    /// so no stage spends time building or locating them.
    pub fn drop_warnings(&mut self) {
        self.no_warnings = true;
        let before = self.list.len();
        self.list.retain(|d| d.severity != Severity::Warning);
        self.dropped += before - self.list.len();
    }

    /// Counts `n` warnings not built: a stage that skips building warnings that would not be
    /// kept ([`Diagnostics::keeps_warnings`]) says how many it would have pushed.
    pub fn count_dropped(&mut self, n: usize) {
        self.dropped += n;
    }

    /// How many warnings were not kept.
    pub fn dropped_warnings(&self) -> usize {
        self.dropped
    }

    /// Moves `other`'s diagnostics (work done aside, [`Diagnostics::empty_like`]) after these,
    /// its count of dropped warnings with them.
    pub fn append(&mut self, other: Diagnostics) {
        self.dropped += other.dropped;
        for d in other.list {
            self.push(d);
        }
    }

    /// An empty list that keeps what this one keeps (for work done aside, appended later).
    pub fn empty_like(&self) -> Diagnostics {
        Diagnostics {
            list: Vec::new(),
            no_warnings: self.no_warnings,
            dropped: 0,
        }
    }

    /// Whether a warning pushed now is kept: a stage may skip building one that is not.
    pub fn keeps_warnings(&self) -> bool {
        !self.no_warnings
    }

    /// Takes `file` out of every diagnostic's places (its text is gone: it changed while the
    /// compile ran), saying so in a note. A diagnostic that was in `file` still names it (`path`):
    /// the user learns which file to look at, and the daemon which file is still being written.
    pub fn forget_file(&mut self, file: FileId, path: &Path, display: &str) {
        for d in self.list.iter_mut() {
            let mut lost = false;
            if d.span.as_ref().is_some_and(|s| s.file == file) {
                d.span = None;
                d.path.get_or_insert_with(|| path.to_owned());
                lost = true;
            }
            let before = d.related.len();
            d.related.retain(|(s, _)| s.file != file);
            lost |= d.related.len() != before;
            if lost {
                d.notes.push(format!(
                    "`{display}` changed while it was being compiled: run again for the line and column"
                ));
            }
        }
    }

    /// Puts every span on its file's character boundaries and inside the file. A streamed
    /// reader places diagnostics by byte positions without the text (a syntax error may fall
    /// inside a multi-byte character, or at the end of the file); this runs once the texts are
    /// back, before anything renders them.
    pub fn snap(&mut self, sources: &Sources) {
        self.explain_xml_errors(sources);
        let snap = |s: &mut Span| {
            let f = &sources.files[s.file];
            // The text the span must lie in, and its file offset.
            let (text, base) = match (&f.excerpts, f.dropped) {
                (Some(x), _) => match x.find(s.range.start) {
                    Some(e) => (e.text.as_str(), e.start),
                    None => return,
                },
                (None, Some(_)) => return,
                (None, None) => (f.text.as_str(), 0),
            };
            // Within the piece kept: a span that goes on to other lines is cut at the end of
            // its first (the renderer would need every line between).
            let mut start = s.range.start.saturating_sub(base).min(text.len());
            while !text.is_char_boundary(start) {
                start -= 1;
            }
            let mut end = s.range.end.saturating_sub(base).clamp(start, text.len());
            while !text.is_char_boundary(end) {
                end += 1;
            }
            s.range = base + start..base + end;
        };
        for d in self.list.iter_mut() {
            if let Some(s) = &mut d.span {
                snap(s);
            }
            for (s, _) in d.related.iter_mut() {
                snap(s);
            }
        }
    }

    /// Says more about an XML syntax error (`E102`) than the parser does, once the texts are
    /// back: an empty file (or one of white space only) says it is empty, and an end tag that
    /// does not match gets a label at the start tag it should have closed (the parser names
    /// only the end tag, often far below the misspelled start tag).
    fn explain_xml_errors(&mut self, sources: &Sources) {
        for d in self.list.iter_mut() {
            if d.code != Code::XmlSyntax {
                continue;
            }
            let Some(s) = &d.span else { continue };
            let f = &sources.files[s.file];
            let text = match f.dropped {
                None => f.text.as_str(),
                // A streamed file (the SFC) of no bytes keeps no text to put back.
                Some((0, _)) => "",
                Some(_) => continue,
            };
            if text.trim().is_empty() {
                d.message = if text.is_empty() {
                    format!("`{}` is empty: it holds no XML document", f.display)
                } else {
                    format!(
                        "`{}` is empty (white space only): it holds no XML document",
                        f.display
                    )
                };
                d.notes.push(
                    "was it saved completely? (a save may have failed, or is still going on)"
                        .to_owned(),
                );
                continue;
            }
            let at = s.range.start;
            let Some(close) = text.get(at..).and_then(|t| t.strip_prefix("</")) else {
                continue;
            };
            let close = &close[..close
                .find(|c: char| c.is_whitespace() || c == '>')
                .unwrap_or(close.len())];
            if let Some(open) = unclosed_start_tag(text, at)
                && &text[open.start + 1..open.end] != close
            {
                let (line, _) = sources.line_col(s.file, open.start);
                let name = &text[open.start + 1..open.end];
                d.related.push((
                    Span::new(s.file, open.clone()),
                    format!("the start tag `<{name}>` on line {line} does not match `</{close}>`"),
                ));
            }
        }
    }

    pub fn push(&mut self, d: Diagnostic) {
        if self.no_warnings && d.severity == Severity::Warning {
            self.dropped += 1;
            return;
        }
        self.list.push(d);
    }

    pub fn has_errors(&self) -> bool {
        self.list.iter().any(|d| d.severity == Severity::Error)
    }

    pub fn error_count(&self) -> usize {
        self.list
            .iter()
            .filter(|d| d.severity == Severity::Error)
            .count()
    }

    pub fn warning_count(&self) -> usize {
        self.list
            .iter()
            .filter(|d| d.severity == Severity::Warning)
            .count()
    }

    pub fn iter(&self) -> impl Iterator<Item = &Diagnostic> {
        self.list.iter()
    }

    pub fn into_vec(self) -> Vec<Diagnostic> {
        self.list
    }

    /// Sorts by file, then position, keeping the order of equal places; errors without a place
    /// come first.
    pub fn sort(&mut self) {
        self.list.sort_by_key(|d| {
            d.span
                .as_ref()
                .map(|s| (1, s.file, s.range.start))
                .unwrap_or((0, 0, 0))
        });
    }
}

macro_rules! codes {
    ($( $(#[$doc:meta])* $name:ident = $code:literal, )*) => {
        /// Stable diagnostic codes. `E…` are errors, `W…` warnings; the number's first digit
        /// names the stage: 1 files and XML, 2 blackboard, 3 SFC, 4 IRL, 5 values and mappings,
        /// 6 output. `docs/DIAGNOSTICS.md` lists them all.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum Code { $( $(#[$doc])* $name, )* }

        impl Code {
            /// The code as printed, e.g. `E301`.
            pub fn as_str(self) -> &'static str {
                match self { $( Code::$name => $code, )* }
            }

            /// Every code, for the documentation test.
            pub const ALL: &'static [Code] = &[ $( Code::$name, )* ];
        }
    };
}

codes! {
    /// A file named by the inputs cannot be read (missing, a directory, not UTF-8, too large).
    FileUnreadable = "E101",
    /// A file is not well-formed XML.
    XmlSyntax = "E102",
    /// A file is well-formed XML but not of the expected kind (wrong root element).
    XmlWrongRoot = "E103",
    /// A `refURI` value cannot be turned into a path.
    BadRefUri = "E104",

    /// No blackboard `InstanceHierarchy`.
    NoHierarchy = "E201",
    /// No `Ressourcen`/`Resources` element in the hierarchy.
    NoResources = "E202",
    /// No SFC reference (`Process Sequence` → interface → `refURI` → `Value`).
    NoSfcReference = "E203",
    /// An attribute name contains a `.`.
    DotInAttributeName = "E204",
    /// A skill parameter without a usable `Value`.
    ParameterWithoutValue = "E205",
    /// A function without exactly one `FunctionDataInterface`, or without `Name`/`refURI`.
    BadFunction = "E206",
    /// A function mapping without a usable `Name`, a bad `Order`, or a mapping path that is not a
    /// skill parameter.
    BadFunctionMapping = "E207",
    /// Two resources, skills, functions or signals with the same name.
    DuplicateName = "E208",
    /// A signal whose `IoType`, `Type`, `Number`, `Length` or `Address` cannot be used.
    BadSignal = "E209",
    /// A resource's `Language` or an IRL file's `info@language` names no language skillpost
    /// writes (KRL, RAPID, URScript).
    BadLanguage = "E210",
    /// A chain of `Controller` attributes that comes back to where it started (docs/CELLS.md).
    ControllerLoop = "E211",
    /// A cell's plan needs more wires between two controllers than the blackboard declares
    /// (docs/CELLS.md): how many are missing, from which controller to which.
    TooFewWires = "E212",
    /// A resource's `Timers` attribute that names no KRL timers, or fewer than the step times
    /// the conditions read (docs/INPUTS.md).
    BadTimers = "E214",
    /// A controller's `HandshakeTimeout` attribute that is not a number of seconds from 0 to a
    /// day (docs/CELLS.md).
    BadHandshakeTimeout = "E215",
    /// A controller's `Points` attribute that is neither `named` nor `inline`
    /// (docs/LANGUAGES.md, "Points").
    BadPoints = "E216",
    /// A resource's tool, base or load attribute (`Tool`, `Base`, `ToolNumber`, `BaseNumber`,
    /// `Load`, `Mass`, `CenterOfMass`) that cannot be used, or one its program's language has
    /// no form for (docs/INPUTS.md, "Tool, base and load").
    BadToolData = "E217",

    /// No `pou` with an `SFC` body (or none of the name asked for).
    NoSfcBody = "E301",
    /// A `localId` is used twice or is not a number.
    BadLocalId = "E302",
    /// A `refLocalId` names no element.
    DanglingReference = "E303",
    /// A step with more than one predecessor or successor.
    StepFanInOut = "E304",
    /// Two steps connected without a transition.
    StepToStep = "E305",
    /// A transition-like element with several inputs and several outputs.
    NToM = "E306",
    /// No start step, or several.
    StartStep = "E307",
    /// No end step, or several.
    EndStep = "E308",
    /// The flow has a cycle.
    Cycle = "E309",
    /// A simultaneous divergence without its convergence, or vice versa.
    UnbalancedBranch = "E310",
    /// A step names a resource the blackboard does not have (or none, ambiguously).
    UnknownResource = "E311",
    /// A step names a skill its resource does not offer (or none).
    UnknownSkill = "E312",
    /// A construct that is not supported yet (macro steps, wired conditions, nesting deeper
    /// than the limit).
    Unsupported = "E313",
    /// A step lacks a variable its skill needs.
    MissingVariable = "E314",
    /// A variable's value is not a well-formed value or list.
    BadVariableSyntax = "E315",
    /// A transition condition is not in the condition language (docs/INPUTS.md), or names a
    /// signal of the wrong type.
    BadCondition = "E316",
    /// A jump without a usable target, or one that cannot be structured (not back to a step on
    /// every path to it, not from the selection that decides the loop).
    BadJump = "E317",
    /// A condition names a signal the program's resource does not declare.
    UnknownSignal = "E318",
    /// A program whose steps would need two robot languages (resources or IRL files of
    /// different languages).
    TwoLanguages = "E319",

    /// An IRL file without `<src>`, or not an `<irl>` document.
    BadIrl = "E401",
    /// A function's command is not in its IRL file.
    UnknownCommand = "E402",
    /// Template parameters and mapped function parameters do not fit.
    ParameterMismatch = "E403",
    /// A conversion in an IRL template (`m`, `mm`, `rad`, `deg`, `quat`, `rotvec`) with
    /// arguments that are not parameters or numbers, or the wrong number of them.
    BadConversionCall = "E404",
    /// An IRL snippet (a definition or a function call's code) whose blocks do not close within
    /// it (an `IF` without `ENDIF`, an `ENDLOOP` without `LOOP`): the program would not load.
    BadSnippet = "E405",

    /// A mapping names a function the resource does not have.
    UnknownFunction = "E501",
    /// A value does not have its parameter's type.
    TypeMismatch = "E502",
    /// A value the program's language cannot take safely: not one token, a keyword, a name
    /// the language does not allow (it could inject code).
    UnsafeValue = "E503",
    /// An index into a list variable is out of range, or a list where one value is needed.
    BadIndex = "E504",
    /// A conversion in a template got a value that is not a number (or gave a result too
    /// large to write).
    BadConversion = "E505",
    /// A value outside what the blackboard's `Constraint` on its parameter allows (below
    /// `RequiredMinValue`, above `RequiredMaxValue`, or none of the `RequiredValue`s).
    OutOfRange = "E506",

    /// The program name is not a name of the program's language (or too long for it).
    BadProgramName = "E601",
    /// A non-ASCII character in generated code.
    NonAscii = "E602",
    /// The output template cannot be used.
    BadTemplate = "E603",
    /// An output or the blackboard cannot be written (disk full, permissions, an output that
    /// is a symbolic link or read-only); the daemon reports it in `compile-failed`, the command
    /// line exits with status 2.
    CannotWrite = "E604",
    /// An output (`<program>.src`/`.dat`) is also a file this compile reads (an IRL file, the
    /// SFC, the template, the blackboard): writing it would overwrite an input.
    OutputIsInput = "E605",
    /// A generated program fails the built-in check of its language ([`crate::check`]):
    /// nothing is written.
    BadProgram = "E606",

    /// The hierarchy is not named `Blackboard` (the only one was used).
    HierarchyNotNamed = "W201",
    /// An `AttributeDataType` that is not understood.
    UnknownType = "W202",
    /// Two function mappings with the same order.
    EqualOrder = "W203",
    /// No write-back target in the blackboard.
    NoWriteBackTarget = "W204",
    /// A program of a cell whose controller has no `Code` interface of its name: its path is
    /// not written back (docs/CELLS.md).
    NoProgramTarget = "W205",
    /// A blackboard element whose name is no CAEX element (a misspelling: it and what it holds
    /// are ignored); names the CAEX element closest to it.
    UnknownElement = "W206",
    /// An InternalLink between signals whose one side names no signal: the wire is left out.
    LinkPartnerMissing = "W207",
    /// A resource attribute whose name is near one skillpost reads (`Controler`): not read.
    NearAttribute = "W208",
    /// A parameter's `Constraint` that cannot be checked (a bound that is not a number, no
    /// value in it): not checked.
    UnusableConstraint = "W209",
    /// A KRL program's points written without KUKA's inline form, because the program sets
    /// motion parameters itself (docs/LANGUAGES.md, "Points").
    PointsNotInline = "W210",
    /// A resource whose steps move without a tool, base or load from the blackboard: its
    /// program keeps the controller's (docs/INPUTS.md, "Tool, base and load"); once per resource.
    NoToolData = "W211",
    /// The start step is not marked `initialStep="true"`.
    StartNotInitial = "W301",
    /// A step's resource was inferred from its skill.
    ResourceInferred = "W302",
    /// A step has variables its skill does not use.
    ExtraVariable = "W303",
    /// Ignored SFC elements (action blocks, unknown elements), one warning per kind and chart.
    Ignored = "W304",
    /// A step's `time@duration` that is not a number of seconds of at least 0: the step has no
    /// time.
    BadDuration = "W309",
    /// Several POUs have an SFC body and none was named: the one used and the others.
    SeveralPous = "W305",
    /// A selection branch right of an unconditional one: it is never taken.
    BranchNeverTaken = "W306",
    /// Flow the structured forms cannot express: compiled with labels and `GOTO` (KRL) or as
    /// a state machine (RAPID, URScript).
    Unstructured = "W307",
    /// An IRL definition whose routine no program of the compile calls: it is not written.
    UnusedDefinition = "W308",
    /// A part of a split program longer than the limit: one block of the top level is.
    LongPart = "W310",
}

impl std::fmt::Display for Code {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The innermost start tag still open at byte `upto` of an XML text (`<` and the name), read
/// without a parser: comments, CDATA sections, processing instructions and declarations are
/// skipped, quoted attribute values may hold `>`. For the text before a syntax error, which
/// the parser found well-formed.
fn unclosed_start_tag(text: &str, upto: usize) -> Option<Range<usize>> {
    let b = text.as_bytes();
    let upto = upto.min(b.len());
    let find =
        |from: usize, pat: &str| text.get(from..).and_then(|t| t.find(pat)).map(|i| from + i);
    let mut open: Vec<Range<usize>> = Vec::new();
    let mut i = 0;
    while i < upto {
        if b[i] != b'<' {
            i += 1;
            continue;
        }
        let rest = &text[i..];
        let skip = |pat: &str| find(i, pat).map(|e| e + pat.len());
        i = if rest.starts_with("<!--") {
            skip("-->")?
        } else if rest.starts_with("<![CDATA[") {
            skip("]]>")?
        } else if rest.starts_with("<?") {
            skip("?>")?
        } else if rest.starts_with("<!") {
            skip(">")?
        } else if rest.starts_with("</") {
            open.pop();
            skip(">")?
        } else {
            let name_end = i
                + 1
                + rest[1..]
                    .find(|c: char| c.is_whitespace() || c == '/' || c == '>')
                    .unwrap_or(rest.len() - 1);
            // The end of the tag: the first `>` outside quotes.
            let mut j = name_end;
            let mut quote = None;
            while j < b.len() {
                match (quote, b[j]) {
                    (None, q @ (b'"' | b'\'')) => quote = Some(q),
                    (Some(q), c) if c == q => quote = None,
                    (None, b'>') => break,
                    _ => {}
                }
                j += 1;
            }
            if j >= b.len() {
                return None;
            }
            if b[j - 1] != b'/' {
                open.push(i..name_end);
            }
            j + 1
        };
    }
    open.pop()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_code_is_documented_once() {
        let doc = include_str!("../../docs/DIAGNOSTICS.md");
        let mut seen = std::collections::HashSet::new();
        for c in Code::ALL {
            assert!(seen.insert(c.as_str()), "code {} used twice", c.as_str());
            assert!(
                doc.contains(&format!("| `{}` |", c.as_str())),
                "code {} missing from docs/DIAGNOSTICS.md",
                c.as_str()
            );
        }
    }

    /// A diagnostic whose file changed while the compile ran loses its line and column, not its
    /// file: that is named as the diagnostics with a place name it, and the daemon finds the
    /// file by its path (`daemon::job::half_written`).
    #[test]
    fn a_forgotten_place_keeps_its_file() {
        let mut s = Sources::default();
        let path = PathBuf::from("/project/sfc.xml");
        let f = s.add(path.clone(), "sfc.xml".into(), "<a/>".into(), false);
        let mut diags = Diagnostics::default();
        diags.push(Diagnostic::error(Code::XmlSyntax, "broken").at(Span::new(f, 0..1)));
        diags.forget_file(f, &path, "sfc.xml");
        let d = &diags.iter().next().unwrap();
        assert!(d.span.is_none());
        assert_eq!(d.path.as_deref(), Some(path.as_path()));
        let at = d.locate(&s);
        assert_eq!((at.file.as_deref(), at.line), (Some("sfc.xml"), None));
        let human = render(&diags.into_vec(), &s, Format::Human, false, false);
        assert!(human.contains("file: sfc.xml"), "{human}");
        // A path that was not read is shown as it is.
        assert_eq!(s.display_of(Path::new("/other.xml")), "/other.xml");
    }

    #[test]
    fn line_and_column_from_offsets() {
        let mut s = Sources::default();
        let f = s.add("a".into(), "a".into(), "ab\r\ncäd\nx".into(), false);
        assert_eq!(s.line_col(f, 0), (1, 1));
        assert_eq!(s.line_col(f, 4), (2, 1));
        // `ä` is two bytes but one column.
        assert_eq!(s.line_col(f, 7), (2, 3));
        assert_eq!(s.line_col(f, 9), (3, 1));
        assert_eq!(s.offset_of(f, 2, 3), 7);
        assert_eq!(s.line_col(f, 999), (3, 2));
    }
}
