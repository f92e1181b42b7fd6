//! The labels that do not fit where they belong: each beside its diamond where it meets
//! nothing, else on the first line below its row's boxes where it meets no other label.

use super::text::text_w;
use super::{GAP, LABEL, Label, Span, UNTIMED_W};

impl Label {
    pub(super) fn new(
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
    pub(super) fn text_x(&self) -> f64 {
        match self.line {
            None => self.x + UNTIMED_W / 2.0 + 2.0,
            Some(_) => self.leader_x() + 3.0,
        }
    }

    /// Where its leader runs down: a diamond's centre, inside a box's left edge.
    pub(super) fn leader_x(&self) -> f64 {
        if self.diamond { self.x } else { self.x + 1.5 }
    }

    pub(super) fn right(&self) -> f64 {
        self.text_x() + self.w
    }
}

/// Gives each label its place: beside its diamond where that meets no other label or diamond,
/// else the first line below the boxes where it meets no other label (labels in time order).
/// `diamonds`: (lane, row, x) of each, sorted.
pub(super) fn place(labels: &mut [Label], diamonds: &[(usize, usize, f64)]) {
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
