//! The emitted control flow, checked by running it, in every robot language (KRL, RAPID,
//! URScript): every `fixtures/ok/flow-*` case is compiled with the binary, and the generated
//! program is run by the product's simulator (`skillpost::simulate`, docs/SIMULATE.md: its
//! readers of the three languages and its machine) under many input sequences
//! (`flow_run/sim.rs` makes each a scenario). The robot's actions (the steps run, in order)
//! must be what the chart means: an independent token player runs the SFC graph itself
//! (IEC 61131-3: a transition fires when its condition holds; a selection takes its first
//! branch, left to right, whose condition holds; simultaneous branches run one after another,
//! left to right; a jump continues at its target step).
//!
//! Every generated KRL program passes the structure check of `common/krl_check.rs`, every
//! script the block check of `common/urscript.rs`, and every RAPID module `rapidchecker` when
//! it is installed (random and retargeted charts: a sample).
//!
//! The chart player and the random chart generator are `flow_run/chart.rs`. A project is
//! switched to a language by its resource's `Language` attribute; the test rewrites the flow
//! base's blackboard so every signal is readable in that language (RAPID: an `Address`
//! `di_<Name>`/`do_<Name>`/`gi_<Name>`; URScript: standard digital I/O by `Number`, the integer
//! group and the `$CYCFLAG` flag through register calls), and the IRL's motion templates so
//! every line is in the language.
//!
//! Besides the fixtures, 150 random structured charts (guarded sequences, selections with empty
//! and unconditional branches, simultaneous branches, loops left by one branch or two that join,
//! loops left early by a selection before the deciding one, endless loops, nested in each
//! other), 120 of them with step times (`S.t`) in transitions after a step, 300 charts with a
//! retargeted jump, and charts holding every form of condition are compiled and run the same
//! way, in each language. The chart player reads the conditions with a reader of its own
//! (independent of the project's ST parser), checked against their meaning written out in
//! Rust. Tests with mutated programs show that each check can fail: the simulator reports a
//! fault (a value of the wrong type, a variable read before it has a value, a motion to a
//! point the program does not declare), or the actions differ from the chart's.
//!
//! Inputs change only when the robot acts: phase `k` of an input sequence holds once `k`
//! actions have run (the last phase holds after; the scenario's `after_steps`). A wait whose
//! condition is false with inputs that cannot change any more is "stuck"; both sides must get
//! stuck at the same place. Endless programs are compared over their first actions. A second
//! run of each sequence has inputs that change every few milliseconds at random and statements
//! that take a millisecond, so a signal changes between a wait and the test after it: the
//! program must still follow the chart's paths.
//!
//! Time is virtual and the same on both sides: an action takes [`ACTION_MS`] (every step's
//! time) and nothing but waiting takes time; a wait whose condition is false reads it again
//! every [`TICK_MS`] (the scenario's `poll`). The player calls a wait stuck when it has not
//! held after [`STUCK_MS`] (at once when it reads no time: the inputs cannot change); the
//! simulator when nothing it reads can change it any more (no step time in a random chart
//! waits longer than 1.5 s). A step's time `S.t` is the time since the step last became active
//! (when the transition before it fired, before its action); the simulator runs KRL's
//! `$TIMER`s, RAPID's clocks and URScript's step-time counters on that clock, each in the
//! steps its controller counts in (1 ms; a URScript counter 2 ms).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

#[path = "common/krl_check.rs"]
mod krl_syntax;
#[allow(dead_code)]
#[path = "common/rapid.rs"]
mod rapid_check;
#[path = "common/urscript.rs"]
mod urscript_check;

#[path = "../benches/common/cell.rs"]
mod cell;
#[path = "flow_run/chart.rs"]
mod chart;
#[path = "flow_run/cosim.rs"]
mod cosim;
#[path = "../benches/common/generator.rs"]
mod generator;
#[path = "flow_run/mutate.rs"]
mod mutate;
#[path = "flow_run/parts.rs"]
mod parts;
#[path = "flow_run/sim.rs"]
mod sim;
#[path = "flow_run/wire.rs"]
mod wire;

use chart::{Chart, ChartGen, Paths, chart_meaning};

/// How many actions are compared at most (endless programs).
const MAX_ACTIONS: usize = 40;

thread_local! {
    /// [`MAX_ACTIONS`], or more for a test that runs a long program through ([`max_actions`]).
    static ACTIONS_CAP: std::cell::Cell<usize> = const { std::cell::Cell::new(MAX_ACTIONS) };
}

/// How many actions a run takes at most (this thread's; [`MAX_ACTIONS`] unless a test set more).
fn max_actions() -> usize {
    ACTIONS_CAP.with(std::cell::Cell::get)
}

/// Virtual time, in milliseconds (the same for the chart player and every interpreter): what
/// an action takes, a wait's tick (a false condition is read again every tick), and how long a
/// wait waits before it is stuck.
const ACTION_MS: i64 = 100;
const TICK_MS: i64 = 10;
const STUCK_MS: i64 = 10_000;

// ---------------------------------------------------------------------------------------------
// The world: signal values per phase
// ---------------------------------------------------------------------------------------------

/// One signal of the flow base (fixtures/base/flow/Blackboard.aml) and how RAPID and URScript
/// read it (KRL: as the base declares it).
struct Sig {
    name: &'static str,
    integer: bool,
    /// RAPID: the configured signal name (`Address`).
    rapid: &'static str,
    /// URScript: the call that reads it (`Number` for standard digital I/O, else `Address`).
    ur: &'static str,
}

const SIGNALS: &[Sig] = &[
    Sig {
        name: "Part_OK",
        integer: false,
        rapid: "di_Part_OK",
        ur: "get_standard_digital_in(1)",
    },
    Sig {
        name: "Magazine_Empty",
        integer: false,
        rapid: "di_Magazine_Empty",
        ur: "get_standard_digital_in(2)",
    },
    Sig {
        name: "Release",
        integer: false,
        rapid: "di_Release",
        ur: "get_standard_digital_in(3)",
    },
    Sig {
        name: "Variant",
        integer: true,
        rapid: "gi_Variant",
        ur: "read_input_integer_register(9)",
    },
    Sig {
        name: "Gripper_Closed",
        integer: false,
        rapid: "do_Gripper_Closed",
        ur: "get_standard_digital_out(5)",
    },
    Sig {
        name: "Door_Closed",
        integer: false,
        rapid: "di_Door_Closed",
        ur: "read_input_boolean_register(3)",
    },
];

/// One phase: each signal's value (booleans as 0/1).
type Phase = BTreeMap<&'static str, i64>;

/// A deterministic pseudo-random sequence (xorshift).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

fn sequences(seed: u64, count: usize) -> Vec<Vec<Phase>> {
    let mut rng = Rng(seed | 1);
    let mut out = Vec::new();
    for _ in 0..count {
        let phases = 1 + (rng.next() % 12) as usize;
        // How often a bit is set in this sequence: 1, 2 or 3 in 4.
        let ones = 1 + rng.next() % 3;
        let mut seq = Vec::new();
        for _ in 0..phases {
            let mut p = Phase::new();
            for s in SIGNALS {
                let v = if s.integer {
                    // Mostly the values the fixtures compare with, sometimes others.
                    [0, 1, 2, 3, 12, 15][(rng.next() % 6) as usize]
                } else {
                    (rng.next() % 4 < ones) as i64
                };
                p.insert(s.name, v);
            }
            seq.push(p);
        }
        out.push(seq);
    }
    out
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Outcome {
    /// The program ended.
    Done,
    /// Waiting for a condition that can no longer change.
    Stuck,
    /// Still running after [`MAX_ACTIONS`] actions.
    Running,
}

// ---------------------------------------------------------------------------------------------
// The languages
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Lang {
    Krl,
    Rapid,
    UrScript,
}

/// A generated program: its main file (and KRL's `.dat`), and the cell the library's compile
/// of its project sees (what the product's simulator runs it on; `None`: a text only checked).
struct Output {
    lang: Lang,
    main: String,
    dat: String,
    cell: Option<std::sync::Arc<skillpost::simulate::Cell>>,
}

impl Output {
    /// Another text of the program, on the same cell.
    fn with(&self, main: String, dat: String) -> Output {
        Output {
            lang: self.lang,
            main,
            dat,
            cell: self.cell.clone(),
        }
    }
}

impl Lang {
    fn ext(self) -> &'static str {
        match self {
            Lang::Krl => "src",
            Lang::Rapid => "mod",
            Lang::UrScript => "script",
        }
    }

    /// The flow base's blackboard in this language: the resource's `Language` and every
    /// signal readable in it.
    fn blackboard(self, text: &str) -> String {
        if self == Lang::Krl {
            return text.to_owned();
        }
        let language = match self {
            Lang::Rapid => "RAPID",
            _ => "URScript",
        };
        let mut out = String::new();
        let mut signal: Option<&Sig> = None;
        let mut found = 0;
        let mut resource = false;
        for l in text.lines() {
            let t = l.trim();
            if let Some(s) = SIGNALS
                .iter()
                .find(|s| t.starts_with(&format!("<ExternalInterface Name=\"{}\"", s.name)))
            {
                signal = Some(s);
                found += 1;
            }
            if let Some(s) = signal {
                let address = match self {
                    Lang::Rapid => Some(s.rapid),
                    _ if s.ur.starts_with("get_standard_digital_") => None,
                    _ => Some(s.ur),
                };
                if let Some(a) = address {
                    let attr = |n: &str| t.starts_with(&format!("<Attribute Name=\"{n}\""));
                    if attr("Number") || attr("Length") || attr("Address") {
                        continue;
                    }
                    if t == "</ExternalInterface>" {
                        out.push_str(&format!(
                            "          <Attribute Name=\"Address\" AttributeDataType=\"xs:string\"><Value>{a}</Value></Attribute>\n"
                        ));
                    }
                }
                if t == "</ExternalInterface>" {
                    signal = None;
                }
            }
            out.push_str(l);
            out.push('\n');
            if t.starts_with("<InternalElement Name=\"KUKA KR15-2\"") {
                resource = true;
                out.push_str(&format!(
                    "        <Attribute Name=\"Language\" AttributeDataType=\"xs:string\"><Value>{language}</Value></Attribute>\n"
                ));
            }
        }
        assert!(resource && found == SIGNALS.len(), "the flow base changed");
        out
    }

    /// The flow base's IRL file in this language: RAPID's and URScript's moves to literal
    /// positions instead of KRL's (they become named points; the syntax checks read every line,
    /// the interpreters hold each motion to its point's declaration).
    fn irl(self, text: &str) -> String {
        let (lin, ptp) = match self {
            Lang::Krl => return text.to_owned(),
            Lang::Rapid => (
                "MoveL [[X, Y, Z], [quat(A, B, C)], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]], v100, fine, tool0;",
                "MoveJ [[X, Y, Z], [quat(A, B, C)], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]], v100, fine, tool0;",
            ),
            Lang::UrScript => ("movel(p[X, Y, Z, A, B, C])", "movej(p[X, Y, Z, A, B, C])"),
        };
        let out = text
            .replace("LIN {X, Y, Z, A, B, C}", lin)
            .replace("PTP {X, Y, Z, A, B, C}", ptp);
        assert!(
            !out.contains("LIN {") && !out.contains("PTP {"),
            "the flow base changed"
        );
        out
    }

    /// A project folder with the flow base in this language.
    fn setup(self, dir: &Path) {
        let base = repo().join("fixtures/base/flow");
        let bb = std::fs::read_to_string(base.join("Blackboard.aml")).unwrap();
        std::fs::write(dir.join("Blackboard.aml"), self.blackboard(&bb)).unwrap();
        let irl = std::fs::read_to_string(base.join("kr15-2.irl")).unwrap();
        std::fs::write(dir.join("kr15-2.irl"), self.irl(&irl)).unwrap();
    }

    /// The program's files, a split program's calls of its parts followed ([`parts`]).
    fn read(self, dir: &Path, program: &str) -> Output {
        let read = |ext: &str| std::fs::read_to_string(dir.join(format!("{program}.{ext}")));
        let (main, dat) = parts::follow(
            self,
            dir,
            read(self.ext()).unwrap(),
            if self == Lang::Krl {
                read("dat").unwrap()
            } else {
                String::new()
            },
        );
        Output {
            lang: self,
            main,
            dat,
            cell: Some(sim::cell(dir, "Blackboard.aml", program)),
        }
    }
}

impl Output {
    /// The language's syntax check of the generated files, one at a time (RAPID's,
    /// `rapidchecker`, runs over batches: [`RapidChecker`]).
    fn syntax(&self, program: &str) -> Result<(), String> {
        match self.lang {
            Lang::Krl => krl_syntax::check_krl(&self.main, &self.dat, program, true),
            Lang::Rapid => Ok(()),
            Lang::UrScript => urscript_check::check_urscript(&self.main),
        }
    }

    /// The program as the product's simulator reads it.
    fn parse(&self) -> sim::Runnable {
        let cell = self.cell.clone().expect("a program of a project");
        sim::Runnable::new(cell, self.lang, &self.main, &self.dat)
    }
}

/// RAPID's syntax check, `rapidchecker` (PyPI; docs/LANGUAGES.md), run once over a batch of modules
/// (it is a Python program: one start per module would be slow), the pinned version of
/// `tests/common/rapid.rs`. Without it the batch is skipped with a note (a failure under
/// `SKILLPOST_STRICT_TESTS=1`). It takes about half a second
/// per module, so of the random and retargeted charts only a sample is checked, unless
/// `SKILLPOST_RAPIDCHECK_ALL=1`.
struct RapidChecker {
    dir: tempfile::TempDir,
    /// Module file and what it is (for the failure message).
    names: Vec<(String, String)>,
}

impl RapidChecker {
    fn new() -> Self {
        RapidChecker {
            dir: tempfile::tempdir().unwrap(),
            names: Vec::new(),
        }
    }

    /// Adds the `k`th module of a long series when it is in the sample (every `every`th).
    fn add_sampled(&mut self, what: &str, output: &Output, k: usize, every: usize) {
        if k.is_multiple_of(every)
            || std::env::var("SKILLPOST_RAPIDCHECK_ALL").as_deref() == Ok("1")
        {
            self.add(what, output);
        }
    }

    fn add(&mut self, what: &str, output: &Output) {
        if output.lang == Lang::Rapid {
            let file = format!("m{}.mod", self.names.len());
            std::fs::write(self.dir.path().join(&file), &output.main).unwrap();
            self.names.push((file, what.to_owned()));
        }
    }

    /// Runs the check (`None`: not installed); `Err` holds its report and the failed modules.
    fn run(&self) -> Option<Result<(), String>> {
        if self.names.is_empty() {
            return Some(Ok(()));
        }
        let python = match rapid_check::rapidchecker_python() {
            Ok(p) => p,
            Err(why) => {
                // Under SKILLPOST_STRICT_TESTS=1 (CI) a missing checker is a failure.
                if std::env::var("SKILLPOST_STRICT_TESTS").as_deref() == Ok("1") {
                    panic!("cannot run the RAPID syntax check: {why}");
                }
                eprintln!("skipped: RAPID syntax check ({why})");
                return None;
            }
        };
        // The pinned rapidchecker (tests/common/rapid.rs), in a folder without a
        // rapidchecker.toml, its output not wrapped.
        let out = Command::new(python)
            .args(["-m", "rapidchecker"])
            .args(self.names.iter().map(|(f, _)| f))
            .current_dir(self.dir.path())
            .env("COLUMNS", "100000")
            .env("NO_COLOR", "1")
            .env("TERM", "dumb")
            .env("PYTHONUTF8", "1")
            .output()
            .unwrap();
        let report = String::from_utf8_lossy(&out.stdout).into_owned()
            + &String::from_utf8_lossy(&out.stderr);
        if out.status.success() {
            return Some(Ok(()));
        }
        let mut msg = String::new();
        for (file, what) in &self.names {
            if report.contains(file.as_str()) {
                let text = std::fs::read_to_string(self.dir.path().join(file)).unwrap();
                msg.push_str(&format!("{file} = {what}:\n{text}\n"));
            }
        }
        Some(Err(format!("{report}\n{msg}")))
    }

    /// Runs the check and fails on an error.
    fn check(&self) {
        if let Some(Err(e)) = self.run() {
            panic!("rapidchecker refuses generated RAPID:\n{e}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The cases
// ---------------------------------------------------------------------------------------------

/// Compiles the project in `dir` with the binary (`--lf Blackboard.aml PROGRAM`); a failure
/// panics with `what` and the compiler's errors.
fn compile_project(dir: &Path, program: &str, what: &str) {
    let out = Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["--lf", "Blackboard.aml", program])
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{what}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn copy_dir(from: &Path, to: &Path) {
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

/// Compiles a flow fixture in `lang`; returns the program's name, its files and the chart.
fn compile(case: &str, lang: Lang) -> (String, Output, Chart) {
    let tmp = tempfile::tempdir().unwrap();
    lang.setup(tmp.path());
    copy_dir(&repo().join("fixtures/ok").join(case), tmp.path());
    let toml = std::fs::read_to_string(tmp.path().join("case.toml")).unwrap();
    let program = toml
        .lines()
        .find_map(|l| l.strip_prefix("program = \""))
        .unwrap()
        .trim_end_matches('"')
        .to_owned();
    compile_project(tmp.path(), &program, &format!("{case} ({lang:?})"));
    let output = lang.read(tmp.path(), &program);
    if let Err(e) = output.syntax(&program) {
        panic!("{case} ({lang:?}): syntax check: {e}\n{}", output.main);
    }
    (program, output, Chart::read(&tmp.path().join("sfc.xml")))
}

/// Runs the program under `count` input sequences against the chart's meaning; returns how
/// many ended in each way.
///
/// Then once more with inputs that change at every read: the program must still follow the
/// chart's paths (every pair of consecutive actions one the chart can produce whatever its
/// conditions, the first and, when it ends, the last action too), so a selection is never
/// passed without taking a branch when a signal changes between the wait and the test.
fn check_compiled(
    case: &str,
    output: &Output,
    chart: &Chart,
    seed: u64,
    count: usize,
) -> BTreeMap<String, usize> {
    let lang = output.lang;
    let text = &output.main;
    let runnable = output.parse();
    let mut seen = BTreeMap::new();
    let all = sequences(seed, count);
    for (k, seq) in all.iter().enumerate() {
        let want = chart_meaning(chart, seq);
        let got = runnable.run(seq, false);
        assert_eq!(
            got, want,
            "{case}: input sequence {k} ({seq:?}): the {lang:?} program (left) does not do what the chart means (right)\n{text}"
        );
        *seen.entry(format!("{:?}", want.1)).or_insert(0) += 1;
    }
    // The chart's paths whatever the conditions.
    let Paths {
        firsts,
        pairs,
        lasts,
    } = chart.paths();
    for (k, seq) in all.iter().enumerate() {
        let (actions, outcome) = runnable.run(seq, true);
        let bad = actions
            .windows(2)
            .find(|w| !pairs.contains(&(w[0].clone(), w[1].clone())));
        assert!(
            bad.is_none(),
            "{case} ({lang:?}): flickering inputs {k}: `{:?}` is no path of the chart (actions {actions:?})\n{text}",
            bad
        );
        if let Some(f) = actions.first() {
            assert!(
                firsts.contains(f),
                "{case} ({lang:?}): flickering inputs {k}: starts with {f}\n{text}"
            );
        }
        if outcome == Outcome::Done {
            assert!(
                lasts.contains(&actions.last().cloned()),
                "{case} ({lang:?}): flickering inputs {k}: ends after {actions:?}\n{text}"
            );
        }
    }
    seen
}

fn run_case(case: &str, lang: Lang) {
    let (_, output, chart) = compile(case, lang);
    let seen = check_compiled(case, &output, &chart, 0x5eed ^ case.len() as u64, 400);
    println!("{case} ({lang:?}): {seen:?}");
}

macro_rules! flow_cases {
    ($($test:ident => $dir:literal,)*) => {
        $(
            /// The fixture in each language.
            mod $test {
                use super::{Lang, run_case};

                #[test]
                fn krl() {
                    run_case($dir, Lang::Krl);
                }

                #[test]
                fn rapid() {
                    run_case($dir, Lang::Rapid);
                }

                #[test]
                fn urscript() {
                    run_case($dir, Lang::UrScript);
                }
            }
        )*
        /// Every flow fixture's RAPID module passes `rapidchecker` (one batch).
        #[test]
        fn every_rapid_flow_fixture_passes_rapidchecker() {
            let mut rapid = RapidChecker::new();
            for case in [$($dir),*] {
                let (_, output, _) = compile(case, Lang::Rapid);
                rapid.add(case, &output);
            }
            rapid.check();
        }

        /// RAPID reads a chart's conditions when the robot stands at the end of the motion
        /// before, as KRL's advance-run stop does (a motion ending in a zone point would
        /// otherwise still run): every wait is `WaitUntil \InPos`, and a selection decided by
        /// an `IF` at once has `WaitTime \InPos, 0;` before it.
        #[test]
        fn rapid_reads_conditions_when_the_robot_stands() {
            let mut decisions = 0;
            for case in [$($dir),*] {
                let (_, output, _) = compile(case, Lang::Rapid);
                let lines: Vec<&str> = output.main.lines().map(str::trim).collect();
                for (i, l) in lines.iter().enumerate() {
                    if l.starts_with("WaitUntil") {
                        assert!(l.starts_with("WaitUntil \\InPos, "), "{case}: `{l}`");
                    }
                    if l.starts_with("! selection localId") {
                        let next = lines[i + 1..].iter().find(|l| !l.starts_with('!')).unwrap();
                        assert!(!next.starts_with("IF "), "{case}: a decision at once: `{next}`");
                        decisions += usize::from(*next == "WaitTime \\InPos, 0;");
                    }
                }
            }
            assert!(decisions >= 3, "{decisions} decisions after WaitTime");
        }

        /// Every flow fixture is run.
        #[test]
        fn every_flow_fixture_is_run() {
            let mut dirs: Vec<String> = std::fs::read_dir(repo().join("fixtures/ok"))
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with("flow-"))
                .collect();
            dirs.sort();
            assert_eq!(dirs, vec![$($dir),*]);
        }
    };
}

flow_cases! {
    flow_codesys_nested_selection => "flow-codesys-nested-selection",
    flow_cyclic => "flow-cyclic",
    flow_guarded_sequence => "flow-guarded-sequence",
    flow_jump_forward => "flow-jump-forward",
    flow_loop_continued => "flow-loop-continued",
    flow_loop_early_exit => "flow-loop-early-exit",
    flow_loop_exit => "flow-loop-exit",
    flow_loop_joined_exits => "flow-loop-joined-exits",
    flow_macro_step => "flow-macro-step",
    flow_nested_loops => "flow-nested-loops",
    flow_parallel_in_selection => "flow-parallel-in-selection",
    flow_reference_condition => "flow-reference-condition",
    flow_selection_in_parallel => "flow-selection-in-parallel",
    flow_selection_three_way => "flow-selection-three-way",
    flow_selection_two_way => "flow-selection-two-way",
    flow_step_time => "flow-step-time",
}

// ---------------------------------------------------------------------------------------------
// Random charts
// ---------------------------------------------------------------------------------------------

/// What each language's random programs must contain in more than 10 charts (the generator
/// reaches every construct).
fn constructs(lang: Lang) -> &'static [&'static str] {
    match lang {
        Lang::Krl => &["LOOP", "SWITCH", "IF ", "WAIT FOR"],
        Lang::Rapid => &[
            "WHILE skp_loop",
            "WHILE TRUE DO",
            "WHILE skp_branch = 0 DO",
            "ELSEIF",
            "WaitUntil",
        ],
        Lang::UrScript => &[
            "while True:",
            "break",
            "while skp_branch == 0:",
            "elif ",
            "while not (",
        ],
    }
}

/// One random chart `text` (`what` names it in messages), compiled by the binary in `lang` in
/// the project `dir`, checked by the language's structure check (RAPID: `rapid` samples it)
/// and run under 60 input sequences against the chart's meaning: the program and how its runs
/// ended, by kind.
fn run_random(
    dir: &Path,
    lang: Lang,
    what: &str,
    text: &str,
    seed: u64,
    rapid: &mut RapidChecker,
) -> (Output, BTreeMap<String, usize>) {
    let sfc = dir.join("sfc.xml");
    std::fs::write(&sfc, text).unwrap();
    compile_project(
        dir,
        "R",
        &format!("{what} does not compile in {lang:?}:\n{text}"),
    );
    let output = lang.read(dir, "R");
    if let Err(e) = output.syntax("R") {
        panic!("{what}: {lang:?} structure check: {e}\n{}", output.main);
    }
    rapid.add_sampled(what, &output, seed as usize, 10);
    let chart = Chart::read(&sfc);
    let seen = check_compiled(what, &output, &chart, seed, 60);
    (output, seen)
}

/// 150 random charts, each compiled by the binary in `lang` and run under 60 input sequences
/// (and again with flickering inputs) against the chart's meaning.
fn random_charts(lang: Lang) {
    let tmp = tempfile::tempdir().unwrap();
    lang.setup(tmp.path());
    let mut shapes = BTreeMap::new();
    let mut rapid = RapidChecker::new();
    for seed in 1..=150u64 {
        let what = format!("random chart {seed}");
        let (output, seen) = run_random(
            tmp.path(),
            lang,
            &what,
            &ChartGen::chart(seed),
            seed,
            &mut rapid,
        );
        for (k, v) in seen {
            *shapes.entry(k).or_insert(0) += v;
        }
        for kw in constructs(lang) {
            if output.main.contains(kw) {
                *shapes.entry((*kw).to_owned()).or_insert(0) += 1;
            }
        }
    }
    rapid.check();
    println!("random charts ({lang:?}): {shapes:?}");
    for kw in constructs(lang) {
        assert!(
            shapes.get(*kw).copied().unwrap_or(0) > 10,
            "{lang:?}: {shapes:?}"
        );
    }
}

#[test]
fn random_charts_do_what_they_mean_krl() {
    random_charts(Lang::Krl);
}

#[test]
fn random_charts_do_what_they_mean_rapid() {
    random_charts(Lang::Rapid);
}

#[test]
fn random_charts_do_what_they_mean_urscript() {
    random_charts(Lang::UrScript);
}

/// How `lang` reads a step's time (the timers of docs/INPUTS.md's step times).
fn step_timer(lang: Lang) -> &'static str {
    match lang {
        Lang::Krl => "$TIMER[",
        Lang::Rapid => "ClkRead(skp_clock",
        Lang::UrScript => "skp_time",
    }
}

/// A step-time window of 150 ms takes the same branch in every language
/// (`fixtures/ok/flow-step-time`: after `Grip`, `Grip.t < T#150ms AND Part_OK` lifts, a
/// timeout retreats). `Part_OK` comes on at a time after `Grip` began (its action takes 100
/// ms, then the selection waits), each controller reading the condition at its own rate (the
/// simulator's `poll = "controller"`: KRL's interpreter cycle of 12 ms, RAPID the wait's
/// `\PollRate`, URScript's control cycle of 2 ms): whenever it comes before 140 ms (the window less RAPID's 40 ms poll rate) all three lift,
/// from 150 ms on all three retreat. RAPID's default rate of 100 ms would read at 100 ms and
/// 200 ms and retreat for a part that came at 120 ms (checked too, so the test can fail).
#[test]
fn a_150_ms_step_time_window_takes_the_same_branch_in_every_language() {
    let quiet: Phase = [("Part_OK", 0), ("Release", 0)].into_iter().collect();
    let part: Phase = [("Part_OK", 1), ("Release", 0)].into_iter().collect();
    let after_grip = |actions: &[String]| -> String {
        let at = actions.iter().position(|a| a == "Grip").expect("Grip runs");
        actions.get(at + 1).cloned().unwrap_or_default()
    };
    for lang in [Lang::Krl, Lang::Rapid, Lang::UrScript] {
        let (_, output, _) = compile("flow-step-time", lang);
        let run = output.parse();
        for delay in [
            0, 40, 99, 100, 101, 110, 120, 130, 139, 140, 150, 151, 200, 1000,
        ] {
            let actions = run.run_timed(&quiet, "Grip", delay, &part);
            let expect = if delay <= 140 { "Lift" } else { "Retreat" };
            assert_eq!(
                after_grip(&actions),
                expect,
                "{lang:?}: Part_OK {delay} ms after Grip began: {actions:?}\n{}",
                output.main
            );
        }
        if lang == Lang::Rapid {
            let slow = output.with(output.main.replace("\\PollRate:=0.04", ""), String::new());
            assert_ne!(slow.main, output.main);
            let actions = slow.parse().run_timed(&quiet, "Grip", 120, &part);
            assert_eq!(after_grip(&actions), "Retreat", "{actions:?}");
        }
    }
}

/// 120 random charts with step times ([`ChartGen::with_step_times`]: the random charts with
/// `S.t` in some transitions after a step), each compiled by the binary in `lang` and run
/// under 60 input sequences against the chart's meaning, the player and the interpreter keeping
/// the same virtual time (waits advance it, a wait that does not come true in 10 s is stuck).
fn random_charts_with_step_times(lang: Lang) {
    let tmp = tempfile::tempdir().unwrap();
    lang.setup(tmp.path());
    let mut seen = BTreeMap::new();
    let mut rapid = RapidChecker::new();
    let mut timed = 0;
    for seed in 1..=120u64 {
        let what = format!("random chart {seed} with step times");
        let text = ChartGen::with_step_times(seed);
        let (output, runs) = run_random(tmp.path(), lang, &what, &text, seed, &mut rapid);
        if output.main.contains(step_timer(lang)) {
            timed += 1;
        }
        for (k, v) in runs {
            *seen.entry(k).or_insert(0) += v;
        }
    }
    rapid.check();
    println!("random charts with step times ({lang:?}): {timed} read a timer, runs {seen:?}");
    assert!(timed > 100, "{lang:?}: {timed} charts read a timer");
}

#[test]
fn random_charts_with_step_times_do_what_they_mean_krl() {
    random_charts_with_step_times(Lang::Krl);
}

#[test]
fn random_charts_with_step_times_do_what_they_mean_rapid() {
    random_charts_with_step_times(Lang::Rapid);
}

#[test]
fn random_charts_with_step_times_do_what_they_mean_urscript() {
    random_charts_with_step_times(Lang::UrScript);
}

/// The random chart `text` of `seed` with one of its jumps sent to a step chosen at random
/// (`None` without a jump).
fn retarget(text: &str, seed: u64) -> Option<String> {
    let steps: Vec<&str> = text
        .match_indices("name=\"S")
        .map(|(i, _)| {
            let rest = &text[i + 6..];
            &rest[..rest.find('"').unwrap()]
        })
        .collect();
    let jumps: Vec<usize> = text
        .match_indices("targetName=\"")
        .map(|(i, _)| i + 12)
        .collect();
    if jumps.is_empty() || steps.is_empty() {
        return None;
    }
    let mut rng = Rng(seed * 7919 + 1);
    let at = jumps[(rng.next() % jumps.len() as u64) as usize];
    let end = at + text[at..].find('"').unwrap();
    let target = steps[(rng.next() % steps.len() as u64) as usize];
    Some(format!("{}{target}{}", &text[..at], &text[end..]))
}

/// Charts that may not be structured: a random chart with one jump retargeted to a random step
/// (forward, into another branch, out of a loop, ...). Every such chart compiles into a program
/// that does what the chart means (docs/INPUTS.md, "Loops and jumps": labels and GOTO in KRL, a
/// state variable in RAPID and URScript), unless the jump enters or leaves a simultaneous
/// branch (an unsafe chart, checked here independently of the compiler): then it is refused
/// with E317 at the jump. Returns which charts compiled and the codes of the refusals. `timed`:
/// the random charts with step times ([`ChartGen::with_step_times`]).
fn retargeted_jumps(lang: Lang, timed: bool) -> (BTreeSet<u64>, BTreeMap<String, usize>) {
    let tmp = tempfile::tempdir().unwrap();
    lang.setup(tmp.path());
    let (mut refused, mut compiled) = (0, BTreeSet::new());
    // Compiled with states (labels and GOTO, or a state variable): flow beyond the structured
    // forms.
    let mut in_states = 0;
    let mut rapid = RapidChecker::new();
    let mut codes = BTreeMap::new();
    for seed in 1..=300u64 {
        let text = if timed {
            ChartGen::with_step_times(seed)
        } else {
            ChartGen::chart(seed)
        };
        let steps: Vec<&str> = text
            .match_indices("name=\"S")
            .map(|(i, _)| {
                let rest = &text[i + 6..];
                &rest[..rest.find('"').unwrap()]
            })
            .collect();
        let jumps: Vec<usize> = text
            .match_indices("targetName=\"")
            .map(|(i, _)| i + 12)
            .collect();
        if jumps.is_empty() || steps.is_empty() {
            continue;
        }
        let mutated = retarget(&text, seed).unwrap();
        let sfc = tmp.path().join("sfc.xml");
        std::fs::write(&sfc, &mutated).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_skillpost"))
            .args(["--lf", "--format", "short", "Blackboard.aml", "R"])
            .current_dir(tmp.path())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        match out.status.code() {
            Some(0) => {
                compiled.insert(seed);
                let output = lang.read(tmp.path(), "R");
                if output.main.contains("skp_s") {
                    in_states += 1;
                }
                output.syntax("R").unwrap_or_else(|e| {
                    panic!("retargeted chart {seed} ({lang:?}): {e}\n{}", output.main)
                });
                rapid.add_sampled(
                    &format!("retargeted chart {seed}"),
                    &output,
                    compiled.len(),
                    4,
                );
                let chart = Chart::read(&sfc);
                check_compiled(
                    &format!("retargeted chart {seed}"),
                    &output,
                    &chart,
                    seed,
                    40,
                );
            }
            Some(1) => {
                refused += 1;
                // Only a jump that enters or leaves a simultaneous branch is refused (IEC
                // 61131-3: an unsafe chart); any other flow compiles (docs/INPUTS.md).
                assert!(
                    !Chart::read(&sfc).jumps_stay_in_their_branches(),
                    "retargeted chart {seed} ({lang:?}) is refused, though its jumps stay in their simultaneous branches:\n{stderr}"
                );
                assert!(
                    stderr.contains("error[E317]") && stderr.contains("simultaneous branch"),
                    "retargeted chart {seed} ({lang:?}): refused for another reason than a jump across simultaneous branches:\n{stderr}"
                );
                for line in stderr.lines() {
                    if let Some(i) = line.find("error[E") {
                        *codes.entry(line[i + 6..i + 10].to_owned()).or_insert(0) += 1;
                    }
                }
                assert!(
                    stderr.contains("sfc.xml:"),
                    "retargeted chart {seed} ({lang:?}): an error without a place:\n{stderr}"
                );
            }
            other => panic!(
                "retargeted chart {seed} ({lang:?}): exit status {other:?}\n{stderr}\n{mutated}"
            ),
        }
    }
    rapid.check();
    println!(
        "retargeted jumps ({lang:?}): {} compiled ({in_states} with states), {refused} refused (each a jump across simultaneous branches): {codes:?}",
        compiled.len()
    );
    assert!(
        compiled.len() > 50 && in_states > 30 && refused > 10,
        "{lang:?}: {} compiled ({in_states} with states), {refused} refused",
        compiled.len()
    );
    (compiled, codes)
}

#[test]
fn retargeted_jumps_are_refused_or_right_krl() {
    retargeted_jumps(Lang::Krl, false);
}

#[test]
fn retargeted_jumps_are_refused_or_right_rapid() {
    retargeted_jumps(Lang::Rapid, false);
}

#[test]
fn retargeted_jumps_are_refused_or_right_urscript() {
    retargeted_jumps(Lang::UrScript, false);
}

/// The same with step times: a step's timer starts right before its action also where the
/// flow goes by states (labels and GOTO, a state variable).
#[test]
fn retargeted_jumps_with_step_times_are_refused_or_right_krl() {
    retargeted_jumps(Lang::Krl, true);
}

#[test]
fn retargeted_jumps_with_step_times_are_refused_or_right_rapid() {
    retargeted_jumps(Lang::Rapid, true);
}

#[test]
fn retargeted_jumps_with_step_times_are_refused_or_right_urscript() {
    retargeted_jumps(Lang::UrScript, true);
}

// ---------------------------------------------------------------------------------------------
// The checks can fail
// ---------------------------------------------------------------------------------------------

/// Whether `f` panics (a check failed).
fn fails(f: impl FnOnce()) -> bool {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).is_err()
}

/// `text` with the first line equal to `line` (trimmed) removed.
fn drop_line(text: &str, line: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let k = lines
        .iter()
        .position(|l| l.trim() == line)
        .unwrap_or_else(|| panic!("no line `{line}` in\n{text}"));
    let mut out: Vec<&str> = lines[..k].to_vec();
    out.extend(&lines[k + 1..]);
    out.join("\n") + "\n"
}

/// Runs a mutated program of the fixture against its chart; `true` when the suite notices
/// (the syntax check, the reader or a run fails).
fn noticed(case: &str, program: &str, chart: &Chart, base: &Output, text: String) -> bool {
    let output = base.with(text, String::new());
    output.syntax(program).is_err()
        || fails(|| {
            check_compiled(case, &output, chart, 7, 100);
        })
}

/// A motion to a point nobody declares — its declaration dropped — is noticed in every
/// language: by the KRL check (the `.dat`), by the RAPID and URScript readers.
#[test]
fn a_motion_to_an_undeclared_point_fails() {
    let case = "flow-loop-early-exit";
    for lang in [Lang::Krl, Lang::Rapid, Lang::UrScript] {
        let (program, out, chart) = compile(case, lang);
        let (file, decl) = match lang {
            Lang::Krl => (&out.dat, "DECL E6POS X"),
            Lang::Rapid => (&out.main, "CONST robtarget p"),
            Lang::UrScript => (&out.main, "global p"),
        };
        let line = file
            .lines()
            .find(|l| l.trim_start().starts_with(decl))
            .unwrap_or_else(|| panic!("{lang:?}: no point in\n{file}"))
            .to_owned();
        let dropped = file.replacen(&format!("{line}\n"), "", 1);
        let output = match lang {
            Lang::Krl => out.with(out.main.clone(), dropped),
            _ => out.with(dropped, out.dat.clone()),
        };
        let caught = output.syntax(&program).is_err()
            || fails(|| {
                check_compiled(case, &output, &chart, 7, 100);
            });
        assert!(caught, "{lang:?}: `{line}` dropped went unnoticed");
        // The program as written runs.
        assert!(out.syntax(&program).is_ok(), "{lang:?}");
        check_compiled(case, &out, &chart, 7, 100);
    }
}

#[test]
fn a_wrong_urscript_program_fails() {
    let case = "flow-loop-early-exit";
    let (program, out, chart) = compile(case, Lang::UrScript);
    let text = out.main.clone();
    assert!(!noticed(case, &program, &chart, &out, text.clone()));
    // A `break` dropped: still a well-formed script, but it goes round again instead of
    // leaving.
    let no_break = drop_line(&text, "break");
    urscript_check::check_urscript(&no_break).unwrap();
    assert!(noticed(case, &program, &chart, &out, no_break));
    // A selection whose branches do not cover every case (`Part_OK`, `NOT Part_OK AND
    // Release`): the program waits for either and records which.
    let case = "flow-selection-two-way";
    let (program, out, chart) = compile(case, Lang::UrScript);
    let text = out.main.clone();
    assert!(!noticed(case, &program, &chart, &out, text.clone()));
    // A parenthesis dropped.
    let at = text.find("((").unwrap();
    let unbalanced = format!("{}{}", &text[..at], &text[at + 1..]);
    assert!(urscript_check::check_urscript(&unbalanced).is_err());
    assert!(noticed(case, &program, &chart, &out, unbalanced));
    // An `end` swapped with the line after it: the branch is run inside the loop that
    // chooses it.
    let lines: Vec<&str> = text.lines().collect();
    let k = lines
        .windows(2)
        .position(|w| w[0].trim() == "end" && w[1].trim().starts_with("if skp_branch"))
        .unwrap();
    let mut swapped = lines.clone();
    swapped.swap(k, k + 1);
    assert!(noticed(
        case,
        &program,
        &chart,
        &out,
        swapped.join("\n") + "\n"
    ));
    // An `end` dropped, a loop's head dropped (its `end` then closes nothing), an `elif`
    // outside an `if`.
    assert!(urscript_check::check_urscript(&drop_line(&text, "end")).is_err());
    assert!(urscript_check::check_urscript(&drop_line(&text, "while skp_branch == 0:")).is_err());
    assert!(urscript_check::check_urscript(&text.replacen("    if ", "    elif ", 1)).is_err());
}

#[test]
fn a_wrong_rapid_program_fails() {
    let case = "flow-loop-early-exit";
    let (program, out, chart) = compile(case, Lang::Rapid);
    let text = out.main.clone();
    assert!(!noticed(case, &program, &chart, &out, text.clone()));
    // The loop's flag not cleared: it goes round again instead of leaving.
    let stays = drop_line(&text, "skp_loop1 := FALSE;");
    assert!(noticed(case, &program, &chart, &out, stays));
    // A selection whose branches do not cover every case (`Part_OK`, `NOT Part_OK AND
    // Release`): the program waits for either and records which.
    let case = "flow-selection-two-way";
    let (program, out, chart) = compile(case, Lang::Rapid);
    let text = out.main.clone();
    assert!(!noticed(case, &program, &chart, &out, text.clone()));
    // The wrong branch recorded.
    let wrong = text.replacen("skp_branch := 2;", "skp_branch := 1;", 1);
    assert_ne!(wrong, text);
    assert!(noticed(case, &program, &chart, &out, wrong));
    // A parenthesis pair dropped: `NOT` inside an expression is a syntax error in RAPID.
    // (`a OR ((NOT b) AND c)` written `a OR NOT ((b) AND c)`.)
    let bare = text.replacen(" OR ((NOT ", " OR NOT ((", 1);
    assert_ne!(bare, text);
    assert!(noticed(case, &program, &chart, &out, bare));
    // A wait for several conditions as the writer wrote it before: `WaitUntil (a) OR (b);`
    // is RAPID, but `rapidchecker` reads `WaitUntil (a)` as a call and refuses the rest.
    let old = text
        .replace("WaitUntil \\InPos, ((", "WaitUntil (")
        .replace(")) \\PollRate:=0.04;\n", ") \\PollRate:=0.04;\n");
    assert_ne!(old, text);
    let mut rapid = RapidChecker::new();
    rapid.add(
        "old wait",
        &Output {
            lang: Lang::Rapid,
            main: old,
            dat: String::new(),
            cell: None,
        },
    );
    if let Some(r) = rapid.run() {
        assert!(r.is_err(), "rapidchecker accepts `WaitUntil (a) OR (b);`");
    }
    // An `ENDIF` swapped with the `ENDWHILE` after it.
    let lines: Vec<&str> = text.lines().collect();
    let k = lines
        .windows(2)
        .position(|w| w[0].trim() == "ENDIF" && w[1].trim() == "ENDWHILE")
        .unwrap();
    let mut swapped = lines.clone();
    swapped.swap(k, k + 1);
    assert!(noticed(
        case,
        &program,
        &chart,
        &out,
        swapped.join("\n") + "\n"
    ));
}

/// Runs a KRL `.src` of the fixture (with its `.dat`) against its chart; `true` when the
/// suite notices (the KRL check or a run fails).
fn krl_noticed(case: &str, program: &str, chart: &Chart, out: &Output, main: String) -> bool {
    let output = out.with(main, out.dat.clone());
    output.syntax(program).is_err()
        || fails(|| {
            check_compiled(case, &output, chart, 7, 100);
        })
}

#[test]
fn a_wrong_krl_program_fails() {
    let case = "flow-loop-early-exit";
    let (program, out, chart) = compile(case, Lang::Krl);
    let run = |main: String| krl_noticed(case, &program, &chart, &out, main);
    assert!(!run(out.main.clone()));
    assert!(run(drop_line(&out.main, "EXIT")));
}

/// Programs with states (flow beyond the structured forms) are checked as closely: a Goto to
/// the wrong state is noticed in every language, so is a state never set (RAPID, URScript) or
/// a label dropped (KRL); a label inside a block a GOTO is outside of is refused by the KRL
/// check.
#[test]
fn a_wrong_program_with_states_fails() {
    let case = "flow-jump-forward";
    // KRL: labels and GOTO.
    let (program, out, chart) = compile(case, Lang::Krl);
    let run = |main: String| krl_noticed(case, &program, &chart, &out, main);
    assert!(!run(out.main.clone()));
    assert!(out.main.contains("GOTO skp_s2"), "{}", out.main);
    assert!(run(out.main.replacen("GOTO skp_s2", "GOTO skp_s1", 1)));
    // (A dropped `GOTO skp_s2` before `skp_s2:` changes nothing; a dropped label does.)
    assert!(run(drop_line(&out.main, "skp_s2:")));
    // A label moved into the block before it: a GOTO would enter the block.
    let lines: Vec<&str> = out.main.lines().collect();
    let k = lines.iter().position(|l| l.trim() == "skp_s2:").unwrap();
    let mut inside: Vec<&str> = lines.clone();
    inside.insert(k, "IF TRUE THEN");
    inside.push("");
    let end = inside.iter().rposition(|l| l.trim() == "END").unwrap();
    inside.insert(end, "ENDIF");
    let inside = inside.join("\n");
    assert!(
        krl_syntax::check_krl(&inside, &out.dat, &program, true).is_err(),
        "{inside}"
    );
    // RAPID and URScript: a state variable.
    for (lang, set, wrong) in [
        (Lang::Rapid, "skp_state := 2;", "skp_state := 1;"),
        (Lang::UrScript, "skp_state = 2", "skp_state = 1"),
    ] {
        let (program, out, chart) = compile(case, lang);
        let text = out.main.clone();
        assert!(!noticed(case, &program, &chart, &out, text.clone()));
        assert!(text.contains(set), "{text}");
        assert!(noticed(
            case,
            &program,
            &chart,
            &out,
            text.replacen(set, wrong, 1)
        ));
        assert!(noticed(case, &program, &chart, &out, drop_line(&text, set)));
    }
}

/// Compiles the chart `text` in `lang` (program `R`); returns its files and the chart.
fn compile_chart(text: &str, lang: Lang) -> (Output, Chart) {
    let tmp = tempfile::tempdir().unwrap();
    lang.setup(tmp.path());
    std::fs::write(tmp.path().join("sfc.xml"), text).unwrap();
    compile_project(tmp.path(), "R", &format!("{lang:?}:\n{text}"));
    (
        lang.read(tmp.path(), "R"),
        Chart::read(&tmp.path().join("sfc.xml")),
    )
}

/// `main` with the start of step `step`'s time (the comment `step time of <step> (` and the
/// lines up to the step's title) changed by `how`: moved after the step's code (`None`), or
/// without its line that starts with `drop` (`Some`).
fn step_time_moved(main: &str, lang: Lang, step: &str, drop: Option<&str>) -> String {
    let comment = match lang {
        Lang::Krl => ";",
        Lang::Rapid => "!",
        Lang::UrScript => "#",
    };
    let lines: Vec<&str> = main.lines().collect();
    let from = lines
        .iter()
        .position(|l| {
            l.trim()
                .starts_with(&format!("{comment}step time of {step} ("))
        })
        .or_else(|| {
            lines.iter().position(|l| {
                l.trim()
                    .starts_with(&format!("{comment} step time of {step} ("))
            })
        })
        .unwrap_or_else(|| panic!("no start of {step}'s time in\n{main}"));
    let title = from
        + lines[from..]
            .iter()
            .position(|l| {
                let l = l.trim();
                match lang {
                    Lang::Krl => l.starts_with(";FOLD ") && l.contains(&format!(" {step}: ")),
                    _ => {
                        l.starts_with(&format!("{comment} step "))
                            && l.contains(&format!(" {step}: "))
                    }
                }
            })
            .unwrap();
    let block: Vec<&str> = lines[from..title].to_vec();
    let mut out: Vec<&str> = lines[..from].to_vec();
    match drop {
        Some(d) => {
            let kept: Vec<&str> = block
                .iter()
                .copied()
                .filter(|l| !l.trim().starts_with(d))
                .collect();
            assert_eq!(kept.len() + 1, block.len(), "one line `{d}…` in {block:?}");
            out.extend(kept);
            out.extend(&lines[title..]);
        }
        None => {
            // The step's code: its FOLD (KRL), its motion lines (RAPID, URScript).
            let mut end = title + 1;
            match lang {
                Lang::Krl => {
                    while !lines[end].trim().starts_with(";ENDFOLD") {
                        end += 1;
                    }
                    end += 1;
                }
                _ => {
                    while ["MoveL", "MoveJ", "movel(", "movej("]
                        .iter()
                        .any(|m| lines[end].trim().starts_with(m))
                    {
                        end += 1;
                    }
                    assert!(end > title + 1, "no motion after {}", lines[title]);
                }
            }
            out.extend(&lines[title..end]);
            out.extend(block);
            out.extend(&lines[end..]);
        }
    }
    out.join("\n") + "\n"
}

/// A step's time must start right before its action, and anew each time the step becomes
/// active: a program whose timer starts after the step's code, or whose reset is dropped, or
/// its whole start, is noticed by the comparison with the chart, in every language
/// ([`ChartGen::step_time_loop`]: a loop whose selection holds only right after the action).
#[test]
fn a_wrong_step_time_fails() {
    let text = ChartGen::step_time_loop();
    for (lang, reset, whole) in [
        (
            Lang::Krl,
            "$TIMER[",
            &["WAIT SEC", "$TIMER[", "$TIMER_STOP["][..],
        ),
        (
            Lang::Rapid,
            "ClkReset",
            &["WaitTime", "ClkReset", "ClkStart"][..],
        ),
        (Lang::UrScript, "skp_time", &["skp_time"][..]),
    ] {
        let (out, chart) = compile_chart(&text, lang);
        if lang == Lang::Krl {
            // The KRL check knows the timers' numbers.
            let at = out.main.find("$TIMER[").unwrap() + 7;
            let end = at + out.main[at..].find(']').unwrap();
            for k in ["0", "65", "x"] {
                let bad = format!("{}{k}{}", &out.main[..at], &out.main[end..]);
                assert!(
                    krl_syntax::check_krl(&bad, &out.dat, "R", true).is_err(),
                    "$TIMER[{k}]"
                );
            }
        }
        let run = |main: String| {
            if lang == Lang::Krl {
                krl_noticed("step time loop", "R", &chart, &out, main)
            } else {
                noticed("step time loop", "R", &chart, &out, main)
            }
        };
        assert!(!run(out.main.clone()), "{lang:?}:\n{}", out.main);
        // The first branch taken, round after round.
        let (actions, outcome) = chart_meaning(&chart, &sequences(7, 1)[0]);
        assert_eq!(&actions[..4], ["S3", "S5", "S8", "S5"], "{lang:?}");
        assert_eq!(outcome, Outcome::Running);
        let moved = step_time_moved(&out.main, lang, "S5", None);
        assert_ne!(moved, out.main);
        assert!(
            run(moved.clone()),
            "{lang:?}: the timer starts after the action:\n{moved}"
        );
        let dropped = step_time_moved(&out.main, lang, "S5", Some(reset));
        assert!(run(dropped.clone()), "{lang:?}: no reset:\n{dropped}");
        let mut none = out.main.clone();
        for w in whole {
            none = step_time_moved(&none, lang, "S5", Some(w));
        }
        assert!(run(none.clone()), "{lang:?}: no start:\n{none}");
    }
}

// ---------------------------------------------------------------------------------------------
// Conditions of every form
// ---------------------------------------------------------------------------------------------

fn bit(p: &Phase, name: &str) -> bool {
    p[name] != 0
}

/// Conditions of every form the ST subset has (XML-escaped as in a chart), each with its
/// meaning written out in Rust: independent of the project's ST parser, whose tree the chart
/// player evaluates.
#[allow(clippy::type_complexity, clippy::nonminimal_bool)]
fn condition_forms() -> Vec<(&'static str, fn(&Phase) -> bool)> {
    vec![
        ("NOT Part_OK = Release", |p| {
            !bit(p, "Part_OK") == bit(p, "Release")
        }),
        ("Part_OK = FALSE", |p| !bit(p, "Part_OK")),
        ("Release = TRUE", |p| bit(p, "Release")),
        ("Variant &lt;&gt; 3 XOR Part_OK", |p| {
            (p["Variant"] != 3) != bit(p, "Part_OK")
        }),
        ("NOT (Variant = 1 OR Release)", |p| {
            !(p["Variant"] == 1 || bit(p, "Release"))
        }),
        (
            "(Part_OK OR Release) AND NOT (Magazine_Empty XOR Door_Closed)",
            |p| {
                (bit(p, "Part_OK") || bit(p, "Release"))
                    && (bit(p, "Magazine_Empty") == bit(p, "Door_Closed"))
            },
        ),
        (
            "Part_OK AND Release OR Magazine_Empty AND NOT Door_Closed",
            |p| {
                bit(p, "Part_OK") && bit(p, "Release")
                    || bit(p, "Magazine_Empty") && !bit(p, "Door_Closed")
            },
        ),
        ("Part_OK OR Release AND Magazine_Empty", |p| {
            bit(p, "Part_OK") || bit(p, "Release") && bit(p, "Magazine_Empty")
        }),
        ("Part_OK XOR Release OR Magazine_Empty", |p| {
            (bit(p, "Part_OK") != bit(p, "Release")) || bit(p, "Magazine_Empty")
        }),
        ("Part_OK OR Release XOR Magazine_Empty", |p| {
            bit(p, "Part_OK") || (bit(p, "Release") != bit(p, "Magazine_Empty"))
        }),
        ("Part_OK XOR Release XOR Door_Closed", |p| {
            (bit(p, "Part_OK") != bit(p, "Release")) != bit(p, "Door_Closed")
        }),
        ("Part_OK XOR Release AND Door_Closed", |p| {
            bit(p, "Part_OK") != (bit(p, "Release") && bit(p, "Door_Closed"))
        }),
        ("Part_OK &amp; NOT Gripper_Closed", |p| {
            bit(p, "Part_OK") && !bit(p, "Gripper_Closed")
        }),
        ("-Variant &lt; -2", |p| -p["Variant"] < -2),
        ("Variant &gt; 1 = Part_OK", |p| {
            (p["Variant"] > 1) == bit(p, "Part_OK")
        }),
        ("Variant &lt;= 2 AND Variant &gt;= 1", |p| {
            (1..=2).contains(&p["Variant"])
        }),
        ("NOT NOT Release", |p| bit(p, "Release")),
        ("Variant = 12 OR Variant = 15", |p| {
            p["Variant"] == 12 || p["Variant"] == 15
        }),
        ("Gripper_Closed &lt;&gt; Door_Closed", |p| {
            bit(p, "Gripper_Closed") != bit(p, "Door_Closed")
        }),
        ("NOT Part_OK AND NOT Release", |p| {
            !bit(p, "Part_OK") && !bit(p, "Release")
        }),
        ("NOT (Part_OK AND Release) = Door_Closed", |p| {
            !(bit(p, "Part_OK") && bit(p, "Release")) == bit(p, "Door_Closed")
        }),
    ]
}

fn unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&amp;", "&")
}

/// The chart player reads the conditions (with a reader of its own) as their meaning written
/// out.
#[test]
fn the_chart_player_reads_st_with_st_precedence() {
    let forms = condition_forms();
    let started = BTreeMap::new();
    for seq in sequences(11, 60) {
        for p in &seq {
            for (c, f) in &forms {
                let e = chart::Cond::parse(&unescape(c));
                let at = chart::At {
                    phase: p,
                    now: 0,
                    started: &started,
                    timed: Default::default(),
                };
                assert_eq!(e.truth(&at), f(p), "`{c}` under {p:?}");
            }
        }
    }
}

/// Every form of condition, in selections (with and without an unconditional branch) and
/// waits, compiled in `lang` and run against the chart's meaning.
fn conditions(lang: Lang) {
    let forms = condition_forms();
    let tmp = tempfile::tempdir().unwrap();
    lang.setup(tmp.path());
    let mut rapid = RapidChecker::new();
    // A few forms per chart, so the program reaches the waits within the actions compared.
    for (k, group) in forms.chunks(4).enumerate() {
        let conds: Vec<&str> = group.iter().map(|f| f.0).collect();
        let text = ChartGen::conditions(&conds);
        let sfc = tmp.path().join("sfc.xml");
        std::fs::write(&sfc, &text).unwrap();
        compile_project(tmp.path(), "R", &format!("{lang:?}"));
        let output = lang.read(tmp.path(), "R");
        if let Err(e) = output.syntax("R") {
            panic!("conditions ({lang:?}): {e}\n{}", output.main);
        }
        let case = format!("conditions {conds:?}");
        rapid.add(&case, &output);
        let chart = Chart::read(&sfc);
        let seen = check_compiled(&case, &output, &chart, 3 + k as u64, 400);
        println!("{case} ({lang:?}): {seen:?}");
        // The selections always take a branch: every run reaches the waits.
        assert!(!seen.contains_key("Running"), "{case}: {seen:?}");
    }
    rapid.check();
}

#[test]
fn conditions_keep_their_meaning_krl() {
    conditions(Lang::Krl);
}

#[test]
fn conditions_keep_their_meaning_rapid() {
    conditions(Lang::Rapid);
}

#[test]
fn conditions_keep_their_meaning_urscript() {
    conditions(Lang::UrScript);
}

/// A program without its comment lines (KRL `;`, RAPID `!`, URScript `#`; KRL's `;FOLD` lines
/// kept).
fn code(program: &str) -> String {
    program
        .lines()
        .filter(|l| {
            let l = l.trim_start();
            l.starts_with(";FOLD") || l.starts_with(";ENDFOLD") || !l.starts_with([';', '!', '#'])
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Every form of condition drawn instead of written (docs/INPUTS.md, wired conditions: FBD blocks
/// and LD rungs, built from the chart player's reading of the text): compiled in `lang`, the
/// same program as its inline ST twin, and run against the ST chart's meaning.
fn wired_conditions(lang: Lang) {
    let forms = condition_forms();
    let tmp = tempfile::tempdir().unwrap();
    lang.setup(tmp.path());
    let mut rapid = RapidChecker::new();
    let (mut ld, mut fbd) = (0, 0);
    for (k, group) in forms.chunks(4).enumerate() {
        let conds: Vec<&str> = group.iter().map(|f| f.0).collect();
        let text = ChartGen::conditions(&conds);
        let sfc = tmp.path().join("sfc.xml");
        std::fs::write(&sfc, &text).unwrap();
        let chart = Chart::read(&sfc);
        compile_project(tmp.path(), "R", &format!("{lang:?}"));
        let written = lang.read(tmp.path(), "R").main;
        let wired = wire::wire_conditions(&text, k as u64).expect("inline conditions");
        ld += wired.matches("<contact ").count();
        fbd += wired.matches("<block ").count();
        std::fs::write(&sfc, &wired).unwrap();
        let case = format!("wired conditions {conds:?}");
        compile_project(tmp.path(), "R", &format!("{case} ({lang:?})\n{wired}"));
        let output = lang.read(tmp.path(), "R");
        // The same code; only a condition's comment shows the network's text, not the ST's.
        assert_eq!(code(&output.main), code(&written), "{case} ({lang:?})");
        if let Err(e) = output.syntax("R") {
            panic!("{case} ({lang:?}): {e}\n{}", output.main);
        }
        rapid.add(&case, &output);
        let seen = check_compiled(&case, &output, &chart, 3 + k as u64, 400);
        assert!(!seen.contains_key("Running"), "{case}: {seen:?}");
    }
    rapid.check();
    assert!(ld > 10 && fbd > 10, "{ld} contacts, {fbd} blocks");
}

#[test]
fn wired_conditions_keep_their_meaning_krl() {
    wired_conditions(Lang::Krl);
}

#[test]
fn wired_conditions_keep_their_meaning_rapid() {
    wired_conditions(Lang::Rapid);
}

#[test]
fn wired_conditions_keep_their_meaning_urscript() {
    wired_conditions(Lang::UrScript);
}

/// The random charts (and those reading step times) with every condition wired compile to the
/// programs of their inline ST twins, whose runs are checked against the chart above.
#[test]
fn random_charts_with_wired_conditions_are_the_same_programs() {
    let tmp = tempfile::tempdir().unwrap();
    Lang::Krl.setup(tmp.path());
    let compile = |text: &str, what: &str| -> String {
        std::fs::write(tmp.path().join("sfc.xml"), text).unwrap();
        compile_project(tmp.path(), "R", what);
        code(&Lang::Krl.read(tmp.path(), "R").main)
    };
    let mut compared = 0;
    for seed in 1..=150u64 {
        for (kind, text) in [
            ("random chart", ChartGen::chart(seed)),
            (
                "random chart with step times",
                ChartGen::with_step_times(seed),
            ),
        ] {
            let Some(wired) = wire::wire_conditions(&text, seed) else {
                continue;
            };
            let what = format!("{kind} {seed}, wired");
            assert_eq!(
                compile(&wired, &format!("{what}\n{wired}")),
                compile(&text, &what),
                "{what}"
            );
            compared += 1;
        }
    }
    assert!(compared > 200, "{compared} charts with conditions");
}

// ---------------------------------------------------------------------------------------------
// The URScript check
// ---------------------------------------------------------------------------------------------

/// The block-structure check accepts URScript and refuses what is not.
#[test]
fn the_urscript_check_refuses_what_is_not_urscript() {
    let ok = "def P():\n  # c\n  skp_branch = 0\n  while skp_branch == 0:\n    while not ((get_standard_digital_in(1)) or (read_input_integer_register(9) >= -2)):\n      sync()\n    end\n    if get_standard_digital_in(1):\n      skp_branch = 1\n    elif True:\n      skp_branch = 2\n    else:\n      break\n    end\n  end\n  movel(p[0.5, 10, 0, 0, 0, 0], a=1.2, v=0.25)\n  textmsg(\"a # b\")\nend\nP()\n";
    urscript_check::check_urscript(ok).unwrap();
    // Step times: a global counter, a thread that advances it, the thread started.
    let clock = "def P():\n  global skp_time1 = 0.0\n  thread skp_clock():\n    while True:\n      skp_time1 = skp_time1 + get_steptime()\n      sync()\n    end\n  end\n  skp_clock_thread = run skp_clock()\n  skp_time1 = 0.0\n  while not (skp_time1 > 0.35):\n    sync()\n  end\nend\nP()\n";
    urscript_check::check_urscript(clock).unwrap();
    let check = |s: &str| urscript_check::check_urscript(s);
    for (bad, why) in [
        ("def P():\n  elif True:\n  end\nend\n", "elif"),
        (
            "def P():\n  if True:\n  else:\n  else:\n  end\nend\n",
            "else",
        ),
        (
            "def P():\n  if True:\n  else:\n  elif True:\n  end\nend\n",
            "elif",
        ),
        ("def P():\n  break\nend\n", "break"),
        ("def P():\n  if True:\n    break\n  end\nend\n", "break"),
        ("while True:\n  break\nend\n", "outside a function"),
        ("def P():\n  while True:\n  end\n", "ends inside"),
        ("def P():\nend\nend\n", "without a block"),
        ("def P():\n  x = 007\nend\n", "leading zero"),
        ("def P():\n  x = 1e3\nend\n", "malformed number"),
        ("def P():\n  x = 1.\nend\n", "after the point"),
        ("def P():\n  x = {1, 2}\nend\n", "unexpected character"),
        ("def P():\n  if True\n  end\nend\n", "without `:`"),
        ("def P():\n  foo():\nend\n", "opens no block"),
        ("def P():\n  x = end\nend\n", "keyword"),
        ("def P():\n  True = 1\nend\n", "keyword"),
        ("def P():\n  1abc = 2\nend\n", "malformed number"),
        ("def P():\n  movel(p[1, 2)\nend\n", "expected"),
        ("def P():\n  textmsg(\"a)\nend\n", "unterminated"),
        ("def 1f():\nend\n", "malformed"),
        ("def P():\n  x = 1 +\nend\n", "operand"),
        ("def P():\n  x\nend\n", "neither a call"),
        ("def P():\n  end x\nend\n", "alone"),
        ("def P():\n  if (True:\n  end\nend\n", "expected"),
        ("def P():\n  x = $IN[3]\nend\n", "unexpected character"),
        ("def P():\n  LIN {1, 2}\nend\n", "unexpected character"),
        ("def P():\n  t = run f()\nend\n", "thread defined before"),
        (
            "def P():\n  thread f():\n    sync()\n  end\n  t = run f(1)\nend\n",
            "thread defined before",
        ),
        (
            "def P():\n  thread f():\n    sync()\n  end\n  t = 1 + run f()\nend\n",
            "keyword `run`",
        ),
        (
            "def P():\n  if True:\n    thread f():\n    end\n  end\nend\n",
            "inside a block",
        ),
        ("def P():\n  global x\nend\n", "without an assignment"),
    ] {
        match check(bad) {
            Ok(()) => panic!("accepted:\n{bad}"),
            Err(e) => assert!(e.contains(why), "`{e}` does not say `{why}`:\n{bad}"),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Cells: several controllers (docs/CELLS.md)
// ---------------------------------------------------------------------------------------------

/// Random charts put on 2 to 4 KUKA controllers: how many, and runs per chart (each with its
/// own step durations, speeds, start delays and input changes).
const CELL_CHARTS: usize = 100;
const CELL_RUNS: usize = 1_000;
const RESTART_CHARTS: usize = 40;
const RESTART_RUNS: usize = 1_000;

/// Every program of a cell passes the KRL grammar check, and all of them together, co-simulated
/// (`flow_run/cosim.rs`), keep the chart's order whatever the timing: the same branches on every
/// controller, no step before one the chart puts before it has ended, no output set by the
/// advance run, no program waiting for a handshake that never comes.
#[test]
fn cells_keep_the_charts_order_whatever_the_timing() {
    let dir = tempfile::tempdir().unwrap();
    let (mut charts, mut seed, mut programs) = (0, 0u64, 0);
    let mut rapid_sample: Vec<(String, Output)> = Vec::new();
    let mut messages = std::collections::BTreeMap::new();
    // Programs with a tell that says the teller has come past a loop or a selection (after
    // steps of its own since the point the partner waits for).
    let mut passed = std::collections::BTreeMap::new();
    while charts < CELL_CHARTS {
        seed += 1;
        let Some((chart, cell, robot_of, _)) = cosim::random_cell(&dir.path().join("cell"), seed)
        else {
            continue;
        };
        for (k, (p, lang)) in cell.programs.iter().zip(&cell.langs).enumerate() {
            if let Some((main, dat)) = p {
                let name = format!("Cell_R{}", k + 1);
                let output = Output {
                    lang: *lang,
                    main: main.clone(),
                    dat: dat.clone(),
                    cell: None,
                };
                if let Err(e) = output.syntax(&name) {
                    panic!("seed {seed}: {name}: {e}\n{main}");
                }
                if *lang == Lang::Rapid && rapid_sample.len() < 12 {
                    rapid_sample.push((format!("seed {seed} {name}"), output));
                }
                for what in ["has left the loop at", "has passed the selection"] {
                    if main.contains(&format!("that it {what}")) {
                        *passed.entry(what).or_insert(0) += 1;
                    }
                }
                programs += 1;
            }
        }
        match cosim::co_simulate(
            &chart,
            &cell,
            &robot_of,
            seed,
            CELL_RUNS,
            cosim::Mutation::None,
            None,
        ) {
            Ok(r) => {
                for (lang, n) in r.messages {
                    *messages.entry(lang).or_insert(0) += n;
                }
            }
            Err(e) => fail_keeping_cell(&dir.path().join("cell"), "cosim", seed, &e),
        }
        charts += 1;
    }
    assert!(programs >= 2 * CELL_CHARTS);
    // The waits on partners that lasted longer than the robots' `HandshakeTimeout` (50 ms
    // here) showed their message on the pendant in every language, each taken away when its
    // wait ended, and none early (`Report`, checked in every run).
    assert_eq!(messages.len(), 3, "{messages:?}");
    assert!(messages.values().all(|&n| n > 0), "{messages:?}");
    eprintln!("messages of waits that lasted: {messages:?}");
    assert_eq!(
        passed.len(),
        2,
        "tells past a loop or a selection: {passed:?}"
    );
    eprintln!("programs with tells past a construct: {passed:?}");
    // A sample of the RAPID modules through rapidchecker (half a second each).
    let mut checker = RapidChecker::new();
    for (what, output) in &rapid_sample {
        checker.add(what, output);
    }
    checker.check();
}

/// Cells whose chart has a retargeted jump (flow beyond the structured forms, docs/INPUTS.md):
/// every program goes through the same states, and the co-simulation finds the chart's order
/// kept whatever the timing. A chart the compiler refuses must be unsafe (E317: a jump into
/// or out of a simultaneous branch).
#[test]
fn cells_with_states_keep_the_charts_order_whatever_the_timing() {
    let dir = tempfile::tempdir().unwrap();
    let (mut charts, mut with_states, mut seed) = (0, 0, 0u64);
    while charts < CELL_CHARTS / 2 && seed < 2_000 {
        seed += 1;
        let Some(text) = retarget(&ChartGen::chart(seed), seed) else {
            continue;
        };
        let (chart, cell, robot_of, _) =
            match cosim::random_cell_of(&dir.path().join("cell"), seed, &text) {
                Ok(Some(c)) => c,
                Ok(None) => continue,
                Err(e) => {
                    assert!(e.contains("E317"), "seed {seed}: refused: {e}\n{text}");
                    continue;
                }
            };
        for (k, (p, lang)) in cell.programs.iter().zip(&cell.langs).enumerate() {
            if let Some((main, dat)) = p {
                let name = format!("Cell_R{}", k + 1);
                let output = Output {
                    lang: *lang,
                    main: main.clone(),
                    dat: dat.clone(),
                    cell: None,
                };
                if let Err(e) = output.syntax(&name) {
                    panic!("seed {seed}: {name}: {e}\n{main}");
                }
            }
        }
        if cell
            .programs
            .iter()
            .flatten()
            .any(|(main, _)| main.contains("skp_s") || main.contains("skp_state"))
        {
            with_states += 1;
        }
        if let Err(e) = cosim::co_simulate(
            &chart,
            &cell,
            &robot_of,
            seed,
            CELL_RUNS / 2,
            cosim::Mutation::None,
            None,
        ) {
            fail_keeping_cell(&dir.path().join("cell"), "cosim-states", seed, &e);
        }
        charts += 1;
    }
    eprintln!("{charts} cells with a retargeted jump co-simulated, {with_states} with states");
    assert!(
        charts >= CELL_CHARTS / 2 && with_states >= 10,
        "{charts} cells, {with_states} with states"
    );
}

/// The cell fixtures: case, its programs and their languages, their controllers.
type CellFixture = (
    &'static str,
    &'static [(&'static str, Lang)],
    &'static [&'static str],
);
const CELL_FIXTURES: &[CellFixture] = &[
    (
        "cell-two-robots-weld",
        &[
            ("Cell_KUKA_KR15_2", Lang::Krl),
            ("Cell_KUKA_KR16_2", Lang::Krl),
        ],
        &["KUKA KR15-2", "KUKA KR16-2"],
    ),
    (
        "cell-kuka-abb-ur",
        &[
            ("Mix_KUKA_KR15_2", Lang::Krl),
            ("Mix_ABB_IRB_1200", Lang::Rapid),
            ("Mix_UR10e", Lang::UrScript),
        ],
        &["KUKA KR15-2", "ABB IRB 1200", "UR10e"],
    ),
    (
        "cell-two-sequences",
        &[
            ("Cell_KUKA_KR15_2", Lang::Krl),
            ("Cell_KUKA_KR16_2", Lang::Krl),
        ],
        &["KUKA KR15-2", "KUKA KR16-2"],
    ),
    (
        "cell-sequences-mixed",
        &[
            ("Mix_KUKA_KR15_2", Lang::Krl),
            ("Mix_ABB_IRB_1200", Lang::Rapid),
            ("Mix_UR10e", Lang::UrScript),
        ],
        &["KUKA KR15-2", "ABB IRB 1200", "UR10e"],
    ),
    (
        "cell-flow-states",
        &[
            ("Cell_KUKA_KR15_2", Lang::Krl),
            ("Cell_KUKA_KR16_2", Lang::Krl),
        ],
        &["KUKA KR15-2", "KUKA KR16-2"],
    ),
    (
        "cell-tell-at-once",
        &[
            ("Cell_KUKA_KR15_2", Lang::Krl),
            ("Cell_KUKA_KR16_2", Lang::Krl),
        ],
        &["KUKA KR15-2", "KUKA KR16-2"],
    ),
    (
        "cell-eight-wires",
        &[
            ("Cell_KUKA_KR15_2", Lang::Krl),
            ("Cell_KUKA_KR16_2", Lang::Krl),
        ],
        &["KUKA KR15-2", "KUKA KR16-2"],
    ),
    // A split cell (docs/LANGUAGES.md, "Long programs: parts"): its parts' calls followed.
    (
        "split-cell",
        &[
            ("Mix_KUKA_KR15_2", Lang::Krl),
            ("Mix_ABB_IRB_1200", Lang::Rapid),
            ("Mix_UR10e", Lang::UrScript),
        ],
        &["KUKA KR15-2", "ABB IRB 1200", "UR10e"],
    ),
];

/// Tell at once: after Grip the first robot places (PlaceA) while the second welds (Weld),
/// which waits for Grip only. The first robot tells that Grip is done right after Grip, before
/// PlaceA (the branch written first), so Weld can start while PlaceA runs, as `-pF` draws it.
/// (The co-simulation runs the fixture with the others, and checks in every run of every cell
/// that a tell that a step is done comes before the teller's next step.)
#[test]
fn a_tell_stands_right_after_its_step() {
    let dir = tempfile::tempdir().unwrap();
    let (case, programs, controllers) = CELL_FIXTURES[5];
    assert_eq!(case, "cell-tell-at-once");
    let (_, cell, _) = cosim::fixture_cell(&dir.path().join(case), case, programs, controllers);
    let src = &cell.programs[0].as_ref().unwrap().0;
    let at = |what: &str| {
        src.find(what)
            .unwrap_or_else(|| panic!("no `{what}` in\n{src}"))
    };
    assert!(
        at(";handshake: tell KUKA KR16-2 that step 'Grip' (localId 5) is done")
            < at(";FOLD 3 PlaceA"),
        "{src}"
    );
    let flow = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["--validate", "-pF", "Blackboard.aml", "Cell"])
        .current_dir(dir.path().join(case))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&flow.stdout);
    assert!(
        text.contains("2.5      | PlaceA (id=10) + 2")
            && text.contains("2.5      |                                | Weld (id=7) + 4"),
        "{text}"
    );
}

/// The cell fixtures, co-simulated the same way.
#[test]
fn cell_fixtures_keep_the_charts_order_whatever_the_timing() {
    let dir = tempfile::tempdir().unwrap();
    for &(case, programs, controllers) in CELL_FIXTURES {
        let (chart, cell, robot_of) =
            cosim::fixture_cell(&dir.path().join(case), case, programs, controllers);
        assert!(!cell.sim.wires.is_empty(), "{case}: no wires read");
        if let Err(e) = cosim::co_simulate(
            &chart,
            &cell,
            &robot_of,
            7,
            CELL_RUNS,
            cosim::Mutation::None,
            None,
        ) {
            panic!("{case}: {e}");
        }
    }
}

/// A random cell's co-simulation failed: the project is copied where it stays (the temporary
/// folder goes with the test) and the test fails, saying where.
fn fail_keeping_cell(cell: &Path, kind: &str, seed: u64, e: &str) -> ! {
    let keep = std::env::temp_dir().join(format!("skillpost-{kind}-seed-{seed}"));
    let _ = std::fs::remove_dir_all(&keep);
    std::fs::create_dir_all(&keep).unwrap();
    copy_dir(cell, &keep);
    panic!(
        "seed {seed}: {e}\n(the project is kept in {})",
        keep.display()
    );
}

/// A cell that runs shift after shift (docs/CELLS.md, "Starting a cell, faults, second cycles"): random cells
/// of 2-4 controllers in every language, each run (a) three cycles, each program started
/// again after its END in a random order with random delays, and (b) one program started
/// again at a random time mid-cycle, every other one later at a random time: before the
/// starts again a part of one run of the chart (no step after one cut short), after them no
/// step before every partner was started again, then (c) one whole run.
#[test]
fn cells_run_again_and_again_and_survive_restarts() {
    let dir = tempfile::tempdir().unwrap();
    let (mut charts, mut seed) = (0, 0u64);
    let mut langs_seen = std::collections::BTreeSet::new();
    while charts < RESTART_CHARTS {
        seed += 1;
        let Some((chart, cell, robot_of, _)) = cosim::random_cell(&dir.path().join("cell"), seed)
        else {
            continue;
        };
        langs_seen.extend(cell.langs.iter().map(|l| format!("{l:?}")));
        for scenario in [cosim::Scenario::Cycles(3), cosim::Scenario::Fault] {
            if let Err(e) = cosim::co_simulate_in(
                &chart,
                &cell,
                &robot_of,
                seed,
                RESTART_RUNS,
                cosim::Mutation::None,
                None,
                scenario,
            ) {
                fail_keeping_cell(&dir.path().join("cell"), "restart", seed, &e);
            }
        }
        charts += 1;
    }
    assert_eq!(langs_seen.len(), 3, "{langs_seen:?}");
}

/// The restart co-simulation catches a cell without the start barrier (run three cycles) and
/// one whose waits on a partner lack the restart guard (a program started again mid-cycle), in
/// each language: only the programs of that language are broken.
#[test]
fn the_restart_co_simulation_catches_a_missing_barrier_or_guard() {
    let dir = tempfile::tempdir().unwrap();
    for (mutation, scenario) in [
        (cosim::Mutation::NoBarrier, cosim::Scenario::Cycles(3)),
        (cosim::Mutation::NoGuard, cosim::Scenario::Fault),
    ] {
        for lang in [Lang::Krl, Lang::Rapid, Lang::UrScript] {
            let (mut caught, mut tried, mut seed) = (0, 0, 2000);
            while tried < 8 && seed < 2400 {
                seed += 1;
                let Some((chart, cell, robot_of, _)) =
                    cosim::random_cell(&dir.path().join("cell"), seed)
                else {
                    continue;
                };
                let applies = cell.programs.iter().zip(&cell.langs).any(|(p, l)| {
                    *l == lang
                        && p.as_ref()
                            .is_some_and(|(src, _)| src.contains("start barrier"))
                });
                if !applies {
                    continue;
                }
                tried += 1;
                if cosim::co_simulate_in(
                    &chart,
                    &cell,
                    &robot_of,
                    seed,
                    200,
                    mutation,
                    Some(lang),
                    scenario,
                )
                .is_err()
                {
                    caught += 1;
                }
            }
            eprintln!(
                "{mutation:?} in {lang:?} ({scenario:?}): caught in {caught} of {tried} cells"
            );
            assert!(
                caught > 0,
                "{mutation:?} in the {lang:?} programs: caught in none of {tried} cells"
            );
        }
    }
}

/// The cell fixtures, run again and again and started again mid-cycle the same way.
#[test]
fn cell_fixtures_survive_restarts() {
    let dir = tempfile::tempdir().unwrap();
    for &(case, programs, controllers) in CELL_FIXTURES {
        let (chart, cell, robot_of) =
            cosim::fixture_cell(&dir.path().join(case), case, programs, controllers);
        for scenario in [cosim::Scenario::Cycles(3), cosim::Scenario::Fault] {
            if let Err(e) = cosim::co_simulate_in(
                &chart,
                &cell,
                &robot_of,
                11,
                CELL_RUNS,
                cosim::Mutation::None,
                None,
                scenario,
            ) {
                panic!("{case}: {e}");
            }
        }
    }
}

/// The co-simulation catches each way a handshake can be wrong, in each language: a dropped
/// wait, a decision taken again by a follower, an output set while the motion before it runs,
/// a wait's message left on the pendant after the wait, a tell that a step is done moved after
/// the teller's next step (its partner would wait for that step too). Only the programs of one language are
/// broken at a time.
#[test]
fn the_cell_co_simulation_catches_broken_handshakes() {
    let dir = tempfile::tempdir().unwrap();
    for mutation in [
        cosim::Mutation::DroppedWait,
        cosim::Mutation::DecidesTwice,
        cosim::Mutation::AdvanceRun,
        cosim::Mutation::MessageKept,
        cosim::Mutation::TellLate,
    ] {
        for lang in [Lang::Krl, Lang::Rapid, Lang::UrScript] {
            // URScript has no advance run (its moves return at their target).
            if mutation == cosim::Mutation::AdvanceRun && lang == Lang::UrScript {
                continue;
            }
            let (mut caught, mut tried, mut seed) = (0, 0, 1000);
            while tried < 8 && seed < 1400 {
                seed += 1;
                let Some((chart, cell, robot_of, _)) =
                    cosim::random_cell(&dir.path().join("cell"), seed)
                else {
                    continue;
                };
                let applies = cell.programs.iter().zip(&cell.langs).any(|(p, l)| {
                    *l == lang
                        && p.as_ref().is_some_and(|(src, _)| match mutation {
                            cosim::Mutation::DecidesTwice => src.contains("skp_got"),
                            cosim::Mutation::TellLate => cosim::mutate(src, mutation, lang) != *src,
                            _ => src.contains("skp_rx"),
                        })
                });
                if !applies {
                    continue;
                }
                tried += 1;
                if cosim::co_simulate(&chart, &cell, &robot_of, seed, 200, mutation, Some(lang))
                    .is_err()
                {
                    caught += 1;
                }
            }
            eprintln!("{mutation:?} in {lang:?}: caught in {caught} of {tried} cells");
            assert!(
                caught > 0,
                "{mutation:?} in the {lang:?} programs: caught in none of {tried} cells"
            );
        }
    }
}

/// `text` with every jumpStep drawn as a connection instead (docs/INPUTS.md, "a connection back
/// to an earlier step is the same as a jump to it"): the jump goes, and its input becomes a
/// second connection of the target step's `connectionPointIn`. `None` without a jump.
fn jumps_as_connections(text: &str) -> Option<String> {
    let doc = roxmltree::Document::parse(text).unwrap();
    let mut out = text.to_owned();
    let mut any = false;
    // Last first, so the earlier byte ranges stay.
    let mut jumps: Vec<(std::ops::Range<usize>, String, String)> = doc
        .descendants()
        .filter(|n| n.has_tag_name("jumpStep"))
        .map(|j| {
            let input = j
                .descendants()
                .find(|n| n.has_tag_name("connection"))
                .and_then(|c| c.attribute("refLocalId"))
                .unwrap()
                .to_owned();
            (
                j.range(),
                j.attribute("targetName").unwrap().to_owned(),
                input,
            )
        })
        .collect();
    jumps.sort_by_key(|j| std::cmp::Reverse(j.0.start));
    for (range, _, _) in &jumps {
        out.replace_range(range.clone(), "");
    }
    for (_, target, input) in jumps {
        let at = out.find(&format!("name=\"{target}\"")).unwrap();
        let end = out[at..].find("</step>").unwrap() + at;
        let conn = format!("<connection refLocalId=\"{input}\"/>");
        match out[at..end].find("</connectionPointIn>") {
            Some(c) => out.insert_str(at + c, &conn),
            None => out.insert_str(
                end,
                &format!("<connectionPointIn>{conn}</connectionPointIn>"),
            ),
        }
        any = true;
    }
    any.then_some(out)
}

/// Every random chart with loops, drawn with connections back instead of jumps, compiles to
/// the same program but for the loops' comments (the random charts' loops are run against the
/// chart's meaning above).
#[test]
fn random_charts_drawn_with_connections_back_are_the_same_programs() {
    let tmp = tempfile::tempdir().unwrap();
    Lang::Krl.setup(tmp.path());
    let compile = |text: &str| -> String {
        std::fs::write(tmp.path().join("sfc.xml"), text).unwrap();
        compile_project(tmp.path(), "R", text);
        Lang::Krl
            .read(tmp.path(), "R")
            .main
            .lines()
            .filter(|l| {
                let l = l.trim_start();
                !l.starts_with(";loop back") && !l.starts_with(";round again")
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let mut compared = 0;
    for seed in 1..=150u64 {
        let text = ChartGen::chart(seed);
        let Some(circles) = jumps_as_connections(&text) else {
            continue;
        };
        assert_eq!(compile(&text), compile(&circles), "random chart {seed}");
        compared += 1;
    }
    assert!(compared > 30, "{compared} charts with loops");
}
