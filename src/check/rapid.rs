//! The RAPID check (`.mod`, `.modx`, `.sys`); what it holds a text to is in the `check` module's documentation.

use super::*;

pub(super) fn rapid(unit: Unit, text: &str) -> Checked {
    let mut b = Blocks::new();
    const ROUTINES: &[&str] = &["PROC", "FUNC", "TRAP"];
    for (n, raw) in lines(text).enumerate() {
        if b.stopped {
            break;
        }
        let line = n + 1;
        let (code, col) = code_of(raw, '!');
        if code.is_empty() || code.starts_with('%') {
            continue;
        }
        let (mut word, mut after) = first_word(code);
        while matches!(word.as_str(), "LOCAL" | "TASK" | "GLOBAL") {
            (word, after) = first_word(after);
        }
        let w = word.as_str();
        let then = ends_with_word(code, "THEN");
        let ends_do = ends_with_word(code, "DO");
        let toplevel = b.stack.is_empty();
        match w {
            "MODULE" => b.open("MODULE", line, col),
            "ENDMODULE" => b.close("ENDMODULE", &["MODULE"], line, col),
            "PROC" | "FUNC" | "TRAP" => {
                if b.in_any(ROUTINES) {
                    problem!(b, line, col, format!("`{w}` inside another routine"));
                }
                if toplevel && unit == Unit::Program {
                    problem!(
                        b,
                        line,
                        col,
                        format!("`{w}` outside `MODULE` … `ENDMODULE`")
                    );
                }
                let kind = match w {
                    "PROC" => "PROC",
                    "FUNC" => "FUNC",
                    _ => "TRAP",
                };
                b.open(kind, line, col)
            }
            "ENDPROC" => b.close("ENDPROC", &["PROC"], line, col),
            "ENDFUNC" => b.close("ENDFUNC", &["FUNC"], line, col),
            "ENDTRAP" => b.close("ENDTRAP", &["TRAP"], line, col),
            "ERROR" | "BACKWARD" | "UNDO"
                if (after.is_empty() || code.ends_with(')')) && !b.in_any(ROUTINES) =>
            {
                problem!(b, line, col, format!("`{w}` handler outside a routine"));
            }
            // `IF c THEN` opens; a compact `IF c stmt;` is one statement.
            "IF" if then => b.open("IF", line, col),
            "ELSEIF" => {
                if !then {
                    problem!(
                        b,
                        line,
                        col,
                        "`ELSEIF` without `THEN` at the end of its line".into(),
                    );
                }
                b.middle("ELSEIF", "IF", line, col)
            }
            "ELSE" => b.else_("ELSE", "IF", line, col),
            "ENDIF" => b.close("ENDIF", &["IF"], line, col),
            "WHILE" | "FOR" => {
                let kind = if w == "FOR" { "FOR" } else { "WHILE" };
                if !ends_do {
                    problem!(
                        b,
                        line,
                        col,
                        format!("`{kind}` without `DO` at the end of its line"),
                    );
                }
                b.open(kind, line, col)
            }
            "ENDWHILE" => b.close("ENDWHILE", &["WHILE"], line, col),
            "ENDFOR" => b.close("ENDFOR", &["FOR"], line, col),
            "TEST" => b.open("TEST", line, col),
            "CASE" | "DEFAULT" => b.middle(w, "TEST", line, col),
            "ENDTEST" => b.close("ENDTEST", &["TEST"], line, col),
            _ if toplevel && unit == Unit::Program => problem!(
                b,
                line,
                col,
                format!("a statement outside `MODULE` … `ENDMODULE`: `{code}`"),
            ),
            _ => {}
        }
    }
    b.finish()
}
