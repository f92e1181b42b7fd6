//! Conditions drawn instead of written (docs/INPUTS.md, "Conditions"): [`wire_conditions`]
//! turns every inline ST condition of a chart into a network in the same SFC body, built from
//! the chart player's own reading of the text ([`Cond`]), not from the project's parser:
//!
//! - a comparison, `XOR`, `NOT` and (in FBD style) `AND`/`OR` become standard function blocks
//!   (`EQ`, `NE`, `LT`, `GT`, `LE`, `GE`, `XOR`, `NOT`, `AND`, `OR`) with their formal
//!   parameters `IN1`, `IN2` (`IN` for `NOT`);
//! - in LD style, a part made only of boolean signals, `NOT` of one, `AND` and `OR` becomes a
//!   rung from a left power rail: a contact per signal (`negated="true"` for `NOT`), in series
//!   for `AND`, side by side into one input for `OR`;
//! - a name, a number, a TIME literal, a step's time and a negated operand are `inVariable`s.
//!
//! Which style a part takes varies with the seed, so a chart mixes both.

use crate::chart::{Cond, CondOp};

/// `text` with each `condition/inline` replaced by a `condition/connectionPointIn` to a
/// network added at the end of the SFC body. `None` when the chart has no inline condition.
pub fn wire_conditions(text: &str, seed: u64) -> Option<String> {
    let doc = roxmltree::Document::parse(text).unwrap();
    let mut next = doc
        .descendants()
        .filter_map(|n| n.attribute("localId"))
        .map(|v| v.parse::<u64>().unwrap())
        .max()
        .unwrap_or(0)
        + 1000;
    let mut edits: Vec<(std::ops::Range<usize>, String)> = Vec::new();
    let mut network = String::new();
    for (k, c) in doc
        .descendants()
        .filter(|n| n.has_tag_name("condition"))
        .enumerate()
    {
        let Some(inline) = c.children().find(|n| n.has_tag_name("inline")) else {
            continue;
        };
        let st: String = inline
            .descendants()
            .filter(|n| n.is_text())
            .map(|n| n.text().unwrap())
            .collect();
        let cond = Cond::parse(&st);
        let mut w = Wirer {
            next: &mut next,
            out: &mut network,
            ld: (seed + k as u64).is_multiple_of(2),
            rail: None,
        };
        let outs = w.node(&cond);
        edits.push((
            c.range(),
            format!(
                "<condition><connectionPointIn>{}</connectionPointIn></condition>",
                connections(&outs)
            ),
        ));
    }
    if edits.is_empty() {
        return None;
    }
    let mut out = text.to_owned();
    edits.sort_by_key(|e| std::cmp::Reverse(e.0.start));
    for (range, with) in edits {
        out.replace_range(range, &with);
    }
    let end = out.rfind("</SFC>").unwrap();
    out.insert_str(end, &network);
    Some(out)
}

fn connections(ids: &[u64]) -> String {
    ids.iter()
        .map(|i| format!("<connection refLocalId=\"{i}\"/>"))
        .collect()
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

struct Wirer<'a> {
    next: &'a mut u64,
    out: &'a mut String,
    /// Rungs of contacts where a part allows them.
    ld: bool,
    /// This condition's left power rail, once drawn.
    rail: Option<u64>,
}

impl Wirer<'_> {
    fn id(&mut self) -> u64 {
        *self.next += 1;
        *self.next
    }

    /// The elements of `c`; returns the connections its consumer's input takes (several: OR).
    fn node(&mut self, c: &Cond) -> Vec<u64> {
        if self.ld && rung(c) {
            let rail = match self.rail {
                Some(r) => r,
                None => {
                    let r = self.id();
                    self.out.push_str(&format!(
                        "<leftPowerRail localId=\"{r}\"><position x=\"0\" y=\"0\"/><connectionPointOut formalParameter=\"\"/></leftPowerRail>\n"
                    ));
                    self.rail = Some(r);
                    r
                }
            };
            return self.contacts(c, vec![rail]);
        }
        match c {
            Cond::Bin(op, a, b) => {
                let name = match op {
                    CondOp::Or => "OR",
                    CondOp::Xor => "XOR",
                    CondOp::And => "AND",
                    CondOp::Eq => "EQ",
                    CondOp::Ne => "NE",
                    CondOp::Lt => "LT",
                    CondOp::Gt => "GT",
                    CondOp::Le => "LE",
                    CondOp::Ge => "GE",
                };
                let (x, y) = (self.node(a), self.node(b));
                vec![self.block(name, &[("IN1", x), ("IN2", y)])]
            }
            Cond::Not(a) => {
                let x = self.node(a);
                vec![self.block("NOT", &[("IN", x)])]
            }
            leaf => {
                let id = self.id();
                self.out.push_str(&format!(
                    "<inVariable localId=\"{id}\"><position x=\"0\" y=\"0\"/><connectionPointOut/><expression>{}</expression></inVariable>\n",
                    escape(&operand(leaf))
                ));
                vec![id]
            }
        }
    }

    /// Contacts for the rung `c` fed from `from`; returns the contacts its consumer takes.
    fn contacts(&mut self, c: &Cond, from: Vec<u64>) -> Vec<u64> {
        match c {
            Cond::Bin(CondOp::And, a, b) => {
                let mid = self.contacts(a, from);
                self.contacts(b, mid)
            }
            Cond::Bin(CondOp::Or, a, b) => {
                let mut outs = self.contacts(a, from.clone());
                outs.extend(self.contacts(b, from));
                outs
            }
            Cond::Signal(s) => vec![self.contact(s, false, &from)],
            Cond::Not(a) => match &**a {
                Cond::Signal(s) => vec![self.contact(s, true, &from)],
                other => panic!("not a rung: NOT {other:?}"),
            },
            other => panic!("not a rung: {other:?}"),
        }
    }

    /// A contact of `signal` (`negated`: normally closed) fed from `from`.
    fn contact(&mut self, signal: &str, negated: bool, from: &[u64]) -> u64 {
        let id = self.id();
        self.out.push_str(&format!(
            "<contact localId=\"{id}\"{}><position x=\"0\" y=\"0\"/><connectionPointIn>{}</connectionPointIn><variable>{signal}</variable></contact>\n",
            if negated { " negated=\"true\"" } else { "" },
            connections(from)
        ));
        id
    }

    fn block(&mut self, name: &str, inputs: &[(&str, Vec<u64>)]) -> u64 {
        let id = self.id();
        let vars: String = inputs
            .iter()
            .map(|(p, from)| {
                format!(
                    "<variable formalParameter=\"{p}\"><connectionPointIn>{}</connectionPointIn></variable>",
                    connections(from)
                )
            })
            .collect();
        self.out.push_str(&format!(
            "<block localId=\"{id}\" typeName=\"{name}\"><position x=\"0\" y=\"0\"/><inputVariables>{vars}</inputVariables><inOutVariables/><outputVariables><variable formalParameter=\"OUT\"><connectionPointOut/></variable></outputVariables></block>\n"
        ));
        id
    }
}

/// Whether `c` can be a rung: boolean signals, `NOT` of one, `AND`, `OR`.
fn rung(c: &Cond) -> bool {
    match c {
        Cond::Signal(s) => boolean(s),
        Cond::Not(a) => matches!(&**a, Cond::Signal(s) if boolean(s)),
        Cond::Bin(CondOp::And | CondOp::Or, a, b) => rung(a) && rung(b),
        _ => false,
    }
}

/// Whether the signal `s` is a boolean one (the random charts' `Variant` is an integer).
fn boolean(s: &str) -> bool {
    crate::SIGNALS
        .iter()
        .any(|g| g.name.eq_ignore_ascii_case(s) && !g.integer)
}

/// An operand as ST text.
fn operand(c: &Cond) -> String {
    match c {
        Cond::Int(i) => i.to_string(),
        Cond::Bool(b) => if *b { "TRUE" } else { "FALSE" }.to_owned(),
        Cond::Time(ns) => format!("T#{ns}ns"),
        Cond::Signal(s) => s.clone(),
        Cond::StepTime(s) => format!("{s}.t"),
        Cond::Neg(a) => format!("-{}", operand(a)),
        other => panic!("not an operand: {other:?}"),
    }
}
