//! Transition conditions (docs/INPUTS.md): the ST subset `TRUE`, `FALSE`, integer and decimal
//! literals (IEC 61131-3's: `1`/`0` as booleans where a boolean belongs, `BOOL#1`, typed
//! `INT#5`/`REAL#1.5`, based `2#`/`8#`/`16#`, `_` between digits; kept in decimal), names (IEC
//! identifiers, any Unicode letter, and qualified names `A.B`), `NOT`, `AND` (`&`), `OR`, `XOR`, `=`, `<>`, `<`, `>`,
//! `<=`, `>=`, unary `-` and parentheses, with ST's precedence (loosest first: `OR`, `XOR`, `AND`,
//! `=`/`<>`, `<`/`>`/`<=`/`>=`, unary `-`/`NOT`). `(* comments *)` are skipped.
//!
//! [`parse`] turns a condition's text into an [`Expr`] whose spans are byte ranges of the file
//! the text came from (the caller maps text offsets to file offsets, since the text may have
//! been assembled from several XML text pieces). [`check`] resolves names and types;
//! [`render_krl`] writes KRL with the parentheses KRL's different precedence needs (KRL binds
//! comparisons weaker than `AND`/`OR`).

use std::ops::Range;

/// Parentheses and `NOT`s nest at most this deep.
pub const MAX_DEPTH: usize = 64;

/// A condition has at most this many tokens (so a chain of operators cannot build a tree deep
/// enough to exhaust the stack of the recursive passes over it).
pub const MAX_TOKENS: usize = 1024;

/// A condition expression. `span` is a byte range in the file the condition was read from.
#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    pub kind: ExprKind,
    pub span: Range<usize>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum ExprKind {
    Bool(bool),
    /// An integer literal, as written (digits only).
    Int(Box<str>),
    /// A decimal literal, as written (`1.5`).
    Real(Box<str>),
    /// A duration (a `T#` / `TIME#` literal), in nanoseconds.
    Time(u64),
    /// A name (a signal, or a step's time `S.t`), as written.
    Name(Box<str>),
    Not(Box<Expr>),
    Neg(Box<Expr>),
    Bin(BinOp, Box<Expr>, Box<Expr>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    Or,
    Xor,
    And,
    Eq,
    Ne,
    Lt,
    Gt,
    Le,
    Ge,
    /// Arithmetic, from the standard functions `ADD`, `SUB`, `MUL` (wired blocks or calls in
    /// ST; the condition language of docs/INPUTS.md has no infix arithmetic).
    Add,
    Sub,
    Mul,
}

impl BinOp {
    /// ST binding strength: higher binds tighter.
    fn strength(self) -> u8 {
        match self {
            BinOp::Or => 1,
            BinOp::Xor => 2,
            BinOp::And => 3,
            BinOp::Eq | BinOp::Ne => 4,
            BinOp::Lt | BinOp::Gt | BinOp::Le | BinOp::Ge => 5,
            BinOp::Add | BinOp::Sub => 6,
            BinOp::Mul => 7,
        }
    }

    /// Whether the operator is arithmetic (numbers to a number).
    pub fn arithmetic(self) -> bool {
        matches!(self, BinOp::Add | BinOp::Sub | BinOp::Mul)
    }

    /// The standard function of an arithmetic operator, as ST calls it.
    fn function(self) -> Option<&'static str> {
        match self {
            BinOp::Add => Some("ADD"),
            BinOp::Sub => Some("SUB"),
            BinOp::Mul => Some("MUL"),
            _ => None,
        }
    }

    /// The operator as ST writes it.
    pub fn st(self) -> &'static str {
        match self {
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

    /// The operator as KRL writes it.
    pub fn krl(self) -> &'static str {
        match self {
            BinOp::Or => "OR",
            BinOp::Xor => "EXOR",
            BinOp::And => "AND",
            BinOp::Eq => "==",
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

    fn logical(self) -> bool {
        matches!(self, BinOp::Or | BinOp::Xor | BinOp::And)
    }
}

impl Expr {
    /// Whether the expression is the literal `TRUE`.
    pub fn is_true(&self) -> bool {
        matches!(self.kind, ExprKind::Bool(true))
    }

    /// Every name in the expression, left to right, with its span.
    pub fn names(&self) -> Vec<(&str, Range<usize>)> {
        let mut out = Vec::new();
        let mut stack = vec![self];
        while let Some(e) = stack.pop() {
            match &e.kind {
                ExprKind::Name(n) => out.push((&**n, e.span.clone())),
                ExprKind::Not(a) | ExprKind::Neg(a) => stack.push(a),
                ExprKind::Bin(_, a, b) => {
                    stack.push(b);
                    stack.push(a);
                }
                _ => {}
            }
        }
        out
    }

    /// The expression in ST, fully parenthesised where operators nest (for listings).
    pub fn to_st(&self) -> String {
        let mut s = String::new();
        write(self, &mut s, &|n| n.to_owned(), &Ops::ST);
        s
    }
}

/// A syntax error: where (a byte range of the condition's text) and what.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SyntaxError {
    pub at: Range<usize>,
    pub message: String,
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    True,
    False,
    /// An integer literal, in decimal digits (a based or typed one converted, `_` dropped).
    Int(Box<str>),
    /// A decimal literal, `_` dropped.
    Real(Box<str>),
    /// A duration in nanoseconds.
    Time(u64),
    Name,
    Not,
    And,
    Or,
    Xor,
    Op(BinOp),
    Minus,
    Open,
    Close,
    Comma,
}

struct Lexer {
    toks: Vec<(Tok, Range<usize>)>,
}

fn describe(text: &str, r: &Range<usize>) -> String {
    format!("`{}`", &text[r.clone()])
}

/// `end` within `text`, at a character boundary.
fn clamp(text: &str, end: usize) -> usize {
    let mut e = end.min(text.len());
    while !text.is_char_boundary(e) {
        e += 1;
    }
    e
}

/// Whether `rest` holds only white space and `(* comments *)`.
fn blank(rest: &str) -> bool {
    let mut r = rest.trim_start();
    while let Some(after) = r.strip_prefix("(*") {
        match after.find("*)") {
            Some(j) => r = after[j + 2..].trim_start(),
            None => return false,
        }
    }
    r.is_empty()
}

/// Whether `rest` starts with a letter (of any script).
fn starts_letter(rest: &str) -> bool {
    rest.chars().next().is_some_and(char::is_alphabetic)
}

/// Digits with `_` between them (IEC 61131-3): from `*i`, in `radix`; the digits without the
/// underscores. `None` when there is no digit, or a `_` that is not between two digits.
fn digits(text: &str, i: &mut usize, radix: u32) -> Option<String> {
    let b = text.as_bytes();
    let mut out = String::new();
    let mut last_underscore = false;
    while *i < b.len() {
        let c = b[*i] as char;
        if c.is_digit(radix) {
            out.push(c);
            last_underscore = false;
        } else if c == '_' && !out.is_empty() && !last_underscore {
            last_underscore = true;
        } else {
            break;
        }
        *i += 1;
    }
    (!out.is_empty() && !last_underscore).then_some(out)
}

/// A number from `*i` (a digit): decimal (`1_000`), based (`2#1010`, `8#17`, `16#FF`) or decimal
/// with a fraction (`1.5`).
fn number(text: &str, i: &mut usize) -> Result<Tok, SyntaxError> {
    let b = text.as_bytes();
    let start = *i;
    let bad = |end: usize, why: &str| {
        let end = clamp(text, end.max(start + 1));
        SyntaxError {
            at: start..end,
            message: format!("{} is not a number: {why}", describe(text, &(start..end))),
        }
    };
    let Some(whole) = digits(text, i, 10) else {
        return Err(bad(*i + 1, "`_` only stands between digits"));
    };
    if b.get(*i) == Some(&b'_') {
        return Err(bad(*i + 1, "`_` only stands between digits"));
    }
    if b.get(*i) == Some(&b'#') {
        let radix = match whole.as_str() {
            "2" => 2,
            "8" => 8,
            "16" => 16,
            _ => return Err(bad(*i + 1, "the base of a based literal is 2, 8 or 16")),
        };
        *i += 1;
        let Some(ds) = digits(text, i, radix) else {
            return Err(bad(
                *i + 1,
                "a based literal needs digits of its base after `#`",
            ));
        };
        return match i64::from_str_radix(&ds, radix) {
            Ok(v) => Ok(Tok::Int(v.to_string().into())),
            Err(_) => Err(bad(*i, "too large")),
        };
    }
    if b.get(*i) == Some(&b'.') && b.get(*i + 1).is_some_and(u8::is_ascii_digit) {
        *i += 1;
        let Some(frac) = digits(text, i, 10) else {
            return Err(bad(*i + 1, "`_` only stands between digits"));
        };
        let w = whole.trim_start_matches('0');
        let w = if w.is_empty() { "0" } else { w };
        return Ok(Tok::Real(format!("{w}.{frac}").into()));
    }
    // Leading zeros dropped (`007` is 7), so no language reads an octal number.
    let v = whole.trim_start_matches('0');
    Ok(Tok::Int(if v.is_empty() { "0" } else { v }.into()))
}

/// The literal after `type#` (`*i` after the `#`): `BOOL#1`, `BOOL#TRUE`, `INT#-5`, `INT#16#FF`,
/// `REAL#1.5`; `word` is the type.
fn typed(text: &str, word: &str, start: usize, i: &mut usize) -> Result<Tok, SyntaxError> {
    let b = text.as_bytes();
    let err = |end: usize, why: String| SyntaxError {
        at: start..clamp(text, end),
        message: why,
    };
    let ty = word.to_ascii_uppercase();
    const INTS: &[&str] = &[
        "SINT", "INT", "DINT", "LINT", "USINT", "UINT", "UDINT", "ULINT", "BYTE", "WORD", "DWORD",
        "LWORD",
    ];
    if ty == "BOOL" {
        let from = *i;
        while *i < b.len() && b[*i].is_ascii_alphanumeric() {
            *i += 1;
        }
        return match text[from..*i].to_ascii_uppercase().as_str() {
            "1" | "TRUE" => Ok(Tok::True),
            "0" | "FALSE" => Ok(Tok::False),
            _ => {
                let end = clamp(text, (*i).max(from + 1));
                Err(err(
                    end,
                    format!(
                        "{} is not a BOOL literal (`BOOL#0`, `BOOL#1`, `BOOL#FALSE`, `BOOL#TRUE`)",
                        describe(text, &(start..end))
                    ),
                ))
            }
        };
    }
    if matches!(ty.as_str(), "T" | "TIME" | "LT" | "LTIME") {
        return duration(text, word, start, i);
    }
    let is_int = INTS.contains(&ty.as_str());
    if !is_int && ty != "REAL" && ty != "LREAL" {
        return Err(err(
            *i,
            format!(
                "`{word}#` literals are not part of the condition language (booleans, integers and decimals are)"
            ),
        ));
    }
    let negative = match b.get(*i) {
        Some(b'-') => {
            *i += 1;
            true
        }
        Some(b'+') => {
            *i += 1;
            false
        }
        _ => false,
    };
    if !b.get(*i).is_some_and(u8::is_ascii_digit) {
        return Err(err(
            (*i + 1).min(text.len()),
            format!("`{word}#` needs a number after it"),
        ));
    }
    let sign = if negative { "-" } else { "" };
    match number(text, i)? {
        Tok::Int(v) if is_int => Ok(Tok::Int(format!("{sign}{v}").into())),
        Tok::Int(v) => Ok(Tok::Real(format!("{sign}{v}.0").into())),
        Tok::Real(v) if !is_int => Ok(Tok::Real(format!("{sign}{v}").into())),
        _ => Err(err(
            *i,
            format!("`{word}#` is an integer type; this number has a fraction"),
        )),
    }
}

/// The duration after `T#` (`*i` after the `#`): components `<number><unit>` from days down to
/// nanoseconds (`d`, `h`, `m`, `s`, `ms`, `us`, `ns`, any case), each unit at most once and in
/// that order, `_` between components, a fraction only on the last (`T#1.5s`); IEC 61131-3's
/// TIME literal. A negative duration is not a step's time and is refused.
fn duration(text: &str, word: &str, start: usize, i: &mut usize) -> Result<Tok, SyntaxError> {
    const UNITS: &[(&str, u128)] = &[
        ("d", 86_400_000_000_000),
        ("h", 3_600_000_000_000),
        ("m", 60_000_000_000),
        ("s", 1_000_000_000),
        ("ms", 1_000_000),
        ("us", 1_000),
        ("ns", 1),
    ];
    let b = text.as_bytes();
    let end_of_literal = |from: usize| {
        let mut j = from;
        while j < b.len() && (b[j].is_ascii_alphanumeric() || b[j] == b'_' || b[j] == b'.') {
            j += 1;
        }
        j
    };
    let bad = |why: &str, i: usize| {
        let end = clamp(text, end_of_literal(i).max(start + 1));
        SyntaxError {
            at: start..end,
            message: format!(
                "{} is not a TIME literal: {why} (`T#350ms`, `T#1m30s`, `TIME#1.5s`)",
                describe(text, &(start..end))
            ),
        }
    };
    if b.get(*i) == Some(&b'-') {
        return Err(bad("a step's time is never negative", *i));
    }
    if b.get(*i) == Some(&b'+') {
        *i += 1;
    }
    let mut total: u128 = 0;
    let mut last_unit = None::<usize>;
    let mut fraction_seen = false;
    loop {
        if !b.get(*i).is_some_and(u8::is_ascii_digit) {
            return Err(bad(
                &format!("`{word}#` needs a number and a unit (d, h, m, s, ms, us, ns)"),
                *i,
            ));
        }
        if fraction_seen {
            return Err(bad("only the last unit may have a fraction", *i));
        }
        let Some(whole) = digits(text, i, 10) else {
            return Err(bad("`_` only stands between digits", *i));
        };
        let mut frac = String::new();
        if b.get(*i) == Some(&b'.') {
            *i += 1;
            match digits(text, i, 10) {
                Some(f) => frac = f,
                None => return Err(bad("a digit must follow `.`", *i)),
            }
            fraction_seen = true;
        }
        let from = *i;
        while *i < b.len() && b[*i].is_ascii_alphabetic() {
            *i += 1;
        }
        let unit = text[from..*i].to_ascii_lowercase();
        let Some(k) = UNITS.iter().position(|(u, _)| *u == unit) else {
            return Err(bad(
                &format!(
                    "{} is not a unit (d, h, m, s, ms, us, ns)",
                    if unit.is_empty() {
                        "nothing".to_owned()
                    } else {
                        format!("`{unit}`")
                    }
                ),
                *i,
            ));
        };
        if last_unit.is_some_and(|l| l >= k) {
            return Err(bad("units go from days down to nanoseconds, each once", *i));
        }
        last_unit = Some(k);
        let scale = UNITS[k].1;
        let w: u128 = whole.parse().unwrap_or(u128::MAX);
        let mut part = w.saturating_mul(scale);
        if !frac.is_empty() {
            // Digits beyond the nanosecond are dropped.
            let mut f: u128 = 0;
            let mut s = scale;
            for d in frac.bytes() {
                s /= 10;
                f = f.saturating_add(u128::from(d - b'0') * s);
            }
            part = part.saturating_add(f);
        }
        total = total.saturating_add(part);
        if total > u128::from(u64::MAX) {
            return Err(bad("too long", *i));
        }
        // `_` between components, then the next number.
        if b.get(*i) == Some(&b'_') && b.get(*i + 1).is_some_and(u8::is_ascii_digit) {
            *i += 1;
            continue;
        }
        if b.get(*i).is_some_and(u8::is_ascii_digit) {
            continue;
        }
        if b.get(*i)
            .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_' || *c == b'.')
        {
            return Err(bad("unexpected character", *i));
        }
        return Ok(Tok::Time(total as u64));
    }
}

/// A duration in nanoseconds as a decimal number of `unit` nanoseconds (`1_000_000`: ms),
/// without trailing zeros (`350`, `0.35`).
pub fn decimal(ns: u64, unit: u64) -> String {
    let whole = ns / unit;
    let frac = ns % unit;
    if frac == 0 {
        return whole.to_string();
    }
    let width = unit.ilog10() as usize;
    let f = format!("{frac:0width$}");
    format!("{whole}.{}", f.trim_end_matches('0'))
}

impl Lexer {
    fn run(text: &str) -> Result<Vec<(Tok, Range<usize>)>, SyntaxError> {
        let mut l = Lexer { toks: Vec::new() };
        let b = text.as_bytes();
        let mut i = 0;
        while i < b.len() {
            let c = b[i];
            let start = i;
            if c.is_ascii_whitespace() {
                i += 1;
                continue;
            }
            if text[i..].starts_with("(*") {
                match text[i + 2..].find("*)") {
                    Some(j) => {
                        i += 2 + j + 2;
                        continue;
                    }
                    None => {
                        return Err(SyntaxError {
                            at: i..i + 2,
                            message: "comment `(*` without its `*)`".to_owned(),
                        });
                    }
                }
            }
            let tok = match c {
                b'(' => {
                    i += 1;
                    Tok::Open
                }
                b')' => {
                    i += 1;
                    Tok::Close
                }
                b',' => {
                    i += 1;
                    Tok::Comma
                }
                b'&' => {
                    i += 1;
                    Tok::And
                }
                b'-' => {
                    i += 1;
                    Tok::Minus
                }
                b'=' => {
                    i += 1;
                    Tok::Op(BinOp::Eq)
                }
                b'<' => match b.get(i + 1) {
                    Some(b'>') => {
                        i += 2;
                        Tok::Op(BinOp::Ne)
                    }
                    Some(b'=') => {
                        i += 2;
                        Tok::Op(BinOp::Le)
                    }
                    _ => {
                        i += 1;
                        Tok::Op(BinOp::Lt)
                    }
                },
                b'>' => match b.get(i + 1) {
                    Some(b'=') => {
                        i += 2;
                        Tok::Op(BinOp::Ge)
                    }
                    _ => {
                        i += 1;
                        Tok::Op(BinOp::Gt)
                    }
                },
                b'0'..=b'9' => number(text, &mut i)?,
                c if c.is_ascii_alphabetic()
                    || c == b'_'
                    || (c >= 0x80 && starts_letter(&text[i..])) =>
                {
                    // IEC identifiers, and any Unicode letter (a signal named `Störung`); a
                    // qualified name (`GVL.PartOK`, `Gripper.Closed`, as CODESYS writes them) is
                    // one name, matched to a signal of that name.
                    while i < b.len() {
                        let ch = text[i..].chars().next().unwrap_or(' ');
                        let next = text[i + ch.len_utf8()..].chars().next();
                        if ch.is_alphanumeric() || ch == '_' {
                            i += ch.len_utf8();
                        } else if ch == '.' && next.is_some_and(|c| c.is_alphabetic() || c == '_') {
                            i += 1;
                        } else {
                            break;
                        }
                    }
                    let w = &text[start..i];
                    if b.get(i) == Some(&b'#') {
                        i += 1;
                        typed(text, w, start, &mut i)?
                    } else if w.eq_ignore_ascii_case("TRUE") {
                        Tok::True
                    } else if w.eq_ignore_ascii_case("FALSE") {
                        Tok::False
                    } else if w.eq_ignore_ascii_case("NOT") {
                        Tok::Not
                    } else if w.eq_ignore_ascii_case("AND") {
                        Tok::And
                    } else if w.eq_ignore_ascii_case("OR") {
                        Tok::Or
                    } else if w.eq_ignore_ascii_case("XOR") {
                        Tok::Xor
                    } else {
                        Tok::Name
                    }
                }
                _ => {
                    let ch = text[i..].chars().next().unwrap_or(' ');
                    let end = i + ch.len_utf8();
                    let hint = match ch {
                        '.' => {
                            ": a name's part after `.` starts with a letter (`GVL.PartOK`); direct addresses (`%IX0.1`) are not supported: declare a signal and use its name"
                        }
                        '%' => {
                            ": direct addresses are not supported; declare a signal (an ExternalInterface of the resource) and use its name"
                        }
                        ':' if text[i..].starts_with(":=") => ": `:=` assigns; compare with `=`",
                        '+' | '*' | '/' => ": arithmetic is not part of the condition language",
                        '#' => {
                            ": a typed or based literal needs its type or base before `#` (`INT#5`, `16#FF`)"
                        }
                        '\'' | '"' => ": strings are not part of the condition language",
                        // `expr;` as ST writes a statement: one `;` at the end is fine.
                        ';' if blank(&text[i + 1..]) => break,
                        ';' => ": a condition is one expression",
                        _ => "",
                    };
                    return Err(SyntaxError {
                        at: i..end,
                        message: format!("unexpected character `{ch}`{hint}"),
                    });
                }
            };
            // A letter right after a number (`3a`) is not a token boundary.
            if matches!(tok, Tok::Int(_) | Tok::Real(_))
                && i < b.len()
                && (b[i].is_ascii_alphabetic() || b[i] == b'_' || b[i] == b'#' || b[i] >= 0x80)
            {
                let mut j = i;
                while j < b.len()
                    && (b[j].is_ascii_alphanumeric()
                        || b[j] == b'_'
                        || b[j] == b'#'
                        || b[j] >= 0x80)
                {
                    j += 1;
                }
                while !text.is_char_boundary(j) {
                    j += 1;
                }
                return Err(SyntaxError {
                    at: start..j,
                    message: format!(
                        "{} is not a number or a name (a based literal is `2#`, `8#` or `16#` and digits, a typed one `INT#5`)",
                        describe(text, &(start..j))
                    ),
                });
            }
            if let Tok::Int(v) = &tok
                && v.parse::<i32>().is_err()
            {
                return Err(SyntaxError {
                    at: start..i,
                    message: format!(
                        "{} is larger than a KRL integer (at most {})",
                        describe(text, &(start..i)),
                        i32::MAX
                    ),
                });
            }
            l.toks.push((tok, start..i));
        }
        Ok(l.toks)
    }
}

/// The standard functions a condition may use, as a wired block or called in ST (docs/INPUTS.md),
/// as messages list them.
pub const STANDARD_FUNCTIONS: &str =
    "AND, OR, XOR, NOT, EQ, NE, GT, GE, LT, LE, ADD, SUB, MUL, SEL and MOVE";

/// What a standard function computes, made operators of the expression.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Function {
    /// `AND`, `OR`, `XOR`, `ADD`, `MUL`: over all its operands.
    Fold(BinOp),
    /// `SUB`: over exactly two.
    Two(BinOp),
    /// `EQ`, `NE`, `GT`, `GE`, `LT`, `LE`: IEC's chain, `GT(a, b, c)` is `a > b AND b > c`.
    Chain(BinOp),
    Not,
    Move,
    /// `SEL(G, IN0, IN1)`: `IN1` when `G`, else `IN0`.
    Sel,
}

impl Function {
    /// The standard function of this name (any case), if it is one of
    /// [`STANDARD_FUNCTIONS`].
    pub fn named(name: &str) -> Option<Function> {
        Some(match name.trim().to_ascii_uppercase().as_str() {
            "AND" => Function::Fold(BinOp::And),
            "OR" => Function::Fold(BinOp::Or),
            "XOR" => Function::Fold(BinOp::Xor),
            "ADD" => Function::Fold(BinOp::Add),
            "MUL" => Function::Fold(BinOp::Mul),
            "SUB" => Function::Two(BinOp::Sub),
            "EQ" => Function::Chain(BinOp::Eq),
            "NE" => Function::Chain(BinOp::Ne),
            "GT" => Function::Chain(BinOp::Gt),
            "GE" => Function::Chain(BinOp::Ge),
            "LT" => Function::Chain(BinOp::Lt),
            "LE" => Function::Chain(BinOp::Le),
            "NOT" => Function::Not,
            "MOVE" => Function::Move,
            "SEL" => Function::Sel,
            _ => return None,
        })
    }

    /// The formal parameters of its block, in operand order; `None`: all of the block's inputs,
    /// in order.
    pub fn formals(self) -> Option<&'static [&'static str]> {
        match self {
            Function::Fold(_) => None,
            Function::Two(_) | Function::Chain(_) => Some(&["IN1", "IN2"]),
            Function::Not | Function::Move => Some(&["IN"]),
            Function::Sel => Some(&["G", "IN0", "IN1"]),
        }
    }

    /// How many operands a call takes: at least, at most.
    fn arity(self) -> (usize, usize) {
        match self {
            Function::Fold(_) | Function::Chain(_) => (2, usize::MAX),
            Function::Two(_) => (2, 2),
            Function::Not | Function::Move => (1, 1),
            Function::Sel => (3, 3),
        }
    }

    /// The expression of the function over `args` (at least one; as many as
    /// [`Function::formals`] names where it names them), every new node spanning `span`.
    pub fn apply(self, args: Vec<Expr>, span: Range<usize>) -> Expr {
        let bin = |op, a: Expr, b: Expr| Expr {
            kind: ExprKind::Bin(op, Box::new(a), Box::new(b)),
            span: span.clone(),
        };
        let mut it = args.into_iter();
        let first = it.next().expect("an operand at least");
        match self {
            Function::Fold(op) | Function::Two(op) => it.fold(first, |acc, a| bin(op, acc, a)),
            Function::Chain(op) => {
                let mut prev = first;
                let mut out: Option<Expr> = None;
                for next in it {
                    let part = bin(op, prev, next.clone());
                    out = Some(match out {
                        None => part,
                        Some(acc) => bin(BinOp::And, acc, part),
                    });
                    prev = next;
                }
                out.unwrap_or(prev)
            }
            Function::Not => Expr {
                kind: ExprKind::Not(Box::new(first)),
                span: span.clone(),
            },
            Function::Move => first,
            Function::Sel => {
                let g = first;
                let (in0, in1) = (it.next().expect("IN0"), it.next().expect("IN1"));
                let not_g = Expr {
                    kind: ExprKind::Not(Box::new(g.clone())),
                    span: span.clone(),
                };
                bin(
                    BinOp::Or,
                    bin(BinOp::And, g, in1),
                    bin(BinOp::And, not_g, in0),
                )
            }
        }
    }
}

struct Parser<'t> {
    text: &'t str,
    toks: Vec<(Tok, Range<usize>)>,
    pos: usize,
    /// Maps a byte offset of the text to the file.
    map: &'t dyn Fn(usize) -> usize,
}

/// Parses a condition. `map` turns a byte offset of `text` into a byte offset of the file (the
/// expression's spans are file ranges); errors are ranges of `text`.
pub fn parse(text: &str, map: &dyn Fn(usize) -> usize) -> Result<Expr, SyntaxError> {
    parse_operand(text, map).map(as_condition)
}

/// An expression that is a whole condition: `1` and `0` read as booleans where a boolean
/// belongs (IEC 61131-3). [`parse`] does this; a wired condition does it once its network is
/// put together, since an `inVariable`'s `1` may be a number compared with an integer signal.
pub fn as_condition(e: Expr) -> Expr {
    booleans(e, true)
}

/// Parses an expression that is a part of a condition (an `inVariable` of a wired one): as
/// [`parse`], but a lone `1` or `0` stays a number until the whole condition is known
/// ([`as_condition`]).
pub fn parse_operand(text: &str, map: &dyn Fn(usize) -> usize) -> Result<Expr, SyntaxError> {
    let toks = Lexer::run(text)?;
    if let Some((_, r)) = toks.get(MAX_TOKENS) {
        return Err(SyntaxError {
            at: r.clone(),
            message: format!("the condition is longer than {MAX_TOKENS} tokens"),
        });
    }
    if toks.is_empty() {
        let t = text.len();
        return Err(SyntaxError {
            at: 0..t,
            message: "empty condition (write `TRUE` for a transition that always fires)".to_owned(),
        });
    }
    let mut p = Parser {
        text,
        toks,
        pos: 0,
        map,
    };
    let e = p.expr(0, 0)?;
    if let Some((_, r)) = p.toks.get(p.pos) {
        let r = r.clone();
        return Err(SyntaxError {
            message: format!(
                "{} after a complete condition: an operator is missing",
                describe(text, &r)
            ),
            at: r,
        });
    }
    Ok(e)
}

/// IEC 61131-3 reads `1` and `0` as booleans where a boolean belongs: the whole condition, the
/// operands of `NOT`, `AND`, `OR`, `XOR`, and a side of `=`/`<>` whose other side is a boolean
/// expression.
fn booleans(e: Expr, want: bool) -> Expr {
    fn boolish(e: &Expr) -> bool {
        match &e.kind {
            ExprKind::Bin(op, ..) => !op.arithmetic(),
            ExprKind::Bool(_) | ExprKind::Not(_) => true,
            _ => false,
        }
    }
    let Expr { kind, span } = e;
    let kind = match kind {
        ExprKind::Int(v) if want && (&*v == "0" || &*v == "1") => ExprKind::Bool(&*v == "1"),
        ExprKind::Not(a) => ExprKind::Not(Box::new(booleans(*a, true))),
        ExprKind::Bin(op @ (BinOp::And | BinOp::Or | BinOp::Xor), a, b) => ExprKind::Bin(
            op,
            Box::new(booleans(*a, true)),
            Box::new(booleans(*b, true)),
        ),
        ExprKind::Bin(op @ (BinOp::Eq | BinOp::Ne), a, b) => {
            let (a, b) = (booleans(*a, false), booleans(*b, false));
            let (a, b) = if boolish(&a) {
                let b = booleans(b, true);
                (a, b)
            } else if boolish(&b) {
                (booleans(a, true), b)
            } else {
                (a, b)
            };
            ExprKind::Bin(op, Box::new(a), Box::new(b))
        }
        ExprKind::Bin(op, a, b) => ExprKind::Bin(
            op,
            Box::new(booleans(*a, false)),
            Box::new(booleans(*b, false)),
        ),
        ExprKind::Neg(a) => ExprKind::Neg(Box::new(booleans(*a, false))),
        k => k,
    };
    Expr { kind, span }
}

impl Parser<'_> {
    fn span(&self, r: Range<usize>) -> Range<usize> {
        let s = (self.map)(r.start);
        let e = (self.map)(r.end.saturating_sub(1)) + 1;
        s..e.max(s)
    }

    fn end_error(&self, what: &str) -> SyntaxError {
        let t = self.text.trim_end().len();
        SyntaxError {
            at: t.saturating_sub(1)..t,
            message: format!("the condition ends where {what} is expected"),
        }
    }

    fn binop(&self) -> Option<BinOp> {
        match self.toks.get(self.pos).map(|t| &t.0) {
            Some(Tok::Or) => Some(BinOp::Or),
            Some(Tok::Xor) => Some(BinOp::Xor),
            Some(Tok::And) => Some(BinOp::And),
            Some(Tok::Op(op)) => Some(*op),
            _ => None,
        }
    }

    /// Precedence climbing: operators binding tighter than `min`.
    fn expr(&mut self, min: u8, depth: usize) -> Result<Expr, SyntaxError> {
        let mut lhs = self.unary(depth)?;
        while let Some(op) = self.binop() {
            if op.strength() <= min {
                break;
            }
            self.pos += 1;
            let rhs = self.expr(op.strength(), depth + 1)?;
            let span = lhs.span.start..rhs.span.end;
            lhs = Expr {
                kind: ExprKind::Bin(op, Box::new(lhs), Box::new(rhs)),
                span,
            };
        }
        Ok(lhs)
    }

    /// A call of a standard function, `F(a, b, …)` (the `(` is next): `AND`, `OR`, `XOR` of two
    /// or more operands, `NOT` of one, the comparisons `EQ`, `NE`, `GT`, `GE`, `LT`, `LE` of two
    /// or more (IEC's chain: `GT(a, b, c)` is `a > b AND b > c`), `SEL(G, IN0, IN1)` and
    /// `MOVE(x)`, as the blocks of a wired condition.
    fn call(&mut self, name: &str, r: Range<usize>, depth: usize) -> Result<Expr, SyntaxError> {
        let Some(f) = Function::named(name) else {
            return Err(SyntaxError {
                at: r,
                message: format!(
                    "function `{name}` is not part of the condition language ({STANDARD_FUNCTIONS} are)"
                ),
            });
        };
        let open = self.toks[self.pos].1.clone();
        self.pos += 1;
        let mut args = Vec::new();
        loop {
            args.push(self.expr(0, depth + 1)?);
            match self.toks.get(self.pos) {
                Some((Tok::Comma, _)) => self.pos += 1,
                Some((Tok::Close, _)) => {
                    self.pos += 1;
                    break;
                }
                Some((_, r2)) => {
                    return Err(SyntaxError {
                        message: format!(
                            "{} where `,` or `)` is expected (in the call of `{name}`)",
                            describe(self.text, r2)
                        ),
                        at: r2.clone(),
                    });
                }
                None => {
                    return Err(SyntaxError {
                        at: open,
                        message: format!("`(` of the call of `{name}` without its `)`"),
                    });
                }
            }
        }
        let close = self.toks[self.pos - 1].1.clone();
        let (least, most) = f.arity();
        if args.len() < least || args.len() > most {
            let wanted = if least == most {
                format!("{least}")
            } else {
                format!("at least {least}")
            };
            return Err(SyntaxError {
                at: r.start..close.end,
                message: format!(
                    "`{name}` takes {wanted} operand(s), this call has {}",
                    args.len()
                ),
            });
        }
        Ok(f.apply(args, self.span(r.start..close.end)))
    }

    fn unary(&mut self, depth: usize) -> Result<Expr, SyntaxError> {
        let Some((tok, r)) = self.toks.get(self.pos).cloned() else {
            return Err(self.end_error("an operand"));
        };
        if depth >= MAX_DEPTH {
            return Err(SyntaxError {
                at: r,
                message: format!("the condition nests deeper than {MAX_DEPTH} levels"),
            });
        }
        self.pos += 1;
        let leaf = |k: ExprKind, p: &Self| Expr {
            kind: k,
            span: p.span(r.clone()),
        };
        let text = &self.text[r.clone()];
        let is_int = matches!(tok, Tok::Int(_));
        Ok(match tok {
            Tok::True => leaf(ExprKind::Bool(true), self),
            Tok::False => leaf(ExprKind::Bool(false), self),
            // A typed literal's sign (`INT#-5`) is a unary minus, as `-5` is.
            Tok::Int(v) | Tok::Real(v) if v.starts_with('-') => {
                let abs: Box<str> = v[1..].into();
                let kind = if is_int {
                    ExprKind::Int(abs)
                } else {
                    ExprKind::Real(abs)
                };
                Expr {
                    kind: ExprKind::Neg(Box::new(leaf(kind, self))),
                    span: self.span(r.clone()),
                }
            }
            Tok::Int(v) => leaf(ExprKind::Int(v.clone()), self),
            Tok::Real(v) => leaf(ExprKind::Real(v.clone()), self),
            Tok::Time(ns) => leaf(ExprKind::Time(ns), self),
            Tok::Name | Tok::And | Tok::Or | Tok::Xor
                if matches!(self.toks.get(self.pos), Some((Tok::Open, _))) =>
            {
                self.call(text, r.clone(), depth)?
            }
            Tok::Name => leaf(ExprKind::Name(text.into()), self),
            Tok::Not | Tok::Minus => {
                let inner = self.unary(depth + 1)?;
                let span = self.span(r.clone()).start..inner.span.end;
                let kind = if tok == Tok::Not {
                    ExprKind::Not(Box::new(inner))
                } else {
                    ExprKind::Neg(Box::new(inner))
                };
                Expr { kind, span }
            }
            Tok::Open => {
                let inner = self.expr(0, depth + 1)?;
                match self.toks.get(self.pos) {
                    Some((Tok::Close, _)) => {
                        self.pos += 1;
                        inner
                    }
                    Some((_, r2)) => {
                        return Err(SyntaxError {
                            message: format!(
                                "{} where `)` is expected (to close the `(` at offset {})",
                                describe(self.text, r2),
                                r.start
                            ),
                            at: r2.clone(),
                        });
                    }
                    None => {
                        return Err(SyntaxError {
                            at: r,
                            message: "`(` without its `)`".to_owned(),
                        });
                    }
                }
            }
            _ => {
                return Err(SyntaxError {
                    message: format!("{} where an operand is expected", describe(self.text, &r)),
                    at: r,
                });
            }
        })
    }
}

/// The type of a (sub)expression.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ty {
    Bool,
    Number,
    /// A duration: a `T#` literal or a step's time.
    Time,
}

impl Ty {
    fn name(self) -> &'static str {
        match self {
            Ty::Bool => "boolean",
            Ty::Number => "number",
            Ty::Time => "time",
        }
    }
}

/// A name or type error: where (a file range) and what; `unknown` marks an unknown name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CheckError {
    pub at: Range<usize>,
    pub message: String,
    pub unknown: bool,
}

/// Resolves the names with `lookup` (`None`: unknown) and checks the types; the whole condition
/// must be boolean. Every error is returned.
pub fn check(e: &Expr, lookup: &dyn Fn(&str) -> Option<Ty>) -> Vec<CheckError> {
    let mut errs = Vec::new();
    if let Some(t) = ty(e, lookup, &mut errs)
        && t != Ty::Bool
    {
        errs.push(CheckError {
            at: e.span.clone(),
            message: "the condition is a number, not a boolean: compare it (`= 3`)".to_owned(),
            unknown: false,
        });
    }
    errs
}

fn ty(e: &Expr, lookup: &dyn Fn(&str) -> Option<Ty>, errs: &mut Vec<CheckError>) -> Option<Ty> {
    let want = |e: &Expr, t: Option<Ty>, wanted: Ty, what: &str, errs: &mut Vec<_>| {
        if let Some(t) = t
            && t != wanted
        {
            let hint = if matches!(e.kind, ExprKind::Not(_)) && wanted != Ty::Bool {
                " (`NOT` binds tighter than a comparison in ST: `NOT (a >= b)` negates the comparison; `NOT` of a number, bitwise in ST, is not part of the condition language)"
            } else {
                ""
            };
            errs.push(CheckError {
                at: e.span.clone(),
                message: format!(
                    "{what} needs a {}, this is a {}{hint}",
                    wanted.name(),
                    t.name()
                ),
                unknown: false,
            });
        }
    };
    match &e.kind {
        ExprKind::Bool(_) => Some(Ty::Bool),
        ExprKind::Int(_) | ExprKind::Real(_) => Some(Ty::Number),
        ExprKind::Time(_) => Some(Ty::Time),
        ExprKind::Name(n) => {
            let t = lookup(n);
            if t.is_none() {
                errs.push(CheckError {
                    at: e.span.clone(),
                    message: n.to_string(),
                    unknown: true,
                });
            }
            t
        }
        ExprKind::Not(a) => {
            let t = ty(a, lookup, errs);
            if t == Some(Ty::Number) {
                // ST's bitwise NOT of a number (`NOT n >= 3` is `(NOT n) >= 3`): one error,
                // here; what it gives is a number, so the comparison around it adds none.
                errs.push(CheckError {
                    at: a.span.clone(),
                    message: "`NOT` needs a boolean, this is a number (`NOT` binds tighter than a comparison in ST, so `NOT n >= 3` is the bitwise NOT of `n`, compared: write `NOT (n >= 3)` to negate the comparison; the bitwise NOT of a number is not part of the condition language)".to_owned(),
                    unknown: false,
                });
                return Some(Ty::Number);
            }
            want(a, t, Ty::Bool, "`NOT`", errs);
            Some(Ty::Bool)
        }
        ExprKind::Neg(a) => {
            let t = ty(a, lookup, errs);
            want(a, t, Ty::Number, "unary `-`", errs);
            Some(Ty::Number)
        }
        ExprKind::Bin(op, a, b) => {
            let (ta, tb) = (ty(a, lookup, errs), ty(b, lookup, errs));
            let what = format!("`{}`", op.st());
            if op.logical() {
                want(a, ta, Ty::Bool, &what, errs);
                want(b, tb, Ty::Bool, &what, errs);
            } else if op.arithmetic() {
                want(a, ta, Ty::Number, &what, errs);
                want(b, tb, Ty::Number, &what, errs);
                return Some(Ty::Number);
            } else if matches!(op, BinOp::Eq | BinOp::Ne) {
                if let (Some(x), Some(y)) = (ta, tb)
                    && x != y
                {
                    errs.push(CheckError {
                        at: e.span.clone(),
                        message: format!(
                            "{what} compares a {} with a {}{}",
                            x.name(),
                            y.name(),
                            if [a, b].iter().any(|o| matches!(o.kind, ExprKind::Not(_))) {
                                " (`NOT` binds tighter than `=` in ST: `NOT (a = b)` negates the comparison; `NOT` of a number, bitwise in ST, is not part of the condition language)"
                            } else {
                                ""
                            }
                        ),
                        unknown: false,
                    });
                }
            } else {
                // Numbers with numbers, times with times.
                let other = |t: Option<Ty>| t.filter(|t| *t != Ty::Bool);
                let wanted = other(ta).or(other(tb)).unwrap_or(Ty::Number);
                want(a, ta, wanted, &what, errs);
                want(b, tb, wanted, &what, errs);
            }
            Some(Ty::Bool)
        }
    }
}

/// The expression in KRL: `signal` renders a (resolved) name. Every operator nested inside
/// another is parenthesised, so KRL's precedence (comparisons bind weaker than `AND`/`OR`,
/// `EXOR` between them) cannot change the meaning.
pub fn render_krl(e: &Expr, signal: &dyn Fn(&str) -> String) -> String {
    render(e, signal, &Ops::KRL)
}

/// How a robot language writes the condition language's operators and literals.
#[derive(Debug)]
pub struct Ops {
    pub op: fn(BinOp) -> &'static str,
    /// A duration (nanoseconds) in the unit the language's step times count in.
    pub time: fn(u64) -> String,
    /// The negation with its space (`NOT `, `not `).
    pub not: &'static str,
    /// Whether arithmetic is written as the standard functions' calls (`ADD(a, b)`: ST, whose
    /// condition language has no infix arithmetic), else infix.
    pub calls: bool,
    pub true_: &'static str,
    pub false_: &'static str,
}

impl Ops {
    /// A duration in milliseconds (KRL's `$TIMER`).
    pub fn milliseconds(ns: u64) -> String {
        decimal(ns, 1_000_000)
    }

    /// A duration in seconds (RAPID's `ClkRead`, URScript's counters).
    pub fn seconds(ns: u64) -> String {
        decimal(ns, 1_000_000_000)
    }

    pub const KRL: Ops = Ops {
        op: BinOp::krl,
        time: Ops::milliseconds,
        calls: false,
        not: "NOT ",
        true_: "TRUE",
        false_: "FALSE",
    };
    const ST: Ops = Ops {
        op: BinOp::st,
        time: |ns| format!("T#{}ms", decimal(ns, 1_000_000)),
        calls: true,
        not: "NOT ",
        true_: "TRUE",
        false_: "FALSE",
    };
}

/// Renders `e` with `ops`, every nested operation in parentheses (no language's precedence is
/// relied on); `signal` gives a name's text, which is parenthesised as an operand when it holds
/// a space (RAPID's `di_Part = 1`).
pub fn render(e: &Expr, signal: &dyn Fn(&str) -> String, ops: &Ops) -> String {
    let mut s = String::new();
    write(e, &mut s, signal, ops);
    s
}

fn write(e: &Expr, out: &mut String, name: &dyn Fn(&str) -> String, ops: &Ops) {
    let sub = |x: &Expr, out: &mut String| {
        let text;
        let paren = match &x.kind {
            // A call (`ADD(a, b)` in ST) needs no parentheses.
            ExprKind::Bin(o, ..) => !(ops.calls && o.arithmetic()),
            ExprKind::Neg(_) | ExprKind::Not(_) => true,
            ExprKind::Name(n) => {
                text = name(n);
                if text.contains(' ') {
                    out.push('(');
                    out.push_str(&text);
                    out.push(')');
                } else {
                    out.push_str(&text);
                }
                return;
            }
            _ => false,
        };
        if paren {
            out.push('(');
        }
        write(x, out, name, ops);
        if paren {
            out.push(')');
        }
    };
    match &e.kind {
        ExprKind::Bool(true) => out.push_str(ops.true_),
        ExprKind::Bool(false) => out.push_str(ops.false_),
        ExprKind::Int(s) | ExprKind::Real(s) => out.push_str(s),
        ExprKind::Time(ns) => out.push_str(&(ops.time)(*ns)),
        ExprKind::Name(n) => out.push_str(&name(n)),
        ExprKind::Not(a) => {
            out.push_str(ops.not);
            sub(a, out);
        }
        ExprKind::Neg(a) => {
            out.push('-');
            sub(a, out);
        }
        ExprKind::Bin(o, a, b) if ops.calls && o.arithmetic() => {
            out.push_str(o.function().unwrap_or_default());
            out.push('(');
            write(a, out, name, ops);
            out.push_str(", ");
            write(b, out, name, ops);
            out.push(')');
        }
        ExprKind::Bin(o, a, b) => {
            sub(a, out);
            out.push(' ');
            out.push_str((ops.op)(*o));
            out.push(' ');
            sub(b, out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(s: &str) -> Result<Expr, SyntaxError> {
        parse(s, &|o| o)
    }

    fn st(s: &str) -> String {
        p(s).unwrap().to_st()
    }

    #[test]
    fn precedence_is_st() {
        assert_eq!(st("a OR b AND c"), "a OR (b AND c)");
        assert_eq!(st("a AND b OR c"), "(a AND b) OR c");
        assert_eq!(st("a XOR b OR c AND d"), "(a XOR b) OR (c AND d)");
        assert_eq!(st("n = 3 AND m < 2"), "(n = 3) AND (m < 2)");
        assert_eq!(st("a = b < c"), "a = (b < c)");
        assert_eq!(st("NOT a AND b"), "(NOT a) AND b");
        assert_eq!(st("NOT (a AND b)"), "NOT (a AND b)");
        assert_eq!(st("a & b & c"), "(a AND b) AND c");
        assert_eq!(st("- n < -3"), "(-n) < (-3)");
        assert_eq!(st(" ((TRUE)) "), "TRUE");
        assert_eq!(st("x >= 1.5 (* a comment *)"), "x >= 1.5");
        assert!(p("true").unwrap().is_true());
        assert!(p("not FALSE").is_ok());
    }

    /// TIME literals (IEC 61131-3): units from days to nanoseconds, `_` between components, a
    /// fraction on the last; rendered in milliseconds for listings.
    #[test]
    fn time_literals_are_read() {
        assert_eq!(st("S.t > T#350ms"), "S.t > T#350ms");
        assert_eq!(st("S.t > t#1h1m"), "S.t > T#3660000ms");
        assert_eq!(st("S.t >= TIME#1s_500ms"), "S.t >= T#1500ms");
        assert_eq!(st("S.t > T#0.35S"), "S.t > T#350ms");
        assert_eq!(st("S.t > LT#1d"), "S.t > T#86400000ms");
        assert_eq!(st("S.t > T#1us"), "S.t > T#0.001ms");
        assert_eq!(st("S.t > T#+2s"), "S.t > T#2000ms");
        let e = |s: &str| p(s).unwrap_err().message;
        assert!(e("S.t > T#5").contains("not a unit"), "{}", e("S.t > T#5"));
        assert!(e("S.t > T#5x").contains("not a unit"));
        assert!(e("S.t > T#-5s").contains("never negative"));
        assert!(e("S.t > T#1s1m").contains("days down to"));
        assert!(e("S.t > T#1.5s2ms").contains("last unit"));
        assert!(e("S.t > T#s").contains("a number and a unit"));
        assert!(e("S.t > T#99999999999d").contains("too long"));
        // Times compare with times only.
        let ty = |s: &str| {
            check(&p(s).unwrap(), &|n| (n == "S.t").then_some(Ty::Time))
                .into_iter()
                .map(|e| e.message)
                .collect::<Vec<_>>()
        };
        assert!(ty("S.t > T#1s").is_empty());
        assert!(ty("T#1s < S.t AND S.t <> T#2s").is_empty());
        assert!(!ty("S.t > 5").is_empty());
        assert!(!ty("S.t AND TRUE").is_empty());
        assert!(!ty("-S.t < T#1s").is_empty());
    }

    /// Standard functions called in ST, as the blocks of a wired condition; `expr;` as a
    /// statement.
    #[test]
    fn function_calls_are_read() {
        assert_eq!(st("AND(a, b, c)"), "(a AND b) AND c");
        assert_eq!(st("OR(a, NOT b)"), "a OR (NOT b)");
        assert_eq!(st("xor(a, b)"), "a XOR b");
        assert_eq!(st("GT(n, 2)"), "n > 2");
        assert_eq!(st("GE(a, b, c)"), "(a >= b) AND (b >= c)");
        assert_eq!(st("SEL(g, a, b)"), "(g AND b) OR ((NOT g) AND a)");
        assert_eq!(st("MOVE(a) AND NOT(b)"), "a AND (NOT b)");
        assert_eq!(st("AND(EQ(n, 1), b)"), "(n = 1) AND b");
        assert_eq!(
            st("GT(ADD(n, 2, m), MUL(n, 3))"),
            "ADD(ADD(n, 2), m) > MUL(n, 3)"
        );
        assert_eq!(st("SUB(n, 1) = 0"), "SUB(n, 1) = 0");
        assert_eq!(
            render_krl(&p("GT(SUB(n, 1), 2)").unwrap(), &|n| n.to_owned()),
            "(n - 1) > 2"
        );
        assert!(
            !check(&p("ADD(a, 1) AND b").unwrap(), &|_| Some(Ty::Bool)).is_empty(),
            "arithmetic of booleans"
        );
        assert!(check(&p("ADD(a, 1) > b").unwrap(), &|_| Some(Ty::Number)).is_empty());
        assert!(p("SUB(a, b, c)").unwrap_err().message.contains("takes 2"));
        assert_eq!(st("a = b;"), "a = b");
        assert_eq!(st("a ; (* done *)"), "a");
        let e = |s: &str| p(s).unwrap_err().message;
        assert!(e("TON(a, b)").contains("not part of the condition language"));
        assert!(e("AND(a)").contains("at least 2"));
        assert!(e("SEL(a, b)").contains("takes 3"));
        assert!(e("AND(a, b").contains("without its `)`"));
        assert!(e("AND(a b)").contains("`,` or `)`"));
        assert!(e("a; b").contains("one expression"));
    }

    /// IEC 61131-3 literals (docs/INPUTS.md): `1`/`0` as booleans where a boolean belongs, `BOOL#1`,
    /// typed and based literals, `_` between digits; written in decimal.
    #[test]
    fn iec_literals_are_read() {
        assert!(p("1").unwrap().is_true());
        assert_eq!(st("0"), "FALSE");
        assert_eq!(st("BOOL#1 AND BOOL#FALSE"), "TRUE AND FALSE");
        assert_eq!(st("NOT 0"), "NOT FALSE");
        assert_eq!(st("a AND 1"), "a AND TRUE");
        assert_eq!(st("(n > 2) = 1"), "(n > 2) = TRUE");
        // A number where a number belongs stays one.
        assert_eq!(st("n = 1"), "n = 1");
        assert_eq!(st("n >= 1"), "n >= 1");
        assert_eq!(st("n = 16#FF"), "n = 255");
        assert_eq!(st("n = 2#1010 OR n = 8#17"), "(n = 10) OR (n = 15)");
        assert_eq!(st("n = INT#-5"), "n = (-5)");
        assert_eq!(st("n = DINT#16#1_0"), "n = 16");
        assert_eq!(st("n < 1_000"), "n < 1000");
        assert_eq!(st("x > REAL#1.5"), "x > 1.5");
        assert_eq!(st("x > LREAL#2"), "x > 2.0");
        assert_eq!(st("n = 007"), "n = 7");
        let e = |s: &str| p(s).unwrap_err().message;
        assert!(e("n = 3#12").contains("base"), "{}", e("n = 3#12"));
        assert!(e("n = 16#").contains("digits of its base"));
        assert!(e("n = 1__0").contains("between digits"));
        assert!(e("n = 1_").contains("between digits"));
        assert!(e("BOOL#2").contains("not a BOOL literal"));
        assert!(e("t > STRING#5").contains("not part of the condition language"));
        assert!(e("n = INT#1.5").contains("fraction"));
        assert!(e("n = 16#1_0000_0000").contains("larger than a KRL integer"));
    }

    /// Short texts of the characters literals are made of never make the reader panic, and an
    /// error's place is always within the text.
    #[test]
    fn literal_like_texts_never_panic() {
        let alphabet: Vec<char> = "01279#_.-+ABFTxü€ (INT#BOOL#)".chars().collect();
        // Found by the fuzzer: a typed literal followed by a letter of two bytes.
        for t in [
            "BOOL#ö",
            "BOOL#öx",
            "INT#ö",
            "16#ö",
            "REAL#ü",
            "1_ö",
            "2#ö",
            "BOOL#\u{f6}rUng\u{0}\u{0}\u{0}\u{0}\u{0}\u{0}\u{0}\u{4}\u{4}\u{4}\u{4}\u{4}\u{4}L#F\u{6}\u{4}\u{4}\u{4}6\u{0}\u{0}\u{0}\u{0}\u{0}\u{4}\u{4}1S T",
        ] {
            if let Err(e) = p(t) {
                assert!(
                    t.is_char_boundary(e.at.start) && t.is_char_boundary(e.at.end),
                    "{t:?}"
                );
            }
        }
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        for _ in 0..50_000 {
            let mut t = String::new();
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            for k in 0..(x % 9) {
                t.push(alphabet[((x >> (k * 5)) % alphabet.len() as u64) as usize]);
            }
            match p(&t) {
                Err(e) => assert!(
                    e.at.end <= t.len()
                        && t.is_char_boundary(e.at.start)
                        && t.is_char_boundary(e.at.end),
                    "{t:?}: {e:?}"
                ),
                // Printed back as ST, it reads the same (the fuzz target's round trip).
                Ok(e) => {
                    let printed = e.to_st();
                    assert_eq!(p(&printed).map(|x| x.to_st()), Ok(printed), "{t:?}");
                }
            }
        }
    }

    #[test]
    fn krl_keeps_the_meaning() {
        let sig = |n: &str| match n {
            "a" => "$IN[1]".to_owned(),
            "b" => "$IN[2]".to_owned(),
            other => other.to_ascii_uppercase(),
        };
        let k = |s: &str| render_krl(&p(s).unwrap(), &sig);
        // ST: `n = 3 AND a` is `(n = 3) AND a`; KRL would read `N == (3 AND $IN[1])`.
        assert_eq!(k("n = 3 AND a"), "(N == 3) AND $IN[1]");
        assert_eq!(k("a XOR b"), "$IN[1] EXOR $IN[2]");
        assert_eq!(k("n <> 2"), "N <> 2");
        assert_eq!(k("NOT a OR b"), "(NOT $IN[1]) OR $IN[2]");
        assert_eq!(k("a = b"), "$IN[1] == $IN[2]");
    }

    #[test]
    fn syntax_errors_are_located() {
        let e = |s: &str| p(s).unwrap_err();
        assert_eq!(e("a AND").at, 4..5);
        assert!(e("a AND").message.contains("ends where an operand"));
        assert_eq!(e("a b").at, 2..3);
        assert!(e("a b").message.contains("operator is missing"));
        assert_eq!(e("(a OR b").at, 0..1);
        assert_eq!(
            st("Robot.Ready AND NOT GVL.Door_Open"),
            "Robot.Ready AND (NOT GVL.Door_Open)"
        );
        assert_eq!(e("Robot.5").at, 5..6);
        assert_eq!(e("Robot.").at, 5..6);
        assert!(e("%IX0.1").message.contains("direct addresses"));
        assert_eq!(e("a := 1").at, 2..3);
        assert_eq!(e("  ").at, 0..2);
        assert_eq!(e("3a").at, 0..2);
        assert_eq!(e("a AND )").at, 6..7);
        assert!(e("(* open").message.contains("`*)`"));
        assert!(
            e("n = 2147483648")
                .message
                .contains("larger than a KRL integer")
        );
        assert!(p("n = 2147483647").is_ok());
        // Unicode letters are letters of names (docs/INPUTS.md); other characters are not.
        assert_eq!(st("Störung AND Grüße"), "Störung AND Grüße");
        assert!(e("a € b").message.contains("`€`"));
        let deep = format!("{}a{}", "(".repeat(100), ")".repeat(100));
        assert!(e(&deep).message.contains("deeper"));
        let nots = format!("{}a", "NOT ".repeat(100));
        assert!(e(&nots).message.contains("deeper"));
        let long = vec!["a"; 600].join(" AND ");
        assert!(e(&long).message.contains("longer than 1024 tokens"));
        let fine = vec!["a"; 500].join(" OR ");
        assert!(p(&fine).is_ok());
    }

    #[test]
    fn spans_follow_the_map() {
        let e = parse("a OR b", &|o| o + 100).unwrap();
        assert_eq!(e.span, 100..106);
        assert_eq!(e.names(), vec![("a", 100..101), ("b", 105..106)]);
    }

    #[test]
    fn types() {
        let look = |n: &str| match n {
            "a" | "b" => Some(Ty::Bool),
            "n" => Some(Ty::Number),
            _ => None,
        };
        let c = |s: &str| check(&p(s).unwrap(), &look);
        assert!(c("a AND NOT b OR n = 3").is_empty());
        assert!(c("n <> -2 XOR a").is_empty());
        let e = c("n AND a");
        assert_eq!(e.len(), 1);
        assert!(e[0].message.contains("needs a boolean"), "{e:?}");
        assert!(
            c("a = 3")[0]
                .message
                .contains("compares a boolean with a number")
        );
        assert!(c("n")[0].message.contains("not a boolean"));
        assert!(c("a < b")[0].message.contains("needs a number"));
        let u = c("x OR y");
        assert_eq!(u.len(), 2);
        assert!(u[0].unknown && u[0].message == "x");
    }
}
