//! What every language's writer shares: lines at a nesting level, the texts of step titles and
//! of the comments that say which element of the chart a piece of code comes from, and
//! conditions rendered with the language's operators and signals.

use crate::bind::BoundStep;
use crate::cond::Ops;
use crate::lang::Language;
use crate::model::ElementKind;
use crate::names::transliterate;

use super::EmitInput;

/// Output text with a nesting level of two spaces per level, after the indentation of the
/// template's `{{steps}}` line.
pub struct Lines<'a> {
    pub out: String,
    pub newline: &'a str,
    /// The indentation of the `{{steps}}` line, before every non-empty line.
    pub base: &'a str,
}

impl<'a> Lines<'a> {
    /// Lines for `input`'s steps block, with room for `estimate` bytes.
    pub fn new(input: &EmitInput<'a>, estimate: usize) -> Self {
        Lines {
            out: String::with_capacity(estimate),
            newline: input.newline,
            base: input.steps_indent,
        }
    }

    /// One line at `level`.
    pub fn line(&mut self, level: usize, text: &str) {
        self.indent(level);
        self.out.push_str(text);
        self.out.push_str(self.newline);
    }

    /// One line at `level`, written straight from its pieces (no `String` made for it).
    pub fn line_fmt(&mut self, level: usize, text: std::fmt::Arguments) {
        self.indent(level);
        // Writing into a `String` cannot fail.
        let _ = std::fmt::Write::write_fmt(&mut self.out, text);
        self.out.push_str(self.newline);
    }

    /// The indentation of `level`.
    pub fn indent(&mut self, level: usize) {
        self.out.push_str(self.base);
        for _ in 0..level {
            self.out.push_str("  ");
        }
    }

    /// A step's title line at `level`: the `prefix` pieces, then [`push_step_title`].
    pub fn step_title(
        &mut self,
        level: usize,
        prefix: &[&str],
        input: &EmitInput,
        i: usize,
        bs: &BoundStep,
        number: usize,
    ) {
        self.indent(level);
        push_step_title(&mut self.out, prefix, input, i, bs, number);
        self.out.push_str(self.newline);
    }

    /// [`Lines::step_title`] from the title after its number, read ahead of the writer
    /// ([`push_title_tail`], when it [`is_clean`]): the same line.
    pub fn step_title_read(&mut self, level: usize, prefix: &[&str], number: usize, tail: &str) {
        self.indent(level);
        for p in prefix {
            self.out.push_str(p);
        }
        push_decimal(&mut self.out, number as u64);
        self.out.push_str(tail);
        self.out.push_str(self.newline);
    }

    /// A step's code: each non-empty line at `level` after `step_indent`.
    pub fn code(&mut self, level: usize, step_indent: &str, code: &str) {
        for line in code.split('\n') {
            if !line.is_empty() {
                self.indent(level);
                self.out.push_str(step_indent);
                self.out.push_str(line);
            }
            self.out.push_str(self.newline);
        }
    }
}

/// A step's title: `N name: skill @ resource (localId n)`, on one line of ASCII, after the
/// `prefix` pieces, appended to `out` (100,000 steps: no string of their own for the titles).
pub fn push_step_title(
    out: &mut String,
    prefix: &[&str],
    input: &EmitInput,
    i: usize,
    bs: &BoundStep,
    number: usize,
) {
    for p in prefix {
        out.push_str(p);
    }
    let at = out.len();
    push_decimal(out, number as u64);
    push_title_tail(out, input, i, bs);
    let title = &out[at..];
    if !is_clean(title) {
        let clean = transliterate(title);
        out.truncate(at);
        out.push_str(&clean);
    }
}

/// What follows the number in a step's title ([`push_step_title`]), as the chart gives it:
/// ` name: skill @ resource (localId n)`. When it [`is_clean`], the title is the number and
/// it (the step's title read ahead of the writer, [`super::ahead`]).
pub fn push_title_tail(out: &mut String, input: &EmitInput, i: usize, bs: &BoundStep) {
    let e = &input.sfc.elements[i];
    let name = match &e.kind {
        ElementKind::Step(st) => &*st.name,
        _ => "",
    };
    let res = &input.blackboard.resources[bs.resource];
    let skill = &res.skills[bs.skill];
    out.push(' ');
    out.push_str(name);
    out.push_str(": ");
    out.push_str(&skill.name.text);
    out.push_str(" @ ");
    out.push_str(&res.name.text);
    out.push_str(" (localId ");
    push_decimal(out, e.local_id);
    out.push(')');
}

/// Whether a title is ASCII on one line already (else it is transliterated).
pub fn is_clean(title: &str) -> bool {
    // (`is_ascii` goes a word at a time.)
    title.is_ascii() && memchr::memchr2(b'\r', b'\n', title.as_bytes()).is_none()
}

/// The name of step `i` as the chart gives it (`""` for another element).
pub fn step_name<'i>(input: &EmitInput<'i>, i: usize) -> &'i str {
    match &input.sfc.elements[i].kind {
        ElementKind::Step(st) => &st.name,
        _ => "",
    }
}

/// Appends `n` in decimal (what `write!(out, "{n}")` gives, without the formatting machinery:
/// two numbers in every step's title).
pub fn push_decimal(out: &mut String, mut n: u64) {
    let mut digits = [0u8; 20];
    let mut i = digits.len();
    loop {
        i -= 1;
        digits[i] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    for &d in &digits[i..] {
        out.push(char::from(d));
    }
}

/// The condition of transition `t` in the language (`ops`, the profile's signals); `None` when
/// it always fires.
pub fn condition(input: &EmitInput, t: usize, ops: &Ops) -> Option<String> {
    let ElementKind::Transition(Some(c)) = &input.sfc.elements[t].kind else {
        return None;
    };
    let res = input.bound.resource.map(|r| &input.blackboard.resources[r]);
    let lang = input.profile.language();
    let signal = |n: &str| -> String {
        if let Some((k, number)) = input.bound.timer_named(n) {
            return timer_read(lang, k, number);
        }
        res.and_then(|r| {
            let si = r.signal(&crate::names::key(n))?;
            input.profile.signal(&r.signals[si]).ok()
        })
        .unwrap_or_else(|| n.to_owned())
    };
    Some(crate::cond::render(&c.expr, &signal, ops))
}

/// How `lang` reads the `k`-th step timer (KRL: `$TIMER[number]`, milliseconds; RAPID: the
/// clock `skp_clock<k+1>`, seconds; URScript: the counter `skp_time<k+1>`, seconds).
pub fn timer_read(lang: Language, k: usize, number: u32) -> String {
    match lang {
        Language::Krl => format!("$TIMER[{number}]"),
        Language::Rapid => format!("ClkRead(skp_clock{})", k + 1),
        Language::UrScript => format!("skp_time{}", k + 1),
    }
}

/// Where step `i`'s time starts, when a condition reads it: the comment's text and the
/// statements, in `lang`. The step is active from here, after the motion before it has ended
/// (KRL's advance run would start the timer early: `WAIT SEC 0` stops it; RAPID waits for the
/// robot to stand still).
pub fn timer_start(input: &EmitInput, i: usize) -> Option<(String, Vec<String>)> {
    let (k, number) = input.bound.timer_of(i)?;
    let el = &input.sfc.elements[i];
    let name = match &el.kind {
        ElementKind::Step(st) => transliterate(&st.name),
        _ => String::new(),
    };
    let what = format!("step time of {name} (localId {})", el.local_id);
    Some(match input.profile.language() {
        Language::Krl => (
            format!("{what} starts when the motion before it has ended"),
            vec![
                "WAIT SEC 0".to_owned(),
                format!("$TIMER[{number}] = 0"),
                format!("$TIMER_STOP[{number}] = FALSE"),
            ],
        ),
        Language::Rapid => (
            format!("{what} starts when the robot stands still"),
            vec![
                "WaitTime \\InPos, 0;".to_owned(),
                format!("ClkReset skp_clock{};", k + 1),
                format!("ClkStart skp_clock{};", k + 1),
            ],
        ),
        Language::UrScript => (
            format!("{what} starts"),
            vec![format!("skp_time{} = 0.0", k + 1)],
        ),
    })
}

/// The condition that selects a selection branch: its transition's, or any of the nested
/// selection's first transitions (`None`: the branch is unconditional).
pub fn branch_condition(input: &EmitInput, br: &crate::plan::Branch, ops: &Ops) -> Option<String> {
    let heads = br.heads();
    if heads.len() == 1 {
        return condition(input, heads[0], ops);
    }
    let mut parts = Vec::with_capacity(heads.len());
    for h in heads {
        parts.push(format!("({})", condition(input, h, ops)?));
    }
    Some(parts.join(&format!(" {} ", (ops.op)(crate::cond::BinOp::Or))))
}

/// The conditions of a selection's branches ([`branch_condition`]), with the last one `None`
/// (taken when the others are not: an `ELSE`) where the branches cover every case: whatever
/// the inputs, one of the conditions holds (`c` and `NOT c`; `V = 2 AND NOT E`, `NOT E`, `E`).
/// A wait for their `OR` would be a wait that is always true; in priority order, when none of
/// the others holds the last one does.
pub fn branch_conditions(
    input: &EmitInput,
    branches: &[crate::plan::Branch],
    ops: &Ops,
) -> Vec<Option<String>> {
    let mut conds: Vec<Option<String>> = branches
        .iter()
        .map(|b| branch_condition(input, b, ops))
        .collect();
    if conds.len() > 1 && conds.iter().all(Option::is_some) && covers_every_case(input, branches) {
        *conds.last_mut().expect("two or more") = None;
    }
    conds
}

/// A selection's conditions cover every case when their `OR` holds for every value of their
/// atoms: each signal, step time and comparison taken as a truth value of its own (`V <> 2` as
/// `NOT (V = 2)`). Atoms are compared by their text; more than [`MAX_ATOMS`] are not tried (a
/// wait is kept, as for any selection that may wait).
fn covers_every_case(input: &EmitInput, branches: &[crate::plan::Branch]) -> bool {
    let mut exprs = Vec::new();
    for br in branches {
        for t in br.heads() {
            match &input.sfc.elements[t].kind {
                ElementKind::Transition(Some(c)) => exprs.push(&c.expr),
                _ => return false,
            }
        }
    }
    always_one_holds(&exprs)
}

/// Whether one of `exprs` holds whatever values their atoms have ([`covers_every_case`]).
fn always_one_holds(exprs: &[&crate::cond::Expr]) -> bool {
    let mut atoms = Atoms::default();
    for e in exprs {
        if !atoms.collect(e) || atoms.keys.len() > MAX_ATOMS {
            return false;
        }
    }
    (0u32..1 << atoms.keys.len())
        .all(|values| exprs.iter().any(|e| atoms.truth(e, values) == Some(true)))
}

/// The most atoms [`covers_every_case`] tries (2^10 cases).
const MAX_ATOMS: usize = 10;

/// The atoms of a selection's conditions: their keys ([`atom_key`]), and for each atom node of
/// the conditions its atom and whether it is negated (found once, not at every case tried).
#[derive(Default)]
struct Atoms {
    keys: Vec<String>,
    places: Vec<(*const crate::cond::Expr, usize, bool)>,
}

impl Atoms {
    /// Adds `e`'s atoms; `false` when `e` is not a truth value made of atoms, `NOT`, `AND`,
    /// `OR`, `XOR` and `TRUE`/`FALSE`.
    fn collect(&mut self, e: &crate::cond::Expr) -> bool {
        use crate::cond::{BinOp, ExprKind};
        match &e.kind {
            ExprKind::Bool(_) => true,
            ExprKind::Not(x) => self.collect(x),
            ExprKind::Bin(BinOp::And | BinOp::Or | BinOp::Xor, a, b) => {
                self.collect(a) && self.collect(b)
            }
            _ => match atom_key(e) {
                Some((key, negated)) => {
                    let k = match self.keys.iter().position(|a| *a == key) {
                        Some(k) => k,
                        None => {
                            self.keys.push(key);
                            self.keys.len() - 1
                        }
                    };
                    self.places.push((std::ptr::from_ref(e), k, negated));
                    true
                }
                None => false,
            },
        }
    }

    /// `e`'s truth when atom `k` has the value of bit `k` of `values`.
    fn truth(&self, e: &crate::cond::Expr, values: u32) -> Option<bool> {
        use crate::cond::{BinOp, ExprKind};
        Some(match &e.kind {
            ExprKind::Bool(b) => *b,
            ExprKind::Not(x) => !self.truth(x, values)?,
            ExprKind::Bin(BinOp::And, a, b) => self.truth(a, values)? && self.truth(b, values)?,
            ExprKind::Bin(BinOp::Or, a, b) => self.truth(a, values)? || self.truth(b, values)?,
            ExprKind::Bin(BinOp::Xor, a, b) => self.truth(a, values)? != self.truth(b, values)?,
            _ => {
                let &(_, k, negated) = self.places.iter().find(|p| p.0 == std::ptr::from_ref(e))?;
                ((values >> k) & 1 == 1) != negated
            }
        })
    }
}

/// An atom's key: a name, or a comparison with its operands' text (`<>` as `=`).
fn atom_key(e: &crate::cond::Expr) -> Option<(String, bool)> {
    use crate::cond::{BinOp, ExprKind};
    let text = |x: &crate::cond::Expr| crate::cond::render(x, &|n: &str| n.to_owned(), &Ops::KRL);
    match &e.kind {
        ExprKind::Name(n) => Some((format!("name {n}"), false)),
        ExprKind::Bin(op, a, b) => {
            let (op, negated) = match op {
                BinOp::Ne => (BinOp::Eq, true),
                BinOp::Eq | BinOp::Lt | BinOp::Gt | BinOp::Le | BinOp::Ge => (*op, false),
                _ => return None,
            };
            Some((format!("{op:?} ({}) ({})", text(a), text(b)), negated))
        }
        _ => None,
    }
}

/// The condition as written, for comments: on one line, without `;` (a comment inside a KRL
/// comment, a statement end in RAPID), ASCII.
pub fn condition_text(input: &EmitInput, t: usize) -> String {
    match &input.sfc.elements[t].kind {
        ElementKind::Transition(Some(c)) => transliterate(
            &c.text
                .replace(';', ",")
                .split_whitespace()
                .collect::<Vec<_>>()
                .join(" "),
        ),
        _ => "TRUE".to_owned(),
    }
}

/// A comment's text on one line of ASCII.
pub fn comment_text(text: &str) -> String {
    transliterate(text)
}

/// The `localId`s of elements, joined by `, `.
pub fn local_ids(input: &EmitInput, elements: &[usize]) -> String {
    let ids: Vec<String> = elements
        .iter()
        .map(|j| input.sfc.elements[*j].local_id.to_string())
        .collect();
    ids.join(", ")
}

/// About how long a program's steps block gets: its steps' code and a title line each.
pub fn steps_estimate(input: &EmitInput) -> usize {
    input
        .bound
        .steps
        .unordered()
        .map(|b| b.code.len() + 80)
        .sum::<usize>()
        + 1024
}

/// The comment before a guarded transition's wait.
pub fn transition_comment(input: &EmitInput, t: usize) -> String {
    format!(
        "transition localId {}: {}",
        input.sfc.elements[t].local_id,
        condition_text(input, t)
    )
}

/// The comment before a loop.
pub fn loop_comment(input: &EmitInput, head: usize, jumps: &[usize], endless: bool) -> String {
    let how = if input.sfc.closed.is_empty() {
        format!("jump localId {}", local_ids(input, jumps))
    } else {
        let v: Vec<String> = jumps.iter().map(|&j| input.sfc.jump_label(j)).collect();
        v.join(", ")
    };
    format!(
        "loop back to step localId {} ({how}){}",
        input.sfc.elements[head].local_id,
        if endless { ", endless" } else { "" }
    )
}

/// The comment before flow the structured forms cannot express.
pub fn machine_comment(states: usize) -> String {
    format!("flow in {states} states: where the chart is not structured, it goes on at a state")
}

/// A state's entry in comments: `step Name (localId 3)`, or the element's tag and localId.
fn entry_text(input: &EmitInput, entry: usize) -> String {
    let e = &input.sfc.elements[entry];
    match &e.kind {
        ElementKind::Step(st) => format!("step {} (localId {})", st.name, e.local_id),
        k => format!("{} localId {}", k.tag(), e.local_id),
    }
}

/// The comment at the beginning of state `n` (from 1).
pub fn state_comment(input: &EmitInput, n: usize, entry: usize) -> String {
    format!("state {n}: {}", entry_text(input, entry))
}

/// The comment before a Goto.
pub fn goto_comment(input: &EmitInput, target: usize, from: usize) -> String {
    let to = entry_text(input, target);
    match &input.sfc.elements[from].kind {
        ElementKind::JumpStep(_) => format!("go on at {to} ({})", input.sfc.jump_label(from)),
        _ => format!("go on at {to}"),
    }
}

/// The comment at the head of selection branch `n` (from 1).
pub fn branch_comment(input: &EmitInput, n: usize, br: &crate::plan::Branch) -> String {
    let heads = br.heads();
    if heads.len() == 1 {
        return format!(
            "branch {n} (transition localId {}): {}",
            input.sfc.elements[heads[0]].local_id,
            condition_text(input, heads[0])
        );
    }
    let conds: Vec<String> = heads
        .iter()
        .map(|&h| format!("({})", condition_text(input, h)))
        .collect();
    format!(
        "branch {n} (selectionDivergence localId {}): {}",
        input.sfc.elements[br.transition].local_id,
        conds.join(" OR ")
    )
}

/// The comment at the end of a branch that goes round the loop again.
pub fn round_again_comment(input: &EmitInput, jump: usize) -> String {
    format!("round again ({})", input.sfc.jump_label(jump))
}

/// The comment before a selection.
pub fn selection_comment(input: &EmitInput, divergence: usize, branches: usize) -> String {
    format!(
        "selection localId {}: {branches} branches, the first whose condition holds",
        input.sfc.elements[divergence].local_id
    )
}

/// The comment before a selection another controller decides (a cell, docs/CELLS.md).
pub fn follow_comment(
    input: &EmitInput,
    divergence: usize,
    branches: usize,
    decider: &str,
) -> String {
    format!(
        "selection localId {}: {branches} branches, the one {decider} takes",
        input.sfc.elements[divergence].local_id
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_selection_covers_every_case_only_when_one_condition_always_holds() {
        let holds = |conds: &[&str]| {
            let exprs: Vec<crate::cond::Expr> = conds
                .iter()
                .map(|c| crate::cond::parse(c, &|i| i).expect("parses"))
                .collect();
            super::always_one_holds(&exprs.iter().collect::<Vec<_>>())
        };
        assert!(holds(&["A", "NOT A"]));
        assert!(holds(&["V = 2 AND NOT E", "NOT E", "E"]));
        assert!(holds(&["V = 2", "V <> 2"]));
        assert!(holds(&["A AND B", "A XOR B", "NOT A AND NOT B"]));
        assert!(holds(&["S1.t > T#150ms", "NOT (S1.t > T#150ms)"]));
        assert!(!holds(&["A", "B"]));
        assert!(!holds(&["V = 2 AND NOT E", "E"]));
        // Different comparisons are different atoms: never taken for a cover.
        assert!(!holds(&["V < 2", "V >= 2"]));
        assert!(!holds(&["A AND B", "NOT A"]));
    }

    /// The same digits as `format!`, at the ends of the range and around each power of ten.
    #[test]
    fn push_decimal_is_format() {
        let mut cases = vec![0, 1, 9, u64::MAX, u64::MAX - 1];
        let mut p = 1u64;
        while let Some(next) = p.checked_mul(10) {
            cases.extend([p - 1, p, p + 1]);
            p = next;
        }
        cases.extend([p - 1, p, p + 1]);
        for n in cases {
            let mut out = String::from("x");
            super::push_decimal(&mut out, n);
            assert_eq!(out, format!("x{n}"));
        }
    }
}
