//! The condition's tokens: `Lexer` (names, operators, `(* comments *)`), numbers, typed
//! literals (`INT#5`, `BOOL#1`), TIME literals in nanoseconds, and `decimal` to write them back.

use std::ops::Range;

use super::{BinOp, SyntaxError};

#[derive(Debug, Clone, PartialEq)]
pub(super) enum Tok {
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

pub(super) struct Lexer {
    toks: Vec<(Tok, Range<usize>)>,
}

pub(super) fn describe(text: &str, r: &Range<usize>) -> String {
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
    pub(super) fn run(text: &str) -> Result<Vec<(Tok, Range<usize>)>, SyntaxError> {
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
