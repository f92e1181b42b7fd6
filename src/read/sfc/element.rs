//! The element being read (a direct child of `SFC`): what its start tag and descendants give,
//! and what it becomes: a step's data, a transition's condition; the POU chosen at the end.

use std::ops::Range;

use quick_xml::events::BytesStart;

use super::Stream;
use super::named::{Named, PieceMap, map_offset, named_expression};
use super::tag::{Open, Tag};
use super::wired::{Formal, PendingWired, WireNode};

use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Span};
use crate::model::{Condition, Element, ElementKind, FileHeader, Name, Sfc, Step, Variable};
use crate::read::tape::{Batch, Rec};

/// A picked attribute's value, kept in a scratch string: where it is there, its raw value's byte
/// range in the file, and whether the value is the raw bytes one to one (no references or
/// normalized whitespace, so offsets into it are offsets into the file).
#[derive(Debug, Clone)]
pub(super) struct Val {
    pub(super) at: Range<usize>,
    pub(super) range: Range<usize>,
    pub(super) exact: bool,
}

impl Val {
    pub(super) fn get<'s>(&self, scratch: &'s str) -> &'s str {
        &scratch[self.at.clone()]
    }
}

/// One `Variable`: its tag and its `name` and `Value`.
#[derive(Clone)]
pub(super) struct VarAttrs {
    pub(super) tag: Span,
    pub(super) name: Option<Val>,
    pub(super) value: Option<Val>,
    /// Read inside `iwb` (these come after the direct ones).
    pub(super) iwb: bool,
}

/// The element being read (a direct child of `SFC`), with what its descendants contributed.
/// One is reused for every element, so its buffers are allocated once.
pub(super) struct Building {
    pub(super) tag: Tag,
    /// The tag's local name when it is [`Tag::Other`].
    other: String,
    pub(super) span: Span,
    pub(super) depth: usize,
    /// Attribute values and variable names and values, one after another.
    pub(super) scratch: String,
    pub(super) local_id: Option<Val>,
    pub(super) name: Option<Val>,
    pub(super) initial: Option<Val>,
    pub(super) target: Option<Val>,
    pub(super) x: Option<f64>,
    pub(super) inputs: Vec<(u64, Range<usize>)>,
    pub(super) bad_inputs: Vec<Diagnostic>,
    pub(super) vars: Vec<VarAttrs>,
    pub(super) iwb: IwbState,
    pub(super) resource: Option<Name>,
    pub(super) resources_seen: bool,
    pub(super) skill: Option<Name>,
    pub(super) duration: Option<f64>,
    /// A `time@duration` that is not a number of seconds ≥ 0: as written, and where.
    pub(super) bad_duration: Option<(String, Range<usize>)>,
    pub(super) time_seen: bool,
    pub(super) condition: Option<Span>,
    pub(super) condition_done: bool,
    pub(super) inline: Option<String>,
    /// Where each piece of `inline` came from: (offset in `inline`, offset in the file, whether
    /// the piece's bytes are the file's bytes one to one).
    pub(super) inline_map: Vec<(usize, usize, bool)>,
    /// `condition/reference@name`: the name and its range.
    pub(super) reference: Option<(String, Range<usize>)>,
    /// `condition/connectionPointIn`: a condition wired from FBD/LD elements.
    pub(super) wired: bool,
    /// Where a wired condition's connections lead (refLocalId, its place).
    pub(super) wired_refs: Vec<(u64, Range<usize>)>,
    /// An FBD/LD element's text: an `inVariable`'s `expression`, a `contact`'s `variable`.
    pub(super) wire_text: Option<(String, PieceMap)>,
    /// A `contact`'s `negated` and `edge` (`rising`/`falling`), a `block`'s `typeName`.
    pub(super) negated: bool,
    pub(super) edge: Option<String>,
    pub(super) type_name: Option<String>,
    /// A `block`'s inputs: formal parameter and its connections.
    pub(super) formal: Vec<Formal>,
    /// The tags below the element (reused).
    pub(super) rel: Vec<Tag>,
}

impl Building {
    pub(super) fn new(file: FileId) -> Self {
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
    pub(super) fn reset(&mut self, tag: Tag, other: &str, span: Span, depth: usize) {
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

    pub(super) fn val(&self, v: &Option<Val>) -> Option<&str> {
        v.as_ref().map(|v| v.get(&self.scratch))
    }

    /// How diagnostics name the element: `localId N` (`?` without one).
    pub(super) fn id_label(&self) -> String {
        format!("localId {}", self.val(&self.local_id).unwrap_or("?"))
    }

    /// The element's local name.
    pub(super) fn tag_name(&self) -> &str {
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
pub(super) enum IwbState {
    Before,
    Inside,
    Done,
}

/// A start tag's event on the tape, and where its bytes sit in the file: the event's content
/// begins one byte after `at` (the `<`).
pub(super) struct Tagged<'a> {
    pub(super) e: BytesStart<'a>,
    /// The local name, a part of the content.
    local: &'a str,
    pub(super) at: usize,
}

impl<'a> Tagged<'a> {
    pub(super) fn new(rec: &Rec, batch: &'a Batch) -> Self {
        let (name, local, content) = batch.names_and_content(rec);
        Tagged {
            e: BytesStart::from_content(content, name.len()),
            local,
            at: batch.at(rec),
        }
    }

    /// The file offset of `s`, a slice of the event's bytes (`fallback` if it is not one).
    pub(super) fn offset_of(&self, s: &str, fallback: usize) -> usize {
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
    pub(super) fn local_name(&self) -> &'a str {
        self.local
    }
}

impl Stream {
    /// A transition's condition: parsed, syntax errors located in the file. `None` when the
    /// transition always fires (no condition, or `TRUE`).
    pub(super) fn condition(
        &mut self,
        b: &Building,
        diags: &mut Diagnostics,
    ) -> Option<Box<Condition>> {
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

    pub(super) fn step(&mut self, b: &Building, diags: &mut Diagnostics) -> Step {
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
    pub(super) fn choose(
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

    /// Starts building the element `tag` at `depth`: its attributes.
    pub(super) fn begin(
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
    pub(super) fn finish(&mut self, b: &mut Building, diags: &mut Diagnostics) -> Option<Element> {
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
}

/// One warning per kind of ignored element (action blocks, unknown elements), naming them.
pub(super) fn report_ignored(ignored: &[(String, Span, String)], diags: &mut Diagnostics) {
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

/// An element inside the one being built closed; `stack` is what remains open.
pub(super) fn end_inside(b: &mut Building, stack: &Open) {
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
pub(super) fn inline_text<'s>(
    b: &mut Building,
    stack: &Open,
    raw: Range<usize>,
    text: impl FnOnce() -> std::borrow::Cow<'s, str>,
) {
    if b.inline.is_some() && in_inline(b, stack) {
        let inline = b.inline.get_or_insert_default();
        push_piece(inline, &mut b.inline_map, raw, &text());
    } else if b.wire_text.is_some()
        && in_wire_text(b, stack)
        && let Some((w, map)) = &mut b.wire_text
    {
        push_piece(w, map, raw, &text());
    }
}

/// Appends `t`, read from the file at `raw`, to a text assembled from pieces, and to `map`
/// where the piece came from (byte for byte when `t` is as long as its source: no reference or
/// line end was resolved in it; [`map_offset`]).
pub(super) fn push_piece(
    text: &mut String,
    map: &mut Vec<(usize, usize, bool)>,
    raw: Range<usize>,
    t: &str,
) {
    map.push((text.len(), raw.start, t.len() == raw.len()));
    text.push_str(t);
}

/// Whether the stack is inside an FBD/LD element's `expression` or `variable`.
fn in_wire_text(b: &Building, stack: &Open) -> bool {
    let rel = &stack.tags[b.depth.min(stack.len())..];
    matches!(rel.first(), Some((Tag::Expression | Tag::WireVariable, _)))
}

/// Whether the stack is inside the element's `condition/inline`.
fn in_inline(b: &Building, stack: &Open) -> bool {
    let rel = &stack.tags[b.depth.min(stack.len())..];
    rel.len() >= 2 && rel[0].0 == Tag::Condition && rel[1].0 == Tag::Inline
}
