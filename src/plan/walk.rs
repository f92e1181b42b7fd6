//! The walk over the checked graph that recognises the program's structure: sequences, waits,
//! simultaneous and selection branches, loops closed by jumps (see `ARCHITECTURE.md`, "The
//! program tree").

use std::collections::HashMap;

use super::{Block, Branch, BranchEnd, Graph, MAX_NESTING, visit};
use crate::diag::{Code, Diagnostic, Diagnostics};
use crate::model::{ElementKind, Sfc};

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
