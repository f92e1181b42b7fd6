//! Cells (docs/CELLS.md): `-pO` per program, `-pF` one lane per controller.

use std::fmt::Write as _;

use super::order::order_lines;
use super::{duration, fmt_num, seconds, step_name};
use crate::model::{Blackboard, ElementKind, Sfc};
use crate::plan::{Block, Plan};

/// What the cell listings need besides the chart: the programs, the blackboard's names, the
/// programs' names (empty without a program name).
pub struct CellView<'a> {
    pub cell: &'a crate::plan::cell::Cell,
    pub bb: &'a Blackboard,
    pub names: &'a [String],
}

impl CellView<'_> {
    /// Controller `k`'s resource name.
    pub fn controller(&self, k: usize) -> &str {
        &self.bb.resources[self.cell.controllers[k]].name.text
    }

    /// Program `k`'s name (`the program of <controller>` without a program name).
    pub fn program(&self, k: usize) -> String {
        self.names
            .get(k)
            .cloned()
            .unwrap_or_else(|| format!("the program of {}", self.controller(k)))
    }

    /// A handshake as one line, for program `me`.
    pub(super) fn handshake(
        &self,
        sfc: &Sfc,
        m: &crate::plan::cell::Message,
        tell: bool,
    ) -> String {
        use crate::plan::cell::Kind;
        let ch = &self.cell.channels[m.channel];
        let about = match &sfc.elements[m.about].kind {
            ElementKind::Step(s) => {
                format!("step {} (id={})", s.name, sfc.elements[m.about].local_id)
            }
            _ => format!("id={}", sfc.elements[m.about].local_id),
        };
        match (tell, m.kind) {
            (true, Kind::Done) => format!("tell {}: {about} done", self.controller(ch.to)),
            (true, Kind::Decision) => format!(
                "tell {}: branch {} taken at the selection {about}",
                self.controller(ch.to),
                m.value + 1
            ),
            (false, Kind::Done) => format!("wait for {}: {about} done", self.controller(ch.from)),
            (true, Kind::Passed(c)) => {
                format!("tell {}: it {} {about}", self.controller(ch.to), c.verb())
            }
            (false, Kind::Passed(c)) => {
                format!(
                    "wait for {}: it {} {about}",
                    self.controller(ch.from),
                    c.verb()
                )
            }
            (false, Kind::Decision) => format!(
                "wait for {}: its branch at the selection {about}",
                self.controller(ch.from)
            ),
        }
    }
}

/// `-pO` of a cell: each program's order, with its handshakes.
pub fn cell_order(sfc: &Sfc, view: &CellView) -> String {
    let mut o = String::new();
    for (k, p) in view.cell.programs.iter().enumerate() {
        let _ = writeln!(
            o,
            "program {} (controller {}):",
            view.program(k),
            view.controller(k)
        );
        order_lines(sfc, Some(view), &p.body, " ", &mut 0, &mut o);
    }
    o
}

/// One lane's entry of a cell's timeline: a step, or a wait for another controller.
#[derive(Debug, Clone, PartialEq)]
pub struct LaneItem {
    pub start: f64,
    pub end: f64,
    /// The step, or (for a wait) the step waited for.
    pub element: usize,
    /// For a wait: the controller waited for.
    pub waits_for: Option<usize>,
}

/// The cell's timeline (`-pF`): each controller's steps at the earliest times the chart
/// allows them (every step after the steps the chart puts before it, on any controller, and
/// after its controller's step before it in its program), its waits for other controllers, and
/// the cell's time. Simultaneous branches on different controllers overlap; a selection counts
/// its longest branch, a loop one round.
pub fn cell_timeline(sfc: &Sfc, plan: &Plan, view: &CellView) -> (Vec<Vec<LaneItem>>, f64) {
    let n = view.cell.controllers.len();
    // Each step's controller, from the programs.
    let mut of: std::collections::HashMap<usize, usize> = Default::default();
    for (k, p) in view.cell.programs.iter().enumerate() {
        crate::plan::visit(&p.body, &mut |b| {
            if let Block::Step(i) = b {
                of.insert(*i, k);
            }
        });
    }
    struct T<'s> {
        sfc: &'s Sfc,
        of: std::collections::HashMap<usize, usize>,
        lanes: Vec<Vec<LaneItem>>,
        free: Vec<f64>,
    }
    // A frontier: (time the steps before end, the last step ended then and its controller).
    type Front = (f64, Option<(usize, usize)>);
    fn walk(t: &mut T, blocks: &[Block], mut front: Front) -> Front {
        for b in blocks {
            match b {
                Block::Step(i) => {
                    let Some(&c) = t.of.get(i) else {
                        continue;
                    };
                    let d = duration(t.sfc, *i);
                    let start = front.0.max(t.free[c]);
                    if let Some((pc, pi)) = front.1
                        && pc != c
                        && front.0 > t.free[c]
                    {
                        t.lanes[c].push(LaneItem {
                            start: t.free[c],
                            end: front.0,
                            element: pi,
                            waits_for: Some(pc),
                        });
                    }
                    t.lanes[c].push(LaneItem {
                        start,
                        end: start + d,
                        element: *i,
                        waits_for: None,
                    });
                    t.free[c] = start + d;
                    front = (start + d, Some((c, *i)));
                }
                Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                    let mut end = front;
                    for br in branches {
                        let e = walk(t, br, front);
                        if e.0 >= end.0 {
                            end = e;
                        }
                    }
                    front = end;
                }
                Block::Choice { branches, .. } | Block::Follow { branches, .. } => {
                    // The longest branch counts: each tried from the same lanes; what a
                    // branch adds is taken off again (the lanes are not copied per branch).
                    let lens: Vec<usize> = t.lanes.iter().map(Vec::len).collect();
                    let free = t.free.clone();
                    let mut best: Option<(Front, Vec<Vec<LaneItem>>, Vec<f64>)> = None;
                    for br in branches {
                        t.free.clone_from(&free);
                        let e = walk(t, &br.body, front);
                        let added: Vec<Vec<LaneItem>> = t
                            .lanes
                            .iter_mut()
                            .zip(&lens)
                            .map(|(lane, &n)| lane.split_off(n))
                            .collect();
                        if best.as_ref().is_none_or(|b| e.0 > b.0.0) {
                            best = Some((e, added, t.free.clone()));
                        }
                    }
                    match best {
                        Some((e, added, f)) => {
                            front = e;
                            for (lane, mut more) in t.lanes.iter_mut().zip(added) {
                                lane.append(&mut more);
                            }
                            t.free = f;
                        }
                        None => t.free = free,
                    }
                }
                Block::Loop { body, .. } => front = walk(t, body, front),
                Block::Machine(states) => {
                    for st in states {
                        front = walk(t, &st.body, front);
                    }
                }
                Block::Goto { .. } => {}
                Block::Wait(_) | Block::Tell(_) | Block::Hear(_) => {}
            }
        }
        front
    }
    let mut t = T {
        sfc,
        of,
        lanes: vec![Vec::new(); n],
        free: vec![0.0; n],
    };
    let end = walk(&mut t, &plan.body, (0.0, None));
    let total = t.free.iter().copied().fold(end.0, f64::max);
    (t.lanes, total)
}

/// `-pF` of a cell: one column per controller, a row per moment something starts, the waits
/// between controllers, and the cell's time.
pub fn cell_flow(sfc: &Sfc, plan: &Plan, view: &CellView) -> String {
    let (lanes, total) = cell_timeline(sfc, plan, view);
    const W: usize = 30;
    let cut = |s: String| -> String {
        if s.chars().count() > W {
            s.chars().take(W - 1).collect::<String>() + "…"
        } else {
            s
        }
    };
    let mut o = String::new();
    let _ = write!(o, "{:<8}", "time");
    for k in 0..lanes.len() {
        let _ = write!(o, " | {:<W$}", cut(view.controller(k).to_owned()));
    }
    let _ = writeln!(o);
    let mut rows: Vec<(f64, usize, String)> = Vec::new();
    for (k, lane) in lanes.iter().enumerate() {
        for it in lane {
            let text = match it.waits_for {
                Some(c) => format!(
                    "waits for {} (id={})",
                    view.controller(c),
                    sfc.elements[it.element].local_id
                ),
                None => format!(
                    "{} (id={}) + {}",
                    step_name(sfc, it.element),
                    sfc.elements[it.element].local_id,
                    fmt_num(it.end - it.start)
                ),
            };
            rows.push((it.start, k, text));
        }
    }
    rows.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    for (time, k, text) in rows {
        let _ = write!(o, "{:<8}", fmt_num(time));
        for c in 0..lanes.len() {
            let cell = if c == k {
                cut(text.clone())
            } else {
                String::new()
            };
            let _ = write!(o, " | {cell:<W$}");
        }
        let _ = writeln!(o);
    }
    let _ = writeln!(
        o,
        "cell time: {} (simultaneous branches on different controllers overlap; the longest alternative counted, loops once)",
        seconds(total)
    );
    o
}
