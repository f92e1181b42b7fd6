//! The chart's meaning (a token player over the SFC graph, IEC 61131-3) and the generator of
//! random structured charts; shared by every language.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use crate::{ACTION_MS, Outcome, Phase, Rng, STUCK_MS, TICK_MS};

#[derive(Debug)]
struct Node {
    tag: String,
    name: String,
    x: f64,
    inputs: Vec<u64>,
    condition: Option<String>,
    target: Option<String>,
    skill: bool,
    /// Marked `initialStep="true"`.
    initial: bool,
}

pub struct Chart {
    nodes: BTreeMap<u64, Node>,
    /// Document order of the ids.
    order: Vec<u64>,
    /// Successors, left to right by x, ties in document order.
    succ: BTreeMap<u64, Vec<u64>>,
    /// Conditions, as the player reads them ([`Cond`]).
    conds: BTreeMap<u64, Cond>,
}

impl Chart {
    pub fn read(path: &Path) -> Chart {
        Chart::parse(&std::fs::read_to_string(path).unwrap())
    }

    /// The chart of a PLCopen XML text.
    pub fn parse(text: &str) -> Chart {
        let doc = roxmltree::Document::parse(text).unwrap();
        let sfc = doc
            .descendants()
            .find(|n| n.is_element() && n.tag_name().name() == "SFC")
            .expect("an SFC body");
        let mut nodes = BTreeMap::new();
        let mut order = Vec::new();
        // The chart's elements and, in a macro step's place, its body's (docs/INPUTS.md): each macro
        // step with its body's elements.
        let mut all = Vec::new();
        let mut macros: Vec<(u64, Vec<u64>)> = Vec::new();
        fn gather<'a, 'i>(
            sfc: roxmltree::Node<'a, 'i>,
            all: &mut Vec<roxmltree::Node<'a, 'i>>,
            macros: &mut Vec<(u64, Vec<u64>)>,
        ) {
            for e in sfc.children().filter(|n| n.is_element()) {
                all.push(e);
                if e.tag_name().name() == "macroStep" {
                    let body = e
                        .children()
                        .find(|n| n.tag_name().name() == "body")
                        .and_then(|b| b.children().find(|n| n.tag_name().name() == "SFC"))
                        .expect("a macro step's body");
                    let from = all.len();
                    gather(body, all, macros);
                    let ids = all[from..]
                        .iter()
                        .filter_map(|n| n.attribute("localId"))
                        .map(|i| i.parse().unwrap())
                        .collect();
                    macros.push((e.attribute("localId").unwrap().parse().unwrap(), ids));
                }
            }
        }
        gather(sfc, &mut all, &mut macros);
        for e in all {
            let id: u64 = e.attribute("localId").unwrap().parse().unwrap();
            let d = |tag: &'static str| {
                e.descendants()
                    .filter(move |n| n.is_element() && n.tag_name().name() == tag)
            };
            // (A macro step's own connections, not its body's.)
            let inputs = d("connection")
                .filter(|c| {
                    !c.ancestors()
                        .take_while(|a| *a != e)
                        .any(|a| a.tag_name().name() == "body")
                })
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
                    initial: e.attribute("initialStep") == Some("true"),
                },
            );
            order.push(id);
        }
        // A macro step leads to its body's first step; what follows it follows the body's last.
        for (m, body) in &macros {
            let first = *body
                .iter()
                .find(|i| nodes[*i].tag == "step" && nodes[*i].inputs.is_empty())
                .expect("a macro body's first step");
            let last = *body
                .iter()
                .find(|i| {
                    nodes[*i].tag == "step" && !body.iter().any(|j| nodes[j].inputs.contains(i))
                })
                .expect("a macro body's last step");
            for (id, n) in nodes.iter_mut() {
                if !body.contains(id) {
                    for i in n.inputs.iter_mut() {
                        if *i == *m {
                            *i = last;
                        }
                    }
                }
            }
            nodes.get_mut(&first).unwrap().inputs.push(*m);
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
                Some((*id, Cond::parse(text)))
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

    /// Whether a selection branch that starts with `head` is selected: its transition holds,
    /// or, when it opens another selection, one of that selection's branches is selected.
    fn selects(&self, head: u64, at: &At) -> bool {
        if self.nodes[&head].tag == "selectionDivergence" {
            self.succs(head).into_iter().any(|h| self.selects(h, at))
        } else {
            self.holds(head, at)
        }
    }

    fn holds(&self, transition: u64, at: &At) -> bool {
        match self.conds.get(&transition) {
            None => true,
            Some(e) => e.truth(at),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The player's own reading of ST conditions
// ---------------------------------------------------------------------------------------------

/// A condition as the chart player reads it: IEC 61131-3 ST, by a reader of its own
/// (independent of the project's parser, `src/cond/`). Booleans and integers are numbers
/// (`TRUE` is 1); durations are nanoseconds of their own type.
#[derive(Debug, Clone)]
pub enum Cond {
    Int(i64),
    /// `TRUE` or `FALSE` (a number, 1 or 0, to the player).
    Bool(bool),
    /// A TIME literal (`T#350ms`, `TIME#1s_500ms`, `t#0.35S`), in nanoseconds.
    Time(i64),
    /// A signal, by its name as written.
    Signal(String),
    /// A step's elapsed time `S.t` (also `S.T`): the step's name, lower-cased.
    StepTime(String),
    Not(Box<Cond>),
    Neg(Box<Cond>),
    Bin(CondOp, Box<Cond>, Box<Cond>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CondOp {
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

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    /// A name or a keyword, as written.
    Word(String),
    Int(i64),
    /// A TIME literal, in nanoseconds.
    Time(i64),
    Op(&'static str),
}

/// The duration of a TIME literal's text after its `#` (`1s_500ms`, `0.35S`, `+2s`), in
/// nanoseconds: components `<number><unit>` (d, h, m, s, ms, us, ns; any case) from the largest
/// unit down, `_` between digits and between components, a fraction only on the last.
pub fn time_literal(text: &str) -> i64 {
    const UNITS: &[(&str, i128)] = &[
        ("ms", 1_000_000),
        ("us", 1_000),
        ("ns", 1),
        ("d", 86_400_000_000_000),
        ("h", 3_600_000_000_000),
        ("m", 60_000_000_000),
        ("s", 1_000_000_000),
    ];
    let lower = text.to_ascii_lowercase();
    let mut rest = lower.strip_prefix('+').unwrap_or(&lower);
    let mut total: i128 = 0;
    let mut fraction = false;
    let mut last = i128::MAX;
    while !rest.is_empty() {
        assert!(!fraction, "T#{text}: a fraction only on the last unit");
        rest = rest.trim_start_matches('_');
        let digits = rest
            .find(|c: char| !(c.is_ascii_digit() || c == '_' || c == '.'))
            .unwrap_or_else(|| panic!("T#{text}: a number without a unit"));
        let number = rest[..digits].replace('_', "");
        rest = &rest[digits..];
        let (unit, factor) = *UNITS
            .iter()
            .find(|(u, _)| rest.starts_with(u))
            .unwrap_or_else(|| panic!("T#{text}: no unit at `{rest}`"));
        rest = &rest[unit.len()..];
        assert!(factor < last, "T#{text}: units from days down");
        last = factor;
        let (whole, part) = number.split_once('.').unwrap_or((&number, ""));
        fraction = !part.is_empty();
        let whole: i128 = whole
            .parse()
            .unwrap_or_else(|_| panic!("T#{text}: `{number}`"));
        let scale = 10i128.pow(part.len() as u32);
        let part: i128 = if part.is_empty() {
            0
        } else {
            part.parse().unwrap()
        };
        assert_eq!(
            part * factor % scale,
            0,
            "T#{text}: finer than a nanosecond"
        );
        total += whole * factor + part * factor / scale;
    }
    i64::try_from(total).expect("a duration that fits")
}

fn st_tokens(s: &str) -> Vec<Tok> {
    let c: Vec<char> = s.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < c.len() {
        let ch = c[i];
        if ch.is_whitespace() {
            i += 1;
        } else if ch == '(' && c.get(i + 1) == Some(&'*') {
            // A comment.
            let rest: String = c[i + 2..].iter().collect();
            let end = rest
                .find("*)")
                .unwrap_or_else(|| panic!("unclosed comment in `{s}`"));
            i += 2 + rest[..end].chars().count() + 2;
        } else if ch.is_ascii_alphabetic() || ch == '_' {
            let st = i;
            while i < c.len() && (c[i].is_ascii_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            let word: String = c[st..i].iter().collect();
            let is_time = ["T", "TIME", "LT", "LTIME"]
                .iter()
                .any(|t| t.eq_ignore_ascii_case(&word));
            if is_time && c.get(i) == Some(&'#') {
                i += 1;
                let st = i;
                while i < c.len() && (c[i].is_ascii_alphanumeric() || "_.+".contains(c[i])) {
                    i += 1;
                }
                let lit: String = c[st..i].iter().collect();
                out.push(Tok::Time(time_literal(&lit)));
            } else {
                out.push(Tok::Word(word));
            }
        } else if ch.is_ascii_digit() {
            let st = i;
            while i < c.len() && (c[i].is_ascii_digit() || c[i] == '_') {
                i += 1;
            }
            assert!(
                c.get(i) != Some(&'.') && c.get(i) != Some(&'#'),
                "only plain integers in the charts: `{s}`"
            );
            let n: String = c[st..i].iter().filter(|d| **d != '_').collect();
            out.push(Tok::Int(n.parse().unwrap()));
        } else {
            let two: String = c[i..(i + 2).min(c.len())].iter().collect();
            let op = ["<>", "<=", ">="]
                .into_iter()
                .find(|o| *o == two)
                .or_else(|| {
                    ["(", ")", "=", "<", ">", "-", "&", ".", ";"]
                        .into_iter()
                        .find(|o| o.starts_with(ch))
                })
                .unwrap_or_else(|| panic!("unexpected `{ch}` in the condition `{s}`"));
            i += op.chars().count();
            out.push(Tok::Op(op));
        }
    }
    // One `;` may end a condition.
    if out.last() == Some(&Tok::Op(";")) {
        out.pop();
    }
    out
}

/// ST's precedence, loosest first: `OR`, `XOR`, `AND`/`&`, `=`/`<>`, `<`/`>`/`<=`/`>=`, then
/// `NOT` and unary `-` (IEC 61131-3, table 71: so `NOT a = b` is `(NOT a) = b`).
struct Reader {
    t: Vec<Tok>,
    i: usize,
    text: String,
}

impl Reader {
    fn word(&self, w: &str) -> bool {
        matches!(self.t.get(self.i), Some(Tok::Word(x)) if x.eq_ignore_ascii_case(w))
    }

    fn op(&self, o: &str) -> bool {
        matches!(self.t.get(self.i), Some(Tok::Op(x)) if *x == o)
    }

    /// Operators of one level, each with the text that writes it.
    fn level(&mut self, ops: &[(&str, bool, CondOp)], next: fn(&mut Self) -> Cond) -> Cond {
        let mut l = next(self);
        while let Some((_, _, op)) = ops
            .iter()
            .find(|(t, is_word, _)| if *is_word { self.word(t) } else { self.op(t) })
        {
            self.i += 1;
            let r = next(self);
            l = Cond::Bin(*op, Box::new(l), Box::new(r));
        }
        l
    }

    fn or(&mut self) -> Cond {
        self.level(&[("OR", true, CondOp::Or)], Self::xor)
    }

    fn xor(&mut self) -> Cond {
        self.level(&[("XOR", true, CondOp::Xor)], Self::and)
    }

    fn and(&mut self) -> Cond {
        self.level(
            &[("AND", true, CondOp::And), ("&", false, CondOp::And)],
            Self::equality,
        )
    }

    fn equality(&mut self) -> Cond {
        self.level(
            &[("=", false, CondOp::Eq), ("<>", false, CondOp::Ne)],
            Self::comparison,
        )
    }

    fn comparison(&mut self) -> Cond {
        self.level(
            &[
                ("<=", false, CondOp::Le),
                (">=", false, CondOp::Ge),
                ("<", false, CondOp::Lt),
                (">", false, CondOp::Gt),
            ],
            Self::unary,
        )
    }

    fn unary(&mut self) -> Cond {
        if self.word("NOT") {
            self.i += 1;
            return Cond::Not(Box::new(self.unary()));
        }
        if self.t.get(self.i) == Some(&Tok::Op("-")) {
            self.i += 1;
            return Cond::Neg(Box::new(self.unary()));
        }
        self.primary()
    }

    fn primary(&mut self) -> Cond {
        let t = self
            .t
            .get(self.i)
            .cloned()
            .unwrap_or_else(|| panic!("the condition `{}` ends early", self.text));
        self.i += 1;
        match t {
            Tok::Op("(") => {
                let e = self.or();
                assert!(self.op(")"), "unclosed `(` in `{}`", self.text);
                self.i += 1;
                e
            }
            Tok::Int(n) => Cond::Int(n),
            Tok::Time(ns) => Cond::Time(ns),
            Tok::Word(w) if w.eq_ignore_ascii_case("TRUE") => Cond::Bool(true),
            Tok::Word(w) if w.eq_ignore_ascii_case("FALSE") => Cond::Bool(false),
            Tok::Word(w) => {
                assert!(
                    !["NOT", "AND", "OR", "XOR"]
                        .iter()
                        .any(|k| k.eq_ignore_ascii_case(&w)),
                    "`{w}` where an operand belongs in `{}`",
                    self.text
                );
                if self.op(".") {
                    self.i += 1;
                    match self.t.get(self.i) {
                        Some(Tok::Word(t)) if t.eq_ignore_ascii_case("t") => {
                            self.i += 1;
                            Cond::StepTime(w.to_ascii_lowercase())
                        }
                        other => panic!("`{w}.{other:?}` in `{}`", self.text),
                    }
                } else {
                    Cond::Signal(w)
                }
            }
            other => panic!("{other:?} where an operand belongs in `{}`", self.text),
        }
    }
}

/// What a condition is evaluated under: the inputs of the phase, the clock (milliseconds) and
/// when each step (lower-cased name) last became active; `timed` records whether a step's time
/// was read (else a false condition stays false while the inputs do not change).
pub struct At<'a> {
    pub phase: &'a Phase,
    pub now: i64,
    pub started: &'a BTreeMap<String, i64>,
    pub timed: std::cell::Cell<bool>,
}

/// A value: a number (booleans are 0 and 1) or a duration (nanoseconds).
#[derive(Debug, Clone, Copy, PartialEq)]
enum V {
    N(i64),
    T(i64),
}

impl Cond {
    /// Reads a condition's text (ST).
    pub fn parse(text: &str) -> Cond {
        let mut r = Reader {
            t: st_tokens(text),
            i: 0,
            text: text.to_owned(),
        };
        let e = r.or();
        assert_eq!(r.i, r.t.len(), "trailing text in the condition `{text}`");
        e
    }

    /// Whether the condition holds under `at`.
    pub fn truth(&self, at: &At) -> bool {
        match self.eval(at) {
            V::N(n) => n != 0,
            V::T(_) => panic!("a duration as a condition: {self:?}"),
        }
    }

    fn eval(&self, at: &At) -> V {
        let n = |v: V| match v {
            V::N(n) => n,
            V::T(_) => panic!("a duration where a boolean belongs: {self:?}"),
        };
        match self {
            Cond::Int(i) => V::N(*i),
            Cond::Bool(b) => V::N(*b as i64),
            Cond::Time(ns) => V::T(*ns),
            Cond::Signal(s) => V::N(
                *at.phase
                    .iter()
                    .find(|(k, _)| k.eq_ignore_ascii_case(s))
                    .unwrap_or_else(|| panic!("unknown signal {s}"))
                    .1,
            ),
            Cond::StepTime(s) => {
                at.timed.set(true);
                let since = at
                    .started
                    .get(s)
                    .unwrap_or_else(|| panic!("the time of step {s}, which was never active"));
                V::T((at.now - since) * 1_000_000)
            }
            Cond::Not(a) => V::N((n(a.eval(at)) == 0) as i64),
            Cond::Neg(a) => match a.eval(at) {
                V::N(x) => V::N(-x),
                V::T(_) => panic!("a negative duration: {self:?}"),
            },
            Cond::Bin(op, a, b) => {
                let (x, y) = (a.eval(at), b.eval(at));
                let (x, y) = match (op, x, y) {
                    (CondOp::Or | CondOp::Xor | CondOp::And, x, y) => (n(x), n(y)),
                    (_, V::N(x), V::N(y)) | (_, V::T(x), V::T(y)) => (x, y),
                    _ => panic!("a duration compared with a number: {self:?}"),
                };
                V::N(match op {
                    CondOp::Or => x != 0 || y != 0,
                    CondOp::Xor => (x != 0) != (y != 0),
                    CondOp::And => x != 0 && y != 0,
                    CondOp::Eq => x == y,
                    CondOp::Ne => x != y,
                    CondOp::Lt => x < y,
                    CondOp::Gt => x > y,
                    CondOp::Le => x <= y,
                    CondOp::Ge => x >= y,
                } as i64)
            }
        }
    }
}

struct Player<'a> {
    chart: &'a Chart,
    seq: &'a [Phase],
    actions: Vec<String>,
    /// The clock (milliseconds) and when each step last became active.
    now: i64,
    started: BTreeMap<String, i64>,
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

    /// Waits until `what` holds (the time model of `flow_run.rs`): while it is false the
    /// clock advances by ticks, and it is read again; `false`: stuck (false after waiting
    /// [`STUCK_MS`], or false without reading a step's time, so it stays false).
    fn wait(&mut self, what: impl Fn(&Chart, &At) -> bool) -> bool {
        let since = self.now;
        loop {
            let at = At {
                phase: self.phase(),
                now: self.now,
                started: &self.started,
                timed: std::cell::Cell::new(false),
            };
            if what(self.chart, &at) {
                return true;
            }
            if !at.timed.get() || self.now - since >= STUCK_MS {
                return false;
            }
            self.now += TICK_MS;
        }
    }

    /// Runs from `id` until the flow ends or reaches a simultaneous convergence (returned).
    fn run(&mut self, mut id: u64) -> Stop {
        let c = self.chart;
        let mut moves = 0usize;
        loop {
            moves += 1;
            if self.actions.len() >= crate::max_actions() || moves > 100_000 {
                return Stop::Running;
            }
            let n = &c.nodes[&id];
            let succs = c.succs(id);
            match n.tag.as_str() {
                "step" => {
                    // Active from now; its action takes time.
                    self.started.insert(n.name.to_ascii_lowercase(), self.now);
                    if n.skill {
                        self.actions.push(n.name.clone());
                        self.now += ACTION_MS;
                    }
                    match succs.as_slice() {
                        [] => return Stop::Done,
                        [s] => id = *s,
                        _ => panic!("step with several successors"),
                    }
                }
                "transition" => {
                    if !self.wait(|c, at| c.holds(id, at)) {
                        return Stop::Stuck;
                    }
                    id = succs[0];
                }
                "selectionDivergence" => {
                    // Waits for any branch, then takes the first that holds.
                    if !self.wait(|c, at| succs.iter().any(|t| c.selects(*t, at))) {
                        return Stop::Stuck;
                    }
                    let at = At {
                        phase: self.phase(),
                        now: self.now,
                        started: &self.started,
                        timed: std::cell::Cell::new(false),
                    };
                    let t = *succs.iter().find(|t| c.selects(**t, &at)).unwrap();
                    // A branch that opens another selection (CODESYS) goes on there.
                    id = if c.nodes[&t].tag == "selectionDivergence" {
                        t
                    } else {
                        c.succs(t)[0]
                    };
                }
                "selectionConvergence" | "macroStep" => id = succs[0],
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
                "jumpStep" => id = c.jump_target(id),
                other => panic!("unexpected element {other}"),
            }
        }
    }
}

impl Chart {
    /// The initial steps: those marked `initialStep="true"` without a predecessor (several
    /// begin sequences that run at the same time, docs/INPUTS.md), else the first step without one.
    fn starts(&self) -> Vec<u64> {
        let marked: Vec<u64> = self
            .order
            .iter()
            .copied()
            .filter(|id| {
                let n = &self.nodes[id];
                n.tag == "step" && n.initial && n.inputs.is_empty()
            })
            .collect();
        if marked.is_empty() {
            vec![self.start()]
        } else {
            marked
        }
    }

    fn start(&self) -> u64 {
        *self
            .order
            .iter()
            .find(|id| self.nodes[id].tag == "step" && self.nodes[id].inputs.is_empty())
            .unwrap()
    }

    fn jump_target(&self, jump: u64) -> u64 {
        let target = self.nodes[&jump].target.as_ref().unwrap();
        *self
            .order
            .iter()
            .find(|s| self.nodes[s].tag == "step" && &self.nodes[s].name == target)
            .unwrap()
    }

    /// Whether every jump stays in its simultaneous branch: its target lies in the same
    /// simultaneous branches (the same branch of each enclosing divergence) as the jump. A jump
    /// that enters or leaves a simultaneous branch makes a chart IEC 61131-3 calls unsafe.
    pub fn jumps_stay_in_their_branches(&self) -> bool {
        // Each element's simultaneous branches, from the start along connections.
        let mut ctx: BTreeMap<u64, Vec<(u64, usize)>> = BTreeMap::new();
        let mut todo = vec![(self.start(), Vec::new())];
        while let Some((id, stack)) = todo.pop() {
            if ctx.contains_key(&id) {
                continue;
            }
            ctx.insert(id, stack.clone());
            let n = &self.nodes[&id];
            match n.tag.as_str() {
                "simultaneousDivergence" => {
                    for (k, b) in self.succs(id).into_iter().enumerate() {
                        let mut s = stack.clone();
                        s.push((id, k));
                        todo.push((b, s));
                    }
                }
                "simultaneousConvergence" => {
                    let mut s = stack.clone();
                    s.pop();
                    for x in self.succs(id) {
                        todo.push((x, s.clone()));
                    }
                }
                "jumpStep" => {}
                _ => {
                    for x in self.succs(id) {
                        todo.push((x, stack.clone()));
                    }
                }
            }
        }
        self.order
            .iter()
            .filter(|id| self.nodes[id].tag == "jumpStep")
            .all(|j| ctx.get(j) == ctx.get(&self.jump_target(*j)))
    }

    /// The chart's paths whatever the conditions (every transition may fire, a selection may
    /// take any branch): which actions can come first, which can follow which, and which can
    /// come last when the chart ends (`None`: it ends without an action). An exhaustive search
    /// over the player's states: an element, the simultaneous branches being run (divergence,
    /// branch) and the last action.
    pub fn paths(&self) -> Paths {
        let mut paths = Paths::default();
        type State = (u64, Vec<(u64, usize)>, Option<String>);
        let mut seen: BTreeSet<State> = BTreeSet::new();
        let mut todo: Vec<State> = vec![(self.start(), Vec::new(), None)];
        while let Some(state) = todo.pop() {
            if !seen.insert(state.clone()) {
                continue;
            }
            let (id, stack, last) = state;
            let n = &self.nodes[&id];
            let succs = self.succs(id);
            let mut go = |to: u64, stack: Vec<(u64, usize)>, last: Option<String>| {
                todo.push((to, stack, last));
            };
            match n.tag.as_str() {
                "step" => {
                    let mut last = last;
                    if n.skill {
                        match &last {
                            Some(l) => {
                                paths.pairs.insert((l.clone(), n.name.clone()));
                            }
                            None => {
                                paths.firsts.insert(n.name.clone());
                            }
                        }
                        last = Some(n.name.clone());
                    }
                    match succs.as_slice() {
                        [] => {
                            assert!(stack.is_empty(), "a branch that ends the chart");
                            paths.lasts.insert(last);
                        }
                        [s] => go(*s, stack, last),
                        _ => panic!("step with several successors"),
                    }
                }
                "transition" | "selectionConvergence" | "macroStep" => go(succs[0], stack, last),
                "selectionDivergence" => {
                    for t in succs {
                        let to = if self.nodes[&t].tag == "selectionDivergence" {
                            t
                        } else {
                            self.succs(t)[0]
                        };
                        go(to, stack.clone(), last.clone());
                    }
                }
                "simultaneousDivergence" => {
                    let mut stack = stack;
                    stack.push((id, 0));
                    go(succs[0], stack, last);
                }
                "simultaneousConvergence" => {
                    let mut stack = stack;
                    let (div, k) = stack.pop().expect("a convergence without divergence");
                    let branches = self.succs(div);
                    if k + 1 < branches.len() {
                        stack.push((div, k + 1));
                        go(branches[k + 1], stack, last);
                    } else {
                        go(succs[0], stack, last);
                    }
                }
                "jumpStep" => go(self.jump_target(id), stack, last),
                other => panic!("unexpected element {other}"),
            }
        }
        paths
    }
}

/// See [`Chart::paths`].
#[derive(Debug, Default)]
pub struct Paths {
    pub firsts: BTreeSet<String>,
    pub pairs: BTreeSet<(String, String)>,
    pub lasts: BTreeSet<Option<String>>,
}

pub fn chart_meaning(chart: &Chart, seq: &[Phase]) -> (Vec<String>, Outcome) {
    let (actions, outcome, _) = play(chart, seq);
    (actions, outcome)
}

/// [`chart_meaning`], and the player's clock at the end (milliseconds).
fn play(chart: &Chart, seq: &[Phase]) -> (Vec<String>, Outcome, i64) {
    let mut p = Player {
        chart,
        seq,
        actions: Vec::new(),
        now: 0,
        started: BTreeMap::new(),
    };
    let outcome = match p.run(chart.start()) {
        Stop::Done => Outcome::Done,
        Stop::Stuck => Outcome::Stuck,
        Stop::Running => Outcome::Running,
        Stop::Conv(_) => panic!("a convergence without divergence"),
    };
    (p.actions, outcome, p.now)
}

// ---------------------------------------------------------------------------------------------
// Random charts
// ---------------------------------------------------------------------------------------------

/// Writes random structured charts: sequences with guarded transitions, selections (2 or 3
/// branches, sometimes an empty or unconditional one), simultaneous branches, loops closed by a
/// jump back (left by one branch or by two that join), nested in each other; sometimes the
/// whole chart ends in an endless loop. [`ChartGen::with_step_times`]: the same charts, some
/// of whose transitions also read a step's time.
pub struct ChartGen {
    rng: Rng,
    parts: Vec<String>,
    next: u64,
    /// Each element's tag, inputs, x and part (for the step times, written afterwards).
    elements: BTreeMap<u64, Element>,
}

struct Element {
    tag: &'static str,
    inputs: Vec<u64>,
    x: u64,
    part: usize,
    cond: Option<String>,
}

pub const CONDITIONS: &[&str] = &[
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
    fn new(rng: Rng) -> ChartGen {
        ChartGen {
            rng,
            parts: Vec::new(),
            next: 0,
            elements: BTreeMap::new(),
        }
    }

    /// Records element `id` (its part is the last one written).
    fn record(&mut self, id: u64, tag: &'static str, inputs: &[u64], x: u64, cond: Option<&str>) {
        self.elements.insert(
            id,
            Element {
                tag,
                inputs: inputs.to_vec(),
                x,
                part: self.parts.len() - 1,
                cond: cond.map(str::to_owned),
            },
        );
    }

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
        self.record(id, "step", input.as_slice(), x, None);
        id
    }

    fn trans_part(id: u64, input: u64, cond: Option<&str>, x: u64) -> String {
        let c = cond
            .map(|c| format!("<condition><inline name=\"\"><ST>{c}</ST></inline></condition>"))
            .unwrap_or_default();
        format!(
            "<transition localId=\"{id}\"><position x=\"{x}\" y=\"{id}\"/>{}{c}</transition>",
            Self::conn(&[input])
        )
    }

    fn trans(&mut self, input: u64, cond: Option<&str>, x: u64) -> u64 {
        let id = self.id();
        self.parts.push(Self::trans_part(id, input, cond, x));
        self.record(id, "transition", &[input], x, cond);
        id
    }

    fn node(&mut self, tag: &'static str, inputs: &[u64], x: u64) -> u64 {
        let id = self.id();
        self.parts.push(format!(
            "<{tag} localId=\"{id}\"><position x=\"{x}\" y=\"{id}\"/>{}</{tag}>",
            Self::conn(inputs)
        ));
        self.record(id, tag, inputs, x, None);
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

    /// The random chart of `seed`, not yet written out.
    fn random(seed: u64) -> ChartGen {
        let mut g = ChartGen::new(Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1));
        let start = g.step(None, false, 0);
        let last = g.items(start, 0);
        if g.pick(5) == 0 {
            g.looped(last, 0, true);
        } else {
            let t = g.trans(last, None, 0);
            g.end_step(t);
        }
        g
    }

    pub fn chart(seed: u64) -> String {
        ChartGen::random(seed).document()
    }

    /// The random chart of `seed` ([`ChartGen::chart`]: the same elements) with step times
    /// (IEC 61131-3 `S.t`) in some of its conditions: only in a transition right after a step
    /// (its input, or the divergence of the selection the transition begins a branch of),
    /// reading that step's time; alone or with the signals by `AND`/`OR`, the TIME literals in
    /// their many spellings. The forms: `S.t >= T#100ms` (true once the step's action has run:
    /// the timer must start before the action), `S.t < T#150ms` (true only right after the
    /// action) and `S.t < T#100ms` (false by then) in a selection's first branch, a timeout
    /// `S.t > T#350ms` or `c OR S.t > T#1s` (waits). At most 6 steps' times per chart (KRL's
    /// timers: 8 by default).
    pub fn with_step_times(seed: u64) -> String {
        let mut g = ChartGen::random(seed);
        let mut rng = Rng(seed.wrapping_mul(0xD1B5_4A32_D192_ED03) | 1);
        g.step_times(&mut rng);
        g.document()
    }

    /// Adds step times to the transitions after a step ([`ChartGen::with_step_times`]).
    fn step_times(&mut self, rng: &mut Rng) {
        let rng = std::cell::RefCell::new(rng);
        let pick = |n: u64| rng.borrow_mut().next() % n;
        let name = |e: &BTreeMap<u64, Element>, s: u64| {
            if e[&s].inputs.is_empty() {
                "Start".to_owned()
            } else {
                format!("S{s}")
            }
        };
        let mut timed: BTreeSet<u64> = BTreeSet::new();
        let ids: Vec<u64> = self.elements.keys().copied().collect();
        for t in ids {
            let e = &self.elements[&t];
            if e.tag != "transition" {
                continue;
            }
            let input = e.inputs[0];
            // The step it follows, and its place among the selection's branches (by priority:
            // left to right, ties in document order), with how many there are.
            let (step, branch) = match self.elements[&input].tag {
                "step" => (input, None),
                "selectionDivergence" => {
                    let s = self.elements[&input].inputs[0];
                    if self.elements[&s].tag != "step" {
                        continue;
                    }
                    let mut heads: Vec<(u64, u64)> = self
                        .elements
                        .iter()
                        .filter(|(_, b)| b.tag == "transition" && b.inputs == [input])
                        .map(|(id, b)| (b.x, *id))
                        .collect();
                    heads.sort_unstable();
                    let rank = heads.iter().position(|h| h.1 == t).unwrap();
                    (s, Some((rank, heads.len())))
                }
                _ => continue,
            };
            if pick(5) >= 2 || (!timed.contains(&step) && timed.len() >= 6) {
                continue;
            }
            let st = format!(
                "{}.{}",
                name(&self.elements, step),
                ["t", "T"][pick(2) as usize]
            );
            // A comparison with a TIME literal (of `ms`) in one of its spellings, either way
            // round.
            let cmp = |op: &str, ms: u64| -> String {
                let spellings: &[&str] = match ms {
                    50 => &["T#50ms", "t#0.05s", "TIME#50MS"],
                    100 => &["T#100ms", "t#100MS", "TIME#0.1s", "T#0s_100ms"],
                    150 => &["T#150ms", "T#0.15s", "time#150ms"],
                    350 => &["T#350ms", "t#0.35S", "TIME#350ms"],
                    1000 => &["T#1s", "TIME#1000ms", "t#1S"],
                    1500 => &["T#1s500ms", "T#1.5s", "TIME#1s_500ms"],
                    _ => unreachable!(),
                };
                let lit = spellings[pick(spellings.len() as u64) as usize];
                if pick(4) == 0 {
                    let flipped = match op {
                        "&lt;" => "&gt;",
                        "&gt;" => "&lt;",
                        "&lt;=" => "&gt;=",
                        "&gt;=" => "&lt;=",
                        o => o,
                    };
                    format!("{lit} {flipped} {st}")
                } else {
                    format!("{st} {op} {lit}")
                }
            };
            let c = self.elements[&t].cond.clone();
            let with = |time: String, op: &str| match &c {
                None => time,
                Some(c) if pick(2) == 0 => format!("({c}) {op} {time}"),
                Some(c) => format!("{time} {op} ({c})"),
            };
            let cond = match branch {
                // A selection's first branch (of several).
                Some((0, n)) if n > 1 => match pick(4) {
                    0 => with(cmp("&gt;=", 100), "AND"),
                    1 => with(cmp("&lt;", 150), "AND"),
                    2 => with(cmp("&lt;", 100), "AND"),
                    _ => cmp("&gt;=", 100),
                },
                // A later branch: a timeout.
                Some(_) => match pick(3) {
                    0 => cmp("&gt;", 350),
                    1 => with(cmp("&gt;", 1000), "OR"),
                    _ => with(cmp("&gt;=", 100), "AND"),
                },
                // A wait.
                None => match pick(5) {
                    0 => with(cmp("&gt;=", 100), "AND"),
                    1 => with(cmp("&gt;", 350), "AND"),
                    2 => with(cmp("&gt;", 1500), "OR"),
                    3 => with(cmp("&lt;", 150), "AND"),
                    _ => cmp("&lt;&gt;", 50),
                },
            };
            timed.insert(step);
            let e = &self.elements[&t];
            let part = ChartGen::trans_part(t, input, Some(&cond), e.x);
            let k = e.part;
            self.parts[k] = part;
            self.elements.get_mut(&t).unwrap().cond = Some(cond);
        }
    }

    /// A chart that reads each of `conditions` (ST, XML-escaped) in three ways: a selection
    /// between it and an unconditional branch; a selection between it and its negation (no
    /// unconditional branch: the program waits for either); then, after all of those, a wait
    /// for each.
    pub fn conditions(conditions: &[&str]) -> String {
        let mut g = ChartGen::new(Rng(1));
        let mut tail = g.step(None, false, 0);
        for c in conditions {
            let negated = format!("NOT ({c})");
            for other in [None, Some(negated.as_str())] {
                let div = g.node("selectionDivergence", &[tail], 0);
                let mut ends = Vec::new();
                for (x, cond) in [(0, Some(*c)), (10, other)] {
                    let t = g.trans(div, cond, x);
                    let s = g.step(Some(t), true, x);
                    ends.push(g.trans(s, None, x));
                }
                let conv = g.node("selectionConvergence", &ends, 0);
                tail = g.step(Some(conv), true, 0);
            }
        }
        for c in conditions {
            let t = g.trans(tail, Some(c), 0);
            tail = g.step(Some(t), true, 0);
        }
        let t = g.trans(tail, None, 0);
        g.end_step(t);
        g.document()
    }

    /// A chart whose step `S5` must be timed exactly: `Start`, `S3`, then a loop: `S5`, a
    /// selection whose first branch, `S5.t >= T#100ms AND S5.t < T#150ms`, holds only right
    /// after `S5`'s action (so only when `S5`'s time starts right before its action, anew in
    /// each round), `S8` and round again; else (`TRUE`) `S12`, a wait `S12.t > T#350ms`, the
    /// end.
    pub fn step_time_loop() -> String {
        let mut g = ChartGen::new(Rng(1));
        let start = g.step(None, false, 0);
        let t = g.trans(start, None, 0);
        let a = g.step(Some(t), true, 0);
        let t = g.trans(a, None, 0);
        let l = g.step(Some(t), true, 0);
        let div = g.node("selectionDivergence", &[l], 0);
        let c = format!("S{l}.t &gt;= T#100ms AND S{l}.t &lt; T#150ms");
        let t1 = g.trans(div, Some(&c), 0);
        let x = g.step(Some(t1), true, 0);
        let tx = g.trans(x, None, 0);
        g.jump(tx, l);
        let t2 = g.trans(div, None, 10);
        let y = g.step(Some(t2), true, 10);
        let ty = g.trans(y, Some(&format!("S{y}.t &gt; T#350ms")), 10);
        g.end_step(ty);
        assert_eq!((a, l, x, y), (3, 5, 8, 12));
        g.document()
    }

    /// The end step after transition `t`.
    fn end_step(&mut self, t: u64) {
        let id = self.id();
        self.parts.push(format!(
            "<step localId=\"{id}\" name=\"End\"><position x=\"0\" y=\"{id}\"/>{}</step>",
            ChartGen::conn(&[t])
        ));
        self.record(id, "end", &[t], 0, None);
    }

    fn document(&self) -> String {
        format!(
            "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<project xmlns=\"http://www.plcopen.org/xml/tc6_0201\"><fileHeader companyName=\"t\" productName=\"random\" productVersion=\"1\" creationDateTime=\"2026-11-23T08:00:00\"/><types><pous><pou name=\"R\" pouType=\"program\"><body><SFC>\n{}\n</SFC></body></pou></pous></types></project>\n",
            self.parts.join("\n")
        )
    }
}

// ---------------------------------------------------------------------------------------------
// Explaining what several controllers did (the cell co-simulation, `flow_run/cosim.rs`)
// ---------------------------------------------------------------------------------------------

/// One action of a run of the chart and the actions the chart puts right before it (indexes
/// into the run): the steps of the transitions, convergences and jumps that lead to it.
pub type Caused = (String, Vec<usize>);

/// A token of the search: the element it is about to enter, and the actions right before it.
#[derive(Clone)]
struct Token {
    id: u64,
    frontier: Vec<usize>,
}

/// A state of the search: the tokens, the simultaneous convergences being waited at (how
/// many branches arrived, their frontiers), how many actions of each controller the run has
/// taken, and the run so far.
#[derive(Clone)]
struct Marking {
    tokens: Vec<Token>,
    waiting: BTreeMap<u64, (usize, Vec<usize>)>,
    taken: Vec<usize>,
    run: Vec<Caused>,
}

impl Chart {
    /// Moves every token that has one way to go until each stands before a step with a skill
    /// or a selection (or has ended); `false` when a token goes round without end.
    fn settle(&self, m: &mut Marking) -> bool {
        let mut k = 0;
        let mut moves = 0;
        while k < m.tokens.len() {
            moves += 1;
            if moves > 10_000 {
                return false;
            }
            let id = m.tokens[k].id;
            let n = &self.nodes[&id];
            let succs = self.succs(id);
            match n.tag.as_str() {
                "step" if n.skill => k += 1,
                "selectionDivergence" => k += 1,
                "step" => match succs.as_slice() {
                    [] => {
                        m.tokens.remove(k);
                    }
                    [s] => m.tokens[k].id = *s,
                    _ => panic!("step with several successors"),
                },
                "transition" | "selectionConvergence" => m.tokens[k].id = succs[0],
                "jumpStep" => m.tokens[k].id = self.jump_target(id),
                "simultaneousDivergence" => {
                    let t = m.tokens.remove(k);
                    for (j, s) in succs.iter().enumerate() {
                        m.tokens.insert(
                            k + j,
                            Token {
                                id: *s,
                                frontier: t.frontier.clone(),
                            },
                        );
                    }
                }
                "simultaneousConvergence" => {
                    let t = m.tokens.remove(k);
                    let inputs = self.nodes[&id].inputs.len();
                    let w = m.waiting.entry(id).or_default();
                    w.0 += 1;
                    w.1.extend(t.frontier);
                    if w.0 == inputs {
                        let (_, frontier) = m.waiting.remove(&id).unwrap();
                        m.tokens.insert(
                            k,
                            Token {
                                id: succs[0],
                                frontier,
                            },
                        );
                    }
                }
                other => panic!("unexpected element {other}"),
            }
        }
        true
    }

    /// A run of the chart by its meaning (IEC 61131-3: simultaneous branches run at the same
    /// time; a selection takes any branch, a wait fires at any time) whose actions, taken one
    /// controller at a time (`controller` of a step name → index), are exactly `seen` (what
    /// each controller did, in its order); `ended`: every program ran to its end, so the run
    /// must reach the chart's end without another action. `None` when there is none: the
    /// controllers did not do what one run of the chart does.
    pub fn explain(
        &self,
        seen: &[Vec<String>],
        controller: &dyn Fn(&str) -> usize,
        ended: bool,
    ) -> Option<Vec<Caused>> {
        let total: usize = seen.iter().map(Vec::len).sum();
        type Key = (Vec<u64>, Vec<(u64, usize)>, Vec<usize>);
        let mut visited: BTreeSet<Key> = BTreeSet::new();
        let mut todo = vec![Marking {
            tokens: self
                .starts()
                .into_iter()
                .map(|id| Token {
                    id,
                    frontier: Vec::new(),
                })
                .collect(),
            waiting: BTreeMap::new(),
            taken: vec![0; seen.len()],
            run: Vec::new(),
        }];
        while let Some(mut m) = todo.pop() {
            if !self.settle(&mut m) {
                continue;
            }
            let mut ids: Vec<u64> = m.tokens.iter().map(|t| t.id).collect();
            ids.sort_unstable();
            let key = (
                ids,
                m.waiting.iter().map(|(k, v)| (*k, v.0)).collect(),
                m.taken.clone(),
            );
            if !visited.insert(key) {
                continue;
            }
            let all = m.run.len() == total;
            if all && (!ended || m.tokens.is_empty()) {
                return Some(m.run);
            }
            // A selection first: its choice does not depend on anything else that can move.
            if let Some(k) = m
                .tokens
                .iter()
                .position(|t| self.nodes[&t.id].tag == "selectionDivergence")
            {
                for t in self.succs(m.tokens[k].id).iter().rev() {
                    let mut b = m.clone();
                    b.tokens[k].id = self.succs(*t)[0];
                    todo.push(b);
                }
                continue;
            }
            if all {
                // Ended: another action is not allowed.
                continue;
            }
            for k in (0..m.tokens.len()).rev() {
                let name = &self.nodes[&m.tokens[k].id].name;
                let c = controller(name);
                if seen[c].get(m.taken[c]) != Some(name) {
                    continue;
                }
                let mut b = m.clone();
                b.taken[c] += 1;
                let preds = std::mem::take(&mut b.tokens[k].frontier);
                b.run.push((name.clone(), preds));
                b.tokens[k].frontier = vec![b.run.len() - 1];
                match self.succs(b.tokens[k].id).as_slice() {
                    [] => {
                        b.tokens.remove(k);
                    }
                    [s] => b.tokens[k].id = *s,
                    _ => panic!("step with several successors"),
                }
                todo.push(b);
            }
        }
        None
    }
}

// ---------------------------------------------------------------------------------------------
// The player's time
// ---------------------------------------------------------------------------------------------

/// TIME literals in their spellings: components from days down to nanoseconds, any case, `_`
/// between them, a fraction on the last; malformed ones are refused.
#[test]
fn the_player_reads_time_literals() {
    const MS: i64 = 1_000_000;
    for (lit, ns) in [
        ("350ms", 350 * MS),
        ("2s", 2_000 * MS),
        ("1s500ms", 1_500 * MS),
        ("1s_500ms", 1_500 * MS),
        ("100MS", 100 * MS),
        ("1.5s", 1_500 * MS),
        ("0.35S", 350 * MS),
        ("1m30s", 90_000 * MS),
        ("1h", 3_600_000 * MS),
        ("1d2h", 93_600_000 * MS),
        ("+2s", 2_000 * MS),
        ("1_000ms", 1_000 * MS),
        ("350.5ms", 350_500_000),
        ("1us", 1_000),
        ("7ns", 7),
    ] {
        assert_eq!(time_literal(lit), ns, "T#{lit}");
    }
    let started = BTreeMap::new();
    let phase = Phase::new();
    for (text, holds) in [
        ("T#350ms = TIME#0.35s", true),
        ("t#100MS < T#1s", true),
        ("TIME#4s >= LT#4000ms", true),
        ("T#1s500ms <> T#1.5s", false),
        ("LTIME#1m > T#59s999ms", true),
    ] {
        let at = At {
            phase: &phase,
            now: 0,
            started: &started,
            timed: Default::default(),
        };
        assert_eq!(Cond::parse(text).truth(&at), holds, "{text}");
        assert!(!at.timed.get(), "{text} reads no step's time");
    }
    for bad in ["5", "5x", "1.5s2ms", "s", "1s1m", "ms5"] {
        let r = std::panic::catch_unwind(|| time_literal(bad));
        assert!(r.is_err(), "T#{bad} is no TIME literal");
    }
}

/// A step's time `S.t` (also `S.T`, the step's name in any case) is the time since the step
/// last became active, compared with a TIME literal on either side; a duration is no number.
#[test]
fn the_player_reads_step_times() {
    let phase: Phase = [("Part_OK", 1), ("Release", 0)].into_iter().collect();
    let started: BTreeMap<String, i64> = [("grip".to_owned(), 1_000)].into_iter().collect();
    let at = || At {
        phase: &phase,
        now: 1_350,
        started: &started,
        timed: Default::default(),
    };
    for (text, holds) in [
        ("Grip.t > T#350ms", false),
        ("Grip.t >= T#350ms", true),
        ("grip.T = T#0.35s", true),
        ("T#350ms <> GRIP.t", false),
        ("T#349ms < Grip.t AND Part_OK", true),
        ("Grip.t < T#350ms OR Release", false),
        ("NOT (Grip.t <= T#349ms) AND NOT Release", true),
        ("T#1s < Grip.t OR Part_OK (* a comment *);", true),
    ] {
        let a = at();
        assert_eq!(Cond::parse(text).truth(&a), holds, "{text}");
        assert!(a.timed.get(), "{text} reads a step's time");
    }
    for bad in [
        "Grip.t > 350",
        "Grip.t AND Part_OK",
        "Grip.t",
        "Lift.t > T#1s",
    ] {
        let r = std::panic::catch_unwind(|| Cond::parse(bad).truth(&at()));
        assert!(r.is_err(), "`{bad}` is no condition the player accepts");
    }
}

/// The player keeps the time: a step becomes active before its action, which takes
/// [`ACTION_MS`]; a wait reads its condition every [`TICK_MS`] until it holds; a selection waits
/// for any branch, then takes the first that holds; a wait on a step's time that cannot come
/// true is stuck after [`STUCK_MS`], one on the inputs alone at once.
#[test]
fn the_player_keeps_time() {
    let mut g = ChartGen::new(Rng(1));
    let start = g.step(None, false, 0);
    let t = g.trans(start, None, 0);
    let a = g.step(Some(t), true, 0);
    let t = g.trans(a, Some(&format!("S{a}.t &gt; T#350ms")), 0);
    let b = g.step(Some(t), true, 0);
    let div = g.node("selectionDivergence", &[b], 0);
    let t1 = g.trans(div, Some(&format!("S{b}.t &lt; T#150ms AND Part_OK")), 0);
    let c = g.step(Some(t1), true, 0);
    let c_end = g.trans(c, None, 0);
    let t2 = g.trans(div, Some(&format!("T#1s &lt; S{b}.T OR Release")), 10);
    let d = g.step(Some(t2), true, 10);
    let d_end = g.trans(d, None, 10);
    let conv = g.node("selectionConvergence", &[c_end, d_end], 0);
    let e = g.step(Some(conv), true, 0);
    let t = g.trans(e, Some(&format!("S{e}.t &lt; T#50ms")), 0);
    g.end_step(t);
    let chart = Chart::parse(&g.document());
    let names = |v: &[u64]| -> Vec<String> { v.iter().map(|s| format!("S{s}")).collect() };
    let phase = |part: i64, release: i64| -> Vec<Phase> {
        vec![
            [("Part_OK", part), ("Release", release)]
                .into_iter()
                .collect(),
        ]
    };
    // A: 0-100, the wait until A.t > 350 ms: 360; B: 360-460; neither branch: the timeout at
    // B.t = 1010 ms, 1370; D: 1370-1470, E: 1470-1570; E.t < 50 ms never: stuck 10 s later.
    assert_eq!(
        play(&chart, &phase(0, 0)),
        (names(&[a, b, d, e]), Outcome::Stuck, 11_570)
    );
    // Part_OK right after B's action (B.t = 100 ms < 150 ms): the first branch.
    assert_eq!(
        play(&chart, &phase(1, 0)),
        (names(&[a, b, c, e]), Outcome::Stuck, 10_660)
    );
    assert_eq!(
        play(&chart, &phase(0, 1)),
        (names(&[a, b, d, e]), Outcome::Stuck, 10_660)
    );
    // A wait on the inputs alone: stuck at once.
    let mut g = ChartGen::new(Rng(1));
    let start = g.step(None, false, 0);
    let t = g.trans(start, None, 0);
    let a = g.step(Some(t), true, 0);
    let t = g.trans(a, Some("Part_OK"), 0);
    g.end_step(t);
    let chart = Chart::parse(&g.document());
    assert_eq!(
        play(&chart, &phase(0, 0)),
        (names(&[a]), Outcome::Stuck, ACTION_MS)
    );
    assert_eq!(
        play(&chart, &phase(1, 0)),
        (names(&[a]), Outcome::Done, ACTION_MS)
    );
}
