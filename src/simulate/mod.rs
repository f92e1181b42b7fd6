//! `skillpost simulate` (docs/SIMULATE.md): the cell's programs, as the compile wrote them, run
//! together on a built-in interpreter of the forms skillpost writes and of the IRL snippets'
//! statements, before a robot runs them.
//!
//! - [`ir`]: what runs: flat instructions over resolved expressions, the same for every
//!   language, and the expression reader the language readers share.
//! - [`krl`], [`rapid`], [`urscript`]: each language's program text → [`ir::Program`]. A
//!   statement a reader does not know is kept as [`ir::Ins::Unknown`] (listed once, takes no
//!   time of its own); nothing a program says makes a reader panic.
//! - [`engine`]: the discrete-event machine: controllers, wires, the world's inputs, the
//!   steps' times, the advance run; one run → an [`engine::Outcome`].
//! - [`scenario`]: the scenario file.
//! - [`report`]: text, JSON and Value Change Dump.
//!
//! [`Cell::from_compilation`] takes what a compile made (a split program's parts read after its
//! main file, their routines called in place) and [`simulate`] runs it as often as asked.

pub mod engine;
pub mod ir;
pub mod krl;
pub mod rapid;
pub mod report;
pub mod scenario;
pub mod urscript;

use std::collections::{BTreeSet, HashMap, HashSet};

use crate::compile::Compilation;
use crate::lang::Language;
use crate::model::{ElementKind, SignalKind};
use ir::{IoKeys, Key, Program, Val};

/// A controller of the cell and its program.
#[derive(Debug, Clone)]
pub struct Controller {
    pub name: String,
    pub program: String,
    /// The program's main file (`P.src`), for the places the report names.
    pub file: String,
    pub language: Language,
    /// Its moves return when the motion has ended (URScript).
    pub blocking: bool,
}

/// A wire: the output that drives it, the input it drives (controller, key), its name.
#[derive(Debug, Clone)]
pub struct Wire {
    pub name: String,
    pub from: (usize, Key),
    pub to: (usize, Key),
    /// The signals' names at either end (for the dump).
    pub from_signal: String,
    pub to_signal: String,
}

/// An input of the world (no wire drives it): its resource's signal, and how the controller's
/// program reads it.
#[derive(Debug, Clone)]
pub struct Input {
    pub name: String,
    pub number: Option<i64>,
    pub controller: usize,
    /// The keys its program reads it by (a KRL group: its bits, least significant first).
    pub key: Vec<Key>,
    pub integer: bool,
}

/// A resource of the blackboard: its inputs, and the names of its inputs that are wires.
#[derive(Debug, Clone)]
pub struct Resource {
    pub name: String,
    /// The controller that runs it (`None`: none of the cell's).
    pub controller: Option<usize>,
    pub inputs: Vec<Input>,
    pub wired: Vec<String>,
}

#[derive(Debug, Clone)]
pub struct StepInfo {
    pub duration: Option<f64>,
}

/// What the simulator knows of a cell: its controllers, wires, inputs and chart.
#[derive(Debug, Clone, Default)]
pub struct Cell {
    pub controllers: Vec<Controller>,
    pub wires: Vec<Wire>,
    pub resources: Vec<Resource>,
    /// Every input of the world, flat.
    pub inputs: Vec<Input>,
    /// Every output a resource declares (not a wire's), flat: its name for the report.
    pub outputs: Vec<Input>,
    /// Per input of [`Cell::inputs`]: the numbers the programs compare it with (random runs
    /// give integer inputs these, and their neighbours).
    pub input_values: Vec<Vec<f64>>,
    /// The chart's steps by localId.
    pub steps: HashMap<u64, StepInfo>,
    /// The names of the steps the programs run (for `after = "STEP"`).
    pub step_names: Vec<String>,
    /// Each step's steps before it in the chart (through transitions, branches, joins).
    pub preds: HashMap<u64, Vec<u64>>,
    /// A selection's first transitions: transition localId → the selection's localId.
    pub selection_of: HashMap<u64, u64>,
    /// The chart repeats (a sequence without an end step, or an endless loop).
    pub endless: bool,
    /// Per controller: the keys of its signals and wires (what its program's reader takes
    /// for an input or an output).
    pub io: Vec<IoKeys>,
}

impl Cell {
    /// Controller `k`'s program read from its text (KRL: the `.src` and the `.dat`; a split
    /// program's parts after its main file): a program as it stands on the controller, touched
    /// up or changed by hand, simulated in place of the one the compile wrote.
    pub fn read_program(&self, k: usize, main: &str, dat: &str) -> Program {
        let io = self.io.get(k).cloned().unwrap_or_default();
        read_program(self.controllers[k].language, main, dat, &io)
    }

    pub fn resource(&self, name: &str) -> Option<usize> {
        self.resources
            .iter()
            .position(|r| crate::names::eq(&r.name, name))
    }

    /// How the report names input `key` of controller `c`: `` `Part_Present` on `R` ``.
    pub fn input_name(&self, c: usize, key: &str) -> String {
        for r in &self.resources {
            for i in &r.inputs {
                if i.controller == c && i.key.iter().any(|k| k == key) {
                    return format!("`{}` on {}", i.name, r.name);
                }
            }
        }
        for o in &self.outputs {
            if o.controller == c && o.key.iter().any(|k| k == key) {
                return format!("`{}` (its own output)", o.name);
            }
        }
        format!("`{key}`")
    }
}

/// When a change or restart happens.
#[derive(Debug, Clone, PartialEq)]
pub enum When {
    At(f64),
    /// When the motion of this step (name or localId) ends, the first time it runs.
    After(String),
    /// When the motion of the n-th step the change's (restart's) controller runs ends,
    /// counted from the run's start over every cycle and restart.
    AfterSteps(usize),
}

#[derive(Debug, Clone)]
pub struct Change {
    pub when: When,
    pub controller: usize,
    pub key: Vec<Key>,
    pub value: Val,
}

#[derive(Debug, Clone)]
pub struct Restart {
    pub when: When,
    pub controller: usize,
}

/// How to run: the scenario file's settings, or the random runs' defaults.
#[derive(Debug, Clone)]
pub struct Scenario {
    pub runs: usize,
    pub seed: Option<u64>,
    pub jitter: f64,
    pub default_step_s: f64,
    pub max_time_s: f64,
    pub max_steps: usize,
    pub max_statements: u64,
    /// Inputs at the start: controller, keys, value.
    pub start: Vec<(usize, Vec<Key>, Val)>,
    pub changes: Vec<Change>,
    pub restarts: Vec<Restart>,
    /// Wires crossed (as wired on the shop floor): each pair's inputs swapped.
    pub swaps: Vec<(usize, usize)>,
    /// Random inputs and timing (no scenario file).
    pub random: bool,
    /// Cycles each program runs: after its END the operator starts it again, after a pause of
    /// up to `cycle_pause_s` (at random), until it has run this many.
    pub cycles: usize,
    pub cycle_pause_s: f64,
    /// Per controller: its start, the pace of its motions, the time a statement takes.
    pub timing: HashMap<usize, Timing>,
    /// Random runs: the mean time between two changes of one input (`None`: three steps'
    /// time, 1 s without step times).
    pub change_every_s: Option<f64>,
}

/// How one controller keeps time (a scenario's `[timing.<controller>]`).
#[derive(Debug, Clone, PartialEq)]
pub struct Timing {
    /// When its program starts (seconds); `None`: at 0 (a random run: up to 0.5 s).
    pub start_s: Option<f64>,
    /// Each motion takes this many times its step's time (2: as at 50 % override).
    pub motion_factor: f64,
    /// What each statement besides motions and waits takes (seconds).
    pub statement_s: f64,
    /// How often a wait reads its condition.
    pub poll: Poll,
}

/// How often a controller's waits read their conditions (a scenario's `poll`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Poll {
    /// At once when what a wait reads changes (the picture's timing).
    #[default]
    Exact,
    /// At the wait's start and every so many seconds after.
    Every(f64),
    /// At the controller's own rate: KRL's interpreter cycle (12 ms), RAPID's `\PollRate` of
    /// the wait (0.1 s without), URScript's control cycle (2 ms).
    Controller,
}

impl Default for Timing {
    fn default() -> Timing {
        Timing {
            start_s: None,
            motion_factor: 1.0,
            statement_s: 0.0,
            poll: Poll::Exact,
        }
    }
}

/// Runs without a scenario file.
pub const RANDOM_RUNS: usize = 20;
/// The jitter of random runs: each step's time varies by up to this fraction.
pub const RANDOM_JITTER: f64 = 0.2;

impl Scenario {
    /// A day: the time limit of a run unless its steps take longer (then ten times that).
    pub const DEFAULT_MAX_TIME: f64 = 86_400.0;

    /// The defaults of a scenario file.
    pub fn with_file() -> Scenario {
        Scenario {
            runs: 1,
            seed: None,
            jitter: 0.0,
            default_step_s: 0.0,
            max_time_s: Scenario::DEFAULT_MAX_TIME,
            max_steps: 0,
            max_statements: 0,
            start: Vec::new(),
            changes: Vec::new(),
            restarts: Vec::new(),
            swaps: Vec::new(),
            random: false,
            cycles: 1,
            cycle_pause_s: 0.0,
            timing: HashMap::new(),
            change_every_s: None,
        }
    }

    /// Random runs: random inputs (the world sets what a program waits for), jitter, start
    /// delays.
    pub fn random() -> Scenario {
        Scenario {
            runs: RANDOM_RUNS,
            jitter: RANDOM_JITTER,
            random: true,
            ..Scenario::with_file()
        }
    }
}

/// One step run: on which controller, which chart step, when.
#[derive(Debug, Clone, PartialEq)]
pub struct StepRun {
    pub controller: usize,
    pub local_id: u64,
    pub name: String,
    pub start: f64,
    pub end: f64,
    /// A restart cut its motion short.
    pub cut: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProblemKind {
    /// Programs wait for each other (or for one that ended or stopped).
    Deadlock,
    /// A program waits for an input nothing sets.
    Stuck,
    /// A step started before a step the chart puts before it had ended.
    Order,
    /// A wire set while a motion before it still ran.
    WireInMotion,
    /// Controllers took different branches at one selection.
    Decision,
    /// A program stopped itself (a partner was started again) or faulted.
    Stopped,
    Fault,
    /// The run reached a limit before the programs ended.
    Limit,
    /// A wait's message on the pendant shown before its wait had lasted its time, shown twice,
    /// or still shown when the program went on to a step or ended.
    Message,
    /// A program told a partner that a step was done only after it had started another step:
    /// the partner waits for that one too.
    LateTell,
}

impl ProblemKind {
    pub fn name(self) -> &'static str {
        match self {
            ProblemKind::Deadlock => "deadlock",
            ProblemKind::Stuck => "stuck",
            ProblemKind::Order => "order",
            ProblemKind::WireInMotion => "wire-in-motion",
            ProblemKind::Decision => "decision",
            ProblemKind::Stopped => "stopped",
            ProblemKind::Fault => "fault",
            ProblemKind::Limit => "limit",
            ProblemKind::Message => "message",
            ProblemKind::LateTell => "late-tell",
        }
    }
}

/// A problem of a run, located: controller, line of its program, chart element, time.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    pub kind: ProblemKind,
    pub time: f64,
    pub controller: Option<usize>,
    pub line: Option<u32>,
    pub local_id: Option<u64>,
    pub message: String,
}

/// What `simulate` found over all runs.
#[derive(Debug, Clone, Default)]
pub struct Report {
    pub cell: Cell,
    /// Per run: its seed and outcome (the timeline and changes are kept for the first run and
    /// the first 10 with problems; the others keep their problems and times).
    pub runs: Vec<(u64, engine::Outcome)>,
    /// Statements not simulated: controller, line, text (each once).
    pub not_simulated: Vec<(usize, u32, String)>,
    /// Steps (localId, name) and branches (transition localId, selection localId) that no run
    /// reached.
    pub never_steps: Vec<(u64, String)>,
    pub never_branches: Vec<(u64, Option<u64>)>,
    /// The cycle time of the chart as the picture draws it (the steps' times, no waits).
    pub scenario: Option<String>,
}

impl Report {
    pub fn problems(&self) -> usize {
        self.runs.iter().map(|r| r.1.problems.len()).sum()
    }
}

fn key_of(lang: Language, output: bool, kind: &SignalKind) -> Vec<Key> {
    match (lang, kind) {
        (Language::Krl, SignalKind::Bit(n)) => {
            vec![format!("{}[{n}]", if output { "$OUT" } else { "$IN" })]
        }
        (Language::Krl, SignalKind::Group { number, length }) => (*number
            ..number
                .saturating_add(*length)
                .min(number.saturating_add(64)))
            .map(|k| format!("{}[{k}]", if output { "$OUT" } else { "$IN" }))
            .collect(),
        (Language::Krl | Language::Rapid, SignalKind::Address { text, .. }) => {
            vec![text.to_ascii_uppercase()]
        }
        (Language::UrScript, SignalKind::Bit(n)) => vec![if output {
            format!("set_standard_digital_out({n})")
        } else {
            format!("get_standard_digital_in({n})")
        }],
        (Language::UrScript, SignalKind::Address { text, .. }) => vec![text.replace(' ', "")],
        (_, SignalKind::Bit(n)) => vec![n.to_string()],
        (_, SignalKind::Group { number, .. }) => vec![number.to_string()],
    }
}

/// A reason a cell cannot be simulated.
#[derive(Debug, Clone)]
pub struct CellError(pub String);

impl Cell {
    /// The cell of a compile (without errors) and each controller's program read.
    pub fn from_compilation(c: &Compilation) -> Result<(Cell, Vec<Program>), CellError> {
        let (Some(bb), Some(sfc), Some(plan)) = (&c.blackboard, &c.sfc, &c.plan) else {
            return Err(CellError("the compile kept no model".into()));
        };
        // Controllers: the cell's, else the one that runs the program.
        let ctl_res: Vec<usize> = match &c.cell {
            Some(cell) => cell.controllers.clone(),
            None => {
                let name = c.controller.clone().unwrap_or_default();
                let r = bb
                    .resources
                    .iter()
                    .position(|r| crate::names::eq(&r.name.text, &name))
                    .or_else(|| c.languages.keys().next().map(|&r| bb.controller_of(r)))
                    .ok_or_else(|| CellError("no controller runs the program".into()))?;
                vec![bb.controller_of(r)]
            }
        };
        let mut cell = Cell::default();
        let lang_of = |r: usize| -> Language {
            c.languages
                .get(&r)
                .copied()
                .or_else(|| bb.resources[r].language.as_ref().map(|l| l.0))
                .or(c.language)
                .unwrap_or(Language::Krl)
        };
        let mut io: Vec<IoKeys> = vec![IoKeys::default(); ctl_res.len()];
        let ctl_of = |r: usize| ctl_res.iter().position(|&x| x == bb.controller_of(r));
        for (k, &r) in ctl_res.iter().enumerate() {
            let program = c.program_names.get(k).cloned().unwrap_or_default();
            let language = lang_of(r);
            let file = c
                .outputs
                .iter()
                .zip(&c.output_programs)
                .find(|((_, o), (p, _))| *p == program && o.stem.is_none())
                .and_then(|((path, _), _)| path.file_name())
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_else(|| program.clone());
            cell.controllers.push(Controller {
                name: bb.resources[r].name.text.to_string(),
                program,
                file,
                language,
                blocking: language == Language::UrScript,
            });
        }
        let wired_inputs: HashSet<(usize, usize)> = bb.wires.iter().map(|w| w.to).collect();
        for w in &bb.wires {
            let (Some(a), Some(b)) = (ctl_of(w.from.0), ctl_of(w.to.0)) else {
                continue;
            };
            let (fs, ts) = (
                &bb.resources[w.from.0].signals[w.from.1],
                &bb.resources[w.to.0].signals[w.to.1],
            );
            let fk = key_of(cell.controllers[a].language, true, &fs.kind);
            let tk = key_of(cell.controllers[b].language, false, &ts.kind);
            io[a].outs.extend(fk.iter().cloned());
            io[b].ins.extend(tk.iter().cloned());
            if let (Some(f), Some(t)) = (fk.first(), tk.first()) {
                cell.wires.push(Wire {
                    name: if w.name.is_empty() {
                        format!("{}-{}", fs.name.text, ts.name.text)
                    } else {
                        w.name.clone()
                    },
                    from: (a, f.clone()),
                    to: (b, t.clone()),
                    from_signal: fs.name.text.to_string(),
                    to_signal: ts.name.text.to_string(),
                });
            }
        }
        for (r, res) in bb.resources.iter().enumerate() {
            let mut out = Resource {
                name: res.name.text.to_string(),
                controller: ctl_of(r),
                inputs: Vec::new(),
                wired: Vec::new(),
            };
            let Some(ctl) = ctl_of(r) else {
                cell.resources.push(out);
                continue;
            };
            let lang = cell.controllers[ctl].language;
            for (s, sig) in res.signals.iter().enumerate() {
                let key = key_of(lang, sig.output, &sig.kind);
                if sig.output {
                    io[ctl].outs.extend(key.iter().cloned());
                    cell.outputs.push(Input {
                        name: sig.name.text.to_string(),
                        number: None,
                        controller: ctl,
                        key,
                        integer: sig.is_integer(),
                    });
                    continue;
                }
                io[ctl].ins.extend(key.iter().cloned());
                if wired_inputs.contains(&(r, s)) {
                    out.wired.push(sig.name.text.to_string());
                    continue;
                }
                let number = match &sig.kind {
                    SignalKind::Bit(n) => Some(i64::from(*n)),
                    SignalKind::Group { number, .. } => Some(i64::from(*number)),
                    SignalKind::Address { .. } => None,
                };
                let input = Input {
                    name: sig.name.text.to_string(),
                    number,
                    controller: ctl,
                    key,
                    integer: sig.is_integer(),
                };
                cell.inputs.push(input.clone());
                out.inputs.push(input);
            }
            cell.resources.push(out);
        }
        // The programs, read.
        let mut programs = Vec::new();
        for (k, ctl) in cell.controllers.iter().enumerate() {
            // The main file, then its parts (a split program: each part's routine is called
            // from the main program and read in its place).
            let text_of = |ext: &str| -> String {
                let files = c
                    .outputs
                    .iter()
                    .zip(&c.output_programs)
                    .filter(|((_, o), (p, _))| *p == ctl.program && o.extension == ext);
                let (main, parts): (Vec<_>, Vec<_>) =
                    files.partition(|((_, o), _)| o.stem.is_none());
                main.into_iter()
                    .chain(parts)
                    .map(|((_, o), _)| o.text.as_str())
                    .collect::<Vec<_>>()
                    .join("\n")
            };
            let main = match ctl.language {
                Language::Krl => text_of("src"),
                Language::Rapid => text_of("mod"),
                Language::UrScript => text_of("script"),
            };
            programs.push(read_program(ctl.language, &main, &text_of("dat"), &io[k]));
        }
        cell.io = io;
        // The chart.
        let by_id: HashMap<u64, usize> = sfc
            .elements
            .iter()
            .enumerate()
            .map(|(i, e)| (e.local_id, i))
            .collect();
        for e in &sfc.elements {
            match &e.kind {
                ElementKind::Step(s) => {
                    cell.steps.insert(
                        e.local_id,
                        StepInfo {
                            duration: s.duration,
                        },
                    );
                    // The steps before it, through everything that is not a step.
                    let mut preds = BTreeSet::new();
                    let mut stack: Vec<u64> = inputs_of(e);
                    let mut seen = HashSet::new();
                    while let Some(id) = stack.pop() {
                        if !seen.insert(id) || seen.len() > 10_000 {
                            continue;
                        }
                        let Some(&i) = by_id.get(&id) else { continue };
                        let el = &sfc.elements[i];
                        if el.kind.is_step() {
                            preds.insert(id);
                        } else {
                            stack.extend(inputs_of(el));
                        }
                    }
                    cell.preds.insert(e.local_id, preds.into_iter().collect());
                }
                ElementKind::Transition(_) => {
                    for id in inputs_of(e) {
                        if let Some(&i) = by_id.get(&id)
                            && matches!(sfc.elements[i].kind, ElementKind::SelectionDivergence)
                        {
                            cell.selection_of.insert(e.local_id, id);
                        }
                    }
                }
                _ => {}
            }
        }
        cell.endless = plan.sequences.iter().any(|s| s.1.is_none());
        crate::plan::visit(&plan.body, &mut |b| {
            if let crate::plan::Block::Loop { endless: true, .. } = b {
                cell.endless = true;
            }
        });
        let mut names = BTreeSet::new();
        for p in &programs {
            for (i, _) in &p.ins {
                if let ir::Ins::Step { name, .. } = i {
                    names.insert(name.clone());
                }
            }
        }
        cell.step_names = names.into_iter().collect();
        Ok((cell, programs))
    }
}

fn read_program(language: Language, main: &str, dat: &str, io: &IoKeys) -> Program {
    match language {
        Language::Krl => krl::read(main, dat, io),
        Language::Rapid => rapid::read(main, io),
        Language::UrScript => urscript::read(main, io),
    }
}

fn inputs_of(e: &crate::model::Element) -> Vec<u64> {
    match &e.inputs {
        crate::model::Inputs::None => Vec::new(),
        crate::model::Inputs::One((id, _)) => vec![*id],
        crate::model::Inputs::Many(v) => v.iter().map(|(id, _)| *id).collect(),
    }
}

/// Per input of the world: the numbers the programs compare it with (`Count >= 5`: 5).
pub fn compared_values(cell: &Cell, programs: &[Program]) -> Vec<Vec<f64>> {
    use ir::{Ins, X};
    fn walk(x: &X, out: &mut Vec<(Vec<Key>, f64)>) {
        match x {
            X::Bin(_, a, b) => {
                match (&**a, &**b) {
                    (X::In(k, _), X::Const(v)) | (X::Const(v), X::In(k, _)) => {
                        if let Some(n) = v.num() {
                            out.push((vec![k.clone()], n));
                        }
                    }
                    (X::Group(ks), X::Const(v)) | (X::Const(v), X::Group(ks)) => {
                        if let Some(n) = v.num() {
                            out.push((ks.clone(), n));
                        }
                    }
                    _ => {}
                }
                walk(a, out);
                walk(b, out);
            }
            X::Not(a) | X::Neg(a) => walk(a, out),
            _ => {}
        }
    }
    let mut found: Vec<Vec<(Vec<Key>, f64)>> = vec![Vec::new(); programs.len()];
    for (c, p) in programs.iter().enumerate() {
        for (i, _) in &p.ins {
            if let Ins::Wait { cond: x, .. } | Ins::JumpIfNot(x, _) = i {
                walk(x, &mut found[c]);
            }
        }
    }
    cell.inputs
        .iter()
        .map(|inp| {
            let mut v: Vec<f64> = found
                .get(inp.controller)
                .into_iter()
                .flatten()
                .filter(|(k, _)| *k == inp.key)
                .map(|(_, n)| *n)
                .filter(|n| n.is_finite() && *n >= 0.0 && *n < 1e9)
                .collect();
            v.sort_by(f64::total_cmp);
            v.dedup();
            v.truncate(64);
            v
        })
        .collect()
}

/// Limits of a run that the scenario does not set: proportional to the chart.
fn limits(s: &mut Scenario, cell: &Cell, programs: &[Program]) {
    let steps: usize = programs
        .iter()
        .map(|p| {
            p.ins
                .iter()
                .filter(|i| matches!(i.0, ir::Ins::Step { .. }))
                .count()
        })
        .sum();
    if s.max_steps == 0 {
        s.max_steps = if cell.endless {
            // A chart that repeats: two rounds of every step, at least.
            2 * steps + 2
        } else if s.random {
            // Random inputs may keep a loop going: twenty rounds of every step are enough.
            (20 * steps).max(500)
        } else {
            (100 * steps).max(1000)
        };
    }
    // The time limit: a day, or ten times the steps' time where that is longer.
    if s.max_time_s == Scenario::DEFAULT_MAX_TIME {
        let total: f64 = programs
            .iter()
            .flat_map(|p| &p.ins)
            .filter_map(|i| match &i.0 {
                ir::Ins::Step { local_id, .. } => cell.steps.get(local_id)?.duration,
                _ => None,
            })
            .sum();
        s.max_time_s = s
            .max_time_s
            .max(10.0 * (total + s.default_step_s * steps as f64));
    }
    if s.max_statements == 0 {
        let ins: usize = programs.iter().map(|p| p.ins.len()).sum();
        s.max_statements = (2_000 * ins as u64).clamp(1_000_000, 200_000_000);
    }
}

/// One run of the cell under `scenario` (its swaps aside) from `seed`, with the limits the
/// scenario leaves open set from the programs, and its decisions checked: what each of
/// [`simulate`]'s runs does, for a caller that makes up a scenario for every run.
pub fn run_once(
    cell: &Cell,
    programs: &[Program],
    scenario: &Scenario,
    seed: u64,
) -> engine::Outcome {
    let mut s = scenario.clone();
    limits(&mut s, cell, programs);
    run_checked(cell, programs, &s, seed)
}

/// One run under a scenario whose limits are set, and its decisions checked.
fn run_checked(cell: &Cell, programs: &[Program], s: &Scenario, seed: u64) -> engine::Outcome {
    let mut out = engine::run(cell, programs, s, engine::Rng(seed), s.random);
    decisions(cell, &mut out);
    out
}

/// Runs the cell `runs` times (the scenario's count unless given), from `seed`.
pub fn simulate(
    mut cell: Cell,
    programs: &[Program],
    mut scenario: Scenario,
    runs: Option<usize>,
    seed: Option<u64>,
) -> Report {
    limits(&mut scenario, &cell, programs);
    cell.input_values = compared_values(&cell, programs);
    for &(a, b) in &scenario.swaps {
        let ta = cell.wires[a].to.clone();
        cell.wires[a].to = std::mem::replace(&mut cell.wires[b].to, ta);
    }
    let runs = runs.unwrap_or(scenario.runs).max(1);
    let seed = seed.or(scenario.seed).unwrap_or(0x5EED);
    let mut report = Report::default();
    let mut seen_steps: HashSet<u64> = HashSet::new();
    let mut seen_branches: HashSet<u64> = HashSet::new();
    let mut kept = 0usize;
    let mut seeds = engine::Rng(seed);
    for k in 0..runs {
        let run_seed = if k == 0 { seed } else { seeds.next_u64() };
        let mut out = run_checked(&cell, programs, &scenario, run_seed);
        for s in &out.timeline {
            seen_steps.insert(s.local_id);
        }
        for b in &out.branches {
            seen_branches.insert(b.1);
        }
        let keep = k == 0 || (!out.problems.is_empty() && kept < 10);
        if !out.problems.is_empty() && k != 0 {
            kept += 1;
        }
        if !keep {
            out.timeline = Vec::new();
            out.changes = Vec::new();
            out.branches = Vec::new();
            out.messages = Vec::new();
        }
        report.runs.push((run_seed, out));
    }
    // Every step and branch a program has, in program order, each once.
    let mut all_steps: Vec<(u64, String)> = Vec::new();
    let mut all_branches: Vec<u64> = Vec::new();
    let (mut steps_in, mut branches_in) = (HashSet::new(), HashSet::new());
    for (c, p) in programs.iter().enumerate() {
        for (i, _) in &p.ins {
            match i {
                ir::Ins::Step { local_id, name } if steps_in.insert(*local_id) => {
                    all_steps.push((*local_id, name.clone()));
                }
                ir::Ins::Branch { transition, .. } if branches_in.insert(*transition) => {
                    all_branches.push(*transition);
                }
                _ => {}
            }
        }
        for (text, line) in &p.unknown {
            report.not_simulated.push((c, *line, text.clone()));
        }
    }
    report.never_steps = all_steps
        .into_iter()
        .filter(|s| !seen_steps.contains(&s.0))
        .collect();
    report.never_branches = all_branches
        .into_iter()
        .filter(|t| !seen_branches.contains(t))
        .map(|t| (t, cell.selection_of.get(&t).copied()))
        .collect();
    report.cell = cell;
    report
}

/// Controllers that took different branches at one selection, in the same round of the same
/// start (each start of a program, for its next cycle or after a fault, begins its rounds
/// again).
fn decisions(cell: &Cell, out: &mut engine::Outcome) {
    /// Per controller: the transitions it took, in order, and when.
    type Taken = HashMap<usize, Vec<(u64, f64)>>;
    // (selection, start) → what each controller took there.
    let mut taken: HashMap<(u64, usize), Taken> = HashMap::new();
    for &(c, t, time) in &out.branches {
        if let Some(&sel) = cell.selection_of.get(&t) {
            let start = out
                .restarts
                .iter()
                .filter(|r| r.0 == c && r.1 <= time)
                .count();
            taken
                .entry((sel, start))
                .or_default()
                .entry(c)
                .or_default()
                .push((t, time));
        }
    }
    let mut sels: Vec<_> = taken.into_iter().collect();
    sels.sort_by_key(|s| s.0);
    for ((sel, _), by) in sels {
        let mut ctls: Vec<_> = by.into_iter().collect();
        ctls.sort_by_key(|c| c.0);
        let Some((first_c, first)) = ctls.first().cloned() else {
            continue;
        };
        for (c, list) in &ctls[1..] {
            if let Some((k, (t, time))) = list
                .iter()
                .zip(&first)
                .enumerate()
                .find(|(_, (a, b))| a.0 != b.0)
                .map(|(k, (a, _))| (k, *a))
            {
                out.problems.push(Problem {
                    kind: ProblemKind::Decision,
                    time,
                    controller: Some(*c),
                    line: None,
                    local_id: Some(sel),
                    message: format!(
                        "the selection localId {sel} was decided twice: {} took the branch of transition {} and {} the branch of transition {t} (round {})",
                        cell.controllers[first_c].name,
                        first[k].0,
                        cell.controllers[*c].name,
                        k + 1
                    ),
                });
                break;
            }
        }
    }
}
