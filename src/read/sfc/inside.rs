//! The descendants of the element being built: a step's position, connections, variables and
//! `addData` (its skill, resource, time), a transition's condition (inline, a reference, wired),
//! an FBD/LD element's parts. Each is picked by where it stands below the element.

use super::element::{Building, IwbState, VarAttrs};
use super::tag::{Open, Tag};
use super::{Stream, Tagged};

use crate::diag::{Code, Diagnostic, Span};

impl Stream {
    /// A descendant of the element being built, at `stack` (which ends below the element).
    pub(super) fn inside(
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
}
