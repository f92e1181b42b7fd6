//! The Universal Robots URScript profile: `<program>.script` (docs/LANGUAGES.md).
//!
//! The program is `def <program>():` … `end` with the IRL definitions inside before the steps,
//! then a call of it. Blocks close with `end`; a wait is `while not (c): sync() end`; a loop is
//! `while True:` left by `break`.

use std::borrow::Cow;

use super::structured::{self, Dialect, Leave};
use super::{EmitInput, Generated, Language, Profile};
use crate::cond::{BinOp, Ops};
use crate::diag::Diagnostics;
use crate::model::{Signal, SignalKind};
use crate::template::Syntax;
use crate::value::Literal;

/// The built-in template's text.
pub const DEFAULT_TEMPLATE: &str = include_str!("../../templates/urscript.toml");

/// URScript's keywords and the names a value must not be (they would become code or change
/// what a name means).
pub(crate) const KEYWORDS: &[&str] = &[
    "and",
    "break",
    "continue",
    "def",
    "elif",
    "else",
    "end",
    "False",
    "for",
    "global",
    "halt",
    "if",
    "in",
    "join",
    "kill",
    "local",
    "not",
    "or",
    "pass",
    "return",
    "run",
    "sec",
    "thread",
    "True",
    "while",
    "xor",
    "enter_critical",
    "exit_critical",
];

/// The longest URScript program name.
const MAX_NAME: usize = 63;

/// The highest standard digital input or output.
const MAX_STANDARD_IO: u32 = 7;

fn is_keyword(w: &str) -> bool {
    KEYWORDS.contains(&w)
}

fn is_ur_name(w: &str, max: usize) -> bool {
    let b = w.as_bytes();
    !b.is_empty()
        && b.len() <= max
        && (b[0].is_ascii_alphabetic() || b[0] == b'_')
        && b.iter().all(|c| c.is_ascii_alphanumeric() || *c == b'_')
}

const OPS: Ops = Ops {
    calls: false,
    time: Ops::seconds,
    op: ur_op,
    not: "not ",
    true_: "True",
    false_: "False",
};

fn ur_op(op: BinOp) -> &'static str {
    match op {
        BinOp::Or => "or",
        BinOp::Xor => "xor",
        BinOp::And => "and",
        BinOp::Eq => "==",
        BinOp::Ne => "!=",
        BinOp::Lt => "<",
        BinOp::Gt => ">",
        BinOp::Le => "<=",
        BinOp::Ge => ">=",
        BinOp::Add => "+",
        BinOp::Sub => "-",
        BinOp::Mul => "*",
    }
}

/// A number as URScript reads it: no leading zeros before the point (`007` is a syntax error
/// in Python-like languages), no exponent (written out).
fn ur_number(n: &str) -> Result<Cow<'_, str>, String> {
    let (sign, body) = match n.strip_prefix('-') {
        Some(b) => ("-", b),
        None => ("", n),
    };
    let (mant, exp) = match body.split_once('E') {
        Some((m, e)) => (m, e.parse::<i32>().map_err(|_| "exponent out of range")?),
        None => (body, 0),
    };
    if !(-40..=40).contains(&exp) {
        return Err(format!(
            "`{n}` is out of the range URScript numbers are written in here"
        ));
    }
    let leading_zero = mant.len() > 1 && mant.starts_with('0') && !mant.starts_with("0.");
    if !body.contains('E') && !leading_zero {
        return Ok(Cow::Borrowed(n));
    }
    // Digits and the position of the point, shifted by the exponent.
    let (int, frac) = mant.split_once('.').unwrap_or((mant, ""));
    let digits: String = format!("{int}{frac}");
    let point = int.len() as i64 + exp as i64;
    let mut s = String::new();
    if point <= 0 {
        s.push_str("0.");
        s.extend(std::iter::repeat_n('0', (-point) as usize));
        s.push_str(&digits);
    } else if point as usize >= digits.len() {
        s.push_str(&digits);
        s.extend(std::iter::repeat_n('0', point as usize - digits.len()));
    } else {
        s.push_str(&digits[..point as usize]);
        s.push('.');
        s.push_str(&digits[point as usize..]);
    }
    // Leading zeros of the integer part; trailing zeros after a point.
    let (i, f) = match s.split_once('.') {
        Some((i, f)) => (i.to_owned(), Some(f.trim_end_matches('0').to_owned())),
        None => (s.clone(), None),
    };
    let i = i.trim_start_matches('0');
    let i = if i.is_empty() { "0" } else { i };
    let mut out = format!("{sign}{i}");
    if let Some(f) = f.filter(|f| !f.is_empty()) {
        out.push('.');
        out.push_str(&f);
    } else if mant.contains('.') {
        out.push_str(".0");
    }
    if out == "-0" || out == "-0.0" {
        out.remove(0);
    }
    Ok(Cow::Owned(out))
}

/// URScript's words for the program tree; loops are left by `break`.
const DIALECT: Dialect = Dialect {
    ops: &OPS,
    comment: "#",
    if_: ("if ", ":"),
    elif: ("elif ", ":"),
    else_: "else:",
    end_if: "end",
    while_: ("while ", ":"),
    end_while: "end",
    assign: (" = ", ""),
    equals: " == ",
    // `while not (c): sync() end`: waits a control cycle at a time.
    wait: |out, level, c| {
        out.line(level, &format!("while not ({c}):"));
        out.line(level + 1, "sync()");
        out.line(level, "end");
    },
    // movel and movej return when the motion has ended.
    settle: None,
    leave: Leave::Statement("break"),
    // A block of comments only is no block to URScript's Python-like parser: a branch without
    // steps waits one control cycle.
    empty_block: Some("sync()"),
    declare: |_, _, _| Vec::new(),
    // URScript has no clock to read: a thread adds each control cycle's time to every step's
    // counter (as PolyScope's timers do); a step's start sets its counter to 0.
    timers: |n, watched| {
        let mut names: Vec<String> = (1..=n).map(|k| format!("skp_time{k}")).collect();
        let mut lines = Vec::new();
        if n > 0 {
            lines.push((
                0,
                format!(
                    "# step times: {} count the seconds since their step started",
                    names.join(", ")
                ),
            ));
        }
        if watched {
            let v = super::handshake::WATCH_VAR;
            lines.push((
                0,
                format!("# {v} counts the seconds a wait on another controller lasts"),
            ));
            names.push(v.to_owned());
        }
        for v in &names {
            lines.push((0, format!("global {v} = 0.0")));
        }
        lines.push((0, "thread skp_clock():".to_owned()));
        lines.push((1, "while True:".to_owned()));
        for v in &names {
            lines.push((2, format!("{v} = {v} + get_steptime()")));
        }
        lines.push((2, "sync()".to_owned()));
        lines.push((1, "end".to_owned()));
        lines.push((0, "end".to_owned()));
        lines.push((0, "skp_clock_thread = run skp_clock()".to_owned()));
        (Vec::new(), lines)
    },
};

/// The URScript profile.
pub struct UrScript;

impl crate::bind::Rules for UrScript {
    fn language(&self) -> Language {
        Language::UrScript
    }

    fn literal<'v>(&self, v: &Literal<'v>) -> Result<Cow<'v, str>, String> {
        Ok(match v {
            Literal::Number(n) => match n {
                Cow::Borrowed(b) => ur_number(b)?,
                Cow::Owned(o) => Cow::Owned(ur_number(o)?.into_owned()),
            },
            Literal::Bool(true) => Cow::Borrowed("True"),
            Literal::Bool(false) => Cow::Borrowed("False"),
            Literal::Str(s) => {
                if s.contains('\\') {
                    return Err("a URScript string value must not contain `\\`".to_owned());
                }
                Cow::Owned(format!("\"{s}\""))
            }
            Literal::Word(w) => {
                if !is_ur_name(w, usize::MAX) {
                    return Err(format!(
                        "`{w}` is not a URScript name (a letter or `_`, then letters, digits or `_`)"
                    ));
                }
                if is_keyword(w) {
                    return Err(format!(
                        "`{w}` is a URScript keyword: as a value it would become code"
                    ));
                }
                Cow::Borrowed(*w)
            }
        })
    }

    fn signal(&self, s: &Signal) -> Result<String, String> {
        match &s.kind {
            SignalKind::Bit(n) if *n <= MAX_STANDARD_IO => Ok(if s.output {
                format!("get_standard_digital_out({n})")
            } else {
                format!("get_standard_digital_in({n})")
            }),
            SignalKind::Bit(n) => Err(format!(
                "Number {n}: a UR robot has standard digital {} 0 to {MAX_STANDARD_IO}; for others give an `Address` (`get_tool_digital_in(0)`, `read_input_boolean_register(3)`)",
                if s.output { "outputs" } else { "inputs" }
            )),
            SignalKind::Group { .. } => Err(
                "URScript reads an integer signal through its `Address` (`read_input_integer_register(2)`), not `Number`/`Length`".to_owned(),
            ),
            SignalKind::Address { text, .. } if text.starts_with('$') || text.contains('[') => {
                Err(format!(
                    "URScript cannot read Address `{text}`: write a name or a call with one number (`read_input_integer_register(2)`)"
                ))
            }
            SignalKind::Address { text, .. } => Ok(text.clone()),
        }
    }
}

impl Profile for UrScript {
    fn files(&self) -> &'static [&'static str] {
        &["script"]
    }

    fn builtin_template(&self) -> &'static str {
        DEFAULT_TEMPLATE
    }

    fn syntax(&self) -> Syntax {
        Language::UrScript.syntax()
    }

    fn check_program_name(&self, name: &str) -> Result<(), String> {
        if !is_ur_name(name, MAX_NAME) {
            Err(format!(
                "not a URScript program name: letters, digits or `_`, not starting with a digit, at most {MAX_NAME} characters"
            ))
        } else if is_keyword(name) {
            Err("a URScript keyword cannot name a program".to_owned())
        } else {
            Ok(())
        }
    }

    fn generate(&self, input: &EmitInput, diags: &mut Diagnostics) -> Option<Generated> {
        structured::generate(input, &DIALECT, diags)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_written_as_urscript_reads_them() {
        let n = |s: &str| ur_number(s).unwrap().into_owned();
        assert_eq!(n("0.5"), "0.5");
        assert_eq!(n("-12"), "-12");
        assert_eq!(n("007"), "7");
        assert_eq!(n("1.5E3"), "1500.0");
        assert_eq!(n("1E3"), "1000");
        assert_eq!(n("2.5E-3"), "0.0025");
        assert_eq!(n("-0.0E0"), "0.0");
        assert!(ur_number("1E99").is_err());
    }
}
