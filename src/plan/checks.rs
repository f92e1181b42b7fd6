//! The graph rules, each element on its own (`check_nodes`), jump targets, start and end, and
//! cycles of connections.

use std::collections::HashMap;
use std::sync::Arc;

use super::{Graph, label, list_ids};
use crate::diag::{Code, Diagnostic, Diagnostics};
use crate::model::{ElementKind, Sfc};

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
                if !g.has_macro_body(i) {
                    diags.push(err(
                        Code::Unsupported,
                        "macroStep without a body (`body/SFC`): there is nothing to run in its place".to_owned(),
                    ));
                } else if np != 1 || ns != 1 {
                    // (Also the consequence of a body without one end step: secondary.)
                    secondary.push(err(
                        Code::StepFanInOut,
                        format!(
                            "macroStep has {np} inputs and is followed by {ns}; like a step, it has one of each"
                        ),
                    ));
                }
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
                        _ if !div && np == 1 && !g.lost_jumps(i) => diags.push(unbalanced(format!(
                            "{tag} joins only one branch: {opens} opens {branches} branches and {closes} joins them"
                        ))),
                        _ => {}
                    }
                    if matches!(kind, ElementKind::SelectionDivergence) {
                        for &h in g.succs(i) {
                            // A branch may open another selection (CODESYS nests them).
                            if !matches!(
                                el[h].kind,
                                ElementKind::Transition(_) | ElementKind::SelectionDivergence
                            ) {
                                diags.push(unbalanced(format!(
                                    "selection branch starts with {} localId {}; each selection branch starts with a transition (its condition)",
                                    el[h].kind.tag(),
                                    el[h].local_id
                                )));
                            }
                        }
                    }
                }
                if g.only_jumps(i) {
                    // Gathers only jumps: not part of the flow (CODESYS).
                } else if np == 0 {
                    diags.push(err(
                        Code::StartStep,
                        format!("{tag} has no input: the flow must start at a step"),
                    ));
                }
                if ns == 0 && !g.only_jumps(i) {
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
    // A connection back to an earlier step (`close_circles`) knows its step.
    for c in &sfc.closed {
        out[c.jump] = Some(c.target);
    }
    if !el
        .iter()
        .enumerate()
        .any(|(i, e)| matches!(e.kind, ElementKind::JumpStep(_)) && out[i].is_none())
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
        if out[i].is_some() {
            continue;
        }
        match by_name.get(&*target.key).map(Vec::as_slice) {
            Some([t]) => out[i] = Some(*t),
            None | Some([]) => diags.push(
                Diagnostic::error(
                    Code::BadJump,
                    format!(
                        "jump target `{}` names no step{}",
                        target.text,
                        // Only on this error path: every step's name is looked at.
                        crate::names::did_you_mean(
                            &target.text,
                            el.iter().filter_map(|e| match &e.kind {
                                ElementKind::Step(st) => Some(st.name.as_ref()),
                                _ => None,
                            })
                        )
                    ),
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

/// The start and the end step of each sequence, found after the jumps are resolved: a step
/// that only jumps lead to is not a second start (unless there is no other), and a chart that
/// ends in jumps only has no end step (`None`). Several steps marked `initialStep="true"`, each
/// in a network of its own (not connected to the others by connections or jumps), begin
/// sequences of their own (docs/INPUTS.md), in document order; two in one network are an error.
/// Reports a missing or repeated start or end.
pub fn start_end(
    sfc: &Sfc,
    g: &Graph,
    jumps: &[Option<usize>],
    diags: &mut Diagnostics,
) -> Option<Vec<(usize, Option<usize>)>> {
    let el = &sfc.elements;
    let mut targeted = vec![false; el.len()];
    for t in jumps.iter().flatten() {
        targeted[*t] = true;
    }
    // The marked initial steps, found once (each a step's data to look at: 100,000 steps).
    let initials: Vec<usize> = (0..el.len()).filter(|&i| initial(sfc, g, i)).collect();
    if initials.len() < 2 {
        // One sequence at most: which network each element is in does not matter.
        return one_sequence(sfc, g, &targeted, &initials, &|_| true, diags).map(|se| vec![se]);
    }
    let net = networks(g, jumps);
    // The networks with a marked initial step, in the document order of their first one.
    let mut marked_nets: Vec<usize> = Vec::new();
    let mut has_initial = vec![false; el.len()];
    for &i in &initials {
        let e = &el[i];
        if !has_initial[net[i]] {
            has_initial[net[i]] = true;
            marked_nets.push(net[i]);
            if marked_nets.len() > super::MAX_SEQUENCES {
                // Each sequence needs a controller of its own; finding each one's start and
                // end is a pass over the chart.
                diags.push(
                    Diagnostic::error(
                        Code::StartStep,
                        format!(
                            "more than {} sequences (steps marked initialStep=\"true\" with nothing connecting them): each runs on controllers of its own; this is the {}th",
                            super::MAX_SEQUENCES,
                            marked_nets.len()
                        ),
                    )
                    .at(e.span.clone())
                    .element(label(sfc, i)),
                );
                return None;
            }
        }
    }
    if marked_nets.len() < 2 {
        return one_sequence(sfc, g, &targeted, &initials, &|_| true, diags).map(|se| vec![se]);
    }
    // Several sequences: each network's own start and end. A step in a network without an
    // initial step is never run.
    let mut out = Vec::with_capacity(marked_nets.len());
    let mut ok = true;
    for &n in &marked_nets {
        match one_sequence(sfc, g, &targeted, &initials, &|i| net[i] == n, diags) {
            Some(se) => out.push(se),
            None => ok = false,
        }
    }
    let orphans: Vec<usize> = (0..el.len())
        .filter(|&i| el[i].kind.is_step() && !g.in_macro_body(i) && !has_initial[net[i]])
        .collect();
    if let Some(&first) = orphans.first() {
        let heads: Vec<usize> = orphans
            .iter()
            .copied()
            .filter(|&i| g.preds(i).is_empty())
            .collect();
        diags.push(
            Diagnostic::error(
                Code::StartStep,
                format!(
                    "{} step{} in no sequence with an initial step: {}; the chart has several initial steps, each beginning a sequence of its own, and nothing runs {} (mark {} initialStep=\"true\" to begin a sequence, or connect {} to one)",
                    orphans.len(),
                    if orphans.len() == 1 { "" } else { "s" },
                    list_ids(sfc, &orphans),
                    if orphans.len() == 1 { "it" } else { "them" },
                    if heads.is_empty() { "one of them".to_owned() } else { list_ids(sfc, &heads) },
                    if orphans.len() == 1 { "it" } else { "them" },
                ),
            )
            .at(el[first].span.clone())
            .element(label(sfc, first)),
        );
        ok = false;
    }
    ok.then_some(out)
}

/// The networks of the chart: elements joined by connections or jumps (in either direction)
/// share a number.
fn networks(g: &Graph, jumps: &[Option<usize>]) -> Vec<usize> {
    let n = g.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let mut join = |a: usize, b: usize| {
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        if ra != rb {
            parent[ra.max(rb)] = ra.min(rb);
        }
    };
    for i in 0..n {
        for &s in g.succs(i) {
            join(i, s);
        }
        if let Some(Some(t)) = jumps.get(i) {
            join(i, *t);
        }
    }
    (0..n).map(|i| root(&mut parent, i)).collect()
}

/// Whether element `i` is a step marked `initialStep="true"` of the chart itself (a macro step's
/// body marks its own initial step).
fn initial(sfc: &Sfc, g: &Graph, i: usize) -> bool {
    matches!(&sfc.elements[i].kind, ElementKind::Step(st) if st.initial) && !g.in_macro_body(i)
}

/// The start and the end of the one sequence of the elements `mine` holds (a pass over the
/// chart for each sequence: [`super::MAX_SEQUENCES`] bounds them).
fn one_sequence(
    sfc: &Sfc,
    g: &Graph,
    targeted: &[bool],
    initials: &[usize],
    mine: &dyn Fn(usize) -> bool,
    diags: &mut Diagnostics,
) -> Option<(usize, Option<usize>)> {
    let el = &sfc.elements;
    // One pass over the chart: whether it has jumps, its steps without a predecessor and
    // those without a successor.
    let mut has_jumps = false;
    let (mut no_pred, mut ends) = (Vec::new(), Vec::new());
    for (i, e) in el.iter().enumerate() {
        match e.kind {
            ElementKind::JumpStep(_) if mine(i) => has_jumps = true,
            ElementKind::Step(_) if mine(i) => {
                if g.preds(i).is_empty() {
                    no_pred.push(i);
                }
                if g.succs(i).is_empty() {
                    ends.push(i);
                }
            }
            _ => {}
        }
    }
    let untargeted: Vec<usize> = no_pred.iter().copied().filter(|&i| !targeted[i]).collect();
    // The start is the step marked initialStep="true" (docs/INPUTS.md): the one marked step without
    // a predecessor (the original also marks its end step), else the one marked step (a chart
    // drawn as a closed circle); else the one step without a predecessor that no jump leads to.
    let initial = |i: &usize| initial(sfc, g, *i);
    let marked: Vec<usize> = initials.iter().copied().filter(|&i| mine(i)).collect();
    let marked_free: Vec<usize> = untargeted.iter().copied().filter(initial).collect();
    let starts = match (marked_free.as_slice(), marked.as_slice()) {
        ([_], _) | ([], [_]) => {
            let s = marked_free.first().or(marked.first()).copied().unwrap_or(0);
            // Other steps nothing leads to are never run.
            let unreached: Vec<usize> = untargeted.iter().copied().filter(|&i| i != s).collect();
            if !unreached.is_empty() {
                let mut d = Diagnostic::error(
                    Code::StartStep,
                    format!(
                        "{} step{} without a predecessor besides the start step {}: {} (nothing leads to {}; connect {} or remove {})",
                        unreached.len(),
                        if unreached.len() == 1 { "" } else { "s" },
                        label(sfc, s),
                        list_ids(sfc, &unreached),
                        if unreached.len() == 1 { "it" } else { "them" },
                        if unreached.len() == 1 { "it" } else { "them" },
                        if unreached.len() == 1 { "it" } else { "them" },
                    ),
                )
                .at(el[unreached[0]].span.clone())
                .element(label(sfc, unreached[0]));
                d = d.related(el[s].span.clone(), "the start step (initialStep=\"true\")");
                diags.push(d);
                return None;
            }
            vec![s]
        }
        (many, _) if many.len() > 1 => many.to_vec(),
        _ if untargeted.is_empty() => no_pred,
        _ => untargeted,
    };
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
            let all_marked = starts.iter().all(initial);
            let mut d = Diagnostic::error(
                Code::StartStep,
                if all_marked {
                    format!(
                        "{} initial steps (marked initialStep=\"true\", without a predecessor) in one network: {}; a network has one initial step (IEC 61131-3). Several initial steps begin sequences of their own only when nothing connects them",
                        starts.len(),
                        list_ids(sfc, &starts)
                    )
                } else {
                    format!(
                        "{} start steps (steps without a predecessor): {}",
                        starts.len(),
                        list_ids(sfc, &starts)
                    )
                },
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

/// Kahn's algorithm; returns an element on a cycle of connections, if any (jumps are not
/// connections).
pub fn find_cycle(g: &Graph) -> Option<usize> {
    let n = g.len();
    // Every connection from an earlier element (as charts are mostly written): no cycle, seen
    // in one pass over the connections.
    if (0..n).all(|i| g.preds(i).iter().all(|&p| p < i)) {
        return None;
    }
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
