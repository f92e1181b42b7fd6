//! The plan as a picture (`--svg FILE`, the daemon's `picture = true`): an SVG timeline with one
//! lane per controller (one lane when there is one), a box per step as long as its
//! `time@duration` (a step without one, such as the initial step, drawn as a small dashed
//! diamond at its moment and marked "no time"), the
//! handshakes between controllers as arrows and the time a controller waits for another as a
//! hatched box, each alternative of a selection on a row of its own (the longest one counts for
//! what follows), a loop's body once inside a band that says so, a time axis in seconds and the
//! cycle time. Text is text (step name, skill, localId), so a browser finds and selects it; no
//! scripts, no external resources. The same plan gives the same bytes.
//!
//! Like the listings of [`crate::print`], it reads the chart and the plan and does no I/O.

use std::collections::HashMap;
use std::fmt::Write as _;

use crate::model::{ElementKind, Sfc};
use crate::plan::{Block, Plan};

/// What the picture's lanes are: each controller's name (and its program's), and which lane
/// runs each step (by element index); a step not listed runs on lane 0.
pub struct Lanes {
    pub names: Vec<(String, String)>,
    pub of: HashMap<usize, usize>,
}

/// Pixels per second at most and at least, and the widest picture (px) the scale aims at.
const MAX_SCALE: f64 = 160.0;
const MIN_SCALE: f64 = 4.0;
const AIM_WIDTH: f64 = 1100.0;
/// The width of a step without a time (a diamond), and the least width of any box (px).
const UNTIMED_W: f64 = 10.0;
const MIN_W: f64 = 3.0;
const LEFT: f64 = 170.0;
const TOP: f64 = 78.0;
/// A row: steps without a time at the top, the boxes, a selection branch's condition below.
const ROW_H: f64 = 62.0;
const BOX_Y: f64 = 16.0;
const BOX_H: f64 = 30.0;
const LANE_GAP: f64 = 14.0;

#[derive(Debug, Clone)]
enum Kind {
    Step {
        element: usize,
        timed: bool,
    },
    /// The lane idles until `element` (a step of lane `of`) has ended.
    Wait {
        element: usize,
        of: usize,
    },
}

#[derive(Debug, Clone)]
struct Item {
    lane: usize,
    row: usize,
    start: f64,
    end: f64,
    kind: Kind,
    /// A selection branch's condition, shown above its first box.
    label: Option<String>,
}

#[derive(Debug, Clone)]
struct Arrow {
    from: (usize, usize),
    to: (usize, usize),
    at: f64,
    to_at: f64,
}

#[derive(Debug, Clone)]
struct Band {
    start: f64,
    end: f64,
    text: String,
    loop_: bool,
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

impl Layout<'_> {
    fn walk(&mut self, blocks: &[Block], mut front: Front, row: usize) -> Front {
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
                        let start = front.0.max(self.free[c]);
                        if let Some((pc, prow, pe)) = front.1
                            && pc != c
                        {
                            if front.0 > self.free[c] {
                                self.items.push(Item {
                                    lane: c,
                                    row,
                                    start: self.free[c],
                                    end: front.0,
                                    kind: Kind::Wait {
                                        element: pe,
                                        of: pc,
                                    },
                                    label: None,
                                });
                            }
                            self.arrows.push(Arrow {
                                from: (pc, prow),
                                to: (c, row),
                                at: front.0,
                                to_at: start,
                            });
                        }
                        (c, start)
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
                    }
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
                    let free = self.free.clone();
                    let mut best: Option<(Front, Vec<f64>)> = None;
                    for (k, br) in branches.iter().enumerate() {
                        self.free.clone_from(&free);
                        let r = if k == 0 {
                            row
                        } else {
                            self.rows += 1;
                            self.rows - 1
                        };
                        let cond = br.condition_text(self.sfc);
                        self.label = Some(format!("{}. {cond}", k + 1));
                        let e = self.walk(&br.body, front, r);
                        if let Some(text) = self.label.take() {
                            // No step in this branch: its condition where it would begin.
                            let lane = front.1.map_or(0, |(c, _, _)| c);
                            self.notes
                                .push((lane, r, front.0, format!("{text} (no step)")));
                        }
                        if best.as_ref().is_none_or(|b| e.0 > b.0.0) {
                            best = Some((e, self.free.clone()));
                        }
                    }
                    let start = front.0;
                    if let Some((e, f)) = best {
                        front = (e.0, e.1);
                        self.free = f;
                    }
                    self.bands.push(Band {
                        start,
                        end: front.0,
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
                    let start = front.0;
                    front = self.walk(body, front, row);
                    self.bands.push(Band {
                        start,
                        end: front.0,
                        text: format!(
                            "{} to id={}: one round shown",
                            if *endless { "endless loop" } else { "loop" },
                            local_id(self.sfc, *head)
                        ),
                        loop_: true,
                    });
                }
                Block::Machine(states) => {
                    let start = front.0;
                    for st in states {
                        front = self.walk(&st.body, front, row);
                    }
                    self.bands.push(Band {
                        start,
                        end: front.0,
                        text: format!("{} states, each once", states.len()),
                        loop_: false,
                    });
                }
                Block::Goto { .. } | Block::Wait(_) | Block::Tell(_) | Block::Hear(_) => {}
            }
        }
        front
    }
}

/// `&`, `<`, `>` and `"` as XML wants them.
fn esc(s: &str) -> String {
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
fn tick_step(scale: f64) -> f64 {
    let raw = 80.0 / scale;
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * p)
}

/// The SVG of `plan` (of `sfc`) on `lanes`; `title` names the program and the chart.
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
    };
    let end = l.walk(&plan.body, (0.0, None), 0);
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
    let x = |t: f64| LEFT + t * scale;
    let lane_h = l.rows as f64 * ROW_H + 12.0;
    let lane_y = |k: usize| TOP + k as f64 * (lane_h + LANE_GAP);
    let row_y = |k: usize, r: usize| lane_y(k) + 6.0 + r as f64 * ROW_H;
    let right = l
        .items
        .iter()
        .map(|it| {
            x(it.start)
                + match it.kind {
                    Kind::Step { timed: false, .. } => UNTIMED_W,
                    _ => ((it.end - it.start) * scale).max(MIN_W),
                }
        })
        .fold(x(total), f64::max);
    // Room for the bands' texts, which start where their band does.
    let right = l
        .bands
        .iter()
        .map(|b| x(b.start) + 7.0 * b.text.chars().count() as f64)
        .fold(right, f64::max);
    let width = (right + 220.0).ceil();
    let height = (lane_y(n) + 70.0).ceil();

    let mut o = String::new();
    let _ = writeln!(
        o,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="DejaVu Sans, Arial, sans-serif" font-size="11">"#,
        w = px(width),
        h = px(height)
    );
    let _ = writeln!(o, "<title>{}</title>", esc(title));
    o.push_str(concat!(
        "<defs>\n",
        r##"<marker id="arrow" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="7" markerHeight="7" orient="auto-start-reverse"><path d="M 0 0 L 10 5 L 0 10 z" fill="#b03a2e"/></marker>"##,
        "\n",
        r##"<pattern id="hatch" width="6" height="6" patternUnits="userSpaceOnUse" patternTransform="rotate(45)"><rect width="6" height="6" fill="#fbeee6"/><line x1="0" y1="0" x2="0" y2="6" stroke="#d35400" stroke-width="2"/></pattern>"##,
        "\n</defs>\n"
    ));
    let _ = writeln!(
        o,
        r##"<rect x="0" y="0" width="{}" height="{}" fill="#ffffff"/>"##,
        px(width),
        px(height)
    );
    let _ = writeln!(
        o,
        r#"<text x="12" y="20" font-size="14" font-weight="bold">{}</text>"#,
        esc(title)
    );
    // Bands (behind everything): loops and selections over every lane, their text above.
    let mut band_rows: Vec<f64> = Vec::new();
    for b in &l.bands {
        let (x0, x1) = (x(b.start), x(b.end).max(x(b.start) + MIN_W));
        // The first text row free at this band's start.
        let level = band_rows.iter().position(|r| *r <= x0).unwrap_or_else(|| {
            band_rows.push(0.0);
            band_rows.len() - 1
        });
        band_rows[level] = x0 + 7.0 * b.text.chars().count() as f64;
        let (fill, stroke) = if b.loop_ {
            ("#eef6ee", "#2e7d32")
        } else {
            ("#eef2fb", "#3949ab")
        };
        let _ = writeln!(
            o,
            r#"<g class="{}"><rect x="{}" y="{}" width="{}" height="{}" fill="{fill}" stroke="{stroke}" stroke-dasharray="5 3"/><text x="{}" y="{}" fill="{stroke}">{}{}</text></g>"#,
            if b.loop_ { "loop" } else { "selection" },
            px(x0),
            px(TOP - 8.0),
            px(x1 - x0),
            px(lane_y(n) - TOP + 4.0),
            px(x0 + 3.0),
            px(TOP - 12.0 - 12.0 * level as f64),
            if b.loop_ { "↺ " } else { "◇ " },
            esc(&b.text)
        );
    }
    // Lanes.
    for k in 0..n {
        let (name, program) = lanes
            .names
            .get(k)
            .cloned()
            .unwrap_or_else(|| ("the robot".into(), String::new()));
        let _ = writeln!(
            o,
            r##"<g class="lane"><rect x="8" y="{}" width="{}" height="{}" fill="none" stroke="#9e9e9e"/><text x="14" y="{}" font-weight="bold">{}</text><text x="14" y="{}" fill="#555555">{}</text></g>"##,
            px(lane_y(k)),
            px(width - 16.0),
            px(lane_h),
            px(lane_y(k) + 20.0),
            esc(&name),
            px(lane_y(k) + 36.0),
            esc(&program)
        );
    }
    // Waits, then steps.
    for it in &l.items {
        let y = row_y(it.lane, it.row);
        let (x0, w) = (x(it.start), ((it.end - it.start) * scale).max(MIN_W));
        match it.kind {
            Kind::Wait { element, of } => {
                let who = lanes
                    .names
                    .get(of)
                    .map_or("another controller", |n| n.0.as_str());
                let _ = writeln!(
                    o,
                    r##"<g class="wait"><title>waits {} s for {} (id={})</title><rect x="{}" y="{}" width="{}" height="{}" fill="url(#hatch)" stroke="#d35400"/><text x="{}" y="{}" fill="#a04000">waits for {}</text></g>"##,
                    secs(it.end - it.start),
                    esc(who),
                    local_id(sfc, element),
                    px(x0),
                    px(y + BOX_Y),
                    px(w),
                    px(BOX_H),
                    px(x0 + 3.0),
                    px(y + BOX_Y + 19.0),
                    esc(who)
                );
            }
            Kind::Step { element, timed } => {
                let (name, skill) = match &sfc.elements[element].kind {
                    ElementKind::Step(s) => (
                        s.name.to_string(),
                        s.skill
                            .as_ref()
                            .map(|n| n.text.to_string())
                            .unwrap_or_default(),
                    ),
                    _ => (String::new(), String::new()),
                };
                let id = local_id(sfc, element);
                let what = if skill.is_empty() {
                    format!("{name} (id={id})")
                } else {
                    format!("{name} (id={id}), {skill}")
                };
                if timed {
                    let _ = write!(
                        o,
                        r##"<g class="step"><title>{}</title><rect x="{}" y="{}" width="{}" height="{}" rx="3" fill="#cfe3f7" stroke="#37474f"/><text x="{}" y="{}" font-weight="bold">{}</text><text x="{}" y="{}" font-size="9">{}id={id}</text>"##,
                        esc(&format!(
                            "{what}: {} s from {} s",
                            secs(it.end - it.start),
                            secs(it.start)
                        )),
                        px(x0),
                        px(y + BOX_Y),
                        px(w),
                        px(BOX_H),
                        px(x0 + 3.0),
                        px(y + BOX_Y + 13.0),
                        esc(&name),
                        px(x0 + 3.0),
                        px(y + BOX_Y + 25.0),
                        if skill.is_empty() {
                            String::new()
                        } else {
                            format!("{} · ", esc(&skill))
                        }
                    );
                } else {
                    // A moment, not a box: a diamond where the step begins, its text beside.
                    let (cx, cy, r) = (x0, y + 9.0, UNTIMED_W / 2.0);
                    let _ = write!(
                        o,
                        r##"<g class="step untimed"><title>{}</title><path d="M {} {} L {} {} L {} {} L {} {} z" fill="#f5f5f5" stroke="#37474f" stroke-dasharray="2 1"/><text x="{}" y="{}" font-size="9"><tspan font-weight="bold">{}</tspan> {}id={id} <tspan fill="#b71c1c">no time</tspan></text>"##,
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
                        px(cx + r + 2.0),
                        px(cy + 3.0),
                        esc(&name),
                        if skill.is_empty() {
                            String::new()
                        } else {
                            format!("{} · ", esc(&skill))
                        }
                    );
                }
                if let Some(label) = &it.label {
                    let _ = write!(
                        o,
                        r##"<text x="{}" y="{}" font-size="9" fill="#3949ab">{}</text>"##,
                        px(x0 + 2.0),
                        px(y + BOX_Y + BOX_H + 10.0),
                        esc(label)
                    );
                }
                o.push_str("</g>\n");
            }
        }
    }
    for (lane, row, t, text) in &l.notes {
        let _ = writeln!(
            o,
            r##"<text class="branch" x="{}" y="{}" font-size="9" fill="#3949ab">{}</text>"##,
            px(x(*t) + 2.0),
            px(row_y(*lane, *row) + BOX_Y + BOX_H + 10.0),
            esc(text)
        );
    }
    // Handshakes: from the end of the step waited for to the start of the step that waited.
    for a in &l.arrows {
        let y0 = row_y(a.from.0, a.from.1) + BOX_Y + BOX_H / 2.0;
        let y1 = row_y(a.to.0, a.to.1) + BOX_Y + BOX_H / 2.0;
        let _ = writeln!(
            o,
            r##"<line class="handshake" x1="{}" y1="{}" x2="{}" y2="{}" stroke="#b03a2e" stroke-width="1.5" marker-end="url(#arrow)"/>"##,
            px(x(a.at)),
            px(y0),
            px(x(a.to_at)),
            px(y1)
        );
    }
    // The time axis and the cycle time.
    let axis_y = lane_y(n) + 4.0;
    let _ = writeln!(
        o,
        r##"<line x1="{}" y1="{}" x2="{}" y2="{}" stroke="#212121"/>"##,
        px(LEFT),
        px(axis_y),
        px(x(total).max(LEFT + 80.0)),
        px(axis_y)
    );
    let step = tick_step(scale);
    let mut t = 0.0;
    let mut k = 0u32;
    while t <= total + 1e-9 || k == 0 {
        let _ = writeln!(
            o,
            r##"<line x1="{x}" y1="{}" x2="{x}" y2="{}" stroke="#212121"/><text x="{x}" y="{}" text-anchor="middle" font-size="10">{} s</text>"##,
            px(axis_y),
            px(axis_y + 5.0),
            px(axis_y + 17.0),
            secs(t),
            x = px(x(t))
        );
        k += 1;
        t = f64::from(k) * step;
        if k > 10_000 {
            break;
        }
    }
    let _ = writeln!(
        o,
        r##"<line class="cycle" x1="{x}" y1="{}" x2="{x}" y2="{}" stroke="#212121" stroke-dasharray="2 2"/><text x="{}" y="{}" font-weight="bold">cycle time {} s</text>"##,
        px(TOP - 8.0),
        px(axis_y + 5.0),
        px(x(total) + 6.0),
        px(axis_y + 34.0),
        secs(total),
        x = px(x(total))
    );
    let _ = writeln!(
        o,
        r##"<text x="12" y="{}" font-size="10" fill="#555555">selections: the longest alternative counts; loops: one round; a handshake arrow runs from the step waited for to the step that waited</text>"##,
        px(axis_y + 56.0)
    );
    o.push_str("</svg>\n");
    o
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
}
