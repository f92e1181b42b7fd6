//! The flow graph: ids, connections, predecessors and successors.

use std::collections::HashMap;

use crate::diag::{Code, Diagnostic, Diagnostics, Span};
use crate::model::{ElementKind, Sfc};

/// The flow graph: predecessors and successors by element index, in compact (CSR) form: one
/// array of edges per direction and an offset per element.
#[derive(Debug, Default)]
pub struct Graph {
    pred_at: Vec<usize>,
    pred: Vec<usize>,
    succ_at: Vec<usize>,
    succ: Vec<usize>,
    /// The selectionConvergences drawn with a jumpStep among their inputs (as CODESYS exports
    /// a branch that ends in a jump), ascending: that input is not a connection.
    lost_jumps: Vec<usize>,
    /// The selectionConvergences that gather only jumps (and such convergences), ascending:
    /// CODESYS closes a drawing so; they are not part of the flow.
    only_jumps: Vec<usize>,
    /// Per element, whether it belongs to a macro step's body (empty without macro steps).
    in_macro_body: Vec<bool>,
    /// The macro steps with a body, ascending.
    macro_steps: Vec<usize>,
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

    /// Whether element `i` is a selectionConvergence that a jumpStep was drawn into (the jump
    /// ends its branch; the drawn connection is not part of the flow).
    pub fn lost_jumps(&self, i: usize) -> bool {
        self.lost_jumps.binary_search(&i).is_ok()
    }

    /// Whether element `i` is a selectionConvergence whose inputs are all jumps (or such
    /// convergences): it is not part of the flow.
    pub fn only_jumps(&self, i: usize) -> bool {
        self.only_jumps.binary_search(&i).is_ok()
    }

    /// Whether element `i` belongs to a macro step's body.
    pub fn in_macro_body(&self, i: usize) -> bool {
        self.in_macro_body.get(i).copied().unwrap_or(false)
    }

    /// Whether element `i` is a macro step with a body.
    pub fn has_macro_body(&self, i: usize) -> bool {
        self.macro_steps.binary_search(&i).is_ok()
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
pub(super) enum Ids {
    Dense(Vec<u32>),
    Sparse(foldhash::HashMap<u64, usize>),
}

impl Ids {
    const NONE: u32 = u32::MAX;

    pub(super) fn new(sfc: &Sfc) -> Self {
        let n = sfc.elements.len();
        let max = sfc.elements.iter().map(|e| e.local_id).max().unwrap_or(0);
        if n < Self::NONE as usize && max < (4 * n as u64 + 1024) {
            Ids::Dense(vec![Self::NONE; max as usize + 1])
        } else {
            Ids::Sparse(foldhash::HashMap::with_capacity_and_hasher(
                n,
                Default::default(),
            ))
        }
    }

    pub(super) fn get(&self, id: u64) -> Option<usize> {
        match self {
            Ids::Dense(t) => t
                .get(id as usize)
                .copied()
                .filter(|&v| v != Self::NONE)
                .map(|v| v as usize),
            Ids::Sparse(m) => m.get(&id).copied(),
        }
    }

    pub(super) fn insert(&mut self, id: u64, i: usize) {
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
    // Macro steps (docs/INPUTS.md): the body's chart runs in the step's place. What follows the
    // macro step follows the body's end step; the body's initial step follows the macro step.
    let mut after_macro: HashMap<usize, (usize, std::ops::Range<usize>)> = HashMap::new();
    let mut into_body: HashMap<usize, usize> = HashMap::new();
    // Each body element's innermost macro step, in one sweep over the elements with the bodies
    // open at each (bodies nest or are apart); a macro step in more bodies than branches may
    // nest in each other is E313 (docs/INPUTS.md).
    const NONE: usize = usize::MAX;
    let mut owner = vec![NONE; if sfc.macros.is_empty() { 0 } else { n }];
    if !sfc.macros.is_empty() {
        let mut by_start: Vec<usize> = (0..sfc.macros.len()).collect();
        by_start.sort_unstable_by_key(|&k| sfc.macros[k].body.start);
        let mut next = by_start.iter().peekable();
        let mut open: Vec<usize> = Vec::new();
        let mut too_deep = false;
        for (i, o) in owner.iter_mut().enumerate() {
            while open.last().is_some_and(|&k| sfc.macros[k].body.end <= i) {
                open.pop();
            }
            while let Some(&&k) = next.peek()
                && sfc.macros[k].body.start <= i
            {
                next.next();
                if sfc.macros[k].body.is_empty() {
                    continue;
                }
                if open.len() == super::MAX_NESTING && !too_deep {
                    too_deep = true;
                    let e = &sfc.elements[sfc.macros[k].step];
                    diags.push(
                        Diagnostic::error(
                            Code::Unsupported,
                            format!(
                                "macro steps nested deeper than {} levels",
                                super::MAX_NESTING
                            ),
                        )
                        .at(e.span.clone())
                        .element(format!("localId {}", e.local_id)),
                    );
                }
                open.push(k);
            }
            if let Some(&k) = open.last() {
                *o = k;
            }
        }
    }
    for (k, m) in sfc.macros.iter().enumerate() {
        let body = m.body.clone();
        let el = &sfc.elements;
        // (Not the steps of a macro step's body nested in this one.)
        let steps: Vec<usize> = body
            .clone()
            .filter(|&i| el[i].kind.is_step() && owner[i] == k)
            .collect();
        let used: std::collections::HashSet<usize> = body
            .clone()
            .flat_map(|i| el[i].inputs.iter().filter_map(|(r, _)| ids.get(*r)))
            .collect();
        let first: Vec<usize> = steps
            .iter()
            .copied()
            .filter(|&i| matches!(&el[i].kind, ElementKind::Step(st) if st.initial))
            .collect();
        let first = if first.len() == 1 {
            first
        } else {
            steps
                .iter()
                .copied()
                .filter(|&i| el[i].inputs.is_empty())
                .collect()
        };
        let last: Vec<usize> = steps
            .iter()
            .copied()
            .filter(|i| !used.contains(i))
            .collect();
        if let [i] = first.as_slice() {
            into_body.insert(*i, m.step);
        }
        match (first.as_slice(), last.as_slice()) {
            ([_], [e]) => {
                after_macro.insert(m.step, (*e, body));
            }
            _ => diags.push(
                Diagnostic::error(
                    Code::StartStep,
                    format!(
                        "the body of macroStep localId {} has {} initial step{} and {} end step{}; it needs one of each",
                        el[m.step].local_id,
                        first.len(),
                        if first.len() == 1 { "" } else { "s" },
                        last.len(),
                        if last.len() == 1 { "" } else { "s" },
                    ),
                )
                .at(el[m.step].span.clone())
                .element(format!("localId {}", el[m.step].local_id)),
            ),
        }
    }
    // Edges (producer, consumer), predecessors in document order of the connections.
    let mut pred_at = Vec::with_capacity(n + 1);
    let mut pred = Vec::with_capacity(n);
    let mut succ_count = vec![0usize; n];
    let mut seen: std::collections::HashSet<usize> = std::collections::HashSet::new();
    let mut lost_jumps = Vec::new();
    // Convergences that gather only jumps (one may gather another's): each convergence counts
    // its inputs that are neither a jump nor such a convergence; one whose count falls to 0 is
    // one, and lowers the counts of the convergences it feeds. Linear, in any document order.
    let mut only_jumps = vec![false; n];
    if sfc
        .elements
        .iter()
        .any(|e| matches!(e.kind, ElementKind::JumpStep(_)))
    {
        let is_conv =
            |e: &crate::model::Element| matches!(e.kind, ElementKind::SelectionConvergence);
        let mut others = vec![0usize; n];
        let mut fed: HashMap<usize, Vec<usize>> = HashMap::new();
        let mut ready = Vec::new();
        for (i, e) in sfc.elements.iter().enumerate() {
            if !is_conv(e) || e.inputs.is_empty() {
                continue;
            }
            for (r, _) in e.inputs.iter() {
                match ids.get(*r) {
                    Some(p) if matches!(sfc.elements[p].kind, ElementKind::JumpStep(_)) => {}
                    Some(p) if is_conv(&sfc.elements[p]) => {
                        others[i] += 1;
                        fed.entry(p).or_default().push(i);
                    }
                    _ => others[i] += 1,
                }
            }
            if others[i] == 0 {
                ready.push(i);
            }
        }
        while let Some(i) = ready.pop() {
            only_jumps[i] = true;
            for &c in fed.get(&i).map(Vec::as_slice).unwrap_or_default() {
                others[c] -= 1;
                if others[c] == 0 {
                    ready.push(c);
                }
            }
        }
    }
    for (i, e) in sfc.elements.iter().enumerate() {
        pred_at.push(pred.len());
        let first = pred.len();
        seen.clear();
        for (r, range) in &e.inputs {
            match ids.get(*r) {
                Some(p)
                    if (matches!(sfc.elements[p].kind, ElementKind::JumpStep(_))
                        || only_jumps[p])
                        && matches!(e.kind, ElementKind::SelectionConvergence) =>
                {
                    // CODESYS draws a branch that ends in a jump into the selection's
                    // convergence; the jump ends the branch.
                    if lost_jumps.last() != Some(&i) {
                        lost_jumps.push(i);
                    }
                }
                Some(p) => {
                    // Out of a macro step (from outside its body): out of its body's end.
                    let p = match after_macro.get(&p) {
                        Some((end, body)) if !body.contains(&i) => *end,
                        _ => p,
                    };
                    // A scan for the usual one or two inputs; a convergence of many is
                    // deduplicated through `seen` (its width must not cost its square).
                    let dup = if pred.len() - first < 8 {
                        pred[first..].contains(&p)
                    } else {
                        if seen.len() < pred.len() - first {
                            seen.clear();
                            seen.extend(pred[first..].iter().copied());
                        }
                        !seen.insert(p)
                    };
                    if !dup {
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
        if let Some(&m) = into_body.get(&i) {
            pred.push(m);
            succ_count[m] += 1;
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
        lost_jumps,
        only_jumps: only_jumps
            .iter()
            .enumerate()
            .filter_map(|(i, &o)| o.then_some(i))
            .collect(),
        in_macro_body: owner.iter().map(|&o| o != NONE).collect(),
        macro_steps: {
            let mut v: Vec<usize> = sfc.macros.iter().map(|m| m.step).collect();
            v.sort_unstable();
            v
        },
    }
}
