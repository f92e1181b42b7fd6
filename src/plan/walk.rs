//! The walk over the checked graph that recognises the program's structure: sequences, waits,
//! simultaneous and selection branches, loops closed by jumps (see `ARCHITECTURE.md`, "The
//! program tree").

use std::cell::OnceCell;

use foldhash::HashMap;

mod selection;

pub use super::analysis::Order;
use super::analysis::{Dominators, branch_contexts, unplaced_step};
use super::{Block, Branch, BranchEnd, Graph, MAX_NESTING, State, gotos, visit};
use crate::diag::{Code, Diagnostic, Diagnostics};
use crate::model::{ElementKind, Sfc};

/// Walks the checked graph from `start` and recognises its structure. `None` when the flow
/// has errors (reported).
///
/// Where the structured forms cannot express the flow (a jump forward, into another branch,
/// out of several loops; branches that do not meet again), the walk is repeated with the
/// elements where it failed as the beginnings of states of a [`Block::Machine`]: each state is
/// walked as a structured sequence that ends in a [`Block::Goto`] where it reaches another
/// state. Each repetition adds at least one state, so the walk ends; every structure that does
/// not touch a state stays as it was.
pub fn walk(
    sfc: &Sfc,
    g: &Graph,
    jumps: &[Option<usize>],
    start: usize,
    order: Option<&Order>,
    diags: &mut Diagnostics,
) -> Option<Vec<Block>> {
    // Each element's simultaneous branches: made when a jump or a state asks (a chart without
    // jumps whose flow is structured never does).
    let contexts = OnceCell::new();
    let contexts_of = || contexts_at(&contexts, sfc, g, start);
    // A jump into or out of a simultaneous branch: the chart itself is wrong.
    let el = &sfc.elements;
    let mut unsafe_jumps = 0;
    for (j, t) in jumps.iter().enumerate() {
        if let Some(t) = *t
            && contexts_of()[j] != contexts_of()[t]
        {
            unsafe_jumps += 1;
            diags.push(
                Diagnostic::error(
                    Code::BadJump,
                    format!(
                        "this jump to step localId {} enters or leaves a simultaneous branch: simultaneous branches are entered at their divergence and left at their convergence (IEC 61131-3 calls such a chart unsafe)",
                        el[t].local_id
                    ),
                )
                .at(el[j].span.clone())
                .element(format!("localId {}", el[j].local_id))
                .related(el[t].span.clone(), "the jump's target"),
            );
        }
    }
    if unsafe_jumps > 0 {
        return None;
    }
    let mut entries = vec![false; sfc.elements.len()];
    // A jump to a step that does not lie on every path to it is never a loop: its target
    // begins a state from the start, so a chart of many such jumps is walked once, not once per
    // jump, and the branches they leave do not nest. (Jumps that leave several loops are found
    // by the walk.)
    // (`order` is there when the chart has jumps.)
    if let Some(order) = order {
        let dom = Dominators::new(g, start, order);
        for (j, t) in jumps.iter().enumerate() {
            if let Some(t) = *t
                && !dom.dominates(t, j)
            {
                entries[t] = true;
            }
        }
    }
    loop {
        let mut local = diags.empty_like();
        let (result, proposed) = walk_once(sfc, g, jumps, start, &entries, &contexts, &mut local);
        let mut new = false;
        if result.is_none() {
            for p in proposed {
                if !entries[p] {
                    entries[p] = true;
                    new = true;
                }
            }
        }
        if !new {
            diags.append(local);
            if let Some(body) = &result
                && let Some(lost) = unplaced_step(sfc, g, jumps, start, body)
            {
                // Never a program without a step of the chart.
                let e = &sfc.elements[lost];
                diags.push(
                    Diagnostic::error(
                        Code::Unsupported,
                        "this step has no place in the program skillpost built for the chart (an internal error; please report it with the chart)",
                    )
                    .at(e.span.clone())
                    .element(format!("localId {}", e.local_id)),
                );
                return None;
            }
            return result;
        }
    }
}

/// [`branch_contexts`] from `start`, made the first time it is asked for.
fn contexts_at<'c>(
    contexts: &'c OnceCell<Vec<u32>>,
    sfc: &Sfc,
    g: &Graph,
    start: usize,
) -> &'c [u32] {
    contexts.get_or_init(|| branch_contexts(sfc, g, start))
}

/// One walk with the given state entries: the body, or `None` and the elements that, made
/// entries of states, would let the walk go further.
fn walk_once(
    sfc: &Sfc,
    g: &Graph,
    jumps: &[Option<usize>],
    start: usize,
    entries: &[bool],
    contexts: &OnceCell<Vec<u32>>,
    diags: &mut Diagnostics,
) -> (Option<Vec<Block>>, Vec<usize>) {
    // A jump to a state's entry is a Goto, never a loop.
    let mut targeted = vec![false; sfc.elements.len()];
    for t in jumps.iter().flatten() {
        targeted[*t] = !entries[*t];
    }
    let mut jumps_to: HashMap<usize, Vec<usize>> = HashMap::default();
    for (j, t) in jumps.iter().enumerate() {
        if let Some(t) = t
            && !entries[*t]
        {
            jumps_to.entry(*t).or_default().push(j);
        }
    }
    let mut w = Walker {
        sfc,
        g,
        jumps,
        targeted,
        jumps_to,
        entries,
        contexts,
        start,
        proposed: Vec::new(),
        loops: Vec::new(),
        marks: vec![0; sfc.elements.len()],
        next_loop: 0,
        diags,
        failed: false,
    };
    let (mut body, end) = w.machine(start, true, 0);
    if w.failed {
        return (None, w.proposed);
    }
    // (A loop's deciding selection outside any loop cannot happen: the head would have opened
    // the loop.)
    match w.state_end(&mut body, end) {
        None => return (None, w.proposed),
        Some(End::Conv(c)) => {
            w.stray_convergence(c);
            return (None, w.proposed);
        }
        Some(_) => {}
    }
    // Where the chart is not structured, said once per place that goes to another state.
    if w.diags.keeps_warnings() {
        let el = &sfc.elements;
        visit(&body, &mut |b| {
            if let Block::Goto { target, from } = b {
                let how = if matches!(el[*from].kind, ElementKind::JumpStep(_)) {
                    "this jump"
                } else {
                    "the flow here"
                };
                w.diags.push(
                    Diagnostic::warning(
                        Code::Unstructured,
                        format!(
                            "{how} to {} localId {} is not a loop or a branch the program can write structured: it goes on at a label (KRL) or a state (RAPID, URScript)",
                            el[*target].kind.tag(),
                            el[*target].local_id
                        ),
                    )
                    .at(el[*from].span.clone())
                    .element(format!("localId {}", el[*from].local_id)),
                );
            }
        });
    } else {
        let mut n = 0;
        visit(&body, &mut |b| {
            n += usize::from(matches!(b, Block::Goto { .. }))
        });
        w.diags.count_dropped(n);
    }
    (Some(body), Vec::new())
}

/// The first state outside its own machine a branch goes to, if any.
fn gone_to(b: &[Block]) -> Option<usize> {
    let mut out = Vec::new();
    gotos(b, &mut out);
    out.first().copied()
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
    /// At a [`Block::Goto`] (the sequence's last block), or a selection whose branches all end
    /// in one: nothing follows.
    Left,
    /// At a selection whose branches all go to other states (not yet in the sequence).
    Branched(Box<Block>),
    /// At a selection whose branches go to other states but one, which ends at this
    /// simultaneousConvergence (the block is not yet in the sequence).
    BranchedAt(Box<Block>, usize),
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
    /// Nothing: every branch goes round again or to another state.
    Gone,
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
    /// The elements that begin states ([`Block::Machine`]): reaching one is a Goto.
    entries: &'a [bool],
    /// Each element's simultaneous branches ([`branch_contexts`]), made when first asked
    /// ([`Walker::branch_of`]).
    contexts: &'a OnceCell<Vec<u32>>,
    start: usize,
    /// Elements that would let a failed walk go further as entries of states.
    proposed: Vec<usize>,
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

impl<'a> Walker<'a> {
    /// Each element's simultaneous branches.
    fn branch_of(&self) -> &'a [u32] {
        contexts_at(self.contexts, self.sfc, self.g, self.start)
    }

    /// Walks a sequence from `cur` until it ends. `entered` says `cur` itself is to be taken
    /// even if it is a convergence (we arrive there after its branches) or a loop head that is
    /// being opened.
    fn seq(&mut self, mut cur: usize, mut entered: bool, depth: usize) -> (Vec<Block>, End) {
        let el = &self.sfc.elements;
        let mut out = Vec::new();
        let mut prev = cur;
        loop {
            if self.failed {
                return (out, End::Done);
            }
            if !entered && self.entries[cur] {
                out.push(Block::Goto {
                    target: cur,
                    from: prev,
                });
                return (out, End::Left);
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
                        prev = cur;
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
                ElementKind::JumpStep(_) => {
                    if let Some(t) = self.jumps[cur]
                        && self.entries[t]
                    {
                        out.push(Block::Goto {
                            target: t,
                            from: cur,
                        });
                        return (out, End::Left);
                    }
                    return (out, End::Jump(cur));
                }
                _ => {}
            }
            match succs.len() {
                0 => return (out, End::Done),
                1 => {
                    prev = cur;
                    cur = succs[0];
                }
                _ => {
                    if depth >= MAX_NESTING {
                        self.too_deep(cur);
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
                        Some(Err(End::Branched(block))) => {
                            out.push(*block);
                            return (out, End::Left);
                        }
                        Some(Err(End::BranchedAt(block, c))) => {
                            out.push(*block);
                            return (out, End::Conv(c));
                        }
                        Some(Err(end)) => return (out, end),
                        None => return (out, End::Done),
                    }
                }
            }
        }
    }

    /// Walks the sequence from `first` (as [`Walker::seq`]); where it goes to states, they are
    /// walked too and the sequence is a [`Block::Machine`] of them, which ends where its states
    /// end (in a simultaneous branch: at the branch's convergence).
    fn machine(&mut self, first: usize, entered: bool, depth: usize) -> (Vec<Block>, End) {
        // (A first element that begins a state is taken, not gone to.)
        let (body, end) = self.seq(first, entered || self.entries[first], depth);
        let mut next = Vec::new();
        gotos(&body, &mut next);
        if self.failed || next.is_empty() {
            return (body, end);
        }
        let el = &self.sfc.elements;
        let branch_of = self.branch_of();
        let here = branch_of[first];
        let mut states = vec![State { entry: first, body }];
        let mut ends = vec![end];
        let mut number: HashMap<usize, usize> = HashMap::default();
        number.insert(first, 0);
        let mut queue: std::collections::VecDeque<usize> = next.into_iter().collect();
        while let Some(entry) = queue.pop_front() {
            if number.contains_key(&entry) {
                continue;
            }
            if branch_of[entry] != here {
                let mut from = first;
                for st in &states {
                    visit(&st.body, &mut |b| {
                        if let Block::Goto { target, from: f } = b
                            && *target == entry
                        {
                            from = *f;
                        }
                    });
                }
                self.fail(
                    from,
                    Code::BadJump,
                    format!(
                        "this goes on at {} localId {} in another simultaneous branch: simultaneous branches are entered at their divergence and left at their convergence (IEC 61131-3 calls such a chart unsafe)",
                        el[entry].kind.tag(),
                        el[entry].local_id
                    ),
                );
                return (Vec::new(), End::Done);
            }
            number.insert(entry, states.len());
            let (body, end) = self.seq(entry, true, depth);
            if self.failed {
                return (Vec::new(), End::Done);
            }
            let mut next = Vec::new();
            gotos(&body, &mut next);
            queue.extend(next);
            states.push(State { entry, body });
            ends.push(end);
        }
        // How the states end: the machine ends where they do.
        let mut conv = None;
        let mut out = End::Left;
        for (st, end) in states.iter_mut().zip(ends) {
            match self.state_end(&mut st.body, end) {
                None => return (Vec::new(), End::Done),
                Some(End::Done) => out = End::Done,
                Some(End::Endless) => {
                    if !matches!(out, End::Done) {
                        out = End::Endless;
                    }
                }
                Some(End::Conv(c)) => {
                    if let Some(x) = conv.filter(|&x| x != c) {
                        self.proposed.push(x);
                        self.stray_convergence(c);
                        return (Vec::new(), End::Done);
                    }
                    conv = Some(c);
                }
                Some(_) => {}
            }
        }
        if let Some(c) = conv {
            out = End::Conv(c);
        }
        (vec![Block::Machine(states)], out)
    }

    /// Simultaneous branches from `div`: the block and the convergence to go on from.
    fn parallel(&mut self, div: usize, heads: Vec<usize>, depth: usize) -> Branches {
        let el = &self.sfc.elements;
        let mut branches = Vec::with_capacity(heads.len());
        let mut joins = Vec::with_capacity(heads.len());
        let mut endless = false;
        for h in heads {
            let (b, end) = self.machine(h, false, depth + 1);
            if self.failed {
                return None;
            }
            match end {
                End::Jump(j) => {
                    self.bad_jump(
                        j,
                        "it leaves a simultaneous branch, which must end in its convergence",
                    );
                    // Not a state: the chart itself is wrong.
                    self.proposed.clear();
                    return None;
                }
                _ if let Some(t) = gone_to(&b) => {
                    // (Within a branch, its own states are a machine: this goes elsewhere.)
                    self.fail(
                        div,
                        Code::BadJump,
                        format!(
                            "a jump enters or leaves a branch of this simultaneousDivergence at {} localId {}: simultaneous branches are entered at their divergence and left at their convergence (IEC 61131-3 calls such a chart unsafe)",
                            el[t].kind.tag(),
                            el[t].local_id
                        ),
                    );
                    return None;
                }
                End::Conv(c) => joins.push(c),
                // A branch that repeats without end (a jump back within it): the branches
                // never join, and nothing after them runs.
                End::Endless | End::Left => endless = true,
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
        if endless && joins.iter().all(|j| Some(j) == joins.first()) {
            return Some(Err(End::Branched(Box::new(Block::Parallel {
                divergence: div,
                convergence: joins.first().copied().unwrap_or(div),
                branches,
            }))));
        }
        let Some(&conv) = joins.first() else {
            // (Unreachable: a branch that does not join is endless or failed.)
            self.fail(
                div,
                Code::UnbalancedBranch,
                format!("{} opens branches that never join", el[div].kind.tag()),
            );
            return None;
        };
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

    /// Walks a selection branch from its transition `h` (whose condition selects it; it is not
    /// waited for).
    fn branch_walk(&mut self, h: usize, depth: usize) -> (Vec<Block>, End) {
        match self.after_head(h) {
            Some(f) => self.seq(f, false, depth + 1),
            None => (Vec::new(), End::Done),
        }
    }

    /// Where a selection branch's walk starts: after its transition `h`, or at `h` itself when
    /// the branch opens another selection (whose transitions select it).
    fn after_head(&self, h: usize) -> Option<usize> {
        if matches!(self.sfc.elements[h].kind, ElementKind::SelectionDivergence) {
            Some(h)
        } else {
            self.g.succs(h).first().copied()
        }
    }

    /// Opens a loop at step `head`: its blocks and then `Ok((element, entered))` to go on from,
    /// or `Err(end)` when the sequence ends; `None` on failure.
    fn open_loop(&mut self, head: usize, depth: usize) -> (Vec<Block>, Option<GoOn>) {
        if depth >= MAX_NESTING {
            self.too_deep(head);
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
                // (`After::Gone`: left only to other states.)
                let block = Block::Loop {
                    head,
                    jumps,
                    body,
                    endless,
                };
                let next = match after {
                    After::Nothing => Err(End::Endless),
                    After::Gone => Err(End::Left),
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

    /// Where the branches of a selection that do not join end (a convergence, the end step):
    /// as states, they need not join.
    fn propose_meetings(&mut self, walked: &[(usize, Vec<Block>, End, bool)]) {
        for (_, body, end, _) in walked {
            match end {
                // (Branches meet at a simultaneousConvergence only at the end of theirs.)
                End::Conv(c)
                    if !matches!(
                        self.sfc.elements[*c].kind,
                        ElementKind::SimultaneousConvergence
                    ) =>
                {
                    self.proposed.push(*c)
                }
                End::Done => {
                    if let Some(Block::Step(s)) = body.last() {
                        self.proposed.push(*s);
                    }
                }
                _ => {}
            }
        }
    }

    /// The flow nests too deep at `at` (reported). Where flow allows it, this is left to
    /// states: `at` begins one (walked from depth 0), and when loops are open, every jump's
    /// target does too (the chart loses its loops, but one more walk suffices; a chart this
    /// deep is not written by hand).
    fn too_deep(&mut self, at: usize) {
        self.proposed.push(at);
        if !self.loops.is_empty() {
            let targets: Vec<usize> = self.jumps.iter().flatten().copied().collect();
            self.proposed.extend(targets);
        }
        self.fail(
            at,
            Code::Unsupported,
            format!("branches and loops nested deeper than {MAX_NESTING} levels"),
        );
    }

    /// A convergence where branches meet that no divergence opened here (reported): as a
    /// state, it need not close a divergence.
    fn stray_convergence(&mut self, c: usize) {
        self.proposed.push(c);
        self.fail(
            c,
            Code::UnbalancedBranch,
            format!(
                "{} joins branches that no divergence opened",
                self.sfc.elements[c].kind.tag()
            ),
        );
    }

    /// How a state's sequence ended, its last block added: `Some(Conv(c))` (it ends its
    /// simultaneous branch there) or another end after which nothing follows; `None` for a jump
    /// that leads nowhere structured (reported).
    fn state_end(&mut self, body: &mut Vec<Block>, end: End) -> Option<End> {
        match end {
            End::Jump(j) => {
                self.bad_jump(j, "it does not lead back to a step on every path to it");
                None
            }
            End::Decided { choice, .. } | End::Branched(choice) | End::BranchedAt(choice, _) => {
                body.push(*choice);
                Some(End::Left)
            }
            other => Some(other),
        }
    }

    /// The innermost loop cannot be structured: as a state, its head is gone to.
    fn propose_loop(&mut self) {
        if let Some(l) = self.loops.last() {
            self.proposed.push(l.head);
        }
    }

    fn bad_jump(&mut self, j: usize, why: &str) {
        if let Some(t) = self.jumps[j] {
            self.proposed.push(t);
        }
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
