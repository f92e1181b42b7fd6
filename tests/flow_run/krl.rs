//! The KRL interpreter: statements, `IF`, `LOOP`/`EXIT`, `REPEAT`/`UNTIL`, `SWITCH`, `WAIT FOR`,
//! `WAIT SEC`, `$IN`/`$OUT`, `SIGNAL` groups, KRL's own operator precedence, and the timers
//! `$TIMER[k]` (milliseconds of the virtual clock of `flow_run.rs`), `$TIMER_STOP[k]`.

use std::collections::HashMap;

use crate::machine::{Timer, decimal};
use crate::{ACTION_MS, Io, Outcome, Phase, SIGNALS, STUCK_MS, TICK_MS};

/// What a KRL timer holds when the program starts: `$TIMER` keeps its value from before (here a
/// stopped 1000 s), so a timer read without its reset is noticed.
pub const TIMER_BEFORE_MS: i64 = 1_000_000;

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
    /// A decimal (`350.5`), in billionths.
    Real(i64),
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
    /// `WAIT SEC t` (milliseconds; `WAIT SEC 0` stops the advance run, no time).
    Sleep(i64),
    /// `$TIMER[k] = e`, `$TIMER_STOP[k] = e`.
    TimerSet(usize, KExpr),
    TimerStop(usize, KExpr),
}

/// `k` of `$TIMER[k]`-like text after the `[` (a KRL timer: 1 to 64).
fn timer_index(rest: &str) -> usize {
    let k: usize = rest
        .strip_suffix(']')
        .and_then(|k| k.trim().parse().ok())
        .unwrap_or_else(|| panic!("KRL: a timer `[{rest}`"));
    assert!((1..=64).contains(&k), "KRL: there is no $TIMER[{k}]");
    k
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
            // A decimal (`350.5`).
            if c[st..i].iter().all(char::is_ascii_digit)
                && c.get(i) == Some(&'.')
                && c.get(i + 1).is_some_and(char::is_ascii_digit)
            {
                i += 1;
                while i < c.len() && c[i].is_ascii_digit() {
                    i += 1;
                }
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
            _ if t.starts_with(|c: char| c.is_ascii_digit()) => KExpr::Real(decimal(&t)),
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
                let upper = rest.to_ascii_uppercase();
                if upper.starts_with("SEC ") {
                    out.push(Stmt::Sleep(decimal(rest[4..].trim()) / 1_000_000));
                } else {
                    assert!(upper.starts_with("FOR "), "KRL: `{c}`");
                    out.push(Stmt::Wait(kexpr(&rest[4..])));
                }
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
            _ if c.to_ascii_uppercase().starts_with("$TIMER") => {
                let (lhs, rhs) = c.split_once('=').unwrap_or_else(|| panic!("KRL: `{c}`"));
                let lhs = lhs.trim().to_ascii_uppercase();
                if let Some(k) = lhs.strip_prefix("$TIMER[") {
                    out.push(Stmt::TimerSet(timer_index(k), kexpr(rhs)));
                } else if let Some(k) = lhs.strip_prefix("$TIMER_STOP[") {
                    out.push(Stmt::TimerStop(timer_index(k), kexpr(rhs)));
                } else {
                    panic!("KRL: `{c}`");
                }
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
    /// A REAL, in billionths.
    R(i64),
    B(bool),
}

/// A number in billionths (an INT compared with a REAL).
fn billionths(v: KVal) -> Option<i128> {
    match v {
        KVal::I(i) => Some(i as i128 * 1_000_000_000),
        KVal::R(r) => Some(r as i128),
        KVal::B(_) => None,
    }
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
    /// The clock (milliseconds), the timers used so far, and how many times a timer was read
    /// (a condition that read none cannot change while the inputs do not).
    now: i64,
    timers: HashMap<usize, Timer>,
    time_reads: std::cell::Cell<usize>,
    /// The timed mode ([`krl_run_timed`]): a `WAIT FOR` reads its condition every `tick`
    /// milliseconds (the interpreter cycle), and the inputs change at a time (their bits).
    timed: Option<(i64, &'a crate::machine::Change, HashMap<String, bool>)>,
    /// When the action of the change began.
    change_at: Option<i64>,
}

enum Flow {
    Next,
    Exit,
    /// A GOTO to the label: out of every block, to the DEF's level.
    Goto(String),
    Stuck,
    Running,
}

impl<'a> Machine<'a> {
    /// A machine at its start: the `.dat`'s signals and values, the inputs of `seq`.
    fn new(dat: &str, seq: &'a [Phase], flicker: bool) -> Machine<'a> {
        let (signals, vars) = read_dat(dat);
        Machine {
            seq,
            flicker,
            reads: std::cell::Cell::new(0),
            bits: seq.iter().map(bits).collect(),
            actions: Vec::new(),
            vars,
            signals,
            steps: 0,
            visits: HashMap::new(),
            now: 0,
            timers: HashMap::new(),
            time_reads: std::cell::Cell::new(0),
            timed: None,
            change_at: None,
        }
    }

    fn bits(&self) -> &HashMap<String, bool> {
        if let (Some((_, ch, bits)), Some(at)) = (&self.timed, self.change_at)
            && self.now >= at + ch.delay
        {
            return bits;
        }
        if self.flicker {
            let r = self.reads.get();
            self.reads.set(r + 1);
            return &self.bits[r % self.seq.len()];
        }
        &self.bits[self.actions.len().min(self.seq.len() - 1)]
    }

    fn timer(&mut self, k: usize) -> &mut Timer {
        self.timers
            .entry(k)
            .or_insert(Timer::stopped(TIMER_BEFORE_MS))
    }

    fn eval(&self, e: &KExpr) -> KVal {
        match e {
            KExpr::Int(i) => KVal::I(*i),
            KExpr::Real(r) => KVal::R(*r),
            KExpr::Bool(b) => KVal::B(*b),
            KExpr::Sys(s) if s.starts_with("$TIMER[") => {
                self.time_reads.set(self.time_reads.get() + 1);
                let k = timer_index(&s[7..]);
                let t = self
                    .timers
                    .get(&k)
                    .copied()
                    .unwrap_or(Timer::stopped(TIMER_BEFORE_MS));
                KVal::I(t.read(self.now))
            }
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
                KVal::R(r) => KVal::R(-r),
                v => panic!("- of {v:?}"),
            },
            KExpr::Bin(op, a, b) => {
                let (x, y) = (self.eval(a), self.eval(b));
                if matches!(x, KVal::R(_)) || matches!(y, KVal::R(_)) {
                    let (Some(x), Some(y)) = (billionths(x), billionths(y)) else {
                        panic!("KRL type error: {x:?} {op} {y:?}");
                    };
                    return KVal::B(match op.as_str() {
                        "==" => x == y,
                        "<>" => x != y,
                        "<" => x < y,
                        ">" => x > y,
                        "<=" => x <= y,
                        ">=" => x >= y,
                        _ => panic!("KRL type error: {x:?} {op} {y:?}"),
                    });
                }
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
                    if self.actions.len() >= crate::max_actions() {
                        return Flow::Running;
                    }
                    if let Some((_, ch, _)) = &self.timed
                        && ch.after == *name
                        && self.change_at.is_none()
                    {
                        self.change_at = Some(self.now);
                    }
                    self.actions.push(name.clone());
                    self.now += ACTION_MS;
                    Flow::Next
                }
                Stmt::Wait(c) => {
                    // Inputs change only when the robot acts: a false condition that read no
                    // timer stays false; one that read a timer is read again every tick, until
                    // it has waited STUCK_MS.
                    let since = self.now;
                    loop {
                        let reads = self.time_reads.get();
                        if self.truth(c) {
                            break Flow::Next;
                        }
                        if self.time_reads.get() == reads || self.now - since >= STUCK_MS {
                            break Flow::Stuck;
                        }
                        self.now += self.timed.as_ref().map_or(TICK_MS, |t| t.0);
                    }
                }
                Stmt::Sleep(ms) => {
                    self.now += ms;
                    Flow::Next
                }
                Stmt::TimerSet(k, e) => {
                    let v = match self.eval(e) {
                        KVal::I(i) => i,
                        v => panic!("KRL: $TIMER[{k}] = {v:?}"),
                    };
                    let now = self.now;
                    self.timer(*k).set(v, now);
                    Flow::Next
                }
                Stmt::TimerStop(k, e) => {
                    let now = self.now;
                    match self.eval(e) {
                        KVal::B(true) => self.timer(*k).stop(now),
                        KVal::B(false) => self.timer(*k).start(now),
                        v => panic!("KRL: $TIMER_STOP[{k}] = {v:?}"),
                    }
                    Flow::Next
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
                        KVal::R(_) => panic!("KRL: a REAL into the INT {n}"),
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
            // A single bit (a cell's wire, `SIGNAL From_A_1 $IN[41]`): the co-simulation puts
            // the bit in its name's place (`cosim::krl_signals`).
            if w.len() == 3 {
                continue;
            }
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
    let (actions, outcome, _) = krl_run_clocked(program, dat, seq, flicker);
    (actions, outcome)
}

/// [`krl_run_with`], and the clock at the end (milliseconds).
fn krl_run_clocked(
    program: &[Stmt],
    dat: &str,
    seq: &[Phase],
    flicker: bool,
) -> (Vec<String>, Outcome, i64) {
    let mut m = Machine::new(dat, seq, flicker);
    let outcome = match m.run(program) {
        Flow::Next => Outcome::Done,
        Flow::Exit => panic!("EXIT outside a loop"),
        Flow::Stuck => Outcome::Stuck,
        Flow::Running => Outcome::Running,
        Flow::Goto(l) => panic!("GOTO {l}: no label it may go to"),
    };
    (m.actions, outcome, m.now)
}

/// [`krl_run_with`] in timed mode: the inputs of `seq`'s first phase, changed as `change`
/// says at its time; a `WAIT FOR` reads its condition every `tick` milliseconds.
pub fn krl_run_timed(
    program: &[Stmt],
    dat: &str,
    seq: &[Phase],
    tick: i64,
    change: &crate::machine::Change,
) -> Vec<String> {
    let mut m = Machine::new(dat, seq, false);
    m.timed = Some((tick, change, bits(&change.phase)));
    m.run(program);
    m.actions
}

/// The interpreter itself: KRL's precedence is not ST's, so a condition without the emitted
/// parentheses would mean something else (or not type-check).
#[test]
fn the_interpreter_uses_krl_precedence() {
    let phase: Phase = [("Part_OK", 1), ("Release", 0), ("Variant", 3)]
        .into_iter()
        .collect();
    let seq = vec![phase];
    let mut m = Machine::new("", &seq, false);
    m.signals = [("V".to_owned(), (9, 12))].into_iter().collect();
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

/// Time: an action takes `ACTION_MS`; `WAIT SEC 0` none; `$TIMER[k] = 0` sets a timer's start
/// to now and `$TIMER_STOP[k] = FALSE` starts it (`TRUE` stops it); a `WAIT FOR` (also the
/// selection's, in its `REPEAT`) that reads a timer is read again every tick until it holds, or
/// is stuck after `STUCK_MS`; one that reads no timer is stuck at once. The same chart as the
/// player's test (`chart::the_player_keeps_time`), the same times.
#[test]
fn the_interpreter_keeps_time() {
    let src = "DEF t( )\n;step time of A\nWAIT SEC 0\n$TIMER[16] = 0\n$TIMER_STOP[16] = FALSE\n;FOLD 1 A: x\n;ENDFOLD\nWAIT FOR ($TIMER[16] > 350)\nWAIT SEC 0\n$TIMER[15] = 0\n$TIMER_STOP[15] = FALSE\n;FOLD 2 B: x\n;ENDFOLD\nX = 0\nREPEAT\n  WAIT FOR (($TIMER[15] < 150) AND $IN[1]) OR (($TIMER[15] > 1000.5) OR $IN[3])\n  IF ($TIMER[15] < 150) AND $IN[1] THEN\n    X = 1\n  ELSE\n    IF ($TIMER[15] > 1000.5) OR $IN[3] THEN\n      X = 2\n    ENDIF\n  ENDIF\nUNTIL X <> 0\nSWITCH X\nCASE 1\n;FOLD 3 C: x\n;ENDFOLD\nDEFAULT\n;FOLD 4 D: x\n;ENDFOLD\nENDSWITCH\nWAIT SEC 0\n$TIMER[1] = 0\n$TIMER_STOP[1] = FALSE\n;FOLD 5 E: x\n;ENDFOLD\nWAIT FOR $TIMER[1] < 50\nEND\n";
    let program = parse_program(src);
    let run = |part: i64, release: i64| {
        let p: Phase = [("Part_OK", part), ("Release", release)]
            .into_iter()
            .collect();
        krl_run_clocked(&program, "DECL INT X=0\n", &[p], false)
    };
    let out = |a: &[&str], t| (a.iter().map(|s| s.to_string()).collect(), Outcome::Stuck, t);
    assert_eq!(run(0, 0), out(&["A", "B", "D", "E"], 11_570));
    assert_eq!(run(1, 0), out(&["A", "B", "C", "E"], 10_660));
    assert_eq!(run(0, 1), out(&["A", "B", "D", "E"], 10_660));
    // A stopped timer keeps its value; one never set holds what it held before the program; a
    // wait on the inputs alone is stuck at once.
    let src = "DEF t( )\n$TIMER[5] = 0\n$TIMER_STOP[5] = FALSE\n;FOLD 1 A: x\n;ENDFOLD\n$TIMER_STOP[5] = TRUE\n;FOLD 2 B: x\n;ENDFOLD\nWAIT FOR $TIMER[5] == 100\nWAIT FOR $TIMER[64] == 1000000\nWAIT FOR $IN[1]\nEND\n";
    let program = parse_program(src);
    let p: Phase = [("Part_OK", 0)].into_iter().collect();
    assert_eq!(
        krl_run_clocked(&program, "", &[p], false),
        (vec!["A".to_owned(), "B".to_owned()], Outcome::Stuck, 200)
    );
    let bad = std::panic::catch_unwind(|| parse_program("DEF t( )\n$TIMER[65] = 0\nEND\n"));
    assert!(bad.is_err(), "there is no $TIMER[65]");
}
