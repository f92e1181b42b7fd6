//! The statement tree and the machine that runs RAPID and URScript programs (their parsers are
//! `rapid.rs` and `urscript.rs`): steps, waits, `IF`/`ELSEIF`/`ELSE` chains, `WHILE` loops,
//! `break`, assignments to program variables, typed values (a boolean is no number: what a
//! missing parenthesis often causes is a type error, and the machine panics on it).

use std::collections::HashMap;

use crate::{MAX_ACTIONS, Outcome, Phase, SIGNALS};

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
    Bool(bool),
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
    /// RAPID's `WaitUntil c;`.
    Wait(Expr),
    /// `IF`/`ELSEIF` conditions and bodies, then the `ELSE` body.
    If(Vec<(Expr, Vec<Stmt>)>, Vec<Stmt>),
    While(Expr, Vec<Stmt>),
    /// URScript's `break`.
    Break,
    Assign(String, Expr),
    /// URScript's `sync()`: waits a control cycle.
    Sync,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Val {
    I(i64),
    B(bool),
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
}

enum Flow {
    Next,
    Break,
    Stuck,
    Running,
}

struct Machine<'a> {
    program: &'a Program,
    seq: &'a [Phase],
    flicker: bool,
    reads: std::cell::Cell<usize>,
    actions: Vec<String>,
    vars: HashMap<String, Val>,
    steps: usize,
}

/// How many rounds without an action or a change a loop may run with flickering inputs.
const IDLE_ROUNDS: usize = 64;

impl Machine<'_> {
    fn phase(&self) -> &Phase {
        if self.flicker {
            let r = self.reads.get();
            self.reads.set(r + 1);
            return &self.seq[r % self.seq.len()];
        }
        &self.seq[self.actions.len().min(self.seq.len() - 1)]
    }

    fn eval(&self, e: &Expr) -> Val {
        match e {
            Expr::Int(i) => Val::I(*i),
            Expr::Bool(b) => Val::B(*b),
            Expr::Var(n) => *self
                .vars
                .get(n)
                .unwrap_or_else(|| panic!("`{n}` is read before it has a value")),
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
                v => panic!("type error: - of {v:?}"),
            },
            Expr::Bin(op, a, b) => {
                let (x, y) = (self.eval(a), self.eval(b));
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
                    if self.actions.len() >= MAX_ACTIONS {
                        return Flow::Running;
                    }
                    self.actions.push(name.clone());
                    Flow::Next
                }
                Stmt::Sync => Flow::Next,
                Stmt::Wait(c) => {
                    // Inputs change only when the robot acts: a false condition stays false.
                    // Flickering inputs: read again a while.
                    let tries = if self.flicker {
                        2 * self.seq.len() + 1
                    } else {
                        1
                    };
                    if (0..tries).any(|_| self.truth(c)) {
                        Flow::Next
                    } else {
                        Flow::Stuck
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
                    loop {
                        if !self.truth(c) {
                            break Flow::Next;
                        }
                        let before = (self.actions.len(), self.vars.clone());
                        match self.run(body) {
                            Flow::Next => {}
                            Flow::Break => break Flow::Next,
                            other => break other,
                        }
                        if self.actions.len() == before.0 && self.vars == before.1 {
                            // A round without an action and without a change: with inputs
                            // that change only when the robot acts, it never ends.
                            idle += 1;
                            if !self.flicker || idle > IDLE_ROUNDS {
                                break Flow::Stuck;
                            }
                        } else {
                            idle = 0;
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

/// Runs `program` under the input sequence `seq` (`flicker`: the inputs change at every read).
pub fn run(program: &Program, seq: &[Phase], flicker: bool) -> (Vec<String>, Outcome) {
    let mut m = Machine {
        program,
        seq,
        flicker,
        reads: std::cell::Cell::new(0),
        actions: Vec::new(),
        vars: program.declared.clone().unwrap_or_default(),
        steps: 0,
    };
    let outcome = match m.run(&program.body) {
        Flow::Next => Outcome::Done,
        Flow::Break => panic!("`break` outside a loop"),
        Flow::Stuck => Outcome::Stuck,
        Flow::Running => Outcome::Running,
    };
    (m.actions, outcome)
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

/// Splits an expression into tokens: names, numbers, the operators in `ops` (longest first),
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
    };
    let seq = [phase.clone()];
    let m = Machine {
        program: &program,
        seq: &seq,
        flicker: false,
        reads: std::cell::Cell::new(0),
        actions: Vec::new(),
        vars: HashMap::new(),
        steps: 0,
    };
    m.truth(e)
}
