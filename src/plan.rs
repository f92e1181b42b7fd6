//! SFC graph checks and the ordered program tree (SPEC.md section 3, "Rules").
//!
//! The tree is a sequence of [`Block`]s; simultaneous branches become [`Block::Parallel`] with
//! their branches already in emission order (left to right by the x of each branch head, ties in
//! document order). Selection branches and loops will be further variants of [`Block`]; until
//! then they are `E313` errors, so every consumer's `match` is exhaustive today and is told by the
//! compiler where to handle them tomorrow.

use std::collections::HashMap;

use crate::diag::{Code, Diagnostic, Diagnostics, Span};
use crate::model::{ElementKind, Sfc};

/// Simultaneous branches nest at most this deep.
pub const MAX_NESTING: usize = 128;

/// One entry of the program tree. Indexes are into [`Sfc::elements`].
#[derive(Debug, Clone, PartialEq)]
pub enum Block {
    /// A step.
    Step(usize),
    /// Simultaneous branches, in emission order. On one robot they run one after another.
    Parallel {
        divergence: usize,
        convergence: usize,
        branches: Vec<Vec<Block>>,
    },
}

/// The planned program.
#[derive(Debug)]
pub struct Plan {
    /// The whole flow, start and end steps included.
    pub body: Vec<Block>,
    /// The start step.
    pub start: usize,
    /// The end step.
    pub end: usize,
}

impl Plan {
    /// Steps in execution order.
    pub fn steps(&self) -> Vec<usize> {
        fn walk(blocks: &[Block], out: &mut Vec<usize>) {
            for b in blocks {
                match b {
                    Block::Step(i) => out.push(*i),
                    Block::Parallel { branches, .. } => {
                        for br in branches {
                            walk(br, out);
                        }
                    }
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.body, &mut out);
        out
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
    let g = graph(sfc, diags);
    let el = &sfc.elements;
    let id = |i: usize| format!("localId {}", el[i].local_id);
    let mut secondary = Vec::new();

    for (i, e) in el.iter().enumerate() {
        let (np, ns) = (g.preds(i).len(), g.succs(i).len());
        match &e.kind {
            ElementKind::SelectionDivergence | ElementKind::SelectionConvergence => {
                diags.push(
                    Diagnostic::error(
                        Code::Unsupported,
                        format!(
                            "{} is not supported yet: skillpost emits one fixed sequence (only simultaneous branches)",
                            e.kind.tag()
                        ),
                    )
                    .at(e.span.clone())
                    .element(id(i)),
                );
            }
            ElementKind::Transition(Some(c)) => {
                diags.push(
                    Diagnostic::error(
                        Code::Unsupported,
                        format!("transition condition `{}` is not supported yet", c.text),
                    )
                    .at(c.span.clone())
                    .element(id(i)),
                );
            }
            ElementKind::JumpStep(_) | ElementKind::MacroStep => {
                diags.push(
                    Diagnostic::error(
                        Code::Unsupported,
                        format!("{} is not supported yet", e.kind.tag()),
                    )
                    .at(e.span.clone())
                    .element(id(i)),
                );
            }
            ElementKind::Step(_) => {
                if np > 1 || ns > 1 {
                    let (what, n) = if np > 1 {
                        ("predecessors", np)
                    } else {
                        ("successors", ns)
                    };
                    diags.push(
                        Diagnostic::error(
                            Code::StepFanInOut,
                            format!(
                                "step has {n} {what}; a step has at most one (branches need a divergence or convergence)"
                            ),
                        )
                        .at(e.span.clone())
                        .element(id(i)),
                    );
                }
                for &p in g.preds(i) {
                    if el[p].kind.is_step() {
                        diags.push(
                            Diagnostic::error(
                                Code::StepToStep,
                                format!(
                                    "step follows step localId {} without a transition between them",
                                    el[p].local_id
                                ),
                            )
                            .at(e.span.clone())
                            .element(id(i)),
                        );
                    }
                }
            }
            ElementKind::Transition(_)
            | ElementKind::SimultaneousDivergence
            | ElementKind::SimultaneousConvergence => {
                let kind = &e.kind;
                let unbalanced = |msg: String| {
                    Diagnostic::error(Code::UnbalancedBranch, msg)
                        .at(e.span.clone())
                        .element(id(i))
                };
                if np > 1 && ns > 1 {
                    diags.push(
                        Diagnostic::error(
                            Code::NToM,
                            format!(
                                "{} joins {np} inputs and splits into {ns} outputs at once; use a convergence and a divergence",
                                kind.tag()
                            ),
                        )
                        .at(e.span.clone())
                        .element(id(i)),
                    );
                } else {
                    match kind {
                        // Often a consequence of another fault (a cycle, a second start):
                        // reported only when the flow has no other error.
                        ElementKind::Transition(_) if ns > 1 => secondary.push(unbalanced(format!(
                            "transition splits into {ns} outputs ({}); simultaneous branches start with a simultaneousDivergence",
                            list_ids(sfc, g.succs(i))
                        ))),
                        ElementKind::Transition(_) if np > 1 => secondary.push(unbalanced(format!(
                            "transition joins {np} inputs ({}); simultaneous branches end with a simultaneousConvergence",
                            list_ids(sfc, g.preds(i))
                        ))),
                        ElementKind::SimultaneousDivergence if np > 1 => {
                            diags.push(unbalanced(format!(
                                "simultaneousDivergence has {np} inputs; it must have one"
                            )))
                        }
                        ElementKind::SimultaneousDivergence if ns == 1 => diags.push(unbalanced(
                            "simultaneousDivergence opens only one branch".to_owned(),
                        )),
                        ElementKind::SimultaneousConvergence if ns > 1 => {
                            diags.push(unbalanced(format!(
                                "simultaneousConvergence has {ns} outputs; it must have one"
                            )))
                        }
                        ElementKind::SimultaneousConvergence if np == 1 => diags.push(unbalanced(
                            "simultaneousConvergence joins only one branch: no divergence opened it"
                                .to_owned(),
                        )),
                        _ => {}
                    }
                }
                if np == 0 {
                    diags.push(
                        Diagnostic::error(
                            Code::StartStep,
                            format!(
                                "{} has no input: the flow must start at a step",
                                e.kind.tag()
                            ),
                        )
                        .at(e.span.clone())
                        .element(id(i)),
                    );
                }
                if ns == 0 {
                    diags.push(
                        Diagnostic::error(
                            Code::EndStep,
                            format!(
                                "{} has no output: the flow must end at a step",
                                e.kind.tag()
                            ),
                        )
                        .at(e.span.clone())
                        .element(id(i)),
                    );
                }
            }
        }
    }

    let starts: Vec<usize> = (0..el.len())
        .filter(|&i| el[i].kind.is_step() && g.preds(i).is_empty())
        .collect();
    let ends: Vec<usize> = (0..el.len())
        .filter(|&i| el[i].kind.is_step() && g.succs(i).is_empty())
        .collect();
    let file_span = sfc.span.clone();
    match starts.as_slice() {
        [] => diags.push(
            Diagnostic::error(
                Code::StartStep,
                "no start step: every step has a predecessor",
            )
            .at_opt(file_span.clone()),
        ),
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
                    .element(id(*s)),
                );
            }
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
            .element(id(*first));
            for r in rest.iter().take(8) {
                d = d.related(el[*r].span.clone(), "another start step");
            }
            diags.push(d);
        }
    }
    match ends.as_slice() {
        [] => diags.push(
            Diagnostic::error(Code::EndStep, "no end step: every step has a successor")
                .at_opt(file_span.clone()),
        ),
        [_] => {}
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
            .element(id(*first));
            for r in rest.iter().take(8) {
                d = d.related(el[*r].span.clone(), "another end step");
            }
            diags.push(d);
        }
    }

    if let Some(c) = find_cycle(&g) {
        diags.push(
            Diagnostic::error(
                Code::Cycle,
                "the flow has a cycle through this element; loops are not supported yet",
            )
            .at(el[c].span.clone())
            .element(id(c)),
        );
    }

    if diags.error_count() == errors_before {
        for d in secondary {
            diags.push(d);
        }
    }
    if diags.error_count() > errors_before || el.is_empty() {
        if el.is_empty() {
            diags.push(
                Diagnostic::error(Code::StartStep, "the SFC body has no steps").at_opt(file_span),
            );
        }
        return None;
    }
    let (start, end) = (starts[0], ends[0]);
    let mut w = Walker {
        sfc,
        g: &g,
        diags,
        failed: false,
    };
    let (body, conv) = w.seq(start, true, 0);
    if let Some(c) = conv {
        w.diags.push(
            Diagnostic::error(
                Code::UnbalancedBranch,
                format!(
                    "{} joins branches that no divergence opened",
                    el[c].kind.tag()
                ),
            )
            .at(el[c].span.clone())
            .element(id(c)),
        );
        w.failed = true;
    }
    if w.failed {
        return None;
    }
    Some(Plan { body, start, end })
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

/// Kahn's algorithm; returns an element on a cycle, if any.
fn find_cycle(g: &Graph) -> Option<usize> {
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

struct Walker<'a> {
    sfc: &'a Sfc,
    g: &'a Graph,
    diags: &'a mut Diagnostics,
    failed: bool,
}

impl Walker<'_> {
    /// Walks a sequence from `cur` until the flow ends (returns `None`) or reaches a convergence
    /// (an element with several inputs; returned, not consumed). `entered` says `cur` itself is
    /// to be taken even if it is a convergence (we arrive there after its branches).
    fn seq(
        &mut self,
        mut cur: usize,
        mut entered: bool,
        depth: usize,
    ) -> (Vec<Block>, Option<usize>) {
        let el = &self.sfc.elements;
        let mut out = Vec::new();
        loop {
            if !entered && self.g.preds(cur).len() > 1 {
                return (out, Some(cur));
            }
            entered = false;
            if el[cur].kind.is_step() {
                out.push(Block::Step(cur));
            }
            let succs = self.g.succs(cur);
            match succs.len() {
                0 => return (out, None),
                1 => cur = succs[0],
                _ => {
                    if depth >= MAX_NESTING {
                        self.fail(
                            cur,
                            Code::Unsupported,
                            format!(
                                "simultaneous branches nested deeper than {MAX_NESTING} levels"
                            ),
                        );
                        return (out, None);
                    }
                    let mut heads = succs.to_vec();
                    // Left to right by x; ties in document order (the index is document order).
                    heads.sort_by(|&a, &b| el[a].x.total_cmp(&el[b].x).then(a.cmp(&b)));
                    let mut branches = Vec::with_capacity(heads.len());
                    let mut joins = Vec::with_capacity(heads.len());
                    for h in heads {
                        let (b, c) = self.seq(h, false, depth + 1);
                        if self.failed {
                            return (out, None);
                        }
                        branches.push(b);
                        joins.push(c);
                    }
                    let first = joins[0];
                    let Some(conv) = first.filter(|c| joins.iter().all(|j| *j == Some(*c))) else {
                        self.fail(
                            cur,
                            Code::UnbalancedBranch,
                            format!(
                                "{} opens {} branches that do not all end in one convergence",
                                el[cur].kind.tag(),
                                branches.len()
                            ),
                        );
                        return (out, None);
                    };
                    if self.g.preds(conv).len() != branches.len() {
                        self.fail(
                            conv,
                            Code::UnbalancedBranch,
                            format!(
                                "{} joins {} inputs, but the divergence localId {} opened {} branches",
                                el[conv].kind.tag(),
                                self.g.preds(conv).len(),
                                el[cur].local_id,
                                branches.len()
                            ),
                        );
                        return (out, None);
                    }
                    out.push(Block::Parallel {
                        divergence: cur,
                        convergence: conv,
                        branches,
                    });
                    cur = conv;
                    entered = true;
                }
            }
        }
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
