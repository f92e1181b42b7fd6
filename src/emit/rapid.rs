//! The ABB RAPID profile: one module, `<program>.mod` (docs/LANGUAGES.md).
//!
//! The program is `PROC main()` of `MODULE <program>`; IRL definitions become the module's
//! routines. Written so `rapidchecker` accepts it: two spaces per level, keywords upper case, no
//! labels and one value per `CASE`: a loop is a `WHILE` left through a flag (`skp_loopN`, the
//! rest of the body after a branch that leaves skipped by `IF skp_loopN THEN`), and a selection
//! without an unconditional branch records its branch in `skp_branch` first.

use std::borrow::Cow;

use super::structured::{self, BRANCH_VAR, Dialect, Leave};
use super::{EmitInput, Generated, Language, Profile};
use crate::cond::{BinOp, Ops};
use crate::diag::Diagnostics;
use crate::model::{Signal, SignalKind};
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
    calls: false,
    time: Ops::seconds,
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
        BinOp::Add => "+",
        BinOp::Sub => "-",
        BinOp::Mul => "*",
    }
}

/// RAPID's words for the program tree; loops are left through flags.
const DIALECT: Dialect = Dialect {
    ops: &OPS,
    comment: "!",
    if_: ("IF ", " THEN"),
    elif: ("ELSEIF ", " THEN"),
    else_: "ELSE",
    end_if: "ENDIF",
    while_: ("WHILE ", " DO"),
    end_while: "ENDWHILE",
    assign: (" := ", ";"),
    equals: " = ",
    wait: |out, level, c| out.line(level, &wait_until(c)),
    settle: Some("WaitTime \\InPos, 0;"),
    leave: Leave::Flag,
    empty_block: None,
    declare: |branch, flags, state| {
        let mut d = Vec::new();
        if branch {
            d.push(format!("VAR num {BRANCH_VAR} := 0;"));
        }
        if state {
            d.push(format!("VAR num {} := 0;", super::structured::STATE_VAR));
        }
        for n in 1..=flags {
            d.push(format!("VAR bool skp_loop{n} := TRUE;"));
        }
        d
    },
    // A clock per step time (`ClkRead` counts seconds).
    // A watched wait needs no clock: `WaitUntil \MaxTime \TimeFlag` (see `handshake`).
    timers: |n, _| {
        let d = (1..=n)
            .map(|k| format!("VAR clock skp_clock{k};"))
            .collect();
        (d, Vec::new())
    },
};

/// The RAPID profile.
pub struct Rapid;

impl crate::bind::Rules for Rapid {
    fn language(&self) -> Language {
        Language::Rapid
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
}

impl Profile for Rapid {
    fn files(&self) -> &'static [&'static str] {
        &["mod"]
    }

    fn declares_signals(&self) -> bool {
        true
    }

    fn builtin_template(&self) -> &'static str {
        DEFAULT_TEMPLATE
    }

    fn syntax(&self) -> Syntax {
        Language::Rapid.syntax()
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

    fn generate(&self, input: &EmitInput, diags: &mut Diagnostics) -> Option<Generated> {
        structured::generate(input, &DIALECT, diags)
    }
}

/// How often a `WaitUntil` reads its condition: RAPID's least `\PollRate` (the default is
/// 0.1 s; KRL reads every interpreter cycle), so a short window is not missed.
pub const POLL_RATE: &str = "\\PollRate:=0.04";

/// `WaitUntil \InPos, c \PollRate:=0.04;`: the robot stands at the end of the motion before
/// (as KRL's `WAIT FOR` stops the advance run), then the program waits for the condition,
/// reading it every 40 ms. The condition is in parentheses when it starts with one, so it never
/// reads as a call's argument list.
fn wait_until(c: &str) -> String {
    if c.starts_with('(') {
        format!("WaitUntil \\InPos, ({c}) {POLL_RATE};")
    } else {
        format!("WaitUntil \\InPos, {c} {POLL_RATE};")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wait_stands_first_and_never_begins_its_condition_with_a_parenthesis() {
        assert_eq!(
            wait_until("di_Part = 1"),
            "WaitUntil \\InPos, di_Part = 1 \\PollRate:=0.04;"
        );
        assert_eq!(
            wait_until("NOT (di_Part = 1)"),
            "WaitUntil \\InPos, NOT (di_Part = 1) \\PollRate:=0.04;"
        );
        assert_eq!(
            wait_until("(di_Part = 1) OR (gi_Type > 2)"),
            "WaitUntil \\InPos, ((di_Part = 1) OR (gi_Type > 2)) \\PollRate:=0.04;"
        );
    }
}
