//! The simulator's speed (`harness = false`): random runs of a generated two-controller cell.
//!
//! ```text
//! cargo bench --bench simulate                        # 1,000 steps, 1,000 runs
//! SKILLPOST_BENCH_STEPS=100000 SKILLPOST_BENCH_RUNS=1 cargo bench --bench simulate
//! ```
//!
//! The chart (`benches/common/generator.rs`: simultaneous branches every 25 steps, a selection
//! every 10) is spread over two robots wired to each other (`benches/common/cell.rs`), runs of
//! 1 to 20 steps each, so the programs hand over hundreds of times. The table gives the time of
//! the runs (the compile and the reading of the programs apart), runs per second and
//! interpreted statements per second, and, as the floor, a bare loop over the same
//! instructions that only counts them.

use std::time::Instant;

use skillpost::compile::{self, Options};
use skillpost::load::FsSource;
use skillpost::simulate::{self, Cell, Scenario};

#[path = "common/cell.rs"]
mod cell;
#[path = "common/cell_project.rs"]
mod cell_project;
#[path = "common/generator.rs"]
mod generator;

fn env(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let steps = env("SKILLPOST_BENCH_STEPS", 1000);
    let runs = env("SKILLPOST_BENCH_RUNS", 1000);
    let spec = generator::Spec {
        steps,
        branch_every: 25,
        branch_width: 2,
        select_every: 10,
        looped: false,
    };
    let tmp = tempfile::tempdir().unwrap();
    let one = tmp.path().join("one");
    let project = generator::write_project(&one, &spec).unwrap();
    let two = match std::env::var_os("SKILLPOST_BENCH_KEEP") {
        Some(d) => std::path::PathBuf::from(d),
        None => tmp.path().join("two"),
    };
    cell_project::write(&project, &two, 2).unwrap();

    let opts = Options {
        program: Some("P".into()),
        keep_model: true,
        drop_warnings: true,
        max_lines: skillpost::emit::split::Limits::all(0),
        ..Options::default()
    };
    let c = compile::compile(
        &FsSource::default(),
        &two.join(generator::BLACKBOARD_FILE),
        &opts,
    );
    assert!(!c.has_errors(), "{:?}", c.diagnostics);
    let t = Instant::now();
    let (cell, programs) = Cell::from_compilation(&c).unwrap();
    let read = t.elapsed();
    let t = Instant::now();
    let report = simulate::simulate(cell, &programs, Scenario::random(), Some(runs), Some(1));
    let took = t.elapsed();
    let statements: u64 = report.runs.iter().map(|r| r.1.statements).sum();
    let problems = report.problems();
    assert_eq!(problems, 0, "{}", simulate::report::human(&report));
    // The floor: a loop that visits as many instructions and only counts them.
    let ins: Vec<usize> = programs.iter().map(|p| p.ins.len()).collect();
    let t = Instant::now();
    let mut n = 0u64;
    let mut k = 0usize;
    while n < statements {
        let p = k % programs.len();
        for i in &programs[p].ins {
            n += 1 + u64::from(matches!(i.0, simulate::ir::Ins::End));
        }
        k += 1;
        std::hint::black_box(&ins);
    }
    let floor = t.elapsed();
    println!(
        "| chart | runs | read programs | runs took | runs/s | statements | statements/s | bare loop |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    println!(
        "| {steps} steps, 2 controllers | {runs} | {:.1} ms | {:.2} s | {:.0} | {statements} | {:.1} M | {:.1} ms |",
        read.as_secs_f64() * 1e3,
        took.as_secs_f64(),
        runs as f64 / took.as_secs_f64(),
        statements as f64 / took.as_secs_f64() / 1e6,
        floor.as_secs_f64() * 1e3,
    );
}
