//! Conditions wired from the FBD/LD elements of a body (docs/INPUTS.md).

use std::collections::HashMap;
use std::ops::Range;

use super::Stream;
use super::named::{PieceMap, map_offset};

use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Span};
use crate::model::{Condition, Element, ElementKind};

/// An FBD/LD element a wired condition may be drawn from (docs/INPUTS.md).
#[derive(Debug)]
pub(super) struct WireNode {
    pub(super) local_id: u64,
    /// `inVariable`, `inOutVariable`, `leftPowerRail`, `contact`, `block`, or another.
    pub(super) tag: String,
    pub(super) span: Span,
    /// An `inVariable`'s expression or a `contact`'s variable, with its pieces' places.
    pub(super) text: Option<(String, PieceMap)>,
    pub(super) negated: bool,
    /// A contact's `edge` (`rising`, `falling`).
    pub(super) edge: Option<String>,
    pub(super) type_name: Option<String>,
    /// Direct inputs (a `contact`'s).
    pub(super) inputs: Vec<(u64, Range<usize>)>,
    /// A `block`'s inputs by formal parameter.
    pub(super) formal: Vec<Formal>,
}

/// A `block`'s input: its formal parameter and its connections (refLocalId, place).
pub(super) type Formal = (String, Vec<(u64, Range<usize>)>);

/// A transition whose condition is wired: its localId, where its condition's connections
/// lead, its condition element.
#[derive(Debug)]
pub(super) struct PendingWired {
    pub(super) transition: u64,
    pub(super) refs: Vec<(u64, Range<usize>)>,
    pub(super) at: Span,
}

impl Stream {
    /// The transitions whose conditions are wired (docs/INPUTS.md) get their expressions, built
    /// from the FBD/LD elements of the body; the body's parts are then forgotten.
    pub(super) fn resolve_wired(&mut self, els: &mut [Element], diags: &mut Diagnostics) {
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
    pub(super) fn named_network(
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
