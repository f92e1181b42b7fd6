//! `-pO` for split programs (docs/LANGUAGES.md, "Long programs"): which part holds which steps,
//! by the listing's own step numbers.

use std::fmt::Write as _;

use serde_json::{Value as Json, json};

use crate::compile::Compilation;
use crate::plan::Block;

/// One split program's parts.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgramParts {
    pub program: String,
    /// Its main file, which calls the parts.
    pub main: String,
    pub parts: Vec<PartSteps>,
}

/// One part: its routine, its file, and the `-pO` numbers of its first and last step (`None`
/// when it holds no step: only waits or handshakes).
#[derive(Debug, Clone, PartialEq)]
pub struct PartSteps {
    pub routine: String,
    pub file: String,
    pub steps: Option<(usize, usize)>,
}

/// The split programs of the compile, in output order.
pub fn of(c: &Compilation) -> Vec<ProgramParts> {
    let mut out = Vec::new();
    for (k, (path, f)) in c.outputs.iter().enumerate() {
        if f.parts.is_empty() {
            continue;
        }
        let program = c
            .output_programs
            .get(k)
            .map(|(p, _)| p.clone())
            .or_else(|| c.program_names.first().cloned())
            .unwrap_or_default();
        let body: &[Block] = match (&c.cell, &c.plan) {
            (Some(cell), _) => {
                let i = c.program_names.iter().position(|p| *p == program);
                match i.and_then(|i| cell.programs.get(i)) {
                    Some(p) => &p.body,
                    None => continue,
                }
            }
            (None, Some(plan)) => &plan.body,
            (None, None) => continue,
        };
        // The steps each top-level block holds, numbered as `-pO` numbers them.
        let mut before = 0;
        let mut counts = Vec::with_capacity(body.len());
        for b in body {
            let mut n = 0;
            crate::plan::visit(std::slice::from_ref(b), &mut |x| {
                if matches!(x, Block::Step(_)) {
                    n += 1;
                }
            });
            counts.push((before, n));
            before += n;
        }
        let parts = f
            .parts
            .iter()
            .map(|p| {
                let first = counts.get(p.blocks.start).map_or(0, |c| c.0);
                let n: usize = counts
                    .get(p.blocks.clone())
                    .map_or(0, |cs| cs.iter().map(|c| c.1).sum());
                PartSteps {
                    routine: p.routine.clone(),
                    file: p.file.clone(),
                    steps: (n > 0).then_some((first + 1, first + n)),
                }
            })
            .collect();
        out.push(ProgramParts {
            program,
            main: path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            parts,
        });
    }
    out
}

/// The lines `-pO` adds after the order: each split program's parts.
pub fn text(programs: &[ProgramParts]) -> String {
    let mut o = String::new();
    for p in programs {
        let _ = writeln!(
            o,
            "parts of {} ({} calls them in this order):",
            p.program, p.main
        );
        for part in &p.parts {
            let steps = match part.steps {
                Some((a, b)) if a == b => format!("step #{a}"),
                Some((a, b)) => format!("steps #{a} to #{b}"),
                None => "no step".to_owned(),
            };
            let _ = writeln!(o, "  {} in {}: {steps}", part.routine, part.file);
        }
    }
    o
}

/// `"parts"` of the JSON order listing (or of its program in a cell's).
pub fn add_json(order: &mut Json, programs: &[ProgramParts]) {
    let list = |p: &ProgramParts| -> Json {
        p.parts
            .iter()
            .map(|part| {
                json!({
                    "routine": part.routine,
                    "file": part.file,
                    "first_step": part.steps.map(|s| s.0),
                    "last_step": part.steps.map(|s| s.1),
                })
            })
            .collect()
    };
    if let Some(cell) = order.get_mut("programs").and_then(Json::as_array_mut) {
        for prog in cell {
            let name = prog.get("program").and_then(Json::as_str).unwrap_or("");
            if let Some(p) = programs.iter().find(|p| p.program == name) {
                prog["parts"] = list(p);
            }
        }
    } else if let Some(p) = programs.first() {
        order["parts"] = list(p);
    }
}
