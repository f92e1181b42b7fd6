//! `skillpost simulate` (docs/SIMULATE.md): compile in memory, run the cell's programs on the
//! built-in interpreter, report. Exit status 0 no problem, 1 a problem, 2 inputs with errors
//! (or a file that cannot be read or written).

use std::io::Write as _;
use std::path::{Path, PathBuf};

use crate::compile::{self, Options};
use crate::diag::Format;
use crate::load::FsSource;
use crate::simulate::{self, Cell, Scenario, report};

#[derive(Debug, clap::Args)]
pub(super) struct SimulateArgs {
    /// The blackboard (.aml)
    #[arg(value_name = "BLACKBOARD")]
    blackboard: PathBuf,
    /// The program name, as for a compile (nothing is written)
    #[arg(value_name = "PROGRAM")]
    program: String,
    /// A scenario file (TOML): inputs at the start, their changes, restarts, jitter, runs
    #[arg(long, value_name = "FILE")]
    scenario: Option<PathBuf>,
    /// How many runs (default: the scenario's `runs`, else 20 random runs)
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    runs: Option<u64>,
    /// The seed of the random numbers (the same seed gives the same runs)
    #[arg(long, value_name = "S")]
    seed: Option<u64>,
    /// Write the first run's signals and wires as a Value Change Dump (GTKWave, Surfer)
    #[arg(long, value_name = "FILE")]
    vcd: Option<PathBuf>,
    /// Draw the first run as an SVG timeline, measured: a lane per controller, each step when
    /// it ran, the restarts and problems, the cycle time
    #[arg(long, value_name = "FILE")]
    svg: Option<PathBuf>,
    /// The report: text (stdout), or one JSON document (stdout)
    #[arg(long, value_enum, default_value_t = SimFormat::Human)]
    format: SimFormat,
    /// The SFC POU to use (as for a compile)
    #[arg(long, value_name = "NAME")]
    pou: Option<String>,
    /// Split long programs into parts as a compile with this option would (N, or LANG=N;
    /// repeatable): the parts are run as the main program calls them
    #[arg(long, value_name = "N|LANG=N", action = clap::ArgAction::Append)]
    max_lines: Vec<String>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(super) enum SimFormat {
    Human,
    Json,
}

/// Whether `path` names a file the compile read (an output must never replace an input).
fn is_input(c: &compile::Compilation, path: &Path) -> bool {
    let canon = |p: &Path| std::fs::canonicalize(p).ok();
    let target = canon(path);
    c.files_read
        .iter()
        .any(|f| f == path || (target.is_some() && canon(f) == target))
}

pub(super) fn simulate_command(a: &SimulateArgs) -> u8 {
    let fs = FsSource {
        max_file_size: crate::load::DEFAULT_MAX_FILE_SIZE,
    };
    let mut max_lines = crate::emit::split::Limits::default();
    for m in &a.max_lines {
        if let Err(why) = max_lines.set(m) {
            eprintln!("error: --max-lines {m}: {why}");
            return 2;
        }
    }
    // The programs as a compile writes them, split into parts where it splits them.
    let opts = Options {
        program: Some(a.program.clone()),
        keep_model: true,
        drop_warnings: true,
        pou: a.pou.clone(),
        max_lines,
        ..Options::default()
    };
    let c = compile::compile(&fs, &a.blackboard, &opts);
    if c.has_errors() || c.io_failure {
        super::report(&c.diagnostics, &c.sources, Format::Human, false);
        eprintln!("error: nothing simulated: the inputs have errors");
        return 2;
    }
    let (cell, programs) = match Cell::from_compilation(&c) {
        Ok(x) => x,
        Err(e) => {
            eprintln!("error: nothing simulated: {}", e.0);
            return 2;
        }
    };
    let scenario = match &a.scenario {
        Some(f) => match simulate::scenario::load(f, &cell) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("error: {e}");
                return 2;
            }
        },
        None => Scenario::random(),
    };
    let mut r = simulate::simulate(
        cell,
        &programs,
        scenario,
        a.runs.map(|n| n as usize),
        a.seed,
    );
    r.scenario = a.scenario.as_ref().map(|s| s.display().to_string());
    let files = [
        (
            "--vcd",
            a.vcd.as_ref(),
            report::vcd as fn(&simulate::Report) -> String,
        ),
        ("--svg", a.svg.as_ref(), report::svg),
    ];
    for (option, path, render) in files {
        let Some(v) = path else { continue };
        if is_input(&c, v) {
            eprintln!(
                "error: {option} {}: that is an input of the compile; nothing written",
                v.display()
            );
            return 2;
        }
        if let Err(e) = compile::write_beside(&c, v, render(&r).as_bytes()) {
            eprintln!("error: cannot write {}: {e}", v.display());
            return 2;
        }
    }
    let text = match a.format {
        SimFormat::Human => report::human(&r),
        SimFormat::Json => {
            let mut s = report::json(&r).to_string();
            s.push('\n');
            s
        }
    };
    let mut out = std::io::stdout().lock();
    let _ = out.write_all(text.as_bytes());
    let _ = out.flush();
    u8::from(r.problems() > 0)
}
