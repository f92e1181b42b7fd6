//! The chart's meaning (a token player over the SFC graph, IEC 61131-3) and the generator of
//! random structured charts; shared by every language.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use skillpost::cond::{BinOp, Expr as StExpr, ExprKind};

use crate::{MAX_ACTIONS, Outcome, Phase, Rng};

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

pub struct Chart {
    nodes: BTreeMap<u64, Node>,
    /// Document order of the ids.
    order: Vec<u64>,
    /// Successors, left to right by x, ties in document order.
    succ: BTreeMap<u64, Vec<u64>>,
    /// Parsed conditions.
    conds: BTreeMap<u64, StExpr>,
}

impl Chart {
    pub fn read(path: &Path) -> Chart {
        let text = std::fs::read_to_string(path).unwrap();
        let doc = roxmltree::Document::parse(&text).unwrap();
        let sfc = doc
            .descendants()
            .find(|n| n.is_element() && n.tag_name().name() == "SFC")
            .expect("an SFC body");
        let mut nodes = BTreeMap::new();
        let mut order = Vec::new();
        // The chart's elements and, in a macro step's place, its body's (SPEC.md 3): each macro
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

    /// Whether a selection branch that starts with `head` is selected: its transition holds,
    /// or, when it opens another selection, one of that selection's branches is selected.
    fn selects(&self, head: u64, phase: &Phase) -> bool {
        if self.nodes[&head].tag == "selectionDivergence" {
            self.succs(head).into_iter().any(|h| self.selects(h, phase))
        } else {
            self.holds(head, phase)
        }
    }

    fn holds(&self, transition: u64, phase: &Phase) -> bool {
        match self.conds.get(&transition) {
            None => true,
            Some(e) => st_eval(e, phase) != 0,
        }
    }
}

/// Evaluates a condition with ST's meaning (the parser's tree already has ST's precedence).
pub fn st_eval(e: &StExpr, phase: &Phase) -> i64 {
    match &e.kind {
        ExprKind::Bool(b) => *b as i64,
        ExprKind::Int(s) => s.parse().unwrap(),
        ExprKind::Real(_) => panic!("no decimals in the fixtures"),
        ExprKind::Time(_) => panic!("step times are not played yet"),
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
                    if !c.holds(id, self.phase()) {
                        return Stop::Stuck;
                    }
                    id = succs[0];
                }
                "selectionDivergence" => {
                    let t = match succs.iter().find(|t| c.selects(**t, self.phase())) {
                        Some(t) => *t,
                        None => return Stop::Stuck,
                    };
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
    let mut p = Player {
        chart,
        seq,
        actions: Vec::new(),
    };
    let outcome = match p.run(chart.start()) {
        Stop::Done => Outcome::Done,
        Stop::Stuck => Outcome::Stuck,
        Stop::Running => Outcome::Running,
        Stop::Conv(_) => panic!("a convergence without divergence"),
    };
    (p.actions, outcome)
}

// ---------------------------------------------------------------------------------------------
// Random charts
// ---------------------------------------------------------------------------------------------

/// Writes random structured charts: sequences with guarded transitions, selections (2 or 3
/// branches, sometimes an empty or unconditional one), simultaneous branches, loops closed by a
/// jump back (left by one branch or by two that join), nested in each other; sometimes the
/// whole chart ends in an endless loop.
pub struct ChartGen {
    rng: Rng,
    parts: Vec<String>,
    next: u64,
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

    pub fn chart(seed: u64) -> String {
        let mut g = ChartGen {
            rng: Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1),
            parts: Vec::new(),
            next: 0,
        };
        let start = g.step(None, false, 0);
        let last = g.items(start, 0);
        if g.pick(5) == 0 {
            g.looped(last, 0, true);
            g.document()
        } else {
            let t = g.trans(last, None, 0);
            g.end(t)
        }
    }

    /// A chart that reads each of `conditions` (ST, XML-escaped) in three ways: a selection
    /// between it and an unconditional branch; a selection between it and its negation (no
    /// unconditional branch: the program waits for either); then, after all of those, a wait
    /// for each.
    pub fn conditions(conditions: &[&str]) -> String {
        let mut g = ChartGen {
            rng: Rng(1),
            parts: Vec::new(),
            next: 0,
        };
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
        g.end(t)
    }

    /// The end step after transition `t`, and the whole document.
    fn end(mut self, t: u64) -> String {
        let id = self.id();
        self.parts.push(format!(
            "<step localId=\"{id}\" name=\"End\"><position x=\"0\" y=\"{id}\"/>{}</step>",
            ChartGen::conn(&[t])
        ));
        self.document()
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
            tokens: vec![Token {
                id: self.start(),
                frontier: Vec::new(),
            }],
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
