//! The generator's project (`generator.rs`) made a cell: its chart spread over `n` robots wired
//! to each other (`cell.rs`). Shared by `benches/cells.rs`, `benches/simulate.rs` and
//! `tests/bind_split.rs`, each of which includes `cell.rs` and `generator.rs` beside it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use crate::{cell, generator};

/// Writes into `dir` (created) a cell of `n` robots `R1`… with 6 wires each way on numbered
/// I/O, running the chart of `one` (a generated project), each step on the robot of its run
/// (`cell::spread`). Returns the blackboard's path.
pub fn write(one: &generator::Project, dir: &Path, n: usize) -> std::io::Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let single = generator::blackboard_text(generator::SFC_FILE, generator::IRL_FILE);
    let bb = cell::cell_blackboard(
        "KUKA KR15-2",
        n,
        6,
        &|_| single.clone(),
        &|_, p, j| {
            let number = |v: usize| ("Number", v.to_string());
            (number(100 + 10 * p + j), number(200 + 10 * p + j))
        },
        &|_, text| text.to_owned(),
    );
    let blackboard = dir.join(generator::BLACKBOARD_FILE);
    std::fs::write(&blackboard, bb)?;
    std::fs::copy(&one.irl, dir.join(generator::IRL_FILE))?;
    let sfc = std::fs::read_to_string(&one.sfc)?;
    std::fs::write(dir.join(generator::SFC_FILE), cell::spread(&sfc, n))?;
    Ok(blackboard)
}
