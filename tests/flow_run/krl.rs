//! The KRL interpreter: statements, `IF`, `LOOP`/`EXIT`, `REPEAT`/`UNTIL`, `SWITCH`, `WAIT FOR`,
//! `$IN`/`$OUT`, `SIGNAL` groups, KRL's own operator precedence.

use std::collections::HashMap;

use crate::{Io, MAX_ACTIONS, Outcome, Phase, SIGNALS};

/// The controller's view of a phase: every addressed bit.
pub fn bits(phase: &Phase) -> HashMap<String, bool> {
    let mut out = HashMap::new();
    for s in SIGNALS {
        let v = phase.get(s.name).copied().unwrap_or(0);
        match s.krl {
            Io::Bit(addr) => {
                out.insert(addr.to_owned(), v != 0);
            }
            Io::Group(first, len) => {
                for k in 0..len {
                    out.insert(format!("$IN[{}]", first + k), (v >> k) & 1 == 1);
                }
            }
        }
    }
    out
}

#[derive(Debug, Clone)]
pub enum KExpr {
    Int(i64),
    Bool(bool),
    /// A variable or a `SIGNAL` name.
    Name(String),
    /// `$IN[3]`, `$OUT[5]`, `$CYCFLAG[3]`.
    Sys(String),
    Not(Box<KExpr>),
    Neg(Box<KExpr>),
    Bin(String, Box<KExpr>, Box<KExpr>),
}

#[derive(Debug, Clone)]
pub enum Stmt {
    /// A step's FOLD: the step name from its title (`;FOLD 2 Grip: Move LIN @ …`).
    Fold(String),
    Wait(KExpr),
    If(KExpr, Vec<Stmt>, Vec<Stmt>),
    Loop(Vec<Stmt>),
    Exit,
    Repeat(Vec<Stmt>, KExpr),
    /// `SWITCH e`, cases (`None` = `DEFAULT`).
    Switch(KExpr, Vec<(Option<i64>, Vec<Stmt>)>),
    Assign(String, KExpr),
    /// `NAME:` (upper-cased).
    Label(String),
    Goto(String),
}

/// Tokens of a KRL expression.
fn ktokens(s: &str) -> Vec<String> {
    let mut out = Vec::new();
    let c: Vec<char> = s.chars().collect();
    let mut i = 0;
    while i < c.len() {
        let ch = c[i];
        if ch.is_whitespace() {
            i += 1;
        } else if ch == '$' || ch.is_ascii_alphanumeric() || ch == '_' {
            let st = i;
            i += 1;
            while i < c.len() && (c[i].is_ascii_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            if i < c.len() && c[i] == '[' {
                while c[i] != ']' {
                    i += 1;
                }
                i += 1;
            }
            out.push(c[st..i].iter().collect());
        } else {
            let two: String = c[i..(i + 2).min(c.len())].iter().collect();
            if ["==", "<>", "<=", ">="].contains(&two.as_str()) {
                out.push(two);
                i += 2;
            } else {
                out.push(ch.to_string());
                i += 1;
            }
        }
    }
    out
}

/// KRL precedence, loosest first: comparisons, `OR`, `EXOR`, `AND`, then `NOT` and unary `-`.
struct KParser {
    t: Vec<String>,
    i: usize,
}

impl KParser {
    fn peek(&self) -> Option<String> {
        self.t.get(self.i).map(|s| s.to_ascii_uppercase())
    }

    fn expr(&mut self) -> KExpr {
        let mut l = self.or();
        while let Some(op) = self
            .peek()
            .filter(|p| ["==", "<>", "<", ">", "<=", ">="].contains(&p.as_str()))
        {
            self.i += 1;
            let r = self.or();
            l = KExpr::Bin(op, Box::new(l), Box::new(r));
        }
        l
    }

    fn level(&mut self, ops: &[&str], next: fn(&mut Self) -> KExpr) -> KExpr {
        let mut l = next(self);
        while let Some(op) = self.peek().filter(|p| ops.contains(&p.as_str())) {
            self.i += 1;
            let r = next(self);
            l = KExpr::Bin(op, Box::new(l), Box::new(r));
        }
        l
    }

    fn or(&mut self) -> KExpr {
        self.level(&["OR"], Self::exor)
    }

    fn exor(&mut self) -> KExpr {
        self.level(&["EXOR"], Self::and)
    }

    fn and(&mut self) -> KExpr {
        self.level(&["AND"], Self::unary)
    }

    fn unary(&mut self) -> KExpr {
        let t = self.peek().expect("an operand");
        self.i += 1;
        match t.as_str() {
            "NOT" => KExpr::Not(Box::new(self.unary())),
            "-" => KExpr::Neg(Box::new(self.unary())),
            "(" => {
                let e = self.expr();
                assert_eq!(self.peek().as_deref(), Some(")"), "unclosed (");
                self.i += 1;
                e
            }
            "TRUE" => KExpr::Bool(true),
            "FALSE" => KExpr::Bool(false),
            _ if t.starts_with('$') => KExpr::Sys(t),
            _ if t.chars().all(|c| c.is_ascii_digit()) => KExpr::Int(t.parse().unwrap()),
            _ => KExpr::Name(t),
        }
    }
}

pub fn kexpr(s: &str) -> KExpr {
    let mut p = KParser {
        t: ktokens(s),
        i: 0,
    };
    let e = p.expr();
    assert_eq!(p.i, p.t.len(), "trailing tokens in `{s}`");
    e
}

/// The code of a line (without a `;` comment), upper-cased keywords kept as written.
pub fn code(line: &str) -> &str {
    line.split(';').next().unwrap().trim()
}

/// Parses the main program's statements (between its `DEF` and `END`).
pub fn parse_program(src: &str) -> Vec<Stmt> {
    let lines: Vec<&str> = src.lines().collect();
    let start = lines
        .iter()
        .position(|l| l.trim_start().starts_with("DEF "))
        .unwrap()
        + 1;
    let mut i = start;
    let body = parse_block(&lines, &mut i, &["END"]);
    body.0
}

/// After a `;FOLD <title>` line: skips to its `;ENDFOLD` (folds nest) and returns the step's
/// name when it is a step's FOLD (`;FOLD 2 Grip: Move LIN @ …`), `None` for others (`INI`).
pub fn fold(lines: &[&str], i: &mut usize, title: &str) -> Option<String> {
    let mut depth = 1;
    while depth > 0 {
        let l = lines[*i].trim();
        *i += 1;
        if l.starts_with(";FOLD") {
            depth += 1;
        } else if l.starts_with(";ENDFOLD") {
            depth -= 1;
        }
    }
    let mut words = title.split_whitespace();
    words
        .next()
        .is_some_and(|n| n.parse::<usize>().is_ok())
        .then(|| words.next().unwrap().trim_end_matches(':').to_owned())
}

/// Parses statements until a line whose first word is one of `until`; returns them and that
/// line's code.
fn parse_block(lines: &[&str], i: &mut usize, until: &[&str]) -> (Vec<Stmt>, String) {
    let mut out = Vec::new();
    while *i < lines.len() {
        let raw = lines[*i].trim();
        *i += 1;
        if let Some(title) = raw.strip_prefix(";FOLD ") {
            if let Some(name) = fold(lines, i, title) {
                out.push(Stmt::Fold(name));
            }
            continue;
        }
        let c = code(raw);
        if c.is_empty() {
            continue;
        }
        let first = c.split_whitespace().next().unwrap().to_ascii_uppercase();
        if until.contains(&first.as_str()) {
            return (out, c.to_owned());
        }
        match first.as_str() {
            "WAIT" => {
                let rest = c[4..].trim_start();
                assert!(rest.to_ascii_uppercase().starts_with("FOR "), "WAIT SEC?");
                out.push(Stmt::Wait(kexpr(&rest[4..])));
            }
            "IF" => {
                let cond = c[2..].trim().strip_suffix("THEN").unwrap();
                let (then, end) = parse_block(lines, i, &["ELSE", "ENDIF"]);
                let otherwise = if end.eq_ignore_ascii_case("ELSE") {
                    parse_block(lines, i, &["ENDIF"]).0
                } else {
                    Vec::new()
                };
                out.push(Stmt::If(kexpr(cond), then, otherwise));
            }
            "LOOP" => out.push(Stmt::Loop(parse_block(lines, i, &["ENDLOOP"]).0)),
            "GOTO" => out.push(Stmt::Goto(c[4..].trim().to_ascii_uppercase())),
            _ if c.ends_with(':') && !c.contains(char::is_whitespace) => {
                out.push(Stmt::Label(c.trim_end_matches(':').to_ascii_uppercase()));
            }
            "EXIT" => out.push(Stmt::Exit),
            "REPEAT" => {
                let (body, end) = parse_block(lines, i, &["UNTIL"]);
                out.push(Stmt::Repeat(body, kexpr(&end[5..])));
            }
            "SWITCH" => {
                let sel = kexpr(&c[6..]);
                let mut cases = Vec::new();
                let (none, mut end) = parse_block(lines, i, &["CASE", "DEFAULT", "ENDSWITCH"]);
                assert!(none.is_empty(), "statements before the first CASE");
                while !end.eq_ignore_ascii_case("ENDSWITCH") {
                    let label = if end.to_ascii_uppercase().starts_with("CASE") {
                        Some(end[4..].trim().parse().unwrap())
                    } else {
                        None
                    };
                    let (body, next) = parse_block(lines, i, &["CASE", "DEFAULT", "ENDSWITCH"]);
                    cases.push((label, body));
                    end = next;
                }
                out.push(Stmt::Switch(sel, cases));
            }
            _ => {
                // `NAME = expr` for a program variable; anything else (INI, BAS, PTP HOME,
                // system variables) does not concern the control flow.
                if let Some((lhs, rhs)) = c.split_once('=')
                    && !lhs.trim().starts_with('$')
                    && lhs
                        .trim()
                        .chars()
                        .all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
                    && !rhs.starts_with('=')
                {
                    out.push(Stmt::Assign(lhs.trim().to_ascii_uppercase(), kexpr(rhs)));
                }
            }
        }
    }
    panic!("the program ends inside a block (expected {until:?})");
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum KVal {
    I(i64),
    B(bool),
}

struct Machine<'a> {
    seq: &'a [Phase],
    /// Inputs change at every read (not only when the robot acts): signals that flicker
    /// between a wait and the test after it.
    flicker: bool,
    reads: std::cell::Cell<usize>,
    /// The controller's view of each phase.
    bits: Vec<HashMap<String, bool>>,
    actions: Vec<String>,
    vars: HashMap<String, i64>,
    /// `SIGNAL` name → (first input, last input).
    signals: HashMap<String, (u32, u32)>,
    steps: usize,
    /// The actions done when each label was last gone to.
    visits: HashMap<String, usize>,
}

enum Flow {
    Next,
    Exit,
    /// A GOTO to the label: out of every block, to the DEF's level.
    Goto(String),
    Stuck,
    Running,
}

impl Machine<'_> {
    fn bits(&self) -> &HashMap<String, bool> {
        if self.flicker {
            let r = self.reads.get();
            self.reads.set(r + 1);
            return &self.bits[r % self.seq.len()];
        }
        &self.bits[self.actions.len().min(self.seq.len() - 1)]
    }

    fn eval(&self, e: &KExpr) -> KVal {
        match e {
            KExpr::Int(i) => KVal::I(*i),
            KExpr::Bool(b) => KVal::B(*b),
            KExpr::Sys(s) => KVal::B(*self.bits().get(s).unwrap_or_else(|| panic!("unknown {s}"))),
            KExpr::Name(n) => {
                if let Some((a, b)) = self.signals.get(n) {
                    let bits = self.bits();
                    let mut v = 0;
                    for (k, ix) in (*a..=*b).enumerate() {
                        if bits[&format!("$IN[{ix}]")] {
                            v |= 1 << k;
                        }
                    }
                    KVal::I(v)
                } else {
                    KVal::I(*self.vars.get(n).unwrap_or_else(|| panic!("undeclared {n}")))
                }
            }
            KExpr::Not(a) => match self.eval(a) {
                KVal::B(b) => KVal::B(!b),
                v => panic!("NOT of {v:?}"),
            },
            KExpr::Neg(a) => match self.eval(a) {
                KVal::I(i) => KVal::I(-i),
                v => panic!("- of {v:?}"),
            },
            KExpr::Bin(op, a, b) => {
                let (x, y) = (self.eval(a), self.eval(b));
                KVal::B(match (op.as_str(), x, y) {
                    ("AND", KVal::B(x), KVal::B(y)) => x && y,
                    ("OR", KVal::B(x), KVal::B(y)) => x || y,
                    ("EXOR", KVal::B(x), KVal::B(y)) => x != y,
                    ("==", x, y) => x == y,
                    ("<>", x, y) => x != y,
                    ("<", KVal::I(x), KVal::I(y)) => x < y,
                    (">", KVal::I(x), KVal::I(y)) => x > y,
                    ("<=", KVal::I(x), KVal::I(y)) => x <= y,
                    (">=", KVal::I(x), KVal::I(y)) => x >= y,
                    // A type error: what a missing parenthesis would cause in KRL.
                    _ => panic!("KRL type error: {x:?} {op} {y:?}"),
                })
            }
        }
    }

    fn truth(&self, e: &KExpr) -> bool {
        match self.eval(e) {
            KVal::B(b) => b,
            v => panic!("a condition evaluated to {v:?}"),
        }
    }

    /// Runs `stmts`; a GOTO to a label among them goes on there (one to a label elsewhere
    /// leaves them: KRL jumps out of blocks, never into one).
    fn run(&mut self, stmts: &[Stmt]) -> Flow {
        let mut pc = 0;
        while pc < stmts.len() {
            match self.run_plain(&stmts[pc..]) {
                Flow::Goto(l) => {
                    let Some(at) = stmts
                        .iter()
                        .position(|s| matches!(s, Stmt::Label(x) if *x == l))
                    else {
                        return Flow::Goto(l);
                    };
                    // Back at a label without an action in between: it never ends.
                    if self.visits.insert(l, self.actions.len()) == Some(self.actions.len()) {
                        return Flow::Stuck;
                    }
                    pc = at;
                }
                f => return f,
            }
        }
        Flow::Next
    }

    fn run_plain(&mut self, stmts: &[Stmt]) -> Flow {
        for s in stmts {
            self.steps += 1;
            assert!(self.steps < 1_000_000, "the interpreter runs away");
            let f = match s {
                Stmt::Fold(name) => {
                    if self.actions.len() >= MAX_ACTIONS {
                        return Flow::Running;
                    }
                    self.actions.push(name.clone());
                    Flow::Next
                }
                Stmt::Wait(c) => {
                    // Inputs change only when the robot acts: a false condition stays false.
                    if self.truth(c) {
                        Flow::Next
                    } else {
                        Flow::Stuck
                    }
                }
                Stmt::If(c, then, otherwise) => {
                    if self.truth(c) {
                        self.run(then)
                    } else {
                        self.run(otherwise)
                    }
                }
                Stmt::Loop(body) => loop {
                    let before = self.actions.len();
                    match self.run(body) {
                        Flow::Next => {}
                        Flow::Exit => break Flow::Next,
                        other => break other,
                    }
                    if self.actions.len() == before {
                        // A round without an action and without a change: it never ends.
                        break Flow::Stuck;
                    }
                },
                Stmt::Exit => Flow::Exit,
                Stmt::Label(_) => Flow::Next,
                Stmt::Goto(l) => Flow::Goto(l.clone()),
                Stmt::Repeat(body, until) => {
                    let mut rounds = 0;
                    loop {
                        match self.run(body) {
                            Flow::Next => {}
                            other => break other,
                        }
                        if self.truth(until) {
                            break Flow::Next;
                        }
                        rounds += 1;
                        if rounds > 100 {
                            break Flow::Stuck;
                        }
                    }
                }
                Stmt::Switch(sel, cases) => {
                    let v = match self.eval(sel) {
                        KVal::I(i) => i,
                        v => panic!("SWITCH on {v:?}"),
                    };
                    let body = cases
                        .iter()
                        .find(|(l, _)| *l == Some(v))
                        .or_else(|| cases.iter().find(|(l, _)| l.is_none()))
                        .map(|(_, b)| b.clone())
                        .unwrap_or_default();
                    self.run(&body)
                }
                Stmt::Assign(n, e) => {
                    let v = match self.eval(e) {
                        KVal::I(i) => i,
                        KVal::B(b) => b as i64,
                    };
                    assert!(self.vars.contains_key(n), "assignment to undeclared {n}");
                    self.vars.insert(n.clone(), v);
                    Flow::Next
                }
            };
            match f {
                Flow::Next => {}
                other => return other,
            }
        }
        Flow::Next
    }
}

/// Reads the `.dat`: `SIGNAL` groups and `DECL INT` variables.
fn read_dat(dat: &str) -> (HashMap<String, (u32, u32)>, HashMap<String, i64>) {
    let (signals, decls) = dat_entries(dat);
    let vars = decls
        .into_iter()
        .filter(|(_, ty, _)| ty == "INT")
        .map(|(name, _, init)| (name, init.parse().unwrap()))
        .collect();
    (signals, vars)
}

/// A `.dat`'s `SIGNAL` groups (name → first and last input) and its declarations (name, type,
/// initial value as written), names upper-cased.
pub type Dat = (HashMap<String, (u32, u32)>, Vec<(String, String, String)>);

/// Reads a `.dat` ([`Dat`]).
pub fn dat_entries(dat: &str) -> Dat {
    let mut signals = HashMap::new();
    let mut decls = Vec::new();
    for l in dat.lines().map(code) {
        let w: Vec<&str> = l.split_whitespace().collect();
        if w.first() == Some(&"SIGNAL") {
            let ix = |s: &str| -> u32 {
                s.strip_prefix("$IN[")
                    .and_then(|r| r.strip_suffix(']'))
                    .unwrap()
                    .parse()
                    .unwrap()
            };
            assert_eq!(w[3], "TO");
            signals.insert(w[1].to_ascii_uppercase(), (ix(w[2]), ix(w[4])));
        } else if w.first() == Some(&"DECL") {
            let (name, init) = w[2].split_once('=').unwrap_or((w[2], "0"));
            decls.push((name.to_ascii_uppercase(), w[1].to_owned(), init.to_owned()));
        }
    }
    (signals, decls)
}

fn krl_run(program: &[Stmt], dat: &str, seq: &[Phase]) -> (Vec<String>, Outcome) {
    krl_run_with(program, dat, seq, false)
}

pub fn krl_run_with(
    program: &[Stmt],
    dat: &str,
    seq: &[Phase],
    flicker: bool,
) -> (Vec<String>, Outcome) {
    let (signals, vars) = read_dat(dat);
    let mut m = Machine {
        seq,
        flicker,
        reads: std::cell::Cell::new(0),
        bits: seq.iter().map(bits).collect(),
        actions: Vec::new(),
        vars,
        signals,
        steps: 0,
        visits: HashMap::new(),
    };
    let outcome = match m.run(program) {
        Flow::Next => Outcome::Done,
        Flow::Exit => panic!("EXIT outside a loop"),
        Flow::Stuck => Outcome::Stuck,
        Flow::Running => Outcome::Running,
        Flow::Goto(l) => panic!("GOTO {l}: no label it may go to"),
    };
    (m.actions, outcome)
}

/// The interpreter itself: KRL's precedence is not ST's, so a condition without the emitted
/// parentheses would mean something else (or not type-check).
#[test]
fn the_interpreter_uses_krl_precedence() {
    let phase: Phase = [("Part_OK", 1), ("Release", 0), ("Variant", 3)]
        .into_iter()
        .collect();
    let seq = vec![phase];
    let m = Machine {
        seq: &seq,
        flicker: false,
        reads: std::cell::Cell::new(0),
        bits: seq.iter().map(bits).collect(),
        actions: Vec::new(),
        vars: HashMap::new(),
        signals: [("V".to_owned(), (9, 12))].into_iter().collect(),
        steps: 0,
        visits: HashMap::new(),
    };
    // `$IN[1] OR $IN[3] == FALSE` is `($IN[1] OR $IN[3]) == FALSE` in KRL.
    assert!(!m.truth(&kexpr("$IN[1] OR $IN[3] == FALSE")));
    assert!(m.truth(&kexpr("$IN[1] OR ($IN[3] == FALSE)")));
    assert!(m.truth(&kexpr("(V == 3) AND $IN[1]")));
    assert!(m.truth(&kexpr("NOT $IN[3] AND $IN[1]")));
    assert!(m.truth(&kexpr("$IN[1] EXOR $IN[3]")));
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        m.truth(&kexpr("V == 3 AND $IN[1]"))
    }));
    assert!(r.is_err(), "`3 AND $IN[1]` is a KRL type error");
}

/// The interpreter runs the constructs the emitter writes.
#[test]
fn the_interpreter_runs_loops_and_switches() {
    let src = "DEF t( )\nLOOP\n;FOLD 1 A: x\n;ENDFOLD\nX = 0\nREPEAT\nIF $IN[1] THEN\nX = 2\nENDIF\nUNTIL X <> 0\nSWITCH X\nCASE 1\n;FOLD 2 B: x\n;ENDFOLD\nDEFAULT\nEXIT\nENDSWITCH\nENDLOOP\n;FOLD 3 C: x\n;ENDFOLD\nEND\n";
    let program = parse_program(src);
    let on: Phase = [("Part_OK", 1)].into_iter().collect();
    let (actions, outcome) = krl_run(&program, "DECL INT X=0\n", &[on]);
    assert_eq!(actions, ["A", "C"]);
    assert_eq!(outcome, Outcome::Done);
    let off: Phase = [("Part_OK", 0)].into_iter().collect();
    let (actions, outcome) = krl_run(&program, "DECL INT X=0\n", &[off]);
    assert_eq!(actions, ["A"]);
    assert_eq!(outcome, Outcome::Stuck);
}
