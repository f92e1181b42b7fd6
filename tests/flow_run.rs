//! The emitted control flow, checked by running it: every `fixtures/ok/flow-*` case is compiled
//! with the binary, and the generated `.src`/`.dat` are executed by a small KRL interpreter
//! (statements, `IF`, `LOOP`/`EXIT`, `REPEAT`/`UNTIL`, `SWITCH`, `WAIT FOR`, `$IN`/`$OUT`,
//! `SIGNAL` groups, KRL's own operator precedence) under many input sequences. The robot's
//! actions (the step FOLDs executed, in order) must be what the chart means: an independent
//! token player runs the SFC graph itself (IEC 61131-3: a transition fires when its condition
//! holds; a selection takes its first branch, left to right, whose condition holds; simultaneous
//! branches run one after another, left to right; a jump continues at its target step).
//!
//! Besides the fixtures, 150 random structured charts (guarded sequences, selections with empty
//! and unconditional branches, simultaneous branches, loops left by one branch or two that join,
//! loops left early by a selection before the deciding one, endless loops, nested in each
//! other) are compiled and run the same way.
//!
//! Inputs change only when the robot acts: phase `k` of an input sequence holds while `k`
//! actions have run (the last phase holds after). A wait whose condition is false with inputs
//! that cannot change any more is "stuck"; both sides must get stuck at the same place. Endless
//! programs are compared over their first actions.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;

use skillpost::cond::{BinOp, Expr as StExpr, ExprKind};

#[path = "common/krl_check.rs"]
mod krl_syntax;

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
    /// Successors, left to right by x, ties in document order.
    succ: BTreeMap<u64, Vec<u64>>,
    /// Parsed conditions.
    conds: BTreeMap<u64, StExpr>,
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
        let mut succ: BTreeMap<u64, Vec<(usize, u64)>> = BTreeMap::new();
        for (pos, id) in order.iter().enumerate() {
            for i in &nodes[id].inputs {
                succ.entry(*i).or_default().push((pos, *id));
            }
        }
        let succ = succ
            .into_iter()
            .map(|(k, mut v)| {
                v.sort_by(|a, b| nodes[&a.1].x.total_cmp(&nodes[&b.1].x).then(a.0.cmp(&b.0)));
                (k, v.into_iter().map(|(_, id)| id).collect())
            })
            .collect();
        let conds = nodes
            .iter()
            .filter_map(|(id, n)| {
                let text = n.condition.as_ref()?;
                let e = skillpost::cond::parse(text, &|o| o).expect("the chart's condition");
                Some((*id, e))
            })
            .collect();
        Chart {
            nodes,
            order,
            succ,
            conds,
        }
    }

    /// Successors, left to right by x, ties in document order.
    fn succs(&self, id: u64) -> Vec<u64> {
        self.succ.get(&id).cloned().unwrap_or_default()
    }

    fn holds(&self, transition: u64, phase: &Phase) -> bool {
        match self.conds.get(&transition) {
            None => true,
            Some(e) => st_eval(e, phase) != 0,
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
    /// Free mode: every transition fires and a selection takes a branch at random (the chart's
    /// paths, whatever the conditions).
    free: Option<Rng>,
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
        let mut moves = 0usize;
        loop {
            moves += 1;
            if self.actions.len() >= MAX_ACTIONS || moves > 100_000 {
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
                    if self.free.is_none() && !c.holds(id, self.phase()) {
                        return Stop::Stuck;
                    }
                    id = succs[0];
                }
                "selectionDivergence" => {
                    let t = match &mut self.free {
                        Some(rng) => succs[(rng.next() % succs.len() as u64) as usize],
                        None => match succs.iter().find(|t| c.holds(**t, self.phase())) {
                            Some(t) => *t,
                            None => return Stop::Stuck,
                        },
                    };
                    id = c.succs(t)[0];
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
    chart_run(chart, seq, None)
}

fn chart_run(chart: &Chart, seq: &[Phase], free: Option<Rng>) -> (Vec<String>, Outcome) {
    let start = *chart
        .order
        .iter()
        .find(|id| chart.nodes[id].tag == "step" && chart.nodes[id].inputs.is_empty())
        .unwrap();
    let mut p = Player {
        chart,
        seq,
        actions: Vec::new(),
        free,
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
    /// The controller's view of each phase.
    bits: Vec<HashMap<String, bool>>,
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
        bits: seq.iter().map(bits).collect(),
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
    check_compiled(case, &src, &dat, &chart, seed, 400)
}

fn check_compiled(
    case: &str,
    src: &str,
    dat: &str,
    chart: &Chart,
    seed: u64,
    count: usize,
) -> BTreeMap<String, usize> {
    let program = parse_program(src);
    let mut seen = BTreeMap::new();
    let mut pairs = std::collections::BTreeSet::new();
    let mut firsts = std::collections::BTreeSet::new();
    let mut lasts = std::collections::BTreeSet::new();
    let all = sequences(seed, count);
    for (k, seq) in all.iter().enumerate() {
        let want = chart_meaning(chart, seq);
        let got = krl_run(&program, dat, seq);
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
    // The chart's paths whatever the conditions: every pair of consecutive actions possible.
    for r in 0..500u64 {
        let (actions, outcome) =
            chart_run(chart, &all[0], Some(Rng(seed ^ ((r + 1) * 0x2545_F491))));
        for w in actions.windows(2) {
            pairs.insert((w[0].clone(), w[1].clone()));
        }
        firsts.extend(actions.first().cloned());
        if outcome == Outcome::Done {
            lasts.insert(actions.last().cloned());
        }
    }
    for (k, seq) in all.iter().enumerate() {
        let (actions, outcome) = krl_run_with(&program, dat, seq, true);
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
    flow_loop_early_exit => "flow-loop-early-exit",
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
        bits: seq.iter().map(bits).collect(),
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

// ---------------------------------------------------------------------------------------------
// Random charts
// ---------------------------------------------------------------------------------------------

/// Writes random structured charts: sequences with guarded transitions, selections (2 or 3
/// branches, sometimes an empty or unconditional one), simultaneous branches, loops closed by a
/// jump back (left by one branch or by two that join), nested in each other; sometimes the
/// whole chart ends in an endless loop.
struct ChartGen {
    rng: Rng,
    parts: Vec<String>,
    next: u64,
}

const CONDITIONS: &[&str] = &[
    "Part_OK",
    "NOT Part_OK",
    "Magazine_Empty",
    "Release OR Magazine_Empty",
    "Variant = 1",
    "Variant &gt;= 2 AND NOT Release",
    "Door_Closed XOR Part_OK",
    "Gripper_Closed",
];

impl ChartGen {
    fn id(&mut self) -> u64 {
        self.next += 1;
        self.next
    }

    fn pick(&mut self, n: u64) -> u64 {
        self.rng.next() % n
    }

    fn cond(&mut self) -> Option<&'static str> {
        match self.pick(3) {
            0 => None,
            _ => Some(CONDITIONS[self.pick(CONDITIONS.len() as u64) as usize]),
        }
    }

    fn conn(inputs: &[u64]) -> String {
        let c: String = inputs
            .iter()
            .map(|i| format!("<connection refLocalId=\"{i}\"/>"))
            .collect();
        format!("<connectionPointIn>{c}</connectionPointIn>")
    }

    fn step(&mut self, input: Option<u64>, skill: bool, x: u64) -> u64 {
        let id = self.id();
        let name = if input.is_none() {
            "Start".to_owned()
        } else {
            format!("S{id}")
        };
        let mut s = format!(
            "<step localId=\"{id}\" name=\"{name}\"{}><position x=\"{x}\" y=\"{id}\"/>",
            if input.is_none() {
                " initialStep=\"true\""
            } else {
                ""
            }
        );
        if let Some(i) = input {
            s.push_str(&Self::conn(&[i]));
        }
        if skill {
            s.push_str(&format!(
                "<addData><data name=\"iwb\" handleUnknown=\"preserve\"><iwb><ressources><ressource name=\"KUKA KR15-2\"/></ressources><skill name=\"Move LIN\"/><Variable name=\"Frame\" Value=\"({id}, 0, 0, 0, 0, 0)\"/></iwb></data></addData>"
            ));
        }
        s.push_str("</step>");
        self.parts.push(s);
        id
    }

    fn trans(&mut self, input: u64, cond: Option<&str>, x: u64) -> u64 {
        let id = self.id();
        let c = cond
            .map(|c| format!("<condition><inline name=\"\"><ST>{c}</ST></inline></condition>"))
            .unwrap_or_default();
        self.parts.push(format!(
            "<transition localId=\"{id}\"><position x=\"{x}\" y=\"{id}\"/>{}{c}</transition>",
            Self::conn(&[input])
        ));
        id
    }

    fn node(&mut self, tag: &str, inputs: &[u64], x: u64) -> u64 {
        let id = self.id();
        self.parts.push(format!(
            "<{tag} localId=\"{id}\"><position x=\"{x}\" y=\"{id}\"/>{}</{tag}>",
            Self::conn(inputs)
        ));
        id
    }

    fn jump(&mut self, input: u64, target: u64) {
        let id = self.id();
        self.parts.push(format!(
            "<jumpStep localId=\"{id}\" targetName=\"S{target}\"><position x=\"0\" y=\"{id}\"/>{}</jumpStep>",
            Self::conn(&[input])
        ));
    }

    /// Items after step `tail`; returns the last step.
    fn items(&mut self, tail: u64, depth: u32) -> u64 {
        let mut tail = tail;
        for _ in 0..1 + self.pick(3) {
            tail = self.item(tail, depth);
        }
        tail
    }

    /// One item after step `tail`; returns the step it ends with.
    fn item(&mut self, tail: u64, depth: u32) -> u64 {
        let kind = if depth >= 3 { 0 } else { self.pick(5) };
        match kind {
            // A guarded step.
            0 | 1 => {
                let c = self.cond();
                let t = self.trans(tail, c, 0);
                self.step(Some(t), true, 0)
            }
            // A selection.
            2 => {
                let n = 2 + self.pick(2);
                let div = self.node("selectionDivergence", &[tail], 0);
                let default = self.pick(2) == 0;
                let mut ends = Vec::new();
                for k in 0..n {
                    let x = 10 * (n - k); // left to right = reverse document order
                    let c = if default && k == n - 1 {
                        None
                    } else {
                        Some(CONDITIONS[self.pick(CONDITIONS.len() as u64) as usize])
                    };
                    let t = self.trans(div, c, x);
                    if self.pick(4) == 0 {
                        ends.push(t); // an empty branch
                    } else {
                        let s = self.step(Some(t), true, x);
                        let last = self.items(s, depth + 1);
                        let c2 = self.cond();
                        ends.push(self.trans(last, c2, x));
                    }
                }
                let conv = self.node("selectionConvergence", &ends, 0);
                self.step(Some(conv), true, 0)
            }
            // Simultaneous branches.
            3 => {
                let c = self.cond();
                let t = self.trans(tail, c, 0);
                let div = self.node("simultaneousDivergence", &[t], 0);
                let mut lasts = Vec::new();
                for k in 0..2 {
                    let s = self.step(Some(div), true, 10 * k);
                    lasts.push(self.items(s, depth + 1));
                }
                let conv = self.node("simultaneousConvergence", &lasts, 0);
                let c = self.cond();
                let t = self.trans(conv, c, 0);
                self.step(Some(t), true, 0)
            }
            // A loop.
            _ => self.looped(tail, depth, false),
        }
    }

    /// A loop after step `tail`; returns the step after it (endless: the last step inside).
    fn looped(&mut self, tail: u64, depth: u32, endless: bool) -> u64 {
        let c = self.cond();
        let t = self.trans(tail, c, 0);
        let head = self.step(Some(t), true, 0);
        let mut last = self.items(head, depth + 1);
        // Sometimes a selection leaves the loop early; its exit joins the others later.
        let mut early = Vec::new();
        if !endless && self.pick(3) == 0 {
            let div = self.node("selectionDivergence", &[last], 0);
            let (xe, xg) = if self.pick(2) == 0 { (0, 10) } else { (10, 0) };
            let ce = Some(CONDITIONS[self.pick(CONDITIONS.len() as u64) as usize]);
            let te = self.trans(div, ce, xe);
            if self.pick(2) == 0 {
                let s = self.step(Some(te), true, xe);
                let c = self.cond();
                early.push(self.trans(s, c, xe));
            } else {
                early.push(te);
            }
            let cg = if xg > xe { None } else { self.cond() };
            let tg = self.trans(div, cg, xg);
            let sg = self.step(Some(tg), true, xg);
            last = self.items(sg, depth + 1);
        }
        if endless {
            let c = self.cond();
            let t = self.trans(last, c, 0);
            self.jump(t, head);
            return last;
        }
        let div = self.node("selectionDivergence", &[last], 0);
        let repeat = Some(CONDITIONS[self.pick(CONDITIONS.len() as u64) as usize]);
        let two_exits = self.pick(3) == 0;
        // The repeat branch is first or last (priority).
        let repeat_first = self.pick(2) == 0;
        let xs: [u64; 3] = if repeat_first {
            [0, 10, 20]
        } else {
            [20, 0, 10]
        };
        let tr = self.trans(div, repeat, xs[0]);
        if self.pick(2) == 0 {
            let s = self.step(Some(tr), true, xs[0]);
            let c = self.cond();
            let t = self.trans(s, c, xs[0]);
            self.jump(t, head);
        } else {
            self.jump(tr, head);
        }
        let exit_cond = if self.pick(2) == 0 && !repeat_first {
            Some(CONDITIONS[self.pick(CONDITIONS.len() as u64) as usize])
        } else if repeat_first && self.pick(2) == 0 {
            None
        } else {
            Some(CONDITIONS[self.pick(CONDITIONS.len() as u64) as usize])
        };
        if two_exits {
            let a = self.trans(div, Some("Release"), xs[1]);
            let sa = self.step(Some(a), true, xs[1]);
            let ta = self.trans(sa, None, xs[1]);
            let b = self.trans(div, exit_cond, xs[2]);
            let mut ins = vec![ta, b];
            ins.extend(early);
            let conv = self.node("selectionConvergence", &ins, 0);
            self.step(Some(conv), true, 0)
        } else if !early.is_empty() {
            let e = self.trans(div, exit_cond, xs[1]);
            let mut ins = vec![e];
            ins.extend(early);
            let conv = self.node("selectionConvergence", &ins, 0);
            self.step(Some(conv), true, 0)
        } else {
            let e = self.trans(div, exit_cond, xs[1]);
            self.step(Some(e), true, 0)
        }
    }

    fn chart(seed: u64) -> String {
        let mut g = ChartGen {
            rng: Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1),
            parts: Vec::new(),
            next: 0,
        };
        let start = g.step(None, false, 0);
        let last = g.items(start, 0);
        if g.pick(5) == 0 {
            g.looped(last, 0, true);
        } else {
            let t = g.trans(last, None, 0);
            let id = g.id();
            g.parts.push(format!(
                "<step localId=\"{id}\" name=\"End\"><position x=\"0\" y=\"{id}\"/>{}</step>",
                ChartGen::conn(&[t])
            ));
        }
        format!(
            "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<project xmlns=\"http://www.plcopen.org/xml/tc6_0201\"><fileHeader companyName=\"t\" productName=\"random\" productVersion=\"1\" creationDateTime=\"2026-11-23T08:00:00\"/><types><pous><pou name=\"R\" pouType=\"program\"><body><SFC>\n{}\n</SFC></body></pou></pous></types></project>\n",
            g.parts.join("\n")
        )
    }
}

/// 150 random charts, each compiled by the binary and run under 60 input sequences (and again
/// with flickering inputs) against the chart's meaning.
#[test]
fn random_charts_do_what_they_mean() {
    let tmp = tempfile::tempdir().unwrap();
    copy_dir(&repo().join("fixtures/base/flow"), tmp.path());
    let mut shapes = BTreeMap::new();
    for seed in 1..=150u64 {
        let text = ChartGen::chart(seed);
        let sfc = tmp.path().join("sfc.xml");
        std::fs::write(&sfc, &text).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_skillpost"))
            .args(["--lf", "Blackboard.aml", "R"])
            .current_dir(tmp.path())
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "random chart {seed} does not compile:\n{}\n{text}",
            String::from_utf8_lossy(&out.stderr)
        );
        let src = std::fs::read_to_string(tmp.path().join("R.src")).unwrap();
        let dat = std::fs::read_to_string(tmp.path().join("R.dat")).unwrap();
        if let Err(e) = krl_syntax::check_krl(&src, &dat, "R", true) {
            panic!("random chart {seed}: KRL structure check: {e}\n{src}");
        }
        let chart = Chart::read(&sfc);
        let seen = check_compiled(
            &format!("random chart {seed}"),
            &src,
            &dat,
            &chart,
            seed,
            60,
        );
        for (k, v) in seen {
            *shapes.entry(k).or_insert(0) += v;
        }
        for kw in ["LOOP", "SWITCH", "IF ", "WAIT FOR"] {
            if src.contains(kw) {
                *shapes.entry(kw.to_owned()).or_insert(0) += 1;
            }
        }
    }
    println!("random charts: {shapes:?}");
    // The generator reaches every construct.
    for kw in ["LOOP", "SWITCH", "IF ", "WAIT FOR"] {
        assert!(shapes.get(kw).copied().unwrap_or(0) > 10, "{shapes:?}");
    }
}

/// Charts that may not be structured: a random chart with one jump retargeted to a random step
/// (forward, into another branch, out of a loop, ...). The compiler must never crash: it either
/// refuses the chart with located errors (exit status 1) or compiles it into a program that does
/// what the chart means.
#[test]
fn retargeted_jumps_are_refused_or_right() {
    let tmp = tempfile::tempdir().unwrap();
    copy_dir(&repo().join("fixtures/base/flow"), tmp.path());
    let (mut refused, mut compiled) = (0, 0);
    let mut codes = BTreeMap::new();
    for seed in 1..=300u64 {
        let text = ChartGen::chart(seed);
        let steps: Vec<&str> = text
            .match_indices("name=\"S")
            .map(|(i, _)| {
                let rest = &text[i + 6..];
                &rest[..rest.find('"').unwrap()]
            })
            .collect();
        let jumps: Vec<usize> = text
            .match_indices("targetName=\"")
            .map(|(i, _)| i + 12)
            .collect();
        if jumps.is_empty() || steps.is_empty() {
            continue;
        }
        let mut rng = Rng(seed * 7919 + 1);
        let at = jumps[(rng.next() % jumps.len() as u64) as usize];
        let end = at + text[at..].find('"').unwrap();
        let target = steps[(rng.next() % steps.len() as u64) as usize];
        let mutated = format!("{}{target}{}", &text[..at], &text[end..]);
        let sfc = tmp.path().join("sfc.xml");
        std::fs::write(&sfc, &mutated).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_skillpost"))
            .args(["--lf", "--format", "short", "Blackboard.aml", "R"])
            .current_dir(tmp.path())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        match out.status.code() {
            Some(0) => {
                compiled += 1;
                let src = std::fs::read_to_string(tmp.path().join("R.src")).unwrap();
                let dat = std::fs::read_to_string(tmp.path().join("R.dat")).unwrap();
                krl_syntax::check_krl(&src, &dat, "R", true)
                    .unwrap_or_else(|e| panic!("retargeted chart {seed}: {e}\n{src}"));
                let chart = Chart::read(&sfc);
                check_compiled(
                    &format!("retargeted chart {seed}"),
                    &src,
                    &dat,
                    &chart,
                    seed,
                    40,
                );
            }
            Some(1) => {
                refused += 1;
                for line in stderr.lines() {
                    if let Some(i) = line.find("error[E") {
                        *codes.entry(line[i + 6..i + 10].to_owned()).or_insert(0) += 1;
                    }
                }
                assert!(
                    stderr.contains("sfc.xml:"),
                    "retargeted chart {seed}: an error without a place:\n{stderr}"
                );
            }
            other => panic!("retargeted chart {seed}: exit status {other:?}\n{stderr}\n{mutated}"),
        }
    }
    println!("retargeted jumps: {compiled} compiled, {refused} refused: {codes:?}");
    assert!(
        compiled > 10 && refused > 10,
        "{compiled} compiled, {refused} refused"
    );
}
