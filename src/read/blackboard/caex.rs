//! The CAEX schema's element names: `E201` for a blackboard without an `InstanceHierarchy`,
//! `W206` for an element name of the CAEX namespace that is no CAEX element.

use roxmltree::Node;

use super::super::xml::{caex_element, tag_span};
use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources};

/// The element names of the CAEX 2.15 and 3.0 schemas (`CAEX_ClassModel_V2.15.xsd`,
/// `CAEX_ClassModel_V.3.0.xsd`), sorted.
const CAEX_ELEMENTS: &[&str] = &[
    "AdditionalInformation",
    "Attribute",
    "AttributeNameMapping",
    "AttributeType",
    "AttributeTypeLib",
    "AuthorName",
    "CAEXFile",
    "Comment",
    "Constraint",
    "Copyright",
    "DefaultValue",
    "Description",
    "ExternalInterface",
    "ExternalReference",
    "InstanceHierarchy",
    "InterfaceClass",
    "InterfaceClassLib",
    "InterfaceIDMapping",
    "InterfaceNameMapping",
    "InternalElement",
    "InternalLink",
    "MappingObject",
    "NewVersion",
    "NominalScaledType",
    "OldVersion",
    "OrdinalScaledType",
    "RefSemantic",
    "RequiredMaxValue",
    "RequiredMinValue",
    "RequiredValue",
    "Requirements",
    "Revision",
    "RevisionDate",
    "RoleClass",
    "RoleClassLib",
    "RoleRequirements",
    "SourceDocumentInformation",
    "SourceObjectInformation",
    "SuperiorStandardVersion",
    "SupportedRoleClass",
    "SystemUnitClass",
    "SystemUnitClassLib",
    "UnknownType",
    "Value",
    "Version",
];

/// CAEX elements whose content may be any XML (`xs:anyType` in CAEX 2.15): not looked into.
const ANY_CONTENT: &[&str] = &[
    "AdditionalInformation",
    "DefaultValue",
    "RequiredMaxValue",
    "RequiredMinValue",
    "RequiredValue",
    "Value",
];

/// The CAEX element name closest to `name`, at most two edits away.
fn closest_element(name: &str) -> Option<&'static str> {
    CAEX_ELEMENTS
        .iter()
        .map(|k| (crate::names::edit_distance(name, k), *k))
        .filter(|(d, _)| *d <= 2)
        .min_by_key(|(d, _)| *d)
        .map(|(_, k)| k)
}

/// Whether `node` is an element of the CAEX document's own namespace (that of `root`, or none)
/// whose name is no CAEX element.
fn is_unknown_element(root: Node, node: Node) -> bool {
    node.is_element()
        && (node.tag_name().namespace().is_none()
            || node.tag_name().namespace() == root.tag_name().namespace())
        && CAEX_ELEMENTS
            .binary_search(&node.tag_name().name())
            .is_err()
}

/// `E201` for a blackboard without an `InstanceHierarchy`: names the element that stands where
/// one was expected (a child of `CAEXFile` that is no CAEX element), with the name it is closest
/// to.
pub(super) fn no_hierarchy(sources: &Sources, file: FileId, root: Node) -> Diagnostic {
    let found = root
        .children()
        .filter(|c| is_unknown_element(root, *c))
        .min_by_key(|c| crate::names::edit_distance(c.tag_name().name(), "InstanceHierarchy"));
    let Some(found) = found else {
        return Diagnostic::error(Code::NoHierarchy, "the blackboard has no InstanceHierarchy")
            .at(tag_span(file, root));
    };
    let name = found.tag_name().name();
    let (line, col) = sources.line_col(file, found.range().start);
    let guess = match closest_element(name) {
        Some(k) => format!(": did you mean `{k}`?"),
        None => ", which is no CAEX element".to_owned(),
    };
    Diagnostic::error(
        Code::NoHierarchy,
        format!("the blackboard has no InstanceHierarchy: found `{name}` at {line}:{col}{guess}"),
    )
    .at(tag_span(file, found))
}

/// `W206` for each element name of the CAEX namespace that is no CAEX element (a misspelled
/// `<Atribute>` is ignored with everything in it): once per name, at its first place, with the
/// CAEX element it is closest to. Elements of other namespaces, and the content of elements
/// that may hold any XML (`Value`, `AdditionalInformation`, ...), are not looked at.
pub(super) fn unknown_elements(file: FileId, root: Node, diags: &mut Diagnostics) {
    let mut seen: Vec<(&str, Node, usize)> = Vec::new();
    let mut stack = vec![root];
    while let Some(n) = stack.pop() {
        let name = n.tag_name().name();
        if is_unknown_element(root, n) {
            match seen.iter_mut().find(|(k, _, _)| *k == name) {
                Some((_, _, count)) => *count += 1,
                None => seen.push((name, n, 1)),
            }
            // What an unknown element holds is not read: its own misspellings do not matter.
            continue;
        }
        if ANY_CONTENT.contains(&name) {
            continue;
        }
        let mut kids: Vec<Node> = n
            .children()
            .filter(|c| {
                c.is_element()
                    && (c.tag_name().namespace().is_none()
                        || c.tag_name().namespace() == root.tag_name().namespace())
            })
            .collect();
        kids.reverse();
        stack.extend(kids);
    }
    for (name, node, count) in seen {
        let mut message = format!("`{name}` is no CAEX element: it is ignored, with what it holds");
        if let Some(k) = closest_element(name) {
            message.push_str(&format!("; did you mean `{k}`?"));
        }
        let mut d = Diagnostic::warning(Code::UnknownElement, message)
            .at(tag_span(file, node))
            .element(caex_element(node));
        if count > 1 {
            d = d.note(format!(
                "`{name}` stands {count} times in the blackboard; this is the first"
            ));
        }
        diags.push(d);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn caex_element_names_are_sorted_for_the_binary_search() {
        assert!(CAEX_ELEMENTS.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn the_closest_caex_element_is_at_most_two_edits_away() {
        assert_eq!(crate::names::edit_distance("Atribute", "Attribute"), 1);
        assert_eq!(crate::names::edit_distance("kitten", "sitting"), 3);
        assert_eq!(closest_element("Atribute"), Some("Attribute"));
        assert_eq!(
            closest_element("InstanceHierachy"),
            Some("InstanceHierarchy")
        );
        assert_eq!(closest_element("InternalElment"), Some("InternalElement"));
        assert_eq!(closest_element("internalelement"), Some("InternalElement"));
        assert_eq!(closest_element("Skills"), None);
    }
}
