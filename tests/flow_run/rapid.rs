//! A RAPID reader for the machine: `MODULE`, `PROC main()`, `VAR num`/`VAR bool` declarations,
//! `! step` comments, `WaitUntil`, `IF`/`ELSEIF`/`ELSE`/`ENDIF`, `WHILE`/`ENDWHILE`, `:=`.
//!
//! Expressions follow the RAPID kernel manual's grammar and priorities, strictly:
//!
//! ```text
//! <expr>         ::= [ NOT ] <logical term> { ( OR | XOR ) <logical term> }
//! <logical term> ::= <relation> { AND <relation> }
//! <relation>     ::= <simple expr> [ <relop> <simple expr> ]
//! <simple expr>  ::= [ - ] <primary>
//! <primary>      ::= <literal> | <name> | ( <expr> )
//! ```
//!
//! so `NOT` may only begin an expression (`a AND NOT b` is a syntax error), comparisons do not
//! chain, and comparisons bind tighter than `AND`, which binds tighter than `OR`/`XOR`. Where
//! the manual leaves the meaning open (`NOT a OR b`: `NOT` and `OR` share the lowest priority)
//! the reader refuses the expression: the writer must parenthesise. A boolean signal is a
//! `signaldi` whose value is the number 0 or 1.

use std::collections::HashMap;

use super::machine::{Expr, Op, Program, Stmt, Val, step_name, tokens};
use crate::SIGNALS;

const OPS: &[&str] = &["<>", "<=", ">=", ":=", "=", "<", ">", "-", ";"];

struct P {
    t: Vec<String>,
    i: usize,
    text: String,
}

impl P {
    fn peek(&self) -> Option<&str> {
        self.t.get(self.i).map(String::as_str)
    }

    fn bump(&mut self) -> String {
        let t = self
            .t
            .get(self.i)
            .cloned()
            .unwrap_or_else(|| panic!("RAPID: `{}` ends too early", self.text));
        self.i += 1;
        t
    }

    fn expr(&mut self) -> Expr {
        let not = self.peek() == Some("NOT");
        if not {
            self.i += 1;
        }
        let mut l = self.logical_term();
        while let Some(op) = self.peek().and_then(|p| match p {
            "OR" => Some(Op::Or),
            "XOR" => Some(Op::Xor),
            _ => None,
        }) {
            assert!(
                !not,
                "RAPID: `NOT … OR/XOR …` without parentheses has no clear meaning: `{}`",
                self.text
            );
            self.i += 1;
            let r = self.logical_term();
            l = Expr::Bin(op, Box::new(l), Box::new(r));
        }
        if not { Expr::Not(Box::new(l)) } else { l }
    }

    fn logical_term(&mut self) -> Expr {
        let mut l = self.relation();
        while self.peek() == Some("AND") {
            self.i += 1;
            let r = self.relation();
            l = Expr::Bin(Op::And, Box::new(l), Box::new(r));
        }
        l
    }

    fn relop(&self) -> Option<Op> {
        Some(match self.peek()? {
            "=" => Op::Eq,
            "<>" => Op::Ne,
            "<" => Op::Lt,
            ">" => Op::Gt,
            "<=" => Op::Le,
            ">=" => Op::Ge,
            _ => return None,
        })
    }

    fn relation(&mut self) -> Expr {
        let l = self.simple();
        let Some(op) = self.relop() else {
            return l;
        };
        self.i += 1;
        let r = self.simple();
        assert!(
            self.relop().is_none(),
            "RAPID: comparisons do not chain: `{}`",
            self.text
        );
        Expr::Bin(op, Box::new(l), Box::new(r))
    }

    fn simple(&mut self) -> Expr {
        if self.peek() == Some("-") {
            self.i += 1;
            return Expr::Neg(Box::new(self.primary()));
        }
        self.primary()
    }

    fn primary(&mut self) -> Expr {
        let t = self.bump();
        match t.as_str() {
            "(" => {
                let e = self.expr();
                assert_eq!(self.bump(), ")", "RAPID: unclosed `(` in `{}`", self.text);
                e
            }
            "TRUE" => Expr::Bool(true),
            "FALSE" => Expr::Bool(false),
            _ if t.bytes().all(|c| c.is_ascii_digit()) => Expr::Int(t.parse().unwrap()),
            _ if t.as_bytes()[0].is_ascii_alphabetic() => {
                assert!(
                    !["NOT", "AND", "OR", "XOR", "THEN", "DO"].contains(&t.as_str()),
                    "RAPID: `{t}` where an operand belongs in `{}`",
                    self.text
                );
                match SIGNALS.iter().position(|s| s.rapid == t) {
                    Some(k) => Expr::Signal(k),
                    // A program variable, or a digital input a fixture has and the flow
                    // base has not (the cell co-simulation gives it its own values).
                    None => {
                        assert!(
                            t.starts_with("skp_") || t.starts_with("di_"),
                            "RAPID: unknown name `{t}` in `{}`",
                            self.text
                        );
                        Expr::Var(t)
                    }
                }
            }
            _ => panic!("RAPID: `{t}` where an operand belongs in `{}`", self.text),
        }
    }
}

/// Parses a RAPID expression.
pub fn expr(s: &str) -> Expr {
    let mut p = P {
        t: tokens(s, OPS),
        i: 0,
        text: s.to_owned(),
    };
    let e = p.expr();
    assert_eq!(p.i, p.t.len(), "RAPID: trailing tokens in `{s}`");
    e
}

/// Reads the module of program `name`.
pub fn parse(text: &str, name: &str) -> Program {
    let lines: Vec<&str> = text.lines().map(|l| l.trim()).collect();
    let mut i = 0;
    let next = |i: &mut usize| -> &str {
        while *i < lines.len() && (lines[*i].is_empty() || lines[*i].starts_with('!')) {
            *i += 1;
        }
        assert!(*i < lines.len(), "RAPID: the module ends early");
        *i += 1;
        lines[*i - 1]
    };
    assert_eq!(next(&mut i), format!("MODULE {name}"));
    assert_eq!(next(&mut i), "PROC main()");
    // Declarations.
    let mut declared = HashMap::new();
    loop {
        let save = i;
        let l = next(&mut i);
        let Some(decl) = l.strip_prefix("VAR ") else {
            i = save;
            break;
        };
        let decl = decl
            .strip_suffix(';')
            .expect("RAPID: `;` after a declaration");
        let (head, init) = decl.split_once(" := ").expect("RAPID: an initial value");
        let (ty, var) = head.split_once(' ').unwrap();
        let v = match (ty, init) {
            ("num", n) => Val::I(n.parse().expect("a num value")),
            ("bool", "TRUE") => Val::B(true),
            ("bool", "FALSE") => Val::B(false),
            _ => panic!("RAPID: unexpected declaration `{l}`"),
        };
        assert!(
            declared.insert(var.to_owned(), v).is_none(),
            "RAPID: `{var}` declared twice"
        );
    }
    let (body, end) = block(&lines, &mut i, &["ENDPROC"]);
    assert_eq!(end, "ENDPROC");
    // Routines from IRL definitions, then the module's end.
    let rest: Vec<&str> = lines[i..]
        .iter()
        .copied()
        .filter(|l| !l.is_empty() && !l.starts_with('!'))
        .collect();
    assert_eq!(rest.last(), Some(&"ENDMODULE"), "RAPID: no ENDMODULE");
    Program {
        body,
        declared: Some(declared),
        bits_are_numbers: true,
    }
}

/// Statements up to a line whose first word is in `until`; returns them and that line.
fn block(lines: &[&str], i: &mut usize, until: &[&str]) -> (Vec<Stmt>, String) {
    let mut out = Vec::new();
    // After a step title, lines that are no statement of the control flow are the step's code.
    let mut in_step = false;
    while *i < lines.len() {
        let l = lines[*i];
        *i += 1;
        if l.is_empty() {
            continue;
        }
        if let Some(c) = l.strip_prefix('!') {
            match c.trim_start().strip_prefix("step ") {
                Some(title) => {
                    out.push(Stmt::Step(step_name(title)));
                    in_step = true;
                }
                None => in_step = false,
            }
            continue;
        }
        let first = l.split_whitespace().next().unwrap();
        if until.contains(&first) {
            return (out, l.to_owned());
        }
        let stmt = match first {
            "IF" => {
                let mut arms = Vec::new();
                let mut head = l.to_owned();
                let otherwise = loop {
                    let kw = head.split_whitespace().next().unwrap().to_owned();
                    let c = head[kw.len()..]
                        .trim()
                        .strip_suffix(" THEN")
                        .unwrap_or_else(|| panic!("RAPID: `{head}` without THEN"));
                    let c = expr(c);
                    let (body, end) = block(lines, i, &["ELSEIF", "ELSE", "ENDIF"]);
                    arms.push((c, body));
                    match end.as_str() {
                        "ENDIF" => break Vec::new(),
                        "ELSE" => {
                            let (body, end) = block(lines, i, &["ENDIF"]);
                            assert_eq!(end, "ENDIF");
                            break body;
                        }
                        _ => head = end,
                    }
                };
                Some(Stmt::If(arms, otherwise))
            }
            "WHILE" => {
                let c = l[5..]
                    .trim()
                    .strip_suffix(" DO")
                    .unwrap_or_else(|| panic!("RAPID: `{l}` without DO"));
                let c = expr(c);
                let (body, end) = block(lines, i, &["ENDWHILE"]);
                assert_eq!(end, "ENDWHILE");
                Some(Stmt::While(c, body))
            }
            "WaitUntil" => {
                let c = l[9..]
                    .strip_suffix(';')
                    .unwrap_or_else(|| panic!("RAPID: `{l}` without `;`"));
                Some(Stmt::Wait(expr(c)))
            }
            _ => match l.split_once(" := ") {
                Some((var, e)) if var.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'_') => {
                    let e = e
                        .strip_suffix(';')
                        .unwrap_or_else(|| panic!("RAPID: `{l}` without `;`"));
                    Some(Stmt::Assign(var.to_owned(), expr(e)))
                }
                _ => None,
            },
        };
        match stmt {
            Some(s) => {
                out.push(s);
                in_step = false;
            }
            None => assert!(in_step, "RAPID: unexpected line `{l}`"),
        }
    }
    panic!("RAPID: the module ends inside a block (expected {until:?})");
}
