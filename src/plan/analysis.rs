//! What the walk asks of the chart before and after it recognises the structure: a topological
//! order of the connections, the dominator tree (whether every path to an element passes
//! another), each element's simultaneous branches, and the check that every reachable step was
//! placed.

use foldhash::HashMap;

use super::{Block, Graph, visit};
use crate::model::{ElementKind, Sfc};

/// The dominator tree of the connections from the start (which have no cycle: `find_cycle`),
/// numbered for constant-time questions.
pub(super) struct Dominators {
    /// Entry and exit numbers of each element in a walk of the tree (`usize::MAX`: not reached
    /// from the start by connections).
    enter: Vec<usize>,
    exit: Vec<usize>,
}

impl Dominators {
    pub(super) fn new(g: &Graph, start: usize, o: &Order) -> Self {
        let n = g.len();
        let (order, by_order) = (&o.place, &o.elements);
        const NONE: usize = usize::MAX;
        let mut idom = vec![NONE; n];
        idom[start] = start;
        for &v in by_order {
            if v == start {
                continue;
            }
            let mut new = NONE;
            for &p in g.preds(v) {
                if idom[p] == NONE {
                    continue;
                }
                new = if new == NONE {
                    p
                } else {
                    // The nearest common dominator: each idom comes earlier in the order.
                    let (mut a, mut b) = (p, new);
                    while a != b {
                        while order[a] > order[b] {
                            a = idom[a];
                        }
                        while order[b] > order[a] {
                            b = idom[b];
                        }
                    }
                    a
                };
            }
            idom[v] = new;
        }
        // Each element's children in the tree, flat: `v`'s are `child[first[v]..first[v + 1]]`
        // (one allocation, not one per element: 100,000 steps).
        let mut first = vec![0usize; n + 1];
        for v in 0..n {
            if idom[v] != NONE && v != start {
                first[idom[v] + 1] += 1;
            }
        }
        for v in 0..n {
            first[v + 1] += first[v];
        }
        let mut child = vec![0usize; first[n]];
        let mut fill = first.clone();
        for v in 0..n {
            if idom[v] != NONE && v != start {
                child[fill[idom[v]]] = v;
                fill[idom[v]] += 1;
            }
        }
        drop(fill);
        let children = |v: usize| &child[first[v]..first[v + 1]];
        let (mut enter, mut exit) = (vec![NONE; n], vec![NONE; n]);
        let mut clock = 0;
        let mut stack = vec![(start, 0usize)];
        enter[start] = 0;
        while let Some((v, k)) = stack.pop() {
            if k < children(v).len() {
                stack.push((v, k + 1));
                let c = children(v)[k];
                clock += 1;
                enter[c] = clock;
                stack.push((c, 0));
            } else {
                clock += 1;
                exit[v] = clock;
            }
        }
        Dominators { enter, exit }
    }

    /// Whether every path of connections from the start to `b` passes `a`.
    pub(super) fn dominates(&self, a: usize, b: usize) -> bool {
        self.enter[a] != usize::MAX
            && self.enter[b] != usize::MAX
            && self.enter[a] <= self.enter[b]
            && self.exit[b] <= self.exit[a]
    }
}

/// A topological order of the connections (jumps are not connections; `find_cycle` found no
/// cycle of connections), the same for every sequence of a chart: computed once.
pub struct Order {
    /// Each element's place in the order (`usize::MAX`: none, on a cycle).
    place: Vec<usize>,
    /// The elements in the order (those on a cycle last).
    elements: Vec<usize>,
}

impl Order {
    pub fn new(g: &Graph) -> Self {
        let n = g.len();
        let mut missing: Vec<usize> = (0..n).map(|i| g.preds(i).len()).collect();
        // First in, first out: the elements of a short branch (a jump) come before those of a
        // long one, so more forward jumps are seen as such.
        let mut ready: std::collections::VecDeque<usize> =
            (0..n).filter(|&i| missing[i] == 0).collect();
        let mut place = vec![usize::MAX; n];
        let mut elements = Vec::with_capacity(n);
        while let Some(i) = ready.pop_front() {
            place[i] = elements.len();
            elements.push(i);
            for &s in g.succs(i) {
                missing[s] -= 1;
                if missing[s] == 0 {
                    ready.push_back(s);
                }
            }
        }
        elements.extend((0..n).filter(|&i| place[i] == usize::MAX));
        Order { place, elements }
    }
}

/// A step the chart reaches (by connections and jumps from the start) that `body` does not
/// hold.
pub(super) fn unplaced_step(
    sfc: &Sfc,
    g: &Graph,
    jumps: &[Option<usize>],
    start: usize,
    body: &[Block],
) -> Option<usize> {
    let mut placed = vec![false; sfc.elements.len()];
    visit(body, &mut |b| {
        if let Block::Step(i) = b {
            placed[*i] = true;
        }
    });
    let mut seen = vec![false; sfc.elements.len()];
    let mut todo = vec![start];
    while let Some(i) = todo.pop() {
        if std::mem::replace(&mut seen[i], true) {
            continue;
        }
        if sfc.elements[i].kind.is_step() && !placed[i] {
            return Some(i);
        }
        todo.extend_from_slice(g.succs(i));
        todo.extend(jumps[i]);
    }
    None
}

/// Each element's simultaneous branches (the branch of each enclosing simultaneousDivergence),
/// as a number per distinct list (0: none), from `start` along connections. A Goto stays
/// among the elements of one number: a jump that enters or leaves a simultaneous branch makes
/// a chart IEC 61131-3 calls unsafe.
pub(super) fn branch_contexts(sfc: &Sfc, g: &Graph, start: usize) -> Vec<u32> {
    let el = &sfc.elements;
    let mut ctx = vec![u32::MAX; el.len()];
    // Each context: its parent and the (divergence, branch) that opened it.
    let mut known: HashMap<(u32, usize, usize), u32> = HashMap::default();
    let mut parent: Vec<u32> = vec![0];
    let mut todo = vec![(start, 0u32)];
    while let Some((i, c)) = todo.pop() {
        if ctx[i] != u32::MAX {
            continue;
        }
        ctx[i] = c;
        match el[i].kind {
            ElementKind::SimultaneousDivergence => {
                for (k, &b) in g.succs(i).iter().enumerate() {
                    let next = parent.len() as u32;
                    let id = *known.entry((c, i, k)).or_insert(next);
                    if id == next {
                        parent.push(c);
                    }
                    todo.push((b, id));
                }
            }
            ElementKind::SimultaneousConvergence => {
                let up = parent[c as usize];
                for &x in g.succs(i) {
                    todo.push((x, up));
                }
            }
            ElementKind::JumpStep(_) => {}
            _ => {
                for &x in g.succs(i) {
                    todo.push((x, c));
                }
            }
        }
    }
    for c in ctx.iter_mut() {
        if *c == u32::MAX {
            *c = 0;
        }
    }
    ctx
}
