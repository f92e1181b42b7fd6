//! The SFC (PLCopen TC6 XML 2.01, 2.00 or 1.0; namespaces ignored): the program's elements,
//! their connections, and the skill steps' data (SPEC.md section 3).
//!
//! The reader only extracts; the graph rules are checked by [`crate::plan`].

use roxmltree::Node;

use super::xml::{attr_span, child, children, tag_span};
use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::model::{Element, ElementKind, FileHeader, Interner, Sfc, Step, Value, Variable};

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
    let mut names = Interner::default();
    for e in sfc.children().filter(|c| c.is_element()) {
        if let Some(el) = element(file, e, &mut names, diags) {
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

fn element(
    file: FileId,
    e: Node,
    names: &mut Interner,
    diags: &mut Diagnostics,
) -> Option<Element> {
    let tag = e.tag_name().name();
    let kind = match tag {
        "step" => ElementKind::Step(Box::new(step(file, e, names, diags))),
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

fn step(file: FileId, s: Node, names: &mut Interner, diags: &mut Diagnostics) -> Step {
    let mut iwb = None;
    let mut variables = Vec::new();
    let mut invalid_variables = Vec::new();
    let mut var_nodes: Vec<Node> = Vec::new();
    for c in s.children().filter(|c| c.is_element()) {
        match c.tag_name().name() {
            "addData" if iwb.is_none() => {
                iwb = children(c, "data").find_map(|d| child(d, "iwb"));
            }
            "Variable" => var_nodes.push(c),
            _ => {}
        }
    }
    let mut resource = None;
    let mut skill = None;
    let mut duration = None;
    if let Some(iwb) = iwb {
        for c in iwb.children().filter(|c| c.is_element()) {
            match c.tag_name().name() {
                "ressources" | "resources" if resource.is_none() => {
                    resource = c
                        .children()
                        .find(|r| {
                            r.is_element()
                                && matches!(r.tag_name().name(), "ressource" | "resource")
                        })
                        .and_then(|r| {
                            let v = r.attribute("name")?;
                            Some(names.name(v, attr_span(file, r, "name")))
                        })
                        .filter(|n| !n.key.is_empty());
                }
                "skill" if skill.is_none() => {
                    skill = c
                        .attribute("name")
                        .map(|v| names.name(v, attr_span(file, c, "name")))
                        .filter(|n| !n.key.is_empty());
                }
                "time" if duration.is_none() => {
                    duration = c
                        .attribute("duration")
                        .and_then(|d| d.trim().parse::<f64>().ok())
                        .filter(|d| d.is_finite() && *d >= 0.0);
                }
                "Variable" => var_nodes.push(c),
                _ => {}
            }
        }
    }
    for v in var_nodes {
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
            invalid_variables.push(names.strings(name).1);
            continue;
        };
        let value_span = Span::new(file, attr.range_value());
        match check_value(attr.value()) {
            Ok(()) => variables.push(Variable {
                name: names.name(name, attr_span(file, v, "name")),
                raw: attr.value().trim().to_owned(),
                value_span,
            }),
            Err((offset, msg)) => {
                invalid_variables.push(names.strings(name).1);
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
        name: names.strings(s.attribute("name").unwrap_or("")).0,
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

/// What a list lookup found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lookup<'a> {
    /// One value.
    Scalar(&'a str),
    /// A list (where one value was looked for).
    List,
    /// The index at `depth` is past the end of a list of `len` items.
    OutOfRange { depth: usize, len: usize },
    /// The index at `depth` was applied to one value, not a list.
    NotAList { depth: usize },
}

/// Looks up `indices` in a value whose syntax [`check_value`] accepted, without allocating.
pub fn lookup<'a>(raw: &'a str, indices: &[usize]) -> Lookup<'a> {
    let mut cur = raw.trim();
    for (depth, &ix) in indices.iter().enumerate() {
        if !cur.starts_with('(') {
            return Lookup::NotAList { depth };
        }
        match items(cur).nth(ix) {
            Some(item) => cur = item,
            None => {
                return Lookup::OutOfRange {
                    depth,
                    len: items(cur).count(),
                };
            }
        }
    }
    if cur.starts_with('(') {
        Lookup::List
    } else {
        Lookup::Scalar(cur)
    }
}

/// The trimmed items of a well-formed list `( … )`.
fn items(list: &str) -> impl Iterator<Item = &str> {
    let inner = list
        .strip_prefix('(')
        .and_then(|l| l.strip_suffix(')'))
        .unwrap_or("");
    let empty = inner.trim().is_empty();
    let b = inner.as_bytes();
    let mut start = 0;
    let mut i = 0;
    let mut done = empty;
    std::iter::from_fn(move || {
        if done {
            return None;
        }
        let (mut depth, mut in_str) = (0usize, false);
        while i < b.len() {
            match b[i] {
                b'"' => in_str = !in_str,
                b'(' if !in_str => depth += 1,
                b')' if !in_str => depth = depth.saturating_sub(1),
                b',' if !in_str && depth == 0 => break,
                _ => {}
            }
            i += 1;
        }
        let item = inner[start..i].trim();
        if i >= b.len() {
            done = true;
        } else {
            i += 1;
            start = i;
        }
        Some(item)
    })
}

/// Checks a value's syntax (the rules of [`parse_value`]) without building it.
pub fn check_value(text: &str) -> Result<(), (usize, String)> {
    parse(text, false).map(|_| ())
}

/// Parses a variable's value: `(a, b, (c, d))` is a (nested) list of trimmed items, `()` is
/// empty, anything else is one trimmed value. Commas inside `"..."` do not split. Errors carry
/// the byte offset in `text`.
pub fn parse_value(text: &str) -> Result<Value, (usize, String)> {
    parse(text, true)
}

fn parse(text: &str, build: bool) -> Result<Value, (usize, String)> {
    let lead = text.len() - text.trim_start().len();
    let t = text.trim();
    if !t.starts_with('(') {
        return Ok(Value::Scalar(if build {
            t.to_owned()
        } else {
            String::new()
        }));
    }
    let mut p = ListParser {
        s: t.as_bytes(),
        text: t,
        i: 0,
        base: lead,
        build,
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
    /// Build the value (else only check the syntax, allocating nothing).
    build: bool,
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
                    let v = self.list(depth + 1)?;
                    if self.build {
                        items.push(v);
                    }
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
                    if self.build {
                        items.push(Value::Scalar(self.text[start..self.i].trim().to_owned()));
                    }
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
    fn lookups() {
        let v = "( 100, (1, \"a,b\"), (), 7 )";
        assert!(check_value(v).is_ok());
        assert_eq!(lookup(v, &[0]), Lookup::Scalar("100"));
        assert_eq!(lookup(v, &[1, 1]), Lookup::Scalar("\"a,b\""));
        assert_eq!(lookup(v, &[1]), Lookup::List);
        assert_eq!(lookup(v, &[3]), Lookup::Scalar("7"));
        assert_eq!(lookup(v, &[4]), Lookup::OutOfRange { depth: 0, len: 4 });
        assert_eq!(lookup(v, &[2, 0]), Lookup::OutOfRange { depth: 1, len: 0 });
        assert_eq!(lookup(v, &[0, 0]), Lookup::NotAList { depth: 1 });
        assert_eq!(lookup("0.5", &[]), Lookup::Scalar("0.5"));
        assert_eq!(lookup("0.5", &[0]), Lookup::NotAList { depth: 0 });
        assert_eq!(lookup("()", &[]), Lookup::List);
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
