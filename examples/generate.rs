//! Generates a large project in the original tool's format, for benchmarks and load tests:
//!
//! ```text
//! cargo run --release --example generate -- --steps 100000 --out /tmp/p100k
//! cargo run --release --example generate -- --steps 100000 --branch-every 50 --branch-width 3 --out /tmp/p100k-b
//! cargo run --release --example generate -- --steps 100000 --select-every 50 --looped --out /tmp/p100k-flow
//! cargo run --release --example generate -- --shape vars --steps 100000 --out /tmp/v100k
//! ./target/release/skillpost /tmp/p100k/Blackboard.aml out
//! ```
//!
//! Writes `Blackboard.aml`, `sfc.xml` and `kr15-2.irl` into `--out`; the same arguments give the
//! same bytes. The generator itself is `benches/common/generator.rs` (shared with the bench).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

#[path = "../benches/common/generator.rs"]
mod generator;

/// Generate a skillpost project of N alternating PTP/LIN steps
#[derive(Debug, Parser)]
#[command(name = "generate")]
struct Args {
    /// Skill steps (Start and End not counted)
    #[arg(long)]
    steps: usize,
    /// Every K main-line steps, a simultaneous branch (with one nested branch level); 0 = none
    #[arg(long, value_name = "K", default_value_t = 0)]
    branch_every: usize,
    /// Branches per simultaneous divergence
    #[arg(long, value_name = "W", default_value_t = 3, value_parser = clap::value_parser!(u32).range(2..))]
    branch_width: u32,
    /// Every K main-line steps a two-way selection (`Part_OK` / `TRUE`); 0 = none
    #[arg(long, value_name = "K", default_value_t = 0)]
    select_every: usize,
    /// Make the main line a loop closed by a jump back (left when `Magazine_Empty`)
    #[arg(long)]
    looped: bool,
    /// Grow one dimension instead (issue 13): `--steps` is then its size N; one of steps, vars,
    /// skills, resources, functions, irl, signals, cond, width, depth, loops
    #[arg(long, value_name = "DIM")]
    shape: Option<String>,
    /// Output folder (created if needed; existing files are overwritten)
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let spec = generator::Spec {
        steps: args.steps,
        branch_every: args.branch_every,
        branch_width: args.branch_width as usize,
        select_every: args.select_every,
        looped: args.looped,
    };
    let t = std::time::Instant::now();
    let written = match &args.shape {
        Some(dim) => match generator::write_shape(&args.out, dim, args.steps) {
            Some(r) => r,
            None => {
                let dims: Vec<&str> = generator::DIMENSIONS.iter().map(|d| d.0).collect();
                eprintln!(
                    "generate: unknown shape `{dim}`; one of {}",
                    dims.join(", ")
                );
                return ExitCode::from(2);
            }
        },
        None => generator::write_project(&args.out, &spec),
    };
    match written {
        Ok(p) => {
            let s = p.stats;
            println!(
                "{}: {} skill steps, {} SFC elements, {} simultaneous branches, SFC {} bytes ({:.1} MB, {:.0} bytes/step) in {:.2} s",
                p.blackboard.display(),
                s.skill_steps,
                s.elements,
                s.branches,
                s.sfc_bytes,
                s.sfc_bytes as f64 / 1e6,
                s.sfc_bytes as f64 / s.skill_steps.max(1) as f64,
                t.elapsed().as_secs_f64()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("generate: {}: {e}", args.out.display());
            ExitCode::from(2)
        }
    }
}
