//! The URScript check (`.script`); what it holds a text to is in the `check` module's documentation.

use super::*;

pub(super) fn urscript(text: &str) -> Checked {
    let mut b = Blocks::new();
    for (n, raw) in lines(text).enumerate() {
        if b.stopped {
            break;
        }
        let line = n + 1;
        let (code, col) = code_of(raw, '#');
        if code.is_empty() {
            continue;
        }
        // URScript's keywords are lower case (`End` is a name).
        let w = &code[..code.find(|c: char| !is_word_char(c)).unwrap_or(code.len())];
        let opens = code.ends_with(':');
        // Indentation: a block's lines deeper than the line that opened it; its `end`, `elif`
        // and `else` as deep as that line (the column is the code's, in characters).
        if let Some(o) = b.stack.last() {
            let closing = matches!(w, "end" | "elif" | "else");
            let (kind, at) = (o.kind, (o.line, o.column));
            if closing && col != at.1 {
                problem_at!(
                    b,
                    line,
                    col,
                    format!(
                        "`{w}` indented to column {col}, its `{kind}` to column {}",
                        at.1
                    ),
                    at,
                );
            } else if !closing && col <= at.1 {
                problem_at!(
                    b,
                    line,
                    col,
                    format!(
                        "a line of a `{kind}` block not indented deeper than the block's first line"
                    ),
                    at,
                );
            }
        }
        match w {
            "def" | "thread" | "if" | "while" if opens => {
                let kind = match w {
                    "def" => "def",
                    "thread" => "thread",
                    "if" => "if",
                    _ => "while",
                };
                b.open(kind, line, col)
            }
            "def" | "thread" | "if" | "while" | "elif" | "else" if !opens => {
                problem!(b, line, col, format!("`{w}` line without `:` at its end"))
            }
            "elif" | "else" => {}
            _ if opens => problem!(
                b,
                line,
                col,
                format!("a line ending in `:` that opens no block: `{code}`"),
            ),
            "end" => b.close("end", &["def", "thread", "if", "while"], line, col),
            "break" | "continue" if !b.in_any(&["while"]) => {
                problem!(b, line, col, format!("`{w}` outside a `while`"));
            }
            _ => {}
        }
        if matches!(w, "elif" | "else") && opens {
            if w == "elif" {
                b.middle("elif", "if", line, col);
            } else {
                b.else_("else", "if", line, col);
            }
        }
    }
    b.finish()
}
