//! A chart of `bind::PARALLEL_FROM` steps or more is bound on two threads, its steps cut into
//! pieces that either thread takes, and the pieces' diagnostics, unused variables (`W303`,
//! grouped over all steps) and definitions (in order of first use) joined after in step order.
//! The result must be what one thread gives: compared through `compile` over every fixture
//! (split at every chart of two steps or more: pieces of a step or two) and a generated
//! 3,000-step project with errors and warnings in both halves (in many pieces).
//! The same switch writes a cell's programs two at a time (docs/CELLS.md): the cell fixtures, with
//! their bases, are compared the same way. And it reads a program's steps (their motions, the
//! points' base names, the titles) on a second thread ahead of the writer (`emit::ahead`): every
//! fixture's program is written so at the switch's 1 and compared with the one thread's. A long
//! program's steps' code is scanned for the words points may not be named and for a statement that
//! sets motion parameters in pieces on two threads: a case where both are in the second half
//! (a later piece).

use std::path::{Path, PathBuf};

use skillpost::compile::{Compilation, Options, compile};
use skillpost::diag::{Format, render};
use skillpost::load::FsSource;

#[path = "../benches/common/cell.rs"]
mod cell;
#[path = "../benches/common/cell_project.rs"]
mod cell_project;
mod common;
#[path = "../benches/common/generator.rs"]
mod generator;

/// What a user sees of a compile: the outputs, the write-back, every diagnostic with its place,
/// and how many warnings were counted without being kept ("N warnings; --warn shows them").
fn seen(c: &Compilation) -> String {
    let outputs: Vec<(PathBuf, &str)> = c
        .outputs
        .iter()
        .map(|(p, f)| (p.clone(), f.text.as_str()))
        .collect();
    let wb = c.write_back.as_ref().map(|w| w.value.clone());
    format!(
        "{outputs:#?}\n{wb:?}\n{}\n{} warnings not kept",
        render(&c.diagnostics, &c.sources, Format::Json, true, false),
        c.dropped_warnings
    )
}

fn same_both_ways(bb: &Path) {
    for drop_warnings in [false, true] {
        let run = |split: usize| {
            compile(
                &FsSource::default(),
                bb,
                &Options {
                    program: Some("out".into()),
                    drop_warnings,
                    bind_split_from: Some(split),
                    picture: None,
                    ..Default::default()
                },
            )
        };
        let one = seen(&run(usize::MAX));
        let two = seen(&run(1));
        assert!(
            one == two,
            "{}: bound on two threads differs from one (drop_warnings {drop_warnings}):\n--- one\n{one}\n--- two\n{two}",
            bb.display()
        );
    }
}

#[test]
fn every_fixture_binds_the_same_on_two_threads() {
    let bbs = common::fixture_files("aml");
    assert!(bbs.len() > 100, "blackboards found: {}", bbs.len());
    for bb in &bbs {
        same_both_ways(bb);
    }
}

/// `text` with the `n`th occurrence of `what` replaced by `with`.
fn replace_nth(text: &str, what: &str, n: usize, with: &str) -> String {
    let (at, _) = text.match_indices(what).nth(n).expect("enough occurrences");
    format!("{}{with}{}", &text[..at], &text[at + what.len()..])
}

/// A generated flat chart of 3,000 steps, a two-way selection every `select_every` (0: none).
fn steps_3000(select_every: usize) -> generator::Spec {
    generator::Spec {
        steps: 3000,
        branch_every: 0,
        branch_width: 0,
        select_every,
        looped: false,
    }
}

#[test]
fn a_large_chart_with_problems_in_both_halves_binds_the_same_on_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let spec = steps_3000(25);
    let project = generator::write_project(dir.path(), &spec).unwrap();
    let mut sfc = std::fs::read_to_string(&project.sfc).unwrap();
    let velocity = "<Variable name=\"Velocity\" Value=\"";
    let n = sfc.matches(velocity).count();
    assert!(n > 2000, "{n} steps with a velocity");
    // Unused variables: one in both halves (one W303 group over both), one in the second half
    // only, and twelve more in each half, six of them in both (more groups than the binder
    // scans: they are found by their index when the halves are joined); a missing variable
    // (E314) and a value that is not one (E50x) in each half.
    let many = |from: usize| -> String {
        (from..from + 12)
            .map(|m| format!("<Variable name=\"Many{m}\" Value=\"{m}\"/>"))
            .collect()
    };
    let first = format!(
        "<Variable name=\"Extra1\" Value=\"1\"/>{}<Variable name=\"Velocity\" Value=\"",
        many(0)
    );
    let second = format!(
        "<Variable name=\"Extra1\" Value=\"2\"/>{}<Variable name=\"Velocity\" Value=\"",
        many(6)
    );
    for (k, with) in [
        (10, first.as_str()),
        (n - 10, second.as_str()),
        (
            n - 20,
            "<Variable name=\"Extra2\" Value=\"3\"/><Variable name=\"Velocity\" Value=\"",
        ),
        (30, "<Variable name=\"Speed\" Value=\""),
        (n - 30, "<Variable name=\"Speed\" Value=\""),
    ] {
        sfc = replace_nth(&sfc, velocity, k, with);
    }
    std::fs::write(&project.sfc, &sfc).unwrap();
    let c = compile(
        &FsSource::default(),
        &project.blackboard,
        &Options {
            program: Some("out".into()),
            ..Default::default()
        },
    );
    let codes: Vec<&str> = c.diagnostics.iter().map(|d| d.code.as_str()).collect();
    assert!(codes.contains(&"E314"), "{codes:?}");
    assert_eq!(
        c.diagnostics
            .iter()
            .filter(|d| d.message.contains("`Extra1`"))
            .count(),
        1,
        "one W303 for Extra1 over both halves"
    );
    for m in [0, 8, 17] {
        let name = format!("`Many{m}`");
        assert_eq!(
            c.diagnostics
                .iter()
                .filter(|d| d.message.contains(&name))
                .count(),
            1,
            "one W303 for {name}"
        );
    }
    same_both_ways(&project.blackboard);
    // And the same without the problems: the outputs themselves.
    let clean = generator::write_project(&dir.path().join("clean"), &spec).unwrap();
    same_both_ways(&clean.blackboard);
}

#[test]
fn a_cells_programs_are_the_same_written_two_at_a_time() {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    for (bases, case, blackboard) in [
        (
            &["cell", "cell2"][..],
            "cell-two-robots-weld",
            "Blackboard.aml",
        ),
        (
            &["cell", "abb", "ur", "mixed"][..],
            "cell-kuka-abb-ur",
            "Blackboard.aml",
        ),
    ] {
        let dir = tempfile::tempdir().unwrap();
        for from in bases
            .iter()
            .map(|b| fixtures.join("base").join(b))
            .chain([fixtures.join("ok").join(case)])
        {
            for e in std::fs::read_dir(from).unwrap() {
                let e = e.unwrap();
                std::fs::copy(e.path(), dir.path().join(e.file_name())).unwrap();
            }
        }
        let bb = dir.path().join(blackboard);
        let c = compile(
            &FsSource::default(),
            &bb,
            &Options {
                program: Some("out".into()),
                ..Default::default()
            },
        );
        assert!(c.outputs.len() >= 3, "{case}: {:?}", c.diagnostics);
        same_both_ways(&bb);
    }
}

/// A cell of four controllers of about equal shares (as the cells bench spreads 3,000 steps)
/// binds its programs two at a time, each on one thread: with problems in every program (a
/// missing variable, a value that is not one, unused variables), the diagnostics and outputs are
/// the same as binding the programs one after another.
#[test]
fn a_cells_programs_bound_two_at_a_time_are_as_bound_one_by_one() {
    let dir = tempfile::tempdir().unwrap();
    let one = generator::write_project(&dir.path().join("one"), &steps_3000(25)).unwrap();
    let four = dir.path().join("four");
    let bb = cell_project::write(&one, &four, 4).unwrap();
    let spread = std::fs::read_to_string(four.join(generator::SFC_FILE)).unwrap();
    let mut sfc = spread.clone();
    let velocity = "<Variable name=\"Velocity\" Value=\"";
    let n = sfc.matches(velocity).count();
    // Spread over the chart, so every program has some; the even ones are `P2P` steps, whose
    // skill reads the velocity.
    for k in (0..8).map(|m| 2 * ((17 + m * (n - 40) / 8) / 2)).rev() {
        sfc = replace_nth(&sfc, velocity, k, "<Variable name=\"Speed\" Value=\"");
        sfc = replace_nth(
            &sfc,
            velocity,
            k + 5,
            "<Variable name=\"Extra\" Value=\"1\"/><Variable name=\"Velocity\" Value=\"x",
        );
    }
    std::fs::write(four.join(generator::SFC_FILE), &sfc).unwrap();
    let compiled = || {
        compile(
            &FsSource::default(),
            &bb,
            &Options {
                program: Some("out".into()),
                ..Default::default()
            },
        )
    };
    let c = compiled();
    let codes: Vec<&str> = c.diagnostics.iter().map(|d| d.code.as_str()).collect();
    assert!(
        codes.iter().filter(|&&c| c == "E314").count() >= 8,
        "{codes:?}"
    );
    same_both_ways(&bb);
    // And without the problems: the four programs themselves.
    std::fs::write(four.join(generator::SFC_FILE), &spread).unwrap();
    let c = compiled();
    assert_eq!(
        c.cell.as_ref().map(|c| c.programs.len()),
        Some(4),
        "{:?}",
        c.diagnostics
    );
    same_both_ways(&bb);
}

/// A cell's programs written two at a time are checked right after each is written, on the
/// thread that wrote it: a template that breaks every program (`E606`, the check of the
/// generated files) is reported as when the programs are written and checked one by one.
#[test]
fn a_cells_programs_checked_as_they_are_written_report_what_the_check_after_finds() {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let dir = tempfile::tempdir().unwrap();
    for from in ["base/cell", "base/cell2", "ok/cell-two-robots-weld"] {
        for e in std::fs::read_dir(fixtures.join(from)).unwrap() {
            let e = e.unwrap();
            std::fs::copy(e.path(), dir.path().join(e.file_name())).unwrap();
        }
    }
    // The KRL template that opens a LOOP nothing closes.
    let template = dir.path().join("bad.toml");
    std::fs::copy(
        fixtures.join("err/e606_template_loop_without_endloop/bad.toml"),
        &template,
    )
    .unwrap();
    let bb = dir.path().join("Blackboard.aml");
    let run = |split: usize| {
        seen(&compile(
            &FsSource::default(),
            &bb,
            &Options {
                program: Some("out".into()),
                template: Some(template.clone()),
                bind_split_from: Some(split),
                picture: None,
                ..Default::default()
            },
        ))
    };
    let (one, two) = (run(usize::MAX), run(1));
    assert_eq!(one, two, "checked as written differs from checked after");
    // Both robots' programs would not load, each reported once.
    assert_eq!(two.matches("E606").count(), 2, "{two}");
    assert!(
        two.contains("the generated out_KUKA_KR15_2.src would not load"),
        "{two}"
    );
    assert!(
        two.contains("the generated out_KUKA_KR16_2.src would not load"),
        "{two}"
    );
}

/// The steps' code of a long program is scanned in pieces on two threads
/// (`emit::points::for_program`):
/// the words no point may be named and the first statement that sets motion parameters (W210)
/// must be found in the second half as in one pass.
#[test]
fn what_a_long_programs_second_half_sets_and_names_is_found_as_on_one_thread() {
    let dir = tempfile::tempdir().unwrap();
    let project = generator::write_project(dir.path(), &steps_3000(0)).unwrap();
    // The IRL definition no longer sets the velocity: only a step's own code does.
    let irl = project.blackboard.with_file_name("kr15-2.irl");
    let text = std::fs::read_to_string(&irl).unwrap();
    assert!(text.contains("$VEL.CP = VALUE"));
    std::fs::write(&irl, text.replace("$VEL.CP = VALUE", "VALUE = VALUE")).unwrap();
    // The velocity a text, so that a step's code can say anything.
    let bb = std::fs::read_to_string(&project.blackboard).unwrap();
    let typed = "\"Velocity\" AttributeDataType=\"xs:double\"";
    assert!(bb.contains(typed));
    std::fs::write(
        &project.blackboard,
        bb.replace(typed, "\"Velocity\" AttributeDataType=\"xs:string\""),
    )
    .unwrap();
    let mut sfc = std::fs::read_to_string(&project.sfc).unwrap();
    let velocity = "<Variable name=\"Velocity\" Value=\"";
    let n = sfc.matches(velocity).count();
    // Near the end: a statement that sets motion parameters, and the name of an early point
    // (`XP2P_4`, step 4's) as a word of the code.
    sfc = replace_nth(&sfc, velocity, n - 10, &format!("{velocity}$VEL.CP\" x=\""));
    sfc = replace_nth(&sfc, velocity, n - 20, &format!("{velocity}XP2P_4\" x=\""));
    std::fs::write(&project.sfc, &sfc).unwrap();
    let c = compile(
        &FsSource::default(),
        &project.blackboard,
        &Options {
            program: Some("out".into()),
            bind_split_from: Some(1),
            ..Default::default()
        },
    );
    let w210: Vec<&str> = c
        .diagnostics
        .iter()
        .filter(|d| d.code.as_str() == "W210")
        .map(|d| d.message.as_str())
        .collect();
    assert!(
        w210.len() == 1 && w210[0].contains("`SetVelCP (\"$VEL.CP\")`"),
        "{w210:?}"
    );
    let dat: String = c
        .outputs
        .iter()
        .filter(|(p, _)| p.extension().is_some_and(|e| e == "dat"))
        .map(|(_, f)| f.text.as_str())
        .collect();
    assert!(dat.contains("DECL E6POS XP2P_3="), "points are named");
    assert!(!dat.contains("DECL E6POS XP2P_4="), "a word of the code");
    same_both_ways(&project.blackboard);
}
