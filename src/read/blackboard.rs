//! The AutomationML blackboard (CAEX 2.15 or 3.0): resources, skills, functions, mappings, and
//! the SFC and write-back references (docs/INPUTS.md).

use roxmltree::Node;

use super::xml::{caex_attr, caex_element, caex_name, caex_value, children, tag_span};
use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::model::{
    Blackboard, Function, FunctionMapping, MappedArg, Name, Param, RefValue, Resource, Signal,
    SignalKind, Skill, ValueType, WriteBackTarget,
};
use crate::names;

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
fn no_hierarchy(sources: &Sources, file: FileId, root: Node) -> Diagnostic {
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
fn unknown_elements(file: FileId, root: Node, diags: &mut Diagnostics) {
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

/// The highest I/O index a signal may use (KRL's `$IN`/`$OUT` have 4096 on a KR C4; 8192 on
/// later controllers).
pub const MAX_IO: u32 = 8192;

/// An `Address` is one safe token: a name or a `$`system variable, optionally with one or two
/// integer indexes (`PART_OK`, `$IN[5]`, `$CYCFLAG[3]`, `$X[1,2]`).
pub fn is_safe_address(s: &str) -> bool {
    // A call with one integer argument (URScript: `read_input_integer_register(2)`).
    if let Some(inner) = s.strip_suffix(')')
        && let Some((f, arg)) = inner.split_once('(')
    {
        return crate::value::is_ident(f)
            && f.len() <= 63
            && !arg.is_empty()
            && arg.len() <= 9
            && arg.bytes().all(|b| b.is_ascii_digit());
    }
    let (base, index) = match s.find('[') {
        Some(i) => (&s[..i], Some(&s[i..])),
        None => (s, None),
    };
    let name = base.strip_prefix('$').unwrap_or(base);
    let ident = !name.is_empty()
        && name.len() <= 24
        && (name.as_bytes()[0].is_ascii_alphabetic() || name.as_bytes()[0] == b'_')
        && name.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'_');
    let index_ok = match index {
        None => true,
        Some(ix) => ix
            .strip_prefix('[')
            .and_then(|r| r.strip_suffix(']'))
            .is_some_and(|inner| {
                let parts: Vec<&str> = inner.split(',').collect();
                parts.len() <= 2
                    && parts.iter().all(|p| {
                        !p.is_empty() && p.len() <= 9 && p.bytes().all(|b| b.is_ascii_digit())
                    })
            }),
    };
    ident && index_ok && !names::is_krl_keyword(name)
}

/// The resources under `Ressourcen`/`Resources` (docs/INPUTS.md): its children that have a child
/// named `Skills` or `FunctionDescription(s)`, and at any depth below grouping elements (plant,
/// line, cell) those that do; a child with no resource below it is a resource itself. Then the
/// devices: resources standing inside a resource (docs/CELLS.md), with the index of the resource
/// they stand in. Top-level resources in document order, then each resource's devices.
fn resource_nodes<'a, 'i>(res: Node<'a, 'i>) -> Vec<(Node<'a, 'i>, Option<usize>)> {
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

    /// Which resource's controller runs each resource (docs/CELLS.md): its `Controller` attribute
    /// when that names another resource, else the nearest enclosing resource's, else itself;
    /// followed along the chain. A chain that comes back to where it started is `E211` at the
    /// attribute that closes it (that resource is then its own controller); a device whose
    /// `Language` differs from its controller's is `E319` at the device's attribute.
    fn controllers(&mut self, resources: &[Resource]) -> Vec<usize> {
        let mut by_key: std::collections::HashMap<&str, usize> = std::collections::HashMap::new();
        for (i, r) in resources.iter().enumerate() {
            by_key.entry(&r.name.key).or_insert(i);
        }
        // The next resource up the chain of each one.
        let next: Vec<Option<usize>> = resources
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let named = r
                    .controller_attr
                    .as_ref()
                    .and_then(|(v, _)| by_key.get(&*names::key(v)).copied())
                    .filter(|&t| t != i);
                named.or(r.parent)
            })
            .collect();
        let mut out = vec![usize::MAX; resources.len()];
        for start in 0..resources.len() {
            if out[start] != usize::MAX {
                continue;
            }
            // Walk up until a known controller, a resource that is its own, or a loop.
            let mut path = vec![start];
            let mut on_path = std::collections::HashSet::from([start]);
            let mut at = start;
            let found = loop {
                match next[at] {
                    None => break at,
                    Some(n) if out[n] != usize::MAX => break out[n],
                    Some(n) if on_path.contains(&n) => {
                        // A loop: the resource whose attribute closes it is its own controller.
                        let r = &resources[at];
                        if let Some((v, span)) = &r.controller_attr {
                            let cycle: Vec<&str> = path
                                [path.iter().position(|&p| p == n).unwrap_or(0)..]
                                .iter()
                                .map(|&p| resources[p].name.text.as_ref())
                                .collect();
                            self.diags.push(
                                Diagnostic::error(
                                    Code::ControllerLoop,
                                    format!(
                                        "resource `{}`: Controller `{}` makes a loop ({} -> {}): one resource of a cell must be a controller of its own",
                                        r.name.text,
                                        v,
                                        cycle.join(" -> "),
                                        resources[n].name.text
                                    ),
                                )
                                .at(span.clone())
                                .element(r.element.clone()),
                            );
                        }
                        break at;
                    }
                    Some(n) => {
                        path.push(n);
                        on_path.insert(n);
                        at = n;
                    }
                }
            };
            for p in path {
                if out[p] == usize::MAX {
                    out[p] = found;
                }
            }
        }
        for (i, r) in resources.iter().enumerate() {
            let c = out[i];
            if c == i {
                continue;
            }
            if let (Some((own, at)), Some((theirs, _))) = (&r.language, &resources[c].language)
                && own != theirs
            {
                self.diags.push(
                    Diagnostic::error(
                        Code::TwoLanguages,
                        format!(
                            "resource `{}` is {own}, but it runs on the controller of `{}`, which is {theirs}: a device is programmed in its controller's language",
                            r.name.text, resources[c].name.text
                        ),
                    )
                    .at(at.clone())
                    .element(r.element.clone()),
                );
            }
        }
        out
    }

    /// The wires between controllers (docs/CELLS.md): every `InternalLink` in the hierarchy whose two
    /// partners (`RefPartnerSideA`, `RefPartnerSideB`: `<element ID>:<interface name>`) are
    /// signals of resources on two different controllers, one an `Output`, the other an `Input`.
    /// Links between other things (or within one controller) are no wires and are left alone; a
    /// link between two outputs or two inputs of two controllers is `E209` at the link.
    fn wires(
        &mut self,
        h: Node,
        resources: &[Resource],
        controllers: &[usize],
    ) -> Vec<crate::model::Wire> {
        let mut by_partner: std::collections::HashMap<(&str, std::sync::Arc<str>), (usize, usize)> =
            std::collections::HashMap::new();
        for (ri, r) in resources.iter().enumerate() {
            for (si, sig) in r.signals.iter().enumerate() {
                if let Some(holder) = &sig.holder {
                    by_partner
                        .entry((holder.as_str(), sig.name.key.clone()))
                        .or_insert((ri, si));
                }
            }
        }
        if by_partner.is_empty() {
            return Vec::new();
        }
        let partner = |v: Option<&str>| {
            let (id, name) = v?.trim().split_once(':')?;
            let key: std::sync::Arc<str> = names::key(name).into();
            by_partner.get(&(id.trim(), key)).copied()
        };
        let mut wires = Vec::new();
        for link in h
            .descendants()
            .filter(|n| n.is_element() && n.tag_name().name() == "InternalLink")
        {
            let sides = [
                link.attribute("RefPartnerSideA"),
                link.attribute("RefPartnerSideB"),
            ];
            let (a, b) = match (partner(sides[0]), partner(sides[1])) {
                (Some(a), Some(b)) => (a, b),
                (None, None) => continue, // no wire between signals
                (found, _) => {
                    // One side is a signal, the other names none: said, not silently dropped.
                    let (side, missing) = if found.is_some() {
                        ("B", sides[1])
                    } else {
                        ("A", sides[0])
                    };
                    let missing = missing.unwrap_or("").trim();
                    let (id, wanted) = missing.split_once(':').unwrap_or((missing, ""));
                    // A link from a signal to an interface that is there but is no signal is
                    // not a wire, and not skillpost's (looked for only here: rare).
                    let exists = h
                        .descendants()
                        .find(|n| {
                            n.is_element() && n.attribute("ID").map(str::trim) == Some(id.trim())
                        })
                        .is_some_and(|holder| {
                            children(holder, "ExternalInterface")
                                .any(|i| caex_name(i).is_some_and(|n| names::eq(n, wanted)))
                        });
                    if exists {
                        continue;
                    }
                    let there: Vec<&str> = resources
                        .iter()
                        .flat_map(|r| &r.signals)
                        .filter(|s| s.holder.as_deref() == Some(id.trim()))
                        .map(|s| s.name.text.as_ref())
                        .collect();
                    let why = if missing.is_empty() {
                        format!("it has no RefPartnerSide{side}")
                    } else if there.is_empty() {
                        format!(
                            "side {side} names `{missing}`, but no element with the ID `{}` holds a signal",
                            id.trim()
                        )
                    } else {
                        format!(
                            "side {side} names `{missing}`, but the element with the ID `{}` has no signal `{}`{}",
                            id.trim(),
                            wanted.trim(),
                            names::did_you_mean(wanted.trim(), there.iter().copied())
                        )
                    };
                    let name = caex_name(link).unwrap_or("");
                    self.diags.push(
                        Diagnostic::warning(
                            Code::LinkPartnerMissing,
                            format!("InternalLink `{name}` is left out: {why}"),
                        )
                        .at(self.span(link))
                        .element(caex_element(link)),
                    );
                    continue;
                }
            };
            let controller = |(r, _): (usize, usize)| controllers.get(r).copied().unwrap_or(r);
            if controller(a) == controller(b) {
                continue;
            }
            let out = |(r, s): (usize, usize)| resources[r].signals[s].output;
            let name = caex_name(link).unwrap_or("").to_owned();
            let (from, to) = match (out(a), out(b)) {
                (true, false) => (a, b),
                (false, true) => (b, a),
                (both_out, _) => {
                    self.diags.push(
                        Diagnostic::error(
                            Code::BadSignal,
                            format!(
                                "InternalLink `{name}` joins two {} (`{}` and `{}`): a wire goes from an Output of one controller to an Input of another",
                                if both_out { "outputs" } else { "inputs" },
                                resources[a.0].signals[a.1].name.text,
                                resources[b.0].signals[b.1].name.text
                            ),
                        )
                        .at(self.span(link))
                        .element(caex_element(link)),
                    );
                    continue;
                }
            };
            wires.push(crate::model::Wire {
                from,
                to,
                name,
                span: self.span(link),
            });
        }
        wires
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

    fn resource(&mut self, r: Node) -> Resource {
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

    /// The resource's signals: `ExternalInterface`s directly under it or under its child named
    /// `Signals`/`Signale` whose `RefBaseClassPath` ends in `SignalInterface` or `Channel`.
    fn signals(&mut self, r: Node) -> (Vec<Signal>, Vec<std::sync::Arc<str>>) {
        let mut ifaces: Vec<Node> = children(r, "ExternalInterface").collect();
        if let Some(group) = internal_element(r, &["Signals", "Signale"]) {
            ifaces.extend(children(group, "ExternalInterface"));
        }
        let mut signals = Vec::new();
        let mut broken = Vec::new();
        for ei in ifaces {
            if !(ref_base_ends_with(ei, "SignalInterface") || ref_base_ends_with(ei, "Channel")) {
                continue;
            }
            match self.signal(ei) {
                Some(s) => signals.push(s),
                None => broken.push(self.name_of(ei).key),
            }
        }
        self.check_unique(
            signals.iter().map(|s| (&s.name, s.element.as_str())),
            "signal",
        );
        (signals, broken)
    }

    fn signal(&mut self, ei: Node) -> Option<Signal> {
        let name = self.name_of(ei);
        let element = caex_element(ei);
        let mut ok = true;
        let value = |attr: &str| {
            caex_attr(ei, attr)
                .and_then(|a| caex_value(self.file, a))
                .filter(|(v, _)| !v.is_empty())
        };
        let mut bad = |diags: &mut Diagnostics, span: Span, msg: String| {
            diags.push(
                Diagnostic::error(Code::BadSignal, format!("signal `{}`: {msg}", name.text))
                    .at(span)
                    .element(element.clone()),
            );
            ok = false;
        };
        let output = match value("IoType") {
            None => false,
            Some((v, span)) => match v.to_ascii_lowercase().as_str() {
                "input" | "in" => false,
                "output" | "out" => true,
                _ => {
                    bad(
                        self.diags,
                        span,
                        format!("IoType `{v}` is neither `Input` nor `Output`"),
                    );
                    false
                }
            },
        };
        let integer = match value("Type") {
            None => false,
            Some((v, span)) => match ValueType::parse(&v) {
                Some(ValueType::Boolean) => false,
                Some(ValueType::Integer) => true,
                _ => {
                    bad(
                        self.diags,
                        span,
                        format!(
                            "Type `{v}` is neither `xs:boolean` (one bit) nor `xs:integer` (a group of `Length` bits)"
                        ),
                    );
                    false
                }
            },
        };
        let kind = if let Some((text, span)) = value("Address") {
            if !is_safe_address(&text) {
                bad(
                    self.diags,
                    span,
                    format!(
                        "Address `{text}` is not one safe token: write a name, a system variable with an index or a call with one number (`PART_OK`, `$IN[5]`, `di_Part`, `read_input_integer_register(2)`)"
                    ),
                );
            }
            SignalKind::Address { text, integer }
        } else {
            let number = match value("Number") {
                None => {
                    bad(
                        self.diags,
                        self.span(ei),
                        "no `Number` (the first I/O index, from 1) and no `Address`".to_owned(),
                    );
                    1
                }
                Some((v, span)) => match v.parse::<u32>() {
                    Ok(n) if (1..=MAX_IO).contains(&n) => n,
                    // URScript counts its standard digital I/O from 0; KRL refuses 0 where a
                    // program would use it (`E209`).
                    Ok(0) if !integer => 0,
                    Ok(0) => {
                        bad(
                            self.diags,
                            span,
                            "Number 0 cannot start a group: KRL counts inputs and outputs from 1 ($IN[1])".to_owned(),
                        );
                        1
                    }
                    _ => {
                        bad(
                            self.diags,
                            span,
                            format!("Number `{v}` is not an I/O index from 1 to {MAX_IO}"),
                        );
                        1
                    }
                },
            };
            if integer {
                let length = match value("Length") {
                    None => {
                        bad(
                            self.diags,
                            self.span(ei),
                            "an xs:integer signal needs a `Length` (its number of bits, 2 to 32)"
                                .to_owned(),
                        );
                        2
                    }
                    Some((v, span)) => match v.parse::<u32>() {
                        Ok(l) if (2..=32).contains(&l) => {
                            if number.saturating_add(l - 1) > MAX_IO {
                                bad(
                                    self.diags,
                                    span,
                                    format!(
                                        "Length {l} from Number {number} passes the last I/O index {MAX_IO}"
                                    ),
                                );
                            }
                            l
                        }
                        _ => {
                            bad(
                                self.diags,
                                span,
                                format!("Length `{v}` is not a number of bits from 2 to 32"),
                            );
                            2
                        }
                    },
                };
                if !names::is_krl_name(&name.text)
                    || names::is_krl_keyword(&name.text)
                    || names::eq(&name.text, crate::lang::BRANCH_VAR)
                {
                    let span = name.span.clone();
                    bad(
                        self.diags,
                        span,
                        "an integer signal is declared as a KRL SIGNAL of this name: it must be a KRL name (a letter or `_`, then letters, digits or `_`, at most 24 characters, not a keyword nor `SKP_BRANCH`)".to_owned(),
                    );
                }
                SignalKind::Group { number, length }
            } else {
                SignalKind::Bit(number)
            }
        };
        ok.then_some(Signal {
            name,
            element,
            output,
            kind,
            holder: ei
                .parent_element()
                .and_then(|p| p.attribute("ID"))
                .map(|id| id.trim().to_owned()),
        })
    }

    fn skill(&mut self, sk: Node) -> Skill {
        let name = self.name_of(sk);
        let mut params = Vec::new();
        let mut defects = Vec::new();
        for a in children(sk, "Attribute") {
            self.param(a, None, &mut Vec::new(), None, &mut params, &mut defects);
        }
        let mut mappings = Vec::new();
        for ei in children(sk, "ExternalInterface") {
            let is_mapping = if ei.attribute("RefBaseClassPath").is_some() {
                ref_base_ends_with(ei, "SkillMapping") || ref_base_ends_with(ei, "FunctionMapping")
            } else {
                caex_name(ei).is_some_and(|n| names::eq(n, "FunctionMapping"))
            };
            if is_mapping && let Some(m) = self.mapping(ei, &params, &mut defects) {
                mappings.push(m);
            }
        }
        // Stable sort: equal orders keep document order.
        mappings.sort_by_key(|m| m.order);
        for w in mappings.windows(2) {
            if w[0].order == w[1].order {
                self.diags.push(
                    Diagnostic::warning(
                        Code::EqualOrder,
                        format!(
                            "skill `{}`: function mappings `{}` and `{}` have the same order {}; they run in document order",
                            name.text, w[0].function.text, w[1].function.text, w[0].order
                        ),
                    )
                    .at(w[1].span.clone())
                    .element(w[1].element.clone())
                    .related(w[0].span.clone(), "the other mapping"),
                );
            }
        }
        Skill {
            name,
            element: caex_element(sk),
            id: sk.attribute("ID").map(str::to_owned),
            params,
            mappings,
            defects,
        }
    }

    /// Reads one skill parameter and its nested ones.
    fn param(
        &mut self,
        a: Node,
        prefix: Option<&str>,
        indices: &mut Vec<usize>,
        variable: Option<&Name>,
        out: &mut Vec<Param>,
        defects: &mut Vec<Diagnostic>,
    ) {
        let own = caex_name(a).unwrap_or("").trim();
        let name_span = super::xml::attr_span(self.file, a, "Name");
        if prefix.map_or(0, |p| p.matches('.').count() + 1) >= super::xml::MAX_DEPTH {
            self.diags.push(
                Diagnostic::error(
                    Code::Unsupported,
                    format!(
                        "skill parameters nested deeper than {} levels are not supported",
                        super::xml::MAX_DEPTH
                    ),
                )
                .at(name_span)
                .element(caex_element(a)),
            );
            return;
        }
        if own.contains('.') {
            self.diags.push(
                Diagnostic::error(
                    Code::DotInAttributeName,
                    format!(
                        "attribute name `{own}` contains a `.`, which joins nested parameter names"
                    ),
                )
                .at(name_span.clone())
                .element(caex_element(a)),
            );
            return;
        }
        let path = match prefix {
            Some(p) => format!("{p}.{own}"),
            None => own.to_owned(),
        };
        let nested: Vec<Node> = children(a, "Attribute").collect();
        let leaf = nested.is_empty();
        let value = caex_value(self.file, a);
        let mut usable = true;
        let mut this_variable = variable.cloned();
        let mut pushed_index = false;
        match (prefix, value) {
            (None, Some((v, span))) if !v.is_empty() => {
                this_variable = Some(Name::new(&v, span));
            }
            (Some(_), Some((v, span))) if !v.is_empty() => match v.parse::<usize>() {
                Ok(i) => {
                    indices.push(i);
                    pushed_index = true;
                }
                Err(_) => {
                    usable = false;
                    defects.push(
                        Diagnostic::error(
                            Code::ParameterWithoutValue,
                            format!(
                                "parameter `{path}`: its value `{v}` is not a 0-based index into the variable's list"
                            ),
                        )
                        .at(span)
                        .element(caex_element(a)),
                    );
                }
            },
            _ => {
                usable = false;
                defects.push(
                    Diagnostic::error(
                        Code::ParameterWithoutValue,
                        format!(
                            "parameter `{path}` has no value: {}",
                            if prefix.is_none() {
                                "it must name the SFC variable"
                            } else {
                                "it must be the index into the variable's list"
                            }
                        ),
                    )
                    .at(name_span.clone())
                    .element(caex_element(a)),
                );
            }
        }
        let ty = if leaf {
            a.attribute("AttributeDataType")
                .filter(|t| !t.trim().is_empty())
                .and_then(|t| {
                    let parsed = ValueType::parse(t);
                    if parsed.is_none() {
                        self.diags.push(
                            Diagnostic::warning(
                                Code::UnknownType,
                                format!(
                                    "parameter `{path}`: unknown AttributeDataType `{t}`; its values are treated as untyped"
                                ),
                            )
                            .at(super::xml::attr_span(self.file, a, "AttributeDataType"))
                            .element(caex_element(a)),
                        );
                    }
                    parsed
                })
        } else {
            None
        };
        let constraints = if leaf {
            self.constraints(a, &path)
        } else {
            Vec::new()
        };
        out.push(Param {
            path: Name::new(&path, name_span),
            variable: if usable { this_variable.clone() } else { None },
            indices: indices.clone(),
            ty,
            leaf,
            constraints,
        });
        for n in nested {
            self.param(
                n,
                Some(&path),
                indices,
                this_variable.as_ref(),
                out,
                defects,
            );
        }
        if pushed_index {
            indices.pop();
        }
    }

    /// The `Constraint`s of the parameter attribute `a` (`path`, for messages). One that cannot
    /// be checked (a bound that is not a number, nothing in it) is a warning, and left out.
    fn constraints(&mut self, a: Node, path: &str) -> Vec<crate::model::Constraint> {
        let text = |n: Node| -> String {
            n.children()
                .filter(|c| c.is_text())
                .filter_map(|c| c.text())
                .collect::<String>()
                .trim()
                .to_owned()
        };
        let mut out = Vec::new();
        for c in children(a, "Constraint") {
            let name = caex_name(c).unwrap_or("").trim().to_owned();
            let span = super::xml::tag_span(self.file, c);
            let mut k = crate::model::Constraint {
                name: name.clone(),
                span: span.clone(),
                min: None,
                max: None,
                one_of: Vec::new(),
            };
            let mut unusable = None;
            for scale in c.children().filter(|n| n.is_element()) {
                for v in scale.children().filter(|n| n.is_element()) {
                    let value = text(v);
                    match v.tag_name().name() {
                        bound @ ("RequiredMinValue" | "RequiredMaxValue") => {
                            match value.parse::<f64>().ok().filter(|x| x.is_finite()) {
                                Some(x) if bound == "RequiredMinValue" => k.min = Some((x, value)),
                                Some(x) => k.max = Some((x, value)),
                                None => {
                                    unusable =
                                        Some(format!("its {bound} `{value}` is not a number"))
                                }
                            }
                        }
                        "RequiredValue" if !value.is_empty() => k.one_of.push(value),
                        _ => {}
                    }
                }
            }
            if unusable.is_none() && k.min.is_none() && k.max.is_none() && k.one_of.is_empty() {
                unusable = Some(
                    "it names no value (no RequiredMinValue, RequiredMaxValue or RequiredValue)"
                        .to_owned(),
                );
            }
            if let (Some((lo, l)), Some((hi, h))) = (&k.min, &k.max)
                && lo > hi
            {
                unusable = Some(format!(
                    "its RequiredMinValue {l} is above its RequiredMaxValue {h}"
                ));
            }
            match unusable {
                Some(why) => self.diags.push(
                    Diagnostic::warning(
                        Code::UnusableConstraint,
                        format!("parameter `{path}`: constraint `{name}` is not checked: {why}"),
                    )
                    .at(span)
                    .element(caex_element(a)),
                ),
                None => out.push(k),
            }
        }
        out
    }

    fn mapping(
        &mut self,
        ei: Node,
        params: &[Param],
        defects: &mut Vec<Diagnostic>,
    ) -> Option<FunctionMapping> {
        let span = self.span(ei);
        let elem = caex_element(ei);
        let function = match caex_attr(ei, "Name").and_then(|a| caex_value(self.file, a)) {
            Some((v, s)) if !v.is_empty() => Name::new(&v, s),
            _ => {
                defects.push(
                    Diagnostic::error(
                        Code::BadFunctionMapping,
                        "function mapping without `Name` value (the function to call)",
                    )
                    .at(span)
                    .element(elem),
                );
                return None;
            }
        };
        let order_attr = caex_attr(ei, "Order").or_else(|| caex_attr(ei, "Index"));
        let order = match order_attr.and_then(|a| caex_value(self.file, a)) {
            None => 0,
            Some((v, _)) if v.is_empty() => 0,
            Some((v, s)) => match v.parse::<i64>() {
                Ok(o) => o,
                Err(_) => {
                    defects.push(
                        Diagnostic::error(
                            Code::BadFunctionMapping,
                            format!(
                                "function mapping `{}`: order `{v}` is not an integer",
                                function.text
                            ),
                        )
                        .at(s)
                        .element(elem.clone()),
                    );
                    0
                }
            },
        };
        let mut args = Vec::new();
        if let Some(m) = caex_attr(ei, "Mapping") {
            let mut stack: Vec<(Node, String)> = children(m, "Attribute")
                .map(|a| (a, caex_name(a).unwrap_or("").trim().to_owned()))
                .collect();
            stack.reverse();
            while let Some((a, path)) = stack.pop() {
                let nested: Vec<Node> = children(a, "Attribute").collect();
                let name_span = super::xml::attr_span(self.file, a, "Name");
                if let Some((v, vspan)) = caex_value(self.file, a).filter(|(v, _)| !v.is_empty()) {
                    let skill_param = Name::new(&path, name_span.clone());
                    if !params.iter().any(|p| p.path.key == skill_param.key) {
                        defects.push(
                            Diagnostic::error(
                                Code::BadFunctionMapping,
                                format!(
                                    "function mapping `{}`: `{path}` is not a parameter of the skill",
                                    function.text
                                ),
                            )
                            .at(name_span.clone())
                            .element(elem.clone()),
                        );
                    } else {
                        args.push(MappedArg {
                            skill_param,
                            function_param: Name::new(&v, vspan),
                        });
                    }
                } else if nested.is_empty() {
                    defects.push(
                        Diagnostic::error(
                            Code::BadFunctionMapping,
                            format!(
                                "function mapping `{}`: `{path}` names no function parameter (no `Value`)",
                                function.text
                            ),
                        )
                        .at(name_span)
                        .element(elem.clone()),
                    );
                }
                for n in nested.into_iter().rev() {
                    let own = caex_name(n).unwrap_or("").trim();
                    stack.push((n, format!("{path}.{own}")));
                }
            }
        }
        Some(FunctionMapping {
            function,
            element: elem,
            order,
            args,
            span,
        })
    }

    fn function(&mut self, f: Node) -> Option<Function> {
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

    fn sfc_reference(&mut self, h: Node) -> Option<RefValue> {
        let Some(ps) = internal_element(h, &["Process Sequenz", "Process Sequence"]) else {
            self.diags.push(
                Diagnostic::error(
                    Code::NoSfcReference,
                    "the blackboard has no `Process Sequence` (or `Process Sequenz`) element naming the SFC file",
                )
                .at(self.span(h))
                .element(caex_element(h)),
            );
            return None;
        };
        let iface = children(ps, "ExternalInterface")
            .find(|ei| caex_name(*ei).is_some_and(|n| names::eq(n, "SFC Benutzereingabe")))
            .or_else(|| {
                children(ps, "ExternalInterface")
                    .find(|ei| ref_base_contains(*ei, "ExternalDataConnector"))
            });
        let Some(iface) = iface else {
            self.diags.push(
                Diagnostic::error(
                    Code::NoSfcReference,
                    "`Process Sequence` has no `SFC Benutzereingabe` (or ExternalDataConnector) interface",
                )
                .at(self.span(ps))
                .element(caex_element(ps)),
            );
            return None;
        };
        match caex_attr(iface, "refURI").and_then(|a| caex_value(self.file, a)) {
            Some((v, span)) if !v.is_empty() => Some(RefValue { value: v, span }),
            _ => {
                self.diags.push(
                    Diagnostic::error(
                        Code::NoSfcReference,
                        "the SFC interface has no `refURI` value naming the SFC file",
                    )
                    .at(self.span(iface))
                    .element(caex_element(iface)),
                );
                None
            }
        }
    }

    /// Every `ExternalInterface` of `Code` with a `refURI` attribute, by its `Name`.
    fn code_targets(&mut self, h: Node) -> Vec<(String, WriteBackTarget)> {
        let Some(code) = internal_element(h, &["Code"]) else {
            return Vec::new();
        };
        children(code, "ExternalInterface")
            .filter_map(|ei| {
                let name = caex_name(ei)?.to_owned();
                let a = caex_attr(ei, "refURI")?;
                let site = crate::model::SpliceSite::of(a)?;
                Some((
                    name,
                    WriteBackTarget {
                        attribute: Span::new(self.file, a.range()),
                        current: caex_value(self.file, a).map(|(v, _)| v),
                        site,
                    },
                ))
            })
            .collect()
    }

    fn write_back(&mut self, h: Node) -> Option<WriteBackTarget> {
        let code = internal_element(h, &["Code"]);
        let iface = code.and_then(|c| {
            children(c, "ExternalInterface")
                .find(|ei| caex_name(*ei).is_some_and(|n| names::eq(n, "KRL code")))
                .or_else(|| {
                    children(c, "ExternalInterface")
                        .find(|ei| ref_base_contains(*ei, "ExternalDataConnector"))
                })
        });
        let attr = iface.and_then(|i| caex_attr(i, "refURI"));
        match attr.and_then(|a| Some((a, crate::model::SpliceSite::of(a)?))) {
            Some((a, site)) => Some(WriteBackTarget {
                attribute: Span::new(self.file, a.range()),
                current: caex_value(self.file, a).map(|(v, _)| v),
                site,
            }),
            None => {
                let at = iface.or(code).unwrap_or(h);
                self.diags.push(
                    Diagnostic::warning(
                        Code::NoWriteBackTarget,
                        "no write-back target (`Code` → `KRL code` → `refURI`): the program's path is not written into the blackboard",
                    )
                    .at(self.span(at)),
                );
                None
            }
        }
    }
}

#[cfg(test)]
mod signal_tests {
    use super::is_safe_address;

    #[test]
    fn addresses_are_one_safe_token() {
        for ok in ["PART_OK", "$IN[5]", "$CYCFLAG[3]", "$X[1,2]", "_a1"] {
            assert!(is_safe_address(ok), "{ok}");
        }
        for bad in [
            "$IN[5]; $OUT[1]=TRUE",
            "$IN[ 5]",
            "$IN[]",
            "$IN[5",
            "a b",
            "1X",
            "$",
            "END",
            "$IN[1][2]",
            "$IN[-1]",
            "",
            "Grüße",
        ] {
            assert!(!is_safe_address(bad), "{bad}");
        }
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
