//! IRL reader (docs/INPUTS.md): an `<irl>` document's `function-call` templates and `definition`s.
//!
//! Element names are matched exactly (by local name), `name` attribute values
//! case-insensitively (through [`Name`]). The reader reports every problem it finds and keeps
//! going: a `function-call` or `definition` without a name is skipped, one with a bad text
//! (non-ASCII code, empty) is reported and kept, so later stages do not add follow-up errors.

use roxmltree::Node;

use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::lang::Language;
use crate::model::Name;
use crate::read::xml::{attr_span, children, parse, tag_span};
use crate::template::{Template, dedent, params_from_brackets};

/// An IRL file.
#[derive(Debug)]
pub struct Irl {
    pub file: FileId,
    pub info: Option<String>,
    /// The language its templates were read in.
    pub language: Language,
    pub calls: Vec<IrlCall>,
    pub definitions: Vec<IrlDefinition>,
}

/// A `function-call` template.
#[derive(Debug)]
pub struct IrlCall {
    pub name: Name,
    /// The declared parameters (or those taken from the first bracket group).
    pub params: Vec<Name>,
    pub template: Template,
    /// The element's start tag.
    pub span: Span,
}

/// A `def/definition`, emitted once after the program.
#[derive(Debug)]
pub struct IrlDefinition {
    pub name: Name,
    /// The text, common indentation removed, lines without their endings.
    pub lines: Vec<String>,
    pub span: Span,
}

/// Reads an IRL file already in `sources`. `None` only when the file is not well-formed XML or
/// not an `<irl>` document; every other problem is pushed into `diags`.
pub fn read_irl(sources: &Sources, file: FileId, diags: &mut Diagnostics) -> Option<Irl> {
    read_irl_in(sources, file, Language::Krl, diags)
}

/// The language an IRL file declares (`<info language="…"/>`), with the attribute's span.
/// `E210` when it names no language skillpost writes; problems of the file itself are left to
/// [`read_irl_in`].
pub fn declared_language(
    sources: &Sources,
    file: FileId,
    diags: &mut Diagnostics,
) -> Option<(Language, Span)> {
    let mut scratch = Diagnostics::default();
    let doc = parse(sources, file, &mut scratch)?;
    let root = doc.root_element();
    let info = children(root, "info").find(|i| i.attribute("language").is_some())?;
    let text = info.attribute("language")?;
    let span = attr_span(file, info, "language");
    match Language::parse(text) {
        Some(l) => Some((l, span)),
        None => {
            diags.push(
                Diagnostic::error(
                    Code::BadLanguage,
                    format!(
                        "IRL language `{}` is none skillpost writes: `KRL`, `RAPID` or `URScript`",
                        text.trim()
                    ),
                )
                .at(span),
            );
            None
        }
    }
}

/// Reads an IRL file whose templates are in `language`.
pub fn read_irl_in(
    sources: &Sources,
    file: FileId,
    language: Language,
    diags: &mut Diagnostics,
) -> Option<Irl> {
    let doc = parse(sources, file, diags)?;
    let text = sources.get(file).text.as_ref();
    let root = doc.root_element();
    if root.tag_name().name() != "irl" {
        diags.push(
            Diagnostic::error(
                Code::XmlWrongRoot,
                format!(
                    "not an IRL file: the root element is <{}>, expected <irl>",
                    root.tag_name().name()
                ),
            )
            .at(tag_span(file, root)),
        );
        return None;
    }
    let info = children(root, "info")
        .find_map(|i| i.attribute("name"))
        .map(|n| n.trim().to_owned());

    let mut irl = Irl {
        file,
        info,
        language,
        calls: Vec::new(),
        definitions: Vec::new(),
    };

    for def in children(root, "def") {
        for node in children(def, "definition") {
            let Some(name) = element_name(file, node, "definition", diags) else {
                continue;
            };
            let body = element_text(file, text, node, &name, diags);
            let lines = dedent(&body);
            if lines.is_empty() {
                diags.push(
                    Diagnostic::error(
                        Code::BadIrl,
                        format!("definition `{}` has no code", name.text),
                    )
                    .at(tag_span(file, node)),
                );
            }
            irl.definitions.push(IrlDefinition {
                name,
                lines,
                span: tag_span(file, node),
            });
        }
    }

    let mut has_src = false;
    for src in children(root, "src") {
        has_src = true;
        for node in children(src, "function-call") {
            if let Some(call) = read_call(file, text, node, language, diags) {
                irl.calls.push(call);
            }
        }
    }
    if !has_src {
        diags.push(
            Diagnostic::error(Code::BadIrl, "IRL file has no <src> element")
                .at(tag_span(file, root)),
        );
    }
    Some(irl)
}

/// One `function-call`: its name, parameters and compiled template.
fn read_call(
    file: FileId,
    text: &str,
    node: Node,
    language: Language,
    diags: &mut Diagnostics,
) -> Option<IrlCall> {
    let name = element_name(file, node, "function-call", diags)?;
    let span = tag_span(file, node);

    let mut params: Vec<Name> = Vec::new();
    let mut declared = false;
    for p in children(node, "parameter") {
        declared = true;
        match p.attribute("name").filter(|n| !n.trim().is_empty()) {
            Some(n) => params.push(Name::new(n, attr_span(file, p, "name"))),
            None => diags.push(
                Diagnostic::error(
                    Code::BadIrl,
                    format!(
                        "a <parameter> of function-call `{}` has no name attribute",
                        name.text
                    ),
                )
                .at(tag_span(file, p)),
            ),
        }
    }

    let body = element_text(file, text, node, &name, diags);
    let lines = dedent(&body);
    if lines.is_empty() {
        diags.push(
            Diagnostic::error(
                Code::BadIrl,
                format!("function-call `{}` has an empty template", name.text),
            )
            .at(span.clone()),
        );
    }
    let joined = lines.join("\n");
    if !declared {
        params = params_from_brackets(&joined)
            .iter()
            .map(|p| Name::new(p, span.clone()))
            .collect();
    }
    for (i, p) in params.iter().enumerate() {
        if let Some(first) = params[..i].iter().find(|q| q.key == p.key) {
            diags.push(
                Diagnostic::error(
                    Code::BadIrl,
                    format!(
                        "function-call `{}` declares parameter `{}` twice",
                        name.text, p.text
                    ),
                )
                .at(p.span.clone())
                .related(first.span.clone(), "first declared here"),
            );
        }
    }
    let names: Vec<String> = params.iter().map(|p| p.text.to_string()).collect();
    let template = Template::compile_for(&joined, &names, language.syntax());
    for (_, why) in template.errors() {
        diags.push(
            Diagnostic::error(
                Code::BadConversionCall,
                format!("function-call `{}`: {why}", name.text),
            )
            .at(span.clone()),
        );
    }
    Some(IrlCall {
        name,
        params,
        template,
        span,
    })
}

/// The `name` attribute of a `function-call` or `definition`; `E401` when missing or blank.
fn element_name(file: FileId, node: Node, what: &str, diags: &mut Diagnostics) -> Option<Name> {
    match node.attribute("name").filter(|n| !n.trim().is_empty()) {
        Some(n) => Some(Name::new(n, attr_span(file, node, "name"))),
        None => {
            diags.push(
                Diagnostic::error(Code::BadIrl, format!("<{what}> without a name attribute"))
                    .at(tag_span(file, node)),
            );
            None
        }
    }
}

/// The element's own text (its text and CDATA children, not the `<parameter>` elements'
/// content). Non-ASCII characters in `;` comments are transliterated (docs/LANGUAGES.md); elsewhere the
/// first one is `E602`.
fn element_text(
    file: FileId,
    source: &str,
    node: Node,
    name: &Name,
    diags: &mut Diagnostics,
) -> String {
    let mut body = String::new();
    let mut reported = false;
    let mut state = LexState::default();
    for t in node.children().filter(|c| c.is_text()) {
        let Some(s) = t.text() else { continue };
        let (clean, bad) = transliterate_comments(s, &mut state);
        body.push_str(&clean);
        let Some(i) = bad.filter(|_| !reported) else {
            continue;
        };
        reported = true;
        let range = t.range();
        let raw = source.get(range.clone()).unwrap_or("");
        let ch = s[i..].chars().next().unwrap_or('?');
        // Where the character stands in the file: the same offset when the text has no
        // references, else the first character reference (`&#228;`) that may have produced it.
        let (at, len) = if raw == s {
            (range.start + i, ch.len_utf8())
        } else {
            match raw.char_indices().find(|(_, c)| !c.is_ascii()) {
                Some((j, c)) => (range.start + j, c.len_utf8()),
                None => (range.start + raw.find("&#").unwrap_or(0), 1),
            }
        };
        diags.push(
            Diagnostic::error(
                Code::NonAscii,
                format!(
                    "non-ASCII character `{ch}` (U+{:04X}) in the code of `{}`",
                    ch as u32, name.text
                ),
            )
            .at(Span::new(file, at..at + len))
            .note("KRL code must be ASCII; only comments are transliterated"),
        );
    }
    body
}

/// Where a KRL line scan stands: inside a string literal, inside a `;` comment.
#[derive(Debug, Default)]
struct LexState {
    string: bool,
    comment: bool,
}

/// Transliterates non-ASCII characters inside `;` comments; returns the text and the byte index
/// (in `s`) of the first non-ASCII character outside comments.
fn transliterate_comments(s: &str, st: &mut LexState) -> (String, Option<usize>) {
    if s.is_ascii() {
        // Keep the state right for the next text node.
        for c in s.bytes() {
            step(c as char, st);
        }
        return (s.to_owned(), None);
    }
    let mut out = String::with_capacity(s.len());
    let mut bad = None;
    for (i, c) in s.char_indices() {
        if st.comment && !c.is_ascii() && c != '\n' {
            out.push_str(&crate::names::transliterate(&c.to_string()));
            continue;
        }
        if !c.is_ascii() && bad.is_none() {
            bad = Some(i);
        }
        step(c, st);
        out.push(c);
    }
    (out, bad)
}

fn step(c: char, st: &mut LexState) {
    match c {
        '\n' | '\r' => *st = LexState::default(),
        '"' if !st.comment => st.string = !st.string,
        ';' if !st.string => st.comment = true,
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// The original sample `kr15-2.irl`, byte for byte (tabs, LF).
    const KR15_2: &str = "<irl>\n\t<info name=\"KUKA KR15-2\"/>\n\t<def>\n\t\t<definition name=\"SetVelCP\">\n\t\t\t<parameter name=\"VALUE\"/>\n\t\t\tDEF SetVelCP(VALUE:IN)\n\t\t\t\tDECL REAL VALUE\n\t\t\t\t$VEL.CP = VALUE\n\t\t\t\tRETURN\n\t\t\tEND\n\t\t</definition>\n\t</def>\n\t<src>\n\t\t<function-call name=\"SetVelCP\">\n\t\t\t<parameter name=\"VALUE\"/>\n\t\t\tSetVelCP (VALUE)\n\t\t</function-call>\n\t\t<function-call name=\"PTP\">\n\t\t\t<parameter name=\"X\"/>\n\t\t\t<parameter name=\"Y\"/>\n\t\t\t<parameter name=\"Z\"/>\n\t\t\t<parameter name=\"A\"/>\n\t\t\t<parameter name=\"B\"/>\n\t\t\t<parameter name=\"C\"/>\n\t\t\tPTP {X, Y, Z, A, B, C}\n\t\t</function-call>\n\t\t<function-call name=\"LIN\">\n\t\t\t<parameter name=\"X\"/>\n\t\t\t<parameter name=\"Y\"/>\n\t\t\t<parameter name=\"Z\"/>\n\t\t\t<parameter name=\"A\"/>\n\t\t\t<parameter name=\"B\"/>\n\t\t\t<parameter name=\"C\"/>\n\t\t\tLIN {X, Y, Z, A, B, C}\n\t\t</function-call>\n\t</src>\n</irl>\n";

    fn read(text: &str) -> (Sources, Option<Irl>, Vec<Diagnostic>) {
        let mut sources = Sources::default();
        let id = sources.add(
            PathBuf::from("t.irl"),
            "t.irl".into(),
            text.to_owned(),
            false,
        );
        let mut diags = Diagnostics::default();
        let irl = read_irl(&sources, id, &mut diags);
        (sources, irl, diags.into_vec())
    }

    fn render(call: &IrlCall, values: &[&str]) -> String {
        let mut out = String::new();
        call.template.render(values, &mut out);
        out
    }

    fn codes(d: &[Diagnostic]) -> Vec<&'static str> {
        d.iter().map(|d| d.code.as_str()).collect()
    }

    fn spanned<'s>(sources: &'s Sources, d: &Diagnostic) -> &'s str {
        let s = d.span.as_ref().expect("a span");
        &sources.get(s.file).text[s.range.clone()]
    }

    #[test]
    fn reads_the_original_sample() {
        let (_, irl, diags) = read(KR15_2);
        assert!(diags.is_empty(), "{diags:?}");
        let irl = irl.unwrap();
        assert_eq!(irl.info.as_deref(), Some("KUKA KR15-2"));
        let names: Vec<&str> = irl.calls.iter().map(|c| c.name.text.as_ref()).collect();
        assert_eq!(names, ["SetVelCP", "PTP", "LIN"]);

        let set = &irl.calls[0];
        assert_eq!(&*set.name.key, "setvelcp");
        assert_eq!(&KR15_2[set.name.span.range.clone()], "SetVelCP");
        assert_eq!(set.params.len(), 1);
        assert_eq!(&*set.params[0].text, "VALUE");
        assert_eq!(&KR15_2[set.params[0].span.range.clone()], "VALUE");
        assert_eq!(render(set, &["0.5"]), "SetVelCP (0.5)");

        let ptp = &irl.calls[1];
        let p: Vec<&str> = ptp.params.iter().map(|p| p.text.as_ref()).collect();
        assert_eq!(p, ["X", "Y", "Z", "A", "B", "C"]);
        assert_eq!(
            render(ptp, &["100", "200", "300", "0", "90", "0"]),
            "PTP {X 100, Y 200, Z 300, A 0, B 90, C 0}"
        );
        assert!(ptp.template.used().iter().all(|u| *u));
        assert_eq!(
            render(&irl.calls[2], &["8", "8", "8", "0", "0", "0"]),
            "LIN {X 8, Y 8, Z 8, A 0, B 0, C 0}"
        );
        assert_eq!(&KR15_2[ptp.span.range.clone()], "<function-call");

        assert_eq!(irl.definitions.len(), 1);
        let d = &irl.definitions[0];
        assert_eq!(&*d.name.text, "SetVelCP");
        assert_eq!(
            d.lines,
            [
                "DEF SetVelCP(VALUE:IN)",
                "\tDECL REAL VALUE",
                "\t$VEL.CP = VALUE",
                "\tRETURN",
                "END"
            ]
        );
    }

    #[test]
    fn crlf_and_params_from_brackets() {
        let text = "<irl>\r\n<src>\r\n  <function-call name=\"ptp\">\r\n    PTP {X PX, Y PY}\r\n  </function-call>\r\n  <function-call name=\"Vel\">SetVel (V)</function-call>\r\n</src></irl>";
        let (_, irl, diags) = read(text);
        assert!(diags.is_empty(), "{diags:?}");
        let irl = irl.unwrap();
        assert!(irl.info.is_none());
        let ptp = &irl.calls[0];
        let p: Vec<&str> = ptp.params.iter().map(|p| p.text.as_ref()).collect();
        assert_eq!(p, ["PX", "PY"]);
        assert_eq!(&text[ptp.params[0].span.range.clone()], "<function-call");
        assert_eq!(render(ptp, &["1", "2"]), "PTP {X 1, Y 2}");
        assert_eq!(render(&irl.calls[1], &["3"]), "SetVel (3)");
    }

    #[test]
    fn overloads_kept_in_order_and_names_case_insensitive() {
        let text = r#"<irl><src>
            <function-call name="Move"><parameter name="a"/>M (A)</function-call>
            <function-call name=" MOVE "><parameter name="A"/><parameter name="B"/>M (a, b)</function-call>
        </src></irl>"#;
        let (_, irl, diags) = read(text);
        assert!(diags.is_empty(), "{diags:?}");
        let irl = irl.unwrap();
        assert_eq!(irl.calls.len(), 2);
        assert_eq!(irl.calls[0].name.key, irl.calls[1].name.key);
        assert_eq!(&*irl.calls[1].name.text, "MOVE");
        assert_eq!(irl.calls[0].template.param_count(), 1);
        assert_eq!(render(&irl.calls[1], &["1", "2"]), "M (1, 2)");
    }

    #[test]
    fn missing_src() {
        let text = "<irl>\n  <info name=\"x\"/>\n</irl>";
        let (sources, irl, diags) = read(text);
        assert_eq!(codes(&diags), ["E401"]);
        assert_eq!(diags[0].message, "IRL file has no <src> element");
        assert_eq!(spanned(&sources, &diags[0]), "<irl");
        let irl = irl.unwrap();
        assert!(irl.calls.is_empty());
        assert_eq!(irl.info.as_deref(), Some("x"));
    }

    #[test]
    fn wrong_root() {
        let (sources, irl, diags) = read("<?xml version=\"1.0\"?>\n<CAEXFile><src/></CAEXFile>");
        assert!(irl.is_none());
        assert_eq!(codes(&diags), ["E103"]);
        assert_eq!(spanned(&sources, &diags[0]), "<CAEXFile");
        // `IRL` is not `irl`: element names match exactly.
        let (_, irl, diags) = read("<IRL><src/></IRL>");
        assert!(irl.is_none());
        assert_eq!(codes(&diags), ["E103"]);
    }

    #[test]
    fn not_xml() {
        let (_, irl, diags) = read("<irl><src></irl>");
        assert!(irl.is_none());
        assert_eq!(codes(&diags), ["E102"]);
    }

    #[test]
    fn non_ascii_position() {
        let text = "<irl>\n<src>\n  <function-call name=\"Grüß\">\n    <parameter name=\"V\"/>\n    MSG (V) ; ok\n    X = \"Größe\"\n  </function-call>\n</src>\n</irl>";
        let (sources, irl, diags) = read(text);
        assert_eq!(codes(&diags), ["E602"]);
        assert_eq!(spanned(&sources, &diags[0]), "ö");
        let start = diags[0].span.as_ref().unwrap().range.start;
        // Line 6 `    X = "Größe"`: `ö` is the 12th character.
        assert_eq!(sources.line_col(0, start), (6, 12));
        // Reported once per template, and the call is kept.
        let irl = irl.unwrap();
        assert_eq!(irl.calls.len(), 1);
        assert_eq!(&*irl.calls[0].name.text, "Grüß");

        // In a definition, and through a character reference.
        let text =
            "<irl><def><definition name=\"d\">\n  A = &#228;\n</definition></def><src/></irl>";
        let (sources, _, diags) = read(text);
        assert_eq!(codes(&diags), ["E602"]);
        assert!(diags[0].message.contains('ä'), "{}", diags[0].message);
        let start = diags[0].span.as_ref().unwrap().range.start;
        assert_eq!(sources.line_col(0, start), (2, 7));
    }

    #[test]
    fn function_call_without_name_is_skipped() {
        let text = "<irl><src>\n<function-call>PTP {X}</function-call>\n<function-call name=\"  \"><parameter name=\"X\"/>A</function-call>\n<function-call name=\"LIN\">LIN {X}</function-call>\n</src>\n<def><definition>D</definition></def></irl>";
        let (sources, irl, diags) = read(text);
        assert_eq!(codes(&diags), ["E401", "E401", "E401"]);
        for d in &diags {
            assert!(d.message.contains("without a name"), "{}", d.message);
        }
        // The definition comes first: `def` is read before `src`.
        assert_eq!(spanned(&sources, &diags[0]), "<definition");
        assert_eq!(spanned(&sources, &diags[1]), "<function-call");
        assert_eq!(
            sources.line_col(0, diags[1].span.as_ref().unwrap().range.start),
            (2, 1)
        );
        assert_eq!(
            sources.line_col(0, diags[2].span.as_ref().unwrap().range.start),
            (3, 1)
        );
        let irl = irl.unwrap();
        assert_eq!(irl.calls.len(), 1);
        assert_eq!(&*irl.calls[0].name.text, "LIN");
        assert!(irl.definitions.is_empty());
    }

    #[test]
    fn empty_template_and_bad_parameters() {
        let text = "<irl><src>\n<function-call name=\"E\">\n  \n</function-call>\n<function-call name=\"P\"><parameter/><parameter name=\"A\"/><parameter name=\"a\"/>F (A)</function-call>\n</src></irl>";
        let (sources, irl, diags) = read(text);
        assert_eq!(codes(&diags), ["E401", "E401", "E401"]);
        assert!(diags[0].message.contains("empty template"));
        assert!(diags[1].message.contains("no name"));
        assert_eq!(spanned(&sources, &diags[1]), "<parameter");
        assert!(diags[2].message.contains("twice"));
        assert_eq!(spanned(&sources, &diags[2]), "a");
        let irl = irl.unwrap();
        assert_eq!(irl.calls.len(), 2);
        assert_eq!(irl.calls[1].params.len(), 2);
    }

    #[test]
    fn template_text_excludes_other_nodes() {
        // Comments and the parameters' own content are not template text; CDATA is.
        let text = "<irl><src><function-call name=\"F\"><parameter name=\"V\">junk</parameter><!-- c -->\n  <![CDATA[IF V < 1 THEN]]>\n  ENDIF\n</function-call></src></irl>";
        let (_, irl, diags) = read(text);
        assert!(diags.is_empty(), "{diags:?}");
        assert_eq!(
            render(&irl.unwrap().calls[0], &["2"]),
            "IF 2 < 1 THEN\nENDIF"
        );
    }

    #[test]
    fn non_ascii_in_comments_is_transliterated() {
        let text = "<irl><src><function-call name=\"W\"><parameter name=\"T\"/>\n  WAIT SEC T ; Wartezeit für Übergabe\n  MSG \"a;ä\" ; ok\n</function-call></src></irl>";
        let (sources, irl, diags) = read(text);
        let irl = irl.unwrap();
        // The `ä` inside the string literal is code: E602 at its place.
        assert_eq!(codes(&diags), vec!["E602"]);
        assert_eq!(spanned(&sources, &diags[0]), "ä");
        let out = render(&irl.calls[0], &["2"]);
        assert!(
            out.starts_with("WAIT SEC 2 ; Wartezeit fuer Uebergabe\n"),
            "{out}"
        );
    }
}
