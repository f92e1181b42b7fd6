//! `skillpost simulate` through the binary (docs/SIMULATE.md): the cell's programs run together on
//! the built-in interpreter; the report's timeline, cycle time, problems and coverage, the
//! Value Change Dump, the scenario file and its errors, and the exit statuses.

mod common;

use std::fs;
use std::path::Path;
use std::process::{Command, Output};

use serde_json::Value;

fn skillpost(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// `simulate` with a scenario written into the project, as JSON; the exit status.
fn simulate(
    dir: &Path,
    bb: &str,
    program: &str,
    scenario: Option<&str>,
    more: &[&str],
) -> (i32, Value) {
    let mut args = vec!["simulate", bb, program, "--format", "json"];
    if let Some(s) = scenario {
        fs::write(dir.join("scenario.toml"), s).unwrap();
        args.extend(["--scenario", "scenario.toml"]);
    }
    args.extend(more);
    let out = skillpost(dir, &args);
    let code = out.status.code().unwrap();
    let v = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "not JSON ({e}), exit {code}:\n{}\n{}",
            text(&out.stdout),
            text(&out.stderr)
        )
    });
    (code, v)
}

/// Each controller's steps in the order they ran: (step, start, end).
fn lanes(run: &Value) -> std::collections::BTreeMap<String, Vec<(String, f64, f64)>> {
    let mut out: std::collections::BTreeMap<String, Vec<(String, f64, f64)>> = Default::default();
    for s in run["timeline"].as_array().unwrap() {
        out.entry(s["controller"].as_str().unwrap().to_owned())
            .or_default()
            .push((
                s["step"].as_str().unwrap().to_owned(),
                s["start_s"].as_f64().unwrap(),
                s["end_s"].as_f64().unwrap(),
            ));
    }
    out
}

fn names(steps: &[(String, f64, f64)]) -> Vec<&str> {
    steps.iter().map(|s| s.0.as_str()).collect()
}

/// The cycle time the picture of the plan (`--svg`) states.
fn picture_cycle(dir: &Path, bb: &str, program: &str) -> f64 {
    let out = skillpost(dir, &[bb, program, "--svg", "plan.svg"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let svg = fs::read_to_string(dir.join("plan.svg")).unwrap();
    let at = svg
        .find("cycle time ")
        .expect("the picture states a cycle time")
        + 11;
    svg[at..].split(' ').next().unwrap().parse().unwrap()
}

fn problems(run: &Value) -> Vec<(String, String)> {
    run["problems"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["kind"].as_str().unwrap().to_owned(),
                p["message"].as_str().unwrap().to_owned(),
            )
        })
        .collect()
}

#[test]
fn a_mixed_cell_runs_in_the_charts_order_with_the_pictures_cycle_time() {
    let p = common::fixture_project("cell-kuka-abb-ur");
    let dir = p.path();
    // Part_Present: the UR places while the KUKA retreats.
    let (code, v) = simulate(
        dir,
        "Blackboard.aml",
        "Mix",
        Some("[inputs.\"ABB IRB 1200\"]\nPart_Present = true\n"),
        &[],
    );
    let run = &v["runs"][0];
    assert_eq!(code, 0, "{v:#}");
    assert_eq!(problems(run), []);
    let l = lanes(run);
    assert_eq!(names(&l["KUKA KR15-2"]), ["Pick", "Grip", "Retreat"]);
    assert_eq!(names(&l["ABB IRB 1200"]), ["Take"]);
    assert_eq!(names(&l["UR10e"]), ["Place", "Release"]);
    // Across controllers, the chart's order: Take after Grip, Place and Retreat after Take.
    let grip = &l["KUKA KR15-2"][1];
    let take = &l["ABB IRB 1200"][0];
    assert!(take.1 >= grip.2, "Take {take:?} before Grip ended {grip:?}");
    assert!(l["UR10e"][0].1 >= take.2 && l["KUKA KR15-2"][2].1 >= take.2);
    let cycle = run["cycle_s"].as_f64().expect("every program ended");
    let picture = picture_cycle(dir, "Blackboard.aml", "Mix");
    assert!(
        (cycle - picture).abs() < 1e-6,
        "simulated {cycle} s, the picture {picture} s"
    );

    // No part: the ABB goes home, the UR does nothing, the KUKA does not retreat.
    let (code, v) = simulate(
        dir,
        "Blackboard.aml",
        "Mix",
        Some("[inputs.\"ABB IRB 1200\"]\nPart_Present = false\n"),
        &["--runs", "2"],
    );
    assert_eq!(code, 0, "{v:#}");
    let l = lanes(&v["runs"][0]);
    assert_eq!(names(&l["KUKA KR15-2"]), ["Pick", "Grip"]);
    assert_eq!(names(&l["ABB IRB 1200"]), ["Take", "Home"]);
    assert!(!l.contains_key("UR10e"));
    // What no run reached: the other branch and its steps.
    let never: Vec<&str> = v["coverage"]["steps_never_reached"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["step"].as_str().unwrap())
        .collect();
    assert_eq!(never, ["Retreat", "Place", "Release"]);
    assert_eq!(
        v["coverage"]["branches_never_reached"],
        serde_json::json!([{"transition": 9, "selection": 8}])
    );
}

#[test]
fn random_runs_reach_every_step_and_branch_of_the_mixed_cell() {
    let p = common::fixture_project("cell-kuka-abb-ur");
    let (code, v) = simulate(
        p.path(),
        "Blackboard.aml",
        "Mix",
        None,
        &["--runs", "30", "--seed", "7"],
    );
    assert_eq!(code, 0, "{v:#}");
    assert_eq!(v["runs"].as_array().unwrap().len(), 30);
    assert_eq!(v["coverage"]["steps_never_reached"], serde_json::json!([]));
    assert_eq!(
        v["coverage"]["branches_never_reached"],
        serde_json::json!([])
    );
    // The same seed gives the same runs.
    let (_, again) = simulate(
        p.path(),
        "Blackboard.aml",
        "Mix",
        None,
        &["--runs", "30", "--seed", "7"],
    );
    assert_eq!(v["runs"], again["runs"]);
}

#[test]
fn two_wires_swapped_are_a_deadlock_at_the_first_handshake_naming_both_controllers() {
    let p = common::fixture_project("cell-two-robots-weld");
    let dir = p.path();
    let (code, v) = simulate(
        dir,
        "Blackboard.aml",
        "Weld",
        Some("[inputs.\"KUKA KR16-2\"]\nMore_Parts = false\n"),
        &[],
    );
    assert_eq!(code, 0, "{v:#}");
    let (code, v) = simulate(
        dir,
        "Blackboard.aml",
        "Weld",
        Some(
            "[inputs.\"KUKA KR16-2\"]\nMore_Parts = false\n\n[[swap]]\nwires = [\"A to B 1\", \"A to B 2\"]\n",
        ),
        &[],
    );
    assert_eq!(code, 1, "{v:#}");
    let run = &v["runs"][0];
    let deadlocks: Vec<&Value> = run["problems"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["kind"] == "deadlock")
        .collect();
    let who: Vec<&str> = deadlocks
        .iter()
        .map(|p| p["controller"].as_str().unwrap())
        .collect();
    assert_eq!(who, ["KUKA KR15-2", "KUKA KR16-2"], "{run:#}");
    // The first handshake: the KR16-2 waits for Grip (localId 5), the KR15-2 for Weld (7).
    assert_eq!(deadlocks[1]["local_id"], 5);
    assert_eq!(deadlocks[0]["local_id"], 7);
    for d in &deadlocks {
        let m = d["message"].as_str().unwrap();
        assert!(m.contains("waits too"), "{m}");
        assert!(d["line"].as_u64().is_some() && d["file"].as_str().unwrap().ends_with(".src"));
    }
    assert_eq!(names(&lanes(run)["KUKA KR15-2"]), ["Pick", "Grip"]);
}

#[test]
fn a_restart_shows_the_start_barrier_and_a_restart_of_both_runs_the_chart_again() {
    let p = common::fixture_project("cell-two-robots-weld");
    let dir = p.path();
    let one = "[inputs.\"KUKA KR16-2\"]\nMore_Parts = false\n\n[[restart]]\ncontroller = \"kuka kr16-2\"\nafter = \"Weld\"\n";
    let (code, v) = simulate(dir, "Blackboard.aml", "Weld", Some(one), &[]);
    assert_eq!(code, 1, "{v:#}");
    let run = &v["runs"][0];
    assert_eq!(run["restarts"][0]["controller"], "KUKA KR16-2");
    assert_eq!(run["restarts"][0]["at_s"], 6.5);
    let ps = problems(run);
    // The partner stops with its message; the one started again waits at its start barrier.
    assert_eq!(ps[0].0, "stopped", "{ps:?}");
    assert!(ps[0].1.contains("KUKA KR16-2 started again"), "{ps:?}");
    assert_eq!(ps[1].0, "deadlock");
    assert!(
        ps[1].1.contains("start barrier") && ps[1].1.contains("start it again"),
        "{ps:?}"
    );
    // Started again too: the cell runs the chart from its start.
    let both = format!("{one}\n[[restart]]\ncontroller = \"KUKA KR15-2\"\nat = 20\n");
    let (code, v) = simulate(dir, "Blackboard.aml", "Weld", Some(&both), &[]);
    assert_eq!(code, 0, "{v:#}");
    let l = lanes(&v["runs"][0]);
    assert_eq!(
        names(&l["KUKA KR15-2"]),
        ["Pick", "Grip", "Pick", "Grip", "PlaceA"]
    );
    assert_eq!(names(&l["KUKA KR16-2"]), ["Weld", "Weld", "RetreatB"]);
    assert!(l["KUKA KR15-2"][2].1 >= 20.0);
}

#[test]
fn the_value_change_dump_parses_and_holds_every_wire() {
    let p = common::fixture_project("cell-kuka-abb-ur");
    let dir = p.path();
    let (code, _) = simulate(
        dir,
        "Blackboard.aml",
        "Mix",
        Some("[inputs.\"ABB IRB 1200\"]\nPart_Present = true\n"),
        &["--vcd", "run.vcd"],
    );
    assert_eq!(code, 0);
    let bytes = fs::read(dir.join("run.vcd")).unwrap();
    let mut parser = vcd::Parser::new(&bytes[..]);
    let header = parser.parse_header().expect("a VCD header");
    let bb = fs::read_to_string(dir.join("Blackboard.aml")).unwrap();
    let links: Vec<String> = bb
        .split("<InternalLink Name=\"")
        .skip(1)
        .map(|s| s.split('"').next().unwrap().replace(' ', "_"))
        .collect();
    assert_eq!(links.len(), 19);
    let mut ids = std::collections::HashMap::new();
    for scope in ["KUKA_KR15_2", "ABB_IRB_1200", "UR10e"] {
        for item in &header
            .find_scope(&[scope])
            .unwrap_or_else(|| panic!("scope {scope}"))
            .items
        {
            if let vcd::ScopeItem::Var(v) = item {
                ids.insert(v.reference.clone(), v.code);
            }
        }
    }
    for l in &links {
        assert!(ids.contains_key(&format!("{l}_out")), "{l}_out missing");
        assert!(ids.contains_key(&format!("{l}_in")), "{l}_in missing");
    }
    assert!(ids.contains_key("Part_Present"));
    // Every wire changes during the run (the start barrier alone drives the run and ready
    // wires), and its input follows its output.
    let mut changed = std::collections::HashSet::new();
    let (mut last_t, mut initial) = (0, false);
    for cmd in parser {
        match cmd.unwrap() {
            vcd::Command::Timestamp(t) => {
                assert!(t >= last_t);
                last_t = t;
            }
            vcd::Command::Begin(vcd::SimulationCommand::Dumpvars) => initial = true,
            vcd::Command::End(vcd::SimulationCommand::Dumpvars) => initial = false,
            vcd::Command::ChangeScalar(id, vcd::Value::V1) if !initial => {
                changed.insert(id);
            }
            _ => {}
        }
    }
    let rose = links
        .iter()
        .filter(|l| changed.contains(&ids[&format!("{l}_in")]))
        .count();
    assert!(rose >= 10, "only {rose} wires rose");
    assert_eq!(last_t, 7500, "the dump ends with the cycle");
}

#[test]
fn the_measured_picture_shows_each_step_the_restart_and_the_problem() {
    let p = common::fixture_project("cell-two-robots-weld");
    let dir = p.path();
    let one = "[inputs.\"KUKA KR16-2\"]\nMore_Parts = false\n\n[[restart]]\ncontroller = \"KUKA KR16-2\"\nafter = \"Weld\"\n";
    let (code, v) = simulate(
        dir,
        "Blackboard.aml",
        "Weld",
        Some(one),
        &["--svg", "run.svg"],
    );
    assert_eq!(code, 1);
    let svg = fs::read_to_string(dir.join("run.svg")).unwrap();
    let doc = roxmltree::Document::parse(&svg).expect("the SVG is XML");
    let texts: Vec<String> = doc
        .descendants()
        .filter(|n| n.has_tag_name("text"))
        .map(|n| n.text().unwrap_or_default().to_owned())
        .collect();
    for s in v["runs"][0]["timeline"].as_array().unwrap() {
        let label = format!("{} (id={})", s["step"].as_str().unwrap(), s["local_id"]);
        assert!(texts.contains(&label), "{label} not in {texts:?}");
    }
    assert!(
        texts.iter().any(|t| t.starts_with("deadlock at ")),
        "{texts:?}"
    );
    assert!(texts.iter().any(|t| t.contains("KUKA KR16-2")));
    assert!(svg.contains("started again at 6.5 s"));
    // The cycle time of an undisturbed run, as the picture of the plan states it.
    let (code, _) = simulate(
        dir,
        "Blackboard.aml",
        "Weld",
        Some("[inputs.\"KUKA KR16-2\"]\nMore_Parts = false\n"),
        &["--svg", "run.svg"],
    );
    assert_eq!(code, 0);
    let picture = picture_cycle(dir, "Blackboard.aml", "Weld");
    let svg = fs::read_to_string(dir.join("run.svg")).unwrap();
    assert!(
        svg.contains(&format!("cycle time {picture} s")),
        "{picture}"
    );
}

#[test]
fn scenario_errors_name_the_file_line_column_and_the_near_name_and_write_nothing() {
    let p = common::fixture_project("cell-kuka-abb-ur");
    let dir = p.path();
    let before: Vec<_> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    let cases = [
        (
            "[inputs.\"ABB IRB 120\"]\nPart_Present = true\n",
            "scenario.toml:1:9: no resource `ABB IRB 120` in the blackboard; did you mean `ABB IRB 1200`?",
        ),
        (
            "[inputs.\"ABB IRB 1200\"]\nPart_Presnt = true\n",
            "scenario.toml:2:1: `ABB IRB 1200` has no input `Part_Presnt`; did you mean `Part_Present`?",
        ),
        (
            "[inputs.\"ABB IRB 1200\"]\nPart_Present = 3\n",
            "scenario.toml:2:16: input `Part_Present` takes true or false",
        ),
        ("jiter = 0.1\n", "scenario.toml:1:1: unknown field `jiter`"),
        (
            "[[restart]]\ncontroller = \"UR10\"\nat = 1\n",
            "no controller `UR10` in this cell; did you mean `UR10e`?",
        ),
        (
            "[[change]]\nresource = \"UR10e\"\nsignal = \"From_ABB_1\"\nvalue = true\nat = 1\n",
            "is a wire: another controller's program drives it",
        ),
        (
            "[[change]]\nresource = \"ABB IRB 1200\"\nsignal = \"To_KUKA_1\"\nvalue = true\nat = 1\n",
            "scenario.toml:3:10: `To_KUKA_1` of `ABB IRB 1200` is an output that drives a wire to another controller: its program sets it, a scenario cannot force it",
        ),
        (
            "[[change]]\nresource = \"ABB IRB 1200\"\nsignal = \"Part_Present\"\nvalue = true\nafter = \"Tak\"\n",
            "no step `Tak` runs in this cell's programs; did you mean `Take`?",
        ),
        (
            "[[swap]]\nwires = [\"KUKA to ABB 1\", \"KUKA to ABB 9\"]\n",
            "no wire `KUKA to ABB 9` in this cell",
        ),
    ];
    for (scenario, expected) in cases {
        fs::write(dir.join("scenario.toml"), scenario).unwrap();
        let out = skillpost(
            dir,
            &[
                "simulate",
                "Blackboard.aml",
                "Mix",
                "--scenario",
                "scenario.toml",
            ],
        );
        assert_eq!(out.status.code(), Some(2), "{scenario}");
        let err = text(&out.stderr);
        assert!(err.contains(expected), "{scenario}:\n{err}");
        assert!(out.stdout.is_empty());
    }
    let after: Vec<_> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        after.len(),
        before.len() + 1,
        "only the scenario was added: {after:?}"
    );
}

#[cfg(unix)]
#[test]
fn a_scenario_that_is_a_fifo_or_endless_is_refused_at_once() {
    let p = common::fixture_project("cell-kuka-abb-ur");
    let dir = p.path();
    let fifo = dir.join("fifo.toml");
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success(),
        "mkfifo"
    );
    for s in ["fifo.toml", "/dev/zero"] {
        let start = std::time::Instant::now();
        let out = skillpost(dir, &["simulate", "Blackboard.aml", "Mix", "--scenario", s]);
        assert_eq!(out.status.code(), Some(2), "{s}: {}", text(&out.stderr));
        assert!(
            text(&out.stderr).contains("cannot read the scenario"),
            "{}",
            text(&out.stderr)
        );
        assert!(start.elapsed() < std::time::Duration::from_secs(20));
    }
}

#[test]
fn inputs_with_errors_exit_2_and_a_wait_for_an_input_nothing_sets_is_told_apart() {
    let p = common::fixture_project("abb-irb1200");
    let dir = p.path();
    let out = skillpost(dir, &["simulate", "Missing.aml", "Palletize"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("nothing simulated"),
        "{}",
        text(&out.stderr)
    );
    // No input set: the robot waits for its part, which nothing in the scenario gives it.
    let (code, v) = simulate(dir, "Cell.aml", "Palletize", Some("runs = 1\n"), &[]);
    assert_eq!(code, 1);
    let ps = problems(&v["runs"][0]);
    assert_eq!(ps.len(), 1, "{ps:?}");
    assert_eq!(ps[0].0, "stuck");
    assert!(
        ps[0]
            .1
            .contains("waits for `Part_Present` on ABB IRB 1200, which nothing sets"),
        "{ps:?}"
    );
    // No program was written.
    assert!(!dir.join("Palletize.mod").exists());
}

#[test]
fn programs_of_every_language_run_without_problems_under_random_inputs() {
    for (fixture, bb, program) in [
        ("reference-sample", None, None),
        ("ur10e", None, None),
        ("abb-irb1200", Some("Cell.aml"), Some("Palletize")),
        ("flow-selection-three-way", None, None),
        ("cell-sequences-mixed", None, None),
    ] {
        let p = common::fixture_project(fixture);
        let dir = p.path();
        let case: toml::Value =
            toml::from_str(&fs::read_to_string(dir.join("case.toml")).unwrap()).unwrap();
        let program = program
            .map(str::to_owned)
            .unwrap_or_else(|| case["program"].as_str().unwrap().to_owned());
        let bb = bb.map(str::to_owned).unwrap_or_else(|| {
            match case.get("blackboard").and_then(|b| b.as_str()) {
                Some(b) => b.to_owned(),
                None => fs::read_dir(dir)
                    .unwrap()
                    .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                    .find(|n| n.ends_with(".aml"))
                    .unwrap(),
            }
        });
        let (code, v) = simulate(dir, &bb, &program, None, &["--runs", "10"]);
        assert_eq!(code, 0, "{fixture}: {v:#}");
        // Every program ends, or (a chart that repeats) runs its rounds.
        for run in v["runs"].as_array().unwrap() {
            assert!(
                run["ended"] == true || run["repeats"] == true,
                "{fixture}: {run:#}"
            );
        }
        assert!(
            !v["runs"][0]["timeline"].as_array().unwrap().is_empty(),
            "{fixture}"
        );
    }
}

#[test]
fn a_program_split_into_parts_runs_as_the_unsplit_one() {
    let p = common::fixture_project("split-cell");
    let dir = p.path();
    let runs = |m: &str| {
        let (code, v) = simulate(
            dir,
            "Blackboard.aml",
            "Mix",
            None,
            &["--max-lines", m, "--runs", "8", "--seed", "3"],
        );
        assert_eq!(code, 0, "--max-lines {m}: {v:#}");
        assert_eq!(v["not_simulated"], serde_json::json!([]), "--max-lines {m}");
        v["runs"].clone()
    };
    let whole = runs("0");
    assert_eq!(whole[0]["timeline"].as_array().unwrap().len(), 6);
    // 20 lines: the KRL program in 3 parts and the RAPID one in 2 (the fixture's snapshot);
    // 5: as small as the cuts go.
    assert_eq!(runs("20"), whole);
    assert_eq!(runs("5"), whole);
}

#[test]
fn the_text_report_gives_the_timeline_the_problem_with_its_place_and_what_was_not_simulated() {
    let p = common::fixture_project("cell-two-robots-weld");
    let dir = p.path();
    fs::write(
        dir.join("scenario.toml"),
        "[inputs.\"KUKA KR16-2\"]\nMore_Parts = false\n\n[[swap]]\nwires = [\"A to B 1\", \"A to B 2\"]\n",
    )
    .unwrap();
    let out = skillpost(
        dir,
        &[
            "simulate",
            "Blackboard.aml",
            "Weld",
            "--scenario",
            "scenario.toml",
        ],
    );
    assert_eq!(out.status.code(), Some(1));
    let t = text(&out.stdout);
    let lines: Vec<&str> = t.lines().collect();
    assert!(lines[0].starts_with("simulate: 1 run of 2 controllers: KUKA KR15-2 (Weld_KUKA_KR15_2.src), KUKA KR16-2 (Weld_KUKA_KR16_2.src); scenario scenario.toml"), "{t}");
    assert!(t.contains("run 1 (seed "), "{t}");
    assert!(
        t.contains("    0.00     1.50  KUKA KR15-2  Pick (localId 3)"),
        "{t}"
    );
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("  problem: deadlock at ")
                && l.contains("(chart element localId 5)")
                && l.ends_with("[Weld_KUKA_KR16_2.src:74]")),
        "{t}"
    );
    assert_eq!(lines.last(), Some(&"2 problems"), "{t}");
    // A statement the simulator does not know is listed once, with its place.
    let irl = fs::read_to_string(dir.join("greifer.irl")).unwrap();
    fs::write(
        dir.join("greifer.irl"),
        irl.replace("$OUT[7] = TRUE", "$OUT[7] = TRUE\n\t\t\t\tCONVEYOR_ON(3)"),
    )
    .unwrap();
    let out = skillpost(dir, &["simulate", "Blackboard.aml", "Weld", "--runs", "3"]);
    let t = text(&out.stdout);
    assert!(t.contains("not simulated"), "{t}");
    assert_eq!(t.matches(": CONVEYOR_ON(3)").count(), 1, "listed once: {t}");
}

/// A shift of cycles: `cycles = 2` starts every program again after its END, each cycle in the
/// chart's order (the second Take after the second Grip), without a problem; a controller's
/// `[timing]` moves its start and stretches its motions, and the cycle time follows.
#[test]
fn cycles_run_the_chart_again_and_a_controllers_timing_stretches_its_motions() {
    let p = common::fixture_project("cell-kuka-abb-ur");
    let dir = p.path();
    let inputs = "[inputs.\"ABB IRB 1200\"]\nPart_Present = true\n";
    let (code, v) = simulate(dir, "Blackboard.aml", "Mix", Some(inputs), &[]);
    assert_eq!(code, 0, "{v:#}");
    let one = lanes(&v["runs"][0]);
    let cycle = v["runs"][0]["cycle_s"].as_f64().unwrap();

    let (code, v) = simulate(
        dir,
        "Blackboard.aml",
        "Mix",
        Some(&format!("cycles = 2\ncycle_pause_s = 0.5\n{inputs}")),
        &[],
    );
    assert_eq!(code, 0, "{v:#}");
    let run = &v["runs"][0];
    let l = lanes(run);
    assert_eq!(
        names(&l["KUKA KR15-2"]),
        ["Pick", "Grip", "Retreat", "Pick", "Grip", "Retreat"]
    );
    assert_eq!(names(&l["ABB IRB 1200"]), ["Take", "Take"]);
    assert_eq!(names(&l["UR10e"]), ["Place", "Release", "Place", "Release"]);
    assert_eq!(run["restarts"].as_array().unwrap().len(), 3, "{run:#}");
    // The second Take waits for the second Grip.
    assert!(l["ABB IRB 1200"][1].1 >= l["KUKA KR15-2"][4].2, "{l:?}");
    assert!(run["cycle_s"].as_f64().unwrap() > 2.0 * cycle - 1e-9);

    // The ABB's motions take twice their time, the KUKA starts at 0.5 s.
    let (code, v) = simulate(
        dir,
        "Blackboard.aml",
        "Mix",
        Some(&format!(
            "{inputs}[timing.\"ABB IRB 1200\"]\nmotion_factor = 2\n[timing.\"KUKA KR15-2\"]\nstart_s = 0.5\n"
        )),
        &[],
    );
    assert_eq!(code, 0, "{v:#}");
    let l = lanes(&v["runs"][0]);
    let (take0, take) = (&one["ABB IRB 1200"][0], &l["ABB IRB 1200"][0]);
    assert!(
        ((take.2 - take.1) - 2.0 * (take0.2 - take0.1)).abs() < 1e-9,
        "{take0:?} {take:?}"
    );
    assert!((l["KUKA KR15-2"][0].1 - 0.5).abs() < 1e-9, "{l:?}");
    assert!(v["runs"][0]["cycle_s"].as_f64().unwrap() > cycle + 0.5);

    // Timing errors are located, with the near name.
    for (bad, want) in [
        (
            "[timing.\"ABB IRB 120\"]\nstart_s = 1\n",
            "t.toml:1:9: no controller `ABB IRB 120` in this cell; did you mean `ABB IRB 1200`?",
        ),
        (
            "[timing.\"UR10e\"]\nmotion_factor = 0\n",
            "t.toml:2:17: `motion_factor` is more than 0",
        ),
        ("cycles = 0\n", "t.toml:1:10: `cycles` is 1 to 1,000,000"),
    ] {
        fs::write(dir.join("t.toml"), bad).unwrap();
        let out = skillpost(
            dir,
            &["simulate", "Blackboard.aml", "Mix", "--scenario", "t.toml"],
        );
        assert_eq!(out.status.code(), Some(2), "{bad}");
        assert!(
            text(&out.stderr).contains(want),
            "{bad}: {}",
            text(&out.stderr)
        );
    }
}

/// A chart that waits for the robot's own output (the flow base's `Gripper_Closed`, declared
/// as an output): stuck without it; forced in the scenario, as from the pendant's I/O display,
/// the program runs to its end.
#[test]
fn an_output_named_in_the_scenario_is_forced() {
    let p = common::fixture_project("flow-guarded-sequence");
    let dir = p.path();
    let inputs =
        "[inputs.\"KUKA KR15-2\"]\nPart_OK = true\nMagazine_Empty = false\nRelease = true\n";
    let (code, v) = simulate(dir, "Blackboard.aml", "GuardedSequence", Some(inputs), &[]);
    assert_eq!(code, 1, "{v:#}");
    let ps = problems(&v["runs"][0]);
    assert!(
        ps.len() == 1 && ps[0].0 == "stuck" && ps[0].1.contains("Gripper_Closed"),
        "{ps:?}"
    );
    let (code, v) = simulate(
        dir,
        "Blackboard.aml",
        "GuardedSequence",
        Some(&format!("{inputs}Gripper_Closed = true\n")),
        &[],
    );
    assert_eq!(code, 0, "{v:#}");
    assert_eq!(v["runs"][0]["ended"], true, "{v:#}");
}

/// A wait on a partner that lasts longer than the controller's `HandshakeTimeout` (10 s by
/// default) shows its message on the pendant and takes it away when the wait ends: with the
/// KUKA's motions a thousand times slower its partners wait minutes, and the report lists each
/// message, shown after the wait began and taken away before the waiting program's next step;
/// at the chart's pace no wait lasts that long and no message shows.
#[test]
fn a_wait_that_lasts_shows_its_message_and_takes_it_away() {
    let p = common::fixture_project("cell-kuka-abb-ur");
    let dir = p.path();
    let inputs = "[inputs.\"ABB IRB 1200\"]\nPart_Present = true\n";
    let (code, v) = simulate(dir, "Blackboard.aml", "Mix", Some(inputs), &[]);
    assert_eq!(code, 0, "{v:#}");
    assert_eq!(v["runs"][0]["messages"], serde_json::json!([]), "{v:#}");

    let (code, v) = simulate(
        dir,
        "Blackboard.aml",
        "Mix",
        Some(&format!(
            "{inputs}[timing.\"KUKA KR15-2\"]\nmotion_factor = 1000\n"
        )),
        &[],
    );
    assert_eq!(code, 0, "{v:#}");
    let run = &v["runs"][0];
    let messages = run["messages"].as_array().unwrap();
    assert!(!messages.is_empty(), "{run:#}");
    let l = lanes(run);
    for m in messages {
        let who = m["controller"].as_str().unwrap();
        assert_ne!(who, "KUKA KR15-2", "{m}");
        let (shown, taken) = (
            m["shown_s"].as_f64().unwrap(),
            m["taken_s"].as_f64().unwrap(),
        );
        assert!(shown >= 10.0 && taken > shown, "{m}");
        // Taken away before the program's next step.
        let next = l[who].iter().find(|s| s.1 >= shown);
        assert!(next.is_none_or(|s| s.1 >= taken), "{m} {next:?}");
    }
}

/// Random runs answer a wait for an input the blackboard does not declare: the tutorial's
/// welder waits in its step's code for its weld source (`WaitDI di_WeldDone, 1;`), which random
/// input changes never touch. Every run ends (the world sets the input when every program
/// waits) instead of running to the time limit while the declared inputs keep changing.
#[test]
fn random_runs_answer_a_wait_for_an_undeclared_input() {
    let tmp = tempfile::tempdir().unwrap();
    let step5 = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/tutorial/step5");
    for e in fs::read_dir(&step5).unwrap() {
        let e = e.unwrap();
        fs::copy(e.path(), tmp.path().join(e.file_name())).unwrap();
    }
    let (code, v) = simulate(
        tmp.path(),
        "Blackboard.aml",
        "Cell",
        None,
        &["--runs", "20"],
    );
    assert_eq!(code, 0, "{v:#}");
    assert_eq!(v["problems"], 0, "{v:#}");
    assert_eq!(v["runs"][0]["ended"], true, "{v:#}");
    let welds = v["runs"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["ended"] == true)
        .count();
    assert_eq!(welds, 20, "{v:#}");
}

/// A wait for a step's time beyond a limit (`S.t > T#1500ms`) ends one tick of the controller's
/// clock after the limit, in every language: KRL's `$TIMER` counts whole milliseconds, a RAPID
/// clock is read to the millisecond, a URScript counter grows once a control cycle. (A wait
/// that woke at the limit itself, found the comparison false and looked no more was reported
/// stuck.)
#[test]
fn a_wait_for_a_step_time_beyond_a_limit_ends_just_after_it_in_every_language() {
    for (fixture, bb, program, line, step, next, tick) in [
        (
            "flow-step-time",
            "Blackboard.aml",
            "StepTime",
            83,
            "Grip",
            "Retreat",
            0.001,
        ),
        (
            "abb-irb1200",
            "Cell.aml",
            "Palletize",
            55,
            "Pick",
            "Grip",
            0.001,
        ),
        ("ur10e", "Cell.aml", "Palletize", 55, "Pick", "Grip", 0.002),
    ] {
        let p = common::fixture_project(fixture);
        let dir = p.path();
        let sfc = dir.join("sfc.xml");
        let mut lines: Vec<String> = fs::read_to_string(&sfc)
            .unwrap()
            .lines()
            .map(str::to_owned)
            .collect();
        let l = &mut lines[line - 1];
        let at = l.find("<xhtml:p>").unwrap() + 9;
        let end = l.find("</xhtml:p>").unwrap();
        l.replace_range(at..end, &format!("{step}.t &gt; T#1500ms"));
        fs::write(&sfc, lines.join("\n")).unwrap();
        let (_, v) = simulate(dir, bb, program, Some("[inputs]\n"), &[]);
        let run = &v["runs"][0];
        let steps = lanes(run).into_values().next().unwrap();
        let at = |name: &str| {
            steps
                .iter()
                .find(|s| s.0 == name)
                .unwrap_or_else(|| panic!("{fixture}: {name} never runs: {run:#}"))
                .1
        };
        let waited = at(next) - at(step);
        assert!(
            (waited - (1.5 + tick)).abs() < 1e-6,
            "{fixture}: {next} {waited} s after {step} began: {run:#}"
        );
    }
}

/// A step's code that moves to a point the program does not declare (`PTP XService` in an
/// IRL definition, the point kept in another file) is a fault at that line, named as written;
/// KSS's own home position (`XHOME`, declared in `$config.dat`) is not.
#[test]
fn a_motion_to_a_point_the_program_does_not_declare_is_a_fault_at_its_line() {
    let p = common::fixture_project("flow-step-time");
    let dir = p.path();
    let irl = fs::read_to_string(dir.join("kr15-2.irl")).unwrap();
    let lin = "\t\t\tLIN {X, Y, Z, A, B, C}\n";
    assert!(irl.contains(lin));
    let with = |extra: &str| {
        fs::write(
            dir.join("kr15-2.irl"),
            irl.replacen(lin, &format!("{lin}\t\t\t{extra}\n"), 1),
        )
        .unwrap();
        simulate(dir, "Blackboard.aml", "StepTime", Some("[inputs]\n"), &[])
    };
    let (code, v) = with("PTP XService");
    assert_eq!(code, 1, "{v:#}");
    let run = &v["runs"][0];
    let faults: Vec<_> = problems(run)
        .into_iter()
        .filter(|(kind, _)| kind == "fault")
        .collect();
    assert_eq!(faults.len(), 1, "{run:#}");
    assert!(
        faults[0]
            .1
            .contains("`XService`, which the program does not declare"),
        "{faults:?}"
    );
    let p0 = &run["problems"][0];
    let line = p0["line"].as_u64().expect("the fault's line") as usize;
    let src = fs::read_to_string(dir.join("StepTime.src")).unwrap_or_default();
    // (The simulation writes nothing: the line is the one a compile writes.)
    assert!(src.is_empty(), "simulate wrote StepTime.src");
    let out = skillpost(dir, &["--lf", "Blackboard.aml", "StepTime"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let src = fs::read_to_string(dir.join("StepTime.src")).unwrap();
    assert_eq!(
        src.lines().nth(line - 1).map(str::trim),
        Some("PTP XService"),
        "{p0:#}"
    );
    let (code, v) = with("PTP XHOME");
    assert_eq!(code, 0, "{v:#}");
}

/// How often a wait reads its condition (`poll`) decides a step-time window: after `Grip`,
/// `Grip.t < T#150ms AND Part_OK` lifts, else a timeout retreats. `Part_OK` comes 120 ms after
/// `Grip` began (its motion takes 100 ms): read at once, or every 12 ms (KRL's interpreter
/// cycle, `poll = "controller"`), the part is in time; read every 100 ms, the wait first sees
/// it at 200 ms and retreats. A change `after_steps = 1` (when the first step's motion ends)
/// comes in time too; a wrong `poll` is refused at its place.
#[test]
fn a_waits_polling_rate_and_a_change_after_a_count_of_steps_decide_a_step_time_window() {
    let p = common::fixture_project("flow-step-time");
    let dir = p.path();
    let after_grip = |scenario: &str| {
        let (code, v) = simulate(dir, "Blackboard.aml", "StepTime", Some(scenario), &[]);
        assert_eq!(code, 0, "{v:#}");
        let steps = lanes(&v["runs"][0]).into_values().next().unwrap();
        let at = steps.iter().position(|s| s.0 == "Grip").expect("Grip runs");
        steps[at + 1].0.clone()
    };
    let timing = "[timing.\"KUKA KR15-2\"]\nmotion_factor = 0.1\n";
    // Approach 0-0.1 s, Grip 0.1-0.2 s: the part at 0.22 s.
    let part =
        "[[change]]\nat = 0.22\nresource = \"KUKA KR15-2\"\nsignal = \"Part_OK\"\nvalue = true\n";
    assert_eq!(after_grip(&format!("{timing}{part}")), "Lift");
    assert_eq!(
        after_grip(&format!("{timing}poll = \"controller\"\n{part}")),
        "Lift"
    );
    assert_eq!(
        after_grip(&format!("{timing}poll = 0.1\n{part}")),
        "Retreat"
    );
    let counted = "[[change]]\nafter_steps = 1\nresource = \"KUKA KR15-2\"\nsignal = \"Part_OK\"\nvalue = true\n";
    assert_eq!(after_grip(&format!("{timing}{counted}")), "Lift");
    for (bad, want) in [
        (
            format!("{timing}poll = \"fast\"\n"),
            "scenario.toml:3:8: `poll` is seconds",
        ),
        (
            counted.replace("after_steps = 1", "after_steps = 0"),
            "scenario.toml:2:15: `after_steps` is 1 to",
        ),
        (
            counted.replace("after_steps = 1", "after_steps = 1\nat = 2"),
            "give one of `after = \"STEP\"`, `after_steps = N` or `at = SECONDS`",
        ),
    ] {
        fs::write(dir.join("scenario.toml"), &bad).unwrap();
        let out = skillpost(
            dir,
            &[
                "simulate",
                "Blackboard.aml",
                "StepTime",
                "--scenario",
                "scenario.toml",
            ],
        );
        assert_eq!(out.status.code(), Some(2), "{bad}");
        let err = text(&out.stderr);
        assert!(err.contains(want), "{bad}\n{err}");
    }
}

/// A polling wait whose step-time limit falls, by a rounding of the clock, a hair after one of
/// its reads looks again at the next read: it neither spins at that instant until the
/// statement limit nor misses the limit (motions at 30 %: the limits fall between reads).
#[test]
fn a_polling_wait_for_a_step_time_reads_on_past_its_limit() {
    let p = common::fixture_project("flow-step-time");
    let dir = p.path();
    for poll in ["0.01", "0.012", "0.04"] {
        let scenario = format!("[timing.\"KUKA KR15-2\"]\nmotion_factor = 0.3\npoll = {poll}\n");
        let (code, v) = simulate(dir, "Blackboard.aml", "StepTime", Some(&scenario), &[]);
        assert_eq!(code, 0, "poll {poll}: {v:#}");
        let steps = names(&lanes(&v["runs"][0]).into_values().next().unwrap())
            .into_iter()
            .map(str::to_owned)
            .collect::<Vec<_>>();
        assert_eq!(
            steps,
            ["Approach", "Grip", "Retreat", "Settle"],
            "poll {poll}"
        );
    }
}
