//! The size of a cell one compile takes (docs/INPUTS.md, "Limits"): every program of a cell has a
//! table over the whole chart (its bound steps' places: 4 bytes per SFC element per program;
//! until 2026-12-01 also its steps' resources and bound calls, 40 bytes), so memory grows with
//! controllers × SFC elements. Refused here, before the chart is split, bound or written, with
//! the figures: 1,000 controllers of 20,000 steps (40,000 elements) took 1.6 GB with the tables
//! of 40 bytes.

use super::{Resolution, StepOrder};
use crate::diag::{Code, Diagnostic, Diagnostics};
use crate::model::{Blackboard, Sfc};

/// At most this many controllers × SFC elements (steps, transitions, divergences, …) in one
/// compile: 12 million, about 500 MB of per-program tables, so that one compile stays under
/// 1 GB with the largest SFC the file limit lets through. 10 controllers of 100,000 steps are
/// 2 million; a project of one controller is never refused.
pub const MAX_CELL_PAIRS: usize = 12_000_000;

/// The controllers that run steps, in the order of their first step (docs/CELLS.md), or `None`
/// after an `E313` at the step whose controller takes the cell past [`MAX_CELL_PAIRS`].
pub fn controllers_within_budget(
    res: &Resolution,
    bb: &Blackboard,
    order: &StepOrder,
    sfc: &Sfc,
    diags: &mut Diagnostics,
) -> Option<Vec<usize>> {
    let elements = sfc.elements.len().max(1);
    // By resource: whether it is among the controllers already.
    let mut seen = vec![false; bb.resources.len()];
    let mut out: Vec<usize> = Vec::new();
    for &i in &order.steps {
        let Some((r, _)) = res.step_skill[i] else {
            continue;
        };
        let c = bb.controller_of(r);
        if std::mem::replace(&mut seen[c], true) {
            continue;
        }
        out.push(c);
        if out.len() > 1 && out.len().saturating_mul(elements) > MAX_CELL_PAIRS {
            let e = &sfc.elements[i];
            let most = MAX_CELL_PAIRS / elements;
            diags.push(
                Diagnostic::error(
                    Code::Unsupported,
                    format!(
                        "a cell of more than {most} controllers with a chart of {elements} SFC \
                         elements: each controller's program is made from the whole chart, and \
                         controllers × elements may be at most {MAX_CELL_PAIRS} in one compile; \
                         this step's resource `{}` runs on controller {} of the cell; split the \
                         chart into projects of fewer controllers",
                        bb.resources[r].name.text,
                        out.len()
                    ),
                )
                .at(e.span.clone())
                .element(format!("localId {}", e.local_id)),
            );
            return None;
        }
    }
    Some(out)
}
