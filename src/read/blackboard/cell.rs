//! The cell (docs/CELLS.md): which resource's controller runs each resource, and the wires
//! (`InternalLink`s) between controllers.

use roxmltree::Node;

use super::super::xml::{caex_element, caex_name, children};
use super::Reader;
use crate::diag::{Code, Diagnostic};
use crate::model::Resource;
use crate::names;

impl Reader<'_> {
    /// Which resource's controller runs each resource (docs/CELLS.md): its `Controller` attribute
    /// when that names another resource, else the nearest enclosing resource's, else itself;
    /// followed along the chain. A chain that comes back to where it started is `E211` at the
    /// attribute that closes it (that resource is then its own controller); a device whose
    /// `Language` differs from its controller's is `E319` at the device's attribute.
    pub(super) fn controllers(&mut self, resources: &[Resource]) -> Vec<usize> {
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
    pub(super) fn wires(
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
}
