//! The ABB RAPID profile: one module, `<program>.mod` (SPEC.md 8).
//!
//! The program is `PROC main()` of `MODULE <program>`; IRL definitions become the module's
//! routines. Written so `rapidchecker` accepts it: two spaces per level, keywords upper case, no
//! labels and one value per `CASE`: a loop is a `WHILE` left through a flag (`skp_loopN`, the
//! rest of the body after a branch that leaves skipped by `IF skp_loopN THEN`), and a selection
//! without an unconditional branch records its branch in `skp_branch` first.

use std::borrow::Cow;

use super::flow::{self, Lines};
use super::{EmitInput, Generated, Language, Profile};
use crate::cond::{BinOp, Ops};
use crate::diag::Diagnostics;
use crate::model::{Signal, SignalKind};
use crate::plan::{Block, Branch, BranchEnd};
use crate::template::Syntax;
use crate::value::Literal;

/// The built-in template's text.
pub const DEFAULT_TEMPLATE: &str = include_str!("../../templates/rapid.toml");

/// RAPID's reserved words (the RAPID reference manual's list).
const RESERVED: &[&str] = &[
    "ALIAS",
    "AND",
    "BACKWARD",
    "CASE",
    "CONNECT",
    "CONST",
    "DEFAULT",
    "DIV",
    "DO",
    "ELSE",
    "ELSEIF",
    "ENDFOR",
    "ENDFUNC",
    "ENDIF",
    "ENDMODULE",
    "ENDPROC",
    "ENDRECORD",
    "ENDTEST",
    "ENDTRAP",
    "ENDWHILE",
    "ERROR",
    "EXIT",
    "FALSE",
    "FOR",
    "FROM",
    "FUNC",
    "GOTO",
    "IF",
    "INOUT",
    "LOCAL",
    "MOD",
    "MODULE",
    "NOSTEPIN",
    "NOT",
    "NOVIEW",
    "OR",
    "PERS",
    "PROC",
    "RAISE",
    "READONLY",
    "RECORD",
    "RETRY",
    "RETURN",
    "STEP",
    "SYSMODULE",
    "TEST",
    "THEN",
    "TO",
    "TRAP",
    "TRUE",
    "TRYNEXT",
    "UNDO",
    "VAR",
    "VIEWONLY",
    "WHILE",
    "WITH",
    "XOR",
];

/// The longest RAPID name.
const MAX_NAME: usize = 32;
/// The longest RAPID string.
const MAX_STRING: usize = 80;

/// The variable that holds the branch a selection without an unconditional branch chose.
pub const BRANCH_VAR: &str = "skp_branch";

fn is_reserved(w: &str) -> bool {
    RESERVED.iter().any(|r| r.eq_ignore_ascii_case(w))
}

/// A RAPID name: a letter, then letters, digits or `_`, at most 32 characters.
fn is_rapid_name(w: &str) -> bool {
    let b = w.as_bytes();
    !b.is_empty()
        && b.len() <= MAX_NAME
        && b[0].is_ascii_alphabetic()
        && b.iter().all(|c| c.is_ascii_alphanumeric() || *c == b'_')
}

const OPS: Ops = Ops {
    op: rapid_op,
    not: "NOT ",
    true_: "TRUE",
    false_: "FALSE",
};

fn rapid_op(op: BinOp) -> &'static str {
    match op {
        BinOp::Or => "OR",
        BinOp::Xor => "XOR",
        BinOp::And => "AND",
        BinOp::Eq => "=",
        BinOp::Ne => "<>",
        BinOp::Lt => "<",
        BinOp::Gt => ">",
        BinOp::Le => "<=",
        BinOp::Ge => ">=",
    }
}

/// The RAPID profile.
pub struct Rapid;

impl Profile for Rapid {
    fn language(&self) -> Language {
        Language::Rapid
    }

    fn files(&self) -> &'static [&'static str] {
        &["mod"]
    }

    fn builtin_template(&self) -> &'static str {
        DEFAULT_TEMPLATE
    }

    fn syntax(&self) -> Syntax {
        Syntax {
            comment: b'!',
            aggregates: false,
            case_sensitive: false,
        }
    }

    fn check_program_name(&self, name: &str) -> Result<(), String> {
        if !is_rapid_name(name) {
            Err(format!(
                "not a RAPID name: a letter, then letters, digits or `_`, at most {MAX_NAME} characters"
            ))
        } else if is_reserved(name) {
            Err("a RAPID reserved word cannot name a module".to_owned())
        } else {
            Ok(())
        }
    }

    fn literal<'v>(&self, v: &Literal<'v>) -> Result<Cow<'v, str>, String> {
        Ok(match v {
            Literal::Number(n) => n.clone(),
            Literal::Bool(true) => Cow::Borrowed("TRUE"),
            Literal::Bool(false) => Cow::Borrowed("FALSE"),
            Literal::Str(s) => {
                if s.contains('\\') {
                    return Err("a RAPID string value must not contain `\\`".to_owned());
                }
                if s.len() > MAX_STRING {
                    return Err(format!(
                        "a RAPID string holds at most {MAX_STRING} characters, this one {}",
                        s.len()
                    ));
                }
                Cow::Owned(format!("\"{s}\""))
            }
            Literal::Word(w) => {
                if !is_rapid_name(w) {
                    return Err(format!(
                        "`{w}` is not a RAPID name (a letter, then letters, digits or `_`, at most {MAX_NAME} characters)"
                    ));
                }
                if is_reserved(w) {
                    return Err(format!(
                        "`{w}` is a RAPID reserved word: as a value it would become code"
                    ));
                }
                Cow::Borrowed(*w)
            }
        })
    }

    fn signal(&self, s: &Signal) -> Result<String, String> {
        match &s.kind {
            SignalKind::Address { text, integer } => {
                if !is_rapid_name(text) || is_reserved(text) {
                    return Err(format!(
                        "RAPID reads a signal by its configured name, and Address `{text}` is not a RAPID name"
                    ));
                }
                Ok(if *integer {
                    text.clone()
                } else {
                    format!("{text} = 1")
                })
            }
            SignalKind::Bit(_) | SignalKind::Group { .. } => Err(
                "RAPID reads a signal by the name it is configured under: give the signal an `Address` with that name (`di_Part`, `gi_Type`)".to_owned(),
            ),
        }
    }

    fn trim_trailing_spaces(&self) -> bool {
        true
    }

    /// Data declarations (`PERS`, `VAR`, `CONST`, maybe after `LOCAL`/`TASK`) before routines:
    /// RAPID wants a module's data before its routines.
    fn definition_rank(&self, first_line: &str) -> u8 {
        let mut words = first_line.split_whitespace().map(str::to_ascii_uppercase);
        let mut w = words.next().unwrap_or_default();
        if w == "LOCAL" || w == "TASK" {
            w = words.next().unwrap_or_default();
        }
        if matches!(w.as_str(), "PERS" | "VAR" | "CONST") {
            0
        } else {
            1
        }
    }

    fn generate(&self, input: &EmitInput, _diags: &mut Diagnostics) -> Option<Generated> {
        let mut w = Writer {
            input,
            out: Lines::new(input, flow::steps_estimate(input)),
            number: 0,
            uses_branch_var: false,
            flags: 0,
            loops: Vec::new(),
        };
        w.blocks(&input.plan.body, 0);
        let mut declarations = Vec::new();
        if w.uses_branch_var {
            declarations.push(format!("VAR num {BRANCH_VAR} := 0;"));
        }
        for n in 1..=w.flags {
            declarations.push(format!("VAR bool skp_loop{n} := TRUE;"));
        }
        Some(Generated {
            steps: w.out.out,
            declarations,
        })
    }
}

/// `WaitUntil c;`, the condition in parentheses when it starts with one: an instruction whose
/// first argument starts with `(` reads as a function call (`WaitUntil (a) OR (b);` is refused
/// by `rapidchecker`).
fn wait_until(c: &str) -> String {
    if c.starts_with('(') {
        format!("WaitUntil ({c});")
    } else {
        format!("WaitUntil {c};")
    }
}

/// Whether `b` leaves the loop it stands in (a branch ending in a leave, not inside a nested
/// loop, whose leaves are that loop's).
fn may_leave(b: &Block) -> bool {
    match b {
        Block::Choice { branches, .. } => branches
            .iter()
            .any(|br| br.end == BranchEnd::Leave || br.body.iter().any(may_leave)),
        Block::Parallel { branches, .. } => branches.iter().flatten().any(may_leave),
        Block::Step(_) | Block::Wait(_) | Block::Loop { .. } => false,
    }
}

struct Writer<'a> {
    input: &'a EmitInput<'a>,
    out: Lines<'a>,
    number: usize,
    uses_branch_var: bool,
    /// Loop flags used so far.
    flags: usize,
    /// The flag of each enclosing loop (`None`: endless, never left).
    loops: Vec<Option<String>>,
}

impl Writer<'_> {
    fn comment(&mut self, level: usize, text: &str) {
        self.out
            .line(level, &format!("! {}", flow::comment_text(text)));
    }

    /// A list of blocks; after one that may leave the loop, the rest only while its flag holds.
    fn blocks(&mut self, blocks: &[Block], level: usize) {
        let mut level = level;
        let mut open = 0;
        for (k, b) in blocks.iter().enumerate() {
            self.block(b, level);
            if k + 1 < blocks.len()
                && may_leave(b)
                && let Some(Some(flag)) = self.loops.last().cloned()
            {
                self.out.line(level, &format!("IF {flag} THEN"));
                level += 1;
                open += 1;
            }
        }
        for _ in 0..open {
            level -= 1;
            self.out.line(level, "ENDIF");
        }
    }

    fn block(&mut self, b: &Block, level: usize) {
        let input = self.input;
        let el = &input.sfc.elements;
        match b {
            Block::Step(i) => {
                let Some(bs) = &input.bound.steps[*i] else {
                    return;
                };
                self.number += 1;
                let title = flow::step_title(input, *i, bs, self.number);
                self.out.line(level, &format!("! step {title}"));
                self.out.code(level, input.step_indent, &bs.code);
            }
            Block::Wait(t) => {
                if let Some(c) = flow::condition(input, *t, &OPS) {
                    let text = flow::condition_text(input, *t);
                    self.comment(
                        level,
                        &format!("transition localId {}: {text}", el[*t].local_id),
                    );
                    self.out.line(level, &wait_until(&c));
                }
            }
            Block::Parallel { branches, .. } => {
                // One after another; after a branch that may leave, the rest only while the
                // loop goes on.
                let mut lvl = level;
                let mut open = 0;
                for (k, br) in branches.iter().enumerate() {
                    self.blocks(br, lvl);
                    if k + 1 < branches.len()
                        && br.iter().any(may_leave)
                        && let Some(Some(flag)) = self.loops.last().cloned()
                    {
                        self.out.line(lvl, &format!("IF {flag} THEN"));
                        lvl += 1;
                        open += 1;
                    }
                }
                for _ in 0..open {
                    lvl -= 1;
                    self.out.line(lvl, "ENDIF");
                }
            }
            Block::Choice {
                divergence,
                branches,
                ..
            } => self.choice(*divergence, branches, level),
            Block::Loop {
                head,
                jumps,
                body,
                endless,
            } => {
                self.comment(
                    level,
                    &format!(
                        "loop back to step localId {} (jump localId {}){}",
                        el[*head].local_id,
                        flow::local_ids(input, jumps),
                        if *endless { ", endless" } else { "" }
                    ),
                );
                if *endless {
                    self.loops.push(None);
                    self.out.line(level, "WHILE TRUE DO");
                } else {
                    self.flags += 1;
                    let flag = format!("skp_loop{}", self.flags);
                    self.out.line(level, &format!("{flag} := TRUE;"));
                    self.out.line(level, &format!("WHILE {flag} DO"));
                    self.loops.push(Some(flag));
                }
                self.blocks(body, level + 1);
                self.loops.pop();
                self.out.line(level, "ENDWHILE");
            }
        }
    }

    fn branch(&mut self, n: usize, br: &Branch, level: usize) {
        let el = &self.input.sfc.elements;
        let text = flow::condition_text(self.input, br.transition);
        self.comment(
            level,
            &format!(
                "branch {n} (transition localId {}): {text}",
                el[br.transition].local_id
            ),
        );
        self.blocks(&br.body, level);
        match br.end {
            BranchEnd::Join => {}
            BranchEnd::Repeat(j) => self.comment(
                level,
                &format!("round again (jump localId {})", el[j].local_id),
            ),
            BranchEnd::Leave => {
                if let Some(Some(flag)) = self.loops.last().cloned() {
                    self.out.line(level, &format!("{flag} := FALSE;"));
                }
            }
        }
    }

    /// Selection branches in priority order: an `IF`/`ELSEIF` chain whose `ELSE` is the first
    /// unconditional branch; without one, the branch is chosen first (waiting for any
    /// condition, testing again if none holds any more), then run.
    fn choice(&mut self, div: usize, branches: &[Branch], level: usize) {
        let input = self.input;
        let conds: Vec<Option<String>> = branches
            .iter()
            .map(|b| flow::condition(input, b.transition, &OPS))
            .collect();
        self.comment(
            level,
            &format!(
                "selection localId {}: {} branches, the first whose condition holds",
                input.sfc.elements[div].local_id,
                branches.len()
            ),
        );
        if let Some(k) = conds.iter().position(Option::is_none) {
            if k == 0 {
                self.branch(1, &branches[0], level);
                return;
            }
            for (n, br) in branches.iter().enumerate().take(k) {
                let c = conds[n].as_deref().unwrap_or("TRUE");
                let kw = if n == 0 { "IF" } else { "ELSEIF" };
                self.out.line(level, &format!("{kw} {c} THEN"));
                self.branch(n + 1, br, level + 1);
            }
            self.out.line(level, "ELSE");
            self.branch(k + 1, &branches[k], level + 1);
            self.out.line(level, "ENDIF");
            return;
        }
        self.uses_branch_var = true;
        let any: Vec<String> = conds
            .iter()
            .map(|c| format!("({})", c.as_deref().unwrap_or("TRUE")))
            .collect();
        self.out.line(level, &format!("{BRANCH_VAR} := 0;"));
        self.out.line(level, &format!("WHILE {BRANCH_VAR} = 0 DO"));
        self.out.line(level + 1, &wait_until(&any.join(" OR ")));
        for (n, c) in conds.iter().enumerate() {
            let c = c.as_deref().unwrap_or("TRUE");
            let kw = if n == 0 { "IF" } else { "ELSEIF" };
            self.out.line(level + 1, &format!("{kw} {c} THEN"));
            self.out
                .line(level + 2, &format!("{BRANCH_VAR} := {};", n + 1));
        }
        self.out.line(level + 1, "ENDIF");
        self.out.line(level, "ENDWHILE");
        for (n, br) in branches.iter().enumerate() {
            if n == 0 {
                self.out.line(level, &format!("IF {BRANCH_VAR} = 1 THEN"));
            } else if n + 1 < branches.len() {
                self.out
                    .line(level, &format!("ELSEIF {BRANCH_VAR} = {} THEN", n + 1));
            } else {
                self.out.line(level, "ELSE");
            }
            self.branch(n + 1, br, level + 1);
        }
        self.out.line(level, "ENDIF");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wait_never_begins_its_argument_with_a_parenthesis() {
        assert_eq!(wait_until("di_Part = 1"), "WaitUntil di_Part = 1;");
        assert_eq!(
            wait_until("NOT (di_Part = 1)"),
            "WaitUntil NOT (di_Part = 1);"
        );
        assert_eq!(
            wait_until("(di_Part = 1) OR (gi_Type > 2)"),
            "WaitUntil ((di_Part = 1) OR (gi_Type > 2));"
        );
    }
}
