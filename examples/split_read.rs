//! What a reading split in two could gain (docs/PERFORMANCE.md, "In-process"): reads a whole SFC
//! the way the compile does (the producer on a second thread), and in turn two copies of a half
//! as large a SFC at once, each on one thread with its producer inline, as two readers of the two
//! halves of one chart would. Prints each pair and the median difference.
//!
//! ```sh
//! cargo run --release --example generate -- --steps 100000 --out /tmp/g100
//! cargo run --release --example generate -- --steps 50000 --out /tmp/g50
//! cargo run --release --example split_read -- /tmp/g100/sfc.xml /tmp/g50/sfc.xml
//! ```

use std::time::{Duration, Instant};

use skillpost::diag::Diagnostics;
use skillpost::read::sfc::read_sfc_stream_with;
use skillpost::read::tape::{BATCH_BYTES, Pipeline};

/// Reads `path` as `pipeline` says: its elements and the time it took.
fn read(path: &str, pipeline: Pipeline) -> (usize, Duration) {
    let t = Instant::now();
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let len = file.metadata().map(|m| m.len()).unwrap_or(0);
    let input = std::io::BufReader::with_capacity(1 << 16, file);
    let mut diags = Diagnostics::default();
    let sfc = read_sfc_stream_with(input, 1, len, None, &mut diags, pipeline, BATCH_BYTES)
        .unwrap_or_else(|e| panic!("{path}: {e:?}"))
        .unwrap_or_else(|| panic!("{path}: no SFC read"));
    (sfc.elements.len(), t.elapsed())
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [whole, half] = &args[..] else {
        eprintln!("usage: split_read WHOLE.xml HALF.xml");
        std::process::exit(2);
    };
    let pairs: usize = std::env::var("PAIRS")
        .ok()
        .and_then(|p| p.parse().ok())
        .unwrap_or(8);
    let mut diffs = Vec::new();
    for _ in 0..pairs {
        let (n, one) = read(whole, Pipeline::Threaded);
        let t = Instant::now();
        let (a, b) = std::thread::scope(|s| {
            let other = s.spawn(|| read(half, Pipeline::Inline));
            let mine = read(half, Pipeline::Inline);
            (other.join().expect("the other half"), mine)
        });
        let two = t.elapsed();
        println!(
            "whole, threaded: {:.1} ms ({n} elements); two halves at once: {:.1} ms ({} elements)",
            ms(one),
            ms(two),
            a.0 + b.0
        );
        diffs.push(ms(two) - ms(one));
    }
    diffs.sort_by(f64::total_cmp);
    println!(
        "two halves - whole, median of {pairs} pairs: {:+.1} ms",
        diffs[diffs.len() / 2]
    );
}
