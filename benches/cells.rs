//! Cells (docs/CELLS.md): the cost of splitting a chart over several controllers (`harness = false`).
//!
//! ```text
//! cargo bench --bench cells                         # 10,000 steps, 1 and 4 controllers
//! SKILLPOST_BENCH_ITERS=21 cargo bench --bench cells
//! SKILLPOST_BENCH_KEEP=/tmp/cells cargo bench --bench cells   # keep the projects (`one`, `four`)
//! ```
//!
//! The kept projects compile with the CLI (`skillpost Blackboard.aml out` in each folder), so
//! the two can be compared by instruction counts (`valgrind --tool=callgrind`), which the
//! machine's load does not move.
//!
//! The same generated chart (`benches/common/generator.rs`: 10,000 skill steps with simultaneous
//! branches, selections and a loop around the whole) is compiled on one controller and on four
//! (`benches/common/cell.rs`: four robots wired to each other; each step on the robot of its
//! run, runs of 1 to 20 steps taken at random with a fixed seed, so the programs hand over
//! thousands of times). Compiles of the two alternate; the table gives the medians, then two
//! ratios: of the medians, and the median of each round's (one compile of each, back to back,
//! so the machine's drift during the run cancels). Issue 40 wants the cell at most 1.15 times
//! one controller: the split and the handshakes linear, no program made from the whole chart.

use std::path::Path;
use std::time::{Duration, Instant};

use skillpost::compile::{self, Options};
use skillpost::load::FsSource;

#[path = "common/cell.rs"]
mod cell;
#[path = "common/cell_project.rs"]
mod cell_project;
#[path = "common/generator.rs"]
mod generator;

const STEPS: usize = 10_000;
const CONTROLLERS: usize = 4;

fn compile_once(bb: &Path) -> (Duration, skillpost::compile::Compilation) {
    let opts = Options {
        program: Some("P".into()),
        drop_warnings: true,
        ..Options::default()
    };
    let t = Instant::now();
    let c = compile::compile(&FsSource::default(), bb, &opts);
    (t.elapsed(), c)
}

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

fn main() {
    let iters: usize = std::env::var("SKILLPOST_BENCH_ITERS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(11);
    let spec = generator::Spec {
        steps: STEPS,
        branch_every: 25,
        branch_width: 2,
        select_every: 10,
        looped: true,
    };
    let tmp = tempfile::tempdir().unwrap();
    let root = match std::env::var_os("SKILLPOST_BENCH_KEEP") {
        Some(d) => std::path::PathBuf::from(d),
        None => tmp.path().to_path_buf(),
    };
    let one = root.join("one");
    let project = generator::write_project(&one, &spec).unwrap();
    let four = root.join("four");
    cell_project::write(&project, &four, CONTROLLERS).unwrap();

    let (a, b) = (
        one.join(generator::BLACKBOARD_FILE),
        four.join(generator::BLACKBOARD_FILE),
    );
    // Warm up, and check that both compile.
    let (_, c1) = compile_once(&a);
    let (_, c4) = compile_once(&b);
    for (what, c) in [("one controller", &c1), ("four controllers", &c4)] {
        assert!(!c.has_errors(), "{what}: {:?}", c.diagnostics);
    }
    let cell = c4.cell.as_ref().expect("a cell of four programs");
    let mut handshakes = 0;
    for p in &cell.programs {
        skillpost::plan::visit(&p.body, &mut |b| {
            if matches!(b, skillpost::plan::Block::Tell(_)) {
                handshakes += 1;
            }
        });
    }
    let bytes = |c: &skillpost::compile::Compilation| -> usize {
        c.outputs.iter().map(|(_, f)| f.text.len()).sum()
    };
    let (mut t1, mut t4) = (Vec::new(), Vec::new());
    // `SKILLPOST_BENCH_ONLY=1` or `=4`: compile only that one (for a profiler).
    let only = std::env::var("SKILLPOST_BENCH_ONLY").ok();
    for _ in 0..iters {
        if only.as_deref() != Some("4") {
            t1.push(compile_once(&a).0);
        }
        if only.as_deref() != Some("1") {
            t4.push(compile_once(&b).0);
        }
    }
    if only.is_some() {
        return;
    }
    // Each round's four ÷ one, run back to back: the machine's speed drifts less within a
    // round than over the run.
    let mut per_round: Vec<f64> = t1
        .iter()
        .zip(&t4)
        .map(|(a, b)| b.as_secs_f64() / a.as_secs_f64())
        .collect();
    per_round.sort_by(f64::total_cmp);
    let round_median = per_round[per_round.len() / 2];
    let (m1, m4) = (median(t1), median(t4));
    println!("| chart | controllers | programs | messages told | output | median compile |");
    println!("|---|---|---|---|---|---|");
    println!(
        "| {STEPS} steps | 1 | 1 | 0 | {:.1} MB | {:.0} ms |",
        bytes(&c1) as f64 / 1e6,
        m1.as_secs_f64() * 1e3
    );
    println!(
        "| {STEPS} steps | {CONTROLLERS} | {} | {handshakes} | {:.1} MB | {:.0} ms |",
        cell.programs.len(),
        bytes(&c4) as f64 / 1e6,
        m4.as_secs_f64() * 1e3
    );
    println!(
        "\nratio four / one: {:.2} (medians of {iters} compiles each, alternating); per round: {round_median:.2} (median of {iters} rounds' four / one)",
        m4.as_secs_f64() / m1.as_secs_f64()
    );
    // `SKILLPOST_BENCH_STAGES=1`: each stage's median over as many compiles again.
    if std::env::var("SKILLPOST_BENCH_STAGES").is_ok() {
        for (what, bb) in [("one", &a), ("four", &b)] {
            let mut by_stage: Vec<(&'static str, Vec<Duration>)> = Vec::new();
            for _ in 0..iters {
                let (_, c) = compile_once(bb);
                for (k, (stage, d, _)) in c.timings.iter().enumerate() {
                    if by_stage.len() <= k {
                        by_stage.push((stage, Vec::new()));
                    }
                    by_stage[k].1.push(*d);
                }
            }
            let stages: Vec<String> = by_stage
                .into_iter()
                .map(|(s, d)| format!("{s} {:.1} ms", median(d).as_secs_f64() * 1e3))
                .collect();
            println!("{what}: {}", stages.join(", "));
        }
    }
}
