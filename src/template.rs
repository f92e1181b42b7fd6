//! IRL template parsing and parameter substitution (docs/INPUTS.md).
//!
//! A template is compiled once ([`Template::compile`]) into a list of pieces — literal text and
//! parameter slots — and rendered many times ([`Template::render`]) by a plain walk over them.
//! Compiling is one linear pass over the text; no regular expressions.
//!
//! # Substitution rules
//!
//! - **Words.** A word is a maximal run of identifier characters: ASCII letters and digits, `_`,
//!   `$`, and (so that a non-ASCII letter never splits a word) any non-ASCII character. Every
//!   other character separates words; in particular `.` does.
//! - **Parameters.** A word is replaced by a parameter's value when it equals the parameter's
//!   name case-insensitively ([`crate::names`]; exactly in URScript, a case-sensitive language:
//!   `a=1.2` there is a keyword argument, not parameter `A`), and it is not excluded by the next
//!   rule. A parameter name that is not a single word (`End Position`) can therefore never occur.
//! - **Never substituted:** a word starting with `$` (a KRL system variable: `$VEL`), a word
//!   starting with a digit (a number: `1E3`), a word directly after `.` (a structure member:
//!   `CP` in `$VEL.CP`, `X` in `P.X`; the word before the `.` is substituted normally), a word
//!   directly after `#` (an enum constant: `#PTP_PARAMS`) or `'` (a bit/hex literal: `'H1F'`).
//! - **String literals** `"..."` (to the next `"` or the end of the line — KRL has no escapes)
//!   and **comments** `;...` (to the end of the line) are copied verbatim.
//! - **Aggregates** `{...}`: the items are separated by the commas outside nested `()`/`[]`/`{}`.
//!   An item that consists only of a parameter `P` (whitespace around it allowed) becomes
//!   `P value`: the name as written, one space, the value (`{X, Y}` → `{X 100, Y 200}`). In any
//!   other item the first word is a field name and is never substituted; the rest of the item is
//!   substituted by the rules above (`{X PX}` → `{X 100}`). A type prefix at the start of an
//!   aggregate (`{E6POS: X, Y}`) is skipped, and the first item starts after the `:`. Nested
//!   aggregates (`{POS {X, Y}}`) follow the same rules at every level. KRL statements are one
//!   line each, so an aggregate left open at the end of a line is closed there.
//! - **Languages.** The comment character and the aggregate rule are the template language's
//!   ([`Syntax`]): KRL comments start with `;` and `{...}` is an aggregate; RAPID comments start
//!   with `!`, URScript's with `#`, and neither has the aggregate rule (`;` ends a RAPID
//!   statement and is copied like any punctuation).
//! - **Conversions** (docs/LANGUAGES.md): `m(P)`, `mm(P)`, `rad(P)`, `deg(P)`, `quat(A, B, C)`,
//!   `rotvec(A, B, C)` — the exact lower-case name, then `(`, arguments that are parameters or
//!   numbers, `)` — are evaluated when the program is bound: the whole call is replaced by the
//!   result, numbers joined by `, ` ([`crate::convert`]). A conversion with other arguments is a
//!   template error ([`Template::errors`]).
//! - Everything else — whitespace, case, punctuation — is copied byte for byte. Values are
//!   inserted as they are and never substituted again.

use std::collections::HashMap;

use crate::convert::Conversion;

/// What a template's language changes in the substitution rules.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Syntax {
    /// The byte that starts a comment to the end of the line.
    pub comment: u8,
    /// Whether `{...}` is a KRL aggregate (the `{X, Y}` → `{X 1, Y 2}` rule).
    pub aggregates: bool,
    /// Whether a word must equal a parameter's name exactly (URScript: `a=1.2` is a keyword
    /// argument, not parameter `A`); else case-insensitively.
    pub case_sensitive: bool,
}

impl Syntax {
    /// KRL's: `;` comments, aggregates.
    pub const KRL: Syntax = Syntax {
        comment: b';',
        aggregates: true,
        case_sensitive: false,
    };
}

/// One conversion in a template: what, and its arguments.
#[derive(Debug, Clone, PartialEq)]
pub struct Conv {
    pub conversion: Conversion,
    pub args: Vec<ConvArg>,
}

/// A conversion's argument: a parameter (by index) or a number written in the template.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ConvArg {
    Param(usize),
    Number(f64),
}

/// Why a conversion could not be rendered.
#[derive(Debug, Clone, PartialEq)]
pub enum ConvError {
    /// The parameter (index) of the conversion is not a number.
    NotANumber {
        conversion: Conversion,
        param: usize,
    },
    /// The result is too large to write (or not finite).
    OutOfRange { conversion: Conversion },
}

/// A compiled template: literal text and parameter slots.
#[derive(Debug, Clone)]
pub struct Template {
    /// All literal text, the pieces' ranges point into it.
    lits: String,
    pieces: Vec<Piece>,
    used: Vec<bool>,
    convs: Vec<Conv>,
    /// Conversions that cannot be used: `(byte offset in the text, message)`.
    errors: Vec<(usize, String)>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Piece {
    /// `lits[start..end]`.
    Lit(usize, usize),
    /// The value of parameter `n`.
    Param(usize),
    /// A conversion (index into `convs`).
    Conv(usize),
}

/// Parse state of one open aggregate.
struct Frame {
    /// No character of the current item seen yet (only whitespace).
    item_start: bool,
    /// The current item is the aggregate's first one (a type prefix may stand there).
    first_item: bool,
    /// Nesting of `(` and `[` inside the current item.
    depth: u32,
}

/// Whether `b` belongs to a word.
fn is_word_byte(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_' || b == b'$' || b >= 0x80
}

struct Compiler<'t> {
    text: &'t str,
    lits: String,
    pieces: Vec<Piece>,
    used: Vec<bool>,
    /// Parameter key → index (the first of equal names wins).
    index: HashMap<String, usize>,
    /// Start of the literal text not yet copied into `lits`.
    pending: usize,
    /// Scratch buffer for lower-casing words.
    buf: String,
    syntax: Syntax,
    convs: Vec<Conv>,
    errors: Vec<(usize, String)>,
}

impl<'t> Compiler<'t> {
    /// The parameter a word at `start..end` stands for, if it may be substituted there.
    fn param_at(&mut self, start: usize, end: usize) -> Option<usize> {
        let b = self.text.as_bytes();
        let first = b[start];
        if first == b'$' || first.is_ascii_digit() {
            return None;
        }
        if start > 0 && matches!(b[start - 1], b'.' | b'#' | b'\'') {
            return None;
        }
        let word = &self.text[start..end];
        if self.syntax.case_sensitive {
            return self.index.get(word).copied();
        }
        self.buf.clear();
        if word.is_ascii() {
            self.buf
                .extend(word.bytes().map(|c| char::from(c.to_ascii_lowercase())));
        } else {
            self.buf.push_str(&crate::names::key(word));
        }
        self.index.get(self.buf.as_str()).copied()
    }

    /// Copies the pending literal text up to `end`.
    fn flush(&mut self, end: usize) {
        if end > self.pending {
            let lit = &self.text[self.pending..end];
            self.push_lit(lit);
        }
        self.pending = end;
    }

    fn push_lit(&mut self, lit: &str) {
        let start = self.lits.len();
        self.lits.push_str(lit);
        let end = self.lits.len();
        if let Some(Piece::Lit(_, e)) = self.pieces.last_mut()
            && *e == start
        {
            *e = end;
            return;
        }
        self.pieces.push(Piece::Lit(start, end));
    }

    /// Replaces the word at `start..end` by parameter `p`.
    fn slot(&mut self, start: usize, end: usize, p: usize) {
        self.flush(start);
        self.pieces.push(Piece::Param(p));
        self.used[p] = true;
        self.pending = end;
    }

    /// At a word `start..end` that names a conversion: the conversion call up to its `)`,
    /// compiled into a piece. Returns where scanning goes on; `None` leaves the word to the
    /// other rules (not a call: no `(` follows, or the word follows `.`/`#`/`'`; or a call that
    /// cannot be a conversion, recorded in `errors`).
    fn conversion(&mut self, start: usize, end: usize) -> Option<usize> {
        let b = self.text.as_bytes();
        let conversion = Conversion::from_name(&self.text[start..end])?;
        if start > 0 && matches!(b[start - 1], b'.' | b'#' | b'\'') {
            return None;
        }
        let mut open = end;
        while open < b.len() && (b[open] == b' ' || b[open] == b'\t') {
            open += 1;
        }
        if b.get(open) != Some(&b'(') {
            return None;
        }
        // The `)` on the same line, before a comment or a string starts.
        let comment = self.syntax.comment;
        let close = b[open + 1..]
            .iter()
            .position(|&c| c == b')' || c == b'\n' || c == comment || c == b'"')
            .map(|k| open + 1 + k)
            .filter(|&k| b[k] == b')');
        let Some(close) = close else {
            self.errors.push((
                start,
                format!(
                    "conversion `{}(` without its `)` on the same line",
                    conversion.name()
                ),
            ));
            // Not a conversion: the words go on by the other rules.
            return None;
        };
        let inner = &self.text[open + 1..close];
        let mut args = Vec::new();
        let mut bad = None;
        for arg in inner.split(',') {
            let a = arg.trim();
            let arg_start = open + 1 + (arg.as_ptr() as usize - inner.as_ptr() as usize);
            let a_start = arg_start + (arg.len() - arg.trim_start().len());
            if crate::value::is_number(a, true) {
                match a.parse::<f64>() {
                    Ok(x) if x.is_finite() => args.push(ConvArg::Number(x)),
                    _ => bad = Some(format!("argument `{a}` is out of range")),
                }
            } else if !a.is_empty()
                && a.bytes().all(is_word_byte)
                && let Some(p) = self.param_at(a_start, a_start + a.len())
            {
                args.push(ConvArg::Param(p));
            } else {
                bad = Some(format!(
                    "argument `{a}` is neither a parameter of the function-call nor a number"
                ));
            }
        }
        if bad.is_none() && args.len() != conversion.arity() {
            bad = Some(format!(
                "takes {} argument{}, not {}",
                conversion.arity(),
                if conversion.arity() == 1 { "" } else { "s" },
                args.len()
            ));
        }
        if let Some(why) = bad {
            self.errors.push((
                start,
                format!("conversion `{}`: {why}", &self.text[start..=close]),
            ));
            // Not a conversion: the words go on by the other rules.
            return None;
        }
        self.flush(start);
        for a in &args {
            if let ConvArg::Param(p) = *a {
                self.used[p] = true;
            }
        }
        self.pieces.push(Piece::Conv(self.convs.len()));
        self.convs.push(Conv { conversion, args });
        self.pending = close + 1;
        Some(close + 1)
    }

    fn run(mut self) -> Template {
        let b = self.text.as_bytes();
        let n = b.len();
        let mut stack: Vec<Frame> = Vec::new();
        let mut i = 0;
        let comment = self.syntax.comment;
        let aggregates = self.syntax.aggregates;
        while i < n {
            let c = b[i];
            match c {
                b'\n' => {
                    stack.clear();
                    i += 1;
                }
                b' ' | b'\t' | b'\r' => i += 1,
                c if c == comment => {
                    while i < n && b[i] != b'\n' {
                        i += 1;
                    }
                }
                b'"' => {
                    in_item(&mut stack);
                    i += 1;
                    while i < n && b[i] != b'"' && b[i] != b'\n' {
                        i += 1;
                    }
                    if i < n && b[i] == b'"' {
                        i += 1;
                    }
                }
                b'{' if aggregates => {
                    in_item(&mut stack);
                    stack.push(Frame {
                        item_start: true,
                        first_item: true,
                        depth: 0,
                    });
                    i += 1;
                }
                b'}' if aggregates => {
                    stack.pop();
                    i += 1;
                }
                b'(' | b'[' => {
                    if let Some(f) = stack.last_mut() {
                        f.item_start = false;
                        f.depth += 1;
                    }
                    i += 1;
                }
                b')' | b']' => {
                    if let Some(f) = stack.last_mut() {
                        f.depth = f.depth.saturating_sub(1);
                    }
                    i += 1;
                }
                b',' => {
                    if let Some(f) = stack.last_mut()
                        && f.depth == 0
                    {
                        f.item_start = true;
                        f.first_item = false;
                    }
                    i += 1;
                }
                c if is_word_byte(c) => {
                    let start = i;
                    while i < n && is_word_byte(b[i]) {
                        i += 1;
                    }
                    let end = i;
                    if let Some(next) = self.conversion(start, end) {
                        in_item(&mut stack);
                        i = next;
                        continue;
                    }
                    match stack.last_mut() {
                        Some(f) if f.item_start => {
                            let mut j = end;
                            while j < n && (b[j] == b' ' || b[j] == b'\t') {
                                j += 1;
                            }
                            let next = b.get(j).copied();
                            if next == Some(b':') && f.first_item {
                                // `{E6POS: ...}`: a type prefix; the first item follows.
                                f.first_item = false;
                                i = j + 1;
                            } else if matches!(next, Some(b',' | b'}')) {
                                f.item_start = false;
                                if let Some(p) = self.param_at(start, end) {
                                    // `P` alone → `P value`.
                                    self.flush(end);
                                    self.push_lit(" ");
                                    self.pieces.push(Piece::Param(p));
                                    self.used[p] = true;
                                }
                            } else {
                                // A field name: never substituted.
                                f.item_start = false;
                            }
                        }
                        _ => {
                            if let Some(p) = self.param_at(start, end) {
                                self.slot(start, end, p);
                            }
                        }
                    }
                }
                _ => {
                    in_item(&mut stack);
                    i += 1;
                }
            }
        }
        self.flush(n);
        self.lits.shrink_to_fit();
        self.pieces.shrink_to_fit();
        Template {
            lits: self.lits,
            pieces: self.pieces,
            used: self.used,
            convs: self.convs,
            errors: self.errors,
        }
    }
}

/// Marks the current aggregate item (if any) as started.
fn in_item(stack: &mut [Frame]) {
    if let Some(f) = stack.last_mut() {
        f.item_start = false;
    }
}

impl Template {
    /// Compiles `text` (already dedented, lines joined by '\n') for the parameters `params`
    /// (names as declared; matching is case-insensitive via [`crate::names`]).
    pub fn compile(text: &str, params: &[String]) -> Template {
        Self::compile_for(text, params, Syntax::KRL)
    }

    /// [`Template::compile`] with a language's [`Syntax`].
    pub fn compile_for(text: &str, params: &[String], syntax: Syntax) -> Template {
        let mut index = HashMap::with_capacity(params.len());
        for (i, p) in params.iter().enumerate() {
            let key = if syntax.case_sensitive {
                p.clone()
            } else {
                crate::names::key(p)
            };
            index.entry(key).or_insert(i);
        }
        Compiler {
            text,
            lits: String::with_capacity(text.len() + 8),
            pieces: Vec::new(),
            used: vec![false; params.len()],
            index,
            pending: 0,
            buf: String::new(),
            syntax,
            convs: Vec::new(),
            errors: Vec::new(),
        }
        .run()
    }

    /// Renders with `values[i]` for `params[i]` into `out` (lines joined by '\n', no trailing
    /// newline). Never panics; a missing value renders as nothing.
    pub fn render<S: AsRef<str>>(&self, values: &[S], out: &mut String) {
        // Conversions read the values as numbers; a value that is none leaves its conversion
        // out (the binder, which knows where the value came from, uses `render_with`).
        let _ = self.render_with(values, &|p| values.get(p)?.as_ref().parse().ok(), out);
    }

    /// Renders with `values` (as the output writes them) and `number` (a parameter's value as a
    /// number, for conversions; `None`: not a number). On a conversion error `out` holds the
    /// text up to it.
    pub fn render_with<S: AsRef<str>>(
        &self,
        values: &[S],
        number: &dyn Fn(usize) -> Option<f64>,
        out: &mut String,
    ) -> Result<(), ConvError> {
        debug_assert_eq!(values.len(), self.used.len(), "one value per parameter");
        out.reserve(self.lits.len() + 8 * values.len());
        for piece in &self.pieces {
            match *piece {
                Piece::Lit(s, e) => out.push_str(&self.lits[s..e]),
                Piece::Param(p) => {
                    if let Some(v) = values.get(p) {
                        out.push_str(v.as_ref());
                    }
                }
                Piece::Conv(c) => {
                    let conv = &self.convs[c];
                    let mut args = [0.0; 3];
                    for (k, a) in conv.args.iter().enumerate() {
                        args[k] = match *a {
                            ConvArg::Number(x) => x,
                            ConvArg::Param(p) => number(p).ok_or(ConvError::NotANumber {
                                conversion: conv.conversion,
                                param: p,
                            })?,
                        };
                    }
                    let mut res = [0.0; 4];
                    conv.conversion.apply(&args[..conv.args.len()], &mut res);
                    if !crate::convert::write_results(&res[..conv.conversion.results()], out) {
                        return Err(ConvError::OutOfRange {
                            conversion: conv.conversion,
                        });
                    }
                }
            }
        }
        Ok(())
    }

    /// How many conversions the template holds.
    pub fn conversions(&self) -> usize {
        self.convs.len()
    }

    /// The conversions that cannot be used, `(byte offset in the text, message)`.
    pub fn errors(&self) -> &[(usize, String)] {
        &self.errors
    }

    /// Which parameter indexes occur in the text (so the binder can report a declared-but-unused
    /// one).
    pub fn used(&self) -> &[bool] {
        &self.used
    }

    /// The number of parameters.
    pub fn param_count(&self) -> usize {
        self.used.len()
    }
}

/// Removes the common leading indentation (spaces and tabs, counted as characters) of the
/// non-blank lines, drops leading and trailing blank lines, trims trailing whitespace of each
/// line, normalises CRLF/CR to '\n'. Returns the lines.
pub fn dedent(text: &str) -> Vec<String> {
    let normalised;
    let text = if text.contains('\r') {
        normalised = text.replace("\r\n", "\n").replace('\r', "\n");
        normalised.as_str()
    } else {
        text
    };
    let lines: Vec<&str> = text.split('\n').map(str::trim_end).collect();
    let Some(first) = lines.iter().position(|l| !l.is_empty()) else {
        return Vec::new();
    };
    let last = lines.iter().rposition(|l| !l.is_empty()).unwrap_or(first);
    let lines = &lines[first..=last];
    let indent = lines
        .iter()
        .filter(|l| !l.is_empty())
        .map(|l| l.bytes().take_while(|&c| c == b' ' || c == b'\t').count())
        .min()
        .unwrap_or(0);
    lines
        .iter()
        .map(|l| l.get(indent..).unwrap_or("").to_owned())
        .collect()
}

/// The parameters of a template that declares none: the items of its first bracket group,
/// `(...)` or `{...}`, split at top-level commas, each trimmed; for an item `NAME VALUE` in a
/// `{}` aggregate the last word, and for an item holding a nested `{}` aggregate that
/// aggregate's parameters. Empty items are skipped, and so are items that cannot be a parameter
/// name (not a word starting with a letter or `_`: a number, a string, an expression).
/// Brackets inside string literals and `;` comments do not count. An unclosed group ends with
/// the text.
pub fn params_from_brackets(text: &str) -> Vec<String> {
    let b = text.as_bytes();
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'(' | b'{' => {
                let mut out = Vec::new();
                group_params(text, i, 0, &mut out);
                return out;
            }
            b'"' | b';' => i = skip_quoted_or_comment(b, i),
            _ => i += 1,
        }
    }
    Vec::new()
}

/// From a `"` or `;` at `i`, the index after the string literal or comment.
fn skip_quoted_or_comment(b: &[u8], mut i: usize) -> usize {
    let quote = b[i] == b'"';
    i += 1;
    while i < b.len() && b[i] != b'\n' && !(quote && b[i] == b'"') {
        i += 1;
    }
    if quote && i < b.len() && b[i] == b'"' {
        i += 1;
    }
    i
}

/// Nested aggregates deeper than this are not searched for parameters (bounds the recursion).
const MAX_NESTING: u32 = 32;

/// Collects the parameters of the group opened at `open` (nested `level` deep); returns the
/// index after its close.
fn group_params(text: &str, open: usize, level: u32, out: &mut Vec<String>) -> usize {
    let b = text.as_bytes();
    let aggregate = b[open] == b'{';
    let mut i = open + 1;
    let mut item_start = i;
    let mut depth = 0u32;
    // Parameters of nested aggregates in the current item.
    let mut nested: Vec<String> = Vec::new();
    let mut has_nested = false;
    let finish = |item: &str, nested: &mut Vec<String>, has_nested: bool, out: &mut Vec<String>| {
        if has_nested {
            out.append(nested);
            return;
        }
        let item = item.trim();
        let candidate = if aggregate {
            item.split_whitespace().last().unwrap_or("")
        } else {
            item
        };
        let bytes = candidate.as_bytes();
        if !bytes.is_empty()
            && (bytes[0].is_ascii_alphabetic() || bytes[0] == b'_' || bytes[0] >= 0x80)
            && bytes.iter().all(|&c| is_word_byte(c))
        {
            out.push(candidate.to_owned());
        }
    };
    while i < b.len() {
        match b[i] {
            b'"' | b';' => {
                i = skip_quoted_or_comment(b, i);
                continue;
            }
            b'{' if aggregate && depth == 0 && level < MAX_NESTING => {
                has_nested = true;
                i = group_params(text, i, level + 1, &mut nested);
                continue;
            }
            b'(' | b'[' | b'{' => depth += 1,
            b')' | b']' | b'}' if depth > 0 => depth -= 1,
            b')' | b'}' => {
                finish(&text[item_start..i], &mut nested, has_nested, out);
                return i + 1;
            }
            b',' if depth == 0 => {
                finish(&text[item_start..i], &mut nested, has_nested, out);
                has_nested = false;
                item_start = i + 1;
            }
            _ => {}
        }
        i += 1;
    }
    finish(&text[item_start..], &mut nested, has_nested, out);
    b.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(names: &[&str]) -> Vec<String> {
        names.iter().map(|s| s.to_string()).collect()
    }

    fn sub(text: &str, names: &[&str], values: &[&str]) -> String {
        let t = Template::compile(text, &params(names));
        let mut out = String::new();
        t.render(values, &mut out);
        out
    }

    #[test]
    fn aggregate_items_get_field_names() {
        assert_eq!(
            sub("PTP {X, Y}", &["X", "Y"], &["100", "200"]),
            "PTP {X 100, Y 200}"
        );
        assert_eq!(
            sub(
                "PTP {X, Y, Z, A, B, C}",
                &["X", "Y", "Z", "A", "B", "C"],
                &["100", "200", "300", "0", "90", "0"]
            ),
            "PTP {X 100, Y 200, Z 300, A 0, B 90, C 0}"
        );
    }

    #[test]
    fn plain_substitution_outside_aggregates() {
        assert_eq!(
            sub("SetVelCP (VALUE)", &["VALUE"], &["0.5"]),
            "SetVelCP (0.5)"
        );
    }

    #[test]
    fn field_name_is_not_substituted() {
        assert_eq!(
            sub("LIN {X PX, Y PY}", &["X", "PX", "PY"], &["9", "1", "2"]),
            "LIN {X 1, Y 2}"
        );
        // The rest of an item is substituted as an expression.
        assert_eq!(sub("LIN {X -PX+1}", &["PX"], &["5"]), "LIN {X -5+1}");
    }

    #[test]
    fn nested_aggregates() {
        assert_eq!(
            sub(
                "P = {POS {X PX, Y}, S S}",
                &["PX", "Y", "S"],
                &["1", "2", "6"]
            ),
            "P = {POS {X 1, Y 2}, S 6}"
        );
        assert_eq!(sub("{A {B {X}}}", &["X"], &["7"]), "{A {B {X 7}}}");
        // A type prefix is skipped.
        assert_eq!(
            sub("PTP {E6POS: X, Y}", &["X", "Y", "E6POS"], &["1", "2", "T"]),
            "PTP {E6POS: X 1, Y 2}"
        );
    }

    #[test]
    fn whitespace_and_case_kept() {
        assert_eq!(
            sub("PTP  {  x ,\tY }  ; done", &["X", "y"], &["1", "2"]),
            "PTP  {  x 1 ,\tY 2 }  ; done"
        );
    }

    #[test]
    fn not_in_strings_or_comments() {
        assert_eq!(
            sub("MSG(\"VALUE\", VALUE) ; VALUE", &["VALUE"], &["3"]),
            "MSG(\"VALUE\", 3) ; VALUE"
        );
        // An unterminated string ends at the end of its line.
        assert_eq!(sub("A(\"V\nV", &["V"], &["1"]), "A(\"V\n1");
        // A `;` inside a string does not start a comment.
        assert_eq!(sub("A(\";\", V)", &["V"], &["1"]), "A(\";\", 1)");
    }

    #[test]
    fn whole_words_only() {
        assert_eq!(sub("X XX X_1 AX X1 X", &["X"], &["9"]), "9 XX X_1 AX X1 9");
        assert_eq!(sub("PTP P1", &["P"], &["9"]), "PTP P1");
    }

    #[test]
    fn system_variables_members_and_enums() {
        assert_eq!(
            sub(
                "$VEL.CP = VALUE",
                &["VALUE", "CP", "VEL"],
                &["0.5", "x", "y"]
            ),
            "$VEL.CP = 0.5"
        );
        assert_eq!(sub("$X = X", &["X", "$X"], &["1", "2"]), "$X = 1");
        // The word before a `.` is substituted, the member after it is not.
        assert_eq!(sub("A = P.X", &["P", "X"], &["F1", "0"]), "A = F1.X");
        assert_eq!(
            sub("BAS (#PTP_PARAMS, PTP_PARAMS)", &["PTP_PARAMS"], &["50"]),
            "BAS (#PTP_PARAMS, 50)"
        );
        assert_eq!(
            sub("A = 1E3 + 'HE3' + E3", &["E3"], &["2"]),
            "A = 1E3 + 'HE3' + 2"
        );
    }

    #[test]
    fn multi_line_templates() {
        let t = "DECL REAL V\n$VEL.CP = V ; set V\n  PTP {X, Y}\nY = {X X}";
        assert_eq!(
            sub(t, &["V", "X", "Y"], &["0.3", "1", "2"]),
            "DECL REAL 0.3\n$VEL.CP = 0.3 ; set V\n  PTP {X 1, Y 2}\n2 = {X 1}"
        );
        // An aggregate left open ends with its line.
        assert_eq!(sub("A {B\nX, Y", &["X", "Y"], &["1", "2"]), "A {B\n1, 2");
    }

    #[test]
    fn case_insensitive() {
        assert_eq!(
            sub("SetVelCP (value) + Value", &["VALUE"], &["1"]),
            "SetVelCP (1) + 1"
        );
        assert_eq!(sub("PTP {x}", &["X"], &["5"]), "PTP {x 5}");
    }

    #[test]
    fn values_are_not_substituted_again() {
        assert_eq!(sub("F(A, B)", &["A", "B"], &["B", "A"]), "F(B, A)");
        assert_eq!(
            sub("PTP {X, Y}", &["X", "Y"], &["Y", "X"]),
            "PTP {X Y, Y X}"
        );
    }

    #[test]
    fn used_and_count() {
        let t = Template::compile("PTP {X, Y} ; Z", &params(&["X", "Y", "Z", "W"]));
        assert_eq!(t.param_count(), 4);
        assert_eq!(t.used(), &[true, true, false, false]);
        // Equal names: the first one is used.
        let t = Template::compile("F(A)", &params(&["a", "A"]));
        assert_eq!(t.used(), &[true, false]);
        let t = Template::compile("", &[]);
        assert_eq!(t.param_count(), 0);
        let mut out = String::from("x");
        t.render::<&str>(&[], &mut out);
        assert_eq!(out, "x");
    }

    #[test]
    fn render_appends_and_is_repeatable() {
        let t = Template::compile("LIN {X, Y}", &params(&["X", "Y"]));
        let mut out = String::from("A\n");
        t.render(&["1", "2"], &mut out);
        out.push('\n');
        t.render(&["3", "4"], &mut out);
        assert_eq!(out, "A\nLIN {X 1, Y 2}\nLIN {X 3, Y 4}");
    }

    #[test]
    fn non_ascii_does_not_split_words() {
        assert_eq!(sub("XÄ X", &["X"], &["1"]), "XÄ 1");
    }

    #[test]
    fn dedent_spaces_tabs_crlf() {
        assert_eq!(
            dedent("\n\t\t\tSetVelCP (VALUE)\n\t\t"),
            vec!["SetVelCP (VALUE)"]
        );
        assert_eq!(
            dedent("\r\n  \r\n    DEF A()\r\n      X = 1   \r\n\r\n    END\r\n  "),
            vec!["DEF A()", "  X = 1", "", "END"]
        );
        // Tabs and spaces count as one character each.
        assert_eq!(dedent("\t\tA\n  B\n\t\t C"), vec!["A", "B", " C"]);
        // Old Mac line endings.
        assert_eq!(dedent("  A\r  B\r"), vec!["A", "B"]);
        assert!(dedent(" \n\t\n").is_empty());
        assert!(dedent("").is_empty());
        // A blank line with more indentation than the rest becomes empty.
        assert_eq!(dedent("  A\n        \n  B"), vec!["A", "", "B"]);
    }

    #[test]
    fn params_from_first_bracket_group() {
        assert_eq!(params_from_brackets("SetVelCP (VALUE)"), vec!["VALUE"]);
        assert_eq!(
            params_from_brackets("PTP {X, Y , Z}\nLIN (Q)"),
            vec!["X", "Y", "Z"]
        );
        assert_eq!(
            params_from_brackets("LIN {X PX, Y PY,, Z 100}"),
            vec!["PX", "PY"]
        );
        assert_eq!(
            params_from_brackets("F (A, f(B, C), 0.5, \"s\", D)"),
            vec!["A", "D"]
        );
        assert_eq!(
            params_from_brackets("P = {POS {X PX, Y PY}, S PS}"),
            vec!["PX", "PY", "PS"]
        );
        assert_eq!(
            params_from_brackets("PTP {E6POS: X PX, Y}"),
            vec!["PX", "Y"]
        );
        assert_eq!(params_from_brackets("; (NOT)\nMSG(\"(no)\", A)"), vec!["A"]);
        assert_eq!(params_from_brackets("F (A, B"), vec!["A", "B"]);
        assert!(params_from_brackets("HALT").is_empty());
        assert!(params_from_brackets("F ()").is_empty());
        // Deep nesting neither overflows the stack nor takes long.
        let deep = format!("{}X{}", "{A ".repeat(100_000), "}".repeat(100_000));
        assert!(params_from_brackets(&deep).is_empty());
        let t = Template::compile(&deep, &params(&["X", "A"]));
        assert_eq!(t.used(), &[true, false]);
    }

    #[test]
    fn conversions_are_evaluated_or_refused_with_the_words_substituted() {
        let p = |n: &[&str]| n.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let ur = Syntax {
            comment: b'#',
            aggregates: false,
            case_sensitive: true,
        };
        let t = Template::compile_for(
            "movel(p[m(X), 0, rotvec(A, 0, 90)], a=1.2)",
            &p(&["X", "A"]),
            ur,
        );
        assert!(t.errors().is_empty(), "{:?}", t.errors());
        assert_eq!(t.conversions(), 2);
        let mut out = String::new();
        t.render_with(
            &["1500", "180"],
            &|i| [1500.0, 180.0].get(i).copied(),
            &mut out,
        )
        .unwrap();
        let mut r = [0.0; 4];
        Conversion::Rotvec.apply(&[180.0, 0.0, 90.0], &mut r);
        let rotvec = crate::convert::format_results(&r[..3]).unwrap();
        // `a=1.2` is URScript's keyword argument: parameter `A` is matched case-sensitively.
        assert_eq!(out, format!("movel(p[1.5, 0, {rotvec}], a=1.2)"));
        // Not a number: the error names the conversion and the parameter.
        let err = t.render_with(&["x", "180"], &|_| None, &mut String::new());
        assert!(
            matches!(err, Err(ConvError::NotANumber { param: 0, .. })),
            "{err:?}"
        );
        // A `)` only inside a comment does not close a conversion: refused, and the words of
        // the line are substituted by the usual rules.
        let t = Template::compile("PTP {X m(X ; m(X)", &p(&["X"]));
        assert_eq!(t.errors().len(), 1, "{:?}", t.errors());
        let mut out = String::new();
        t.render(&["7"], &mut out);
        assert_eq!(out, "PTP {X m(7 ; m(X)");
        // Arguments that are neither parameters nor numbers, or too many.
        assert_eq!(
            Template::compile("quat(A, B)", &p(&["A", "B"]))
                .errors()
                .len(),
            1
        );
        assert_eq!(Template::compile("m(A + 1)", &p(&["A"])).errors().len(), 1);
        assert_eq!(Template::compile("deg(1.5707963)", &[]).conversions(), 1);
        // Not a call, or a member: left alone.
        assert_eq!(
            Template::compile("m := 3; x.m(1); mm", &[]).conversions(),
            0
        );
    }
}
