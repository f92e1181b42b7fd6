//! The KUKA KRL profile: `<program>.src` and `<program>.dat` (docs/LANGUAGES.md).
//!
//! The fixed text (header, initialisation, closing) comes from the output template: the
//! built-in `templates/krl.toml` or the user's copy.

use std::borrow::Cow;

use super::flow::{self, Lines};
use super::{EmitInput, Generated, Language, Profile};
use crate::cond::Ops;
use crate::diag::Diagnostics;
use crate::model::{Signal, SignalKind};
use crate::names::transliterate;
use crate::plan::{Block, Branch, BranchEnd};
use crate::template::Syntax;
use crate::value::Literal;

/// The built-in template's text.
pub const DEFAULT_TEMPLATE: &str = include_str!("../../templates/krl.toml");

/// The KRL profile.
pub struct Krl;

impl crate::bind::Rules for Krl {
    fn language(&self) -> Language {
        Language::Krl
    }

    fn literal<'v>(&self, v: &Literal<'v>) -> Result<Cow<'v, str>, String> {
        Ok(match v {
            Literal::Number(n) => n.clone(),
            Literal::Bool(true) => Cow::Borrowed("TRUE"),
            Literal::Bool(false) => Cow::Borrowed("FALSE"),
            Literal::Str(s) => Cow::Owned(format!("\"{s}\"")),
            Literal::Word(w) => {
                let bare = w.trim_start_matches(['$', '#']);
                if w.len() == bare.len() && crate::names::is_krl_keyword(w) {
                    return Err(format!(
                        "`{w}` is a KRL keyword: as a value it would become code"
                    ));
                }
                Cow::Borrowed(*w)
            }
        })
    }

    fn signal(&self, s: &Signal) -> Result<String, String> {
        let io = if s.output { "$OUT" } else { "$IN" };
        match &s.kind {
            SignalKind::Bit(0) => Err(NUMBER_0.to_owned()),
            SignalKind::Bit(n) => Ok(format!("{io}[{n}]")),
            SignalKind::Group { .. } => Ok(s.name.text.to_string()),
            SignalKind::Address { text, .. } if text.contains('(') => Err(format!(
                "KRL cannot read Address `{text}` (a function call): write a name or a system variable with an index (`PART_OK`, `$IN[5]`)"
            )),
            SignalKind::Address { text, .. } => Ok(text.clone()),
        }
    }
}

/// `E209` for each signal of `Number` 0 on the resources of a KRL program (the program's own
/// and those whose skills its steps run): KRL has no `$IN[0]`, and the I/O list would name one.
/// `false` when there is one.
fn numbers_from_1(input: &EmitInput, diags: &mut Diagnostics) -> bool {
    let mut ok = true;
    for r in input.bound.resources() {
        for s in &input.blackboard.resources[r].signals {
            if s.kind == SignalKind::Bit(0) {
                ok = false;
                diags.push(
                    crate::diag::Diagnostic::error(
                        crate::diag::Code::BadSignal,
                        format!("signal `{}`: {NUMBER_0}", s.name.text),
                    )
                    .at(s.name.span.clone())
                    .element(s.element.clone()),
                );
            }
        }
    }
    ok
}

/// Why a signal of `Number` 0 is no KRL I/O (URScript counts from 0, KRL from 1).
pub const NUMBER_0: &str = "Number 0 is no KRL input or output: KRL counts inputs and outputs from 1 ($IN[1]); Number 0 is for a URScript controller's standard digital I/O";

impl Profile for Krl {
    fn files(&self) -> &'static [&'static str] {
        &["src", "dat"]
    }

    fn builtin_template(&self) -> &'static str {
        DEFAULT_TEMPLATE
    }

    fn syntax(&self) -> Syntax {
        Language::Krl.syntax()
    }

    fn check_program_name(&self, name: &str) -> Result<(), String> {
        if !crate::names::is_krl_name(name) {
            Err("not a KRL name: a letter or `_`, then letters, digits or `_`, at most 24 characters".to_owned())
        } else if crate::names::is_krl_keyword(name) {
            Err("a KRL keyword cannot name a program".to_owned())
        } else {
            Ok(())
        }
    }

    fn generate(&self, input: &EmitInput, diags: &mut Diagnostics) -> Option<Generated> {
        if !numbers_from_1(input, diags) {
            return None;
        }
        let tools = super::tool::Tools::new(input, diags);
        let points = super::points::for_program(input, &tools, diags)?;
        let mut writer = Writer {
            points,
            input,
            tools,
            out: Lines::new(input, flow::steps_estimate(input)),
            number: 0,
            uses_branch_var: false,
            hand: None,
            states: std::collections::HashMap::new(),
            labels: 0,
            ahead: None,
        };
        let hand = super::handshake::Hand::new(input);
        if let Some(h) = &hand {
            h.check(diags);
            h.init(&mut super::handshake::At::new(&mut writer.out, 0));
        }
        writer.hand = hand;
        // Each top-level block's start, and the end: where the program may be split.
        let mut cuts = Vec::with_capacity(input.body.len() + 1);
        // And how many points were declared by then: a block's points are its own.
        let mut point_cuts = Vec::with_capacity(input.body.len() + 1);
        let steps = input.bound.steps.len();
        std::thread::scope(|s| {
            if steps >= input.read_ahead_from {
                writer.ahead = super::ahead::start(s, input, Language::Krl);
            }
            for b in input.body {
                cuts.push(writer.out.out.len());
                point_cuts.push(writer.points.declarations.len());
                writer.block(b, 0);
            }
            // Its thread ends with the steps it has read.
            writer.ahead = None;
        });
        cuts.push(writer.out.out.len());
        point_cuts.push(writer.points.declarations.len());
        if let Some(h) = &writer.hand {
            h.finish(&mut super::handshake::At::new(&mut writer.out, 0));
        }
        let mut declarations = declarations(input, writer.uses_branch_var);
        let mut routines = Vec::new();
        if let Some(h) = &writer.hand {
            declarations.extend(h.declarations());
            routines = h.routines();
        }
        // The points come last: `point_cuts` index the declarations.
        let before = declarations.len();
        declarations.append(&mut writer.points.declarations);
        Some(Generated {
            steps: writer.out.out,
            declarations,
            routines,
            data: writer.tools.data,
            cuts,
            point_cuts: point_cuts.into_iter().map(|n| before + n).collect(),
        })
    }
}

/// The `.dat` variable that holds the branch a selection without an unconditional branch chose.
pub use crate::lang::BRANCH_VAR;

/// Writes the program tree.
struct Writer<'a> {
    input: &'a EmitInput<'a>,
    /// The program's named points.
    points: super::points::Points,
    /// The tool, base and load statements of the steps.
    tools: super::tool::Tools,
    out: Lines<'a>,
    number: usize,
    /// Whether a selection needed [`BRANCH_VAR`].
    uses_branch_var: bool,
    /// The handshakes of a program of a cell.
    hand: Option<super::handshake::Hand<'a>>,
    /// The label number of each state's entry element in the [`Block::Machine`] being written.
    states: std::collections::HashMap<usize, usize>,
    /// Label numbers used so far (machines nest in simultaneous branches).
    labels: usize,
    /// The steps' code read on a second thread (a long program).
    ahead: Option<super::ahead::Ahead>,
}

/// The label number `n` (states of a [`Block::Machine`] and the place after each machine).
fn label(n: usize) -> String {
    format!("skp_s{n}")
}

/// Whether control can run past the end of `body` (it does not end in a Goto in every branch).
fn falls_through(body: &[Block]) -> bool {
    match body.last() {
        Some(Block::Goto { .. }) => false,
        Some(Block::Choice {
            convergence: None,
            branches,
            ..
        }) => branches
            .iter()
            .any(|br| br.end == crate::plan::BranchEnd::Join && falls_through(&br.body)),
        _ => true,
    }
}

impl Writer<'_> {
    fn line(&mut self, level: usize, text: &str) {
        self.out.line(level, text);
    }

    /// A comment line; its text transliterated to ASCII on one line.
    fn comment(&mut self, level: usize, text: &str) {
        self.out.line(level, &format!(";{}", transliterate(text)));
    }

    /// The KRL condition of a transition; `None` when it always fires.
    fn condition(&self, t: usize) -> Option<String> {
        flow::condition(self.input, t, &Ops::KRL)
    }

    fn blocks(&mut self, blocks: &[Block], level: usize) {
        for b in blocks {
            self.block(b, level);
        }
    }

    fn block(&mut self, b: &Block, level: usize) {
        let input = self.input;
        match b {
            Block::Step(i) => {
                if let Some((comment, lines)) = flow::timer_start(input, *i) {
                    self.comment(level, &comment);
                    for l in &lines {
                        self.line(level, l);
                    }
                }
                let Some(bs) = input.bound.steps.get(*i) else {
                    return;
                };
                self.number += 1;
                let found = self.ahead.as_mut().and_then(|a| a.find(*i));
                let read = found.zip(self.ahead.as_ref().map(|a| a.batch()));
                match read.and_then(|(k, b)| b.title(k)) {
                    Some(tail) => self
                        .out
                        .step_title_read(level, &[";FOLD "], self.number, tail),
                    None => self
                        .out
                        .step_title(level, &[";FOLD "], input, *i, bs, self.number),
                }
                if let Some(t) = self.tools.at(*i) {
                    self.out.code(level, input.step_indent, t);
                }
                let code = match read {
                    Some((k, b)) => self.points.step_code_read(&bs.code, &b.read, k),
                    None => self.points.step_code(flow::step_name(input, *i), &bs.code),
                };
                self.out.code(level, input.step_indent, code);
                self.line(level, ";ENDFOLD");
            }
            Block::Wait(t) => {
                if let Some(c) = self.condition(*t) {
                    self.comment(level, &flow::transition_comment(input, *t));
                    self.line(level, &format!("WAIT FOR {c}"));
                }
            }
            Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                for br in branches {
                    self.blocks(br, level);
                }
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
                self.line(level, "LOOP");
                self.blocks(body, level + 1);
                self.line(level, "ENDLOOP");
            }
            Block::Tell(_) | Block::Hear(_) => {
                super::handshake::write_block(self.hand.as_ref(), &mut self.out, level, b);
            }
            Block::Machine(states) => {
                // A label per state, at the level of the machine (KRL jumps out of blocks,
                // never into one); a state that ends without a Goto ends the machine.
                self.comment(level, &flow::machine_comment(states.len()));
                let first = self.labels + 1;
                self.labels += states.len() + 1;
                let end_label = label(self.labels);
                let outer =
                    std::mem::replace(&mut self.states, crate::plan::State::numbers(states, first));
                let mut end = false;
                for (k, st) in states.iter().enumerate() {
                    self.line(level, &format!("{}:", label(first + k)));
                    self.comment(level, &flow::state_comment(input, k + 1, st.entry));
                    match st.body.split_last() {
                        // Going on at the next state: it follows anyway.
                        Some((Block::Goto { target, from }, rest))
                            if self.states.get(target) == Some(&(first + k + 1)) =>
                        {
                            self.blocks(rest, level);
                            self.comment(level, &flow::goto_comment(input, *target, *from));
                        }
                        _ => self.blocks(&st.body, level),
                    }
                    if k + 1 < states.len() && falls_through(&st.body) {
                        self.line(level, &format!("GOTO {end_label}"));
                        end = true;
                    }
                }
                if end {
                    self.line(level, &format!("{end_label}:"));
                }
                self.states = outer;
            }
            Block::Goto { target, from } => {
                let n = self.states.get(target).copied().unwrap_or(0);
                self.comment(level, &flow::goto_comment(input, *target, *from));
                self.line(level, &format!("GOTO {}", label(n)));
            }
            Block::Follow {
                divergence,
                heard,
                branches,
            } => self.follow(*divergence, heard, branches, level),
        }
    }

    /// A selection another controller decides: its decision is heard, then its branch runs.
    fn follow(
        &mut self,
        div: usize,
        heard: &crate::plan::cell::Message,
        branches: &[Branch],
        level: usize,
    ) {
        let decider = self
            .hand
            .as_ref()
            .map(|h| h.teller(heard))
            .unwrap_or_default();
        self.comment(
            level,
            &flow::follow_comment(self.input, div, branches.len(), &decider),
        );
        if let Some(h) = &self.hand {
            h.hear(&mut super::handshake::At::new(&mut self.out, level), heard);
        }
        let var = super::handshake::DECISION_VAR;
        let last = branches.len().saturating_sub(1);
        for (n, br) in branches.iter().enumerate().take(last) {
            self.line(level + n, &format!("IF {var} == {n} THEN"));
            self.branch(n + 1, br, level + n + 1);
            self.line(level + n, "ELSE");
        }
        if let Some(br) = branches.last() {
            self.branch(last + 1, br, level + last);
        }
        for n in (0..last).rev() {
            self.line(level + n, "ENDIF");
        }
    }

    /// A branch's body and how it ends.
    fn branch(&mut self, n: usize, br: &Branch, level: usize) {
        self.comment(level, &flow::branch_comment(self.input, n, br));
        self.blocks(&br.body, level);
        match br.end {
            BranchEnd::Join => {}
            BranchEnd::Repeat(j) => self.comment(level, &flow::round_again_comment(self.input, j)),
            BranchEnd::Leave => self.line(level, "EXIT"),
        }
    }

    /// Selection branches in priority order. With an unconditional branch: `WAIT SEC 0` (the
    /// advance run would test the conditions while the motion before still runs), then an `IF`
    /// chain whose last `ELSE` is that branch. Without: the program waits for any condition, records the
    /// first that holds in [`BRANCH_VAR`] (testing again if none holds any more) and then runs
    /// that branch, so it never passes the selection without taking a branch.
    fn choice(&mut self, div: usize, branches: &[Branch], level: usize) {
        let conds = flow::branch_conditions(self.input, branches, &Ops::KRL);
        self.comment(
            level,
            &flow::selection_comment(self.input, div, branches.len()),
        );
        if let Some(k) = conds.iter().position(Option::is_none) {
            if k > 0 {
                // An IF reads its condition in the advance run, while the motion before it may
                // still run: the chart decides after the step before it has ended.
                self.comment(
                    level,
                    "decided when the motion before it has ended (WAIT SEC 0 stops the advance run)",
                );
                self.line(level, "WAIT SEC 0");
            }
            // Branches after an unconditional one are never taken.
            for (n, br) in branches.iter().enumerate().take(k) {
                let c = conds[n].as_deref().unwrap_or("TRUE");
                self.line(level + n, &format!("IF {c} THEN"));
                self.branch(n + 1, br, level + n + 1);
                self.line(level + n, "ELSE");
            }
            self.branch(k + 1, &branches[k], level + k);
            for n in (0..k).rev() {
                self.line(level + n, "ENDIF");
            }
            return;
        }
        self.uses_branch_var = true;
        let any: Vec<String> = conds
            .iter()
            .map(|c| format!("({})", c.as_deref().unwrap_or("TRUE")))
            .collect();
        self.line(level, &format!("{BRANCH_VAR} = 0"));
        self.line(level, "REPEAT");
        self.line(level + 1, &format!("WAIT FOR {}", any.join(" OR ")));
        for (n, c) in conds.iter().enumerate() {
            let c = c.as_deref().unwrap_or("TRUE");
            self.line(level + 1 + n, &format!("IF {c} THEN"));
            self.line(level + 2 + n, &format!("{BRANCH_VAR} = {}", n + 1));
            if n + 1 < conds.len() {
                self.line(level + 1 + n, "ELSE");
            }
        }
        for n in (0..conds.len()).rev() {
            self.line(level + 1 + n, "ENDIF");
        }
        self.line(level, &format!("UNTIL {BRANCH_VAR} <> 0"));
        self.line(level, &format!("SWITCH {BRANCH_VAR}"));
        for (n, br) in branches.iter().enumerate() {
            if n + 1 < branches.len() {
                self.line(level, &format!("CASE {}", n + 1));
            } else {
                self.line(level, "DEFAULT");
            }
            self.branch(n + 1, br, level + 1);
        }
        self.line(level, "ENDSWITCH");
    }
}

/// The `.dat` declarations: `SIGNAL`s for the integer groups the conditions use, and the
/// selection variable when a selection needs it.
fn declarations(input: &EmitInput, uses_branch_var: bool) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(r) = input.bound.resource {
        let res = &input.blackboard.resources[r];
        for &si in &input.bound.signals {
            let s = &res.signals[si];
            if let SignalKind::Group { number, length } = s.kind {
                let io = if s.output { "$OUT" } else { "$IN" };
                out.push(format!(
                    "SIGNAL {} {io}[{number}] TO {io}[{}]",
                    s.name.text,
                    number + length - 1
                ));
            }
        }
    }
    if uses_branch_var {
        out.push(format!("DECL INT {BRANCH_VAR}=0"));
    }
    out
}
