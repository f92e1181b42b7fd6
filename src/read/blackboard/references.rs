//! The hierarchy's references: the SFC file (`Process Sequence`) and the write-back targets
//! under `Code`.

use roxmltree::Node;

use super::super::xml::{caex_attr, caex_element, caex_name, caex_value, children};
use super::{Reader, internal_element, ref_base_contains};
use crate::diag::{Code, Diagnostic, Span};
use crate::model::{RefValue, WriteBackTarget};
use crate::names;

impl Reader<'_> {
    pub(super) fn sfc_reference(&mut self, h: Node) -> Option<RefValue> {
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
    pub(super) fn code_targets(&mut self, h: Node) -> Vec<(String, WriteBackTarget)> {
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

    pub(super) fn write_back(&mut self, h: Node) -> Option<WriteBackTarget> {
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
