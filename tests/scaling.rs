//! Hostile sizes (issue 13): for every input dimension, a project 16 times larger in that
//! dimension must not take much more than 16 times as long to compile. A quadratic path makes the
//! 16× run cost 256× (the bound below allows 30× plus half a second, since the machine may be loaded), so it cannot come back
//! unnoticed. The figures themselves are the benches' business (`bench/scaling.sh`,
//! docs/PERFORMANCE.md); this only catches growth.
//!
//! Each case runs the command line on a project from `generator::write_shape`. The cases take a
//! lock, so they do not time each other; a bound that is missed is measured once more before the
//! test fails (a loaded machine may stall one run).
//!
//! `SKILLPOST_SCALING_BIN=/path/to/skillpost` times another build. A debug build of the code
//! before issue 13 fails `vars`, `resources` and `signals` here (and `irl` in some runs); its
//! quadratic paths in skills and functions have a small coefficient and stay within the bound at
//! these sizes (CI's time budget): `bench/scaling.sh` (instruction counts) is the precise check.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::time::{Duration, Instant};

#[path = "../benches/common/generator.rs"]
mod generator;

static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// The 16× run may take this many times the 1× run …
const FACTOR: f64 = 30.0;
/// … plus this much (process start, page faults, a loaded machine).
const SLACK: Duration = Duration::from_millis(500);

fn bin() -> PathBuf {
    std::env::var_os("SKILLPOST_SCALING_BIN")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_skillpost")))
}

/// Wall time of one compile of `dir`'s project (outputs written into `dir`).
fn compile(dir: &Path) -> Duration {
    let t = Instant::now();
    let out = Command::new(bin())
        .current_dir(dir)
        .args(["Blackboard.aml", "out"])
        .output()
        .expect("run skillpost");
    let took = t.elapsed();
    assert!(
        out.status.success(),
        "{}: {}\n{}",
        dir.display(),
        out.status,
        String::from_utf8_lossy(&out.stderr[..out.stderr.len().min(2000)])
    );
    took
}

/// The fastest of `runs` compiles.
fn best(dir: &Path, runs: usize) -> Duration {
    (0..runs).map(|_| compile(dir)).min().unwrap()
}

fn check(dim: &str, n: usize, n16: usize) {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let tmp = tempfile::tempdir().unwrap();
    let small = tmp.path().join("small");
    let large = tmp.path().join("large");
    generator::write_shape(&small, dim, n)
        .expect("a known dimension")
        .unwrap();
    generator::write_shape(&large, dim, n16)
        .expect("a known dimension")
        .unwrap();
    let t1 = best(&small, 3);
    let bound = t1.mul_f64(FACTOR * n16 as f64 / (16 * n) as f64) + SLACK;
    let mut t16 = compile(&large);
    if t16 > bound {
        t16 = t16.min(compile(&large));
    }
    eprintln!("{dim}: n = {n}: {t1:.2?}; n = {n16}: {t16:.2?} (bound {bound:.2?})");
    assert!(
        t16 <= bound,
        "{dim}: n = {n} took {t1:.2?}, n = {n16} took {t16:.2?}, more than {FACTOR}× plus {SLACK:?} ({bound:.2?}): a super-linear path?"
    );
}

#[test]
fn steps() {
    check("steps", 200, 3200);
}

#[test]
fn variables_in_one_step() {
    check("vars", 1000, 16000);
}

#[test]
fn skills_per_resource() {
    check("skills", 300, 4800);
}

#[test]
fn resources() {
    check("resources", 2000, 32000);
}

#[test]
fn functions_per_skill() {
    check("functions", 400, 6400);
}

#[test]
fn irl_calls_and_definitions() {
    check("irl", 250, 4000);
}

#[test]
fn irl_files() {
    // Each file's path was looked up in every file read before it (twice): 4,000 files took ten
    // times what 1,000 took.
    check("files", 250, 4000);
}

#[test]
fn irl_definitions_calling_definitions() {
    // Each definition brought in through another one scanned every definition left against
    // all the code again: 1,000 took 39 times what 250 took.
    check("chain", 250, 4000);
}

#[test]
fn irl_definitions_no_program_calls() {
    // Each routine of the library was compared with every one listed before it, to list it
    // once: 32,000 took 3.28 s against 0.04 s for 2,000 (release; now 0.60 s in a test build).
    check("unused", 2000, 32000);
}

#[test]
fn signals() {
    check("signals", 2000, 32000);
}

#[test]
fn condition_size() {
    // A condition has at most 1024 tokens (cond::MAX_TOKENS): 16× = 320 terms (~860 tokens).
    check("cond", 20, 320);
}

#[test]
fn branch_width() {
    check("width", 150, 2400);
}

#[test]
fn nesting_depth() {
    // Nesting is bounded (plan::MAX_NESTING = 128): 1× = 7, 16× = 112.
    check("depth", 7, 112);
}

#[test]
fn loops() {
    check("loops", 150, 2400);
}

#[test]
fn forward_jumps() {
    // Each jump's target begins a state (found before the walk: it does not dominate the jump).
    check("jumps", 150, 2400);
}

#[test]
fn overlapping_loops() {
    // Jumps back into the previous loop's body: the loops nest deeper than the limit (128), so
    // every jump's target begins a state and the chart is walked once more.
    check("overlap", 150, 2400);
}

/// 600 loops each overlapping the next compile, with the labels of their states.
#[test]
fn overlapping_loops_deeper_than_the_nesting_limit_compile() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let tmp = tempfile::tempdir().unwrap();
    generator::write_shape(tmp.path(), "overlap", 600)
        .expect("a known dimension")
        .unwrap();
    compile(tmp.path());
    let src = std::fs::read_to_string(tmp.path().join("out.src")).unwrap();
    assert!(
        src.contains("GOTO skp_s") && src.contains("\nskp_s2:"),
        "no states"
    );
}

#[test]
fn loop_nesting() {
    // Loops inside loops, bounded like branches (plan::MAX_NESTING = 128): 1× = 7, 16× = 112.
    check("loopnest", 7, 112);
}

#[test]
fn nesting_inside_an_element() {
    // The reader's stack of open elements must not be copied whole at every start tag.
    check("nest", 2000, 32000);
}

#[test]
fn markup_left_to_quick_xml() {
    // References, comments and CDATA: the SFC's producer hands quick-xml one event at a time from
    // its `<` or `&` (`read::tape::plain_event`); each must cost its own length, not the rest of
    // the piece.
    check("markup", 2000, 32000);
}
