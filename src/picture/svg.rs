//! The SVG: the layout's items, bands, arrows and labels drawn, the lanes' frames and names,
//! the time axis, the cycle time and a legend.

use std::collections::HashMap;
use std::fmt::Write as _;

use super::labels::place;
use super::text::{esc, px, secs, text_w, tick_step};
use super::{
    AIM_WIDTH, BAND_LEVEL, BOX_H, BOX_Y, Band, Frame, GAP, Kind, LANE_GAP, LINE_H, Label, Lanes,
    Layout, MARGIN, MAX_SCALE, MIN_LEFT, MIN_SCALE, MIN_W, ROW_PAD, UNTIMED_W, local_id,
};
use crate::model::{ElementKind, Sfc};
use crate::plan::Plan;
use crate::plan::cell::{Kind as Said, Message};

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
