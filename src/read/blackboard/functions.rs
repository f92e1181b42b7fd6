//! The functions under a resource's `FunctionDescription(s)`: each one's IRL command and file.

use roxmltree::Node;

use super::super::xml::{caex_attr, caex_element, caex_name, caex_value, children, tag_span};
use super::{Reader, ref_base_ends_with};
use crate::diag::{Code, Diagnostic, Span};
use crate::model::{Function, Name, RefValue};
use crate::names;

impl Reader<'_> {
    pub(super) fn function(&mut self, f: Node) -> Option<Function> {
        let name = self.name_of(f);
        let ifaces: Vec<Node> = children(f, "ExternalInterface")
            .filter(|ei| {
                caex_name(*ei).is_some_and(|n| names::eq(n, "FunctionDataInterface"))
                    || ref_base_ends_with(*ei, "FunctionLogic")
            })
            .collect();
        let iface = match ifaces.as_slice() {
            [one] => *one,
            [] => {
                self.diags.push(
                    Diagnostic::error(
                        Code::BadFunction,
                        format!(
                            "function `{}` has no `FunctionDataInterface` (an ExternalInterface with the IRL command and file)",
                            name.text
                        ),
                    )
                    .at(self.span(f))
                    .element(caex_element(f)),
                );
                return None;
            }
            [_, second, ..] => {
                self.diags.push(
                    Diagnostic::error(
                        Code::BadFunction,
                        format!(
                            "function `{}` has {} function data interfaces; exactly one is allowed",
                            name.text,
                            ifaces.len()
                        ),
                    )
                    .at(self.span(*second))
                    .element(caex_element(f)),
                );
                return None;
            }
        };
        let mut get = |attr: &str| -> Option<(String, Span)> {
            match caex_attr(iface, attr).and_then(|a| caex_value(self.file, a)) {
                Some((v, s)) if !v.is_empty() => Some((v, s)),
                _ => {
                    self.diags.push(
                        Diagnostic::error(
                            Code::BadFunction,
                            format!(
                                "function `{}`: its data interface has no `{attr}` value",
                                name.text
                            ),
                        )
                        .at(tag_span(self.file, iface))
                        .element(caex_element(iface)),
                    );
                    None
                }
            }
        };
        let command = get("Name");
        let irl = get("refURI");
        let ((command, cspan), (irl, ispan)) = (command?, irl?);
        Some(Function {
            name,
            element: caex_element(f),
            id: f.attribute("ID").map(str::to_owned),
            command: Name::new(&command, cspan),
            irl: RefValue {
                value: irl,
                span: ispan,
            },
        })
    }
}
