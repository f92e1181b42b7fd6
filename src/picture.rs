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

use std::collections::{HashMap, VecDeque};
use std::fmt::Write as _;

use crate::model::{ElementKind, Sfc};
use crate::plan::cell::{Kind as Said, Message};
use crate::plan::{Block, Plan};

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

/// What the next thing of a lane's program is.
enum Next<'a> {
    Tell(Message),
    Hear(Message),
    Block(&'a Block),
    /// The end of the innermost body (or no program).
    End,
}

/// What a branch of a selection is walked from, and what the longest one leaves.
#[derive(Clone)]
struct Moment<'a> {
    free: Vec<f64>,
    cursors: Vec<Vec<Frame<'a>>>,
    queues: Vec<VecDeque<Sent>>,
    lane_row: Vec<usize>,
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

/// A frontier: when the steps before have ended, and the last of them (lane, row, element).
type Front = (f64, Option<(usize, usize, usize)>);

fn duration(sfc: &Sfc, i: usize) -> Option<f64> {
    match &sfc.elements[i].kind {
        ElementKind::Step(s) => s.duration,
        _ => None,
    }
}

fn local_id(sfc: &Sfc, i: usize) -> u64 {
    sfc.elements[i].local_id
}

/// What a message says, as `-pO` puts it: `step Grip (id=5) done`.
fn what(sfc: &Sfc, m: &Message) -> String {
    let about = match &sfc.elements[m.about].kind {
        ElementKind::Step(s) => format!("step {} (id={})", s.name, local_id(sfc, m.about)),
        _ => format!("id={}", local_id(sfc, m.about)),
    };
    match m.kind {
        Said::Done => format!("{about} done"),
        Said::Decision => format!("branch {} taken at the selection {about}", m.value + 1),
        Said::Passed(c) => format!("it {} {about}", c.verb()),
    }
}

impl<'s> Layout<'s> {
    /// The next thing lane `c`'s program does.
    fn next(&self, c: usize) -> Next<'s> {
        let Some(f) = self.cursors.get(c).and_then(|s| s.last()) else {
            return Next::End;
        };
        if let Some(m) = f.heard {
            return Next::Hear(m);
        }
        match f.blocks.get(f.at) {
            Some(Block::Tell(m)) => Next::Tell(*m),
            Some(Block::Hear(m)) => Next::Hear(*m),
            Some(b) => Next::Block(b),
            None => Next::End,
        }
    }

    /// Lane `c`'s program goes past its next thing.
    fn pass(&mut self, c: usize) {
        if let Some(f) = self.cursors.get_mut(c).and_then(|s| s.last_mut()) {
            if f.heard.is_some() {
                f.heard = None;
            } else {
                f.at += 1;
            }
        }
    }

    /// Every lane tells and hears what it can before its next block: a tell leaves when its
    /// program has done what comes before it, a hear ends when its message has been told.
    fn settle(&mut self) {
        loop {
            let mut moved = false;
            for c in 0..self.cursors.len() {
                loop {
                    match self.next(c) {
                        Next::Tell(m) => {
                            if self.queues.len() <= m.channel {
                                self.queues.resize(m.channel + 1, VecDeque::new());
                            }
                            self.queues[m.channel].push_back(Sent {
                                lane: c,
                                row: self.lane_row[c],
                                at: self.free[c],
                                said: m,
                            });
                        }
                        Next::Hear(m) => {
                            let Some(s) =
                                self.queues.get_mut(m.channel).and_then(VecDeque::pop_front)
                            else {
                                break;
                            };
                            self.hear(c, s);
                        }
                        Next::Block(_) | Next::End => break,
                    }
                    self.pass(c);
                    moved = true;
                }
            }
            if !moved {
                break;
            }
        }
    }

    /// Lane `c` hears `s`: it waits (hatched) until it was told, an arrow from the tell.
    fn hear(&mut self, c: usize, s: Sent) {
        let (start, row) = (self.free[c], self.lane_row[c]);
        if s.at > start + 1e-9 {
            self.items.push(Item {
                lane: c,
                row,
                start,
                end: s.at,
                kind: Kind::Wait {
                    of: s.lane,
                    said: s.said,
                },
                label: None,
            });
        }
        let at = start.max(s.at);
        self.arrows.push(Arrow {
            from: (s.lane, s.row),
            to: (c, row),
            at: s.at,
            to_at: at,
            said: s.said,
        });
        self.free[c] = at;
    }

    /// The lanes whose programs' next block (after what they can tell and hear) is `b`'s kind,
    /// with that block.
    fn standing_at(&mut self, f: impl Fn(&Block) -> bool) -> Vec<(usize, &'s Block)> {
        self.settle();
        (0..self.cursors.len())
            .filter_map(|c| match self.next(c) {
                Next::Block(b) if f(b) => Some((c, b)),
                _ => None,
            })
            .collect()
    }

    /// Lanes `parts` go into their blocks' bodies (`body` of each), on row `row`.
    fn enter(
        &mut self,
        parts: &[(usize, &'s Block)],
        row: usize,
        body: impl Fn(&'s Block) -> Frame<'s>,
    ) {
        for &(p, b) in parts {
            self.cursors[p].push(body(b));
            self.lane_row[p] = row;
        }
        self.settle();
    }

    /// Lanes `parts` leave the bodies [`Layout::enter`] entered, back on row `row`.
    fn leave(&mut self, parts: &[(usize, &'s Block)], row: usize) {
        self.settle();
        for &(p, _) in parts {
            self.cursors[p].pop();
            self.lane_row[p] = row;
        }
    }

    /// Lanes `parts` go past the blocks they stand at.
    fn past(&mut self, parts: &[(usize, &'s Block)]) {
        for &(p, _) in parts {
            self.pass(p);
        }
        self.settle();
    }

    fn moment(&self) -> Moment<'s> {
        Moment {
            free: self.free.clone(),
            cursors: self.cursors.clone(),
            queues: self.queues.clone(),
            lane_row: self.lane_row.clone(),
        }
    }

    fn back_to(&mut self, m: Moment<'s>) {
        self.free = m.free;
        self.cursors = m.cursors;
        self.queues = m.queues;
        self.lane_row = m.lane_row;
    }

    /// When the last lane that went on since `before` is done (at least `end`).
    fn reach(&self, before: &[f64], end: f64) -> f64 {
        self.free
            .iter()
            .zip(before)
            .filter(|(f, b)| f > b)
            .map(|(f, _)| *f)
            .fold(end, f64::max)
    }

    fn walk(&mut self, blocks: &'s [Block], mut front: Front, row: usize) -> Front {
        for b in blocks {
            match b {
                Block::Step(i) => {
                    let d = duration(self.sfc, *i);
                    // In a cell, a step that runs no code (a start or an end step) is drawn on
                    // the lane before it (a sequence's own at its start) at the front: it
                    // neither takes the lane's time nor makes a lane wait.
                    let coded = self.of.is_empty() || self.of.contains_key(i);
                    let (c, start) = if coded {
                        let c = self.of.get(i).copied().unwrap_or(0);
                        // Its program hears what it waits for, then runs it.
                        if self.standing_at(|s| s == b).iter().any(|(p, _)| *p == c) {
                            self.pass(c);
                            self.lane_row[c] = row;
                        }
                        (c, front.0.max(self.free[c]))
                    } else {
                        let lane = front.1.map(|(c, _, _)| c).or(self.lane_hint);
                        (lane.unwrap_or(0), front.0)
                    };
                    let end = start + d.unwrap_or(0.0);
                    self.items.push(Item {
                        lane: c,
                        row,
                        start,
                        end,
                        kind: Kind::Step {
                            element: *i,
                            timed: d.is_some(),
                        },
                        label: self.label.take(),
                    });
                    if coded {
                        self.free[c] = end;
                        front = (end, Some((c, row, *i)));
                        self.settle();
                    }
                }
                Block::Wait(_) | Block::Goto { .. } => {
                    // A transition's wait, a jump between states: on the lanes whose programs
                    // have it, no time.
                    let here = self.standing_at(|s| s == b);
                    for &(c, _) in &here {
                        self.lane_row[c] = row;
                    }
                    self.past(&here);
                }
                Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                    let mut end = front;
                    for br in branches {
                        if matches!(b, Block::Sequences(_)) {
                            // The lane of the sequence's first step that runs code.
                            let of = self.of;
                            self.lane_hint = crate::plan::first_step(br, &|s| of.get(&s).copied());
                        }
                        let e = self.walk(br, front, row);
                        if e.0 >= end.0 {
                            end = e;
                        }
                    }
                    front = end;
                }
                Block::Choice {
                    divergence,
                    branches,
                    ..
                }
                | Block::Follow {
                    divergence,
                    branches,
                    ..
                } => {
                    // The decider's program has the selection, every follower's a Follow.
                    let parts = self.standing_at(|s| match s {
                        Block::Choice { divergence: d, .. }
                        | Block::Follow { divergence: d, .. } => d == divergence,
                        _ => false,
                    });
                    let before = self.moment();
                    let mut best: Option<(f64, Front, Moment)> = None;
                    for (k, br) in branches.iter().enumerate() {
                        self.back_to(before.clone());
                        let r = if k == 0 {
                            row
                        } else {
                            self.rows += 1;
                            self.rows - 1
                        };
                        self.enter(&parts, r, |s| match s {
                            Block::Choice { branches, .. } => Frame {
                                blocks: branches.get(k).map_or(&[], |b| b.body.as_slice()),
                                at: 0,
                                heard: None,
                            },
                            Block::Follow {
                                heard, branches, ..
                            } => Frame {
                                blocks: branches.get(k).map_or(&[], |b| b.body.as_slice()),
                                at: 0,
                                heard: Some(*heard),
                            },
                            _ => Frame {
                                blocks: &[],
                                at: 0,
                                heard: None,
                            },
                        });
                        let cond = br.condition_text(self.sfc);
                        self.label = Some(format!("{}. {cond}", k + 1));
                        let e = self.walk(&br.body, front, r);
                        if let Some(text) = self.label.take() {
                            // No step in this branch: its condition where it would begin.
                            let lane = front.1.map_or(0, |(c, _, _)| c);
                            self.notes
                                .push((lane, r, front.0, format!("{text} (no step)")));
                        }
                        self.leave(&parts, row);
                        let reach = self.reach(&before.free, e.0);
                        if best.as_ref().is_none_or(|b| reach > b.0) {
                            best = Some((reach, e, self.moment()));
                        }
                    }
                    let start = front.0;
                    let mut end = front.0;
                    if let Some((reach, e, m)) = best {
                        front = e;
                        end = reach;
                        self.back_to(m);
                    }
                    self.past(&parts);
                    self.bands.push(Band {
                        start,
                        end,
                        text: format!(
                            "selection id={}: {} alternatives, the longest counted",
                            local_id(self.sfc, *divergence),
                            branches.len()
                        ),
                        loop_: false,
                    });
                }
                Block::Loop {
                    head,
                    body,
                    endless,
                    ..
                } => {
                    let parts =
                        self.standing_at(|s| matches!(s, Block::Loop { head: h, .. } if h == head));
                    let before = self.free.clone();
                    self.enter(&parts, row, |s| Frame {
                        blocks: match s {
                            Block::Loop { body, .. } => body,
                            _ => &[],
                        },
                        at: 0,
                        heard: None,
                    });
                    let start = front.0;
                    front = self.walk(body, front, row);
                    self.leave(&parts, row);
                    let end = self.reach(&before, front.0);
                    self.past(&parts);
                    self.bands.push(Band {
                        start,
                        end,
                        text: format!(
                            "{} to id={}: one round shown",
                            if *endless { "endless loop" } else { "loop" },
                            local_id(self.sfc, *head)
                        ),
                        loop_: true,
                    });
                }
                Block::Machine(states) => {
                    let first = states.first().map(|s| s.entry);
                    let parts = self.standing_at(|s| match s {
                        Block::Machine(own) => own.first().map(|s| s.entry) == first,
                        _ => false,
                    });
                    let before = self.free.clone();
                    let start = front.0;
                    for (k, st) in states.iter().enumerate() {
                        self.enter(&parts, row, |s| Frame {
                            blocks: match s {
                                Block::Machine(own) => own.get(k).map_or(&[], |s| &s.body),
                                _ => &[],
                            },
                            at: 0,
                            heard: None,
                        });
                        front = self.walk(&st.body, front, row);
                        self.leave(&parts, row);
                    }
                    let end = self.reach(&before, front.0);
                    self.past(&parts);
                    self.bands.push(Band {
                        start,
                        end,
                        text: format!("{} states, each once", states.len()),
                        loop_: false,
                    });
                }
                Block::Tell(_) | Block::Hear(_) => {}
            }
        }
        front
    }
}

/// DejaVu Sans' advance widths of the printable ASCII characters, space to `~`, in thousandths
/// of an em: Book, then Bold.
const BOOK: [u16; 95] = [
    318, 401, 460, 838, 636, 950, 780, 275, 390, 390, 500, 838, 318, 361, 318, 337, 636, 636, 636,
    636, 636, 636, 636, 636, 636, 636, 337, 337, 838, 838, 838, 531, 1000, 709, 686, 698, 770, 632,
    575, 775, 752, 295, 295, 656, 557, 863, 748, 787, 603, 787, 695, 635, 595, 732, 684, 989, 685,
    611, 685, 390, 337, 390, 838, 500, 500, 613, 635, 550, 635, 615, 344, 635, 634, 278, 278, 579,
    278, 974, 634, 612, 635, 635, 395, 521, 392, 634, 592, 818, 592, 592, 525, 636, 337, 636, 838,
];
const BOLD: [u16; 95] = [
    348, 456, 521, 838, 696, 1002, 872, 306, 457, 457, 523, 838, 380, 415, 380, 365, 696, 696, 696,
    696, 696, 696, 696, 696, 696, 696, 400, 400, 838, 838, 838, 580, 1000, 774, 762, 734, 830, 683,
    683, 821, 837, 372, 372, 775, 637, 995, 837, 850, 733, 850, 770, 680, 703, 812, 774, 1103, 771,
    724, 725, 457, 365, 457, 838, 500, 500, 675, 716, 593, 716, 678, 405, 716, 712, 343, 343, 665,
    343, 1042, 712, 687, 716, 716, 493, 595, 478, 712, 652, 924, 645, 652, 582, 712, 365, 712, 838,
];

/// The width (px) of `s` at `size` px in DejaVu Sans, bold or not; a character beyond ASCII is
/// taken as wide as the widest letters (a whole em from the general punctuation on).
pub fn text_w(s: &str, size: f64, bold: bool) -> f64 {
    let table = if bold { &BOLD } else { &BOOK };
    let thousandths: u32 = s
        .chars()
        .map(|c| match c as u32 {
            n @ 32..=126 => u32::from(table[n as usize - 32]),
            0..=0x1fff => {
                if bold {
                    840
                } else {
                    780
                }
            }
            _ => 1000,
        })
        .sum();
    f64::from(thousandths) * size / 1000.0
}

/// `&`, `<`, `>` and `"` as XML wants them.
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            // Characters XML 1.0 does not allow.
            c if (c as u32) < 0x20 && !matches!(c, '\t' | '\n' | '\r') => o.push('\u{fffd}'),
            c => o.push(c),
        }
    }
    o
}

/// A number of seconds as the picture writes it: at most 3 decimals, no trailing zeros.
fn secs(x: f64) -> String {
    let s = format!("{x:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// A pixel coordinate: one decimal.
fn px(x: f64) -> String {
    let s = format!("{x:.1}");
    s.strip_suffix(".0").map(str::to_owned).unwrap_or(s)
}

/// The tick step of the time axis: 1, 2 or 5 times a power of ten, about every 80 px.
pub fn tick_step(scale: f64) -> f64 {
    let raw = 80.0 / scale;
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * p)
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

impl Label {
    fn new(
        (lane, row): (usize, usize),
        x: f64,
        diamond: bool,
        spans: Vec<Span>,
        class: &'static str,
    ) -> Label {
        let w = spans.iter().map(|(t, b, _)| text_w(t, LABEL, *b)).sum();
        Label {
            lane,
            row,
            x,
            diamond,
            spans,
            w,
            line: Some(0),
            class,
        }
    }

    /// Where its text begins.
    fn text_x(&self) -> f64 {
        match self.line {
            None => self.x + UNTIMED_W / 2.0 + 2.0,
            Some(_) => self.leader_x() + 3.0,
        }
    }

    /// Where its leader runs down: a diamond's centre, inside a box's left edge.
    fn leader_x(&self) -> f64 {
        if self.diamond { self.x } else { self.x + 1.5 }
    }

    fn right(&self) -> f64 {
        self.text_x() + self.w
    }
}

/// Gives each label its place: beside its diamond where that meets no other label or diamond,
/// else the first line below the boxes where it meets no other label (labels in time order).
/// `diamonds`: (lane, row, x) of each, sorted.
fn place(labels: &mut [Label], diamonds: &[(usize, usize, f64)]) {
    let mut order: Vec<usize> = (0..labels.len()).collect();
    order.sort_by(|&a, &b| {
        let (la, lb) = (&labels[a], &labels[b]);
        (la.lane, la.row)
            .cmp(&(lb.lane, lb.row))
            .then(la.x.total_cmp(&lb.x))
            .then(a.cmp(&b))
    });
    let mut at = (usize::MAX, usize::MAX);
    let (mut top_end, mut ends) = (f64::NEG_INFINITY, Vec::<f64>::new());
    for k in order {
        let l = &mut labels[k];
        if (l.lane, l.row) != at {
            at = (l.lane, l.row);
            top_end = f64::NEG_INFINITY;
            ends.clear();
        }
        if l.diamond {
            l.line = None;
            let (x0, x1) = (l.text_x(), l.right());
            // The first diamond of the row right of the text's start, less its half width.
            let reach = UNTIMED_W / 2.0 + 2.0;
            let k = diamonds.partition_point(|&(lane, row, cx)| {
                (lane, row) < at || ((lane, row) == at && cx + reach <= x0)
            });
            let clear = x0 >= top_end + GAP
                && diamonds
                    .get(k)
                    .is_none_or(|&(lane, row, cx)| (lane, row) != at || cx - reach >= x1);
            if clear {
                top_end = x1;
                continue;
            }
        }
        l.line = Some(0);
        let from = l.leader_x() - 1.0;
        let j = ends
            .iter()
            .position(|e| e + GAP <= from)
            .unwrap_or_else(|| {
                ends.push(f64::NEG_INFINITY);
                ends.len() - 1
            });
        l.line = Some(j);
        ends[j] = l.right();
    }
}

/// The SVG of `plan` (of `sfc`) on `lanes`; `title` names the programs and the chart.
pub fn svg(sfc: &Sfc, plan: &Plan, lanes: &Lanes, title: &str) -> String {
    let n = lanes.names.len().max(1);
    let mut l = Layout {
        sfc,
        of: &lanes.of,
        items: Vec::new(),
        arrows: Vec::new(),
        bands: Vec::new(),
        free: vec![0.0; n],
        rows: 1,
        label: None,
        notes: Vec::new(),
        lane_hint: None,
        cursors: (0..n)
            .map(|k| {
                lanes
                    .programs
                    .get(k)
                    .map(|p| Frame {
                        blocks: p,
                        at: 0,
                        heard: None,
                    })
                    .into_iter()
                    .collect()
            })
            .collect(),
        queues: Vec::new(),
        lane_row: vec![0; n],
    };
    let end = l.walk(&plan.body, (0.0, None), 0);
    l.settle();
    let total = l.free.iter().copied().fold(end.0, f64::max);
    let shortest = l
        .items
        .iter()
        .filter(|it| matches!(it.kind, Kind::Step { timed: true, .. }) && it.end > it.start)
        .map(|it| it.end - it.start)
        .fold(f64::INFINITY, f64::min);
    // Wide enough that the shortest timed step can hold some text, not wider than needed.
    let mut scale = if total > 0.0 {
        AIM_WIDTH / total
    } else {
        MAX_SCALE
    };
    if shortest.is_finite() {
        scale = scale.max(40.0 / shortest);
    }
    let scale = scale.clamp(MIN_SCALE, MAX_SCALE);
    let name_w = lanes
        .names
        .iter()
        .map(|(a, b)| text_w(a, 11.0, true).max(text_w(b, 11.0, false)))
        .fold(0.0, f64::max);
    let left = MIN_LEFT.max((14.0 + name_w + 20.0).ceil());
    let x = |t: f64| left + t * scale;
    let lane_name = |k: usize| {
        lanes
            .names
            .get(k)
            .map_or("another controller", |n| n.0.as_str())
    };

    // What each item writes: in its box where it fits, else a label.
    let mut labels: Vec<Label> = Vec::new();
    let mut diamonds: Vec<(usize, usize, f64)> = Vec::new();
    let mut inside: Vec<bool> = Vec::new();
    for it in &l.items {
        let (x0, w) = (x(it.start), ((it.end - it.start) * scale).max(MIN_W));
        let at = (it.lane, it.row);
        match it.kind {
            Kind::Wait { of, .. } => {
                let text = format!("waits for {}", lane_name(of));
                let fits = text_w(&text, 11.0, false) + 6.0 <= w;
                inside.push(fits);
                if !fits {
                    labels.push(Label::new(
                        at,
                        x0,
                        false,
                        vec![(text, false, Some("#a04000"))],
                        "label wait",
                    ));
                }
            }
            Kind::Step { element, timed } => {
                let (name, sub) = step_texts(sfc, element);
                if timed {
                    let fits = text_w(&name, 11.0, true).max(text_w(&sub, 9.0, false)) + 6.0 <= w;
                    inside.push(fits);
                    if !fits {
                        labels.push(Label::new(
                            at,
                            x0,
                            false,
                            vec![(name, true, None), (format!(" {sub}"), false, None)],
                            "label step",
                        ));
                    }
                } else {
                    inside.push(false);
                    diamonds.push((it.lane, it.row, x0));
                    labels.push(Label::new(
                        at,
                        x0,
                        true,
                        vec![
                            (name, true, None),
                            (format!(" {sub} "), false, None),
                            ("no time".into(), false, Some("#b71c1c")),
                        ],
                        "label step",
                    ));
                }
                if let Some(cond) = &it.label {
                    labels.push(Label::new(
                        at,
                        x0,
                        false,
                        vec![(cond.clone(), false, Some("#3949ab"))],
                        "label branch",
                    ));
                }
            }
        }
    }
    for (lane, row, t, text) in &l.notes {
        labels.push(Label::new(
            (*lane, *row),
            x(*t),
            false,
            vec![(text.clone(), false, Some("#3949ab"))],
            "label branch",
        ));
    }
    diamonds.sort_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)).then(a.2.total_cmp(&b.2)));
    place(&mut labels, &diamonds);

    // The rows' heights: the boxes and their lines of labels.
    let mut lines = vec![vec![0usize; l.rows]; n];
    for lb in &labels {
        if let Some(j) = lb.line
            && let Some(r) = lines.get_mut(lb.lane).and_then(|v| v.get_mut(lb.row))
        {
            *r = (*r).max(j + 1);
        }
    }
    let row_h = |k: usize, r: usize| BOX_Y + BOX_H + ROW_PAD + lines[k][r] as f64 * LINE_H;
    // The bands' texts: each on the first level free where its band begins.
    let mut band_rows: Vec<f64> = Vec::new();
    let band_level: Vec<usize> = l
        .bands
        .iter()
        .map(|b| {
            let x0 = x(b.start);
            let level = band_rows
                .iter()
                .position(|r| *r + GAP <= x0)
                .unwrap_or_else(|| {
                    band_rows.push(0.0);
                    band_rows.len() - 1
                });
            band_rows[level] = x0 + 3.0 + text_w(&band_text(b), 11.0, false);
            level
        })
        .collect();
    let top = 44.0 + BAND_LEVEL * band_rows.len() as f64;
    let mut lane_y = Vec::with_capacity(n + 1);
    let mut lane_h = Vec::with_capacity(n);
    let mut row_y = Vec::with_capacity(n);
    let mut y = top;
    for k in 0..n {
        lane_y.push(y);
        let mut ys = Vec::with_capacity(l.rows);
        let mut ry = y + 6.0;
        for r in 0..l.rows {
            ys.push(ry);
            ry += row_h(k, r);
        }
        let h = (ry + 6.0 - y).max(48.0);
        row_y.push(ys);
        lane_h.push(h);
        y += h + LANE_GAP;
    }
    let bottom = y - LANE_GAP;
    let mid = |k: usize, r: usize| row_y[k][r] + BOX_Y + BOX_H / 2.0;
    let line_y =
        |k: usize, r: usize, j: usize| row_y[k][r] + BOX_Y + BOX_H + 4.0 + j as f64 * LINE_H + 9.0;

    // Everything but the lanes' frames (which span the width), the rightmost edge kept.
    let mut right = 0.0f64;
    let mut o = String::new();
    let title_w = text_w(title, 14.0, true);
    right = right.max(12.0 + title_w);
    let _ = writeln!(
        o,
        r#"<text x="12" y="20" font-size="14" font-weight="bold">{}</text>"#,
        esc(title)
    );
    // Bands (behind everything): loops and selections over every lane, their text above.
    for (b, level) in l.bands.iter().zip(&band_level) {
        let (x0, x1) = (x(b.start), x(b.end).max(x(b.start) + MIN_W));
        let text = band_text(b);
        right = right.max(x1).max(x0 + 3.0 + text_w(&text, 11.0, false));
        let (fill, stroke) = if b.loop_ {
            ("#eef6ee", "#2e7d32")
        } else {
            ("#eef2fb", "#3949ab")
        };
        let _ = writeln!(
            o,
            r#"<g class="{}"><rect x="{}" y="{}" width="{}" height="{}" fill="{fill}" stroke="{stroke}" stroke-dasharray="5 3"/><text x="{}" y="{}" fill="{stroke}">{}</text></g>"#,
            if b.loop_ { "loop" } else { "selection" },
            px(x0),
            px(top - 8.0),
            px(x1 - x0),
            px(bottom - top + 14.0),
            px(x0 + 3.0),
            px(top - 12.0 - BAND_LEVEL * *level as f64),
            esc(&text)
        );
    }
    let lanes_at = o.len();
    // Waits, then steps, each with its text where it fits.
    for (it, fits) in l.items.iter().zip(&inside) {
        let y = row_y[it.lane][it.row];
        let (x0, w) = (x(it.start), ((it.end - it.start) * scale).max(MIN_W));
        match it.kind {
            Kind::Wait { of, said } => {
                right = right.max(x0 + w);
                let who = lane_name(of);
                let _ = write!(
                    o,
                    r##"<g class="wait"><title>waits {} s for {}: {}</title><rect x="{}" y="{}" width="{}" height="{}" fill="url(#hatch)" stroke="#d35400"/>"##,
                    secs(it.end - it.start),
                    esc(who),
                    esc(&what(sfc, &said)),
                    px(x0),
                    px(y + BOX_Y),
                    px(w),
                    px(BOX_H),
                );
                if *fits {
                    let _ = write!(
                        o,
                        r##"<text x="{}" y="{}" fill="#a04000">waits for {}</text>"##,
                        px(x0 + 3.0),
                        px(y + BOX_Y + 19.0),
                        esc(who)
                    );
                }
                o.push_str("</g>\n");
            }
            Kind::Step { element, timed } => {
                let (name, sub) = step_texts(sfc, element);
                let what = match sub.split_once(" · ") {
                    Some((skill, id)) => format!("{name} ({id}), {skill}"),
                    None => format!("{name} ({sub})"),
                };
                if timed {
                    right = right.max(x0 + w);
                    let _ = write!(
                        o,
                        r##"<g class="step"><title>{}</title><rect x="{}" y="{}" width="{}" height="{}" rx="3" fill="#cfe3f7" stroke="#37474f"/>"##,
                        esc(&format!(
                            "{what}: {} s from {} s",
                            secs(it.end - it.start),
                            secs(it.start)
                        )),
                        px(x0),
                        px(y + BOX_Y),
                        px(w),
                        px(BOX_H),
                    );
                    if *fits {
                        let _ = write!(
                            o,
                            r##"<text x="{}" y="{}" font-weight="bold">{}</text><text x="{}" y="{}" font-size="9">{}</text>"##,
                            px(x0 + 3.0),
                            px(y + BOX_Y + 13.0),
                            esc(&name),
                            px(x0 + 3.0),
                            px(y + BOX_Y + 25.0),
                            esc(&sub)
                        );
                    }
                } else {
                    // A moment, not a box: a diamond where the step begins.
                    let (cx, cy, r) = (x0, y + 8.0, UNTIMED_W / 2.0);
                    right = right.max(cx + r);
                    let _ = write!(
                        o,
                        r##"<g class="step untimed"><title>{}</title><path d="M {} {} L {} {} L {} {} L {} {} z" fill="#f5f5f5" stroke="#37474f" stroke-dasharray="2 1"/>"##,
                        esc(&format!(
                            "{what}: no time (time@duration missing), at {} s",
                            secs(it.start)
                        )),
                        px(cx - r),
                        px(cy),
                        px(cx),
                        px(cy - r),
                        px(cx + r),
                        px(cy),
                        px(cx),
                        px(cy + r),
                    );
                }
                o.push_str("</g>\n");
            }
        }
    }
    // Handshakes: from where the teller tells to where the hearer hears; one that would lie
    // on an earlier one a little to the left of it (off the text of the box it ends at).
    let mut drawn: HashMap<(i64, i64), Vec<(f64, f64)>> = HashMap::new();
    for a in &l.arrows {
        let (teller, hearer) = (lane_name(a.from.0), lane_name(a.to.0));
        let (x1, x2) = (x(a.at), x(a.to_at));
        let (y1, y2) = (mid(a.from.0, a.from.1), mid(a.to.0, a.to.1));
        let (top, low) = (y1.min(y2), y1.max(y2));
        let same = drawn
            .entry(((x1 * 2.0).round() as i64, (x2 * 2.0).round() as i64))
            .or_default();
        let over = same.iter().filter(|d| d.0 < low && top < d.1).count();
        same.push((top, low));
        let dx = -4.0 * over as f64;
        right = right.max(x1.max(x2) + 4.0);
        let _ = writeln!(
            o,
            r##"<line class="handshake" x1="{}" y1="{}" x2="{}" y2="{}" stroke="#b03a2e" stroke-width="1.5"{} marker-end="url(#arrow)"><title>{} tells {}: {}</title></line>"##,
            px(x1 + dx),
            px(y1),
            px(x2 + dx),
            px(y2),
            if a.said.kind == Said::Decision {
                r#" stroke-dasharray="4 2""#
            } else {
                ""
            },
            esc(teller),
            esc(hearer),
            esc(&what(sfc, &a.said))
        );
    }
    // The labels that do not fit: leaders first, then the texts over them (a white halo).
    let anchor_y = |lb: &Label| {
        let y = row_y[lb.lane][lb.row];
        if lb.diamond {
            y + 8.0 + UNTIMED_W / 2.0
        } else {
            y + BOX_Y + BOX_H
        }
    };
    for lb in &labels {
        if let Some(j) = lb.line {
            let _ = writeln!(
                o,
                r##"<line class="leader" x1="{x}" y1="{}" x2="{x}" y2="{}" stroke="#78909c" stroke-width="0.7"/>"##,
                px(anchor_y(lb)),
                px(line_y(lb.lane, lb.row, j) - 3.0),
                x = px(lb.leader_x())
            );
        }
    }
    for lb in &labels {
        right = right.max(lb.right());
        let y = match lb.line {
            Some(j) => line_y(lb.lane, lb.row, j),
            None => row_y[lb.lane][lb.row] + 11.0,
        };
        let _ = write!(
            o,
            r##"<text class="{}" x="{}" y="{}" font-size="9" stroke="#ffffff" stroke-width="3" stroke-linejoin="round" paint-order="stroke">"##,
            lb.class,
            px(lb.text_x()),
            px(y)
        );
        for (text, bold, fill) in &lb.spans {
            match (bold, fill) {
                (false, None) => o.push_str(&esc(text)),
                _ => {
                    let _ = write!(
                        o,
                        "<tspan{}{}>{}</tspan>",
                        if *bold { r#" font-weight="bold""# } else { "" },
                        fill.map(|f| format!(r#" fill="{f}""#)).unwrap_or_default(),
                        esc(text)
                    );
                }
            }
        }
        o.push_str("</text>\n");
    }
    // The time axis and the cycle time.
    let axis_y = bottom + LANE_GAP + 4.0;
    let axis_end = x(total).max(left + 80.0);
    right = right.max(axis_end);
    let _ = writeln!(
        o,
        r##"<line x1="{}" y1="{}" x2="{}" y2="{}" stroke="#212121"/>"##,
        px(left),
        px(axis_y),
        px(axis_end),
        px(axis_y)
    );
    let step = tick_step(scale);
    let mut t = 0.0;
    let mut k = 0u32;
    while t <= total + 1e-9 || k == 0 {
        let text = format!("{} s", secs(t));
        right = right.max(x(t) + text_w(&text, 10.0, false) / 2.0);
        let _ = writeln!(
            o,
            r##"<line x1="{x}" y1="{}" x2="{x}" y2="{}" stroke="#212121"/><text x="{x}" y="{}" text-anchor="middle" font-size="10">{text}</text>"##,
            px(axis_y),
            px(axis_y + 5.0),
            px(axis_y + 17.0),
            x = px(x(t))
        );
        k += 1;
        t = f64::from(k) * step;
        if k > 10_000 {
            break;
        }
    }
    let cycle = format!("cycle time {} s", secs(total));
    right = right.max(x(total) + 6.0 + text_w(&cycle, 11.0, true));
    let _ = writeln!(
        o,
        r##"<line class="cycle" x1="{x}" y1="{}" x2="{x}" y2="{}" stroke="#212121" stroke-dasharray="2 2"/><text x="{}" y="{}" font-weight="bold">{cycle}</text>"##,
        px(top - 8.0),
        px(axis_y + 5.0),
        px(x(total) + 6.0),
        px(axis_y + 34.0),
        x = px(x(total))
    );
    let mut legend = vec![
        "selections: each alternative on a row of its own, the longest counts; loops: one round",
    ];
    if !lanes.programs.is_empty() {
        legend.push(
            "arrows: the programs' handshakes, from the tell to the hear (dashed: a branch taken)",
        );
        legend.push("hatched: a program waits for another in a hear");
    }
    for (k, text) in legend.iter().enumerate() {
        right = right.max(12.0 + text_w(text, 10.0, false));
        let _ = writeln!(
            o,
            r##"<text x="12" y="{}" font-size="10" fill="#555555">{text}</text>"##,
            px(axis_y + 54.0 + 13.0 * k as f64)
        );
    }
    let height = (axis_y + 54.0 + 13.0 * (legend.len() - 1) as f64 + 10.0).ceil();
    let width = (right + MARGIN).ceil();

    // The lanes' frames and names, behind the items.
    let mut frames = String::new();
    for k in 0..n {
        let (name, program) = lanes
            .names
            .get(k)
            .cloned()
            .unwrap_or_else(|| ("the robot".into(), String::new()));
        let _ = writeln!(
            frames,
            r##"<g class="lane"><rect x="8" y="{}" width="{}" height="{}" fill="none" stroke="#9e9e9e"/><text x="14" y="{}" font-weight="bold">{}</text><text x="14" y="{}" fill="#555555">{}</text></g>"##,
            px(lane_y[k]),
            px(width - 16.0),
            px(lane_h[k]),
            px(lane_y[k] + 20.0),
            esc(&name),
            px(lane_y[k] + 36.0),
            esc(&program)
        );
    }
    o.insert_str(lanes_at, &frames);

    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="DejaVu Sans, Arial, sans-serif" font-size="11">"#,
        w = px(width),
        h = px(height)
    );
    let _ = writeln!(svg, "<title>{}</title>", esc(title));
    svg.push_str(concat!(
        "<defs>\n",
        r##"<marker id="arrow" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="7" markerHeight="7" orient="auto-start-reverse"><path d="M 0 0 L 10 5 L 0 10 z" fill="#b03a2e"/></marker>"##,
        "\n",
        r##"<pattern id="hatch" width="6" height="6" patternUnits="userSpaceOnUse" patternTransform="rotate(45)"><rect width="6" height="6" fill="#fbeee6"/><line x1="0" y1="0" x2="0" y2="6" stroke="#d35400" stroke-width="2"/></pattern>"##,
        "\n</defs>\n"
    ));
    let _ = writeln!(
        svg,
        r##"<rect x="0" y="0" width="{}" height="{}" fill="#ffffff"/>"##,
        px(width),
        px(height)
    );
    svg.push_str(&o);
    svg.push_str("</svg>\n");
    svg
}

/// A band's text, with its sign.
fn band_text(b: &Band) -> String {
    format!("{}{}", if b.loop_ { "↺ " } else { "◇ " }, b.text)
}

/// A step's name and what follows it: `skill · id=N` (or `id=N`).
fn step_texts(sfc: &Sfc, element: usize) -> (String, String) {
    let id = local_id(sfc, element);
    match &sfc.elements[element].kind {
        ElementKind::Step(s) => (
            s.name.to_string(),
            match &s.skill {
                Some(skill) => format!("{} · id={id}", skill.text),
                None => format!("id={id}"),
            },
        ),
        _ => (String::new(), format!("id={id}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_numbers_about_80_px_apart() {
        assert_eq!(tick_step(80.0), 1.0);
        assert_eq!(tick_step(100.0), 1.0);
        assert_eq!(tick_step(30.0), 5.0);
        assert_eq!(tick_step(160.0), 0.5);
        assert_eq!(tick_step(4.0), 20.0);
    }

    #[test]
    fn text_is_escaped_and_numbers_are_short() {
        assert_eq!(esc("a<b & \"c\">"), "a&lt;b &amp; &quot;c&quot;&gt;");
        assert_eq!(esc("\u{1}"), "\u{fffd}");
        assert_eq!(secs(1.5), "1.5");
        assert_eq!(secs(2.0), "2");
        assert_eq!(secs(0.0), "0");
        assert_eq!(px(12.0), "12");
        assert_eq!(px(12.25), "12.2");
    }

    #[test]
    fn text_widths_are_dejavu_sans_advances() {
        // "Grip" in DejaVu Sans Bold at 11 px: G 821, r 493, i 343, p 716.
        assert!((text_w("Grip", 11.0, true) - 2.373 * 11.0).abs() < 1e-9);
        assert!((text_w(" ", 1000.0, false) - 318.0).abs() < 1e-9);
        // Beyond ASCII: wide.
        assert!(text_w("ä", 10.0, false) > text_w("a", 10.0, false));
        assert_eq!(text_w("日", 10.0, false), 10.0);
    }

    fn label(lane: usize, x: f64, w: f64, diamond: bool) -> Label {
        Label {
            lane,
            row: 0,
            x,
            diamond,
            spans: Vec::new(),
            w,
            line: Some(0),
            class: "label",
        }
    }

    #[test]
    fn labels_take_the_first_line_where_they_meet_no_other() {
        let mut ls = vec![
            label(0, 100.0, 50.0, false),
            label(0, 120.0, 20.0, false),
            label(0, 130.0, 20.0, false),
            label(0, 200.0, 10.0, false),
            label(1, 120.0, 20.0, false),
        ];
        place(&mut ls, &[]);
        let lines: Vec<_> = ls.iter().map(|l| l.line).collect();
        assert_eq!(
            lines,
            [Some(0), Some(1), Some(2), Some(0), Some(0)],
            "the first ends at 154.5, the second at 144.5, the third begins at 130"
        );
    }

    #[test]
    fn a_diamonds_label_stands_beside_it_unless_it_meets_another() {
        let diamonds = [(0, 0, 100.0), (0, 0, 130.0), (0, 0, 300.0)];
        let mut ls = vec![
            label(0, 100.0, 40.0, true),
            label(0, 130.0, 10.0, true),
            label(0, 300.0, 10.0, true),
        ];
        place(&mut ls, &diamonds);
        // The first would run over the second diamond: below; the others beside.
        let lines: Vec<_> = ls.iter().map(|l| l.line).collect();
        assert_eq!(lines, [Some(0), None, None]);
    }
}
