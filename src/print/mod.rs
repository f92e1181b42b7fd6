//! The listings of the original's print options: `-pB` (blackboard), `-pS` (SFC objects), `-pF`
//! (flow with parallel branches and times), `-pO` (execution order), and `--info`.
//!
//! Each returns a `String`; the command line prints it. The layout follows the original's
//! console output (`../shared/spec/reference/original-sample/`), with localIds everywhere; [`json`]
//! gives the same listings as JSON objects for `--format json` (docs/JSON.md).
//!
//! # The files
//!
//! - `mod.rs` (here): what the listings share (step names and times, the flow's `Totals`,
//!   numbers and seconds as they are written); re-exports the listings.
//! - `blackboard.rs`: `-pB` ([`blackboard()`], [`language_text`], [`signal_text`],
//!   [`wire_uses`]).
//! - `sfc.rs`: `-pS` ([`sfc()`]).
//! - `flow.rs`: `-pF` ([`flow()`]).
//! - `order.rs`: `-pO` ([`order()`]).
//! - `info.rs`: `--info` ([`info()`]).
//! - `cell.rs`: a cell's listings (docs/CELLS.md): [`CellView`], `-pO` per program
//!   ([`cell_order`]), `-pF` one lane per controller ([`cell_timeline`], [`cell_flow`]).
//! - `json.rs`: [`json`], the same listings as JSON objects.
//! - `parts.rs`: [`parts`], `-pO`'s parts of split programs.

mod blackboard;
mod cell;
mod flow;
mod info;
pub mod json;
mod order;
pub mod parts;
mod sfc;

pub use blackboard::{blackboard, language_text, signal_text, wire_uses};
pub use cell::{CellView, LaneItem, cell_flow, cell_order, cell_timeline};
pub use flow::flow;
pub use info::info;
pub use order::order;
pub use sfc::sfc;

use crate::model::{ElementKind, Sfc};
use crate::plan::{condition_text as condition, one_line};

fn step_name(sfc: &Sfc, i: usize) -> &str {
    match &sfc.elements[i].kind {
        ElementKind::Step(s) => &s.name,
        _ => "",
    }
}

fn duration(sfc: &Sfc, i: usize) -> f64 {
    match &sfc.elements[i].kind {
        ElementKind::Step(s) => s.duration.unwrap_or(0.0),
        _ => 0.0,
    }
}

/// What the flow's total time means.
#[derive(Default)]
struct Totals {
    loops: bool,
    /// Flow in states ([`Block::Machine`](crate::plan::Block::Machine)): each counted once.
    states: bool,
    endless: bool,
    choices: bool,
}

/// `1 second`, `0 seconds`, `1.5 seconds`.
fn seconds(x: f64) -> String {
    let n = fmt_num(x);
    if n == "1" {
        "1 second".to_owned()
    } else {
        format!("{n} seconds")
    }
}

fn fmt_num(x: f64) -> String {
    let s = format!("{x:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s.is_empty() {
        "0".to_owned()
    } else {
        s.to_owned()
    }
}
