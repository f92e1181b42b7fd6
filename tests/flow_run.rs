//! The emitted control flow, checked by running it: every `fixtures/ok/flow-*` case is compiled
//! with the binary, and the generated `.src`/`.dat` are executed by a small KRL interpreter
//! (statements, `IF`, `LOOP`/`EXIT`, `REPEAT`/`UNTIL`, `SWITCH`, `WAIT FOR`, `$IN`/`$OUT`,
//! `SIGNAL` groups, KRL's own operator precedence) under many input sequences. The robot's
//! actions (the step FOLDs executed, in order) must be what the chart means: an independent
//! token player runs the SFC graph itself (IEC 61131-3: a transition fires when its condition
//! holds; a selection takes its first branch, left to right, whose condition holds; simultaneous
//! branches run one after another, left to right; a jump continues at its target step).
//!
//! Inputs change only when the robot acts: phase `k` of an input sequence holds while `k`
//! actions have run (the last phase holds after). A wait whose condition is false with inputs
//! that cannot change any more is "stuck"; both sides must get stuck at the same place. Endless
//! programs are compared over their first actions.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;

use skillpost::cond::{BinOp, Expr as StExpr, ExprKind};

/// How many actions are compared at most (endless programs).
const MAX_ACTIONS: usize = 40;

// ---------------------------------------------------------------------------------------------
// The world: signal values per phase
// ---------------------------------------------------------------------------------------------

/// The flow base's signals (fixtures/base/flow/Blackboard.aml), as the chart and the
/// controller see them.
#[derive(Clone, Copy)]
enum Io {
    Bit(&'static str),
    Group(u32, u32),
}

const SIGNALS: &[(&str, Io)] = &[
    ("Part_OK", Io::Bit("$IN[1]")),
    ("Magazine_Empty", Io::Bit("$IN[2]")),
    ("Release", Io::Bit("$IN[3]")),
    ("Variant", Io::Group(9, 4)),
    ("Gripper_Closed", Io::Bit("$OUT[5]")),
    ("Door_Closed", Io::Bit("$CYCFLAG[3]")),
];

/// One phase: each signal's value (booleans as 0/1).
type Phase = BTreeMap<&'static str, i64>;

/// The controller's view of a phase: every addressed bit.
fn bits(phase: &Phase) -> HashMap<String, bool> {
    let mut out = HashMap::new();
    for (name, io) in SIGNALS {
        let v = phase.get(name).copied().unwrap_or(0);
        match io {
            Io::Bit(addr) => {
                out.insert((*addr).to_owned(), v != 0);
            }
            Io::Group(first, len) => {
                for k in 0..*len {
                    out.insert(format!("$IN[{}]", first + k), (v >> k) & 1 == 1);
                }
            }
        }
    }
    out
}

/// A deterministic pseudo-random sequence (xorshift).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

fn sequences(seed: u64, count: usize) -> Vec<Vec<Phase>> {
    let mut rng = Rng(seed | 1);
    let mut out = Vec::new();
    for _ in 0..count {
        let phases = 1 + (rng.next() % 12) as usize;
        // How often a bit is set in this sequence: 1, 2 or 3 in 4.
        let ones = 1 + rng.next() % 3;
        let mut seq = Vec::new();
        for _ in 0..phases {
            let mut p = Phase::new();
            for (name, io) in SIGNALS {
                let v = match io {
                    Io::Bit(_) => (rng.next() % 4 < ones) as i64,
                    // Mostly the values the fixtures compare with, sometimes others.
                    Io::Group(..) => [0, 1, 2, 3, 12, 15][(rng.next() % 6) as usize],
                };
                p.insert(name, v);
            }
            seq.push(p);
        }
        out.push(seq);
    }
    out
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Outcome {
    /// The program ended.
    Done,
    /// Waiting for a condition that can no longer change.
    Stuck,
    /// Still running after [`MAX_ACTIONS`] actions.
    Running,
}

// ---------------------------------------------------------------------------------------------
// The chart's meaning: a token player over the SFC graph
// ---------------------------------------------------------------------------------------------

#[derive(Debug)]
struct Node {
    tag: String,
    name: String,
    x: f64,
    inputs: Vec<u64>,
    condition: Option<String>,
    target: Option<String>,
    skill: bool,
}

struct Chart {
    nodes: BTreeMap<u64, Node>,
    /// Document order of the ids.
    order: Vec<u64>,
}

impl Chart {
    fn read(path: &Path) -> Chart {
        let text = std::fs::read_to_string(path).unwrap();
        let doc = roxmltree::Document::parse(&text).unwrap();
        let sfc = doc
            .descendants()
            .find(|n| n.is_element() && n.tag_name().name() == "SFC")
            .expect("an SFC body");
        let mut nodes = BTreeMap::new();
        let mut order = Vec::new();
        for e in sfc.children().filter(|n| n.is_element()) {
            let id: u64 = e.attribute("localId").unwrap().parse().unwrap();
            let d = |tag: &'static str| {
                e.descendants()
                    .filter(move |n| n.is_element() && n.tag_name().name() == tag)
            };
            let inputs = d("connection")
                .map(|c| c.attribute("refLocalId").unwrap().parse().unwrap())
                .collect();
            let x = d("position")
                .next()
                .and_then(|p| p.attribute("x"))
                .map_or(0.0, |x| x.parse().unwrap());
            let condition = d("condition").next().map(|c| {
                match c
                    .descendants()
                    .find(|n| n.is_element() && n.tag_name().name() == "reference")
                {
                    Some(r) => r.attribute("name").unwrap().to_owned(),
                    None => c
                        .descendants()
                        .filter(|n| n.is_text())
                        .map(|n| n.text().unwrap())
                        .collect(),
                }
            });
            nodes.insert(
                id,
                Node {
                    tag: e.tag_name().name().to_owned(),
                    name: e.attribute("name").unwrap_or("").to_owned(),
                    x,
                    inputs,
                    condition,
                    target: e.attribute("targetName").map(str::to_owned),
                    skill: d("skill").next().is_some(),
                },
            );
            order.push(id);
        }
        Chart { nodes, order }
    }

    /// Successors, left to right by x, ties in document order.
    fn succs(&self, id: u64) -> Vec<u64> {
        let mut s: Vec<u64> = self
            .order
            .iter()
            .copied()
            .filter(|c| self.nodes[c].inputs.contains(&id))
            .collect();
        s.sort_by(|a, b| {
            self.nodes[a].x.total_cmp(&self.nodes[b].x).then(
                self.order
                    .iter()
                    .position(|o| o == a)
                    .cmp(&self.order.iter().position(|o| o == b)),
            )
        });
        s
    }

    fn holds(&self, transition: u64, phase: &Phase) -> bool {
        match &self.nodes[&transition].condition {
            None => true,
            Some(text) => {
                let e = skillpost::cond::parse(text, &|o| o).expect("the fixture's condition");
                st_eval(&e, phase) != 0
            }
        }
    }
}

/// Evaluates a condition with ST's meaning (the parser's tree already has ST's precedence).
fn st_eval(e: &StExpr, phase: &Phase) -> i64 {
    match &e.kind {
        ExprKind::Bool(b) => *b as i64,
        ExprKind::Int(s) => s.parse().unwrap(),
        ExprKind::Real(_) => panic!("no decimals in the fixtures"),
        ExprKind::Name(n) => {
            *phase
                .iter()
                .find(|(k, _)| k.eq_ignore_ascii_case(n))
                .unwrap_or_else(|| panic!("unknown signal {n}"))
                .1
        }
        ExprKind::Not(a) => (st_eval(a, phase) == 0) as i64,
        ExprKind::Neg(a) => -st_eval(a, phase),
        ExprKind::Bin(op, a, b) => {
            let (x, y) = (st_eval(a, phase), st_eval(b, phase));
            (match op {
                BinOp::Or => x != 0 || y != 0,
                BinOp::Xor => (x != 0) != (y != 0),
                BinOp::And => x != 0 && y != 0,
                BinOp::Eq => x == y,
                BinOp::Ne => x != y,
                BinOp::Lt => x < y,
                BinOp::Gt => x > y,
                BinOp::Le => x <= y,
                BinOp::Ge => x >= y,
            }) as i64
        }
    }
}

struct Player<'a> {
    chart: &'a Chart,
    seq: &'a [Phase],
    actions: Vec<String>,
}

enum Stop {
    Conv(u64),
    Done,
    Stuck,
    Running,
}

impl Player<'_> {
    fn phase(&self) -> &Phase {
        &self.seq[self.actions.len().min(self.seq.len() - 1)]
    }

    /// Runs from `id` until the flow ends or reaches a simultaneous convergence (returned).
    fn run(&mut self, mut id: u64) -> Stop {
        let c = self.chart;
        loop {
            if self.actions.len() >= MAX_ACTIONS {
                return Stop::Running;
            }
            let n = &c.nodes[&id];
            let succs = c.succs(id);
            match n.tag.as_str() {
                "step" => {
                    if n.skill {
                        self.actions.push(n.name.clone());
                    }
                    match succs.as_slice() {
                        [] => return Stop::Done,
                        [s] => id = *s,
                        _ => panic!("step with several successors"),
                    }
                }
                "transition" => {
                    if !c.holds(id, self.phase()) {
                        return Stop::Stuck;
                    }
                    id = succs[0];
                }
                "selectionDivergence" => {
                    let Some(t) = succs.iter().find(|t| c.holds(**t, self.phase())) else {
                        return Stop::Stuck;
                    };
                    id = c.succs(*t)[0];
                }
                "selectionConvergence" => id = succs[0],
                "simultaneousDivergence" => {
                    let mut conv = None;
                    for b in succs {
                        match self.run(b) {
                            Stop::Conv(cv) => conv = Some(cv),
                            other => return other,
                        }
                    }
                    id = c.succs(conv.expect("a convergence"))[0];
                }
                "simultaneousConvergence" => return Stop::Conv(id),
                "jumpStep" => {
                    let target = n.target.as_ref().unwrap();
                    id = *c
                        .order
                        .iter()
                        .find(|s| c.nodes[s].tag == "step" && &c.nodes[s].name == target)
                        .unwrap();
                }
                other => panic!("unexpected element {other}"),
            }
        }
    }
}

fn chart_meaning(chart: &Chart, seq: &[Phase]) -> (Vec<String>, Outcome) {
    let start = *chart
        .order
        .iter()
        .find(|id| chart.nodes[id].tag == "step" && chart.nodes[id].inputs.is_empty())
        .unwrap();
    let mut p = Player {
        chart,
        seq,
        actions: Vec::new(),
    };
    let outcome = match p.run(start) {
        Stop::Done => Outcome::Done,
        Stop::Stuck => Outcome::Stuck,
        Stop::Running => Outcome::Running,
        Stop::Conv(_) => panic!("a convergence without divergence"),
    };
    (p.actions, outcome)
}

// ---------------------------------------------------------------------------------------------
// The KRL interpreter
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Clone)]
enum KExpr {
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
enum Stmt {
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

fn kexpr(s: &str) -> KExpr {
    let mut p = KParser {
        t: ktokens(s),
        i: 0,
    };
    let e = p.expr();
    assert_eq!(p.i, p.t.len(), "trailing tokens in `{s}`");
    e
}

/// The code of a line (without a `;` comment), upper-cased keywords kept as written.
fn code(line: &str) -> &str {
    line.split(';').next().unwrap().trim()
}

/// Parses the main program's statements (between its `DEF` and `END`).
fn parse_program(src: &str) -> Vec<Stmt> {
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

/// Parses statements until a line whose first word is one of `until`; returns them and that
/// line's code.
fn parse_block(lines: &[&str], i: &mut usize, until: &[&str]) -> (Vec<Stmt>, String) {
    let mut out = Vec::new();
    while *i < lines.len() {
        let raw = lines[*i].trim();
        *i += 1;
        if let Some(title) = raw.strip_prefix(";FOLD ") {
            // Skip to the matching ;ENDFOLD.
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
            if words.next().is_some_and(|n| n.parse::<usize>().is_ok()) {
                let name = words.next().unwrap().trim_end_matches(':');
                out.push(Stmt::Fold(name.to_owned()));
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
    actions: Vec<String>,
    vars: HashMap<String, i64>,
    /// `SIGNAL` name → (first input, last input).
    signals: HashMap<String, (u32, u32)>,
    steps: usize,
}

enum Flow {
    Next,
    Exit,
    Stuck,
    Running,
}

impl Machine<'_> {
    fn bits(&self) -> HashMap<String, bool> {
        if self.flicker {
            let r = self.reads.get();
            self.reads.set(r + 1);
            return bits(&self.seq[r % self.seq.len()]);
        }
        bits(&self.seq[self.actions.len().min(self.seq.len() - 1)])
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

    fn run(&mut self, stmts: &[Stmt]) -> Flow {
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
    let mut signals = HashMap::new();
    let mut vars = HashMap::new();
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
        } else if w.first() == Some(&"DECL") && w.get(1) == Some(&"INT") {
            let (name, init) = w[2].split_once('=').unwrap_or((w[2], "0"));
            vars.insert(name.to_ascii_uppercase(), init.parse().unwrap());
        }
    }
    (signals, vars)
}

fn krl_run(program: &[Stmt], dat: &str, seq: &[Phase]) -> (Vec<String>, Outcome) {
    krl_run_with(program, dat, seq, false)
}

fn krl_run_with(
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
        actions: Vec::new(),
        vars,
        signals,
        steps: 0,
    };
    let outcome = match m.run(program) {
        Flow::Next => Outcome::Done,
        Flow::Exit => panic!("EXIT outside a loop"),
        Flow::Stuck => Outcome::Stuck,
        Flow::Running => Outcome::Running,
    };
    (m.actions, outcome)
}

// ---------------------------------------------------------------------------------------------
// The cases
// ---------------------------------------------------------------------------------------------

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn copy_dir(from: &Path, to: &Path) {
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

/// Compiles a flow fixture; returns the `.src`, the `.dat` and the chart.
fn compile(case: &str) -> (String, String, Chart) {
    let tmp = tempfile::tempdir().unwrap();
    copy_dir(&repo().join("fixtures/base/flow"), tmp.path());
    copy_dir(&repo().join("fixtures/ok").join(case), tmp.path());
    let toml = std::fs::read_to_string(tmp.path().join("case.toml")).unwrap();
    let program = toml
        .lines()
        .find_map(|l| l.strip_prefix("program = \""))
        .unwrap()
        .trim_end_matches('"')
        .to_owned();
    let out = Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["--lf", "Blackboard.aml", &program])
        .current_dir(tmp.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{case}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let read =
        |ext: &str| std::fs::read_to_string(tmp.path().join(format!("{program}.{ext}"))).unwrap();
    (
        read("src"),
        read("dat"),
        Chart::read(&tmp.path().join("sfc.xml")),
    )
}

/// Runs the case under many input sequences; returns how many ended in each way.
///
/// Then once more with inputs that change at every read: the program must still follow the
/// chart's paths (every pair of consecutive actions one the chart produced above, the first
/// and, when it ends, the last action too), so a selection is never passed without taking a
/// branch when a signal changes between the wait and the test.
fn check(case: &str, seed: u64) -> BTreeMap<String, usize> {
    let (src, dat, chart) = compile(case);
    let program = parse_program(&src);
    let mut seen = BTreeMap::new();
    let mut pairs = std::collections::BTreeSet::new();
    let mut firsts = std::collections::BTreeSet::new();
    let mut lasts = std::collections::BTreeSet::new();
    let all = sequences(seed, 400);
    for (k, seq) in all.iter().enumerate() {
        let want = chart_meaning(&chart, seq);
        let got = krl_run(&program, &dat, seq);
        assert_eq!(
            got, want,
            "{case}: input sequence {k} ({seq:?}): the KRL program (left) does not do what the chart means (right)\n{src}"
        );
        for w in want.0.windows(2) {
            pairs.insert((w[0].clone(), w[1].clone()));
        }
        firsts.extend(want.0.first().cloned());
        if want.1 == Outcome::Done {
            lasts.insert(want.0.last().cloned());
        }
        *seen.entry(format!("{:?}", want.1)).or_insert(0) += 1;
    }
    for (k, seq) in all.iter().enumerate() {
        let (actions, outcome) = krl_run_with(&program, &dat, seq, true);
        let bad = actions
            .windows(2)
            .find(|w| !pairs.contains(&(w[0].clone(), w[1].clone())));
        assert!(
            bad.is_none(),
            "{case}: flickering inputs {k}: `{:?}` is no path of the chart (actions {actions:?})",
            bad
        );
        if let Some(f) = actions.first() {
            assert!(
                firsts.contains(f),
                "{case}: flickering inputs {k}: starts with {f}"
            );
        }
        if outcome == Outcome::Done {
            assert!(
                lasts.contains(&actions.last().cloned()),
                "{case}: flickering inputs {k}: ends after {actions:?}"
            );
        }
    }
    seen
}

macro_rules! flow_cases {
    ($($test:ident => $dir:literal,)*) => {
        $(
            #[test]
            fn $test() {
                let seen = check($dir, 0x5eed ^ $dir.len() as u64);
                println!("{}: {seen:?}", $dir);
            }
        )*
        /// Every flow fixture is run.
        #[test]
        fn every_flow_fixture_is_run() {
            let mut dirs: Vec<String> = std::fs::read_dir(repo().join("fixtures/ok"))
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with("flow-"))
                .collect();
            dirs.sort();
            assert_eq!(dirs, vec![$($dir),*]);
        }
    };
}

flow_cases! {
    flow_cyclic => "flow-cyclic",
    flow_guarded_sequence => "flow-guarded-sequence",
    flow_loop_exit => "flow-loop-exit",
    flow_loop_joined_exits => "flow-loop-joined-exits",
    flow_nested_loops => "flow-nested-loops",
    flow_parallel_in_selection => "flow-parallel-in-selection",
    flow_reference_condition => "flow-reference-condition",
    flow_selection_in_parallel => "flow-selection-in-parallel",
    flow_selection_three_way => "flow-selection-three-way",
    flow_selection_two_way => "flow-selection-two-way",
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
        actions: Vec::new(),
        vars: HashMap::new(),
        signals: [("V".to_owned(), (9, 12))].into_iter().collect(),
        steps: 0,
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
