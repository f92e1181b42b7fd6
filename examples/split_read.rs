//! What reading a large SFC in two halves gains (docs/PERFORMANCE.md, "In-process"): reads one
//! SFC the way the compile does, in turn whole (the producer on a second thread) and in two
//! halves at once (`read/sfc/split.rs`), and checks that both give the same elements. Prints
//! each pair and the median difference.
//!
//! ```sh
//! cargo run --release --example generate -- --steps 100000 --out /tmp/g100
//! cargo run --release --example split_read -- /tmp/g100/sfc.xml
//! ```

use std::time::{Duration, Instant};

use skillpost::diag::Diagnostics;
use skillpost::read::sfc::read_sfc_file;

/// Reads `path` as the compile does, in two halves if `split`: its elements and the time it took.
fn read(path: &str, split: bool) -> (usize, Duration) {
    let t = Instant::now();
    let opened = skillpost::load::open_limited(std::path::Path::new(path), 1 << 40)
        .unwrap_or_else(|e| panic!("{path}: {e}"));
    let len = opened.len.unwrap_or(0);
    let input = std::io::BufReader::with_capacity(1 << 16, opened.reader);
    let at = opened.at.as_deref().filter(|_| split).map(|a| (a, 0));
    let mut diags = Diagnostics::default();
    let sfc = read_sfc_file(input, at, 1, len, None, &mut diags)
        .unwrap_or_else(|e| panic!("{path}: {e:?}"))
        .unwrap_or_else(|| panic!("{path}: no SFC read"));
    (sfc.elements.len(), t.elapsed())
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [path] = &args[..] else {
        eprintln!("usage: split_read SFC.xml");
        std::process::exit(2);
    };
    let pairs: usize = std::env::var("PAIRS")
        .ok()
        .and_then(|p| p.parse().ok())
        .unwrap_or(8);
    let mut diffs = Vec::new();
    for i in 0..pairs {
        // In turn which goes first.
        let ((n, whole), (m, halves)) = if i % 2 == 0 {
            let w = read(path, false);
            (w, read(path, true))
        } else {
            let h = read(path, true);
            (read(path, false), h)
        };
        assert_eq!(n, m, "the same elements either way");
        println!(
            "whole: {:.1} ms; two halves: {:.1} ms ({n} elements)",
            ms(whole),
            ms(halves),
        );
        diffs.push(ms(halves) - ms(whole));
    }
    diffs.sort_by(f64::total_cmp);
    println!(
        "two halves - whole, median of {pairs} pairs: {:+.1} ms",
        diffs[diffs.len() / 2]
    );
}
