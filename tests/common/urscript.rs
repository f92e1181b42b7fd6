//! A block-structure check of a generated URScript file (docs/LANGUAGES.md, "Checks of the output":
//! URScript files are checked by the project's own block-structure test). Used on every `.script` the tests generate
//! (`#[path = "common/urscript.rs"] mod urscript_check;`).
//!
//! What it holds a file to, line by line (URScript has one statement per line, no continuation):
//! - blocks: `def`/`thread`/`if`/`elif`/`else`/`while` lines end in `:` and open a block, closed
//!   by a line `end`; `elif`/`else` only directly in an `if` block (and nothing after its
//!   `else:`); `break`/`continue` only inside a `while` of the same function; `return` only in a
//!   function; every line ending in `:` is one of those; at the end of the file every block is
//!   closed;
//! - tokens: names (a letter or `_`, then letters, digits and `_`), numbers without leading zeros
//!   or exponent (`0`, `12`, `0.5`, `-3.25`), `True`/`False`, `"strings"` on one line, the
//!   operators and punctuation of URScript; anything else (`{`, `$`, `;`, `007`, `1e3`, `1.`)
//!   is refused;
//! - statements: `[global|local] name = expression`, an expression (a call), or a keyword
//!   statement; expressions are well formed (operands and operators alternate, parentheses and
//!   brackets balance, keywords such as `end` or `if` are no operands); a thread is started by
//!   `name = run thread()` (or `run thread()`), of a `thread` defined before, without
//!   arguments.

#![allow(dead_code)]

/// Keywords that cannot be names.
const KEYWORDS: &[&str] = &[
    "and", "break", "continue", "def", "elif", "else", "end", "False", "for", "global", "if",
    "local", "not", "or", "return", "thread", "True", "while", "xor", "halt", "run", "join",
    "kill", "pass",
];

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Name(String),
    Num(String),
    Str,
    Punct(&'static str),
}

const PUNCT: &[&str] = &[
    "==", "!=", "<=", ">=", "**", "(", ")", "[", "]", ",", ":", "=", "<", ">", "+", "-", "*", "/",
    "%",
];

fn tokens(code: &str) -> Result<Vec<Tok>, String> {
    let b = code.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c == b' ' || c == b'\t' {
            i += 1;
        } else if c.is_ascii_alphabetic() || c == b'_' {
            let st = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            out.push(Tok::Name(code[st..i].to_owned()));
        } else if c.is_ascii_digit() {
            let st = i;
            while i < b.len() && b[i].is_ascii_digit() {
                i += 1;
            }
            if i - st > 1 && b[st] == b'0' {
                return Err(format!("number `{}` with a leading zero", &code[st..i]));
            }
            if i < b.len() && b[i] == b'.' {
                i += 1;
                let f = i;
                while i < b.len() && b[i].is_ascii_digit() {
                    i += 1;
                }
                if i == f {
                    return Err(format!(
                        "number `{}` without digits after the point",
                        &code[st..i]
                    ));
                }
            }
            if i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_' || b[i] == b'.') {
                return Err(format!(
                    "malformed number `{}` (no exponents, no letters after digits)",
                    &code[st..=i]
                ));
            }
            out.push(Tok::Num(code[st..i].to_owned()));
        } else if c == b'"' {
            match code[i + 1..].find('"') {
                Some(j) => {
                    if code[i + 1..i + 1 + j].contains('\\') {
                        return Err("a string with `\\`".to_owned());
                    }
                    i += j + 2;
                    out.push(Tok::Str);
                }
                None => return Err("unterminated string".to_owned()),
            }
        } else if let Some(p) = PUNCT.iter().find(|p| code[i..].starts_with(**p)) {
            out.push(Tok::Punct(p));
            i += p.len();
        } else {
            return Err(format!(
                "unexpected character `{}`",
                &code[i..].chars().next().unwrap()
            ));
        }
    }
    Ok(out)
}

/// The code of a line without its comment (a `#` outside a string).
fn strip_comment(line: &str) -> &str {
    let mut in_str = false;
    for (i, c) in line.char_indices() {
        match c {
            '"' => in_str = !in_str,
            '#' if !in_str => return &line[..i],
            _ => {}
        }
    }
    line
}

/// Expression validator over tokens (precedence does not matter here, only well-formedness).
struct Expr<'a> {
    t: &'a [Tok],
    i: usize,
}

impl Expr<'_> {
    fn peek(&self) -> Option<&Tok> {
        self.t.get(self.i)
    }

    fn is_punct(&self, p: &str) -> bool {
        matches!(self.peek(), Some(Tok::Punct(q)) if *q == p)
    }

    fn is_word(&self, w: &str) -> bool {
        matches!(self.peek(), Some(Tok::Name(n)) if n == w)
    }

    fn expect(&mut self, p: &str) -> Result<(), String> {
        if self.is_punct(p) {
            self.i += 1;
            Ok(())
        } else {
            Err(format!("expected `{p}`, found {:?}", self.peek()))
        }
    }

    /// A whole expression: unary operands joined by binary operators.
    fn expr(&mut self) -> Result<(), String> {
        loop {
            self.unary()?;
            let binary = match self.peek() {
                Some(Tok::Name(n)) => ["and", "or", "xor"].contains(&n.as_str()),
                Some(Tok::Punct(p)) => [
                    "==", "!=", "<=", ">=", "<", ">", "+", "-", "*", "/", "%", "**",
                ]
                .contains(p),
                _ => false,
            };
            if !binary {
                return Ok(());
            }
            self.i += 1;
        }
    }

    fn unary(&mut self) -> Result<(), String> {
        while self.is_word("not") || self.is_punct("-") || self.is_punct("+") {
            self.i += 1;
        }
        self.primary()
    }

    fn primary(&mut self) -> Result<(), String> {
        let t = self.peek().cloned();
        self.i += 1;
        match t {
            Some(Tok::Num(_)) | Some(Tok::Str) => Ok(()),
            Some(Tok::Name(n)) if n == "True" || n == "False" => Ok(()),
            Some(Tok::Name(n)) if KEYWORDS.contains(&n.as_str()) => {
                Err(format!("keyword `{n}` where an operand belongs"))
            }
            Some(Tok::Name(n)) => {
                if self.is_punct("(") {
                    self.i += 1;
                    self.args(")")?;
                } else if self.is_punct("[") {
                    // An index, or a pose literal `p[...]`.
                    self.i += 1;
                    if n == "p" {
                        self.args("]")?;
                    } else {
                        self.expr()?;
                        self.expect("]")?;
                    }
                }
                Ok(())
            }
            Some(Tok::Punct("(")) => {
                self.expr()?;
                self.expect(")")
            }
            Some(Tok::Punct("[")) => self.args("]"),
            other => Err(format!("expected an operand, found {other:?}")),
        }
    }

    /// Comma-separated arguments (`name=value` allowed) up to `close`.
    fn args(&mut self, close: &str) -> Result<(), String> {
        if self.is_punct(close) {
            self.i += 1;
            return Ok(());
        }
        loop {
            if let (Some(Tok::Name(n)), Some(Tok::Punct("="))) =
                (self.t.get(self.i), self.t.get(self.i + 1))
            {
                check_name(n)?;
                self.i += 2;
            }
            self.expr()?;
            if self.is_punct(",") {
                self.i += 1;
                continue;
            }
            return self.expect(close);
        }
    }
}

fn check_name(n: &str) -> Result<(), String> {
    if KEYWORDS.contains(&n) {
        Err(format!("keyword `{n}` used as a name"))
    } else {
        Ok(())
    }
}

/// A whole expression in `t`, nothing after it.
fn whole_expr(t: &[Tok]) -> Result<(), String> {
    if t.is_empty() {
        return Err("missing expression".to_owned());
    }
    let mut e = Expr { t, i: 0 };
    e.expr()?;
    if e.i != t.len() {
        return Err(format!("unexpected {:?} after the expression", t[e.i]));
    }
    Ok(())
}

#[derive(Debug, PartialEq)]
enum Block {
    Def,
    If,
    /// An `if` after its `else:`.
    Else,
    While,
}

/// Checks `text` (a whole `.script`); `Err` names the first bad line.
pub fn check_urscript(text: &str) -> Result<(), String> {
    let mut stack: Vec<Block> = Vec::new();
    // The threads defined so far.
    let mut threads: Vec<String> = Vec::new();
    for (n, raw) in text.lines().enumerate() {
        let at = |msg: String| format!("line {}: {msg}: `{}`", n + 1, raw.trim_end());
        let code = strip_comment(raw.trim_end_matches('\r')).trim();
        if code.is_empty() {
            continue;
        }
        let t = tokens(code).map_err(at)?;
        let first = match &t[0] {
            Tok::Name(w) => w.as_str(),
            _ => "",
        };
        let colon = t.last() == Some(&Tok::Punct(":"));
        let head = &t[1..t.len() - usize::from(colon)];
        match first {
            "def" | "thread" => {
                if !colon {
                    return Err(at(format!("`{first}` without `:`")));
                }
                match head {
                    [
                        Tok::Name(name),
                        Tok::Punct("("),
                        params @ ..,
                        Tok::Punct(")"),
                    ] => {
                        check_name(name).map_err(at)?;
                        for (k, p) in params.iter().enumerate() {
                            let ok = if k % 2 == 0 {
                                matches!(p, Tok::Name(p) if check_name(p).is_ok())
                            } else {
                                *p == Tok::Punct(",")
                            };
                            if !ok || params.len() % 2 == 0 && !params.is_empty() {
                                return Err(at("malformed parameter list".to_owned()));
                            }
                        }
                    }
                    _ => return Err(at(format!("malformed `{first}`"))),
                }
                if stack.iter().any(|b| *b != Block::Def) {
                    return Err(at(format!("`{first}` inside a block")));
                }
                if let (Tok::Name(name), "thread") = (&head[0], first) {
                    threads.push(name.clone());
                }
                stack.push(Block::Def);
            }
            "if" | "while" => {
                if !colon {
                    return Err(at(format!("`{first}` without `:`")));
                }
                whole_expr(head).map_err(at)?;
                if stack.is_empty() {
                    return Err(at(format!("`{first}` outside a function")));
                }
                stack.push(if first == "if" {
                    Block::If
                } else {
                    Block::While
                });
            }
            "elif" => {
                if !colon {
                    return Err(at("`elif` without `:`".to_owned()));
                }
                whole_expr(head).map_err(at)?;
                if stack.last() != Some(&Block::If) {
                    return Err(at("`elif` outside an `if` (or after its `else`)".to_owned()));
                }
            }
            "else" => {
                if t.len() != 2 || !colon {
                    return Err(at("`else` must be `else:`".to_owned()));
                }
                match stack.last_mut() {
                    Some(b @ Block::If) => *b = Block::Else,
                    _ => return Err(at("`else` outside an `if` (or a second one)".to_owned())),
                }
            }
            "end" => {
                if t.len() != 1 {
                    return Err(at("`end` must stand alone".to_owned()));
                }
                if stack.pop().is_none() {
                    return Err(at("`end` without a block".to_owned()));
                }
            }
            "break" | "continue" => {
                if t.len() != 1 {
                    return Err(at(format!("`{first}` must stand alone")));
                }
                let in_while = stack
                    .iter()
                    .rev()
                    .take_while(|b| **b != Block::Def)
                    .any(|b| *b == Block::While);
                if !in_while {
                    return Err(at(format!("`{first}` outside a `while`")));
                }
            }
            // `halt` ends the program (the URScript manual's keywords).
            "halt" => {
                if t.len() != 1 {
                    return Err(at("`halt` must stand alone".to_owned()));
                }
            }
            "return" => {
                if stack.is_empty() {
                    return Err(at("`return` outside a function".to_owned()));
                }
                if t.len() > 1 {
                    whole_expr(&t[1..]).map_err(at)?;
                }
            }
            _ => {
                if colon {
                    return Err(at("a line ending in `:` that opens no block".to_owned()));
                }
                let rest = match first {
                    "global" | "local" => &t[1..],
                    _ => &t[..],
                };
                // `run thread()`: the start of a thread defined before.
                let run = |value: &[Tok]| -> Result<(), String> {
                    match value {
                        [
                            Tok::Name(_),
                            Tok::Name(thread),
                            Tok::Punct("("),
                            Tok::Punct(")"),
                        ] if threads.contains(thread) => Ok(()),
                        _ => Err("`run` needs a thread defined before, `run name()`".to_owned()),
                    }
                };
                match rest {
                    [Tok::Name(r), ..] if r == "run" && rest.len() == t.len() => {
                        run(rest).map_err(at)?;
                    }
                    [Tok::Name(name), Tok::Punct("="), Tok::Name(r), ..]
                        if r == "run" && first != "global" && first != "local" =>
                    {
                        check_name(name).map_err(at)?;
                        run(&rest[2..]).map_err(at)?;
                    }
                    [Tok::Name(name), Tok::Punct("="), value @ ..] => {
                        check_name(name).map_err(at)?;
                        whole_expr(value).map_err(at)?;
                    }
                    _ if rest.len() < t.len() => {
                        return Err(at(format!("`{first}` without an assignment")));
                    }
                    _ => {
                        whole_expr(rest).map_err(at)?;
                        // An expression statement is a call (a bare name or value does nothing).
                        let call = matches!(
                            (rest.first(), rest.get(1), rest.last()),
                            (
                                Some(Tok::Name(_)),
                                Some(Tok::Punct("(")),
                                Some(Tok::Punct(")"))
                            )
                        );
                        if !call {
                            return Err(at(
                                "a statement that is neither a call nor an assignment".to_owned()
                            ));
                        }
                    }
                }
            }
        }
    }
    if !stack.is_empty() {
        return Err(format!(
            "the file ends inside {} block(s): {stack:?}",
            stack.len()
        ));
    }
    Ok(())
}
