//! The layout: a walk over the plan that puts each step on its lane at the time it starts, the
//! alternatives of a selection on rows of their own, bands over loops, selections and states;
//! in a cell, each lane's program walked alongside, its tells and hears made arrows and waits.

use std::collections::VecDeque;

use super::{Arrow, Band, Frame, Item, Kind, Layout, Sent, local_id};
use crate::model::{ElementKind, Sfc};
use crate::plan::Block;
use crate::plan::cell::Message;

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

/// A frontier: when the steps before have ended, and the last of them (lane, row, element).
type Front = (f64, Option<(usize, usize, usize)>);

fn duration(sfc: &Sfc, i: usize) -> Option<f64> {
    match &sfc.elements[i].kind {
        ElementKind::Step(s) => s.duration,
        _ => None,
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
    pub(super) fn settle(&mut self) {
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

    pub(super) fn walk(&mut self, blocks: &'s [Block], mut front: Front, row: usize) -> Front {
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
