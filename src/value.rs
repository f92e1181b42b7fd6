//! SFC variable values (docs/INPUTS.md): the list syntax `(a, (b, c))`, looking an item up in place,
//! and the language-neutral typed [`Literal`] a value becomes for a parameter. Which text a
//! literal is in a robot language is the language profile's business (`emit::Profile`).

use std::borrow::Cow;

/// The value types of docs/INPUTS.md.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueType {
    Double,
    Decimal,
    Integer,
    Boolean,
    String,
}

impl ValueType {
    pub fn parse(s: &str) -> Option<Self> {
        let t = s.trim();
        let local = t.rsplit(':').next().unwrap_or(t);
        match local.to_ascii_lowercase().as_str() {
            "double" | "float" => Some(ValueType::Double),
            "decimal" => Some(ValueType::Decimal),
            "integer" | "int" | "long" | "short" => Some(ValueType::Integer),
            "boolean" => Some(ValueType::Boolean),
            "string" | "anyuri" => Some(ValueType::String),
            _ => None,
        }
    }

    pub fn xs_name(self) -> &'static str {
        match self {
            ValueType::Double => "xs:double",
            ValueType::Decimal => "xs:decimal",
            ValueType::Integer => "xs:integer",
            ValueType::Boolean => "xs:boolean",
            ValueType::String => "xs:string",
        }
    }
}

/// An SFC variable's value: `(a, (b, c))` nests lists, anything else is one trimmed value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Scalar(String),
    List(Vec<Value>),
}

/// Lists nest at most this deep.
pub const MAX_LIST_DEPTH: usize = 32;

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
    lookup_from(raw.trim(), indices, 0)
}

/// [`lookup`] in `cur`, a value found at `depth0` levels down (for the depths it reports).
fn lookup_from<'a>(mut cur: &'a str, indices: &[usize], depth0: usize) -> Lookup<'a> {
    for (depth, &ix) in (depth0..).zip(indices) {
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

/// The items of the list [`lookup_in`] looked into last: a skill reads a frame's six items one
/// after another, and each would otherwise be found by scanning the list from its start.
#[derive(Debug, Default)]
pub struct ItemCache<'a> {
    list: Option<&'a str>,
    items: Vec<&'a str>,
}

/// [`lookup`], the items of the outermost list kept in `cache` for the next look-up into the
/// same text (the same place in memory, not equal text). The result is [`lookup`]'s.
pub fn lookup_in<'a>(raw: &'a str, indices: &[usize], cache: &mut ItemCache<'a>) -> Lookup<'a> {
    let cur = raw.trim();
    let Some((&first, rest)) = indices.split_first() else {
        return lookup(raw, indices);
    };
    if !cur.starts_with('(') {
        return Lookup::NotAList { depth: 0 };
    }
    let same = cache
        .list
        .is_some_and(|l| l.as_ptr() == cur.as_ptr() && l.len() == cur.len());
    if !same {
        cache.items.clear();
        cache.items.extend(items(cur));
        cache.list = Some(cur);
    }
    match cache.items.get(first) {
        None => Lookup::OutOfRange {
            depth: 0,
            len: cache.items.len(),
        },
        Some(item) => lookup_from(item, rest, 1),
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
    if plain_list(text.as_bytes()) {
        return Ok(());
    }
    parse(text, false).map(|_| ())
}

/// Whether `text` is a list of plain items, as most values are (a frame's six numbers): `(`,
/// items of printable ASCII and spaces (no quote, no parenthesis), each with a printable byte,
/// separated by `,`, then `)`, with spaces around. One pass over the bytes, where [`parse`]
/// takes three times as long (the SFC's reader checks every value of a chart). `false` for
/// anything else, well-formed or not: [`parse`] then decides, and words its error.
fn plain_list(text: &[u8]) -> bool {
    let mut b = text;
    while let [b' ', rest @ ..] = b {
        b = rest;
    }
    while let [rest @ .., b' '] = b {
        b = rest;
    }
    let [b'(', inner @ .., b')'] = b else {
        return false;
    };
    // Whether the item so far has a printable byte.
    let mut filled = false;
    for &c in inner {
        match c {
            b',' if filled => filled = false,
            b' ' => {}
            b'!'..=b'~' if !matches!(c, b',' | b'(' | b')' | b'"') => filled = true,
            _ => return false,
        }
    }
    filled
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
                Some(&first) => {
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
                    let item = &self.text[start..self.i];
                    // An item that starts with a printable ASCII byte is not empty; any other
                    // is trimmed to tell.
                    if !first.is_ascii_graphic() && item.trim().is_empty() {
                        // Whitespace that `skip_ws` leaves (e.g. a vertical tab) is still
                        // whitespace: `(a, \u{b})` has an empty item like `(a, )`.
                        self.i = start;
                        return Err(self.err("empty list item"));
                    }
                    if self.build {
                        items.push(Value::Scalar(item.trim().to_owned()));
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

/// A value made ready for one parameter, before any robot language: a typed literal. The
/// language profile renders it (`TRUE` or `True`, `"text"`) and refuses what its language cannot
/// take safely.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Literal<'a> {
    /// A number in the common form: optional `-`, digits with a digit on both sides of a `.`,
    /// an upper-case `E` exponent without `+` (`0.5`, `-1.0E3`).
    Number(Cow<'a, str>),
    Bool(bool),
    /// A string's text, without quotes: printable ASCII without `"` (a profile may refuse more).
    Str(&'a str),
    /// One word: a name (`tool0`), or in KRL a system variable or enumeration value (`$POS_ACT`,
    /// `#INITMOV`), kept as written.
    Word(&'a str),
}

impl Literal<'_> {
    /// The number's value, for conversions; `None` when the literal is not a number.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Literal::Number(s) => s.parse().ok(),
            _ => None,
        }
    }
}

/// A value as the literal of its parameter's type (`None`: untyped, which takes one token: a
/// number, `TRUE`/`FALSE`, a name, `$name`, `#name` or a `"string"`). `Err` says why not, for the
/// diagnostic (a message starting with `non-ASCII` is one about the character set).
pub fn literal(s: &str, ty: Option<ValueType>) -> Result<Literal<'_>, String> {
    match ty {
        Some(ValueType::Double) if is_number(s, true) => Ok(Literal::Number(normal_number(s))),
        Some(ValueType::Decimal) if is_number(s, false) => Ok(Literal::Number(normal_number(s))),
        Some(ValueType::Integer) if is_integer(s) => Ok(Literal::Number(normal_number(s))),
        Some(ValueType::Boolean) => match s.to_ascii_lowercase().as_str() {
            "true" | "1" => Ok(Literal::Bool(true)),
            "false" | "0" => Ok(Literal::Bool(false)),
            _ => Err("not an xs:boolean (true, false, 1 or 0)".to_owned()),
        },
        Some(ValueType::String) => string_text(s).map(Literal::Str),
        Some(t) => Err(format!("not an {}", t.xs_name())),
        None => {
            if is_number(s, true) {
                Ok(Literal::Number(normal_number(s)))
            } else if s.eq_ignore_ascii_case("true") {
                Ok(Literal::Bool(true))
            } else if s.eq_ignore_ascii_case("false") {
                Ok(Literal::Bool(false))
            } else if is_ident(s) || s.strip_prefix(['$', '#']).is_some_and(is_ident) {
                Ok(Literal::Word(s))
            } else if s.len() >= 2 && s.starts_with('"') && s.ends_with('"') {
                string_text(&s[1..s.len() - 1]).map(Literal::Str)
            } else if !s.is_ascii() {
                Err("non-ASCII character in a value (robot code is ASCII)".to_owned())
            } else {
                Err("an untyped value must be one token (a number, TRUE/FALSE, a name or a \"string\"); give the parameter an AttributeDataType".to_owned())
            }
        }
    }
}

/// A string's text checked: one line of printable ASCII without `"`.
fn string_text(s: &str) -> Result<&str, String> {
    if s.contains('"') {
        Err("a string value must not contain `\"`".to_owned())
    } else if s.contains(['\n', '\r']) {
        Err("a string value must not contain a line break".to_owned())
    } else if !s.is_ascii() {
        Err("non-ASCII character in a string value (robot code is ASCII)".to_owned())
    } else if s.chars().any(|c| c.is_ascii_control()) {
        Err("a string value must not contain control characters".to_owned())
    } else {
        Ok(s)
    }
}

/// A checked number in the common form every profile's language reads: no `+`, a digit on both
/// sides of the point, `E` for the exponent without `+`.
fn normal_number(s: &str) -> Cow<'_, str> {
    if !needs_normal(s.as_bytes()) {
        return Cow::Borrowed(s);
    }
    let body = s.strip_prefix('+').unwrap_or(s);
    let (sign, body) = match body.strip_prefix('-') {
        Some(rest) => ("-", rest),
        None => ("", body),
    };
    let (mant, exp) = match body.find(['e', 'E']) {
        Some(i) => (&body[..i], Some(&body[i + 1..])),
        None => (body, None),
    };
    let mut out = String::with_capacity(s.len() + 2);
    out.push_str(sign);
    if mant.starts_with('.') {
        out.push('0');
    }
    out.push_str(mant);
    if mant.ends_with('.') {
        out.push('0');
    }
    if let Some(e) = exp {
        out.push('E');
        out.push_str(e.strip_prefix('+').unwrap_or(e));
    }
    Cow::Owned(out)
}

/// Whether [`normal_number`] changes `b`: a `+` in front or in the exponent, `e`, or a point
/// without a digit on one side (one pass: every value of every step comes here).
fn needs_normal(b: &[u8]) -> bool {
    if matches!(b.first(), Some(b'+' | b'.')) || b.last() == Some(&b'.') {
        return true;
    }
    let digit = |i: usize| b.get(i).is_some_and(u8::is_ascii_digit);
    b.iter().enumerate().any(|(i, &c)| match c {
        b'e' => true,
        b'E' => b.get(i + 1) == Some(&b'+'),
        b'.' => (i > 0 && !digit(i - 1)) || (i + 1 < b.len() && !digit(i + 1)),
        _ => false,
    })
}

fn is_integer(s: &str) -> bool {
    let d = s.strip_prefix(['+', '-']).unwrap_or(s);
    !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit())
}

/// A decimal number (`exp`: with an optional exponent), optionally signed.
pub fn is_number(s: &str, exp: bool) -> bool {
    let b = s.strip_prefix(['+', '-']).unwrap_or(s).as_bytes();
    let mut i = 0;
    while i < b.len() && b[i].is_ascii_digit() {
        i += 1;
    }
    let int_digits = i;
    let mut frac_digits = 0;
    if i < b.len() && b[i] == b'.' {
        i += 1;
        let f = i;
        while i < b.len() && b[i].is_ascii_digit() {
            i += 1;
        }
        frac_digits = i - f;
    }
    if int_digits + frac_digits == 0 {
        return false;
    }
    if exp && i < b.len() && (b[i] == b'e' || b[i] == b'E') {
        i += 1;
        if i < b.len() && (b[i] == b'+' || b[i] == b'-') {
            i += 1;
        }
        let e = i;
        while i < b.len() && b[i].is_ascii_digit() {
            i += 1;
        }
        if i == e {
            return false;
        }
    }
    i == b.len()
}

/// An ASCII identifier: a letter or `_`, then letters, digits or `_`.
pub fn is_ident(s: &str) -> bool {
    let b = s.as_bytes();
    !b.is_empty()
        && (b[0].is_ascii_alphabetic() || b[0] == b'_')
        && b.iter().all(|c| c.is_ascii_alphanumeric() || *c == b'_')
}

#[cfg(test)]
mod tests {
    /// [`needs_normal`] is the test it replaced, for every string of up to four characters
    /// from those that matter.
    #[test]
    fn needs_normal_is_the_old_test() {
        let old = |s: &str| {
            let b = s.as_bytes();
            s.starts_with('+')
                || s.contains("E+")
                || s.contains('e')
                || b.windows(2).any(|w| {
                    (w[1] == b'.' && !w[0].is_ascii_digit())
                        || (w[0] == b'.' && !w[1].is_ascii_digit())
                })
                || s.starts_with('.')
                || s.ends_with('.')
        };
        let alphabet = ["1", "0", ".", "+", "-", "e", "E", "x", " "];
        let mut checked = 0;
        every_word(&alphabet, 4, |n| {
            assert_eq!(needs_normal(n.as_bytes()), old(n), "{n:?}");
            checked += 1;
        });
        assert_eq!(needs_normal(b""), old(""));
        assert!(checked > 7000);
    }

    /// Every string of one to `max` pieces from `alphabet`, shorter ones first, each to `each`.
    fn every_word(alphabet: &[&str], max: usize, mut each: impl FnMut(&str)) {
        let mut words = vec![String::new()];
        for _ in 0..max {
            let mut longer = Vec::new();
            for w in &words {
                for c in alphabet {
                    let n = format!("{w}{c}");
                    each(&n);
                    longer.push(n);
                }
            }
            words = longer;
        }
    }

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
    fn a_cached_lookup_finds_what_a_lookup_finds() {
        let values = [
            "( 100, (1, \"a,b\"), (), 7 )",
            "(-137.9, -118.9, 306.1, -73, 10, -68)",
            "((1, (2, 3)), ((4)), \"(x, y)\", ( ))",
            "0.5",
            " abc ",
            "()",
            "( ( ) , 1 )",
        ];
        for v in values {
            assert!(check_value(v).is_ok(), "{v}");
        }
        let mut paths: Vec<Vec<usize>> = vec![vec![]];
        for a in 0..6 {
            paths.push(vec![a]);
            for b in 0..4 {
                paths.push(vec![a, b]);
                for c in 0..3 {
                    paths.push(vec![a, b, c]);
                }
            }
        }
        // One cache across every value and path, in an order that goes back and forth between
        // the values (the cache must notice the list changed).
        let mut cache = ItemCache::default();
        for round in 0..2 {
            for (k, p) in paths.iter().enumerate() {
                for (j, _) in values.iter().enumerate() {
                    let v = values[(j + k + round) % values.len()];
                    assert_eq!(lookup_in(v, p, &mut cache), lookup(v, p), "{v} {p:?}");
                }
            }
        }
        // Another list of the same length.
        let a = String::from("(1, 2)");
        let b = String::from("(3, 4)");
        assert_eq!(lookup_in(&a, &[1], &mut cache), Lookup::Scalar("2"));
        assert_eq!(lookup_in(&b, &[1], &mut cache), Lookup::Scalar("4"));
        assert_eq!(lookup_in(&a, &[0], &mut cache), Lookup::Scalar("1"));
        assert_eq!(
            lookup_in(&a, &[2], &mut cache),
            Lookup::OutOfRange { depth: 0, len: 2 }
        );
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
        // Found by fuzzing: an item of whitespace `skip_ws` does not skip is still empty.
        assert_eq!(parse_value("( \"\"`,\u{b}\r )").unwrap_err().0, 6);
        assert_eq!(check_value("( \"\"`,\u{b}\r )").unwrap_err().0, 6);
        // Non-ASCII white space too; an item that only starts with it is not empty. The check
        // and the parse agree.
        for (v, err) in [
            ("(a, \u{a0})", Some(4)),
            ("(a, \u{2003}\u{a0} )", Some(4)),
            ("(a, \u{a0}b)", None),
            ("(\u{e4}, b)", None),
        ] {
            assert_eq!(check_value(v).err().map(|e| e.0), err, "{v:?}");
            assert_eq!(parse_value(v).err().map(|e| e.0), err, "{v:?}");
        }
    }

    /// [`check_value`]'s short way for plain lists gives what [`parse`] gives, for every string
    /// of up to seven bytes from those that matter (white space of every kind, quotes,
    /// parentheses, commas, a non-ASCII character), and around longer ones.
    #[test]
    fn plain_lists_are_checked_as_the_parser_checks_them() {
        let alphabet = ["(", ")", ",", " ", "a", "\"", "\t", "\u{a0}"];
        let mut accepted = 0;
        every_word(&alphabet, 7, |n| {
            assert_eq!(check_value(n).err(), parse(n, false).err(), "{n:?}");
            if plain_list(n.as_bytes()) {
                accepted += 1;
                assert!(parse(n, false).is_ok(), "{n:?}");
            }
        });
        assert!(accepted > 200, "{accepted}");
        for v in [
            "(-137.9, -118.9, 306.1, -73, 10, -68)",
            " ( 1 , 2 ) ",
            "(#INITMOV, 'x', a_b)",
        ] {
            assert!(plain_list(v.as_bytes()), "{v}");
            assert_eq!(check_value(v), Ok(()));
        }
        for v in [
            "(1, (2))",
            "(\"a\", b)",
            "(1,)",
            "()",
            "(1) x",
            "1",
            "(1,\t2)",
        ] {
            assert!(!plain_list(v.as_bytes()), "{v}");
            assert_eq!(check_value(v).err(), parse(v, false).err(), "{v}");
        }
    }

    #[test]
    fn literals() {
        use ValueType::*;
        assert_eq!(
            literal("+.5e+3", Some(Double)),
            Ok(Literal::Number("0.5E3".into()))
        );
        assert_eq!(literal("7", Some(Integer)), Ok(Literal::Number("7".into())));
        assert!(literal("7.5", Some(Integer)).is_err());
        assert_eq!(literal("1", Some(Boolean)), Ok(Literal::Bool(true)));
        assert_eq!(literal("true", None), Ok(Literal::Bool(true)));
        assert_eq!(literal("a b", Some(String)), Ok(Literal::Str("a b")));
        assert_eq!(literal("\"x\"", None), Ok(Literal::Str("x")));
        assert_eq!(literal("#INITMOV", None), Ok(Literal::Word("#INITMOV")));
        assert!(literal("a;b", None).is_err());
        assert!(literal("\"a\"b\"", None).is_err());
        assert!(literal("a\"b", Some(String)).is_err());
        assert!(literal("Ä", None).unwrap_err().starts_with("non-ASCII"));
        assert_eq!(Literal::Number("-1.5".into()).as_f64(), Some(-1.5));
    }
}
