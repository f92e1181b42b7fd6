//! The KUKA KRL profile: `<program>.src` and `<program>.dat` (SPEC.md section 5).
//!
//! The fixed text (header, initialisation, closing) comes from an [`OutputTemplate`]: the
//! built-in `templates/krl.toml` or the user's copy.

use std::fmt::Write as _;

use serde::Deserialize;

use super::{EmitInput, OutputFile};
use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::model::ElementKind;
use crate::names::transliterate;
use crate::plan::Block;

/// The built-in template's text.
pub const DEFAULT_TEMPLATE: &str = include_str!("../../templates/krl.toml");

/// A KRL output template.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputTemplate {
    pub step_indent: String,
    pub src: String,
    pub dat: String,
}

const INLINE: &[&str] = &["program", "comment"];
const SRC_BLOCKS: &[&str] = &["steps", "definitions"];
const DAT_BLOCKS: &[&str] = &["declarations"];

impl OutputTemplate {
    /// The built-in template.
    pub fn builtin() -> Self {
        let mut sources = Sources::default();
        let file = sources.add(
            "templates/krl.toml".into(),
            "<built-in template>".into(),
            DEFAULT_TEMPLATE.to_owned(),
            false,
        );
        let mut d = Diagnostics::default();
        Self::parse(&sources, file, &mut d).expect("the built-in template is valid")
    }

    /// Parses and checks a template file.
    pub fn parse(sources: &Sources, file: FileId, diags: &mut Diagnostics) -> Option<Self> {
        let text = &sources.get(file).text;
        let t: OutputTemplate = match toml::from_str(text) {
            Ok(t) => t,
            Err(e) => {
                let range = e.span().unwrap_or(0..0);
                diags.push(
                    Diagnostic::error(
                        Code::BadTemplate,
                        format!("output template: {}", e.message()),
                    )
                    .at(Span::new(file, range)),
                );
                return None;
            }
        };
        let mut ok = true;
        let mut bad = |msg: String, needle: &str| {
            let at = text.find(needle).unwrap_or(0);
            diags.push(
                Diagnostic::error(Code::BadTemplate, format!("output template: {msg}"))
                    .at(Span::new(file, at..at + needle.len().max(1))),
            );
            ok = false;
        };
        for (key, body, blocks) in [("src", &t.src, SRC_BLOCKS), ("dat", &t.dat, DAT_BLOCKS)] {
            if let Some(pos) = body.find(|c: char| !c.is_ascii()) {
                let c = body[pos..].chars().next().unwrap_or('?');
                bad(
                    format!("`{key}` contains the non-ASCII character `{c}`"),
                    &c.to_string(),
                );
            }
            for name in placeholders(body) {
                if INLINE.contains(&name) {
                    continue;
                }
                if blocks.contains(&name) {
                    let marker = format!("{{{{{name}}}}}");
                    if !body.lines().any(|l| l.trim() == marker) {
                        bad(
                            format!("`{marker}` must stand on a line of its own in `{key}`"),
                            &marker,
                        );
                    }
                } else {
                    bad(
                        format!("unknown placeholder `{{{{{name}}}}}` in `{key}`"),
                        &format!("{{{{{name}}}}}"),
                    );
                }
            }
        }
        let steps = t.src.lines().filter(|l| l.trim() == "{{steps}}").count();
        if steps != 1 {
            bad(
                format!("`src` must hold `{{{{steps}}}}` exactly once (found {steps})"),
                "src",
            );
        }
        if !t.step_indent.chars().all(|c| c == ' ' || c == '\t') {
            bad(
                "`step_indent` may only hold spaces and tabs".to_owned(),
                "step_indent",
            );
        }
        ok.then_some(t)
    }
}

/// The `name`s of `{{name}}` in `text`.
fn placeholders(text: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("{{") {
        let after = &rest[i + 2..];
        match after.find("}}") {
            Some(j) => {
                out.push(after[..j].trim());
                rest = &after[j + 2..];
            }
            None => break,
        }
    }
    out
}

/// The `&COMMENT` line from the SFC's file header.
pub fn header_comment(h: &crate::model::FileHeader) -> String {
    let parts = [
        ("Company name", &h.company_name),
        ("Product name", &h.product_name),
        ("Product version", &h.product_version),
        ("Creation time", &h.creation_date_time),
    ];
    let s: Vec<String> = parts
        .iter()
        .filter_map(|(k, v)| v.as_ref().map(|v| format!("{k}: {}", v.trim())))
        .collect();
    transliterate(&s.join(" "))
}

/// Emits `.src` and `.dat`.
pub fn emit(
    input: &EmitInput,
    template: &OutputTemplate,
    diags: &mut Diagnostics,
) -> Option<Vec<OutputFile>> {
    let nl = input.newline;
    let comment = header_comment(&input.sfc.header);
    let inline = |line: &str| {
        line.replace("{{program}}", input.program)
            .replace("{{comment}}", &comment)
    };

    // The placeholder lines' blocks are written straight into the output.
    let block = block_name;
    let steps_estimate = input
        .bound
        .steps
        .iter()
        .flatten()
        .map(|b| b.code.len() + 80)
        .sum::<usize>();
    let mut src = String::with_capacity(template.src.len() + steps_estimate + 1024);
    for line in template.src.lines() {
        match block(line) {
            Some("steps") => {
                let mut number = 0usize;
                emit_blocks(input, template, &input.plan.body, &mut number, &mut src);
            }
            Some("definitions") => {
                for &(irl, d) in &input.bound.definitions {
                    let def = &input.irls[irl].definitions[d];
                    src.push_str(nl);
                    for l in &def.lines {
                        src.push_str(l);
                        src.push_str(nl);
                    }
                }
            }
            Some(_) => {}
            None => {
                src.push_str(&inline(line));
                src.push_str(nl);
            }
        }
    }
    let mut dat = String::with_capacity(template.dat.len() + 256);
    for line in template.dat.lines() {
        // No declarations yet: the block is empty.
        if block(line).is_none() {
            dat.push_str(&inline(line));
            dat.push_str(nl);
        }
    }

    for (ext, text) in [("src", &src), ("dat", &dat)] {
        if let Some(pos) = text.find(|c: char| !c.is_ascii()) {
            // Values and templates are checked before; this is the last line of defence.
            diags.push(Diagnostic::error(
                Code::NonAscii,
                format!(
                    "generated .{ext} would contain a non-ASCII character at byte {pos}; nothing was written"
                ),
            ));
            return None;
        }
    }
    Some(vec![
        OutputFile {
            extension: "src",
            text: src,
        },
        OutputFile {
            extension: "dat",
            text: dat,
        },
    ])
}

/// The block placeholder a template line holds, if it is one.
fn block_name(line: &str) -> Option<&str> {
    let t = line.trim();
    t.strip_prefix("{{")
        .and_then(|r| r.strip_suffix("}}"))
        .filter(|n| matches!(*n, "steps" | "definitions" | "declarations"))
}

fn emit_blocks(
    input: &EmitInput,
    template: &OutputTemplate,
    blocks: &[Block],
    number: &mut usize,
    out: &mut String,
) {
    let nl = input.newline;
    for b in blocks {
        match b {
            Block::Step(i) => {
                let Some(bs) = &input.bound.steps[*i] else {
                    continue;
                };
                let e = &input.sfc.elements[*i];
                let ElementKind::Step(st) = &e.kind else {
                    continue;
                };
                *number += 1;
                let res = &input.blackboard.resources[bs.resource];
                let skill = &res.skills[bs.skill];
                let ascii =
                    st.name.is_ascii() && skill.name.text.is_ascii() && res.name.text.is_ascii();
                let title_at = out.len();
                let _ = write!(
                    out,
                    ";FOLD {} {}: {} @ {} (localId {})",
                    number, st.name, skill.name.text, res.name.text, e.local_id
                );
                if !ascii || out[title_at..].contains(['\r', '\n']) {
                    let title = transliterate(&out[title_at..]);
                    out.truncate(title_at);
                    out.push_str(&title);
                }
                out.push_str(nl);
                for line in bs.code.split('\n') {
                    if !line.is_empty() {
                        out.push_str(&template.step_indent);
                        out.push_str(line);
                    }
                    out.push_str(nl);
                }
                out.push_str(";ENDFOLD");
                out.push_str(nl);
            }
            Block::Parallel { branches, .. } => {
                for br in branches {
                    emit_blocks(input, template, br, number, out);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_template_parses() {
        let t = OutputTemplate::builtin();
        assert!(t.src.contains("{{steps}}"));
    }

    fn parse(text: &str) -> (Option<OutputTemplate>, Vec<String>) {
        let mut s = Sources::default();
        let f = s.add("t.toml".into(), "t.toml".into(), text.to_owned(), false);
        let mut d = Diagnostics::default();
        let t = OutputTemplate::parse(&s, f, &mut d);
        (t, d.iter().map(|d| d.message.clone()).collect())
    }

    #[test]
    fn template_errors() {
        let (t, m) = parse("step_indent = \" \"\nsrc = \"DEF x\"\ndat = \"\"\n");
        assert!(t.is_none());
        assert!(m[0].contains("exactly once"), "{m:?}");
        let (t, m) =
            parse("step_indent = \" \"\nsrc = \"\"\"\n{{steps}}\n{{oops}}\n\"\"\"\ndat = \"\"\n");
        assert!(t.is_none());
        assert!(m[0].contains("unknown placeholder `{{oops}}`"), "{m:?}");
        let (t, m) =
            parse("step_indent = \" \"\nsrc = \"\"\"\n{{steps}}\n\"\"\"\ndat = \"\"\nextra = 1\n");
        assert!(t.is_none());
        assert!(m[0].contains("unknown field"), "{m:?}");
    }
}
