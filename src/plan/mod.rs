//! SFC graph checks and the ordered program tree (docs/INPUTS.md).
//!
//! [`plan`] runs in parts, each with its own tests: [`graph`](fn@graph) (ids and connections),
//! [`check_nodes`] (each element's inputs and outputs), [`resolve_jumps`] (jump targets),
//! [`start_end`] (found after the jumps are resolved), [`find_cycle`] (a cycle of connections,
//! not of jumps) and the walk, which recognises the structure: sequences, guarded transitions
//! ([`Block::Wait`]), simultaneous branches ([`Block::Parallel`]), selection branches
//! ([`Block::Choice`]) and loops closed by a jump back ([`Block::Loop`]). Branches are in
//! emission order: left to right by the x of each branch head, ties in document order; for
//! selections that order is their priority.

mod analysis;
pub mod cell;
mod checks;
mod circles;
mod graph;
mod walk;

pub use checks::{check_nodes, find_cycle, resolve_jumps, start_end};
pub use circles::close_circles;
pub use graph::{Graph, graph};
pub use walk::{Order, walk};

use crate::diag::{Code, Diagnostic, Diagnostics};
use crate::model::Sfc;

/// Branches, loops and macro steps nest at most this deep ([`crate::model::MAX_NESTING`]: the SFC
/// reader refuses deeper macro steps as it reads them).
pub const MAX_NESTING: usize = crate::model::MAX_NESTING;

/// At most this many sequences (several initial steps, docs/INPUTS.md): each needs controllers of its
/// own, and each is a walk over the chart.
pub const MAX_SEQUENCES: usize = 64;

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
    /// A handshake (docs/CELLS.md): this controller tells another that a step is done or which
    /// branch it took. Only in the programs of a cell of several controllers ([`cell`]).
    Tell(cell::Message),
    /// A handshake: this controller waits until another tells it what it waits for.
    Hear(cell::Message),
    /// Flow the structured forms cannot express (docs/INPUTS.md, "Loops and jumps"): states, the
    /// first begins at the start. Each state's body is structured; where the chart goes on at
    /// another state, a branch or the state's sequence ends in [`Block::Goto`]. The program
    /// ends when a state ends without one. KRL: a label per state and `GOTO`; RAPID and
    /// URScript: a state variable read in a loop.
    Machine(Vec<State>),
    /// The flow goes on at the state that begins at element `target` (the last block of its
    /// sequence). `from` is the jumpStep, or the element that `target` follows.
    Goto { target: usize, from: usize },
    /// A selection another controller decides: this program waits for the decision
    /// (`heard`, whose value is the branch's index) and runs that branch.
    Follow {
        divergence: usize,
        heard: cell::Message,
        branches: Vec<Branch>,
    },
    /// Independent sequences (docs/INPUTS.md: several steps marked `initialStep="true"`, each
    /// beginning a network of its own), in the document order of their initial steps. They
    /// run at the same time, each on controllers of its own ([`place_sequences`]); the cell
    /// split gives each controller its sequence, with no handshake between sequences.
    Sequences(Vec<Vec<Block>>),
}

/// One state of a [`Block::Machine`]: the element it begins at (a step, or a convergence
/// where branches that the structured forms cannot join meet) and its structured body.
#[derive(Debug, Clone, PartialEq)]
pub struct State {
    pub entry: usize,
    pub body: Vec<Block>,
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

/// The condition of transition `t` as written, on one line (`TRUE` when it has none): what the
/// listings (`-pF`, `-pO`) and the picture show.
pub fn condition_text(sfc: &Sfc, t: usize) -> String {
    match &sfc.elements[t].kind {
        crate::model::ElementKind::Transition(Some(c)) => one_line(&c.text),
        _ => "TRUE".to_owned(),
    }
}

/// A text on one line: its words joined by single spaces.
pub fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

impl Branch {
    /// What selects the branch, as written: its transition's condition, or any first condition
    /// of the selection it opens (`(a) OR (b)`).
    pub fn condition_text(&self, sfc: &Sfc) -> String {
        match self.heads().as_slice() {
            [one] => condition_text(sfc, *one),
            heads => heads
                .iter()
                .map(|&h| format!("({})", condition_text(sfc, h)))
                .collect::<Vec<_>>()
                .join(" OR "),
        }
    }
}

impl State {
    /// Each state's entry element and its number, counting from `first`: what a Goto to that
    /// element goes to.
    pub fn numbers(states: &[State], first: usize) -> std::collections::HashMap<usize, usize> {
        states
            .iter()
            .enumerate()
            .map(|(k, st)| (st.entry, first + k))
            .collect()
    }
}

impl Branch {
    /// The transitions whose conditions select this branch: its own, or, when the branch
    /// starts with another selectionDivergence (as CODESYS draws nested alternatives), the
    /// first transitions of that selection's branches: any of them selects it.
    pub fn heads(&self) -> Vec<usize> {
        match self.body.first() {
            Some(Block::Choice {
                divergence,
                branches,
                ..
            }) if *divergence == self.transition => {
                branches.iter().flat_map(Branch::heads).collect()
            }
            _ => vec![self.transition],
        }
    }
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
    /// The whole flow, start and end steps included: one sequence, or one
    /// [`Block::Sequences`] for several initial steps.
    pub body: Vec<Block>,
    /// Each sequence's start step and end step (`None` for a cyclic sequence: it ends in
    /// jumps only), in the order of [`Block::Sequences`].
    pub sequences: Vec<(usize, Option<usize>)>,
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
            Block::Step(_)
            | Block::Wait(_)
            | Block::Tell(_)
            | Block::Hear(_)
            | Block::Goto { .. } => {}
            Block::Machine(states) => {
                for st in states {
                    visit(&st.body, f);
                }
            }
            Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                for br in branches {
                    visit(br, f);
                }
            }
            Block::Choice { branches, .. } | Block::Follow { branches, .. } => {
                for br in branches {
                    visit(&br.body, f);
                }
            }
            Block::Loop { body, .. } => visit(body, f),
        }
    }
}

/// `f` of the first step of `blocks` (in program order) for which it is `Some`: the controller
/// or lane of a sequence's first step that runs code.
pub fn first_step<T>(blocks: &[Block], f: &dyn Fn(usize) -> Option<T>) -> Option<T> {
    let mut first = None;
    visit(blocks, &mut |b| {
        if let (None, Block::Step(i)) = (&first, b) {
            first = f(*i);
        }
    });
    first
}

/// The Gotos of `blocks` that leave them (not those inside a nested [`Block::Machine`], which
/// go to its own states).
pub fn gotos(blocks: &[Block], out: &mut Vec<usize>) {
    for b in blocks {
        match b {
            Block::Goto { target, .. } => out.push(*target),
            Block::Machine(_)
            | Block::Step(_)
            | Block::Wait(_)
            | Block::Tell(_)
            | Block::Hear(_) => {}
            Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                for br in branches {
                    gotos(br, out);
                }
            }
            Block::Choice { branches, .. } | Block::Follow { branches, .. } => {
                for br in branches {
                    gotos(&br.body, out);
                }
            }
            Block::Loop { body, .. } => gotos(body, out),
        }
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
    let sequences = ends?;
    let mut bodies = Vec::with_capacity(sequences.len());
    // The order of the connections, for the dominators of the jumps' targets (none without
    // jumps: a flat chart of 100,000 steps does not pay for it).
    let order = jumps.iter().any(Option::is_some).then(|| Order::new(&g));
    for &(start, _) in &sequences {
        // Every sequence is walked, so one run reports the faults of each.
        bodies.push(walk(sfc, &g, &jumps, start, order.as_ref(), diags));
    }
    let mut bodies: Vec<Vec<Block>> = bodies.into_iter().collect::<Option<_>>()?;
    let mut body = if bodies.len() == 1 {
        bodies.pop().unwrap_or_default()
    } else {
        vec![Block::Sequences(bodies)]
    };
    // Grown by doubling: up to half of it slack (100,000 steps: 8.4 MB for 6.4).
    body.shrink_to_fit();
    Some(Plan { body, sequences })
}

/// Several initial steps (docs/INPUTS.md): each sequence runs on controllers of its own. A sequence
/// none of whose steps runs code on a controller is left out (a PLC's own sequence: nothing in
/// it is a robot's); two sequences that share a controller are an error at the later one's
/// initial step, naming the controller (`name`). `controller(step)` is the controller of a
/// step that runs code.
pub fn place_sequences(
    plan: &mut Plan,
    sfc: &Sfc,
    controller: &dyn Fn(usize) -> Option<usize>,
    name: &dyn Fn(usize) -> String,
    diags: &mut Diagnostics,
) {
    let Some(Block::Sequences(seqs)) = plan.body.first() else {
        return;
    };
    let mut kept: Vec<Vec<Block>> = Vec::new();
    let mut owner: std::collections::HashMap<usize, usize> = std::collections::HashMap::new();
    let mut ok = true;
    for (k, seq) in seqs.iter().enumerate() {
        let mut mine = std::collections::BTreeSet::new();
        visit(seq, &mut |b| {
            if let Block::Step(i) = b
                && let Some(c) = controller(*i)
            {
                mine.insert(c);
            }
        });
        if mine.is_empty() {
            continue;
        }
        for &c in &mine {
            if let Some(&other) = owner.get(&c) {
                let (a, b) = (plan.sequences[other].0, plan.sequences[k].0);
                diags.push(
                    Diagnostic::error(
                        Code::StartStep,
                        format!(
                            "the sequences of the initial steps {} and {} both run on controller `{}`; several initial steps are sequences that run at the same time, so each needs a controller of its own: move the steps of one to another controller, or join the sequences into one chart with one initial step",
                            label(sfc, a),
                            label(sfc, b),
                            name(c)
                        ),
                    )
                    .at(sfc.elements[b].span.clone())
                    .element(label(sfc, b))
                    .related(sfc.elements[a].span.clone(), "the other initial step"),
                );
                ok = false;
                break;
            }
        }
        for &c in &mine {
            owner.entry(c).or_insert(k);
        }
        kept.push(seq.clone());
    }
    if !ok {
        return;
    }
    plan.body = match kept.len() {
        0 | 1 => kept.pop().unwrap_or_default(),
        _ => vec![Block::Sequences(kept)],
    };
}

pub(crate) fn label(sfc: &Sfc, i: usize) -> String {
    format!("localId {}", sfc.elements[i].local_id)
}

pub(crate) fn list_ids(sfc: &Sfc, idx: &[usize]) -> String {
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
    /// repeat and `!` for a leave, `L3[..]` (`L3*[..]` endless), `M(3=..|7=..)` states by
    /// their entries, `>7` a Goto.
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
                Block::Sequences(seqs) => {
                    let v: Vec<String> = seqs.iter().map(|b| shape(sfc, b)).collect();
                    format!("Q({})", v.join("|"))
                }
                Block::Tell(m) => format!("T{}", m.channel),
                Block::Hear(m) => format!("H{}", m.channel),
                Block::Goto { target, .. } => format!(">{}", id(*target)),
                Block::Machine(states) => {
                    let v: Vec<String> = states
                        .iter()
                        .map(|st| format!("{}={}", id(st.entry), shape(sfc, &st.body)))
                        .collect();
                    format!("M({})", v.join("|"))
                }
                Block::Choice { branches, .. } | Block::Follow { branches, .. } => {
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
                    let c = if matches!(b, Block::Follow { .. }) {
                        "F"
                    } else {
                        "C"
                    };
                    format!("{c}({})", v.join("|"))
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

    /// The start is the step marked initialStep="true" (docs/INPUTS.md); a step only jumps lead to is
    /// no start; two marked steps without a predecessor begin two sequences when nothing joins
    /// them, else they are an error; a step nothing leads to besides the start is an error at
    /// it.
    #[test]
    fn the_start_is_the_marked_initial_step() {
        // A jump-only target (`Emergency`) besides the marked start: fine.
        let emergency =
            "<step localId=\"20\" name=\"Emergency\"><position x=\"0\" y=\"0\"/></step>".to_owned();
        let parts = [
            st(1, "Start", &[]),
            tr(2, &[1], "a"),
            st(3, "S3", &[2]),
            el("selectionDivergence", 4, &[3]),
            tr(5, &[4], "b"),
            jmp(6, &[5], "Emergency"),
            tr(7, &[4], "NOT b"),
            st(8, "End", &[7]),
            emergency.clone(),
            tr(21, &[20], "TRUE"),
            jmp(22, &[21], "Start"),
        ];
        // (Its flow, jumping out of the sequence and back to the start, is not structured:
        // that is reported, but never as a second start step.)
        let (_, _, msgs) = run(&parts);
        assert!(msgs.iter().all(|(c, _)| *c != Code::StartStep), "{msgs:?}");
        // Two marked initial steps, nothing between them: two sequences.
        assert_eq!(
            planned(&[
                st(1, "Start", &[]),
                tr(2, &[1], "TRUE"),
                st(3, "End", &[2]),
                st(4, "Other", &[]),
                tr(5, &[4], "a"),
                st(6, "End2", &[5]),
            ]),
            "Q(S1 S3|S4 W5 S6)"
        );
        // A jump joins them: one network with two initial steps.
        let (_, _, msgs) = run(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "End", &[2]),
            st(4, "Other", &[]),
            tr(5, &[4], "TRUE"),
            jmp(6, &[5], "End"),
        ]);
        assert!(
            msgs.iter().any(|(c, m)| *c == Code::StartStep
                && m.contains("2 initial steps")
                && m.contains("in one network")),
            "{msgs:?}"
        );
        // An unmarked step nothing leads to.
        let lone =
            "<step localId=\"4\" name=\"Lone\"><position x=\"0\" y=\"0\"/></step>".to_owned();
        let (_, _, msgs) = run(&[
            st(1, "Start", &[]),
            tr(2, &[1], "TRUE"),
            st(3, "End", &[2]),
            lone,
        ]);
        assert!(
            msgs.iter().any(|(c, m)| *c == Code::StartStep
                && m.contains("besides the start step localId 1: localId 4")),
            "{msgs:?}"
        );
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
        // which the walk writes as states (not E307).
        let p = planned(&[
            st(1, "Init", &[]),
            tr(2, &[1], "TRUE"),
            jmp(3, &[2], "Later"),
            st(4, "Later", &[]),
            tr(5, &[4], "TRUE"),
            st(6, "End", &[5]),
        ]);
        assert_eq!(p, "M(1=S1 >4|4=S4 S6)");
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
    fn a_loop_continued_past_its_decision_is_written_in_states() {
        // Branch 9 goes on in the loop body while branch 5 jumps back, and jumps back again
        // from a selection inside it: no KRL structure (EXIT leaves one loop, there is no
        // CONTINUE), so the loop's head begins a state that both jumps go to.
        let p = planned(&[
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
        assert_eq!(p, "M(1=S1 >3|3=S3 C(5:>3|9:S10 C(12:>3|14:>15))|15=S15)");
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
    fn nested_loops_deeper_than_the_limit_begin_states() {
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
        // The loops beyond the limit begin states (docs/INPUTS.md): the tree itself stays within
        // the limit, so nothing that walks it recurses deeper.
        assert!(msgs.is_empty(), "{msgs:?}");
        let p = p.expect("a plan");
        assert!(matches!(p.body.first(), Some(Block::Machine(_))));
        fn depth(blocks: &[Block]) -> usize {
            blocks
                .iter()
                .map(|b| match b {
                    Block::Loop { body, .. } => 1 + depth(body),
                    Block::Machine(states) => {
                        states.iter().map(|s| depth(&s.body)).max().unwrap_or(0)
                    }
                    Block::Choice { branches, .. } => {
                        1 + branches.iter().map(|br| depth(&br.body)).max().unwrap_or(0)
                    }
                    _ => 0,
                })
                .max()
                .unwrap_or(0)
        }
        assert!(depth(&p.body) <= 2 * MAX_NESTING, "{}", depth(&p.body));
        assert_eq!(p.steps().len(), 2 * n as usize + 2);
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
