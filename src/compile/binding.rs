//! The programs of a compile bound: one, or one per controller of a cell (docs/CELLS.md),
//! each from its own steps, with the conditions it waits for or decides and the definitions its
//! code calls. A cell's programs are bound two at a time when none holds more than half the
//! steps; else (and for one program) a program's steps are cut into pieces for two threads
//! (`bind::bind`).

use std::collections::HashMap;

use super::*;
use crate::plan::cell::Cell;

/// What every program of a compile is bound from.
pub(super) struct Inputs<'a> {
    pub(super) bb: &'a Blackboard,
    pub(super) sfc: &'a Sfc,
    pub(super) order: &'a bind::StepOrder,
    pub(super) res: &'a bind::Resolution,
    pub(super) irls: &'a [Irl],
    pub(super) fn_irl: &'a HashMap<(usize, usize), usize>,
    pub(super) controllers: &'a [usize],
    pub(super) cell: Option<&'a Cell>,
    /// Whether the programs' languages are sure (no `E210`): their signal rules apply then.
    pub(super) sure: bool,
    /// Steps from which binding takes two threads ([`bind::PARALLEL_FROM`]).
    pub(super) split_from: usize,
}

/// The programs bound, in order; their diagnostics in program order, each program's as
/// binding it alone gives them (`tests/bind_split.rs` compares the ways).
pub(super) fn bind_programs(
    inputs: &Inputs,
    programs: &[ProgramSpec],
    diags: &mut Diagnostics,
) -> Vec<bind::Bound> {
    // A program of a cell binds its own steps, in the chart's order; one program all.
    let own: Vec<Option<bind::StepOrder>> = programs
        .iter()
        .map(|p| {
            let c = p.controller.filter(|_| inputs.controllers.len() > 1)?;
            Some(bind::StepOrder {
                steps: (inputs.order.steps.iter().copied())
                    .filter(|&i| inputs.res.runs_on(inputs.bb, i, c))
                    .collect(),
                start_end: inputs.order.start_end.clone(),
            })
        })
        .collect();
    let orders: Vec<&bind::StepOrder> = own
        .iter()
        .map(|o| o.as_ref().unwrap_or(inputs.order))
        .collect();
    let steps: Vec<usize> = orders.iter().map(|o| o.steps.len()).collect();
    let total: usize = steps.iter().sum();
    let largest = steps.iter().copied().max().unwrap_or(0);
    // A cell's programs of about equal size: each bound on one thread, two at a time (a thread
    // and its programs' tables and conditions at once), the largest first.
    if inputs.cell.is_some()
        && programs.len() >= 2
        && total >= inputs.split_from.max(2)
        && largest * 2 <= total
    {
        let like = diags.empty_like();
        let bound = crate::threads::largest_first("skillpost-bind", &steps, |k| {
            let mut d = like.empty_like();
            let b = bind_program(inputs, k, &programs[k], orders[k], &mut d, usize::MAX);
            (b, d)
        });
        return bound
            .into_iter()
            .map(|(b, d)| {
                diags.append(d);
                b
            })
            .collect();
    }
    programs
        .iter()
        .enumerate()
        .map(|(k, prog)| bind_program(inputs, k, prog, orders[k], diags, inputs.split_from))
        .collect()
}

/// Binds program `k`, its steps `order` (in pieces on two threads from `split_from` steps).
fn bind_program(
    inputs: &Inputs,
    k: usize,
    prog: &ProgramSpec,
    order: &bind::StepOrder,
    diags: &mut Diagnostics,
    split_from: usize,
) -> bind::Bound {
    let Inputs {
        bb,
        sfc,
        res,
        irls,
        fn_irl,
        controllers,
        cell,
        sure,
        ..
    } = *inputs;
    let profile = prog.language.profile();
    let narrowed;
    let res_k = match prog.controller.filter(|_| controllers.len() > 1) {
        Some(c) => {
            narrowed = res.of_controller(bb, c);
            &narrowed
        }
        None => res,
    };
    let mut bound = bind::bind(
        bb,
        sfc,
        order,
        res_k,
        &bind::Calls { irls, fn_irl },
        profile,
        diags,
        split_from,
    );
    // The definitions whose routines the program's code calls, from the IRL files of
    // its own resources.
    let mut mine: Vec<usize> = fn_irl
        .iter()
        .filter(|((r, _), _)| {
            controllers.len() <= 1 || prog.controller == Some(bb.controller_of(*r))
        })
        .map(|(_, &i)| i)
        .collect();
    mine.sort_unstable();
    mine.dedup();
    bind::definitions::complete(&mut bound, irls, &mine, prog.language);
    // A program of a cell reads the conditions it waits for or decides. When the flow
    // has errors (no plan), which controller decides a condition is not known: the
    // first program reads them all, a name any resource declares is no error then (not
    // a follow-on of the flow's errors), the others read none.
    let undecided = cell.is_none() && controllers.len() > 1;
    let only = match cell {
        Some(c) => Some(evaluated(&c.programs[k].body)),
        None if undecided && k > 0 => Some(Vec::new()),
        None => None,
    };
    let reads = bind::conditions(
        bb,
        sfc,
        prog.controller,
        sure.then_some(profile),
        only.as_deref(),
        cell.is_some_and(|c| c.partners(k).next().is_some()),
        undecided,
        diags,
    );
    bound.signals = reads.signals;
    bound.watch = reads.watch;
    bound.set_timers(reads.timers, reads.timer_names);
    // The handshakes' wires are the handshakes' (docs/CELLS.md): a condition reading one
    // would see the toggles.
    if let (Some(cell), Some(c)) = (cell, prog.controller) {
        let used: Vec<usize> = cell
            .channels
            .iter()
            .flat_map(|ch| ch.strobe.iter().chain(&ch.data).chain(&ch.ack).copied())
            .chain(
                cell.links
                    .iter()
                    .flat_map(|l| l.run.into_iter().chain(l.ready)),
            )
            .collect();
        for &si in &bound.signals {
            let Some(&w) = used
                .iter()
                .find(|&&w| bb.wires[w].from == (c, si) || bb.wires[w].to == (c, si))
            else {
                continue;
            };
            let sig = &bb.resources[c].signals[si];
            diags.push(
                    Diagnostic::error(
                        Code::BadSignal,
                        format!(
                            "signal `{}` is a wire the handshakes between controllers use (InternalLink `{}`); a condition must not read it: give the condition a signal of its own, or declare more wires",
                            sig.name.text, bb.wires[w].name
                        ),
                    )
                    .at(sig.name.span.clone())
                    .element(sig.element.clone()),
                );
        }
    }
    bound
}
