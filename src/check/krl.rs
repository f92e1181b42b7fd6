//! The KRL check (`.src`, `.dat`); what it holds a text to is in the `check` module's documentation.

use super::*;

/// KRL's data types a declaration may start with (`DECL` may be left out before them).
const KRL_TYPES: &[&str] = &[
    "INT", "REAL", "BOOL", "CHAR", "FRAME", "POS", "E6POS", "AXIS", "E6AXIS", "SIGNAL", "STRUC",
    "ENUM", "LOAD", "FDAT", "PDAT", "LDAT",
];

/// A KRL name: a letter or `_`, then letters, digits, `_` or `$`, at most 24 characters.
fn is_krl_name(s: &str) -> bool {
    let b = s.as_bytes();
    !b.is_empty()
        && b.len() <= 24
        && (b[0].is_ascii_alphabetic() || b[0] == b'_' || b[0] == b'$')
        && b.iter()
            .all(|c| c.is_ascii_alphanumeric() || *c == b'_' || *c == b'$')
}

/// The name after `DEF`/`DEFFCT type`/`DEFDAT` (before `(` or the end): `after` is the text
/// after the keyword.
fn declared_name<'t>(after: &'t str, keyword: &str) -> Option<&'t str> {
    let mut it = after
        .split(|c: char| c.is_whitespace() || c == '(')
        .filter(|w| !w.is_empty());
    if keyword == "DEFFCT" {
        it.next();
    }
    it.next()
}

/// The first name a declaration declares: `first` is its first word (`DECL` or a type),
/// `after` the text after it. After `DECL` come `GLOBAL` or `CONST`, then the type; the name
/// ends at `=`, `[`, `,`, `(` or white space. `None` when there is none.
fn declared_variable<'t>(first: &str, after: &'t str) -> Option<&'t str> {
    // Bytes, not upper-cased words: every declaration of every `.dat` passes here (100,000
    // points).
    let mut rest = after;
    if first == "DECL" {
        loop {
            let w = &rest[..word_end(rest)];
            if !(w.eq_ignore_ascii_case("GLOBAL") || w.eq_ignore_ascii_case("CONST")) {
                break;
            }
            rest = rest[w.len()..].trim_start();
        }
        // The type.
        rest = rest[word_end(rest)..].trim_start();
    }
    let end = rest
        .bytes()
        .position(|c| matches!(c, b'=' | b'[' | b',' | b'(') || c.is_ascii_whitespace())
        .unwrap_or(rest.len());
    Some(&rest[..end]).filter(|n| !n.is_empty())
}

pub(super) fn krl(unit: Unit, text: &str) -> Checked {
    let mut b = Blocks::new();
    let mut folds: Vec<usize> = Vec::new();
    const LOOPS: &[&str] = &["LOOP", "WHILE", "FOR", "REPEAT"];
    // In the routine open now: an executable statement was seen (declarations come first).
    let mut executed = false;
    for (n, raw) in lines(text).enumerate() {
        if b.stopped {
            break;
        }
        let line = n + 1;
        // Folds are comments: `;FOLD` … `;ENDFOLD`.
        let t = trim_start(raw);
        if let Some(rest) = t.strip_prefix(';') {
            let (w, _) = first_word(trim_start(rest));
            let w = w.as_str();
            if w == "FOLD" {
                if b.too_deep(folds.len(), line, 1) {
                    break;
                }
                folds.push(line);
            } else if w == "ENDFOLD" && folds.pop().is_none() {
                problem!(b, line, 1, "`;ENDFOLD` without its `;FOLD`".into());
            }
        }
        let (code, col) = code_of(raw, ';');
        if code.is_empty() || code.starts_with('&') {
            continue;
        }
        let (first, mut after) = first_word(code);
        let mut word = first;
        if word.as_str() == "GLOBAL" {
            (word, after) = first_word(after);
        }
        let w = word.as_str();
        let toplevel = b.stack.is_empty();
        // Declarations: before the first statement of their routine.
        let declaration = w == "DECL" || (KRL_TYPES.contains(&w) && !code.contains('='));
        // Names: of a routine, a data list or what a declaration declares, a KRL name (a point
        // named after a long step once was not, and the controller refuses the data list).
        let name = match w {
            kw @ ("DEF" | "DEFFCT" | "DEFDAT") => declared_name(after, kw),
            _ if declaration => declared_variable(w, after),
            _ => None,
        };
        if let Some(name) = name
            && !is_krl_name(name)
        {
            problem!(
                b,
                line,
                col,
                format!(
                    "`{name}` is no KRL name (a letter or `_`, then letters, digits or `_`, at \
                     most 24 characters)"
                ),
            );
        }
        let in_routine = b.in_any(&["DEF", "DEFFCT"]);
        if declaration && in_routine && executed {
            problem!(
                b,
                line,
                col,
                "a declaration after the first statement of its routine (KRL wants the \
                 declarations first)"
                    .into(),
            );
        }
        if in_routine && !declaration && !matches!(w, "DEF" | "DEFFCT" | "END" | "ENDFCT") {
            executed = true;
        }
        match w {
            "DEF" => {
                if !toplevel {
                    problem!(b, line, col, "`DEF` inside another block".into());
                }
                executed = false;
                b.open("DEF", line, col)
            }
            "DEFFCT" => {
                if !toplevel {
                    problem!(b, line, col, "`DEFFCT` inside another block".into());
                }
                executed = false;
                b.open("DEFFCT", line, col)
            }
            "DEFDAT" => b.open("DEFDAT", line, col),
            "END" => b.close("END", &["DEF"], line, col),
            "ENDFCT" => b.close("ENDFCT", &["DEFFCT"], line, col),
            "ENDDAT" => b.close("ENDDAT", &["DEFDAT"], line, col),
            "IF" => {
                if !ends_with_word(code, "THEN") {
                    problem!(
                        b,
                        line,
                        col,
                        "`IF` without `THEN` at the end of its line".into(),
                    );
                }
                b.open("IF", line, col)
            }
            "ELSE" => b.else_("ELSE", "IF", line, col),
            "ENDIF" => b.close("ENDIF", &["IF"], line, col),
            "LOOP" => b.open("LOOP", line, col),
            "ENDLOOP" => b.close("ENDLOOP", &["LOOP"], line, col),
            "WHILE" => b.open("WHILE", line, col),
            "ENDWHILE" => b.close("ENDWHILE", &["WHILE"], line, col),
            "FOR" => b.open("FOR", line, col),
            "ENDFOR" => b.close("ENDFOR", &["FOR"], line, col),
            "REPEAT" => b.open("REPEAT", line, col),
            "UNTIL" => b.close("UNTIL", &["REPEAT"], line, col),
            "SWITCH" => b.open("SWITCH", line, col),
            "CASE" | "DEFAULT" => b.middle(w, "SWITCH", line, col),
            "ENDSWITCH" => b.close("ENDSWITCH", &["SWITCH"], line, col),
            "SPLINE" | "PTP_SPLINE" => b.open("SPLINE", line, col),
            "ENDSPLINE" => b.close("ENDSPLINE", &["SPLINE"], line, col),
            "EXIT" if !b.in_any(LOOPS) => {
                problem!(b, line, col, "`EXIT` outside a loop".into());
            }
            _ if toplevel && unit != Unit::Snippet => {
                let within = if unit == Unit::Data { "DEFDAT" } else { "DEF" };
                let within = if unit == Unit::Routines {
                    "DEF` or `DEFFCT"
                } else {
                    within
                };
                problem!(
                    b,
                    line,
                    col,
                    format!("a statement outside any `{within}` … `END`: `{code}`"),
                );
            }
            _ => {}
        }
    }
    for l in folds {
        problem!(b, l, 1, "`;FOLD` without its `;ENDFOLD`".into());
    }
    b.finish()
}
