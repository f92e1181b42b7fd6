//! The SFC (PLCopen TC6 XML 2.01, 2.00 or 1.0; namespaces ignored): the program's elements,
//! their connections, and the skill steps' data (SPEC.md section 3).
//!
//! The SFC is the one input that grows with the product (100,000 steps make 78 MB), so it is read
//! in one streaming pass (`quick-xml`), without building a document tree: the model is all that
//! is kept. Byte positions are taken from the reader and from the attribute slices, which point
//! into the text. The graph rules are checked by [`crate::plan`].

use std::ops::Range;

use quick_xml::events::{BytesStart, Event};

use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::model::{
    Condition, Element, ElementKind, FileHeader, Interner, Name, Sfc, Step, Variable,
};

pub use crate::value::MAX_LIST_DEPTH;

/// Reads the SFC file. `None` when the file is not well-formed or has no usable program body.
pub fn read_sfc(sources: &Sources, file: FileId, diags: &mut Diagnostics) -> Option<Sfc> {
    read_sfc_pou(sources, file, None, diags)
}

/// Reads the SFC file's POU named `pou` (`--pou`, or the reference's `#fragment`); without a
/// name, the first program with an SFC body, else the first POU with one (SPEC.md 3). When
/// several POUs have an SFC body and none was named, a warning names the one used and the
/// others.
pub fn read_sfc_pou(
    sources: &Sources,
    file: FileId,
    pou: Option<&str>,
    diags: &mut Diagnostics,
) -> Option<Sfc> {
    let text = sources.get(file).text.as_str();
    let mut r = Stream {
        wanted: pou.map(|p| p.trim().to_owned()).filter(|p| !p.is_empty()),
        pous: Vec::new(),
        text,
        file,
        names: Interner::default(),
        found: Vec::new(),
        ignored: Vec::new(),
    };
    let before = diags.error_count();
    let mut local = Diagnostics::default();
    let outcome = r.run(&mut local);
    match outcome {
        Err(d) => {
            // Not well-formed: only the syntax error counts (the rest may be an artefact of it).
            diags.push(*d);
            None
        }
        Ok(Outcome::WrongRoot(span, name)) => {
            diags.push(
                Diagnostic::error(
                    Code::XmlWrongRoot,
                    format!("not a PLCopen XML file: the root element is `{name}`, not `project`"),
                )
                .at(span),
            );
            None
        }
        Ok(Outcome::Done {
            header,
            root,
            first_pou,
        }) => {
            for d in local.into_vec() {
                diags.push(d);
            }
            report_ignored(&r.ignored, diags);
            let _ = before;
            let chosen = r
                .found
                .iter()
                .position(|p| p.program)
                .or(if r.found.is_empty() { None } else { Some(0) });
            let with_sfc: Vec<&str> = r
                .pous
                .iter()
                .filter(|p| p.1)
                .map(|p| p.0.as_str())
                .collect();
            let list = |names: &[&str]| {
                let v: Vec<String> = names.iter().take(12).map(|n| format!("`{n}`")).collect();
                let more = if names.len() > 12 { ", ..." } else { "" };
                format!("{}{more}", v.join(", "))
            };
            let Some(i) = chosen else {
                let all: Vec<&str> = r.pous.iter().map(|p| p.0.as_str()).collect();
                let message = match (&r.wanted, &first_pou) {
                    (Some(w), _) if !with_sfc.is_empty() => format!(
                        "no POU named `{w}` with an SFC body; the POUs with one: {}",
                        list(&with_sfc)
                    ),
                    (Some(w), Some(_)) => format!(
                        "no POU named `{w}` with an SFC body; none of the {} POUs ({}) has one",
                        all.len(),
                        list(&all)
                    ),
                    (_, None) => "the SFC file has no `pou` (types/pous/pou)".to_owned(),
                    (None, Some((_, name))) if all.len() == 1 => {
                        format!("pou `{name}` has no SFC body (body/SFC)")
                    }
                    (None, Some(_)) => format!(
                        "none of the {} POUs ({}) has an SFC body (body/SFC)",
                        all.len(),
                        list(&all)
                    ),
                };
                diags.push(
                    Diagnostic::error(Code::NoSfcBody, message)
                        .at(first_pou.map(|(s, _)| s).unwrap_or(root)),
                );
                return None;
            };
            if r.wanted.is_none() && with_sfc.len() > 1 {
                let used = r.found[i].name.clone().unwrap_or_default();
                let others: Vec<&str> = with_sfc.iter().copied().filter(|n| *n != used).collect();
                diags.push(
                    Diagnostic::warning(
                        Code::SeveralPous,
                        format!(
                            "{} POUs have an SFC body; `{used}` is used ({}), not {}: name the one meant with `--pou NAME` or `#NAME` after the SFC file's name in the blackboard",
                            with_sfc.len(),
                            if r.found[i].program { "the first program" } else { "the first with one" },
                            list(&others)
                        ),
                    )
                    .at(r.found[i].sfc_span.clone()),
                );
            }
            let pou = r.found.swap_remove(i);
            Some(Sfc {
                file,
                header,
                pou_name: pou.name,
                elements: pou.elements,
                span: Some(pou.sfc_span),
            })
        }
    }
}

enum Outcome {
    WrongRoot(Span, String),
    Done {
        header: FileHeader,
        /// The root element's tag.
        root: Span,
        /// The first pou's tag and name (for "no SFC body").
        first_pou: Option<(Span, String)>,
    },
}

/// A pou whose SFC body was read.
struct Pou {
    name: Option<String>,
    program: bool,
    sfc_span: Span,
    elements: Vec<Element>,
}

struct Stream<'t> {
    text: &'t str,
    file: FileId,
    names: Interner,
    found: Vec<Pou>,
    /// Elements of the SFC body that are ignored: tag, place, label.
    ignored: Vec<(String, Span, String)>,
    /// The POU asked for by name.
    wanted: Option<String>,
    /// Every POU: name, whether it has an SFC body.
    pous: Vec<(String, bool)>,
}

/// An attribute: its local name, value (entities resolved) and the raw value's byte range.
struct Attr<'t> {
    name: &'t str,
    value: std::borrow::Cow<'t, str>,
    range: Range<usize>,
}

/// The element being read (a direct child of `SFC`), with what its descendants contributed.
struct Building<'t> {
    tag: &'t str,
    span: Span,
    depth: usize,
    /// `localId`, `name`, `initialStep`, `targetName`.
    attrs: [Option<Attr<'t>>; 4],
    x: Option<f64>,
    inputs: Vec<(u64, Range<usize>)>,
    bad_inputs: Vec<Diagnostic>,
    /// `Variable` elements: direct ones, then those in `iwb`.
    /// `name`, `Value`.
    direct_vars: Vec<(Span, [Option<Attr<'t>>; 2])>,
    iwb_vars: Vec<(Span, [Option<Attr<'t>>; 2])>,
    iwb: IwbState,
    resource: Option<Name>,
    resources_seen: bool,
    skill: Option<Name>,
    duration: Option<f64>,
    time_seen: bool,
    condition: Option<Span>,
    condition_done: bool,
    inline: Option<String>,
    /// Where each piece of `inline` came from: (offset in `inline`, offset in the file, whether
    /// the piece's bytes are the file's bytes one to one).
    inline_map: Vec<(usize, usize, bool)>,
    /// `condition/reference@name`: the name and its range.
    reference: Option<(String, Range<usize>)>,
    /// `condition/connectionPointIn`: a condition wired from FBD/LD elements.
    wired: bool,
}

impl<'t> Building<'t> {
    /// The element's attribute `name`, if it has it.
    fn attr(&self, name: &str) -> Option<&Attr<'t>> {
        self.attrs.iter().flatten().find(|a| a.name == name)
    }

    /// How diagnostics name the element: `localId N` (`?` without one).
    fn id_label(&self) -> String {
        format!(
            "localId {}",
            self.attr("localId").map(|a| &*a.value).unwrap_or("?")
        )
    }
}

#[derive(PartialEq, Eq, Clone, Copy)]
enum IwbState {
    Before,
    Inside,
    Done,
}

impl<'t> Stream<'t> {
    fn span(&self, r: Range<usize>) -> Span {
        Span::new(self.file, r)
    }

    /// The byte offset of `s` in the text (it is a slice of it), or `fallback`.
    fn offset_of(&self, s: &str, fallback: usize) -> usize {
        let base = self.text.as_ptr() as usize;
        let p = s.as_ptr() as usize;
        if p >= base && p + s.len() <= base + self.text.len() {
            p - base
        } else {
            fallback
        }
    }

    fn syntax_error(&self, at: usize, msg: String) -> Box<Diagnostic> {
        // The parser's position may fall inside a multi-byte character: mark the character.
        let mut at = at.min(self.text.len());
        while !self.text.is_char_boundary(at) {
            at -= 1;
        }
        let end = (at + 1).min(self.text.len()).max(at);
        Box::new(
            Diagnostic::error(Code::XmlSyntax, format!("not well-formed XML: {msg}"))
                .at(self.span(at..end)),
        )
    }

    /// The local name of a start tag, as a slice of the text.
    fn local_name(&self, e: &BytesStart<'t>) -> &'t str {
        let raw = e.name();
        let full: &str = raw.as_ref();
        let start = self.offset_of(full, usize::MAX);
        let local = full.rsplit(':').next().unwrap_or(full);
        if start == usize::MAX {
            return "";
        }
        let off = start + (full.len() - local.len());
        &self.text[off..off + local.len()]
    }

    /// The attributes named `names` (local names), in that order; others are skipped (not
    /// unescaped). No allocation unless a value has references to resolve.
    fn pick<const N: usize>(
        &self,
        e: &BytesStart<'t>,
        tag_at: usize,
        names: [&str; N],
    ) -> Result<[Option<Attr<'t>>; N], Box<Diagnostic>> {
        let mut out: [Option<Attr<'t>>; N] = std::array::from_fn(|_| None);
        for a in e.attributes() {
            let a = a.map_err(|err| self.syntax_error(tag_at, err.to_string()))?;
            let key_raw: &str = a.key.as_ref();
            let local = match key_raw.rfind(':') {
                Some(i) => &key_raw[i + 1..],
                None => key_raw,
            };
            let Some(slot) = names.iter().position(|n| *n == local) else {
                continue;
            };
            if out[slot].is_some() {
                continue;
            }
            let key_at = self.offset_of(key_raw, tag_at);
            let name_at = key_at + (key_raw.len() - local.len());
            let name: &'t str = self.text.get(name_at..name_at + local.len()).unwrap_or("");
            let raw_at = self.offset_of(&a.value, tag_at);
            let range = raw_at..raw_at + a.value.len();
            let raw: Option<&'t str> = match &a.value {
                std::borrow::Cow::Borrowed(_) => self.text.get(range.clone()),
                std::borrow::Cow::Owned(_) => None,
            };
            let value = match raw {
                Some(raw) if !raw.contains(['&', '\t', '\n', '\r']) => {
                    std::borrow::Cow::Borrowed(raw)
                }
                _ => std::borrow::Cow::Owned(
                    a.normalized_value(quick_xml::XmlVersion::Implicit1_0)
                        .map_err(|err| self.syntax_error(raw_at, err.to_string()))?
                        .into_owned(),
                ),
            };
            out[slot] = Some(Attr { name, value, range });
        }
        Ok(out)
    }

    fn run(&mut self, diags: &mut Diagnostics) -> Result<Outcome, Box<Diagnostic>> {
        // The loader strips one byte-order mark; another one is not XML (and the parser would
        // skip it silently, shifting every position it reports).
        if self.text.starts_with('\u{feff}') {
            return Err(Box::new(
                Diagnostic::error(
                    Code::XmlSyntax,
                    "not well-formed XML: a second byte-order mark at the start of the file",
                )
                .at(self.span(0..3)),
            ));
        }
        let mut reader = quick_xml::Reader::from_str(self.text);
        // Stack of open elements' local names.
        let mut stack: Vec<&'t str> = Vec::new();
        let mut header = FileHeader::default();
        let mut root = self.span(0..0);
        let mut first_pou: Option<(Span, String)> = None;
        // The pou being read, if its SFC is wanted: (name, program, pou depth).
        let mut pou: Option<(Option<String>, bool, usize)> = None;
        let mut want_pou = false;
        let mut body_seen = false;
        let mut sfc: Option<(Span, usize, Vec<Element>)> = None;
        let mut sfc_done = false;
        let mut building: Option<Building<'t>> = None;
        let mut seen_root = false;
        loop {
            let at = reader.buffer_position() as usize;
            let ev = match reader.read_event() {
                Ok(ev) => ev,
                Err(e) => {
                    return Err(self.syntax_error(reader.error_position() as usize, e.to_string()));
                }
            };
            let (start, empty) = match ev {
                Event::Start(e) => (e, false),
                Event::Empty(e) => (e, true),
                Event::End(_) => {
                    let depth = stack.len();
                    stack.pop();
                    if let Some(b) = &building
                        && depth == b.depth
                    {
                        let b = building.take().expect("checked");
                        if let Some(el) = self.finish(b, diags)
                            && let Some((_, _, els)) = &mut sfc
                        {
                            els.push(el);
                        }
                    } else if let Some(b) = &mut building {
                        end_inside(b, &stack);
                    } else if let Some((span, d, els)) = &sfc
                        && depth == *d
                    {
                        // `</SFC>`
                        let (name, program, _) = pou.clone().unwrap_or((None, false, 0));
                        let _ = (span, els);
                        let (span, _, els) = sfc.take().expect("checked");
                        let mut els = els;
                        els.shrink_to_fit();
                        self.found.push(Pou {
                            name,
                            program,
                            sfc_span: span,
                            elements: els,
                        });
                        sfc_done = true;
                    } else if let Some((_, _, d)) = &pou
                        && depth == *d
                    {
                        pou = None;
                        want_pou = false;
                    }
                    continue;
                }
                Event::Text(t) => {
                    let end = reader.buffer_position() as usize;
                    inline_text(&mut building, &stack, at..end, || {
                        t.xml_content(quick_xml::XmlVersion::Implicit1_0)
                    });
                    continue;
                }
                Event::CData(t) => {
                    // `<![CDATA[` … `]]>`
                    let end = (reader.buffer_position() as usize).saturating_sub(3);
                    inline_text(&mut building, &stack, (at + 9).min(end)..end, || {
                        t.xml_content(quick_xml::XmlVersion::Implicit1_0)
                    });
                    continue;
                }
                Event::GeneralRef(r) => {
                    let ch = match r.resolve_char_ref() {
                        Ok(Some(c)) => Some(c),
                        Ok(None) => match &*r {
                            "lt" => Some('<'),
                            "gt" => Some('>'),
                            "amp" => Some('&'),
                            "apos" => Some('\''),
                            "quot" => Some('"'),
                            other => {
                                return Err(self.syntax_error(
                                    at,
                                    format!("unknown entity reference `&{other};`"),
                                ));
                            }
                        },
                        Err(e) => return Err(self.syntax_error(at, e.to_string())),
                    };
                    if let (Some(c), Some(b)) = (ch, &mut building)
                        && b.inline.is_some()
                        && in_inline(b, &stack)
                    {
                        let inline = b.inline.as_mut().expect("checked");
                        b.inline_map.push((inline.len(), at, false));
                        inline.push(c);
                    }
                    continue;
                }
                Event::DocType(_) => {
                    return Err(Box::new(
                        Diagnostic::error(
                            Code::XmlSyntax,
                            "a document type declaration (DTD) is not accepted: entity definitions could expand without bound",
                        )
                        .at(self.span(at..at + 9.min(self.text.len() - at))),
                    ));
                }
                Event::Eof => {
                    if let Some(open) = stack.last() {
                        return Err(self.syntax_error(
                            self.text.len(),
                            format!("the file ends inside `<{open}>`"),
                        ));
                    }
                    if !seen_root {
                        return Err(self.syntax_error(0, "no root element".to_owned()));
                    }
                    return Ok(Outcome::Done {
                        header,
                        root,
                        first_pou,
                    });
                }
                _ => continue,
            };
            let name = self.local_name(&start);
            let tag = self.span(at..(at + 1 + name.len()).min(self.text.len()));
            if stack.is_empty() {
                if seen_root {
                    return Err(self.syntax_error(at, "a second root element".to_owned()));
                }
                seen_root = true;
                root = tag.clone();
                if name != "project" {
                    // Read no further: the caller reports E103 (the rest may be any XML).
                    return Ok(Outcome::WrongRoot(tag, name.to_owned()));
                }
            }
            let depth = stack.len() + 1;
            // The element's place, relative to the document.
            let path = PathKind::of(&stack, name);
            if matches!(path, PathKind::Sfc)
                && let Some(p) = self.pous.last_mut()
            {
                p.1 = true;
            }
            if let Some(b) = &mut building {
                self.inside(b, &stack, name, tag, &start, at)?;
                if empty {
                    end_inside(b, &stack);
                } else {
                    stack.push(name);
                }
                continue;
            }
            match path {
                PathKind::FileHeader => {
                    let [company, product, version, time] = self.pick(
                        &start,
                        at,
                        [
                            "companyName",
                            "productName",
                            "productVersion",
                            "creationDateTime",
                        ],
                    )?;
                    let v = |a: Option<Attr>| a.map(|a| a.value.into_owned());
                    header.company_name = v(company);
                    header.product_name = v(product);
                    header.product_version = v(version);
                    header.creation_date_time = v(time);
                }
                PathKind::Pou => {
                    let [pou_name, pou_type] = self.pick(&start, at, ["name", "pouType"])?;
                    let get = |a: &Option<Attr>| a.as_ref().map(|a| a.value.to_string());
                    let pname = get(&pou_name);
                    let program = get(&pou_type).as_deref() == Some("program");
                    if first_pou.is_none() {
                        first_pou = Some((tag.clone(), pname.clone().unwrap_or_default()));
                    }
                    self.pous.push((pname.clone().unwrap_or_default(), false));
                    let have_program = self.found.iter().any(|p| p.program);
                    want_pou = match &self.wanted {
                        Some(w) => {
                            self.found.is_empty()
                                && pname.as_deref().is_some_and(|n| crate::names::eq(n, w))
                        }
                        None => !have_program && (program || self.found.is_empty()),
                    };
                    if want_pou && !empty {
                        pou = Some((pname, program, depth));
                        body_seen = false;
                        sfc_done = false;
                    }
                }
                PathKind::Body if want_pou && pou.is_some() => {
                    if body_seen {
                        // Only the first body counts.
                        want_pou = false;
                    }
                    body_seen = true;
                }
                PathKind::Sfc if want_pou && pou.is_some() && !sfc_done && sfc.is_none() => {
                    if empty {
                        let (pname, program, _) = pou.clone().expect("checked");
                        self.found.push(Pou {
                            name: pname,
                            program,
                            sfc_span: tag,
                            elements: Vec::new(),
                        });
                        sfc_done = true;
                    } else {
                        // Sized from the bytes left (an element takes about 300-400 bytes):
                        // growing by doubling would hold the old and the new vector at once.
                        let left = self.text.len().saturating_sub(tag.range.end);
                        sfc = Some((tag, depth, Vec::with_capacity((left / 320).min(1 << 24))));
                    }
                }
                _ => {
                    if let Some((_, d, els)) = &mut sfc
                        && depth == *d + 1
                    {
                        let attrs = self.pick(
                            &start,
                            at,
                            ["localId", "name", "initialStep", "targetName"],
                        )?;
                        let b = Building {
                            tag: name,
                            span: tag,
                            depth,
                            attrs,
                            x: None,
                            inputs: Vec::new(),
                            bad_inputs: Vec::new(),
                            direct_vars: Vec::new(),
                            iwb_vars: Vec::new(),
                            iwb: IwbState::Before,
                            resource: None,
                            resources_seen: false,
                            skill: None,
                            duration: None,
                            time_seen: false,
                            condition: None,
                            condition_done: false,
                            inline: None,
                            inline_map: Vec::new(),
                            reference: None,
                            wired: false,
                        };
                        if empty {
                            if let Some(el) = self.finish(b, diags) {
                                els.push(el);
                            }
                        } else {
                            building = Some(b);
                        }
                    }
                }
            }
            if !empty {
                stack.push(name);
            }
        }
    }

    /// A descendant of the element being built, at `stack` (which ends below the element).
    fn inside(
        &mut self,
        b: &mut Building<'t>,
        stack: &[&'t str],
        name: &'t str,
        tag: Span,
        start: &BytesStart<'t>,
        at: usize,
    ) -> Result<(), Box<Diagnostic>> {
        let rel = &stack[b.depth..];
        match (rel, name) {
            ([], "position") if b.x.is_none() => {
                let [x] = self.pick(start, at, ["x"])?;
                b.x = Some(
                    x.and_then(|a| a.value.trim().parse::<f64>().ok())
                        .filter(|x| x.is_finite())
                        .unwrap_or(0.0),
                );
            }
            (["connectionPointIn"], "connection") => match self.pick(start, at, ["refLocalId"])? {
                [Some(a)] => match a.value.trim().parse::<u64>() {
                    Ok(r) => b.inputs.push((r, a.range.clone())),
                    Err(_) => b.bad_inputs.push(
                        Diagnostic::error(
                            Code::DanglingReference,
                            format!("refLocalId `{}` is not a number", a.value),
                        )
                        .at(self.span(a.range.clone())),
                    ),
                },
                [None] => b.bad_inputs.push(
                    Diagnostic::error(Code::DanglingReference, "connection without refLocalId")
                        .at(tag),
                ),
            },
            ([], "Variable") => {
                let attrs = self.pick(start, at, ["name", "Value"])?;
                b.direct_vars.push((tag, attrs));
            }
            (["addData", "data"], "iwb") if b.iwb == IwbState::Before => {
                b.iwb = IwbState::Inside;
            }
            (["addData", "data", "iwb"], _) if b.iwb == IwbState::Inside => match name {
                "ressources" | "resources" if !b.resources_seen => b.resources_seen = true,
                "skill" if b.skill.is_none() => {
                    let [n] = self.pick(start, at, ["name"])?;
                    b.skill = n
                        .map(|a| self.names.name(&a.value, self.span(a.range.clone())))
                        .filter(|n| !n.key.is_empty());
                }
                "time" if !b.time_seen => {
                    b.time_seen = true;
                    let [d] = self.pick(start, at, ["duration"])?;
                    b.duration = d
                        .and_then(|a| a.value.trim().parse::<f64>().ok())
                        .filter(|d| d.is_finite() && *d >= 0.0);
                }
                "Variable" => {
                    let attrs = self.pick(start, at, ["name", "Value"])?;
                    b.iwb_vars.push((tag, attrs));
                }
                _ => {}
            },
            (["addData", "data", "iwb", "ressources" | "resources"], "ressource" | "resource")
                if b.iwb == IwbState::Inside && b.resource.is_none() =>
            {
                let [n] = self.pick(start, at, ["name"])?;
                b.resource = n
                    .map(|a| self.names.name(&a.value, self.span(a.range.clone())))
                    .filter(|n| !n.key.is_empty());
            }
            ([], "condition") if b.condition.is_none() && !b.condition_done => {
                b.condition = Some(tag);
            }
            (["condition"], "inline")
                if b.condition.is_some() && b.inline.is_none() && b.reference.is_none() =>
            {
                b.inline = Some(String::new());
            }
            (["condition"], "reference")
                if b.condition.is_some() && b.inline.is_none() && b.reference.is_none() =>
            {
                let [n] = self.pick(start, at, ["name"])?;
                b.reference = Some(match n {
                    Some(a) => (a.value.into_owned(), a.range),
                    None => (String::new(), tag.range.clone()),
                });
            }
            (["condition"], "connectionPointIn") if b.condition.is_some() => b.wired = true,
            _ => {}
        }
        Ok(())
    }

    /// The element is complete: check it and turn it into the model.
    fn finish(&mut self, b: Building<'t>, diags: &mut Diagnostics) -> Option<Element> {
        let file = self.file;
        let attr = |n: &str| b.attr(n);
        let kind = match b.tag {
            "step" => ElementKind::Step(Box::new(self.step(&b, diags))),
            "transition" => ElementKind::Transition(self.condition(&b, diags)),
            "simultaneousDivergence" => ElementKind::SimultaneousDivergence,
            "simultaneousConvergence" => ElementKind::SimultaneousConvergence,
            "selectionDivergence" => ElementKind::SelectionDivergence,
            "selectionConvergence" => ElementKind::SelectionConvergence,
            "jumpStep" => {
                let target = attr("targetName")
                    .filter(|a| !a.value.trim().is_empty())
                    .map(|a| Box::new(self.names.name(&a.value, Span::new(file, a.range.clone()))));
                if target.is_none() {
                    diags.push(
                        Diagnostic::error(
                            Code::BadJump,
                            "jumpStep without `targetName`: name the step to jump to",
                        )
                        .at(b.span.clone())
                        .element(b.id_label()),
                    );
                }
                ElementKind::JumpStep(target)
            }
            "macroStep" => ElementKind::MacroStep,
            tag => {
                // Reported once per kind and chart (see `report_ignored`).
                let n = self.ignored.iter().filter(|i| i.0 == tag).count() + 1;
                let label = match attr("localId") {
                    Some(a) => format!("localId {}", a.value.trim()),
                    None => format!("{tag} no. {n} of the SFC body"),
                };
                self.ignored.push((tag.to_owned(), b.span.clone(), label));
                return None;
            }
        };
        let local_id = match attr("localId").map(|a| (a.value.trim().parse::<u64>(), a)) {
            Some((Ok(id), _)) => id,
            Some((Err(_), a)) => {
                diags.push(
                    Diagnostic::error(
                        Code::BadLocalId,
                        format!(
                            "`{}` has localId `{}`, which is not a number from 0 to {}",
                            b.tag,
                            a.value,
                            u64::MAX
                        ),
                    )
                    .at(Span::new(file, a.range.clone())),
                );
                return None;
            }
            None => {
                diags.push(
                    Diagnostic::error(Code::BadLocalId, format!("`{}` without localId", b.tag))
                        .at(b.span.clone()),
                );
                return None;
            }
        };
        for d in b.bad_inputs {
            diags.push(d.element(format!("localId {local_id}")));
        }
        Some(Element {
            local_id,
            kind,
            span: b.span,
            x: b.x.unwrap_or(0.0),
            inputs: {
                // Most elements have one input: no slack kept for 100,000 of them.
                let mut inputs = b.inputs;
                inputs.shrink_to_fit();
                inputs
            },
        })
    }

    /// A transition's condition: parsed, syntax errors located in the file. `None` when the
    /// transition always fires (no condition, or `TRUE`).
    fn condition(&self, b: &Building<'t>, diags: &mut Diagnostics) -> Option<Box<Condition>> {
        let c = b.condition.as_ref()?;
        let label = || b.id_label();
        let file = self.file;
        let (text, parsed, reference) = if let Some(inline) = &b.inline {
            let map = |o: usize| map_offset(&b.inline_map, o);
            (inline.trim(), crate::cond::parse(inline, &map), false)
        } else if let Some((name, range)) = &b.reference {
            // The name is the condition: one name, nothing else.
            let lead = name.len() - name.trim_start().len();
            let map = |o: usize| (range.start + o).min(range.end);
            let parsed = if range.len() == name.len() {
                crate::cond::parse(name, &map)
            } else {
                crate::cond::parse(name, &|_| range.start)
            };
            let parsed = match parsed {
                Ok(e) if matches!(e.kind, crate::cond::ExprKind::Name(_)) => Ok(e),
                _ if name.trim().is_empty() => Err(crate::cond::SyntaxError {
                    at: 0..name.len(),
                    message: "condition reference without a `name`".to_owned(),
                }),
                _ => Err(crate::cond::SyntaxError {
                    at: lead..name.trim_end().len(),
                    message: format!(
                        "condition reference `{}` is not one name (the name is the condition: a signal)",
                        name.trim()
                    ),
                }),
            };
            (name.trim(), parsed, true)
        } else if b.wired {
            diags.push(
                Diagnostic::error(
                    Code::Unsupported,
                    "a condition wired from FBD/LD elements (condition/connectionPointIn) is not supported: write it as inline ST",
                )
                .at(c.clone())
                .element(label()),
            );
            return None;
        } else {
            diags.push(
                Diagnostic::error(
                    Code::BadCondition,
                    "`condition` holds neither `inline` ST nor a `reference`",
                )
                .at(c.clone())
                .element(label()),
            );
            return None;
        };
        // As written, on one line (for messages, listings and comments).
        let text = text.split_whitespace().collect::<Vec<_>>().join(" ");
        match parsed {
            Ok(e) if e.is_true() => None,
            Ok(expr) => Some(Box::new(Condition {
                text,
                expr,
                span: c.clone(),
                reference,
            })),
            Err(err) => {
                let at = if reference {
                    let r = &b.reference.as_ref().expect("reference").1;
                    if r.len() == text.len() || err.at.end <= r.len() {
                        (r.start + err.at.start).min(r.end)..(r.start + err.at.end).min(r.end)
                    } else {
                        r.clone()
                    }
                } else {
                    let s = map_offset(&b.inline_map, err.at.start);
                    let e = map_offset(&b.inline_map, err.at.end.saturating_sub(1)) + 1;
                    s..e.max(s + 1)
                };
                // On character boundaries of the file, whatever the pieces' mapping gave.
                let (mut s, mut e) = (at.start.min(self.text.len()), at.end.min(self.text.len()));
                while !self.text.is_char_boundary(s) {
                    s -= 1;
                }
                while !self.text.is_char_boundary(e) {
                    e += 1;
                }
                let at = s..e.max(s);
                diags.push(
                    Diagnostic::error(
                        Code::BadCondition,
                        format!("condition `{}`: {}", text, err.message),
                    )
                    .at(Span::new(file, at))
                    .element(label()),
                );
                None
            }
        }
    }

    fn step(&mut self, b: &Building<'t>, diags: &mut Diagnostics) -> Step {
        let file = self.file;
        let label = || b.id_label();
        let mut variables = Vec::new();
        let mut invalid_variables = Vec::new();
        for (tag, attrs) in b.direct_vars.iter().chain(b.iwb_vars.iter()) {
            let get = |n: &str| attrs.iter().flatten().find(|a| a.name == n);
            let Some(name) = get("name") else {
                diags.push(
                    Diagnostic::error(Code::BadVariableSyntax, "Variable without `name`")
                        .at(tag.clone())
                        .element(label()),
                );
                continue;
            };
            let Some(value) = get("Value") else {
                diags.push(
                    Diagnostic::error(
                        Code::BadVariableSyntax,
                        format!("Variable `{}` without `Value`", name.value),
                    )
                    .at(tag.clone())
                    .element(label()),
                );
                invalid_variables.push(self.names.strings(&name.value).1);
                continue;
            };
            let value_span = Span::new(file, value.range.clone());
            match crate::value::check_value(&value.value) {
                Ok(()) => variables.push(Variable {
                    name: self
                        .names
                        .name(&name.value, Span::new(file, name.range.clone())),
                    raw: value.value.trim().to_owned(),
                    value_span,
                }),
                Err((offset, msg)) => {
                    invalid_variables.push(self.names.strings(&name.value).1);
                    // Point into the raw value when it has no references (then offsets agree).
                    let raw_len = value.range.len();
                    let at = if raw_len == value.value.len() {
                        value.range.start + offset.min(raw_len)
                    } else {
                        value.range.start
                    };
                    diags.push(
                        Diagnostic::error(
                            Code::BadVariableSyntax,
                            format!("variable `{}`: {msg}", name.value),
                        )
                        .at(Span::new(file, at..(at + 1).min(value.range.end.max(at))))
                        .element(label()),
                    );
                }
            }
        }
        let attr = |n: &str| b.attr(n);
        Step {
            name: self
                .names
                .strings(attr("name").map(|a| &*a.value).unwrap_or(""))
                .0,
            initial: attr("initialStep")
                .is_some_and(|a| a.value.trim() == "true" || a.value.trim() == "1"),
            resource: b.resource.clone(),
            skill: b.skill.clone(),
            duration: b.duration,
            variables: {
                // A step has a few variables: no slack kept for 100,000 steps.
                let mut variables = variables;
                variables.shrink_to_fit();
                variables
            },
            invalid_variables,
        }
    }
}

/// One warning per kind of ignored element (action blocks, unknown elements), naming them.
fn report_ignored(ignored: &[(String, Span, String)], diags: &mut Diagnostics) {
    let mut kinds: Vec<&str> = Vec::new();
    for (tag, _, _) in ignored {
        if !kinds.contains(&tag.as_str()) {
            kinds.push(tag);
        }
    }
    for kind in kinds {
        let all: Vec<&(String, Span, String)> = ignored.iter().filter(|i| i.0 == kind).collect();
        let what = if kind == "actionBlock" {
            "action block".to_owned()
        } else {
            format!("`{kind}` element")
        };
        let labels: Vec<&str> = all.iter().take(8).map(|i| i.2.as_str()).collect();
        let more = if all.len() > 8 { ", ..." } else { "" };
        let msg = if all.len() == 1 {
            format!("{what} ignored")
        } else {
            format!(
                "{} {what}s ignored ({}{more})",
                all.len(),
                labels.join(", ")
            )
        };
        diags.push(
            Diagnostic::warning(Code::Ignored, msg)
                .at(all[0].1.clone())
                .element(all[0].2.clone()),
        );
    }
}

/// Where an element stands in the document, for the parts read outside SFC elements.
enum PathKind {
    FileHeader,
    Pou,
    Body,
    Sfc,
    Other,
}

impl PathKind {
    fn of(stack: &[&str], name: &str) -> Self {
        match (stack, name) {
            (["project"], "fileHeader") => PathKind::FileHeader,
            (["project", "types", "pous"], "pou") => PathKind::Pou,
            (["project", "types", "pous", "pou"], "body") => PathKind::Body,
            (["project", "types", "pous", "pou", "body"], "SFC") => PathKind::Sfc,
            _ => PathKind::Other,
        }
    }
}

/// An element inside the one being built closed; `stack` is what remains open.
fn end_inside(b: &mut Building, stack: &[&str]) {
    let rel = &stack[b.depth.min(stack.len())..];
    match rel {
        // `</iwb>` closed: only the first iwb counts.
        ["addData", "data"] if b.iwb == IwbState::Inside => b.iwb = IwbState::Done,
        // `</condition>` closed: only the first condition counts.
        [] if b.condition.is_some() => b.condition_done = true,
        _ => {}
    }
}

/// Adds text (read from `raw`, a range of the file) to the element's inline condition when the
/// stack is inside it.
fn inline_text<'s>(
    building: &mut Option<Building>,
    stack: &[&str],
    raw: Range<usize>,
    text: impl FnOnce() -> std::borrow::Cow<'s, str>,
) {
    if let Some(b) = building
        && b.inline.is_some()
        && in_inline(b, stack)
    {
        let t = text();
        let inline = b.inline.get_or_insert_default();
        b.inline_map
            .push((inline.len(), raw.start, t.len() == raw.len()));
        inline.push_str(&t);
    }
}

/// The file offset of byte `o` of an inline condition assembled from the pieces of `map`.
fn map_offset(map: &[(usize, usize, bool)], o: usize) -> usize {
    let i = map.partition_point(|&(c, _, _)| c <= o);
    match i.checked_sub(1).map(|i| map[i]) {
        Some((c, f, true)) => f + (o - c),
        Some((_, f, false)) => f,
        None => map.first().map_or(0, |m| m.1),
    }
}

/// Whether the stack is inside the element's `condition/inline`.
fn in_inline(b: &Building, stack: &[&str]) -> bool {
    let rel = &stack[b.depth.min(stack.len())..];
    rel.len() >= 2 && rel[0] == "condition" && rel[1] == "inline"
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> (Option<Sfc>, Vec<Diagnostic>) {
        let mut sources = Sources::default();
        let f = sources.add("s.xml".into(), "s.xml".into(), text.to_owned(), false);
        let mut d = Diagnostics::default();
        let sfc = read_sfc(&sources, f, &mut d);
        (sfc, d.into_vec())
    }

    #[test]
    fn transition_conditions() {
        let doc = |cond: &str| {
            format!(
                "<project xmlns=\"http://www.plcopen.org/xml/tc6_0201\"><types><pous><pou name=\"P\" pouType=\"program\"><body><SFC>\
                 <transition localId=\"2\"><condition>{cond}</condition></transition>\
                 </SFC></body></pou></pous></types></project>"
            )
        };
        let (sfc, d) = read(&doc(
            "<inline name=\"\"><ST><xhtml:p xmlns:xhtml=\"x\"> TRUE </xhtml:p></ST></inline>",
        ));
        assert_eq!(sfc.unwrap().elements.len(), 1);
        assert!(d.is_empty(), "{d:?}");
        // Entities and CDATA: the error is located in the file.
        let text = doc("<inline><ST>a &lt; b<![CDATA[ && c]]></ST></inline>");
        let (sfc, d) = read(&text);
        assert_eq!(d.len(), 1, "{d:?}");
        assert_eq!(d[0].code, Code::BadCondition);
        assert!(
            d[0].message.contains("condition `a < b && c`"),
            "{}",
            d[0].message
        );
        // The second `&` of `&&` (the first is a complete AND, the second lacks an operand).
        let at = d[0].span.as_ref().unwrap().range.start;
        assert_eq!(&text[at..at + 1], "&");
        assert_eq!(&text[at - 1..at + 3], "&& c");
        assert!(sfc.unwrap().elements.len() == 1);
        // A parsed condition keeps file spans.
        let text = doc(
            "<inline><ST><xhtml:p xmlns:xhtml=\"x\">Part_OK AND NOT Stop</xhtml:p></ST></inline>",
        );
        let (sfc, d) = read(&text);
        assert!(d.is_empty(), "{d:?}");
        let sfc = sfc.unwrap();
        let ElementKind::Transition(Some(c)) = &sfc.elements[0].kind else {
            panic!("no condition")
        };
        let names = c.expr.names();
        assert_eq!(&text[names[1].1.clone()], "Stop");
        // A reference is one name.
        let text = doc("<reference name=\"Cond1\"/>");
        let (sfc, d) = read(&text);
        assert!(d.is_empty(), "{d:?}");
        let ElementKind::Transition(Some(c)) = &sfc.unwrap().elements[0].kind else {
            panic!("no condition")
        };
        assert!(c.reference);
        assert_eq!(&text[c.expr.span.clone()], "Cond1");
        let (_, d) = read(&doc("<reference name=\"a b\"/>"));
        assert!(d[0].message.contains("is not one name"), "{}", d[0].message);
        let (_, d) = read(&doc(
            "<connectionPointIn><connection refLocalId=\"9\"/></connectionPointIn>",
        ));
        assert_eq!(d[0].code, Code::Unsupported);
        assert!(d[0].message.contains("wired"), "{}", d[0].message);
    }

    #[test]
    fn second_bom_is_a_located_syntax_error() {
        // Found by fuzzing: two byte-order marks, then garbage.
        let (sfc, d) = read("\u{feff}]]<essoe\u{16}reso");
        assert!(sfc.is_none());
        assert_eq!(d.len(), 1);
        assert_eq!(d[0].code, Code::XmlSyntax);
        assert_eq!(d[0].span.as_ref().unwrap().range, 0..3);
    }

    #[test]
    fn truncated_file_is_a_syntax_error() {
        let (sfc, d) = read(
            "<project><types><pous><pou name=\"P\"><body><SFC><step localId=\"1\" name=\"S\"/>",
        );
        assert!(sfc.is_none());
        assert_eq!(d.len(), 1);
        assert_eq!(d[0].code, Code::XmlSyntax);
        assert!(
            d[0].message.contains("ends inside `<SFC>`"),
            "{}",
            d[0].message
        );
    }
}
