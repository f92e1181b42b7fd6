//! The SFC (PLCopen TC6 XML 2.01, 2.00 or 1.0; namespaces ignored): the program's elements,
//! their connections, and the skill steps' data (SPEC.md section 3).
//!
//! The reader only extracts; the graph rules are checked by [`crate::plan`].

use roxmltree::Node;

use super::xml::{attr_span, child, children, tag_span};
use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::model::{Element, ElementKind, FileHeader, Name, Sfc, Step, Value, Variable};

/// Lists nest at most this deep in a variable's value.
pub const MAX_LIST_DEPTH: usize = 32;

/// Reads the SFC file. `None` when there is no usable program body.
pub fn read_sfc(sources: &Sources, file: FileId, diags: &mut Diagnostics) -> Option<Sfc> {
    let doc = super::xml::parse(sources, file, diags)?;
    let root = doc.root_element();
    if root.tag_name().name() != "project" {
        diags.push(
            Diagnostic::error(
                Code::XmlWrongRoot,
                format!(
                    "not a PLCopen XML file: the root element is `{}`, not `project`",
                    root.tag_name().name()
                ),
            )
            .at(tag_span(file, root)),
        );
        return None;
    }
    let header = child(root, "fileHeader")
        .map(|h| FileHeader {
            company_name: h.attribute("companyName").map(str::to_owned),
            product_name: h.attribute("productName").map(str::to_owned),
            product_version: h.attribute("productVersion").map(str::to_owned),
            creation_date_time: h.attribute("creationDateTime").map(str::to_owned),
        })
        .unwrap_or_default();

    let pous: Vec<Node> = child(root, "types")
        .and_then(|t| child(t, "pous"))
        .map(|p| children(p, "pou").collect())
        .unwrap_or_default();
    let pou = pous
        .iter()
        .copied()
        .find(|p| p.attribute("pouType") == Some("program"))
        .or_else(|| pous.first().copied());
    let sfc = pou
        .and_then(|p| child(p, "body"))
        .and_then(|b| child(b, "SFC"));
    let Some(sfc) = sfc else {
        let at = pou.unwrap_or(root);
        diags.push(
            Diagnostic::error(
                Code::NoSfcBody,
                match pou {
                    None => "the SFC file has no `pou` (types/pous/pou)".to_owned(),
                    Some(p) => format!(
                        "pou `{}` has no SFC body (body/SFC)",
                        p.attribute("name").unwrap_or("")
                    ),
                },
            )
            .at(tag_span(file, at)),
        );
        return None;
    };

    let mut elements = Vec::new();
    for e in sfc.children().filter(|c| c.is_element()) {
        if let Some(el) = element(file, e, diags) {
            elements.push(el);
        }
    }
    Some(Sfc {
        file,
        header,
        pou_name: pou.and_then(|p| p.attribute("name")).map(str::to_owned),
        elements,
        span: Some(tag_span(file, sfc)),
    })
}

fn element(file: FileId, e: Node, diags: &mut Diagnostics) -> Option<Element> {
    let tag = e.tag_name().name();
    let kind = match tag {
        "step" => ElementKind::Step(Box::new(step(file, e, diags))),
        "transition" => {
            condition(file, e, diags);
            ElementKind::Transition
        }
        "simultaneousDivergence" => ElementKind::SimultaneousDivergence,
        "simultaneousConvergence" => ElementKind::SimultaneousConvergence,
        "selectionDivergence" => ElementKind::SelectionDivergence,
        "selectionConvergence" => ElementKind::SelectionConvergence,
        "jumpStep" => ElementKind::JumpStep,
        "macroStep" => ElementKind::MacroStep,
        _ => {
            let what = if tag == "actionBlock" {
                "action block".to_owned()
            } else {
                format!("`{tag}` element")
            };
            diags.push(
                Diagnostic::warning(Code::Ignored, format!("{what} ignored"))
                    .at(tag_span(file, e))
                    .element(local_id_label(e)),
            );
            return None;
        }
    };
    let local_id = match e.attribute("localId").map(|v| v.trim().parse::<u64>()) {
        Some(Ok(id)) => id,
        Some(Err(_)) => {
            diags.push(
                Diagnostic::error(
                    Code::BadLocalId,
                    format!(
                        "`{tag}` has localId `{}`, which is not a number from 0 to {}",
                        e.attribute("localId").unwrap_or(""),
                        u64::MAX
                    ),
                )
                .at(attr_span(file, e, "localId")),
            );
            return None;
        }
        None => {
            diags.push(
                Diagnostic::error(Code::BadLocalId, format!("`{tag}` without localId"))
                    .at(tag_span(file, e)),
            );
            return None;
        }
    };
    let x = child(e, "position")
        .and_then(|p| p.attribute("x"))
        .and_then(|x| x.trim().parse::<f64>().ok())
        .filter(|x| x.is_finite())
        .unwrap_or(0.0);
    let mut inputs = Vec::new();
    for cpi in children(e, "connectionPointIn") {
        for c in children(cpi, "connection") {
            match c.attribute_node("refLocalId") {
                Some(a) => match a.value().trim().parse::<u64>() {
                    Ok(r) => inputs.push((r, a.range_value())),
                    Err(_) => diags.push(
                        Diagnostic::error(
                            Code::DanglingReference,
                            format!("refLocalId `{}` is not a number", a.value()),
                        )
                        .at(Span::new(file, a.range_value()))
                        .element(format!("localId {local_id}")),
                    ),
                },
                None => diags.push(
                    Diagnostic::error(Code::DanglingReference, "connection without refLocalId")
                        .at(tag_span(file, c))
                        .element(format!("localId {local_id}")),
                ),
            }
        }
    }
    Some(Element {
        local_id,
        kind,
        span: tag_span(file, e),
        x,
        inputs,
    })
}

fn local_id_label(e: Node) -> String {
    format!("localId {}", e.attribute("localId").unwrap_or("?"))
}

fn condition(file: FileId, t: Node, diags: &mut Diagnostics) {
    let Some(c) = child(t, "condition") else {
        return;
    };
    let text = child(c, "inline").map(|i| {
        i.descendants()
            .filter(|n| n.is_text())
            .filter_map(|n| n.text())
            .collect::<String>()
    });
    let is_true = text
        .as_deref()
        .is_some_and(|s| s.trim().eq_ignore_ascii_case("TRUE"));
    if !is_true {
        let what = match text {
            Some(s) => format!("condition `{}`", s.trim()),
            None => "a condition that is not an inline `TRUE`".to_owned(),
        };
        diags.push(
            Diagnostic::warning(
                Code::Ignored,
                format!("transition with {what} ignored: transitions always fire"),
            )
            .at(tag_span(file, c))
            .element(local_id_label(t)),
        );
    }
}

fn step(file: FileId, s: Node, diags: &mut Diagnostics) -> Step {
    let iwb = children(s, "addData")
        .flat_map(|a| children(a, "data"))
        .find_map(|d| child(d, "iwb"));
    let named = |n: Option<Node>| -> Option<Name> {
        let n = n?;
        let v = n.attribute("name")?;
        Some(Name::new(v, attr_span(file, n, "name")))
    };
    let mut resource = None;
    let mut skill = None;
    let mut duration = None;
    if let Some(iwb) = iwb {
        resource = named(
            child(iwb, "ressources")
                .and_then(|r| child(r, "ressource"))
                .or_else(|| child(iwb, "resources").and_then(|r| child(r, "resource"))),
        )
        .filter(|n| !n.key.is_empty());
        skill = named(child(iwb, "skill")).filter(|n| !n.key.is_empty());
        duration = child(iwb, "time")
            .and_then(|t| t.attribute("duration"))
            .and_then(|d| d.trim().parse::<f64>().ok())
            .filter(|d| d.is_finite() && *d >= 0.0);
    }
    let mut variables = Vec::new();
    let mut invalid_variables = Vec::new();
    let direct = children(s, "Variable");
    let nested = iwb.into_iter().flat_map(|i| children(i, "Variable"));
    for v in direct.chain(nested) {
        let Some(name) = v.attribute("name") else {
            diags.push(
                Diagnostic::error(Code::BadVariableSyntax, "Variable without `name`")
                    .at(tag_span(file, v))
                    .element(local_id_label(s)),
            );
            continue;
        };
        let Some(attr) = v.attribute_node("Value") else {
            diags.push(
                Diagnostic::error(
                    Code::BadVariableSyntax,
                    format!("Variable `{name}` without `Value`"),
                )
                .at(tag_span(file, v))
                .element(local_id_label(s)),
            );
            invalid_variables.push(crate::names::key(name));
            continue;
        };
        let value_span = Span::new(file, attr.range_value());
        match parse_value(attr.value()) {
            Ok(value) => variables.push(Variable {
                name: Name::new(name, attr_span(file, v, "name")),
                value,
                value_span,
            }),
            Err((offset, msg)) => {
                invalid_variables.push(crate::names::key(name));
                // Point into the raw value when it has no entity references (then offsets agree).
                let raw_len = value_span.range.len();
                let at = if raw_len == attr.value().len() {
                    value_span.range.start + offset.min(raw_len)
                } else {
                    value_span.range.start
                };
                diags.push(
                    Diagnostic::error(Code::BadVariableSyntax, format!("variable `{name}`: {msg}"))
                        .at(Span::new(
                            file,
                            at..(at + 1).min(value_span.range.end.max(at)),
                        ))
                        .element(local_id_label(s)),
                );
            }
        }
    }
    Step {
        name: s.attribute("name").unwrap_or("").to_owned(),
        initial: s
            .attribute("initialStep")
            .is_some_and(|v| v.trim() == "true" || v.trim() == "1"),
        resource,
        skill,
        duration,
        variables,
        invalid_variables,
    }
}

/// Parses a variable's value: `(a, b, (c, d))` is a (nested) list of trimmed items, `()` is
/// empty, anything else is one trimmed value. Commas inside `"..."` do not split. Errors carry
/// the byte offset in `text`.
pub fn parse_value(text: &str) -> Result<Value, (usize, String)> {
    let lead = text.len() - text.trim_start().len();
    let t = text.trim();
    if !t.starts_with('(') {
        return Ok(Value::Scalar(t.to_owned()));
    }
    let mut p = ListParser {
        s: t.as_bytes(),
        text: t,
        i: 0,
        base: lead,
    };
    let v = p.list(0)?;
    p.skip_ws();
    if p.i < p.s.len() {
        return Err((lead + p.i, "text after the closing `)`".to_owned()));
    }
    Ok(v)
}

struct ListParser<'a> {
    s: &'a [u8],
    text: &'a str,
    i: usize,
    base: usize,
}

impl ListParser<'_> {
    fn skip_ws(&mut self) {
        while self.i < self.s.len() && self.s[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
    }

    fn err(&self, msg: &str) -> (usize, String) {
        (self.base + self.i, msg.to_owned())
    }

    /// At `(`: parses to the matching `)`.
    fn list(&mut self, depth: usize) -> Result<Value, (usize, String)> {
        if depth >= MAX_LIST_DEPTH {
            return Err(self.err(&format!("lists nested deeper than {MAX_LIST_DEPTH} levels")));
        }
        let open = self.i;
        self.i += 1; // '('
        let mut items = Vec::new();
        self.skip_ws();
        if self.s.get(self.i) == Some(&b')') {
            self.i += 1;
            return Ok(Value::List(items));
        }
        loop {
            self.skip_ws();
            match self.s.get(self.i) {
                Some(b'(') => {
                    items.push(self.list(depth + 1)?);
                    self.skip_ws();
                }
                Some(b',') | Some(b')') => return Err(self.err("empty list item")),
                None => {
                    self.i = open;
                    return Err(self.err("`(` without its `)`"));
                }
                Some(_) => {
                    let start = self.i;
                    let mut in_str = false;
                    while let Some(&c) = self.s.get(self.i) {
                        match c {
                            b'"' => in_str = !in_str,
                            b',' | b')' if !in_str => break,
                            b'(' if !in_str => {
                                return Err(self.err("`(` inside a list item"));
                            }
                            _ => {}
                        }
                        self.i += 1;
                    }
                    items.push(Value::Scalar(self.text[start..self.i].trim().to_owned()));
                }
            }
            match self.s.get(self.i) {
                Some(b',') => self.i += 1,
                Some(b')') => {
                    self.i += 1;
                    return Ok(Value::List(items));
                }
                None => {
                    self.i = open;
                    return Err(self.err("`(` without its `)`"));
                }
                Some(_) => return Err(self.err("expected `,` or `)`")),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: &str) -> Value {
        Value::Scalar(v.to_owned())
    }

    #[test]
    fn values() {
        assert_eq!(parse_value(" 0.5 ").unwrap(), s("0.5"));
        assert_eq!(
            parse_value("(100, 200 , 300)").unwrap(),
            Value::List(vec![s("100"), s("200"), s("300")])
        );
        assert_eq!(parse_value("()").unwrap(), Value::List(vec![]));
        assert_eq!(
            parse_value("(1, (2, 3), ())").unwrap(),
            Value::List(vec![
                s("1"),
                Value::List(vec![s("2"), s("3")]),
                Value::List(vec![])
            ])
        );
        assert_eq!(
            parse_value("(\"a,b\", c)").unwrap(),
            Value::List(vec![s("\"a,b\""), s("c")])
        );
        assert_eq!(parse_value("abc def").unwrap(), s("abc def"));
    }

    #[test]
    fn value_errors_have_offsets() {
        assert_eq!(parse_value("(1, 2").unwrap_err().0, 0);
        assert_eq!(parse_value("  (1, 2").unwrap_err().0, 2);
        assert_eq!(parse_value("(1,,2)").unwrap_err().0, 3);
        assert_eq!(parse_value("(1) x").unwrap_err().0, 4);
        assert!(parse_value(&"(".repeat(100)).is_err());
    }
}
