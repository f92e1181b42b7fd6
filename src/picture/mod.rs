//! The plan as a picture (`--svg FILE`, the daemon's `picture = true`): an SVG timeline with one
//! lane per controller (one lane when there is one), a box per step as long as its
//! `time@duration` (a step without one, such as the initial step, drawn as a small dashed
//! diamond at its moment and marked "no time"), each alternative of a selection on a row of
//! its own (the longest one counts for what follows), a loop's body once inside a band that
//! says so, a time axis in seconds and the cycle time.
//!
//! In a cell, the lanes follow the programs the cell split wrote ([`crate::plan::cell`]): every
//! handshake a program does is an arrow, from where its teller tells to where its hearer hears
//! (a step done, a loop or selection passed, and each branch a decider tells its followers:
//! the decision of a selection and of a loop's repeat or exit, drawn on each alternative's
//! row, dashed), so the arrows are exactly the programs' tells; the time a program waits in a
//! hear is a hatched box. A step starts when its program gets there: after its own steps
//! before and the hears before it.
//!
//! Every text is readable: a step's name, skill and localId stand in its box where they fit,
//! else on a line below the row's boxes, tied to the box by a thin leader, on the first line
//! where they meet no other text (a step without a time: beside its diamond, else below too);
//! likewise a wait's text and a selection branch's condition. The picture is as wide as what
//! it draws, plus a small margin (text widths from DejaVu Sans' advance widths, the first
//! font it asks for; the others are narrower). Text is text (step name, skill, localId), so a
//! browser finds and selects it; no scripts, no external resources. The same plan gives the
//! same bytes.
//!
//! Like the listings of [`crate::print`], it reads the chart and the plan and does no I/O.
//!
//! # The files
//!
//! - `mod.rs` (here): [`Lanes`], the measures (px), and what the layout and the drawing
//!   share: the items, arrows and bands laid out, the layout's state (`Layout`: each lane's
//!   program and where it stands, the messages not heard yet), a label that does not fit.
//! - `layout.rs`: the walk over the plan (and a cell's programs) that puts every step, wait,
//!   handshake and band in time and on its row.
//! - `labels.rs`: the labels placed: beside a diamond, else on the first free line below.
//! - `text.rs`: text widths (DejaVu Sans), XML escaping, numbers as written, the axis' tick
//!   step ([`text_w`], [`esc`], [`tick_step`]; `simulate::report` draws with them too).
//! - `svg.rs`: [`svg()`], the picture drawn from the layout.
//! - `tests.rs`: the unit tests.

mod labels;
mod layout;
mod svg;
mod text;

pub use svg::svg;
pub use text::{esc, text_w, tick_step};

use std::collections::{HashMap, VecDeque};

use crate::model::Sfc;
use crate::plan::Block;
use crate::plan::cell::Message;

/// What the picture's lanes are: each controller's name (and its program's), which lane runs
/// each step (by element index; a step not listed runs on lane 0), and in a cell each lane's
/// program as the cell split wrote it, with its handshakes (none: no arrows).
pub struct Lanes<'a> {
    pub names: Vec<(String, String)>,
    pub of: HashMap<usize, usize>,
    pub programs: Vec<&'a [Block]>,
}

/// Pixels per second at most and at least, and the widest picture (px) the scale aims at.
const MAX_SCALE: f64 = 160.0;
const MIN_SCALE: f64 = 4.0;
const AIM_WIDTH: f64 = 1100.0;
/// The width of a step without a time (a diamond), and the least width of any box (px).
const UNTIMED_W: f64 = 10.0;
const MIN_W: f64 = 3.0;
/// Where the time axis begins at least (the lanes' names are left of it).
const MIN_LEFT: f64 = 170.0;
/// A row: the diamonds of steps without a time at the top, the boxes, then lines of labels.
const BOX_Y: f64 = 16.0;
const BOX_H: f64 = 30.0;
const LINE_H: f64 = 13.0;
const ROW_PAD: f64 = 8.0;
const LANE_GAP: f64 = 14.0;
/// The font size of a label outside a box, and the room between two labels on a line.
const LABEL: f64 = 9.0;
const GAP: f64 = 8.0;
/// The lines of the bands' texts above the lanes, apart.
const BAND_LEVEL: f64 = 14.0;
/// Right of the rightmost thing drawn.
const MARGIN: f64 = 12.0;

#[derive(Debug, Clone)]
enum Kind {
    Step {
        element: usize,
        timed: bool,
    },
    /// The lane's program waits in a hear until lane `of` tells it `said`.
    Wait {
        of: usize,
        said: Message,
    },
}

#[derive(Debug, Clone)]
struct Item {
    lane: usize,
    row: usize,
    start: f64,
    end: f64,
    kind: Kind,
    /// A selection branch's condition, shown with its first box.
    label: Option<String>,
}

/// A handshake: lane `from.0` (on row `from.1`) tells at `at`, lane `to.0` hears at `to_at`.
#[derive(Debug, Clone)]
struct Arrow {
    from: (usize, usize),
    to: (usize, usize),
    at: f64,
    to_at: f64,
    said: Message,
}

#[derive(Debug, Clone)]
struct Band {
    start: f64,
    end: f64,
    text: String,
    loop_: bool,
}

/// Where a lane's program stands: in `blocks` at `at`; `heard` is a selection's decision the
/// program waits for before the branch (a [`Block::Follow`]'s), not heard yet.
#[derive(Debug, Clone, Copy)]
struct Frame<'a> {
    blocks: &'a [Block],
    at: usize,
    heard: Option<Message>,
}

/// A message told and not heard yet: by lane `lane` on row `row` at time `at`.
#[derive(Debug, Clone, Copy)]
struct Sent {
    lane: usize,
    row: usize,
    at: f64,
    said: Message,
}

struct Layout<'s> {
    sfc: &'s Sfc,
    of: &'s HashMap<usize, usize>,
    items: Vec<Item>,
    arrows: Vec<Arrow>,
    bands: Vec<Band>,
    free: Vec<f64>,
    rows: usize,
    /// The condition of the branch whose first step comes next.
    label: Option<String>,
    /// Conditions of branches without a step: (lane, row, time, text).
    notes: Vec<(usize, usize, f64, String)>,
    /// The lane of a step that runs no code and follows nothing on a lane (a sequence's
    /// start step): the sequence's.
    lane_hint: Option<usize>,
    /// A cell: each lane's program, where it stands, the messages on each channel not heard
    /// yet, and the row each lane is on.
    cursors: Vec<Vec<Frame<'s>>>,
    queues: Vec<VecDeque<Sent>>,
    lane_row: Vec<usize>,
}

fn local_id(sfc: &Sfc, i: usize) -> u64 {
    sfc.elements[i].local_id
}

/// A piece of a label: its text, bold or not, its colour (else the label's).
type Span = (String, bool, Option<&'static str>);

/// A text that does not fit where it belongs: beside its diamond at the top of the row, or on
/// a line below the row's boxes, tied by a leader to its box (or diamond) at `x`.
struct Label {
    lane: usize,
    row: usize,
    x: f64,
    diamond: bool,
    spans: Vec<Span>,
    w: f64,
    /// `None`: beside the diamond; `Some(j)`: line `j` below the boxes.
    line: Option<usize>,
    class: &'static str,
}

#[cfg(test)]
mod tests;
