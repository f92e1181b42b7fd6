//! The KUKA KRL profile: `<program>.src` and `<program>.dat` (SPEC.md section 5).
//!
//! The fixed text (header, initialisation, closing) comes from an [`OutputTemplate`]: the
//! built-in `templates/krl.toml` or the user's copy.

use std::fmt::Write as _;

use serde::Deserialize;

use super::{EmitInput, OutputFile};
use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::model::{ElementKind, Signal, SignalKind};
use crate::names::transliterate;
use crate::plan::{Block, Branch, BranchEnd};

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
    let mut writer = Writer {
        input,
        template,
        number: 0,
        uses_branch_var: false,
    };
    for line in template.src.lines() {
        match block(line) {
            Some("steps") => {
                writer.blocks(&input.plan.body, 0, &mut src);
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
    let decls = declarations(input, writer.uses_branch_var);
    if !decls.is_empty()
        && !template
            .dat
            .lines()
            .any(|l| block(l) == Some("declarations"))
    {
        // The program would use names nothing declares.
        diags.push(Diagnostic::error(
            Code::BadTemplate,
            format!(
                "output template: the program needs declarations in its .dat ({}), but `dat` has no `{{{{declarations}}}}` line",
                decls.join("; ")
            ),
        ));
        return None;
    }
    for line in template.dat.lines() {
        match block(line) {
            Some("declarations") => {
                for d in &decls {
                    dat.push_str(d);
                    dat.push_str(nl);
                }
            }
            Some(_) => {}
            None => {
                dat.push_str(&inline(line));
                dat.push_str(nl);
            }
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

/// The `.dat` variable that holds the branch a selection without an unconditional branch chose.
pub const BRANCH_VAR: &str = "SKP_BRANCH";

/// Writes the program tree.
struct Writer<'a> {
    input: &'a EmitInput<'a>,
    template: &'a OutputTemplate,
    number: usize,
    /// Whether a selection needed [`BRANCH_VAR`].
    uses_branch_var: bool,
}

impl Writer<'_> {
    fn line(&self, out: &mut String, level: usize, text: &str) {
        for _ in 0..level {
            out.push_str("  ");
        }
        out.push_str(text);
        out.push_str(self.input.newline);
    }

    /// A comment line; its text transliterated to ASCII on one line.
    fn comment(&self, out: &mut String, level: usize, text: &str) {
        self.line(out, level, &format!(";{}", transliterate(text)));
    }

    /// The KRL condition of a transition; `None` when it always fires.
    fn condition(&self, t: usize) -> Option<String> {
        let ElementKind::Transition(Some(c)) = &self.input.sfc.elements[t].kind else {
            return None;
        };
        let res = self
            .input
            .bound
            .resource
            .map(|r| &self.input.blackboard.resources[r]);
        let signal = |n: &str| -> String {
            let Some(r) = res else {
                return n.to_owned();
            };
            let Some(si) = r.signal(&crate::names::key(n)) else {
                return n.to_owned();
            };
            krl_signal(&r.signals[si])
        };
        Some(crate::cond::render_krl(&c.expr, &signal))
    }

    /// The condition as written, for comments: on one line, without `;` (which would start a
    /// comment inside the comment, and could look like a fold marker).
    fn condition_text(&self, t: usize) -> String {
        match &self.input.sfc.elements[t].kind {
            ElementKind::Transition(Some(c)) => c
                .text
                .replace(';', ",")
                .split_whitespace()
                .collect::<Vec<_>>()
                .join(" "),
            _ => "TRUE".to_owned(),
        }
    }

    fn blocks(&mut self, blocks: &[Block], level: usize, out: &mut String) {
        for b in blocks {
            self.block(b, level, out);
        }
    }

    fn block(&mut self, b: &Block, level: usize, out: &mut String) {
        let input = self.input;
        let nl = input.newline;
        let el = &input.sfc.elements;
        match b {
            Block::Step(i) => {
                let Some(bs) = &input.bound.steps[*i] else {
                    return;
                };
                let e = &el[*i];
                let ElementKind::Step(st) = &e.kind else {
                    return;
                };
                self.number += 1;
                let res = &input.blackboard.resources[bs.resource];
                let skill = &res.skills[bs.skill];
                let ascii =
                    st.name.is_ascii() && skill.name.text.is_ascii() && res.name.text.is_ascii();
                for _ in 0..level {
                    out.push_str("  ");
                }
                let title_at = out.len();
                let _ = write!(
                    out,
                    ";FOLD {} {}: {} @ {} (localId {})",
                    self.number, st.name, skill.name.text, res.name.text, e.local_id
                );
                if !ascii || out[title_at..].contains(['\r', '\n']) {
                    let title = transliterate(&out[title_at..]);
                    out.truncate(title_at);
                    out.push_str(&title);
                }
                out.push_str(nl);
                for line in bs.code.split('\n') {
                    if !line.is_empty() {
                        for _ in 0..level {
                            out.push_str("  ");
                        }
                        out.push_str(&self.template.step_indent);
                        out.push_str(line);
                    }
                    out.push_str(nl);
                }
                self.line(out, level, ";ENDFOLD");
            }
            Block::Wait(t) => {
                if let Some(c) = self.condition(*t) {
                    self.comment(
                        out,
                        level,
                        &format!(
                            "transition localId {}: {}",
                            el[*t].local_id,
                            self.condition_text(*t)
                        ),
                    );
                    self.line(out, level, &format!("WAIT FOR {c}"));
                }
            }
            Block::Parallel { branches, .. } => {
                for br in branches {
                    self.blocks(br, level, out);
                }
            }
            Block::Choice {
                divergence,
                branches,
                ..
            } => self.choice(*divergence, branches, level, out),
            Block::Loop {
                head,
                jumps,
                body,
                endless,
            } => {
                let ids: Vec<String> = jumps.iter().map(|j| el[*j].local_id.to_string()).collect();
                self.comment(
                    out,
                    level,
                    &format!(
                        "loop back to step localId {} (jump localId {}){}",
                        el[*head].local_id,
                        ids.join(", "),
                        if *endless { ", endless" } else { "" }
                    ),
                );
                self.line(out, level, "LOOP");
                self.blocks(body, level + 1, out);
                self.line(out, level, "ENDLOOP");
            }
        }
    }

    /// A branch's body and how it ends.
    fn branch(&mut self, n: usize, br: &Branch, level: usize, out: &mut String) {
        let el = &self.input.sfc.elements;
        self.comment(
            out,
            level,
            &format!(
                "branch {n} (transition localId {}): {}",
                el[br.transition].local_id,
                self.condition_text(br.transition)
            ),
        );
        self.blocks(&br.body, level, out);
        match br.end {
            BranchEnd::Join => {}
            BranchEnd::Repeat(j) => self.comment(
                out,
                level,
                &format!("round again (jump localId {})", el[j].local_id),
            ),
            BranchEnd::Leave => self.line(out, level, "EXIT"),
        }
    }

    /// Selection branches in priority order. With an unconditional branch: an `IF` chain whose
    /// last `ELSE` is that branch. Without: the program waits for any condition, records the
    /// first that holds in [`BRANCH_VAR`] (testing again if none holds any more) and then runs
    /// that branch, so it never passes the selection without taking a branch.
    fn choice(&mut self, div: usize, branches: &[Branch], level: usize, out: &mut String) {
        let el = &self.input.sfc.elements;
        let conds: Vec<Option<String>> = branches
            .iter()
            .map(|b| self.condition(b.transition))
            .collect();
        self.comment(
            out,
            level,
            &format!(
                "selection localId {}: {} branches, the first whose condition holds",
                el[div].local_id,
                branches.len()
            ),
        );
        if let Some(k) = conds.iter().position(Option::is_none) {
            // Branches after an unconditional one are never taken.
            for (n, br) in branches.iter().enumerate().take(k) {
                let c = conds[n].as_deref().expect("conditional");
                self.line(out, level + n, &format!("IF {c} THEN"));
                self.branch(n + 1, br, level + n + 1, out);
                self.line(out, level + n, "ELSE");
            }
            self.branch(k + 1, &branches[k], level + k, out);
            for n in (0..k).rev() {
                self.line(out, level + n, "ENDIF");
            }
            return;
        }
        self.uses_branch_var = true;
        let any: Vec<String> = conds
            .iter()
            .map(|c| format!("({})", c.as_deref().unwrap_or("TRUE")))
            .collect();
        self.line(out, level, &format!("{BRANCH_VAR} = 0"));
        self.line(out, level, "REPEAT");
        self.line(out, level + 1, &format!("WAIT FOR {}", any.join(" OR ")));
        for (n, c) in conds.iter().enumerate() {
            let c = c.as_deref().unwrap_or("TRUE");
            self.line(out, level + 1 + n, &format!("IF {c} THEN"));
            self.line(out, level + 2 + n, &format!("{BRANCH_VAR} = {}", n + 1));
            if n + 1 < conds.len() {
                self.line(out, level + 1 + n, "ELSE");
            }
        }
        for n in (0..conds.len()).rev() {
            self.line(out, level + 1 + n, "ENDIF");
        }
        self.line(out, level, &format!("UNTIL {BRANCH_VAR} <> 0"));
        self.line(out, level, &format!("SWITCH {BRANCH_VAR}"));
        for (n, br) in branches.iter().enumerate() {
            if n + 1 < branches.len() {
                self.line(out, level, &format!("CASE {}", n + 1));
            } else {
                self.line(out, level, "DEFAULT");
            }
            self.branch(n + 1, br, level + 1, out);
        }
        self.line(out, level, "ENDSWITCH");
    }
}

/// A signal in KRL: `$IN[n]`/`$OUT[n]` for a bit, the `SIGNAL` name for an integer group, the
/// `Address` as it stands.
pub fn krl_signal(s: &Signal) -> String {
    let io = if s.output { "$OUT" } else { "$IN" };
    match &s.kind {
        SignalKind::Bit(n) => format!("{io}[{n}]"),
        SignalKind::Group { .. } => s.name.text.to_string(),
        SignalKind::Address { text, .. } => text.clone(),
    }
}

/// The `.dat` declarations: `SIGNAL`s for the integer groups the conditions use, and the
/// selection variable when a selection needs it.
fn declarations(input: &EmitInput, uses_branch_var: bool) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(r) = input.bound.resource {
        let res = &input.blackboard.resources[r];
        for &si in &input.bound.signals {
            let s = &res.signals[si];
            if let SignalKind::Group { number, length } = s.kind {
                let io = if s.output { "$OUT" } else { "$IN" };
                out.push(format!(
                    "SIGNAL {} {io}[{number}] TO {io}[{}]",
                    s.name.text,
                    number + length - 1
                ));
            }
        }
    }
    if uses_branch_var {
        out.push(format!("DECL INT {BRANCH_VAR}=0"));
    }
    out
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
