//! The program-tree writer of the languages with `IF`/`ELSEIF`/`ELSE` chains and `WHILE` loops:
//! RAPID and URScript. A [`Dialect`] gives the keywords; the structure is the same:
//!
//! - a step: a comment line `step n …`, then its code;
//! - a guarded transition: the dialect's wait;
//! - simultaneous branches: one after another;
//! - a selection with an unconditional branch: `if c1 … elif c2 … else` (that branch) `end`;
//!   without one: the branch is chosen first into `skp_branch` (waiting for any condition,
//!   testing again if none holds any more), then run by an `if` chain on it;
//! - a loop: `while true` left by the dialect's way ([`Leave`]).

use super::flow::{self, Lines};
use super::{EmitInput, Generated};
use crate::cond::{BinOp, Ops};
use crate::plan::{Block, Branch, BranchEnd};

/// The variable that holds the branch a selection without an unconditional branch chose.
pub const BRANCH_VAR: &str = "skp_branch";

/// The variable that holds the state a [`Block::Machine`] goes on at (0: none, the program
/// ends).
pub const STATE_VAR: &str = "skp_state";

/// How a dialect leaves a loop.
#[derive(Debug)]
pub enum Leave {
    /// A statement that leaves the innermost loop (`break`).
    Statement(&'static str),
    /// A flag per loop (`skp_loopN`): the loop runs while it holds, a leaving branch clears it,
    /// and what follows a block that may leave runs only while it holds (RAPID has no `EXIT`
    /// from a `WHILE` that `rapidchecker` accepts, and no labels).
    Flag,
}

/// A dialect's step timers: their declarations, and the lines (with their levels) before the
/// first step.
pub type TimerLines = (Vec<String>, Vec<(usize, String)>);

/// One language's words for the structure.
#[derive(Debug)]
pub struct Dialect {
    pub ops: &'static Ops,
    /// Starts a comment (`!`, `#`).
    pub comment: &'static str,
    /// `(before, after)` a condition.
    pub if_: (&'static str, &'static str),
    pub elif: (&'static str, &'static str),
    pub else_: &'static str,
    pub end_if: &'static str,
    pub while_: (&'static str, &'static str),
    pub end_while: &'static str,
    /// `(between, after)` in an assignment (` := `, `;`).
    pub assign: (&'static str, &'static str),
    /// The equality operator with its spaces.
    pub equals: &'static str,
    /// Writes a wait for the condition.
    pub wait: fn(&mut Lines, usize, &str),
    /// What makes the robot stand before a selection with an unconditional branch is decided
    /// (`None`: the motion commands return only when the motion has ended).
    pub settle: Option<&'static str>,
    pub leave: Leave,
    /// A statement for a branch that would hold no statement (`None`: an empty block is fine).
    pub empty_block: Option<&'static str>,
    /// The declarations of the variables used: whether `skp_branch` was, how many loop flags,
    /// whether [`STATE_VAR`] was.
    pub declare: fn(bool, usize, bool) -> Vec<String>,
    /// For `n` step timers, and whether the waits on partners are watched (a program of a
    /// cell, [`crate::bind::Watch`]): their declarations, and the lines (with their levels)
    /// that start the program before its first step.
    pub timers: fn(usize, bool) -> TimerLines,
}

/// Writes the program tree in `dialect`; a cell's wires the language cannot use go into
/// `diags` (`E209`).
pub fn generate(
    input: &EmitInput,
    dialect: &Dialect,
    diags: &mut crate::diag::Diagnostics,
) -> Option<Generated> {
    let tools = super::tool::Tools::new(input, diags);
    let points = super::points::for_program(input, &tools, diags)?;
    let mut w = Writer {
        points,
        input,
        tools,
        d: dialect,
        out: Lines::new(input, flow::steps_estimate(input)),
        number: 0,
        uses_branch_var: false,
        flags: 0,
        loops: Vec::new(),
        hand: super::handshake::Hand::new(input),
        states: None,
        uses_state_var: false,
    };
    let (timer_declarations, prologue) =
        match (input.bound.timers.len(), input.bound.watch.is_some()) {
            (0, false) => (Vec::new(), Vec::new()),
            (n, watched) => (dialect.timers)(n, watched),
        };
    for (level, line) in &prologue {
        w.out.line(*level, line);
    }
    if let Some(h) = &w.hand {
        h.check(diags);
        h.init(&mut super::handshake::At::new(&mut w.out, 0));
    }
    // Each top-level block's start, and the end: where the program may be split. (At the top
    // level no loop is open and no state, so `sequence` puts no block under another.)
    let mut cuts = Vec::with_capacity(input.body.len() + 1);
    for b in input.body {
        cuts.push(w.out.out.len());
        w.block(b, 0);
    }
    cuts.push(w.out.out.len());
    if let Some(h) = &w.hand {
        h.finish(&mut super::handshake::At::new(&mut w.out, 0));
    }
    let mut declarations = (dialect.declare)(w.uses_branch_var, w.flags, w.uses_state_var);
    declarations.extend(timer_declarations);
    if let Some(h) = &w.hand {
        declarations.extend(h.declarations());
    }
    Some(Generated {
        steps: w.out.out,
        declarations,
        routines: Vec::new(),
        data: {
            let mut data = w.tools.data;
            data.append(&mut w.points.declarations);
            data
        },
        cuts,
        point_cuts: Vec::new(),
    })
}

/// Whether `b` leaves the loop it stands in (a branch ending in a leave, not inside a nested
/// loop, whose leaves are that loop's).
fn may_leave(b: &Block) -> bool {
    match b {
        Block::Choice { branches, .. } | Block::Follow { branches, .. } => branches
            .iter()
            .any(|br| br.end == BranchEnd::Leave || br.body.iter().any(may_leave)),
        Block::Parallel { branches, .. } | Block::Sequences(branches) => {
            branches.iter().flatten().any(may_leave)
        }
        Block::Step(_)
        | Block::Wait(_)
        | Block::Loop { .. }
        | Block::Tell(_)
        | Block::Hear(_)
        | Block::Goto { .. }
        | Block::Machine(_) => false,
    }
}

/// Whether `b` goes to another state somewhere (a [`Block::Goto`], loops included; not one
/// inside a nested machine, which goes to that machine's own states).
fn may_goto(b: &Block) -> bool {
    let mut targets = Vec::new();
    crate::plan::gotos(std::slice::from_ref(b), &mut targets);
    !targets.is_empty()
}

/// The states of the [`Block::Machine`] being written: each entry's number (from 1), and how
/// many loops were open when the state began (the loops a Goto leaves are those after).
struct States {
    number: std::collections::HashMap<usize, usize>,
    base: usize,
}

struct Writer<'a> {
    input: &'a EmitInput<'a>,
    /// The program's named points.
    points: super::points::Points,
    /// The tool, base and load statements of the steps.
    tools: super::tool::Tools,
    d: &'a Dialect,
    out: Lines<'a>,
    number: usize,
    uses_branch_var: bool,
    /// Loop flags used so far ([`Leave::Flag`]).
    flags: usize,
    /// The flag of each enclosing loop (`None`: left by a statement, or endless).
    loops: Vec<Option<String>>,
    /// The handshakes of a program of a cell.
    hand: Option<super::handshake::Hand<'a>>,
    /// Inside a [`Block::Machine`].
    states: Option<States>,
    uses_state_var: bool,
}

impl Writer<'_> {
    /// Whether loops of the current state are open (a Goto must leave them).
    fn in_state_loop(&self) -> bool {
        self.states
            .as_ref()
            .is_some_and(|s| self.loops.len() > s.base)
    }

    /// The test that no Goto was taken in this state.
    fn still_here(&self) -> String {
        format!("{STATE_VAR}{}0", self.d.equals)
    }
    fn comment(&mut self, level: usize, text: &str) {
        let line = format!("{} {}", self.d.comment, flow::comment_text(text));
        self.out.line(level, &line);
    }

    fn if_line(&mut self, level: usize, first: bool, c: &str) {
        let (a, b) = if first { self.d.if_ } else { self.d.elif };
        self.out.line(level, &format!("{a}{c}{b}"));
    }

    fn assign(&mut self, level: usize, var: &str, value: &str) {
        let (a, b) = self.d.assign;
        self.out.line(level, &format!("{var}{a}{value}{b}"));
    }

    /// Blocks one after another. After one that may leave the loop (with a flag), the rest
    /// runs only while the flag holds.
    fn sequence<'b>(&mut self, parts: impl Iterator<Item = &'b [Block]>, level: usize) {
        let mut level = level;
        let mut open = 0;
        let mut parts = parts.peekable();
        while let Some(part) = parts.next() {
            for (k, b) in part.iter().enumerate() {
                self.block(b, level);
                let more = k + 1 < part.len() || parts.peek().is_some();
                let goes = self.states.is_some() && may_goto(b);
                let in_loop = self.in_state_loop();
                if goes
                    && in_loop
                    && matches!(b, Block::Loop { .. })
                    && let Leave::Statement(stmt) = self.d.leave
                {
                    // A Goto in the inner loop left only that one: leave this one too.
                    let test = format!("{STATE_VAR} {} 0", (self.d.ops.op)(BinOp::Ne));
                    self.if_line(level, true, &test);
                    self.out.line(level + 1, stmt);
                    self.out.line(level, self.d.end_if);
                    continue;
                }
                if !more {
                    continue;
                }
                let flagged = matches!(self.d.leave, Leave::Flag);
                if (may_leave(b) || (goes && flagged && in_loop))
                    && let Some(Some(flag)) = self.loops.last().cloned()
                {
                    self.if_line(level, true, &flag);
                    level += 1;
                    open += 1;
                } else if goes && !in_loop {
                    let test = self.still_here();
                    self.if_line(level, true, &test);
                    level += 1;
                    open += 1;
                }
            }
        }
        for _ in 0..open {
            level -= 1;
            self.out.line(level, self.d.end_if);
        }
    }

    fn blocks(&mut self, blocks: &[Block], level: usize) {
        self.sequence(std::iter::once(blocks), level);
    }

    fn block(&mut self, b: &Block, level: usize) {
        let input = self.input;
        match b {
            Block::Step(i) => {
                if let Some((comment, lines)) = flow::timer_start(input, *i) {
                    self.comment(level, &comment);
                    for l in &lines {
                        self.out.line(level, l);
                    }
                }
                let Some(bs) = input.bound.steps.get(*i) else {
                    return;
                };
                self.number += 1;
                self.out.step_title(
                    level,
                    &[self.d.comment, " step "],
                    input,
                    *i,
                    bs,
                    self.number,
                );
                if let Some(t) = self.tools.at(*i) {
                    self.out.code(level, input.step_indent, t);
                }
                let code = self.points.step_code(flow::step_name(input, *i), &bs.code);
                self.out.code(level, input.step_indent, code);
            }
            Block::Wait(t) => {
                if let Some(c) = flow::condition(input, *t, self.d.ops) {
                    self.comment(level, &flow::transition_comment(input, *t));
                    (self.d.wait)(&mut self.out, level, &c);
                }
            }
            Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                self.sequence(branches.iter().map(Vec::as_slice), level);
            }
            Block::Choice {
                divergence,
                branches,
                ..
            } => self.choice(*divergence, branches, level),
            Block::Loop {
                head,
                jumps,
                body,
                endless,
            } => {
                self.comment(level, &flow::loop_comment(input, *head, jumps, *endless));
                let (a, b) = self.d.while_;
                let goes = self.states.is_some() && body.iter().any(may_goto);
                let flag = match self.d.leave {
                    Leave::Flag if !*endless || goes => {
                        self.flags += 1;
                        let flag = format!("skp_loop{}", self.flags);
                        self.assign(level, &flag, self.d.ops.true_);
                        self.out.line(level, &format!("{a}{flag}{b}"));
                        Some(flag)
                    }
                    _ => {
                        self.out.line(level, &format!("{a}{}{b}", self.d.ops.true_));
                        None
                    }
                };
                self.loops.push(flag);
                self.blocks(body, level + 1);
                self.loops.pop();
                self.out.line(level, self.d.end_while);
            }
            Block::Tell(_) | Block::Hear(_) => {
                super::handshake::write_block(self.hand.as_ref(), &mut self.out, level, b);
            }
            Block::Machine(states) => self.machine(states, level),
            Block::Goto { target, from } => {
                let n = self
                    .states
                    .as_ref()
                    .and_then(|s| s.number.get(target).copied())
                    .unwrap_or(0);
                self.comment(level, &flow::goto_comment(self.input, *target, *from));
                self.assign(level, STATE_VAR, &n.to_string());
                if self.in_state_loop() {
                    match &self.d.leave {
                        Leave::Statement(s) => self.out.line(level, s),
                        Leave::Flag => {
                            let base = self.states.as_ref().map_or(0, |s| s.base);
                            let flags: Vec<String> =
                                self.loops[base..].iter().flatten().cloned().collect();
                            for f in flags {
                                self.assign(level, &f, self.d.ops.false_);
                            }
                        }
                    }
                }
            }
            Block::Follow {
                divergence,
                heard,
                branches,
            } => {
                let decider = self
                    .hand
                    .as_ref()
                    .map(|h| h.teller(heard))
                    .unwrap_or_default();
                self.comment(
                    level,
                    &flow::follow_comment(self.input, *divergence, branches.len(), &decider),
                );
                if let Some(h) = &self.hand {
                    h.hear(&mut super::handshake::At::new(&mut self.out, level), heard);
                }
                let var = super::handshake::DECISION_VAR;
                if branches.len() == 1 {
                    self.branch(1, &branches[0], level);
                    return;
                }
                for (n, br) in branches.iter().enumerate() {
                    if n + 1 < branches.len() {
                        let test = format!("{var}{}{n}", self.d.equals);
                        self.if_line(level, n == 0, &test);
                    } else {
                        self.out.line(level, self.d.else_);
                    }
                    self.branch(n + 1, br, level + 1);
                }
                self.out.line(level, self.d.end_if);
            }
        }
    }

    /// Flow beyond the structured forms: a loop over the states, each chosen by [`STATE_VAR`];
    /// a state's Gotos set it, and it stays 0 when the program ends.
    fn machine(&mut self, states: &[crate::plan::State], level: usize) {
        self.uses_state_var = true;
        let number = crate::plan::State::numbers(states, 1);
        let outer = self.states.replace(States {
            number,
            base: self.loops.len(),
        });
        self.comment(level, &flow::machine_comment(states.len()));
        self.assign(level, STATE_VAR, "1");
        let (a, b) = self.d.while_;
        let ne = (self.d.ops.op)(BinOp::Ne);
        self.out.line(level, &format!("{a}{STATE_VAR} {ne} 0{b}"));
        for (k, st) in states.iter().enumerate() {
            let test = format!("{STATE_VAR}{}{}", self.d.equals, k + 1);
            self.if_line(level + 1, k == 0, &test);
            self.comment(level + 2, &flow::state_comment(self.input, k + 1, st.entry));
            self.assign(level + 2, STATE_VAR, "0");
            self.blocks(&st.body, level + 2);
        }
        self.out.line(level + 1, self.d.end_if);
        self.out.line(level, self.d.end_while);
        self.states = outer;
    }

    fn branch(&mut self, n: usize, br: &Branch, level: usize) {
        self.comment(level, &flow::branch_comment(self.input, n, br));
        let start = self.out.out.len();
        self.blocks(&br.body, level);
        match br.end {
            BranchEnd::Join => {}
            BranchEnd::Repeat(j) => self.comment(level, &flow::round_again_comment(self.input, j)),
            BranchEnd::Leave => match (&self.d.leave, self.loops.last().cloned()) {
                (Leave::Statement(s), _) => self.out.line(level, s),
                (Leave::Flag, Some(Some(flag))) => self.assign(level, &flag, self.d.ops.false_),
                (Leave::Flag, _) => {}
            },
        }
        if let Some(stmt) = self.d.empty_block {
            let comment = self.d.comment;
            let body = &self.out.out[start..];
            if body.lines().all(|l| {
                let t = l.trim();
                t.is_empty() || t.starts_with(comment)
            }) {
                self.out.line(level, stmt);
            }
        }
    }

    /// Selection branches in priority order: an `if`/`elif` chain whose `else` is the first
    /// unconditional branch; without one, the branch is chosen first (waiting for any
    /// condition, testing again if none holds any more), then run.
    fn choice(&mut self, div: usize, branches: &[Branch], level: usize) {
        let input = self.input;
        let conds = flow::branch_conditions(input, branches, self.d.ops);
        self.comment(
            level,
            &flow::selection_comment(self.input, div, branches.len()),
        );
        if let Some(k) = conds.iter().position(Option::is_none) {
            // Branches after an unconditional one are never taken.
            if k == 0 {
                self.branch(1, &branches[0], level);
                return;
            }
            if let Some(settle) = self.d.settle {
                self.comment(
                    level,
                    "decided when the motion before it has ended (the robot stands first)",
                );
                self.out.line(level, settle);
            }
            for (n, br) in branches.iter().enumerate().take(k) {
                self.if_line(level, n == 0, conds[n].as_deref().unwrap_or_default());
                self.branch(n + 1, br, level + 1);
            }
            self.out.line(level, self.d.else_);
            self.branch(k + 1, &branches[k], level + 1);
            self.out.line(level, self.d.end_if);
            return;
        }
        self.uses_branch_var = true;
        let any: Vec<String> = conds
            .iter()
            .map(|c| format!("({})", c.as_deref().unwrap_or_default()))
            .collect();
        let or = format!(" {} ", (self.d.ops.op)(crate::cond::BinOp::Or));
        let (a, b) = self.d.while_;
        self.assign(level, BRANCH_VAR, "0");
        self.out
            .line(level, &format!("{a}{BRANCH_VAR}{}0{b}", self.d.equals));
        (self.d.wait)(&mut self.out, level + 1, &any.join(&or));
        for (n, c) in conds.iter().enumerate() {
            self.if_line(level + 1, n == 0, c.as_deref().unwrap_or_default());
            self.assign(level + 2, BRANCH_VAR, &(n + 1).to_string());
        }
        self.out.line(level + 1, self.d.end_if);
        self.out.line(level, self.d.end_while);
        for (n, br) in branches.iter().enumerate() {
            if n + 1 < branches.len() || n == 0 {
                let test = format!("{BRANCH_VAR}{}{}", self.d.equals, n + 1);
                self.if_line(level, n == 0, &test);
            } else {
                self.out.line(level, self.d.else_);
            }
            self.branch(n + 1, br, level + 1);
        }
        self.out.line(level, self.d.end_if);
    }
}
