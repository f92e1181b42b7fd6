//! Text and numbers as the picture writes them: widths from DejaVu Sans' advances, XML
//! escaping, seconds and pixels, the time axis' tick step.

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
pub(super) fn secs(x: f64) -> String {
    let s = format!("{x:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// A pixel coordinate: one decimal.
pub(super) fn px(x: f64) -> String {
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
