//! The unit tests of the picture: the axis' ticks, escaping and numbers, text widths, where
//! labels go.

use super::labels::place;
use super::text::{px, secs};
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
