//! The simulator (`src/simulate/`) on any program text: the first byte chooses the language
//! (KRL, RAPID, URScript), the rest is the program (KRL: `.src`, a NUL, the `.dat`).
//!
//! - reading never panics, whatever the text;
//! - a run never panics and ends within its limits; every step of the timeline ends after it
//!   starts, every problem names a controller of the cell.
#![no_main]

use libfuzzer_sys::fuzz_target;
use skillpost::lang::Language;
use skillpost::simulate::{self, Cell, Controller, Scenario, ir::IoKeys, krl, rapid, urscript};

fuzz_target!(|data: &[u8]| {
    let Some((&which, rest)) = data.split_first() else {
        return;
    };
    let text = String::from_utf8_lossy(rest);
    let io = IoKeys::default();
    let (language, program) = match which % 3 {
        0 => {
            let (src, dat) = text.split_once('\0').unwrap_or((&text, ""));
            (Language::Krl, krl::read(src, dat, &io))
        }
        1 => (Language::Rapid, rapid::read(&text, &io)),
        _ => (Language::UrScript, urscript::read(&text, &io)),
    };
    let cell = Cell {
        controllers: vec![Controller {
            name: "R".into(),
            program: "P".into(),
            file: "P".into(),
            language,
            blocking: language == Language::UrScript,
        }],
        ..Cell::default()
    };
    let scenario = Scenario {
        runs: 1,
        max_steps: 200,
        max_statements: 20_000,
        max_time_s: 1_000.0,
        ..Scenario::random()
    };
    let report = simulate::simulate(cell, &[program], scenario, None, Some(u64::from(which)));
    for (_, o) in &report.runs {
        assert!(o.statements <= 20_001, "{} statements", o.statements);
        for s in &o.timeline {
            assert!(s.start <= s.end, "{s:?}");
        }
        for p in &o.problems {
            assert!(p.controller.is_none_or(|c| c == 0), "{p:?}");
        }
    }
    let _ = simulate::report::human(&report);
    let _ = simulate::report::json(&report);
    let _ = simulate::report::vcd(&report);
});
