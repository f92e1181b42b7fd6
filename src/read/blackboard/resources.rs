//! The resources under `Ressourcen`/`Resources` (also below grouping elements, and the devices
//! standing inside a resource) and a resource's own attributes.

use roxmltree::Node;

use super::super::xml::{caex_attr, caex_element, caex_name, caex_value, children};
use super::{Reader, internal_element};
use crate::diag::{Code, Diagnostic, Span};
use crate::model::{Name, Resource};
use crate::names;

/// The resources under `Ressourcen`/`Resources` (docs/INPUTS.md): its children that have a child
/// named `Skills` or `FunctionDescription(s)`, and at any depth below grouping elements (plant,
/// line, cell) those that do; a child with no resource below it is a resource itself. Then the
/// devices: resources standing inside a resource (docs/CELLS.md), with the index of the resource
/// they stand in. Top-level resources in document order, then each resource's devices.
pub(super) fn resource_nodes<'a, 'i>(res: Node<'a, 'i>) -> Vec<(Node<'a, 'i>, Option<usize>)> {
    let is_resource = |n: Node| {
        internal_element(
            n,
            &["Skills", "FunctionDescription", "FunctionDescriptions"],
        )
        .is_some()
    };
    // The resources below `top` (not below a resource found): depth-first, document order.
    let below = |top: Node<'a, 'i>, skip_own: bool| {
        let mut found = Vec::new();
        let mut stack: Vec<(Node, usize)> = children(top, "InternalElement")
            .filter(|k| {
                !skip_own
                    || !caex_name(*k).is_some_and(|n| {
                        [
                            "Skills",
                            "FunctionDescription",
                            "FunctionDescriptions",
                            "Signals",
                            "Signale",
                        ]
                        .iter()
                        .any(|w| names::eq(n, w))
                    })
            })
            .map(|k| (k, 1))
            .collect();
        stack.reverse();
        while let Some((n, depth)) = stack.pop() {
            if is_resource(n) {
                found.push(n);
            } else if depth < super::xml::MAX_DEPTH {
                let mut kids: Vec<(Node, usize)> = children(n, "InternalElement")
                    .map(|k| (k, depth + 1))
                    .collect();
                kids.reverse();
                stack.extend(kids);
            }
        }
        found
    };
    let mut out: Vec<(Node, Option<usize>)> = Vec::new();
    for c in children(res, "InternalElement") {
        if is_resource(c) {
            out.push((c, None));
            continue;
        }
        let found = below(c, false);
        if found.is_empty() {
            out.push((c, None));
        } else {
            out.extend(found.into_iter().map(|n| (n, None)));
        }
    }
    // Devices: a worklist over the resources found so far (it grows as devices are found).
    let mut i = 0;
    while i < out.len() {
        let (r, _) = out[i];
        if is_resource(r) {
            out.extend(below(r, true).into_iter().map(|n| (n, Some(i))));
        }
        i += 1;
    }
    out
}

impl Reader<'_> {
    pub(super) fn resource(&mut self, r: Node) -> Resource {
        let name = self.name_of(r);
        let mut skills = Vec::new();
        if let Some(s) = internal_element(r, &["Skills"]) {
            for sk in children(s, "InternalElement") {
                skills.push(self.skill(sk));
            }
        }
        self.check_unique(
            skills.iter().map(|s| (&s.name, s.element.as_str())),
            "skill",
        );
        let mut functions = Vec::new();
        let mut broken_functions = Vec::new();
        for fd in children(r, "InternalElement").filter(|e| {
            caex_name(*e).is_some_and(|n| {
                names::eq(n, "FunctionDescription") || names::eq(n, "FunctionDescriptions")
            })
        }) {
            for f in children(fd, "InternalElement") {
                match self.function(f) {
                    Some(f) => functions.push(f),
                    None => broken_functions.push(self.name_of(f).key),
                }
            }
        }
        self.check_unique(
            functions.iter().map(|f| (&f.name, f.element.as_str())),
            "function",
        );
        let (signals, broken_signals) = self.signals(r);
        let language = self.language(r, &name);
        self.near_attributes(r);
        let controller_attr = caex_attr(r, "Controller")
            .or_else(|| caex_attr(r, "Steuerung"))
            .and_then(|a| caex_value(self.file, a))
            .filter(|(v, _)| !v.is_empty());
        let program_attr = caex_attr(r, "Program")
            .or_else(|| caex_attr(r, "Programm"))
            .and_then(|a| caex_value(self.file, a))
            .filter(|(v, _)| !v.trim().is_empty());
        let timers_attr = caex_attr(r, "Timers")
            .and_then(|a| caex_value(self.file, a))
            .filter(|(v, _)| !v.trim().is_empty());
        let handshake_timeout_attr = caex_attr(r, "HandshakeTimeout")
            .and_then(|a| caex_value(self.file, a))
            .filter(|(v, _)| !v.trim().is_empty());
        let points_attr = caex_attr(r, "Points")
            .and_then(|a| caex_value(self.file, a))
            .filter(|(v, _)| !v.trim().is_empty());
        let tooling = super::tooling::read(self.file, r, &caex_element(r), self.diags);
        const GROUPS: [&str; 5] = [
            "Skills",
            "FunctionDescription",
            "FunctionDescriptions",
            "Signals",
            "Signale",
        ];
        let misnamed = children(r, "InternalElement")
            .filter_map(|e| {
                let n = caex_name(e)?;
                let meant = names::closest(n, GROUPS)?;
                let meant = GROUPS.into_iter().find(|g| *g == meant)?;
                Some((n.to_owned(), self.span(e), meant))
            })
            .collect();
        Resource {
            name,
            language,
            parent: None,
            misnamed,
            controller_attr,
            program_attr,
            timers_attr,
            handshake_timeout_attr,
            points_attr,
            tooling,
            element: caex_element(r),
            id: r.attribute("ID").map(str::to_owned),
            skills,
            functions,
            broken_functions,
            signals,
            broken_signals,
            index: Default::default(),
        }
    }

    /// `W208` for each attribute of resource `r` whose name is near, but not, one a resource's
    /// attributes skillpost reads (`Controler`): it would be ignored without a word.
    fn near_attributes(&mut self, r: Node) {
        const OWN: [&str; 9] = [
            "Controller",
            "Steuerung",
            "Program",
            "Programm",
            "Language",
            "Sprache",
            "Timers",
            "HandshakeTimeout",
            "Points",
        ];
        let read: Vec<&str> = OWN.into_iter().chain(super::tooling::NAMES).collect();
        for a in children(r, "Attribute") {
            let Some(name) = caex_name(a) else { continue };
            if read.iter().any(|k| names::eq(k, name)) {
                continue;
            }
            let n = names::key(name).chars().count();
            let near = read
                .iter()
                .map(|k| (names::edit_distance(name, k), *k))
                .filter(|(d, _)| *d <= 2 && 2 * d < n)
                .min_by_key(|(d, _)| *d);
            if let Some((_, meant)) = near {
                self.diags.push(
                    Diagnostic::warning(
                        Code::NearAttribute,
                        format!("attribute `{name}` is not read: did you mean `{meant}`?"),
                    )
                    .at(self.span(a))
                    .element(caex_element(r)),
                );
            }
        }
    }

    /// The resource's `Language` (alias `Sprache`) attribute, any case; `E210` for a value
    /// that names no language skillpost writes.
    fn language(&mut self, r: Node, name: &Name) -> Option<(crate::lang::Language, Span)> {
        let attr = caex_attr(r, "Language").or_else(|| caex_attr(r, "Sprache"))?;
        let (v, span) = caex_value(self.file, attr).filter(|(v, _)| !v.trim().is_empty())?;
        match crate::lang::Language::parse(&v) {
            Some(l) => Some((l, span)),
            None => {
                self.diags.push(
                    Diagnostic::error(
                        Code::BadLanguage,
                        format!(
                            "resource `{}`: Language `{}` is none skillpost writes: `KRL`, `RAPID` or `URScript`",
                            name.text,
                            v.trim()
                        ),
                    )
                    .at(span)
                    .element(caex_element(r)),
                );
                None
            }
        }
    }
}
