//! The statement tree and the machine that runs RAPID and URScript programs (their parsers are
//! `rapid.rs` and `urscript.rs`): steps, waits, `IF`/`ELSEIF`/`ELSE` chains, `WHILE` loops,
//! `break`, assignments to program variables, typed values (a boolean is no number: what a
//! missing parenthesis often causes is a type error, and the machine panics on it).
//!
//! Time (the model of `flow_run.rs`): a step's action takes [`ACTION_MS`], a wait whose
//! condition is false reads it again every [`TICK_MS`] until it holds or is stuck; nothing else
//! takes time. RAPID's clocks (`ClkReset`, `ClkStart`, `ClkRead`) and URScript's step-time
//! counters (variables a `thread` advances by `get_steptime()`) follow the clock.

use std::collections::HashMap;

use crate::{ACTION_MS, Outcome, Phase, SIGNALS, STUCK_MS, TICK_MS};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Op {
    Or,
    Xor,
    And,
    Eq,
    Ne,
    Lt,
    Gt,
    Le,
    Ge,
}

#[derive(Debug, Clone)]
pub enum Expr {
    Int(i64),
    /// A decimal number (`0.35`), in billionths.
    Real(i64),
    Bool(bool),
    /// RAPID's `ClkRead(clock)`: the clock's seconds.
    ClkRead(String),
    /// A program variable.
    Var(String),
    /// A signal: its index in [`SIGNALS`].
    Signal(usize),
    Not(Box<Expr>),
    Neg(Box<Expr>),
    Bin(Op, Box<Expr>, Box<Expr>),
}

#[derive(Debug, Clone)]
pub enum Stmt {
    /// A step's title line (`! step 2 Grip: …`, `# step 2 Grip: …`): the step's name.
    Step(String),
    /// RAPID's `WaitUntil c;` with the milliseconds between its reads (`\PollRate`; 100
    /// without, RAPID's default), URScript's `while not (c): sync() end` (`None`: every control
    /// cycle). Only the timed mode reads at these rates ([`run_timed`]).
    Wait(Expr, Option<i64>),
    /// RAPID's `WaitTime \InPos, 0;` (the robot stands still: no time here), `WaitTime t;`:
    /// milliseconds.
    Sleep(i64),
    /// RAPID's `ClkReset c;`, `ClkStart c;`, `ClkStop c;`.
    ClkReset(String),
    ClkStart(String),
    ClkStop(String),
    /// URScript's `x = run skp_clock()`: the thread that advances the step-time counters
    /// ([`Program::counters`]) starts.
    RunCounters,
    /// `IF`/`ELSEIF` conditions and bodies, then the `ELSE` body.
    If(Vec<(Expr, Vec<Stmt>)>, Vec<Stmt>),
    While(Expr, Vec<Stmt>),
    /// URScript's `break`.
    Break,
    Assign(String, Expr),
    /// URScript's `sync()` outside a wait (a branch without steps): no time in the model.
    Sync,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Val {
    I(i64),
    /// A decimal number, in billionths (a clock's seconds, URScript's `0.35`).
    R(i64),
    B(bool),
}

/// A number in billionths, for comparisons of integers with decimals.
fn billionths(v: Val) -> Option<i128> {
    match v {
        Val::I(i) => Some(i as i128 * 1_000_000_000),
        Val::R(r) => Some(r as i128),
        Val::B(_) => None,
    }
}

/// A decimal literal (`0.35`, `350.5`, `12`) in billionths.
pub fn decimal(text: &str) -> i64 {
    let (whole, part) = text.split_once('.').unwrap_or((text, ""));
    assert!(
        part.len() <= 9
            && !whole.is_empty()
            && (whole.bytes().chain(part.bytes())).all(|c| c.is_ascii_digit()),
        "not a decimal: `{text}`"
    );
    let part = format!("{part:0<9}");
    whole.parse::<i64>().unwrap() * 1_000_000_000 + part.parse::<i64>().unwrap()
}

/// A timer of the virtual clock (KRL's `$TIMER[k]`, RAPID's `clock`), in milliseconds: its
/// value when it was last set or stopped, and since when it runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Timer {
    at: i64,
    since: Option<i64>,
}

impl Timer {
    /// A timer stopped at `ms`.
    pub fn stopped(ms: i64) -> Timer {
        Timer {
            at: ms,
            since: None,
        }
    }

    pub fn read(&self, now: i64) -> i64 {
        self.at + self.since.map_or(0, |s| now - s)
    }

    /// Sets the value (a running timer runs on from it).
    pub fn set(&mut self, ms: i64, now: i64) {
        self.at = ms;
        if self.since.is_some() {
            self.since = Some(now);
        }
    }

    /// Starts it (a running timer runs on).
    pub fn start(&mut self, now: i64) {
        if self.since.is_none() {
            self.since = Some(now);
        }
    }

    pub fn stop(&mut self, now: i64) {
        self.at = self.read(now);
        self.since = None;
    }
}

/// A parsed program.
#[derive(Debug, Clone)]
pub struct Program {
    pub body: Vec<Stmt>,
    /// Declared variables and their initial values (RAPID); `None`: variables come into being
    /// when assigned (URScript).
    pub declared: Option<HashMap<String, Val>>,
    /// A boolean signal reads as the number 0 or 1 (RAPID's `di_Part = 1`), else as a boolean.
    pub bits_are_numbers: bool,
    /// RAPID: the declared clocks.
    pub clocks: Vec<String>,
    /// URScript: the variables a thread advances by `get_steptime()` each control cycle (the
    /// step-time counters), when it has been started ([`Stmt::RunCounters`]).
    pub counters: Vec<String>,
}

enum Flow {
    Next,
    Break,
    Stuck,
    Running,
}

/// Inputs that change at a time: `phase` holds from `delay` milliseconds after the action
/// `after` began (its step became active) on, in place of the sequence's.
#[derive(Debug, Clone)]
pub struct Change {
    pub after: String,
    pub delay: i64,
    pub phase: Phase,
}

struct Machine<'a> {
    program: &'a Program,
    seq: &'a [Phase],
    /// The timed mode ([`run_timed`]): a wait reads its condition every `tick` (RAPID: its
    /// `\PollRate`, else 100 ms), and the inputs change at a time.
    timed: Option<(i64, &'a Change)>,
    /// When the action of the change began.
    change_at: Option<i64>,
    flicker: bool,
    reads: std::cell::Cell<usize>,
    actions: Vec<String>,
    vars: HashMap<String, Val>,
    /// Assignments that changed a variable (the step-time counters' advance is none).
    changes: usize,
    steps: usize,
    /// The clock (milliseconds), RAPID's clocks, whether URScript's counters run, and how
    /// many times a time was read (a condition that read none cannot change while the inputs
    /// do not).
    now: i64,
    clocks: HashMap<String, Timer>,
    counting: bool,
    time_reads: std::cell::Cell<usize>,
}

/// How many rounds without an action or a change a loop may run with flickering inputs.
const IDLE_ROUNDS: usize = 64;

impl<'a> Machine<'a> {
    fn new(program: &'a Program, seq: &'a [Phase], flicker: bool) -> Machine<'a> {
        Machine {
            program,
            seq,
            timed: None,
            change_at: None,
            flicker,
            reads: std::cell::Cell::new(0),
            actions: Vec::new(),
            vars: program.declared.clone().unwrap_or_default(),
            changes: 0,
            steps: 0,
            now: 0,
            // A clock declared in the routine starts stopped at 0.
            clocks: program
                .clocks
                .iter()
                .map(|c| (c.clone(), Timer::stopped(0)))
                .collect(),
            counting: false,
            time_reads: std::cell::Cell::new(0),
        }
    }

    fn phase(&self) -> &Phase {
        if let (Some((_, ch)), Some(at)) = (self.timed, self.change_at)
            && self.now >= at + ch.delay
        {
            return &ch.phase;
        }
        if self.flicker {
            let r = self.reads.get();
            self.reads.set(r + 1);
            return &self.seq[r % self.seq.len()];
        }
        &self.seq[self.actions.len().min(self.seq.len() - 1)]
    }

    /// Time passes: URScript's counters advance (RAPID's clocks follow [`Machine::now`]).
    fn advance(&mut self, ms: i64) {
        self.now += ms;
        if self.counting {
            for c in &self.program.counters {
                match self.vars.get_mut(c) {
                    Some(Val::R(r)) => *r += ms * 1_000_000,
                    other => panic!("the counter `{c}` is {other:?}"),
                }
            }
        }
    }

    fn clock(&mut self, c: &str) -> &mut Timer {
        self.clocks
            .get_mut(c)
            .unwrap_or_else(|| panic!("RAPID: `{c}` is no declared clock"))
    }

    fn eval(&self, e: &Expr) -> Val {
        match e {
            Expr::Int(i) => Val::I(*i),
            Expr::Real(r) => Val::R(*r),
            Expr::Bool(b) => Val::B(*b),
            Expr::ClkRead(c) => {
                self.time_reads.set(self.time_reads.get() + 1);
                let t = self
                    .clocks
                    .get(c)
                    .unwrap_or_else(|| panic!("RAPID: `{c}` is no declared clock"));
                Val::R(t.read(self.now) * 1_000_000)
            }
            Expr::Var(n) => {
                if self.program.counters.contains(n) {
                    self.time_reads.set(self.time_reads.get() + 1);
                }
                *self
                    .vars
                    .get(n)
                    .unwrap_or_else(|| panic!("`{n}` is read before it has a value"))
            }
            Expr::Signal(k) => {
                let s = &SIGNALS[*k];
                let v = self.phase().get(s.name).copied().unwrap_or(0);
                if s.integer || self.program.bits_are_numbers {
                    Val::I(v)
                } else {
                    Val::B(v != 0)
                }
            }
            Expr::Not(a) => match self.eval(a) {
                Val::B(b) => Val::B(!b),
                v => panic!("type error: NOT of {v:?}"),
            },
            Expr::Neg(a) => match self.eval(a) {
                Val::I(i) => Val::I(-i),
                Val::R(r) => Val::R(-r),
                v => panic!("type error: - of {v:?}"),
            },
            Expr::Bin(op, a, b) => {
                let (x, y) = (self.eval(a), self.eval(b));
                if matches!(x, Val::R(_)) || matches!(y, Val::R(_)) {
                    let (Some(x), Some(y)) = (billionths(x), billionths(y)) else {
                        panic!("type error: {x:?} {op:?} {y:?}");
                    };
                    return Val::B(match op {
                        Op::Eq => x == y,
                        Op::Ne => x != y,
                        Op::Lt => x < y,
                        Op::Gt => x > y,
                        Op::Le => x <= y,
                        Op::Ge => x >= y,
                        _ => panic!("type error: {x:?} {op:?} {y:?}"),
                    });
                }
                Val::B(match (op, x, y) {
                    (Op::And, Val::B(x), Val::B(y)) => x && y,
                    (Op::Or, Val::B(x), Val::B(y)) => x || y,
                    (Op::Xor, Val::B(x), Val::B(y)) => x != y,
                    (Op::Eq, Val::I(x), Val::I(y)) => x == y,
                    (Op::Eq, Val::B(x), Val::B(y)) => x == y,
                    (Op::Ne, Val::I(x), Val::I(y)) => x != y,
                    (Op::Ne, Val::B(x), Val::B(y)) => x != y,
                    (Op::Lt, Val::I(x), Val::I(y)) => x < y,
                    (Op::Gt, Val::I(x), Val::I(y)) => x > y,
                    (Op::Le, Val::I(x), Val::I(y)) => x <= y,
                    (Op::Ge, Val::I(x), Val::I(y)) => x >= y,
                    _ => panic!("type error: {x:?} {op:?} {y:?}"),
                })
            }
        }
    }

    fn truth(&self, e: &Expr) -> bool {
        match self.eval(e) {
            Val::B(b) => b,
            v => panic!("a condition evaluated to {v:?}"),
        }
    }

    fn run(&mut self, stmts: &[Stmt]) -> Flow {
        for s in stmts {
            self.steps += 1;
            assert!(self.steps < 1_000_000, "the interpreter runs away");
            let f = match s {
                Stmt::Step(name) => {
                    if self.actions.len() >= crate::max_actions() {
                        return Flow::Running;
                    }
                    if let Some((_, ch)) = self.timed
                        && ch.after == *name
                        && self.change_at.is_none()
                    {
                        self.change_at = Some(self.now);
                    }
                    self.actions.push(name.clone());
                    self.advance(ACTION_MS);
                    Flow::Next
                }
                Stmt::Sync => Flow::Next,
                Stmt::Sleep(ms) => {
                    self.advance(*ms);
                    Flow::Next
                }
                Stmt::ClkReset(c) => {
                    let now = self.now;
                    self.clock(c).set(0, now);
                    Flow::Next
                }
                Stmt::ClkStart(c) => {
                    let now = self.now;
                    self.clock(c).start(now);
                    Flow::Next
                }
                Stmt::ClkStop(c) => {
                    let now = self.now;
                    self.clock(c).stop(now);
                    Flow::Next
                }
                Stmt::RunCounters => {
                    assert!(!self.counting, "URScript: the counters' thread runs twice");
                    self.counting = true;
                    Flow::Next
                }
                Stmt::Wait(c, poll) => {
                    let tick = match self.timed {
                        Some((tick, _)) => poll.unwrap_or(tick),
                        None => TICK_MS,
                    };
                    // Inputs change only when the robot acts: a false condition that read no
                    // time stays false; one that read a time is read again every tick, until
                    // it has waited STUCK_MS. Flickering inputs: read again a while.
                    let tries = if self.flicker {
                        2 * self.seq.len() + 1
                    } else {
                        1
                    };
                    let since = self.now;
                    let mut tried = 0;
                    loop {
                        let reads = self.time_reads.get();
                        if self.truth(c) {
                            break Flow::Next;
                        }
                        tried += 1;
                        let timed = self.time_reads.get() > reads;
                        if (!timed && tried >= tries) || (timed && self.now - since >= STUCK_MS) {
                            break Flow::Stuck;
                        }
                        self.advance(tick);
                    }
                }
                Stmt::If(arms, otherwise) => {
                    let body = arms
                        .iter()
                        .find(|(c, _)| self.truth(c))
                        .map_or(otherwise, |(_, b)| b);
                    self.run(body)
                }
                Stmt::While(c, body) => {
                    let mut idle = 0;
                    let mut idle_since = self.now;
                    loop {
                        let (start, reads) = (self.now, self.time_reads.get());
                        if !self.truth(c) {
                            break Flow::Next;
                        }
                        let before = (self.actions.len(), self.changes);
                        match self.run(body) {
                            Flow::Next => {}
                            Flow::Break => break Flow::Next,
                            other => break other,
                        }
                        if (self.actions.len(), self.changes) != before {
                            idle = 0;
                            idle_since = self.now;
                        } else if self.time_reads.get() > reads && self.now > start {
                            // A round that waited and read a time: a wait, stuck after
                            // STUCK_MS.
                            if self.now - idle_since > STUCK_MS {
                                break Flow::Stuck;
                            }
                        } else {
                            // A round without an action and without a change: with inputs
                            // that change only when the robot acts, it never ends.
                            idle += 1;
                            if !self.flicker || idle > IDLE_ROUNDS {
                                break Flow::Stuck;
                            }
                        }
                    }
                }
                Stmt::Break => Flow::Break,
                Stmt::Assign(n, e) => {
                    let v = self.eval(e);
                    let old = match &self.program.declared {
                        Some(d) => Some(
                            *d.get(n)
                                .unwrap_or_else(|| panic!("assignment to undeclared `{n}`")),
                        ),
                        None => self.vars.get(n).copied(),
                    };
                    if let Some(old) = old {
                        assert_eq!(
                            std::mem::discriminant(&old),
                            std::mem::discriminant(&v),
                            "`{n}` changes its type: {old:?} := {v:?}"
                        );
                    }
                    if self.vars.insert(n.clone(), v) != Some(v) {
                        self.changes += 1;
                    }
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

/// Runs `program` under the input sequence `seq` (`flicker`: the inputs change at every read).
pub fn run(program: &Program, seq: &[Phase], flicker: bool) -> (Vec<String>, Outcome) {
    let (actions, outcome, _) = run_clocked(program, seq, flicker);
    (actions, outcome)
}

/// [`run`] in timed mode: the inputs of `seq`'s first phase, changed as `change` says at its
/// time; a wait reads its condition every `tick` milliseconds (URScript: its control cycle),
/// RAPID's at its `\PollRate` (100 ms without one, RAPID's default).
pub fn run_timed(program: &Program, seq: &[Phase], tick: i64, change: &Change) -> Vec<String> {
    let mut m = Machine::new(program, seq, false);
    m.timed = Some((tick, change));
    m.run(&program.body);
    m.actions
}

/// [`run`], and the clock at the end (milliseconds).
pub fn run_clocked(program: &Program, seq: &[Phase], flicker: bool) -> (Vec<String>, Outcome, i64) {
    let mut m = Machine::new(program, seq, flicker);
    let outcome = match m.run(&program.body) {
        Flow::Next => Outcome::Done,
        Flow::Break => panic!("`break` outside a loop"),
        Flow::Stuck => Outcome::Stuck,
        Flow::Running => Outcome::Running,
    };
    (m.actions, outcome, m.now)
}

/// The step name in a step title's text after `step ` (`2 Grip: Move LIN @ …` → `Grip`).
pub fn step_name(title: &str) -> String {
    let mut words = title.split_whitespace();
    assert!(
        words.next().is_some_and(|n| n.parse::<usize>().is_ok()),
        "a step title without its number: `{title}`"
    );
    words
        .next()
        .expect("a step name")
        .trim_end_matches(':')
        .to_owned()
}

/// Splits an expression into tokens: names, numbers (`12`, `0.35`), the operators in `ops` (longest first),
/// parentheses and commas.
pub fn tokens(s: &str, ops: &[&str]) -> Vec<String> {
    let b = s.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c.is_ascii_whitespace() {
            i += 1;
        } else if c.is_ascii_alphanumeric() || c == b'_' {
            let st = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            // A decimal number (`0.35`).
            if b[st..i].iter().all(u8::is_ascii_digit)
                && b.get(i) == Some(&b'.')
                && b.get(i + 1).is_some_and(u8::is_ascii_digit)
            {
                i += 1;
                while i < b.len() && b[i].is_ascii_digit() {
                    i += 1;
                }
            }
            out.push(s[st..i].to_owned());
        } else if let Some(op) = ops.iter().find(|o| s[i..].starts_with(**o)) {
            out.push((*op).to_owned());
            i += op.len();
        } else if c == b'(' || c == b')' || c == b',' {
            out.push((c as char).to_string());
            i += 1;
        } else {
            panic!("unexpected character `{}` in `{s}`", c as char);
        }
    }
    out
}

/// The truth of `e` under `phase` (tests of the readers).
pub fn truth(e: &Expr, phase: &Phase, bits_are_numbers: bool) -> bool {
    let program = Program {
        body: Vec::new(),
        declared: None,
        bits_are_numbers,
        clocks: Vec::new(),
        counters: Vec::new(),
    };
    let seq = [phase.clone()];
    Machine::new(&program, &seq, false).truth(e)
}
