//! The skills under a resource's `Skills`: their parameters (nested, with their constraints) and
//! their function mappings.

use roxmltree::Node;

use super::super::xml::{caex_attr, caex_element, caex_name, caex_value, children};
use super::{Reader, ref_base_ends_with};
use crate::diag::{Code, Diagnostic};
use crate::model::{FunctionMapping, MappedArg, Name, Param, Skill, ValueType};
use crate::names;

impl Reader<'_> {
    pub(super) fn skill(&mut self, sk: Node) -> Skill {
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
}
