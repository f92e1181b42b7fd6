//! The AutomationML blackboard (CAEX 2.15 or 3.0): resources, skills, functions, mappings, and
//! the SFC and write-back references (docs/INPUTS.md).

mod caex;
mod cell;
mod functions;
mod references;
mod resources;
mod signals;
mod skills;

use roxmltree::Node;

use super::xml::{caex_element, caex_name, children, tag_span};
use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::model::{Blackboard, Name};
use crate::names;
use caex::{no_hierarchy, unknown_elements};
use resources::resource_nodes;
pub use signals::{MAX_IO, is_safe_address};

// The submodules' `super::xml`/`super::tooling` paths resolve through these.
use super::{tooling, xml};

/// Reads the blackboard. Returns `None` only when the document cannot be used at all (not XML,
/// no hierarchy); otherwise a model with every problem reported in `diags`.
pub fn read_blackboard(
    sources: &Sources,
    file: FileId,
    diags: &mut Diagnostics,
) -> Option<Blackboard> {
    let doc = super::xml::parse(sources, file, diags)?;
    let root = doc.root_element();
    if root.tag_name().name() != "CAEXFile" {
        diags.push(
            Diagnostic::error(
                Code::XmlWrongRoot,
                format!(
                    "not a CAEX file: the root element is `{}`, not `CAEXFile`",
                    root.tag_name().name()
                ),
            )
            .at(tag_span(file, root)),
        );
        return None;
    }
    let hierarchies: Vec<Node> = children(root, "InstanceHierarchy").collect();
    let named: Vec<Node> = hierarchies
        .iter()
        .copied()
        .filter(|h| caex_name(*h).is_some_and(|n| names::eq(n, "Blackboard")))
        .collect();
    let hierarchy = match (named.as_slice(), hierarchies.as_slice()) {
        ([h], _) => *h,
        ([h, ..], _) => {
            diags.push(
                Diagnostic::warning(
                    Code::HierarchyNotNamed,
                    "several InstanceHierarchies are named `Blackboard`; the first is used",
                )
                .at(tag_span(file, *h)),
            );
            *h
        }
        ([], [h]) => {
            diags.push(
                Diagnostic::warning(
                    Code::HierarchyNotNamed,
                    format!(
                        "no InstanceHierarchy is named `Blackboard`; the only one, `{}`, is used",
                        caex_name(*h).unwrap_or("")
                    ),
                )
                .at(tag_span(file, *h)),
            );
            *h
        }
        ([], []) => {
            diags.push(no_hierarchy(sources, file, root));
            return None;
        }
        ([], _) => {
            diags.push(
                Diagnostic::error(
                    Code::NoHierarchy,
                    format!(
                        "no InstanceHierarchy is named `Blackboard`, and there are {}: which one is meant?",
                        hierarchies.len()
                    ),
                )
                .at(tag_span(file, root)),
            );
            return None;
        }
    };

    // Always: a run that keeps no warnings counts them (a blackboard is small).
    unknown_elements(file, root, diags);
    let r = Reader { file, diags };
    Some(r.hierarchy(hierarchy))
}

struct Reader<'d> {
    file: FileId,
    diags: &'d mut Diagnostics,
}

/// An `InternalElement` child of `parent` whose `Name` is one of `names`.
fn internal_element<'a, 'i>(parent: Node<'a, 'i>, wanted: &[&str]) -> Option<Node<'a, 'i>> {
    children(parent, "InternalElement")
        .find(|e| caex_name(*e).is_some_and(|n| wanted.iter().any(|w| names::eq(n, w))))
}

fn ref_base_ends_with(node: Node, suffix: &str) -> bool {
    node.attribute("RefBaseClassPath").is_some_and(|p| {
        let p = p.trim();
        p.len() >= suffix.len()
            && p.is_char_boundary(p.len() - suffix.len())
            && p[p.len() - suffix.len()..].eq_ignore_ascii_case(suffix)
    })
}

fn ref_base_contains(node: Node, part: &str) -> bool {
    node.attribute("RefBaseClassPath")
        .is_some_and(|p| p.to_ascii_lowercase().contains(&part.to_ascii_lowercase()))
}

impl Reader<'_> {
    fn span(&self, node: Node) -> Span {
        tag_span(self.file, node)
    }

    fn name_of(&self, node: Node) -> Name {
        let span = super::xml::attr_span(self.file, node, "Name");
        Name::new(caex_name(node).unwrap_or(""), span)
    }

    fn hierarchy(mut self, h: Node) -> Blackboard {
        let mut resources = Vec::new();
        match internal_element(h, &["Ressourcen", "Resources"]) {
            Some(res) => {
                for (r, parent) in resource_nodes(res) {
                    let mut resource = self.resource(r);
                    resource.parent = parent;
                    resources.push(resource);
                }
                self.check_unique(
                    resources.iter().map(|r| (&r.name, r.element.as_str())),
                    "resource",
                );
            }
            None => self.diags.push(
                Diagnostic::error(
                    Code::NoResources,
                    "the blackboard has no `Ressourcen` (or `Resources`) element",
                )
                .at(self.span(h))
                .element(caex_element(h)),
            ),
        }

        let controllers = self.controllers(&resources);
        let wires = self.wires(h, &resources, &controllers);
        let sfc_ref = self.sfc_reference(h);
        let write_back = self.write_back(h);
        let code_targets = self.code_targets(h);
        Blackboard {
            file: self.file,
            resources,
            controllers,
            wires,
            sfc_ref,
            write_back,
            code_targets,
        }
    }

    fn check_unique<'n>(&mut self, names: impl Iterator<Item = (&'n Name, &'n str)>, what: &str) {
        let mut seen: std::collections::HashMap<&str, &Name> = std::collections::HashMap::new();
        for (n, element) in names {
            if let Some(first) = seen.get(&*n.key) {
                self.diags.push(
                    Diagnostic::error(
                        Code::DuplicateName,
                        format!("a second {what} named `{}`", n.text),
                    )
                    .at(n.span.clone())
                    .element(element)
                    .related(first.span.clone(), "the first one"),
                );
            } else {
                seen.insert(&n.key, n);
            }
        }
    }
}
