//! A RAPID reader for the machine: `MODULE`, `PROC main()`, `VAR num`/`VAR bool`/`VAR clock`
//! declarations, `! step` comments, `WaitUntil`, `WaitTime`, `IF`/`ELSEIF`/`ELSE`/`ENDIF`,
//! `WHILE`/`ENDWHILE`, `:=`, the clock instructions `ClkReset`/`ClkStart`/`ClkStop` and
//! `ClkRead(c)` (seconds, a decimal `num`).
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

use super::machine::{Expr, Op, Program, Stmt, Val, decimal, step_name, tokens};
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
            _ if t.as_bytes()[0].is_ascii_digit() => Expr::Real(decimal(&t)),
            // A clock's seconds.
            "ClkRead" => {
                assert_eq!(self.bump(), "(", "RAPID: `ClkRead` without `(`");
                let c = self.bump();
                assert!(
                    c.starts_with("skp_clock"),
                    "RAPID: `ClkRead({c})` of no clock in `{}`",
                    self.text
                );
                assert_eq!(self.bump(), ")", "RAPID: `ClkRead({c}` without `)`");
                Expr::ClkRead(c)
            }
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
    // Clocks may be module data too.
    let mut clocks = Vec::new();
    let mut points = std::collections::HashSet::new();
    loop {
        let l = next(&mut i);
        if l == "PROC main()" {
            break;
        }
        // A named point (docs/LANGUAGES.md, "Points"): a target of numbers, declared once.
        if let Some(point) = l
            .strip_prefix("CONST robtarget ")
            .or_else(|| l.strip_prefix("CONST jointtarget "))
        {
            let (name, value) = point
                .split_once(" := ")
                .unwrap_or_else(|| panic!("RAPID: `{l}`"));
            let value = value
                .strip_suffix(';')
                .unwrap_or_else(|| panic!("RAPID: `{l}` without `;`"));
            let numbers = value
                .split(['[', ']', ','])
                .map(str::trim)
                .filter(|x| !x.is_empty());
            let count = numbers
                .inspect(|x| {
                    assert!(
                        x.parse::<f64>().is_ok(),
                        "RAPID: `{x}` in the point `{name}`"
                    )
                })
                .count();
            let want = if l.contains("robtarget") { 17 } else { 12 };
            assert_eq!(count, want, "RAPID: `{l}`");
            assert!(
                points.insert(name.to_owned()),
                "RAPID: point `{name}` declared twice"
            );
            continue;
        }
        let clock = l
            .strip_prefix("VAR clock ")
            .and_then(|c| c.strip_suffix(';'))
            .unwrap_or_else(|| panic!("RAPID: `{l}` where `PROC main()` belongs"));
        clocks.push(clock.to_owned());
    }
    // A motion to a named point needs its declaration.
    for l in &lines[i..] {
        let word = l
            .split(|c: char| !c.is_ascii_alphanumeric())
            .next()
            .unwrap_or("");
        if ["MoveL", "MoveJ", "MoveC", "MoveAbsJ"].contains(&word) {
            let target = l[word.len()..]
                .trim_start()
                .split(',')
                .next()
                .unwrap_or("")
                .trim();
            if target
                .bytes()
                .all(|c| c.is_ascii_alphanumeric() || c == b'_')
            {
                assert!(
                    points.contains(target),
                    "RAPID: `{l}` moves to `{target}`, which no point declares"
                );
            }
        }
    }
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
        if let Some(clock) = decl.strip_prefix("clock ") {
            assert!(
                !clocks.contains(&clock.to_owned()) && !clock.contains(' '),
                "RAPID: `{l}`"
            );
            clocks.push(clock.to_owned());
            continue;
        }
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
        clocks,
        counters: Vec::new(),
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
            // (Not `step time of …` and `step times: …`, the step-time comments.)
            match c
                .trim_start()
                .strip_prefix("step ")
                .filter(|t| !t.starts_with("time"))
            {
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
            // `WaitTime \InPos, 0;`: the robot stands still (no time); `WaitTime t;`.
            "WaitTime" => {
                let t = l[8..]
                    .strip_suffix(';')
                    .unwrap_or_else(|| panic!("RAPID: `{l}` without `;`"))
                    .trim();
                let t = t.strip_prefix("\\InPos,").unwrap_or(t).trim();
                Some(Stmt::Sleep(decimal(t) / 1_000_000))
            }
            "ClkReset" | "ClkStart" | "ClkStop" => {
                let c = l[8..]
                    .strip_suffix(';')
                    .unwrap_or_else(|| panic!("RAPID: `{l}` without `;`"))
                    .trim()
                    .to_owned();
                Some(match first {
                    "ClkReset" => Stmt::ClkReset(c),
                    "ClkStart" => Stmt::ClkStart(c),
                    _ => Stmt::ClkStop(c),
                })
            }
            // `WaitUntil \InPos, c;`: the robot stands first (a step's motion has ended when
            // the next line runs here), then the wait.
            "WaitUntil" => {
                let c = l[9..]
                    .strip_suffix(';')
                    .unwrap_or_else(|| panic!("RAPID: `{l}` without `;`"));
                let c = c.trim_start();
                let c = c.strip_prefix("\\InPos,").unwrap_or(c);
                // Read every 40 ms with `\PollRate:=0.04`, else every 100 ms (RAPID's default);
                // the machine's timed mode reads at that rate, the others every tick.
                let (c, poll) = match c.trim_end().strip_suffix("\\PollRate:=0.04") {
                    Some(c) => (c, 40),
                    None => (c, 100),
                };
                Some(Stmt::Wait(expr(c), Some(poll)))
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

/// Time: a step's action takes `ACTION_MS`, `WaitTime \InPos, 0` none; `ClkReset` sets a clock
/// to 0, `ClkStart` starts it, `ClkStop` stops it, `ClkRead` reads its seconds (a decimal); a
/// `WaitUntil` that reads a clock is read again every tick until it holds, or is stuck after
/// `STUCK_MS`. The same chart and times as the player's test (`chart::the_player_keeps_time`).
#[test]
fn the_reader_keeps_time() {
    let text = "MODULE t\n  CONST robtarget p10 := [[10, 3, 0], [1, 0, 0, 0], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]];\n  PROC main()\n    VAR num skp_branch := 0;\n    VAR clock skp_clock1;\n    VAR clock skp_clock2;\n    VAR clock skp_clock3;\n    ! step time of A (localId 3) starts when the robot stands still\n    WaitTime \\InPos, 0;\n    ClkReset skp_clock1;\n    ClkStart skp_clock1;\n    ! step 1 A: x\n    MoveL p10, v100, fine, tool0;\n    WaitUntil ClkRead(skp_clock1) > 0.35;\n    WaitTime \\InPos, 0;\n    ClkReset skp_clock2;\n    ClkStart skp_clock2;\n    ! step 2 B: x\n    skp_branch := 0;\n    WHILE skp_branch = 0 DO\n      WaitUntil ((ClkRead(skp_clock2) < 0.15) AND (di_Part_OK = 1)) OR ((ClkRead(skp_clock2) > 1.0005) OR (di_Release = 1));\n      IF (ClkRead(skp_clock2) < 0.15) AND (di_Part_OK = 1) THEN\n        skp_branch := 1;\n      ELSEIF (ClkRead(skp_clock2) > 1.0005) OR (di_Release = 1) THEN\n        skp_branch := 2;\n      ENDIF\n    ENDWHILE\n    IF skp_branch = 1 THEN\n      ! step 3 C: x\n    ELSE\n      ! step 4 D: x\n    ENDIF\n    WaitTime \\InPos, 0;\n    ClkReset skp_clock3;\n    ClkStart skp_clock3;\n    ! step 5 E: x\n    WaitUntil ClkRead(skp_clock3) < 0.05;\n  ENDPROC\nENDMODULE\n";
    let program = parse(text, "t");
    let run = |part: i64, release: i64| {
        let p: crate::Phase = [("Part_OK", part), ("Release", release)]
            .into_iter()
            .collect();
        crate::machine::run_clocked(&program, &[p], false)
    };
    let out = |a: &[&str], t| {
        (
            a.iter().map(|s| s.to_string()).collect(),
            crate::Outcome::Stuck,
            t,
        )
    };
    assert_eq!(run(0, 0), out(&["A", "B", "D", "E"], 11_570));
    assert_eq!(run(1, 0), out(&["A", "B", "C", "E"], 10_660));
    assert_eq!(run(0, 1), out(&["A", "B", "D", "E"], 10_660));
    // A stopped clock keeps its value; a wait on the inputs alone is stuck at once; a clock
    // not declared is an error.
    let text = "MODULE t\n  PROC main()\n    VAR clock skp_clock1;\n    ClkReset skp_clock1;\n    ClkStart skp_clock1;\n    ! step 1 A: x\n    ClkStop skp_clock1;\n    ! step 2 B: x\n    WaitUntil ClkRead(skp_clock1) = 0.1;\n    WaitUntil di_Part_OK = 1;\n  ENDPROC\nENDMODULE\n";
    let p: crate::Phase = [("Part_OK", 0)].into_iter().collect();
    assert_eq!(
        crate::machine::run_clocked(&parse(text, "t"), std::slice::from_ref(&p), false),
        (
            vec!["A".to_owned(), "B".to_owned()],
            crate::Outcome::Stuck,
            200
        )
    );
    // A clock of the module.
    let module = text.replace(
        "  PROC main()\n    VAR clock skp_clock1;\n",
        "  VAR clock skp_clock1;\n  PROC main()\n",
    );
    assert_ne!(module, text);
    assert_eq!(
        crate::machine::run_clocked(&parse(&module, "t"), std::slice::from_ref(&p), false).2,
        200
    );
    let undeclared = text.replace("    VAR clock skp_clock1;\n", "");
    let r = std::panic::catch_unwind(|| {
        crate::machine::run_clocked(&parse(&undeclared, "t"), std::slice::from_ref(&p), false)
    });
    assert!(r.is_err(), "a clock must be declared");
}
