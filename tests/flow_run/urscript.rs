//! A URScript reader for the machine: `def P():` … `end` and the call `P()`, `# step` comments,
//! `if`/`elif`/`else`/`end`, `while c:` … `end`, `break`, `sync()`, `[global] name = value`; a
//! wait `while not (c): sync() end`. Step times: the thread that advances the step-time
//! counters (`thread skp_clock():` with lines `x = x + get_steptime()`, started by
//! `t = run skp_clock()`) is not run line by line: the machine advances its counters with the
//! clock (seconds, decimals).
//!
//! Expressions with URScript's (Python-like) precedence, loosest first: `or` and `xor`, `and`,
//! `not`, comparisons, unary `-`. So `not a == b` is `not (a == b)`. Where the meaning is not
//! clear from the manual the reader refuses the expression, so the writer must parenthesise:
//! `xor` next to `or` or `and` without parentheses, and chained comparisons (`a == b == c`).
//! Signals are read by calls (`get_standard_digital_in(1)`, `read_input_integer_register(9)`);
//! a boolean signal is a boolean, not a number.

use super::machine::{Expr, Op, Program, Stmt, decimal, step_name, tokens};
use crate::SIGNALS;

const OPS: &[&str] = &["==", "!=", "<=", ">=", "<", ">", "-", "="];

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
            .unwrap_or_else(|| panic!("URScript: `{}` ends too early", self.text));
        self.i += 1;
        t
    }

    /// `or`/`xor` chains; returns the expression and whether it is such a chain.
    fn disjunction(&mut self) -> Expr {
        let (mut l, mut bare_and) = self.conjunction();
        let mut ops = Vec::new();
        while let Some(op) = self.peek().and_then(|p| match p {
            "or" => Some(Op::Or),
            "xor" => Some(Op::Xor),
            _ => None,
        }) {
            self.i += 1;
            ops.push(op);
            let (r, and) = self.conjunction();
            bare_and |= and;
            l = Expr::Bin(op, Box::new(l), Box::new(r));
        }
        if ops.contains(&Op::Xor) {
            assert!(
                ops.iter().all(|o| *o == Op::Xor) && !bare_and,
                "URScript: `xor` beside `or`/`and` without parentheses: `{}`",
                self.text
            );
        }
        l
    }

    /// `and` chains; returns the expression and whether it holds an `and`.
    fn conjunction(&mut self) -> (Expr, bool) {
        let mut l = self.negation();
        let mut and = false;
        while self.peek() == Some("and") {
            self.i += 1;
            and = true;
            let r = self.negation();
            l = Expr::Bin(Op::And, Box::new(l), Box::new(r));
        }
        (l, and)
    }

    fn negation(&mut self) -> Expr {
        if self.peek() == Some("not") {
            self.i += 1;
            return Expr::Not(Box::new(self.negation()));
        }
        self.comparison()
    }

    fn cmp(&self) -> Option<Op> {
        Some(match self.peek()? {
            "==" => Op::Eq,
            "!=" => Op::Ne,
            "<" => Op::Lt,
            ">" => Op::Gt,
            "<=" => Op::Le,
            ">=" => Op::Ge,
            _ => return None,
        })
    }

    fn comparison(&mut self) -> Expr {
        let l = self.unary();
        let Some(op) = self.cmp() else {
            return l;
        };
        self.i += 1;
        let r = self.unary();
        assert!(
            self.cmp().is_none(),
            "URScript: chained comparison in `{}`",
            self.text
        );
        Expr::Bin(op, Box::new(l), Box::new(r))
    }

    fn unary(&mut self) -> Expr {
        if self.peek() == Some("-") {
            self.i += 1;
            return Expr::Neg(Box::new(self.unary()));
        }
        self.primary()
    }

    fn primary(&mut self) -> Expr {
        let t = self.bump();
        match t.as_str() {
            "(" => {
                let e = self.disjunction();
                assert_eq!(
                    self.bump(),
                    ")",
                    "URScript: unclosed `(` in `{}`",
                    self.text
                );
                e
            }
            "True" => Expr::Bool(true),
            "False" => Expr::Bool(false),
            _ if t.as_bytes()[0].is_ascii_digit() && t.contains('.') => {
                assert!(
                    t.starts_with("0.") || !t.starts_with('0'),
                    "URScript: leading zero in `{t}`"
                );
                Expr::Real(decimal(&t))
            }
            _ if t.bytes().all(|c| c.is_ascii_digit()) => {
                assert!(
                    t == "0" || !t.starts_with('0'),
                    "URScript: leading zero in `{t}`"
                );
                Expr::Int(t.parse().unwrap())
            }
            _ if t.as_bytes()[0].is_ascii_alphabetic() || t.starts_with('_') => {
                assert!(
                    !["not", "and", "or", "xor", "if", "elif", "while", "end"]
                        .contains(&t.as_str()),
                    "URScript: `{t}` where an operand belongs in `{}`",
                    self.text
                );
                if self.peek() == Some("(") {
                    self.i += 1;
                    let arg = self.bump();
                    assert_eq!(
                        self.bump(),
                        ")",
                        "URScript: a call of `{t}` with one number"
                    );
                    let call = format!("{t}({arg})");
                    let k = SIGNALS
                        .iter()
                        .position(|s| s.ur == call)
                        .unwrap_or_else(|| panic!("URScript: unknown call `{call}`"));
                    Expr::Signal(k)
                } else {
                    assert!(
                        t.starts_with("skp_"),
                        "URScript: unknown name `{t}` in `{}`",
                        self.text
                    );
                    Expr::Var(t)
                }
            }
            _ => panic!(
                "URScript: `{t}` where an operand belongs in `{}`",
                self.text
            ),
        }
    }
}

/// Parses a URScript expression.
pub fn expr(s: &str) -> Expr {
    let mut p = P {
        t: tokens(s, OPS),
        i: 0,
        text: s.to_owned(),
    };
    let e = p.disjunction();
    assert_eq!(p.i, p.t.len(), "URScript: trailing tokens in `{s}`");
    e
}

/// Reads the script of program `name`.
pub fn parse(text: &str, name: &str) -> Program {
    let lines: Vec<&str> = text.lines().map(|l| l.trim()).collect();
    let code = |l: &&str| !l.is_empty() && !l.starts_with('#');
    let mut i = lines
        .iter()
        .position(&code)
        .expect("URScript: an empty file");
    assert_eq!(lines[i], format!("def {name}():"));
    i += 1;
    let mut threads = Threads::default();
    let (body, end) = block(&lines, &mut i, &["end"], &mut threads);
    assert_eq!(end, "end");
    let rest: Vec<&str> = lines[i..].iter().copied().filter(code).collect();
    assert_eq!(
        rest,
        [format!("{name}()")],
        "URScript: the program is called once after its definition"
    );
    Program {
        body,
        declared: None,
        bits_are_numbers: false,
        clocks: Vec::new(),
        counters: threads.counters,
    }
}

/// The threads defined (names), and the step-time counters the clock thread advances.
#[derive(Default)]
struct Threads {
    names: Vec<String>,
    counters: Vec<String>,
    /// The named points declared so far: a motion may go only to one of them.
    points: std::collections::HashSet<String>,
}

/// After `thread skp_clock():`: reads the clock thread (`while True:`, a line
/// `x = x + get_steptime()` per counter, `sync()`, `end`, `end`), its counters into `threads`.
fn clock_thread(lines: &[&str], i: &mut usize, threads: &mut Threads) {
    let mut next = || {
        let l = lines[*i];
        *i += 1;
        l
    };
    assert_eq!(next(), "while True:", "URScript: the clock thread's loop");
    loop {
        let l = next();
        if l == "sync()" {
            break;
        }
        let (var, rhs) = l
            .split_once(" = ")
            .unwrap_or_else(|| panic!("URScript: `{l}` in the clock thread"));
        assert_eq!(
            rhs,
            format!("{var} + get_steptime()"),
            "URScript: the clock thread adds each cycle's time"
        );
        assert!(var.starts_with("skp_time"), "URScript: counter `{var}`");
        threads.counters.push(var.to_owned());
    }
    assert_eq!(
        next(),
        "end",
        "URScript: the clock thread's loop ends after sync()"
    );
    assert_eq!(
        next(),
        "end",
        "URScript: the clock thread ends after its loop"
    );
}

/// `head` without the `keyword ` before and the `:` after.
fn condition<'a>(head: &'a str, keyword: &str) -> &'a str {
    head[keyword.len()..]
        .strip_suffix(':')
        .unwrap_or_else(|| panic!("URScript: `{head}` without `:`"))
}

/// Statements up to a line whose first word is in `until`; returns them and that line.
fn block(
    lines: &[&str],
    i: &mut usize,
    until: &[&str],
    threads: &mut Threads,
) -> (Vec<Stmt>, String) {
    let mut out = Vec::new();
    // After a step title, lines that are no statement of the control flow are the step's code.
    let mut in_step = false;
    while *i < lines.len() {
        let l = lines[*i];
        *i += 1;
        if l.is_empty() {
            continue;
        }
        if let Some(c) = l.strip_prefix('#') {
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
        let first = l
            .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .next()
            .unwrap();
        if until.contains(&first) {
            return (out, l.to_owned());
        }
        let stmt = match first {
            "if" => {
                let mut arms = Vec::new();
                let mut head = l.to_owned();
                let otherwise = loop {
                    let kw = if head.starts_with("if ") {
                        "if "
                    } else {
                        "elif "
                    };
                    let c = expr(condition(&head, kw));
                    let (body, end) = block(lines, i, &["elif", "else", "end"], threads);
                    arms.push((c, body));
                    match end.as_str() {
                        "end" => break Vec::new(),
                        "else:" => {
                            let (body, end) = block(lines, i, &["end"], threads);
                            assert_eq!(end, "end");
                            break body;
                        }
                        _ if end.starts_with("elif ") => head = end,
                        _ => panic!("URScript: unexpected `{end}`"),
                    }
                };
                Some(Stmt::If(arms, otherwise))
            }
            "while" => {
                let c = expr(condition(l, "while "));
                let (body, end) = block(lines, i, &["end"], threads);
                assert_eq!(end, "end");
                // A wait: one control cycle at a time until the condition holds.
                match c {
                    Expr::Not(c) if matches!(body.as_slice(), [Stmt::Sync]) => {
                        Some(Stmt::Wait(*c, None))
                    }
                    c => Some(Stmt::While(c, body)),
                }
            }
            "break" if l == "break" => Some(Stmt::Break),
            "sync" if l == "sync()" => Some(Stmt::Sync),
            "thread" => {
                let name = condition(l, "thread ")
                    .strip_suffix("()")
                    .unwrap_or_else(|| panic!("URScript: `{l}`"));
                assert_eq!(
                    name, "skp_clock",
                    "URScript: a thread other than the clock's"
                );
                assert!(threads.names.is_empty(), "URScript: a second clock thread");
                clock_thread(lines, i, threads);
                threads.names.push(name.to_owned());
                Some(Stmt::Sync)
            }
            _ if l.ends_with(" run skp_clock()") => {
                assert!(
                    threads.names.iter().any(|t| t == "skp_clock"),
                    "URScript: `{l}` before the thread is defined"
                );
                Some(Stmt::RunCounters)
            }
            "global" => match l[7..].split_once(" = ") {
                // A named point (docs/LANGUAGES.md, "Points"): six numbers, declared once.
                Some((var, e)) if e.starts_with("p[") || e.starts_with('[') => {
                    let items: Vec<&str> = e
                        .trim_start_matches('p')
                        .strip_prefix('[')
                        .and_then(|r| r.strip_suffix(']'))
                        .unwrap_or_else(|| panic!("URScript: `{l}`"))
                        .split(',')
                        .collect();
                    assert!(
                        items.len() == 6 && items.iter().all(|x| x.trim().parse::<f64>().is_ok()),
                        "URScript: a point of six numbers in `{l}`"
                    );
                    assert!(
                        threads.points.insert(var.to_owned()),
                        "URScript: point `{var}` declared twice"
                    );
                    continue;
                }
                Some((var, e)) if var.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'_') => {
                    Some(Stmt::Assign(var.to_owned(), expr(e)))
                }
                _ => panic!("URScript: `{l}`"),
            },
            "movel" | "movej" | "movep" | "movec" => {
                // A motion to a named point needs its declaration before it.
                let args = l[l.find('(').unwrap() + 1..].split(',');
                for a in args.take(if first == "movec" { 2 } else { 1 }) {
                    let a = a.trim().trim_end_matches(')');
                    if a.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'_') {
                        assert!(
                            threads.points.contains(a),
                            "URScript: `{l}` moves to `{a}`, which no point declares"
                        );
                    }
                }
                None
            }
            _ => match l.split_once(" = ") {
                Some((var, e)) if var.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'_') => {
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
            None => assert!(in_step, "URScript: unexpected line `{l}`"),
        }
    }
    panic!("URScript: the script ends inside a block (expected {until:?})");
}

/// Time: a step's action takes `ACTION_MS`; the counters the clock thread advances (once it
/// runs) grow by the seconds that pass; a wait `while not (c): sync() end` that reads one is
/// read again every tick until it holds, or is stuck after `STUCK_MS`; `sync()` elsewhere
/// takes no time. The same chart and times as the player's test
/// (`chart::the_player_keeps_time`).
#[test]
fn the_reader_keeps_time() {
    let text = "def t():\n  # step times: skp_time1, skp_time2, skp_time3 count the seconds since their step started\n  global skp_time1 = 0.0\n  global skp_time2 = 0.0\n  global skp_time3 = 0.0\n  thread skp_clock():\n    while True:\n      skp_time1 = skp_time1 + get_steptime()\n      skp_time2 = skp_time2 + get_steptime()\n      skp_time3 = skp_time3 + get_steptime()\n      sync()\n    end\n  end\n  skp_clock_thread = run skp_clock()\n  # step time of A (localId 3) starts\n  skp_time1 = 0.0\n  # step 1 A: x\n  movel(p[10, 3, 0, 0, 0, 0])\n  while not (skp_time1 > 0.35):\n    sync()\n  end\n  # step time of B (localId 5) starts\n  skp_time2 = 0.0\n  # step 2 B: x\n  skp_branch = 0\n  while skp_branch == 0:\n    while not (((skp_time2 < 0.15) and get_standard_digital_in(1)) or ((skp_time2 > 1.0005) or get_standard_digital_in(3))):\n      sync()\n    end\n    if (skp_time2 < 0.15) and get_standard_digital_in(1):\n      skp_branch = 1\n    elif (skp_time2 > 1.0005) or get_standard_digital_in(3):\n      skp_branch = 2\n    end\n  end\n  if skp_branch == 1:\n    # step 3 C: x\n    sync()\n  else:\n    # step 4 D: x\n    sync()\n  end\n  skp_time3 = 0.0\n  # step 5 E: x\n  while not (skp_time3 < 0.05):\n    sync()\n  end\nend\nt()\n";
    crate::urscript_check::check_urscript(text).unwrap();
    let program = parse(text, "t");
    let run = |program: &Program, part: i64, release: i64| {
        let p: crate::Phase = [("Part_OK", part), ("Release", release)]
            .into_iter()
            .collect();
        crate::machine::run_clocked(program, &[p], false)
    };
    let out = |a: &[&str], t| {
        (
            a.iter().map(|s| s.to_string()).collect(),
            crate::Outcome::Stuck,
            t,
        )
    };
    assert_eq!(run(&program, 0, 0), out(&["A", "B", "D", "E"], 11_570));
    assert_eq!(run(&program, 1, 0), out(&["A", "B", "C", "E"], 10_660));
    assert_eq!(run(&program, 0, 1), out(&["A", "B", "D", "E"], 10_660));
    // Without the thread started the counters stay: the first wait is stuck.
    let stopped = text.replace("  skp_clock_thread = run skp_clock()\n", "");
    assert_eq!(
        run(&parse(&stopped, "t"), 0, 0),
        out(&["A"], crate::ACTION_MS + crate::STUCK_MS)
    );
}
