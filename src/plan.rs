//! SFC graph checks and the ordered program tree (SPEC.md sections 3 and 3.1).
//!
//! [`plan`] runs in parts, each with its own tests: [`graph`] (ids and connections),
//! [`check_nodes`] (each element's inputs and outputs), [`resolve_jumps`] (jump targets),
//! [`start_end`] (found after the jumps are resolved), [`find_cycle`] (a cycle of connections,
//! not of jumps) and the walk, which recognises the structure: sequences, guarded transitions
//! ([`Block::Wait`]), simultaneous branches ([`Block::Parallel`]), selection branches
//! ([`Block::Choice`]) and loops closed by a jump back ([`Block::Loop`]). Branches are in
//! emission order: left to right by the x of each branch head, ties in document order; for
//! selections that order is their priority.

use std::collections::HashMap;
use std::sync::Arc;

use crate::diag::{Code, Diagnostic, Diagnostics, Span};
use crate::model::{ElementKind, Sfc};

/// Branches and loops nest at most this deep.
pub const MAX_NESTING: usize = 128;

/// One entry of the program tree. Indexes are into [`Sfc::elements`].
#[derive(Debug, Clone, PartialEq)]
pub enum Block {
    /// A step.
    Step(usize),
    /// A transition with a condition in a sequence: the program waits until it holds.
    Wait(usize),
    /// Simultaneous branches, in emission order. On one robot they run one after another.
    Parallel {
        divergence: usize,
        convergence: usize,
        branches: Vec<Vec<Block>>,
    },
    /// Selection branches in priority order: the first whose first transition's condition
    /// holds is taken. `convergence` is `None` for the selection that decides a loop when its
    /// branches do not join again.
    Choice {
        divergence: usize,
        convergence: Option<usize>,
        branches: Vec<Branch>,
    },
    /// A loop back to the step `head` (the body's first block). It repeats until a branch of
    /// its last block (a [`Block::Choice`]) ends in [`BranchEnd::Leave`]; `endless` when none
    /// does (a cyclic chart).
    Loop {
        head: usize,
        /// The jumpSteps that close the loop.
        jumps: Vec<usize>,
        body: Vec<Block>,
        endless: bool,
    },
}

/// One selection branch.
#[derive(Debug, Clone, PartialEq)]
pub struct Branch {
    /// The branch's first transition: its condition selects the branch.
    pub transition: usize,
    /// What runs after the transition fired.
    pub body: Vec<Block>,
    pub end: BranchEnd,
}

/// How a selection branch ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BranchEnd {
    /// At the selection's convergence: the program goes on after it.
    Join,
    /// In a jump (the element) back to the enclosing loop's head: the loop goes round again.
    Repeat(usize),
    /// The loop is left: the program goes on after it.
    Leave,
}

/// The planned program.
#[derive(Debug)]
pub struct Plan {
    /// The whole flow, start and end steps included.
    pub body: Vec<Block>,
    /// The start step.
    pub start: usize,
    /// The end step; `None` for a cyclic chart (it ends in jumps only).
    pub end: Option<usize>,
}

impl Plan {
    /// Steps in program order (each once; loop bodies once).
    pub fn steps(&self) -> Vec<usize> {
        let mut out = Vec::new();
        visit(&self.body, &mut |b| {
            if let Block::Step(i) = b {
                out.push(*i);
            }
        });
        out
    }
}

/// Calls `f` for every block, depth first in program order.
pub fn visit(blocks: &[Block], f: &mut dyn FnMut(&Block)) {
    for b in blocks {
        f(b);
        match b {
            Block::Step(_) | Block::Wait(_) => {}
            Block::Parallel { branches, .. } => {
                for br in branches {
                    visit(br, f);
                }
            }
            Block::Choice { branches, .. } => {
                for br in branches {
                    visit(&br.body, f);
                }
            }
            Block::Loop { body, .. } => visit(body, f),
        }
    }
}

/// The flow graph: predecessors and successors by element index, in compact (CSR) form: one
/// array of edges per direction and an offset per element.
#[derive(Debug, Default)]
pub struct Graph {
    pred_at: Vec<usize>,
    pred: Vec<usize>,
    succ_at: Vec<usize>,
    succ: Vec<usize>,
}

impl Graph {
    /// The elements connected into element `i`.
    pub fn preds(&self, i: usize) -> &[usize] {
        &self.pred[self.pred_at[i]..self.pred_at[i + 1]]
    }

    /// The elements element `i` connects to.
    pub fn succs(&self, i: usize) -> &[usize] {
        &self.succ[self.succ_at[i]..self.succ_at[i + 1]]
    }

    /// The number of elements.
    pub fn len(&self) -> usize {
        self.pred_at.len().saturating_sub(1)
    }

    /// Whether there are no elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Finds elements by localId: a direct table when the ids are dense (as planning tools write
/// them), a hash map otherwise.
enum Ids {
    Dense(Vec<u32>),
    Sparse(HashMap<u64, usize>),
}

impl Ids {
    const NONE: u32 = u32::MAX;

    fn new(sfc: &Sfc) -> Self {
        let n = sfc.elements.len();
        let max = sfc.elements.iter().map(|e| e.local_id).max().unwrap_or(0);
        if n < Self::NONE as usize && max < (4 * n as u64 + 1024) {
            Ids::Dense(vec![Self::NONE; max as usize + 1])
        } else {
            Ids::Sparse(HashMap::with_capacity(n))
        }
    }

    fn get(&self, id: u64) -> Option<usize> {
        match self {
            Ids::Dense(t) => t
                .get(id as usize)
                .copied()
                .filter(|&v| v != Self::NONE)
                .map(|v| v as usize),
            Ids::Sparse(m) => m.get(&id).copied(),
        }
    }

    fn insert(&mut self, id: u64, i: usize) {
        match self {
            Ids::Dense(t) => t[id as usize] = i as u32,
            Ids::Sparse(m) => {
                m.insert(id, i);
            }
        }
    }
}

/// Builds the graph and reports duplicate and dangling ids. Connections that name nothing are
/// dropped from the graph, and so are repeated ones.
pub fn graph(sfc: &Sfc, diags: &mut Diagnostics) -> Graph {
    let n = sfc.elements.len();
    let mut ids = Ids::new(sfc);
    for (i, e) in sfc.elements.iter().enumerate() {
        if let Some(first) = ids.get(e.local_id) {
            diags.push(
                Diagnostic::error(
                    Code::BadLocalId,
                    format!("localId {} is used twice", e.local_id),
                )
                .at(e.span.clone())
                .element(format!("localId {}", e.local_id))
                .related(sfc.elements[first].span.clone(), "first used here"),
            );
        } else {
            ids.insert(e.local_id, i);
        }
    }
    // Edges (producer, consumer), predecessors in document order of the connections.
    let mut pred_at = Vec::with_capacity(n + 1);
    let mut pred = Vec::with_capacity(n);
    let mut succ_count = vec![0usize; n];
    for e in sfc.elements.iter() {
        pred_at.push(pred.len());
        let first = pred.len();
        for (r, range) in &e.inputs {
            match ids.get(*r) {
                Some(p) => {
                    if !pred[first..].contains(&p) {
                        pred.push(p);
                        succ_count[p] += 1;
                    }
                }
                None => diags.push(
                    Diagnostic::error(
                        Code::DanglingReference,
                        format!("refLocalId {r} names no element"),
                    )
                    .at(Span::new(sfc.file, range.clone()))
                    .element(format!("localId {}", e.local_id)),
                ),
            }
        }
    }
    pred_at.push(pred.len());
    // Successors: counting sort by producer; consumers in element order.
    let mut succ_at = Vec::with_capacity(n + 1);
    let mut total = 0;
    for c in &succ_count {
        succ_at.push(total);
        total += c;
    }
    succ_at.push(total);
    let mut fill = succ_at.clone();
    let mut succ = vec![0usize; total];
    for i in 0..n {
        for &p in &pred[pred_at[i]..pred_at[i + 1]] {
            succ[fill[p]] = i;
            fill[p] += 1;
        }
    }
    Graph {
        pred_at,
        pred,
        succ_at,
        succ,
    }
}

/// Checks the graph rules and builds the program tree. `None` when the flow has errors (all of
/// them reported).
pub fn plan(sfc: &Sfc, diags: &mut Diagnostics) -> Option<Plan> {
    let errors_before = diags.error_count();
    let el = &sfc.elements;
    if !el.iter().any(|e| e.kind.is_step()) {
        // The root cause, once: no start, no end and no steps are one fault.
        diags.push(
            Diagnostic::error(Code::StartStep, "the SFC body has no steps")
                .at_opt(sfc.span.clone()),
        );
        return None;
    }
    let g = graph(sfc, diags);
    let secondary = check_nodes(sfc, &g, diags);
    let jumps = resolve_jumps(sfc, diags);
    let ends = start_end(sfc, &g, &jumps, diags);
    if let Some(c) = find_cycle(&g) {
        diags.push(
            Diagnostic::error(
                Code::Cycle,
                "the flow has a cycle of connections through this element; close loops with a jumpStep back to the step",
            )
            .at(el[c].span.clone())
            .element(label(sfc, c)),
        );
    }
    if diags.error_count() == errors_before {
        for d in secondary {
            diags.push(d);
        }
    }
    if diags.error_count() > errors_before {
        return None;
    }
    let (start, end) = ends?;
    walk(sfc, &g, &jumps, start, diags).map(|body| Plan { body, start, end })
}

fn label(sfc: &Sfc, i: usize) -> String {
    format!("localId {}", sfc.elements[i].local_id)
}

/// Checks each element's inputs and outputs. Returns the diagnostics that are often a
/// consequence of another fault, to be reported only when there is no other error.
pub fn check_nodes(sfc: &Sfc, g: &Graph, diags: &mut Diagnostics) -> Vec<Diagnostic> {
    let el = &sfc.elements;
    let id = |i: usize| label(sfc, i);
    let mut secondary = Vec::new();
    for (i, e) in el.iter().enumerate() {
        let (np, ns) = (g.preds(i).len(), g.succs(i).len());
        let err = |code: Code, msg: String| {
            Diagnostic::error(code, msg)
                .at(e.span.clone())
                .element(id(i))
        };
        match &e.kind {
            ElementKind::MacroStep => {
                diags.push(err(
                    Code::Unsupported,
                    "macroStep is not supported yet".to_owned(),
                ));
            }
            ElementKind::JumpStep(_) => {
                if np != 1 {
                    diags.push(err(
                        Code::BadJump,
                        format!("jumpStep has {np} inputs; it follows exactly one transition"),
                    ));
                }
                if ns > 0 {
                    diags.push(err(
                        Code::BadJump,
                        format!(
                            "jumpStep is followed by {} ({}); a jump ends its branch",
                            ns,
                            list_ids(sfc, g.succs(i))
                        ),
                    ));
                }
            }
            ElementKind::Step(_) => {
                if np > 1 || ns > 1 {
                    let (what, n) = if np > 1 {
                        ("predecessors", np)
                    } else {
                        ("successors", ns)
                    };
                    diags.push(err(
                        Code::StepFanInOut,
                        format!(
                            "step has {n} {what}; a step has at most one (branches need a divergence or convergence)"
                        ),
                    ));
                }
                for &p in g.preds(i) {
                    if el[p].kind.is_step() {
                        diags.push(err(
                            Code::StepToStep,
                            format!(
                                "step follows step localId {} without a transition between them",
                                el[p].local_id
                            ),
                        ));
                    }
                }
            }
            kind => {
                let unbalanced = |msg: String| err(Code::UnbalancedBranch, msg);
                let tag = kind.tag();
                if np > 1 && ns > 1 {
                    diags.push(err(
                        Code::NToM,
                        format!(
                            "{tag} joins {np} inputs and splits into {ns} outputs at once; use a convergence and a divergence"
                        ),
                    ));
                } else {
                    let (sim, div) = match kind {
                        ElementKind::SimultaneousDivergence => (true, true),
                        ElementKind::SimultaneousConvergence => (true, false),
                        ElementKind::SelectionDivergence => (false, true),
                        ElementKind::SelectionConvergence => (false, false),
                        _ => (false, false),
                    };
                    let branches = if sim { "simultaneous" } else { "selection" };
                    let opens = if sim {
                        "a simultaneousDivergence"
                    } else {
                        "a selectionDivergence"
                    };
                    let closes = if sim {
                        "a simultaneousConvergence"
                    } else {
                        "a selectionConvergence"
                    };
                    match kind {
                        // Often a consequence of another fault (a cycle, a second start):
                        // reported only when the flow has no other error.
                        ElementKind::Transition(_) if ns > 1 => secondary.push(unbalanced(format!(
                            "transition splits into {ns} outputs ({}); branches start with a simultaneousDivergence or a selectionDivergence",
                            list_ids(sfc, g.succs(i))
                        ))),
                        ElementKind::Transition(_) if np > 1 => secondary.push(unbalanced(format!(
                            "transition joins {np} inputs ({}); branches end with a simultaneousConvergence or a selectionConvergence",
                            list_ids(sfc, g.preds(i))
                        ))),
                        ElementKind::Transition(_) => {}
                        _ if div && np > 1 => {
                            diags.push(unbalanced(format!("{tag} has {np} inputs; it must have one")))
                        }
                        _ if div && ns == 1 => diags.push(unbalanced(format!(
                            "{tag} opens only one branch"
                        ))),
                        _ if !div && ns > 1 => diags.push(unbalanced(format!(
                            "{tag} has {ns} outputs; it must have one"
                        ))),
                        _ if !div && np == 1 => diags.push(unbalanced(format!(
                            "{tag} joins only one branch: {opens} opens {branches} branches and {closes} joins them"
                        ))),
                        _ => {}
                    }
                    if matches!(kind, ElementKind::SelectionDivergence) {
                        for &h in g.succs(i) {
                            if !matches!(el[h].kind, ElementKind::Transition(_)) {
                                diags.push(unbalanced(format!(
                                    "selection branch starts with {} localId {}; each selection branch starts with a transition (its condition)",
                                    el[h].kind.tag(),
                                    el[h].local_id
                                )));
                            }
                        }
                    }
                }
                if np == 0 {
                    diags.push(err(
                        Code::StartStep,
                        format!("{tag} has no input: the flow must start at a step"),
                    ));
                }
                if ns == 0 {
                    diags.push(err(
                        Code::EndStep,
                        format!("{tag} has no output: the flow must end at a step or a jump"),
                    ));
                }
            }
        }
    }
    secondary
}

/// Each jumpStep's target step (by element index), `None` for other elements and for jumps
/// whose target names no step or several (reported).
pub fn resolve_jumps(sfc: &Sfc, diags: &mut Diagnostics) -> Vec<Option<usize>> {
    let el = &sfc.elements;
    let mut out = vec![None; el.len()];
    if !el
        .iter()
        .any(|e| matches!(e.kind, ElementKind::JumpStep(_)))
    {
        return out;
    }
    // Only the steps whose name some jump names are indexed (a quick length test first: the
    // names of 100,000 steps are not all turned into keys).
    let mut by_name: HashMap<Arc<str>, Vec<usize>> = HashMap::new();
    let mut lengths: Vec<usize> = Vec::new();
    for e in el {
        if let ElementKind::JumpStep(Some(t)) = &e.kind {
            by_name.entry(t.key.clone()).or_default();
            if !lengths.contains(&t.key.len()) {
                lengths.push(t.key.len());
            }
        }
    }
    for (i, e) in el.iter().enumerate() {
        if let ElementKind::Step(st) = &e.kind {
            let name = st.name.trim();
            if name.is_ascii() && !lengths.contains(&name.len()) {
                continue;
            }
            if let Some(v) = by_name.get_mut(crate::names::key(name).as_str()) {
                v.push(i);
            }
        }
    }
    for (i, e) in el.iter().enumerate() {
        let ElementKind::JumpStep(Some(target)) = &e.kind else {
            continue;
        };
        match by_name.get(&*target.key).map(Vec::as_slice) {
            Some([t]) => out[i] = Some(*t),
            None | Some([]) => diags.push(
                Diagnostic::error(
                    Code::BadJump,
                    format!("jump target `{}` names no step", target.text),
                )
                .at(target.span.clone())
                .element(label(sfc, i)),
            ),
            Some(several) => {
                let mut d = Diagnostic::error(
                    Code::BadJump,
                    format!(
                        "jump target `{}` names {} steps ({}); give the target step a name of its own",
                        target.text,
                        several.len(),
                        list_ids(sfc, several)
                    ),
                )
                .at(target.span.clone())
                .element(label(sfc, i));
                for &t in several.iter().take(4) {
                    d = d.related(el[t].span.clone(), "a step of that name");
                }
                diags.push(d)
            }
        }
    }
    out
}

/// The start and the end step, found after the jumps are resolved: a step that only jumps lead
/// to is not a second start (unless there is no other), and a chart that ends in jumps only has
/// no end step (`None`). Reports a missing or repeated start or end.
pub fn start_end(
    sfc: &Sfc,
    g: &Graph,
    jumps: &[Option<usize>],
    diags: &mut Diagnostics,
) -> Option<(usize, Option<usize>)> {
    let el = &sfc.elements;
    let mut targeted = vec![false; el.len()];
    for t in jumps.iter().flatten() {
        targeted[*t] = true;
    }
    let has_jumps = el
        .iter()
        .any(|e| matches!(e.kind, ElementKind::JumpStep(_)));
    let no_pred: Vec<usize> = (0..el.len())
        .filter(|&i| el[i].kind.is_step() && g.preds(i).is_empty())
        .collect();
    let untargeted: Vec<usize> = no_pred.iter().copied().filter(|&i| !targeted[i]).collect();
    let starts = if untargeted.is_empty() {
        no_pred
    } else {
        untargeted
    };
    let ends: Vec<usize> = (0..el.len())
        .filter(|&i| el[i].kind.is_step() && g.succs(i).is_empty())
        .collect();
    let mut ok = true;
    let start = match starts.as_slice() {
        [] => {
            diags.push(
                Diagnostic::error(
                    Code::StartStep,
                    "no start step: every step has a predecessor",
                )
                .at_opt(sfc.span.clone()),
            );
            ok = false;
            0
        }
        [s] => {
            if let ElementKind::Step(st) = &el[*s].kind
                && !st.initial
            {
                diags.push(
                    Diagnostic::warning(
                        Code::StartNotInitial,
                        "the start step is not marked initialStep=\"true\"",
                    )
                    .at(el[*s].span.clone())
                    .element(label(sfc, *s)),
                );
            }
            *s
        }
        [first, rest @ ..] => {
            let mut d = Diagnostic::error(
                Code::StartStep,
                format!(
                    "{} start steps (steps without a predecessor): {}",
                    starts.len(),
                    list_ids(sfc, &starts)
                ),
            )
            .at(el[*first].span.clone())
            .element(label(sfc, *first));
            for r in rest.iter().take(8) {
                d = d.related(el[*r].span.clone(), "another start step");
            }
            diags.push(d);
            ok = false;
            0
        }
    };
    let end = match ends.as_slice() {
        [] if has_jumps => None,
        [] => {
            diags.push(
                Diagnostic::error(Code::EndStep, "no end step: every step has a successor")
                    .at_opt(sfc.span.clone()),
            );
            ok = false;
            None
        }
        [e] => Some(*e),
        [first, rest @ ..] => {
            let mut d = Diagnostic::error(
                Code::EndStep,
                format!(
                    "{} end steps (steps without a successor): {}",
                    ends.len(),
                    list_ids(sfc, &ends)
                ),
            )
            .at(el[*first].span.clone())
            .element(label(sfc, *first));
            for r in rest.iter().take(8) {
                d = d.related(el[*r].span.clone(), "another end step");
            }
            diags.push(d);
            ok = false;
            None
        }
    };
    ok.then_some((start, end))
}

fn list_ids(sfc: &Sfc, idx: &[usize]) -> String {
    let mut s: Vec<String> = idx
        .iter()
        .take(10)
        .map(|&i| format!("localId {}", sfc.elements[i].local_id))
        .collect();
    if idx.len() > 10 {
        s.push(format!("and {} more", idx.len() - 10));
    }
    s.join(", ")
}

/// Kahn's algorithm; returns an element on a cycle of connections, if any (jumps are not
/// connections).
pub fn find_cycle(g: &Graph) -> Option<usize> {
    let n = g.len();
    let mut indeg: Vec<usize> = (0..n).map(|i| g.preds(i).len()).collect();
    let mut queue: Vec<usize> = (0..n).filter(|&i| indeg[i] == 0).collect();
    let mut seen = 0;
    while let Some(i) = queue.pop() {
        seen += 1;
        for &s in g.succs(i) {
            indeg[s] -= 1;
            if indeg[s] == 0 {
                queue.push(s);
            }
        }
    }
    if seen == n {
        return None;
    }
    // Every remaining node either is on a cycle or follows one; walk predecessors among the
    // remaining nodes until one repeats: that one is on a cycle.
    let mut cur = (0..n).find(|&i| indeg[i] > 0)?;
    let mut visited = vec![false; n];
    loop {
        if visited[cur] {
            return Some(cur);
        }
        visited[cur] = true;
        cur = *g.preds(cur).iter().find(|&&p| indeg[p] > 0)?;
    }
}

/// Walks the checked graph from `start` and recognises its structure. `None` when a part cannot
/// be structured (reported).
pub fn walk(
    sfc: &Sfc,
    g: &Graph,
    jumps: &[Option<usize>],
    start: usize,
    diags: &mut Diagnostics,
) -> Option<Vec<Block>> {
    let mut targeted = vec![false; sfc.elements.len()];
    for t in jumps.iter().flatten() {
        targeted[*t] = true;
    }
    let mut jumps_to: HashMap<usize, Vec<usize>> = HashMap::new();
    for (j, t) in jumps.iter().enumerate() {
        if let Some(t) = t {
            jumps_to.entry(*t).or_default().push(j);
        }
    }
    let mut w = Walker {
        sfc,
        g,
        jumps,
        targeted,
        jumps_to,
        loops: Vec::new(),
        marks: vec![0; sfc.elements.len()],
        next_loop: 0,
        diags,
        failed: false,
    };
    let (mut body, end) = w.seq(start, true, 0);
    if w.failed {
        return None;
    }
    match end {
        End::Done | End::Endless => {}
        End::Conv(c) => {
            let el = &sfc.elements;
            w.fail(
                c,
                Code::UnbalancedBranch,
                format!(
                    "{} joins branches that no divergence opened",
                    el[c].kind.tag()
                ),
            );
        }
        End::Jump(j) => w.bad_jump(j, "it does not lead back to a step on every path to it"),
        End::Decided { choice, .. } => {
            // A selection with jumps to a loop head outside any loop cannot happen (the head
            // would have opened the loop); keep the blocks for completeness.
            body.push(*choice);
        }
    }
    (!w.failed).then_some(body)
}

/// How a walked sequence ended.
#[derive(Debug)]
enum End {
    /// At a convergence (not consumed).
    Conv(usize),
    /// At the end step.
    Done,
    /// At a jump (the element).
    Jump(usize),
    /// In an endless loop: nothing follows.
    Endless,
    /// At the selection that decides the innermost loop: the selection (its last block) and
    /// what follows the loop.
    Decided { choice: Box<Block>, after: After },
}

/// What follows a loop.
#[derive(Debug)]
enum After {
    /// Nothing: every branch goes round again.
    Nothing,
    /// The exits joined at this convergence: go on from there.
    From(usize),
    /// The one exit branch goes on from this element (`None`: it ends at its transition).
    Continue(Option<usize>),
}

/// What follows branches: `Ok((block, convergence))` to go on from, or `Err(end)` when the
/// sequence ends (a loop's deciding selection); `None` on failure (reported).
type Branches = Option<Result<(Block, usize), End>>;

/// Where the sequence goes on after a loop: `Ok((element, entered))`, or `Err(end)`.
type GoOn = Result<(usize, bool), End>;

/// An open loop.
struct LoopCtx {
    /// The loop's first step, the jumps' target.
    head: usize,
    /// The nesting depth of the loop's body.
    depth: usize,
    /// The loop's number: the elements of its body carry it in [`Walker::marks`].
    id: u32,
    /// Branches that leave the loop from selections before its deciding one (they and the
    /// deciding selection's exits must all join in one convergence).
    mid_exits: usize,
}

struct Walker<'a> {
    sfc: &'a Sfc,
    g: &'a Graph,
    jumps: &'a [Option<usize>],
    targeted: Vec<bool>,
    /// The jumps to each target step.
    jumps_to: HashMap<usize, Vec<usize>>,
    /// The open loops, innermost last.
    loops: Vec<LoopCtx>,
    /// Per element, the number of the last loop whose body holds it: the elements from which a
    /// jump back to the loop's head can be reached without passing the head. A selection branch
    /// outside the body leaves the loop. (An inner loop's marks overwrite its outer loop's only
    /// where the outer loop asks no more: the branches of the outer loop's deciding selection
    /// come after the inner loop and cannot reach the inner loop's jumps.)
    marks: Vec<u32>,
    next_loop: u32,
    diags: &'a mut Diagnostics,
    failed: bool,
}

impl Walker<'_> {
    /// Walks a sequence from `cur` until it ends. `entered` says `cur` itself is to be taken
    /// even if it is a convergence (we arrive there after its branches) or a loop head that is
    /// being opened.
    fn seq(&mut self, mut cur: usize, mut entered: bool, depth: usize) -> (Vec<Block>, End) {
        let el = &self.sfc.elements;
        let mut out = Vec::new();
        loop {
            if self.failed {
                return (out, End::Done);
            }
            if !entered && self.g.preds(cur).len() > 1 {
                return (out, End::Conv(cur));
            }
            if el[cur].kind.is_step()
                && self.targeted[cur]
                && !self.loops.iter().any(|l| l.head == cur)
            {
                let (blocks, end) = self.open_loop(cur, depth);
                out.extend(blocks);
                match end {
                    Some(Ok((c, ent))) => {
                        cur = c;
                        entered = ent;
                        continue;
                    }
                    Some(Err(end)) => return (out, end),
                    None => return (out, End::Done),
                }
            }
            entered = false;
            let succs = self.g.succs(cur);
            match &el[cur].kind {
                ElementKind::Step(_) => out.push(Block::Step(cur)),
                ElementKind::Transition(Some(_)) => out.push(Block::Wait(cur)),
                ElementKind::JumpStep(_) => return (out, End::Jump(cur)),
                _ => {}
            }
            match succs.len() {
                0 => return (out, End::Done),
                1 => cur = succs[0],
                _ => {
                    if depth >= MAX_NESTING {
                        self.fail(
                            cur,
                            Code::Unsupported,
                            format!("branches and loops nested deeper than {MAX_NESTING} levels"),
                        );
                        return (out, End::Done);
                    }
                    let mut heads = succs.to_vec();
                    // Left to right by x; ties in document order (the index is document order).
                    heads.sort_by(|&a, &b| el[a].x.total_cmp(&el[b].x).then(a.cmp(&b)));
                    let next = if matches!(el[cur].kind, ElementKind::SelectionDivergence) {
                        self.selection(cur, heads, depth)
                    } else {
                        self.parallel(cur, heads, depth)
                    };
                    match next {
                        Some(Ok((block, conv))) => {
                            out.push(block);
                            cur = conv;
                            entered = true;
                        }
                        Some(Err(end)) => return (out, end),
                        None => return (out, End::Done),
                    }
                }
            }
        }
    }

    /// Simultaneous branches from `div`: the block and the convergence to go on from.
    fn parallel(&mut self, div: usize, heads: Vec<usize>, depth: usize) -> Branches {
        let el = &self.sfc.elements;
        let mut branches = Vec::with_capacity(heads.len());
        let mut joins = Vec::with_capacity(heads.len());
        for h in heads {
            let (b, end) = self.seq(h, false, depth + 1);
            if self.failed {
                return None;
            }
            match end {
                End::Conv(c) => joins.push(c),
                End::Jump(j) => {
                    self.bad_jump(
                        j,
                        "it leaves a simultaneous branch, which must end in its convergence",
                    );
                    return None;
                }
                _ => {
                    self.fail(
                        div,
                        Code::UnbalancedBranch,
                        format!(
                            "{} opens a branch that does not end in a simultaneousConvergence",
                            el[div].kind.tag()
                        ),
                    );
                    return None;
                }
            }
            branches.push(b);
        }
        let conv = joins[0];
        if joins.iter().any(|j| *j != conv) {
            self.fail(
                div,
                Code::UnbalancedBranch,
                format!(
                    "{} opens {} branches that do not all end in one convergence",
                    el[div].kind.tag(),
                    branches.len()
                ),
            );
            return None;
        }
        if !matches!(el[conv].kind, ElementKind::SimultaneousConvergence)
            || self.g.preds(conv).len() != branches.len()
        {
            self.fail(
                conv,
                Code::UnbalancedBranch,
                format!(
                    "{} joins {} inputs, but the simultaneousDivergence localId {} opened {} branches",
                    el[conv].kind.tag(),
                    self.g.preds(conv).len(),
                    el[div].local_id,
                    branches.len()
                ),
            );
            return None;
        }
        Some(Ok((
            Block::Parallel {
                divergence: div,
                convergence: conv,
                branches,
            },
            conv,
        )))
    }

    /// Selection branches from `div`: the block and the convergence to go on from, or, for the
    /// selection that decides the innermost loop, how the loop body ends.
    fn selection(&mut self, div: usize, heads: Vec<usize>, depth: usize) -> Branches {
        let el = &self.sfc.elements;
        // Branches after an unconditional one are never taken (they are still checked).
        if let Some(k) = heads
            .iter()
            .position(|&h| matches!(el[h].kind, ElementKind::Transition(None)))
        {
            for &h in &heads[k + 1..] {
                self.diags.push(
                    Diagnostic::warning(
                        Code::BranchNeverTaken,
                        format!(
                            "this selection branch is never taken: the branch of transition localId {} before it (left of it) has no condition and always wins",
                            el[heads[k]].local_id
                        ),
                    )
                    .at(el[h].span.clone())
                    .element(format!("localId {}", el[h].local_id)),
                );
            }
        }
        let inner = self.loops.last().map(|l| (l.head, l.depth));
        // At the innermost loop's own level, this selection may decide the loop: branches
        // outside the loop's body leave it, and go on where the loop stands.
        let deciding = inner.is_some_and(|(_, d)| d == depth);
        // (transition, body, end, inside the loop) per branch, in priority order. A branch that
        // leaves the loop is walked later, if at all: one exit branch is the program's
        // continuation after the loop and is walked there, in the sequence that holds the loop
        // (not here: a chain of loops must not nest the walk).
        let inside_of: Vec<bool> = heads
            .iter()
            .map(|&h| !deciding || self.loops.last().is_some_and(|l| self.marks[h] == l.id))
            .collect();
        let n_outside = inside_of.iter().filter(|i| !**i).count();
        // One branch goes on in the loop, the others leave it: either this selection decides
        // the loop (the branch ends in the jump back) or it leaves the loop early and the branch
        // is the rest of the loop's own sequence. Either way it is walked at the loop's level.
        let single_inside = deciding && n_outside > 0 && n_outside + 1 == heads.len();
        if single_inside && let Some(l) = self.loops.last_mut() {
            l.mid_exits += n_outside;
        }
        let mut walked: Vec<(usize, Vec<Block>, End, bool)> = Vec::with_capacity(heads.len());
        for (h, inside) in heads.into_iter().zip(inside_of) {
            let (b, end) = if inside && single_inside {
                match self.g.succs(h).first().copied() {
                    Some(f) => self.seq(f, false, depth),
                    None => (Vec::new(), End::Done),
                }
            } else if inside {
                self.branch_walk(h, depth)
            } else {
                (Vec::new(), End::Endless)
            };
            if self.failed {
                return None;
            }
            walked.push((h, b, end, inside));
        }
        if single_inside {
            let k = walked.iter().position(|w| w.3).expect("one inside");
            if !matches!(walked[k].2, End::Decided { .. }) {
                // Not an early exit: these are this selection's own exits.
                if let Some(l) = self.loops.last_mut() {
                    l.mid_exits -= n_outside;
                }
            } else {
                return self.early_exit(div, walked, depth);
            }
        }
        let any_repeat = walked.iter().any(|(_, _, e, inside)| {
            *inside && matches!(e, End::Jump(j) if inner.is_some_and(|(h, _)| self.jumps[*j] == Some(h)))
        });
        let outside = walked.iter().filter(|w| !w.3).count();
        let mids = self.loops.last().map_or(0, |l| l.mid_exits);
        if !any_repeat || outside > 1 || (outside == 1 && mids > 0) {
            // The exits are walked here: to their convergence (or, without a jump back, as an
            // ordinary selection), outside the loop.
            for w in walked.iter_mut().filter(|w| !w.3) {
                let ctx = self.loops.pop().expect("deciding needs a loop");
                let (b, end) = self.branch_walk(w.0, depth);
                self.loops.push(ctx);
                if self.failed {
                    return None;
                }
                w.1 = b;
                w.2 = end;
            }
        }
        let repeats: Vec<bool> = walked
            .iter()
            .map(|(_, _, e, inside)| *inside && matches!(e, End::Jump(j) if inner.is_some_and(|(h, _)| self.jumps[*j] == Some(h))))
            .collect();
        // Jumps anywhere else cannot be structured.
        for (k, (_, _, e, _)) in walked.iter().enumerate() {
            if let End::Jump(j) = e
                && !repeats[k]
            {
                let why = match self.jumps[*j] {
                    Some(t) if self.loops.iter().any(|l| l.head == t) => {
                        "it leaves an inner loop as well (KRL's EXIT leaves one loop)"
                    }
                    _ => {
                        "it does not lead back to a step on every path to it (a forward jump, or into another branch)"
                    }
                };
                self.bad_jump(*j, why);
                return None;
            }
        }
        if !repeats.iter().any(|r| *r) {
            // An ordinary selection: every branch ends in one convergence.
            let conv = match walked.first().map(|w| &w.2) {
                Some(End::Conv(c)) => Some(*c),
                _ => None,
            };
            let joined = conv.is_some_and(|c| {
                walked.iter().all(|w| matches!(w.2, End::Conv(x) if x == c))
                    && matches!(el[c].kind, ElementKind::SelectionConvergence)
                    && self.g.preds(c).len() == walked.len()
            });
            let Some(conv) = conv.filter(|_| joined) else {
                self.fail(
                    div,
                    Code::UnbalancedBranch,
                    format!(
                        "selectionDivergence opens {} branches that do not all end in one selectionConvergence joining just them",
                        walked.len()
                    ),
                );
                return None;
            };
            let branches = walked
                .into_iter()
                .map(|(t, body, _, _)| Branch {
                    transition: t,
                    body,
                    end: BranchEnd::Join,
                })
                .collect();
            return Some(Ok((
                Block::Choice {
                    divergence: div,
                    convergence: Some(conv),
                    branches,
                },
                conv,
            )));
        }
        // The selection that decides the innermost loop: it must stand in the loop's own
        // sequence, not inside another branch of it, and its other branches must leave the loop.
        let first_repeat = walked
            .iter()
            .zip(&repeats)
            .find_map(|((_, _, e, _), r)| match e {
                End::Jump(j) if *r => Some(*j),
                _ => None,
            })
            .expect("a repeat");
        if !deciding {
            self.bad_jump(
                first_repeat,
                "its selection lies inside another branch of the loop; only a selection in the loop's own sequence can decide it (KRL's EXIT leaves one loop)",
            );
            return None;
        }
        if let Some(k) = (0..walked.len()).find(|&k| !repeats[k] && walked[k].3) {
            self.fail(
                walked[k].0,
                Code::BadJump,
                format!(
                    "this branch of the selection localId {} goes on in the loop while another branch jumps back: a loop is decided by one selection whose other branches leave it",
                    el[div].local_id
                ),
            );
            return None;
        }
        let exits: Vec<usize> = (0..walked.len()).filter(|&k| !repeats[k]).collect();
        let after = match exits.as_slice() {
            [] => After::Nothing,
            // The one exit is walked as what follows the loop (unless earlier exits join it).
            [one] if mids == 0 => After::Continue(self.g.succs(walked[*one].0).first().copied()),
            several => {
                let conv = match &walked[several[0]].2 {
                    End::Conv(c) => Some(*c),
                    _ => None,
                };
                let joined = conv.is_some_and(|c| {
                    several
                        .iter()
                        .all(|&k| matches!(walked[k].2, End::Conv(x) if x == c))
                        && self.g.preds(c).len() == several.len() + mids
                });
                let Some(conv) = conv.filter(|_| joined) else {
                    self.fail(
                        div,
                        Code::UnbalancedBranch,
                        format!(
                            "selectionDivergence decides a loop, and its {} branches that leave it (with {mids} that leave it earlier) do not end in one selectionConvergence joining just them",
                            several.len()
                        ),
                    );
                    return None;
                };
                After::From(conv)
            }
        };
        let branches = walked
            .into_iter()
            .enumerate()
            .map(|(k, (t, body, end, _))| Branch {
                transition: t,
                body,
                end: match end {
                    End::Jump(j) if repeats[k] => BranchEnd::Repeat(j),
                    _ => BranchEnd::Leave,
                },
            })
            .collect();
        Some(Err(End::Decided {
            choice: Box::new(Block::Choice {
                divergence: div,
                convergence: None,
                branches,
            }),
            after,
        }))
    }

    /// A selection before the loop's deciding one, with one branch going on in the loop (walked:
    /// it ended at the deciding selection, `walked[k].2` is `End::Decided`) and the others
    /// leaving it: they are walked to the convergence that joins every exit of the loop.
    fn early_exit(
        &mut self,
        div: usize,
        mut walked: Vec<(usize, Vec<Block>, End, bool)>,
        depth: usize,
    ) -> Branches {
        let k = walked.iter().position(|w| w.3).expect("one inside");
        let End::Decided { choice, after } = std::mem::replace(&mut walked[k].2, End::Endless)
        else {
            unreachable!("checked by the caller")
        };
        let total = self.loops.last().map_or(0, |l| l.mid_exits);
        for w in walked.iter_mut().filter(|w| !w.3) {
            let ctx = self.loops.pop().expect("an early exit needs a loop");
            let (b, end) = self.branch_walk(w.0, depth);
            self.loops.push(ctx);
            if self.failed {
                return None;
            }
            if let End::Jump(j) = end {
                self.bad_jump(
                    j,
                    "it leaves a loop from a selection before the one that decides it; only its exits may follow",
                );
                return None;
            }
            w.1 = b;
            w.2 = end;
        }
        let conv = walked.iter().find(|w| !w.3).and_then(|w| match w.2 {
            End::Conv(c) => Some(c),
            _ => None,
        });
        let joined = conv.is_some_and(|c| {
            walked
                .iter()
                .filter(|w| !w.3)
                .all(|w| matches!(w.2, End::Conv(x) if x == c))
                && match &after {
                    After::From(a) => *a == c,
                    // The deciding selection has no exits of its own: every exit is early.
                    After::Nothing => self.g.preds(c).len() == total,
                    After::Continue(_) => false,
                }
        });
        let Some(conv) = conv.filter(|_| joined) else {
            self.fail(
                div,
                Code::UnbalancedBranch,
                format!(
                    "selectionDivergence leaves the loop before the selection that decides it; every branch that leaves the loop must end in one selectionConvergence (here {} of them)",
                    total + walked.len().saturating_sub(1)
                ),
            );
            return None;
        };
        let mut choice = Some(*choice);
        let branches = walked
            .into_iter()
            .map(|(t, mut body, _, inside)| {
                if inside && let Some(c) = choice.take() {
                    body.push(c);
                }
                Branch {
                    transition: t,
                    body,
                    end: if inside {
                        BranchEnd::Join
                    } else {
                        BranchEnd::Leave
                    },
                }
            })
            .collect();
        Some(Err(End::Decided {
            choice: Box::new(Block::Choice {
                divergence: div,
                convergence: None,
                branches,
            }),
            after: After::From(conv),
        }))
    }

    /// Walks a selection branch from its transition `h` (whose condition selects it; it is not
    /// waited for).
    fn branch_walk(&mut self, h: usize, depth: usize) -> (Vec<Block>, End) {
        match self.g.succs(h).first().copied() {
            Some(f) => self.seq(f, false, depth + 1),
            None => (Vec::new(), End::Done),
        }
    }

    /// Opens a loop at step `head`: its blocks and then `Ok((element, entered))` to go on from,
    /// or `Err(end)` when the sequence ends; `None` on failure.
    fn open_loop(&mut self, head: usize, depth: usize) -> (Vec<Block>, Option<GoOn>) {
        if depth >= MAX_NESTING {
            self.fail(
                head,
                Code::Unsupported,
                format!("branches and loops nested deeper than {MAX_NESTING} levels"),
            );
            return (Vec::new(), None);
        }
        // The body: what can reach a jump back without passing the head.
        self.next_loop += 1;
        let id = self.next_loop;
        let mut stack: Vec<usize> = self.jumps_to.get(&head).cloned().unwrap_or_default();
        while let Some(x) = stack.pop() {
            if x == head || self.marks[x] == id {
                continue;
            }
            self.marks[x] = id;
            stack.extend_from_slice(self.g.preds(x));
        }
        // The body is a sequence one level deeper than the loop.
        self.loops.push(LoopCtx {
            head,
            depth: depth + 1,
            id,
            mid_exits: 0,
        });
        let (mut body, end) = self.seq(head, true, depth + 1);
        self.loops.pop();
        if self.failed {
            return (Vec::new(), None);
        }
        // The jumps back to this loop's head (in its deciding selection, however nested).
        let collect = |blocks: &[Block], jumps: &mut Vec<usize>, targets: &[Option<usize>]| {
            visit(blocks, &mut |b| {
                if let Block::Choice { branches, .. } = b {
                    for br in branches {
                        if let BranchEnd::Repeat(j) = br.end
                            && targets[j] == Some(head)
                            && !jumps.contains(&j)
                        {
                            jumps.push(j);
                        }
                    }
                }
            });
        };
        let mut jumps = Vec::new();
        match end {
            End::Jump(j) if self.jumps[j] == Some(head) => {
                // A jump back in the loop's own sequence: an endless loop.
                let block = Block::Loop {
                    head,
                    jumps: vec![j],
                    body,
                    endless: true,
                };
                (vec![block], Some(Err(End::Endless)))
            }
            End::Decided { choice, after } => {
                body.push(*choice);
                collect(&body, &mut jumps, self.jumps);
                let endless = matches!(after, After::Nothing);
                let block = Block::Loop {
                    head,
                    jumps,
                    body,
                    endless,
                };
                let next = match after {
                    After::Nothing => Err(End::Endless),
                    After::From(c) => Ok((c, true)),
                    After::Continue(Some(e)) => Ok((e, false)),
                    After::Continue(None) => Err(End::Done),
                };
                (vec![block], Some(next))
            }
            // No jump back to the head on the way: its jumps come from elsewhere (reported
            // where they are found); the steps are an ordinary sequence.
            other => (body, Some(Err(other))),
        }
    }

    fn bad_jump(&mut self, j: usize, why: &str) {
        let el = &self.sfc.elements;
        let target = match &el[j].kind {
            ElementKind::JumpStep(Some(t)) => format!("`{}`", t.text),
            _ => "?".to_owned(),
        };
        let target_id = self.jumps[j]
            .map(|t| format!(" (localId {})", el[t].local_id))
            .unwrap_or_default();
        let mut d = Diagnostic::error(
            Code::BadJump,
            format!("the jump to step {target}{target_id} cannot be structured: {why}"),
        )
        .at(el[j].span.clone())
        .element(format!("localId {}", el[j].local_id));
        if let Some(t) = self.jumps[j] {
            d = d.related(el[t].span.clone(), "the jump's target");
        }
        self.diags.push(d);
        self.failed = true;
    }

    fn fail(&mut self, at: usize, code: Code, msg: String) {
        let e = &self.sfc.elements[at];
        self.diags.push(
            Diagnostic::error(code, msg)
                .at(e.span.clone())
                .element(format!("localId {}", e.local_id)),
        );
        self.failed = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diag::Sources;

    fn conn(inputs: &[u64]) -> String {
        let c: String = inputs
            .iter()
            .map(|i| format!("<connection refLocalId=\"{i}\"/>"))
            .collect();
        if inputs.is_empty() {
            String::new()
        } else {
            format!("<connectionPointIn>{c}</connectionPointIn>")
        }
    }
    fn st(id: u64, name: &str, inp: &[u64]) -> String {
        format!(
            "<step localId=\"{id}\" name=\"{name}\"{}><position x=\"0\" y=\"0\"/>{}</step>",
            if inp.is_empty() {
                " initialStep=\"true\""
            } else {
                ""
            },
            conn(inp)
        )
    }
    fn tr(id: u64, inp: &[u64], cond: &str) -> String {
        format!(
            "<transition localId=\"{id}\"><position x=\"0\" y=\"0\"/>{}<condition><inline name=\"\"><ST>{cond}</ST></inline></condition></transition>",
            conn(inp)
        )
    }
    fn el(tag: &str, id: u64, inp: &[u64]) -> String {
        format!(
            "<{tag} localId=\"{id}\"><position x=\"0\" y=\"0\"/>{}</{tag}>",
            conn(inp)
        )
    }
    fn jmp(id: u64, inp: &[u64], target: &str) -> String {
        format!(
            "<jumpStep localId=\"{id}\" targetName=\"{target}\"><position x=\"0\" y=\"0\"/>{}</jumpStep>",
            conn(inp)
        )
    }

    /// Reads an SFC body and plans it: the plan (if any) and the diagnostics' codes and messages.
    fn run(parts: &[String]) -> (Option<Plan>, Sfc, Vec<(Code, String)>) {
        let text = format!(
            "<project><types><pous><pou name=\"P\" pouType=\"program\"><body><SFC>{}</SFC></body></pou></pous></types></project>",
            parts.concat()
        );
        let mut sources = Sources::default();
        let f = sources.add("s.xml".into(), "s.xml".into(), text, false);
        let mut d = Diagnostics::default();
        let sfc = crate::read::sfc::read_sfc(&sources, f, &mut d).expect("readable");
        let p = plan(&sfc, &mut d);
        let msgs = d
            .into_vec()
            .into_iter()
            .filter(|d| d.severity == crate::diag::Severity::Error)
            .map(|d| (d.code, d.message))
            .collect();
        (p, sfc, msgs)
    }

    /// The tree with localIds: `S3` step, `W4` wait, `P(..|..)`, `C(..|..)` with `^` for a
    /// repeat and `!` for a leave, `L3[..]` (`L3*[..]` endless).
    fn shape(sfc: &Sfc, blocks: &[Block]) -> String {
        let id = |i: usize| sfc.elements[i].local_id;
        let mut out = Vec::new();
        for b in blocks {
            out.push(match b {
                Block::Step(i) => format!("S{}", id(*i)),
                Block::Wait(i) => format!("W{}", id(*i)),
                Block::Parallel { branches, .. } => {
                    let v: Vec<String> = branches.iter().map(|b| shape(sfc, b)).collect();
                    format!("P({})", v.join("|"))
                }
                Block::Choice { branches, .. } => {
                    let v: Vec<String> = branches
                        .iter()
                        .map(|b| {
                            let end = match b.end {
                                BranchEnd::Join => "",
                                BranchEnd::Repeat(_) => "^",
                                BranchEnd::Leave => "!",
                            };
                            format!("{}:{}{end}", id(b.transition), shape(sfc, &b.body))
                        })
                        .collect();
                    format!("C({})", v.join("|"))
                }
                Block::Loop {
                    head,
                    body,
                    endless,
                    ..
                } => format!(
                    "L{}{}[{}]",
                    id(*head),
                    if *endless { "*" } else { "" },
                    shape(sfc, body)
                ),
            });
        }
        out.join(" ")
    }

    fn planned(parts: &[String]) -> String {
        let (p, sfc, msgs) = run(parts);
        assert!(msgs.is_empty(), "{msgs:?}");
        shape(&sfc, &p.expect("a plan").body)
    }

    #[test]
    fn empty_body_is_one_error() {
        let (p, _, msgs) = run(&[]);
        assert!(p.is_none());
        assert_eq!(msgs.len(), 1, "{msgs:?}");
        assert!(msgs[0].1.contains("no steps"));
    }

    #[test]
    fn node_checks() {
        // A selection branch starting with a step; a jump followed by a step.
        let (_, _, msgs) = run(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "A", &[2]),
            el("selectionDivergence", 4, &[3]),
            st(5, "B", &[4]),
            tr(6, &[4], "x"),
            jmp(7, &[6], "A"),
            st(8, "C", &[7]),
        ]);
        assert!(
            msgs.iter()
                .any(|(c, m)| *c == Code::UnbalancedBranch
                    && m.contains("starts with step localId 5")),
            "{msgs:?}"
        );
        assert!(
            msgs.iter()
                .any(|(c, m)| *c == Code::BadJump && m.contains("a jump ends its branch")),
            "{msgs:?}"
        );
    }

    #[test]
    fn jump_targets() {
        let (_, _, msgs) = run(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "Twin", &[2]),
            tr(4, &[3], "TRUE"),
            st(5, "twin", &[4]),
            tr(6, &[5], "a"),
            el("selectionDivergence", 7, &[6]),
            tr(8, &[7], "b"),
            jmp(9, &[8], "TWIN"),
            tr(10, &[7], "c"),
            jmp(11, &[10], "Nobody"),
        ]);
        let jumps: Vec<&String> = msgs
            .iter()
            .filter(|(c, _)| *c == Code::BadJump)
            .map(|(_, m)| m)
            .collect();
        assert!(jumps[0].contains("names 2 steps"), "{msgs:?}");
        assert!(jumps[1].contains("`Nobody` names no step"), "{msgs:?}");
    }

    #[test]
    fn start_and_end_after_jumps() {
        // The start step is also the jump target and has no connection in: one start; the
        // chart ends in a jump only: no end step, and no error.
        let p = planned(&[
            st(1, "Init", &[]),
            tr(2, &[1], "go"),
            st(3, "Work", &[2]),
            tr(4, &[3], "TRUE"),
            jmp(5, &[4], "Init"),
        ]);
        assert_eq!(p, "L1*[S1 W2 S3]");
        // A step that only a jump leads to is not a second start: here the jump is forward,
        // which the walk reports (not E307).
        let (_, _, msgs) = run(&[
            st(1, "Init", &[]),
            tr(2, &[1], "TRUE"),
            jmp(3, &[2], "Later"),
            st(4, "Later", &[]),
            tr(5, &[4], "TRUE"),
            st(6, "End", &[5]),
        ]);
        assert!(msgs.iter().all(|(c, _)| *c != Code::StartStep), "{msgs:?}");
        assert!(msgs.iter().any(|(c, _)| *c == Code::BadJump), "{msgs:?}");
        // Without jumps a missing end is still an error.
        let (_, _, msgs) = run(&[
            st(1, "A", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "B", &[2, 4]),
            tr(4, &[3], "TRUE"),
        ]);
        assert!(msgs.iter().any(|(c, _)| *c == Code::EndStep), "{msgs:?}");
    }

    #[test]
    fn cycles_of_connections_are_not_loops() {
        let (_, _, msgs) = run(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            el("selectionConvergence", 3, &[2, 8]),
            st(4, "A", &[3]),
            el("selectionDivergence", 5, &[4]),
            tr(6, &[5], "done"),
            st(7, "End", &[6]),
            tr(8, &[5], "NOT done"),
        ]);
        assert!(
            msgs.iter()
                .any(|(c, m)| *c == Code::Cycle && m.contains("jumpStep")),
            "{msgs:?}"
        );
    }

    #[test]
    fn walk_sequence_selection_parallel() {
        let p = planned(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "A", &[2]),
            tr(4, &[3], "ready"),
            st(5, "B", &[4]),
            el("selectionDivergence", 6, &[5]),
            tr(7, &[6], "x"),
            el("simultaneousDivergence", 8, &[7]),
            st(9, "C", &[8]),
            st(10, "D", &[8]),
            el("simultaneousConvergence", 11, &[9, 10]),
            tr(12, &[11], "TRUE"),
            tr(13, &[6], "TRUE"),
            el("selectionConvergence", 14, &[12, 13]),
            st(15, "End", &[14]),
        ]);
        assert_eq!(p, "S1 S3 W4 S5 C(7:P(S9|S10)|13:) S15");
    }

    #[test]
    fn walk_loop_with_exit() {
        let p = planned(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "Pick", &[2]),
            el("selectionDivergence", 4, &[3]),
            tr(5, &[4], "more"),
            st(6, "Count", &[5]),
            tr(7, &[6], "TRUE"),
            jmp(8, &[7], "Pick"),
            tr(9, &[4], "NOT more"),
            st(10, "Home", &[9]),
            tr(11, &[10], "TRUE"),
            st(12, "End", &[11]),
        ]);
        assert_eq!(p, "S1 L3[S3 C(5:S6^|9:!)] S10 S12");
    }

    #[test]
    fn walk_nested_loops() {
        // Rows of a pallet: the inner loop over Place, the outer over Row.
        let p = planned(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "Row", &[2]),
            tr(4, &[3], "TRUE"),
            st(5, "Place", &[4]),
            el("selectionDivergence", 6, &[5]),
            tr(7, &[6], "NOT row_full"),
            jmp(8, &[7], "Place"),
            tr(9, &[6], "row_full"),
            st(10, "Next", &[9]),
            el("selectionDivergence", 11, &[10]),
            tr(12, &[11], "NOT pallet_full"),
            jmp(13, &[12], "Row"),
            tr(14, &[11], "pallet_full"),
            st(15, "End", &[14]),
        ]);
        assert_eq!(p, "S1 L3[S3 L5[S5 C(7:^|9:!)] S10 C(12:^|14:!)] S15");
    }

    #[test]
    fn walk_exits_that_join() {
        let p = planned(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "Pick", &[2]),
            el("selectionDivergence", 4, &[3]),
            tr(5, &[4], "a"),
            jmp(6, &[5], "Pick"),
            tr(7, &[4], "b"),
            st(8, "B", &[7]),
            tr(9, &[8], "TRUE"),
            tr(10, &[4], "c"),
            el("selectionConvergence", 11, &[9, 10]),
            st(12, "End", &[11]),
        ]);
        assert_eq!(p, "S1 L3[S3 C(5:^|7:S8!|10:!)] S12");
    }

    #[test]
    fn walk_rejects_a_loop_continued_past_its_decision() {
        // Branch 9 goes on in the loop body while branch 5 jumps back, and jumps back again
        // from a selection inside it: no KRL structure (EXIT leaves one loop, there is no
        // CONTINUE).
        let (p, _, msgs) = run(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "Pick", &[2]),
            el("selectionDivergence", 4, &[3]),
            tr(5, &[4], "a"),
            jmp(6, &[5], "Pick"),
            tr(9, &[4], "b"),
            st(10, "B", &[9]),
            el("selectionDivergence", 11, &[10]),
            tr(12, &[11], "c"),
            jmp(13, &[12], "Pick"),
            tr(14, &[11], "NOT c"),
            st(15, "End", &[14]),
        ]);
        assert!(p.is_none());
        assert!(
            msgs.iter()
                .any(|(c, m)| *c == Code::BadJump && m.contains("inside another branch")),
            "{msgs:?}"
        );
    }

    #[test]
    fn a_chain_of_loops_does_not_nest_the_walk() {
        // 20,000 loops one after another: each loop's exit is the next loop's way in. The walk
        // goes on after each loop in the same sequence, so the stack does not grow with them.
        let n = 20_000u64;
        let mut parts = vec![st(1, "Start", &[]), tr(2, &[1], "TRUE")];
        let mut prev = 2;
        for k in 0..n {
            let b = 10 + k * 10;
            parts.push(st(b, &format!("L{k}"), &[prev]));
            parts.push(el("selectionDivergence", b + 1, &[b]));
            parts.push(tr(b + 2, &[b + 1], "again"));
            parts.push(jmp(b + 3, &[b + 2], &format!("L{k}")));
            parts.push(tr(b + 4, &[b + 1], "NOT again"));
            prev = b + 4;
        }
        parts.push(st(5, "End", &[prev]));
        let (p, _, msgs) = std::thread::Builder::new()
            .stack_size(256 * 1024)
            .spawn(move || {
                let (p, sfc, msgs) = run(&parts);
                (p.map(|p| p.body.len()), sfc.elements.len(), msgs)
            })
            .unwrap()
            .join()
            .unwrap();
        assert!(msgs.is_empty(), "{:?}", &msgs[..msgs.len().min(3)]);
        // Start, the loops, End.
        assert_eq!(p, Some(n as usize + 2));
    }

    #[test]
    fn nested_loops_deeper_than_the_limit_are_an_error() {
        // Loop k's body holds loop k + 1; each is left to its parent's decision.
        let n = MAX_NESTING as u64 + 10;
        let mut parts = vec![st(1, "Start", &[]), tr(2, &[1], "TRUE")];
        let mut prev = 2;
        for k in 0..n {
            let b = 10 + k * 10;
            parts.push(st(b, &format!("L{k}"), &[prev]));
            parts.push(tr(b + 1, &[b], "TRUE"));
            prev = b + 1;
        }
        // Innermost first: each loop's deciding selection after the inner loop's exit.
        let mut last = prev;
        let mut last_is_step = false;
        for k in (0..n).rev() {
            let b = 10_000 + k * 10;
            let s = if last_is_step {
                last
            } else {
                parts.push(st(b, &format!("X{k}"), &[last]));
                b
            };
            parts.push(el("selectionDivergence", b + 1, &[s]));
            parts.push(tr(b + 2, &[b + 1], "again"));
            parts.push(jmp(b + 3, &[b + 2], &format!("L{k}")));
            parts.push(tr(b + 4, &[b + 1], "NOT again"));
            last = b + 4;
            last_is_step = false;
        }
        parts.push(st(5, "End", &[last]));
        let (p, _, msgs) = run(&parts);
        assert!(p.is_none());
        assert!(
            msgs.iter()
                .any(|(c, m)| *c == Code::Unsupported && m.contains("nested deeper")),
            "{msgs:?}"
        );
    }

    #[test]
    fn an_inner_exit_straight_back_to_the_outer_head() {
        let p = planned(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "Row", &[2]),
            tr(4, &[3], "TRUE"),
            st(5, "Place", &[4]),
            el("selectionDivergence", 6, &[5]),
            tr(7, &[6], "more"),
            jmp(8, &[7], "Place"),
            tr(9, &[6], "NOT more"),
            jmp(10, &[9], "Row"),
        ]);
        assert_eq!(p, "S1 L3*[S3 L5[S5 C(7:^|9:!)]]");
    }

    #[test]
    fn walk_early_exit() {
        // Selection 4 leaves the loop early (branch 9); selection 7 decides it; both exits join
        // in 12.
        let p = planned(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "Pick", &[2]),
            el("selectionDivergence", 4, &[3]),
            tr(5, &[4], "good"),
            st(6, "Good", &[5]),
            el("selectionDivergence", 7, &[6]),
            tr(8, &[7], "more"),
            jmp(13, &[8], "Pick"),
            tr(10, &[7], "NOT more"),
            tr(9, &[4], "NOT good"),
            st(11, "Bad", &[9]),
            tr(14, &[11], "TRUE"),
            el("selectionConvergence", 12, &[10, 14]),
            st(15, "End", &[12]),
        ]);
        assert_eq!(p, "S1 L3[S3 C(5:S6 C(8:^|10:!)|9:S11!)] S15");
        // Steps on both exits before they join: they run before each EXIT.
        let p = planned(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "Pick", &[2]),
            el("selectionDivergence", 4, &[3]),
            tr(5, &[4], "good"),
            st(6, "Good", &[5]),
            el("selectionDivergence", 7, &[6]),
            tr(8, &[7], "more"),
            jmp(13, &[8], "Pick"),
            tr(10, &[7], "NOT more"),
            st(16, "Done", &[10]),
            tr(17, &[16], "TRUE"),
            tr(9, &[4], "NOT good"),
            st(11, "Bad", &[9]),
            tr(14, &[11], "TRUE"),
            el("selectionConvergence", 12, &[17, 14]),
            st(15, "End", &[12]),
        ]);
        assert_eq!(p, "S1 L3[S3 C(5:S6 C(8:^|10:S16!)|9:S11!)] S15");
    }
}
