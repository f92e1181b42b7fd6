//! Compile-time benchmark on generated projects (`harness = false`; no bench framework).
//!
//! ```text
//! cargo bench --bench compile               # every case
//! cargo bench --bench compile -- 100k       # cases whose label contains `100k`
//! cargo bench --bench compile -- =100k      # the case labelled `100k` only
//! SKILLPOST_BENCH_ITERS=40 cargo bench --bench compile -- =100k   # 40 runs instead of 5
//! ```
//!
//! On a shared machine the quick-xml ratio is judged by `best ÷ quick-xml` (the fastest compile
//! over the fastest floor): the floor uses one CPU, the compile two, so a pair is slow whenever
//! either CPU is slowed by something else (docs/PERFORMANCE.md, issue 13).
//!
//! For each case it generates a project (`benches/common/generator.rs`) into a temporary folder,
//! warms up once, then runs several iterations, alternating:
//! - **floor**: a bare `roxmltree::Document::parse` of the SFC text already in memory (what a
//!   DOM-based reader costs at least), and a bare `quick-xml` pass over it (every event, every
//!   start tag's attributes split, nothing unescaped or kept: what a streaming reader costs at
//!   least);
//! - **compile**: `compile::compile` from the blackboard path (reads every file), then
//!   **write**: `compile::apply` into a fresh project folder (outputs + write-back);
//! - **stages**: the same pipeline called stage by stage through the public functions, to see
//!   where the time goes (its outputs are checked against `compile`'s).
//!
//! Peak memory: the bench runs itself once more per case as a child process (Linux: `VmHWM` from
//! `/proc/self/status`) for the floor (read the SFC + parse) and for compile + apply; the release
//! binary's own figure comes from `bench/run.sh` (`/usr/bin/time -v`).
//!
//! It prints markdown tables of medians.
//!
//! **Shapes** (issue 13, label `100k-shapes`; `cargo bench --bench compile -- shapes` runs only
//! this): the same 100,000 skill steps straight, with parallel branches, with selections and as a
//! loop closed by a jumpStep, each compiled in turns for several rounds; it prints the time per
//! step and the ratio to the straight project, by wall time and by the thread's on-CPU time.

use std::collections::HashMap;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use skillpost::bind;
use skillpost::compile::{self, Options};
use skillpost::diag::{Diagnostics, Sources};
use skillpost::emit::{EmitInput, Language, LanguageProfile as _, OutputFile, OutputTemplate};
use skillpost::load::FsSource;
use skillpost::plan;
use skillpost::read::irl::Irl;
use skillpost::read::{blackboard::read_blackboard, irl::read_irl, sfc::read_sfc, xml};

#[path = "common/floor.rs"]
mod floor;
#[path = "common/generator.rs"]
mod generator;

use generator::Spec;

struct Case {
    label: &'static str,
    spec: Spec,
    iters: usize,
    /// A shape of `generator::write_shape` instead (issue 13), `spec.steps` its size; only
    /// shapes that leave the blackboard as it is (the write pass regenerates it).
    shape: Option<&'static str>,
}

const CASES: &[Case] = &[
    Case {
        label: "1k",
        spec: Spec {
            steps: 1_000,
            branch_every: 0,
            branch_width: 0,
            select_every: 0,
            looped: false,
        },
        iters: 30,
        shape: None,
    },
    Case {
        label: "10k",
        spec: Spec {
            steps: 10_000,
            branch_every: 0,
            branch_width: 0,
            select_every: 0,
            looped: false,
        },
        iters: 15,
        shape: None,
    },
    Case {
        label: "100k",
        spec: Spec {
            steps: 100_000,
            branch_every: 0,
            branch_width: 0,
            select_every: 0,
            looped: false,
        },
        iters: 5,
        shape: None,
    },
    Case {
        label: "100k-branched",
        spec: Spec {
            steps: 100_000,
            branch_every: 50,
            branch_width: 3,
            select_every: 0,
            looped: false,
        },
        iters: 5,
        shape: None,
    },
    // Issue 13: 100,000 extra variables in one step (of 16): goal under 0.3 s.
    Case {
        label: "100k-vars-one-step",
        spec: Spec {
            steps: 100_000,
            branch_every: 0,
            branch_width: 0,
            select_every: 0,
            looped: false,
        },
        iters: 5,
        shape: Some("vars"),
    },
    // Issue 4's shape: every 4 main-line steps a 4-way branch (with a nested one).
    Case {
        label: "100k-branched-4x4",
        spec: Spec {
            steps: 100_000,
            branch_every: 4,
            branch_width: 4,
            select_every: 0,
            looped: false,
        },
        iters: 5,
        shape: None,
    },
    // Issue 11's flow project: every 50 main-line steps a two-way selection, the whole line a
    // loop closed by a jumpStep.
    Case {
        label: "100k-looped",
        spec: Spec {
            steps: 100_000,
            branch_every: 0,
            branch_width: 0,
            select_every: 50,
            looped: true,
        },
        iters: 5,
        shape: None,
    },
];

/// Issue 13's side-by-side comparison (label `100k-shapes`): the same 100,000 skill steps
/// straight, branched and looping, compiled in turns (each round starts at another shape, so a
/// change in the machine's load falls on all of them). The first is the reference.
const SHAPES_LABEL: &str = "100k-shapes";
const SHAPES_ROUNDS: usize = 7;
const SHAPES: &[(&str, Spec)] = &[
    (
        "straight",
        Spec {
            steps: 100_000,
            branch_every: 0,
            branch_width: 0,
            select_every: 0,
            looped: false,
        },
    ),
    (
        "parallel every 50 (3-way, one nested)",
        Spec {
            steps: 100_000,
            branch_every: 50,
            branch_width: 3,
            select_every: 0,
            looped: false,
        },
    ),
    (
        "parallel every 4 (4-way, one nested)",
        Spec {
            steps: 100_000,
            branch_every: 4,
            branch_width: 4,
            select_every: 0,
            looped: false,
        },
    ),
    (
        "selection every 50 (2-way)",
        Spec {
            steps: 100_000,
            branch_every: 0,
            branch_width: 0,
            select_every: 50,
            looped: false,
        },
    ),
    (
        "selection every 10 (2-way)",
        Spec {
            steps: 100_000,
            branch_every: 0,
            branch_width: 0,
            select_every: 10,
            looped: false,
        },
    ),
    (
        "loop (jumpStep) + selection every 50",
        Spec {
            steps: 100_000,
            branch_every: 0,
            branch_width: 0,
            select_every: 50,
            looped: true,
        },
    ),
];

/// Stage names, in pipeline order.
const STAGES: &[&str] = &[
    "blackboard",
    "load sfc",
    "read_sfc",
    "plan",
    "bind",
    "emit",
    "sort diags",
    "drop",
];

/// Set in a child process: `floor` or `compile`, with the file as the argument.
const CHILD_ENV: &str = "SKILLPOST_BENCH_CHILD";

#[derive(Default)]
struct Samples {
    floor: Vec<Duration>,
    stream_floor: Vec<Duration>,
    tokenize: Vec<Duration>,
    compile: Vec<Duration>,
    write: Vec<Duration>,
    stages: Vec<Vec<Duration>>,
    /// `compile::compile`'s own clock (`Compilation::timings`) per stage, and the rest of it.
    own: Vec<Vec<Duration>>,
    diagnostics: usize,
}

struct Row {
    label: &'static str,
    stats: generator::Stats,
    iters: usize,
    floor: Duration,
    stream_floor: Duration,
    /// compile / quick-xml floor, the median of the ratios of each iteration (measured back to
    /// back, so a slower stretch of a shared machine weighs on both).
    stream_ratio: f64,
    /// The fastest compile / the fastest quick-xml floor: what each costs with the least
    /// interference from the machine's other load (on a shared 2-core VM the two-threaded
    /// compile loses more to a busy neighbour than the one-threaded floor does).
    best_ratio: f64,
    tokenize: Duration,
    compile: Duration,
    write: Duration,
    stages: Vec<Duration>,
    own: Vec<Duration>,
    floor_peak: Option<Peak>,
    compile_peak: Option<Peak>,
    diagnostics: usize,
}

/// What a child process reports.
#[derive(Debug, Clone, Copy, Default)]
struct Peak {
    /// Peak resident set size, kB.
    rss_kb: u64,
    /// The SFC's roxmltree nodes and attributes (floor only).
    nodes: u64,
    attributes: u64,
}

fn main() {
    if let Ok(mode) = std::env::var(CHILD_ENV) {
        let path = std::env::args_os().nth(1).expect("child: a file argument");
        child(&mode, Path::new(&path));
        return;
    }
    // `cargo bench` passes `--bench`; any other argument filters the cases by label (`=LABEL`:
    // that label only).
    let filters: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let tmp = tempfile::Builder::new()
        .prefix("skillpost-bench-")
        .tempdir()
        .expect("temporary folder");
    let mut rows = Vec::new();
    for case in CASES {
        let matches = |f: &String| match f.strip_prefix('=') {
            Some(exact) => case.label == exact,
            None => case.label.contains(f.as_str()),
        };
        if !filters.is_empty() && !filters.iter().any(matches) {
            continue;
        }
        rows.push(run_case(case, tmp.path()));
    }
    if !rows.is_empty() {
        print_tables(&rows);
    }
    if filters.is_empty()
        || filters
            .iter()
            .any(|f| !f.starts_with('=') && SHAPES_LABEL.contains(f.as_str()))
    {
        print_shapes(&run_shapes(tmp.path()));
    }
}

/// One shape's samples: per round, wall time, the process's CPU time and the calling thread's run-queue wait of the compile.
struct ShapeRow {
    label: &'static str,
    stats: generator::Stats,
    wall: Vec<Duration>,
    cpu: Vec<Duration>,
    waited: Vec<Duration>,
}

fn run_shapes(tmp: &Path) -> Vec<ShapeRow> {
    let mut rows: Vec<(ShapeRow, PathBuf)> = SHAPES
        .iter()
        .enumerate()
        .map(|(k, (label, spec))| {
            let dir = tmp.join(format!("shape-{k}"));
            let t = Instant::now();
            let p = generator::write_project(&dir, spec).expect("generate the project");
            eprintln!(
                "{SHAPES_LABEL}: {label}: generated {} steps, {} elements, {:.1} MB in {:.2} s",
                p.stats.skill_steps,
                p.stats.elements,
                p.stats.sfc_bytes as f64 / 1e6,
                t.elapsed().as_secs_f64()
            );
            let row = ShapeRow {
                label,
                stats: p.stats,
                wall: Vec::new(),
                cpu: Vec::new(),
                waited: Vec::new(),
            };
            (row, p.blackboard)
        })
        .collect();
    let n = rows.len();
    // Round 0 warms up (page cache, allocator) and is not counted.
    for round in 0..=SHAPES_ROUNDS {
        for k in 0..n {
            let (row, bb) = &mut rows[(round + k) % n];
            let sched = run_queue_wait();
            let process = process_cpu();
            let t = Instant::now();
            let c = compile::compile(&FsSource::default(), bb, &options());
            let wall = t.elapsed();
            let sched_after = run_queue_wait();
            let process_after = process_cpu();
            assert!(
                !c.has_errors(),
                "{}: the generated project has errors",
                row.label
            );
            assert!(
                c.outputs.iter().any(|(_, f)| f.extension == "src"),
                "{}: no .src output",
                row.label
            );
            drop(c);
            // A large model is freed on a thread of its own (`compile::free_aside`, ~40 ms for
            // 100k steps): let it finish before the next compile is measured.
            std::thread::sleep(Duration::from_millis(200));
            if round > 0 {
                row.wall.push(wall);
                if let (Some(p0), Some(p1)) = (process, process_after) {
                    row.cpu.push(p1.saturating_sub(p0));
                }
                if let (Some(w0), Some(w1)) = (sched, sched_after) {
                    row.waited.push(w1.saturating_sub(w0));
                }
            }
        }
        eprintln!("{SHAPES_LABEL}: round {round} of {SHAPES_ROUNDS} done");
    }
    for (k, _) in SHAPES.iter().enumerate() {
        let _ = std::fs::remove_dir_all(tmp.join(format!("shape-{k}")));
    }
    rows.into_iter().map(|(r, _)| r).collect()
}

/// This thread's time waiting for a CPU (the second field of `/proc/thread-self/schedstat`, ns;
/// Linux).
fn run_queue_wait() -> Option<Duration> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let waited = text.split_whitespace().nth(1)?.parse().ok()?;
    Some(Duration::from_nanos(waited))
}

/// This process's CPU time, every thread's (also of threads that ended): `utime + stime` of
/// `/proc/self/stat`, in clock ticks of 10 ms (`USER_HZ` = 100; Linux).
fn process_cpu() -> Option<Duration> {
    let text = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The fields after the command name, which is in parentheses and may hold spaces: the
    // third field of the line is the first here, so `utime` (14th) is the 12th.
    let rest = &text[text.rfind(')')? + 1..];
    let mut f = rest.split_whitespace().skip(11);
    let utime: u64 = f.next()?.parse().ok()?;
    let stime: u64 = f.next()?.parse().ok()?;
    Some(Duration::from_millis((utime + stime) * 10))
}

/// The median of the per-round ratios `a[i] / b[i]` (paired: the same round, so the same load).
fn paired_ratio(a: &[Duration], b: &[Duration]) -> f64 {
    let mut r: Vec<f64> = a
        .iter()
        .zip(b)
        .map(|(x, y)| x.as_secs_f64() / y.as_secs_f64())
        .collect();
    r.sort_by(f64::total_cmp);
    match r.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => r[n / 2],
        n => (r[n / 2 - 1] + r[n / 2]) / 2.0,
    }
}

fn print_shapes(rows: &[ShapeRow]) {
    let Some(base) = rows.first() else { return };
    println!();
    println!(
        "Shapes ({SHAPES_LABEL}): compile::compile of each project, {SHAPES_ROUNDS} rounds in turns;"
    );
    println!(
        "medians. Per step = time / skill steps. Ratio = median of the per-round ratios to `{}`",
        base.label
    );
    println!("(goal: within 10 %). CPU = the process's CPU time over the compile, every thread's");
    println!("(/proc/self/stat, 10 ms ticks: the SFC is read and the steps bound on two threads);");
    println!("waited = the calling thread's time runnable but waiting for a CPU (other processes,");
    println!(
        "/proc/thread-self/schedstat). Per element = the CPU ratio per SFC element instead of"
    );
    println!("per skill step.");
    println!();
    println!(
        "| shape | skill steps | SFC elements | SFC MB | wall ms | wall µs/step | wall ratio | CPU ms | CPU µs/step | CPU ratio | CPU ratio per element | waited ms | within 10 % per step |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    let mut spread: Vec<f64> = Vec::new();
    for r in rows {
        let steps = r.stats.skill_steps.max(1) as f64;
        let wall = median(&mut r.wall.clone());
        let cpu = median(&mut r.cpu.clone());
        let waited = median(&mut r.waited.clone());
        let wall_ratio = paired_ratio(&r.wall, &base.wall);
        let cpu_ratio = paired_ratio(&r.cpu, &base.cpu);
        // The per-step figures: every shape has the same skill steps, but compare per step anyway.
        let per = |d: Duration| d.as_secs_f64() * 1e6 / steps;
        let base_steps = base.stats.skill_steps.max(1) as f64;
        let scale = base_steps / steps;
        // Judged by CPU time where there is one (the wall time carries the other processes).
        let judged = if r.cpu.is_empty() {
            wall_ratio
        } else {
            cpu_ratio
        };
        let verdict = if (judged * scale - 1.0).abs() <= 0.10 {
            "yes"
        } else {
            "**no**"
        };
        println!(
            "| {} | {} | {} | {:.1} | {} | {:.2} | {:.3} | {} | {:.2} | {:.3} | {:.3} | {} | {} |",
            r.label,
            r.stats.skill_steps,
            r.stats.elements,
            r.stats.sfc_bytes as f64 / 1e6,
            ms(wall),
            per(wall),
            wall_ratio * scale,
            ms(cpu),
            per(cpu),
            cpu_ratio * scale,
            cpu_ratio * base.stats.elements as f64 / r.stats.elements.max(1) as f64,
            ms(waited),
            verdict,
        );
        spread.push(judged * scale);
    }
    let (lo, hi) = spread
        .iter()
        .fold((f64::INFINITY, 0f64), |(lo, hi), &x| (lo.min(x), hi.max(x)));
    println!();
    println!(
        "Spread per step (slowest / fastest shape, by {}): {:.3}.",
        if base.cpu.is_empty() { "wall" } else { "CPU" },
        hi / lo
    );
}

fn run_case(case: &Case, tmp: &Path) -> Row {
    // `SKILLPOST_BENCH_ITERS=N`: N runs per case instead of its own count (more runs on a noisy
    // machine).
    let iters = std::env::var("SKILLPOST_BENCH_ITERS")
        .ok()
        .and_then(|n| n.parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or(case.iters);
    let dir = tmp.join(case.label);
    let t = Instant::now();
    let project = match case.shape {
        Some(dim) => generator::write_shape(&dir, dim, case.spec.steps)
            .expect("a known shape")
            .expect("generate the project"),
        None => generator::write_project(&dir, &case.spec).expect("generate the project"),
    };
    eprintln!(
        "{}: generated {} steps, {:.1} MB in {:.2} s; {} iterations",
        case.label,
        project.stats.skill_steps,
        project.stats.sfc_bytes as f64 / 1e6,
        t.elapsed().as_secs_f64(),
        iters
    );
    let text = std::fs::read_to_string(&project.sfc).expect("read the SFC");
    let mut s = Samples {
        stages: vec![Vec::new(); STAGES.len()],
        own: vec![Vec::new(); OWN_STAGES.len() + 1],
        ..Default::default()
    };
    // Iteration 0 warms up (page cache, allocator) and checks the staged pipeline against
    // `compile`; it is not counted.
    for i in 0..=iters {
        let floor = floor(&text);
        let stream_floor = stream_floor(&text);
        let tokenize = tokenize(&text);
        let run = dir.join(format!("run-{i}"));
        let bb = fresh_project(&run);
        let (compile, write, outputs, diagnostics, own) = compile_and_apply(&bb);
        s.diagnostics = diagnostics;
        let (stages, staged) = stages(&bb);
        if i == 0 {
            assert_eq!(
                outputs, staged,
                "the staged pipeline no longer matches compile::compile"
            );
            assert!(
                outputs.iter().any(|(e, t)| *e == "src" && t.len() > 100),
                "no .src output"
            );
        } else {
            s.floor.push(floor);
            s.stream_floor.push(stream_floor);
            s.tokenize.push(tokenize);
            s.compile.push(compile);
            // Each run's pair on stderr: on a shared machine the spread says how far to trust
            // the medians.
            eprintln!(
                "{} run {i}: quick-xml floor {:.1} ms, compile {:.1} ms ({:.2}x)",
                case.label,
                stream_floor.as_secs_f64() * 1e3,
                compile.as_secs_f64() * 1e3,
                compile.as_secs_f64() / stream_floor.as_secs_f64()
            );
            let mut rest = compile;
            for (k, stage) in OWN_STAGES.iter().enumerate() {
                let d = own
                    .iter()
                    .find(|(n, _)| n == stage)
                    .map_or(Duration::ZERO, |(_, d)| *d);
                rest = rest.saturating_sub(d);
                s.own[k].push(d);
            }
            s.own[OWN_STAGES.len()].push(rest);
            s.write.push(write);
            for (k, d) in stages.into_iter().enumerate() {
                s.stages[k].push(d);
            }
        }
        std::fs::remove_dir_all(&run).expect("remove the run folder");
    }
    drop(text);
    let floor_peak = peak("floor", &project.sfc);
    let run = dir.join("run-peak");
    let compile_peak = peak("compile", &fresh_project(&run));
    std::fs::remove_dir_all(&dir).expect("remove the project");
    Row {
        label: case.label,
        stats: project.stats,
        iters,
        floor: median(&mut s.floor),
        stream_ratio: paired_ratio(&s.compile, &s.stream_floor),
        best_ratio: fastest(&s.compile).as_secs_f64() / fastest(&s.stream_floor).as_secs_f64(),
        stream_floor: median(&mut s.stream_floor),
        tokenize: median(&mut s.tokenize),
        compile: median(&mut s.compile),
        write: median(&mut s.write),
        stages: s.stages.iter_mut().map(|v| median(v)).collect(),
        own: s.own.iter_mut().map(|v| median(v)).collect(),
        floor_peak,
        compile_peak,
        diagnostics: s.diagnostics,
    }
}

/// Runs this bench again as a child process in `mode` on `file`; `None` where `/proc` is missing.
fn peak(mode: &str, file: &Path) -> Option<Peak> {
    let exe = std::env::current_exe().ok()?;
    let out = std::process::Command::new(exe)
        .env(CHILD_ENV, mode)
        .arg(file)
        .output()
        .ok()?;
    assert!(
        out.status.success(),
        "child `{mode}` failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let mut f = text.split_whitespace().map(|w| w.parse::<u64>().ok());
    Some(Peak {
        rss_kb: f.next()??,
        nodes: f.next()??,
        attributes: f.next()??,
    })
}

/// The child process: one measured run, then `rss_kb nodes attributes` on stdout.
fn child(mode: &str, file: &Path) {
    let (nodes, attributes) = match mode {
        "floor" => {
            let text = std::fs::read_to_string(file).expect("read the SFC");
            let doc = roxmltree::Document::parse(&text).expect("parse the SFC");
            let nodes = doc.descendants().count() as u64;
            let attributes = doc.descendants().map(|n| n.attributes().len() as u64).sum();
            (nodes, attributes)
        }
        "compile" => {
            let c = compile::compile(&FsSource::default(), file, &options());
            assert!(!c.has_errors(), "the generated project has errors");
            compile::apply(&c).expect("write the outputs");
            (0, 0)
        }
        _ => panic!("unknown child mode `{mode}`"),
    };
    match vm_hwm_kb() {
        Some(kb) => println!("{kb} {nodes} {attributes}"),
        None => println!("-"),
    }
}

/// This process's peak resident set size (Linux).
fn vm_hwm_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// A project folder of its own (so every write is a real one) whose blackboard names the shared
/// SFC and IRL files one level up.
fn fresh_project(run: &Path) -> PathBuf {
    std::fs::create_dir_all(run).expect("create the run folder");
    let bb = run.join(generator::BLACKBOARD_FILE);
    let text = generator::blackboard_text(
        &format!("../{}", generator::SFC_FILE),
        &format!("../{}", generator::IRL_FILE),
    );
    std::fs::write(&bb, text).expect("write the blackboard");
    bb
}

fn floor(text: &str) -> Duration {
    let t = Instant::now();
    let doc = roxmltree::Document::parse(text).expect("the generated SFC is well-formed");
    black_box(&doc);
    drop(doc);
    t.elapsed()
}

fn stream_floor(text: &str) -> Duration {
    let t = Instant::now();
    floor::quick_xml_pass(text).expect("the generated SFC is well-formed");
    t.elapsed()
}

/// The SFC reader's first half alone (`read::tape`: tokenizing, UTF-8, the copy into batches),
/// in one thread, over the text in memory: what the second thread does while the reader builds
/// the model.
fn tokenize(text: &str) -> Duration {
    let t = Instant::now();
    let n = skillpost::read::tape::tokenize_only(
        text.as_bytes(),
        skillpost::read::tape::Pipeline::Inline,
    );
    black_box(n);
    t.elapsed()
}

fn options() -> Options {
    Options {
        program: Some("p".into()),
        ..Default::default()
    }
}

/// The stages `compile::compile` times itself (`Compilation::timings`), in order.
const OWN_STAGES: [&str; 5] = ["read-blackboard", "read-sfc", "plan", "bind", "emit"];

/// What [`compile_and_apply`] measured: compile, write, the outputs, the number of diagnostics
/// and the compile's own stage timings.
type Applied = (
    Duration,
    Duration,
    Vec<(&'static str, String)>,
    usize,
    Vec<(&'static str, Duration)>,
);

/// `compile` then `apply`, timed separately; returns the outputs for the cross-check, the
/// number of diagnostics (all warnings) and the compile's own stage timings.
fn compile_and_apply(bb: &Path) -> Applied {
    let t = Instant::now();
    let c = compile::compile(&FsSource::default(), bb, &options());
    let compile = t.elapsed();
    assert!(!c.has_errors(), "the generated project has errors");
    let t = Instant::now();
    let applied = compile::apply(&c).expect("write the outputs");
    let write = t.elapsed();
    assert!(
        applied.outputs.iter().all(|(_, w)| *w),
        "an output was not written"
    );
    let outputs = c
        .outputs
        .iter()
        .map(|(_, f)| (f.extension, f.text.clone()))
        .collect();
    (
        compile,
        write,
        outputs,
        c.diagnostics.len(),
        c.timings.iter().map(|(s, d, _)| (*s, *d)).collect(),
    )
}

/// The pipeline of `compile::compile`, stage by stage (the built-in template, no confinement).
fn stages(bb_path: &Path) -> (Vec<Duration>, Vec<(&'static str, String)>) {
    let fs = FsSource::default();
    let base = bb_path.parent().expect("the blackboard has a folder");
    let mut sources = Sources::default();
    let mut diags = Diagnostics::default();
    let mut times = Vec::with_capacity(STAGES.len());
    let mut lap = {
        let mut t = Instant::now();
        move |times: &mut Vec<Duration>| {
            let now = Instant::now();
            times.push(now - t);
            t = now;
        }
    };

    let bb_file = xml::load(
        &fs,
        bb_path,
        bb_path.display().to_string(),
        None,
        &mut sources,
        &mut diags,
    )
    .expect("load the blackboard");
    let bb = read_blackboard(&sources, bb_file, &mut diags).expect("read the blackboard");
    let template = OutputTemplate::builtin(Language::Krl);
    lap(&mut times);

    let sfc_ref = bb.sfc_ref.clone().expect("an SFC reference");
    let sfc_path = skillpost::paths::resolve_ref(base, &sfc_ref.value).expect("resolve the SFC");
    let sfc_file = xml::load(
        &fs,
        &sfc_path,
        sfc_path.display().to_string(),
        Some(sfc_ref.span.clone()),
        &mut sources,
        &mut diags,
    )
    .expect("load the SFC");
    lap(&mut times);

    let sfc = read_sfc(&sources, sfc_file, &mut diags).expect("read the SFC");
    lap(&mut times);

    let plan = plan::plan(&sfc, &mut diags).expect("plan");
    lap(&mut times);

    let order = bind::StepOrder::planned(&plan);
    let res = bind::resolve(&bb, &sfc, &order, &mut diags);
    let needed = bind::needed_functions(&bb, &res, &mut diags);
    let mut irls: Vec<Irl> = Vec::new();
    let mut fn_irl = HashMap::new();
    let mut by_file = HashMap::new();
    for (r, f) in needed {
        let func = &bb.resources[r].functions[f];
        let path =
            skillpost::paths::resolve_ref(base, &func.irl.value).expect("resolve an IRL file");
        let file = xml::load(
            &fs,
            &path,
            path.display().to_string(),
            Some(func.irl.span.clone()),
            &mut sources,
            &mut diags,
        )
        .expect("load an IRL file");
        let idx = *by_file.entry(file).or_insert_with(|| {
            read_irl(&sources, file, &mut diags).map(|irl| {
                irls.push(irl);
                irls.len() - 1
            })
        });
        if let Some(i) = idx {
            fn_irl.insert((r, f), i);
        }
    }
    let profile = Language::Krl.profile();
    let bound = bind::bind(
        &bb,
        &sfc,
        &order,
        &res,
        &bind::Calls {
            irls: &irls,
            fn_irl: &fn_irl,
        },
        profile,
        &mut diags,
        bind::PARALLEL_FROM,
    );
    lap(&mut times);

    let input = EmitInput {
        program: "p",
        blackboard: &bb,
        sfc: &sfc,
        body: &plan.body,
        bound: &bound,
        irls: &irls,
        newline: "\r\n",
        step_indent: &template.step_indent,
        steps_indent: template.steps_indent(),
        profile,
        cell: None,
        max_lines: skillpost::emit::split::Limits::default().of(Language::Krl),
        read_ahead_from: bind::PARALLEL_FROM,
    };
    let files: Vec<OutputFile> =
        skillpost::emit::emit_files(&input, &template, &mut diags).expect("emit");
    lap(&mut times);

    diags.sort();
    assert!(!diags.has_errors(), "the staged pipeline reported errors");
    lap(&mut times);

    let outputs = files
        .iter()
        .map(|f| (f.extension, f.text.clone()))
        .collect();
    drop((
        files, bound, irls, res, order, plan, sfc, bb, diags, sources,
    ));
    lap(&mut times);
    (times, outputs)
}

fn fastest(v: &[Duration]) -> Duration {
    v.iter().copied().min().unwrap_or(Duration::ZERO)
}

fn median(v: &mut [Duration]) -> Duration {
    v.sort();
    match v.len() {
        0 => Duration::ZERO,
        n if n % 2 == 1 => v[n / 2],
        n => (v[n / 2 - 1] + v[n / 2]) / 2,
    }
}

fn ms(d: Duration) -> String {
    let ms = d.as_secs_f64() * 1e3;
    if ms < 10.0 {
        format!("{ms:.2}")
    } else if ms < 100.0 {
        format!("{ms:.1}")
    } else {
        format!("{ms:.0}")
    }
}

fn print_tables(rows: &[Row]) {
    println!();
    println!(
        "Medians. roxmltree floor = bare roxmltree::Document::parse of the SFC text in memory;"
    );
    println!(
        "quick-xml floor = a bare quick-xml event pass over it; compile = compile::compile from"
    );
    println!(
        "the blackboard path (reads every file); ratio = compile / roxmltree floor; ÷ quick-xml ="
    );
    println!(
        "compile / quick-xml floor (median of the ratios of each iteration); tokenize = the SFC"
    );
    println!(
        "reader's producer alone (read::tape, one thread); write = compile::apply into a fresh folder;"
    );
    println!("best ÷ quick-xml = the fastest compile / the fastest quick-xml floor of the runs.");
    println!();
    println!(
        "| case | steps | SFC MB | runs | roxmltree floor ms | quick-xml floor ms | tokenize ms | compile ms | ratio | ÷ quick-xml | best ÷ quick-xml | write ms | compile + write ms | roxmltree floor peak MB | compile peak MB |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mb = |p: Option<Peak>| match p {
        Some(p) => format!("{:.0}", p.rss_kb as f64 / 1024.0),
        None => "n/a".to_owned(),
    };
    for r in rows {
        println!(
            "| {} | {} | {:.1} | {} | {} | {} | {} | {} | {:.2} | {:.2} | {:.2} | {} | {} | {} | {} |",
            r.label,
            r.stats.skill_steps,
            r.stats.sfc_bytes as f64 / 1e6,
            r.iters,
            ms(r.floor),
            ms(r.stream_floor),
            ms(r.tokenize),
            ms(r.compile),
            r.compile.as_secs_f64() / r.floor.as_secs_f64(),
            r.stream_ratio,
            r.best_ratio,
            ms(r.write),
            ms(r.compile + r.write),
            mb(r.floor_peak),
            mb(r.compile_peak),
        );
    }
    println!();
    println!("Peak MB = peak resident set size of a child process doing only that (MiB).");
    for r in rows {
        let dom = match r.floor_peak {
            Some(p) => format!("{} roxmltree nodes, {} attributes", p.nodes, p.attributes),
            None => "DOM size n/a".to_owned(),
        };
        println!(
            "{}: {} SFC elements, {}; compile reports {} warnings.",
            r.label, r.stats.elements, dom, r.diagnostics
        );
    }
    println!();
    println!("Stages (ms, medians of the staged pipeline; `read_sfc` includes its XML parse,");
    println!("`bind` includes resolve and the IRL files, `drop` frees everything):");
    println!();
    print_head(STAGES.iter().chain(&["sum"]));
    for r in rows {
        let mut line = format!("| {} |", r.label);
        for d in &r.stages {
            line.push_str(&format!(" {} |", ms(*d)));
        }
        line.push_str(&format!(" {} |", ms(r.stages.iter().sum())));
        println!("{line}");
    }
    println!();
    println!("The compile's own clock (ms, medians; `Compilation::timings` of the compile column:");
    println!("`read-sfc` is the streamed reading of the file, on two threads from 1 MiB; `bind`");
    println!("includes resolve, the IRL files and the conditions; `rest` = compile - the stages:");
    println!("output checks, the write-back's text, sorting and locating diagnostics):");
    println!();
    print_head(OWN_STAGES.iter().chain(&[
        "rest",
        "compile",
        "read-sfc ÷ quick-xml",
        "after reading ÷ quick-xml",
    ]));
    for r in rows {
        let mut line = format!("| {} |", r.label);
        for d in &r.own {
            line.push_str(&format!(" {} |", ms(*d)));
        }
        let floor = r.stream_floor.as_secs_f64();
        let read = r.own[1].as_secs_f64();
        let after: f64 = r.own[2..].iter().map(Duration::as_secs_f64).sum();
        line.push_str(&format!(
            " {} | {:.2} | {:.2} |",
            ms(r.compile),
            read / floor,
            after / floor
        ));
        println!("{line}");
    }
}

/// A markdown table's head: `case`, then `columns`, right-aligned.
fn print_head<'a>(columns: impl Iterator<Item = &'a &'a str>) {
    let mut head = String::from("| case |");
    let mut rule = String::from("|---|");
    for c in columns {
        head.push_str(&format!(" {c} |"));
        rule.push_str("---:|");
    }
    println!("{head}");
    println!("{rule}");
}
