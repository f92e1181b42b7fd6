//! The machine: every controller's program at once, a discrete-event simulation. Each
//! controller has its own clock; the one whose clock is earliest runs its next instruction
//! (ties in controller order), so a read of a wire sees every write before it. Statements take
//! no time; a step's motion takes the step's time; waits wait until what they read changes (an
//! output of a partner, an input of the world, a timer that reaches a limit).
//!
//! KRL and RAPID run ahead of their motions (the advance run) until a statement that waits for
//! them (`WAIT FOR`, `WAIT SEC`, RAPID's `\InPos`); a wire set while a motion still runs is a
//! problem. URScript's moves return when the motion has ended.

use std::collections::HashMap;

use super::ir::{Clockish, Ins, Key, Op, Program, Settle, Val, X};
use super::{Cell, Change, Poll, Problem, ProblemKind, Restart, Scenario, StepRun, When};

mod eval;
mod verdict;
mod world;

use eval::EvalError;

/// URScript's control cycle on e-Series (500 Hz): what `sync()` takes.
pub(super) const SYNC_S: f64 = 0.002;
/// KRL's interpreter cycle on a KR C4 (12 ms): how often a `WAIT FOR` reads its condition.
const KRL_CYCLE_S: f64 = 0.012;
/// RAPID's `WaitUntil` without `\PollRate` reads its condition every 0.1 s.
const RAPID_POLL_S: f64 = 0.1;

#[derive(Debug, Clone, PartialEq)]
enum State {
    Running,
    /// Waiting at a wait since `since`; `wake`: when a time limit or timer it reads is up.
    Blocked {
        since: f64,
        wake: Option<f64>,
    },
    Ended,
    /// Stopped until started again: by the program itself (`faulted` false) or by a fault
    /// already reported.
    Halted {
        message: Option<String>,
        faulted: bool,
    },
}

#[derive(Debug, Clone)]
struct Ctl {
    pc: usize,
    t: f64,
    state: State,
    motion_end: f64,
    vars: HashMap<String, Val>,
    /// URScript counters: value and since when it counts.
    counters: HashMap<String, (f64, f64)>,
    /// KRL timers: (ms at t0, t0, running).
    timers: HashMap<u32, (f64, f64, bool)>,
    clocks: HashMap<String, (f64, f64, bool)>,
    outs: HashMap<Key, Val>,
    /// The wait the program is at: its pc and since when (for `\MaxTime`).
    wait_at: Option<(usize, f64)>,
    /// Since when it waits for what a wait's condition names (a watched wait that ran out of
    /// time and the wait after it are one wait).
    waiting_since: Option<f64>,
    note: Option<String>,
    message: Option<String>,
    /// The step whose motion runs, and its index in the timeline.
    running: Option<usize>,
    /// In a step's own code: what takes time there takes the step's time.
    in_step: bool,
    /// Its motions' pace and what a statement takes ([`super::Timing`]).
    factor: f64,
    statement_s: f64,
    /// Cycles still to run after this one (the operator starts it again after its END).
    cycles_left: usize,
    /// Since when a wait's message shows on the pendant.
    shown: Option<f64>,
    /// The last wait ended by its time limit, not by what it waits for.
    timed_out: bool,
    /// The localId of the step it started last in this cycle.
    last_step: Option<u64>,
    /// How often its waits read their conditions.
    poll: Poll,
    /// Steps it has started since the run began (every cycle and restart).
    steps_run: usize,
}

/// What one run produced.
#[derive(Debug, Clone, Default)]
pub struct Outcome {
    pub timeline: Vec<StepRun>,
    pub problems: Vec<Problem>,
    /// Every change of a signal or wire: time, controller, key, value.
    pub changes: Vec<(f64, usize, Key, Val)>,
    /// Branches taken: controller, transition localId, time.
    pub branches: Vec<(usize, u64, f64)>,
    /// Every program ended.
    pub ended: bool,
    /// When the last program ended (its motion included), or when the run stopped.
    pub end_time: f64,
    /// The run stopped at its limit of steps of a chart that repeats.
    pub repeats: bool,
    /// A random run stopped at its limit of steps: its inputs kept a loop going.
    pub capped: bool,
    pub statements: u64,
    /// Programs started again (by the scenario, or for their next cycle): controller, time.
    pub restarts: Vec<(usize, f64)>,
    /// Messages of waits on the pendant: controller, shown, taken away.
    pub messages: Vec<(usize, f64, f64)>,
}

/// SplitMix64: a fixed, portable pseudo-random sequence.
#[derive(Debug, Clone)]
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A number in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A change the world makes at a time.
#[derive(Debug, Clone)]
enum Event {
    Input(usize, Vec<Key>, Val),
    /// An output the scenario forces (as from the pendant's I/O display).
    Force(usize, Key, Val),
    Restart(usize),
    /// A random run: the world changes input `k` of [`Cell::inputs`] now and then.
    Flip(usize),
}

struct Run<'c> {
    cell: &'c Cell,
    programs: &'c [Program],
    ctls: Vec<Ctl>,
    /// Per controller: its inputs of the world by key.
    world: Vec<HashMap<Key, Val>>,
    /// Per controller: input key → (controller, output key) that drives it.
    wired: Vec<HashMap<Key, (usize, Key)>>,
    events: Vec<(f64, Event)>,
    pending_after: Vec<(String, Event, bool)>,
    /// Changes and restarts after a controller's n-th step: controller, n, what.
    pending_count: Vec<(usize, usize, Event)>,
    out: Outcome,
    rng: Rng,
    jitter: f64,
    default_step: f64,
    /// Random runs: the world sets an input a program waits for when all programs wait.
    answering: bool,
    step_limit: usize,
    time_limit: f64,
    /// The mean time between two changes of one input in a random run.
    flip_mean: f64,
    /// The latest run of each step (by localId) in the timeline.
    last_run: HashMap<u64, usize>,
    statement_limit: u64,
    /// Per controller: the localIds of its own steps.
    own_steps: Vec<std::collections::HashSet<u64>>,
    cycle_pause: f64,
}

/// Runs the cell once under `scenario` (its inputs, changes, restarts, jitter), with `rng`.
pub fn run(
    cell: &Cell,
    programs: &[Program],
    scenario: &Scenario,
    rng: Rng,
    random: bool,
) -> Outcome {
    let mut wired = vec![HashMap::new(); cell.controllers.len()];
    for w in &cell.wires {
        wired[w.to.0].insert(w.to.1.clone(), (w.from.0, w.from.1.clone()));
    }
    let mut r = Run {
        cell,
        programs,
        ctls: Vec::new(),
        world: vec![HashMap::new(); cell.controllers.len()],
        wired,
        events: Vec::new(),
        pending_after: Vec::new(),
        pending_count: Vec::new(),
        out: Outcome::default(),
        rng,
        jitter: scenario.jitter,
        default_step: scenario.default_step_s,
        answering: random,
        step_limit: scenario.max_steps,
        time_limit: scenario.max_time_s,
        flip_mean: if let Some(m) = scenario.change_every_s {
            m.max(1e-6)
        } else {
            let (n, sum) = cell
                .steps
                .values()
                .filter_map(|s| s.duration)
                .fold((0usize, 0.0), |(n, s), d| (n + 1, s + d));
            if n == 0 {
                1.0
            } else {
                (3.0 * sum / n as f64).max(0.05)
            }
        },
        last_run: HashMap::new(),
        statement_limit: scenario.max_statements,
        own_steps: programs
            .iter()
            .map(|p| {
                p.ins
                    .iter()
                    .filter_map(|i| match &i.0 {
                        Ins::Step { local_id, .. } => Some(*local_id),
                        _ => None,
                    })
                    .collect()
            })
            .collect(),
        cycle_pause: scenario.cycle_pause_s.max(0.0),
    };
    for (c, _) in cell.controllers.iter().enumerate() {
        let timing = scenario.timing.get(&c).cloned().unwrap_or_default();
        let delay = match timing.start_s {
            Some(s) => s.max(0.0),
            None if random => r.rng.unit() * 0.5,
            None => 0.0,
        };
        let mut ctl = Ctl {
            pc: 0,
            t: delay,
            state: State::Running,
            motion_end: delay,
            vars: HashMap::new(),
            counters: HashMap::new(),
            timers: HashMap::new(),
            clocks: HashMap::new(),
            outs: HashMap::new(),
            wait_at: None,
            waiting_since: None,
            note: None,
            message: None,
            running: None,
            in_step: false,
            factor: timing.motion_factor.max(0.0),
            statement_s: timing.statement_s.max(0.0),
            cycles_left: scenario.cycles.max(1) - 1,
            shown: None,
            timed_out: false,
            last_step: None,
            poll: timing.poll,
            steps_run: 0,
        };
        reset_vars(&mut ctl, &programs[c]);
        r.ctls.push(ctl);
    }
    // The world's inputs at the start.
    for (k, inp) in cell.inputs.iter().enumerate() {
        let v = if random {
            if inp.integer || inp.key.len() > 1 {
                r.random_number(k)
            } else {
                Val::Bool(r.rng.next_u64() & 1 == 1)
            }
        } else if inp.integer {
            Val::Num(0.0)
        } else {
            Val::Bool(false)
        };
        r.set_world(inp.controller, &inp.key, &v, 0.0);
    }
    for (c, key, v) in &scenario.start {
        match r.forced(*c, key) {
            Some(k) => r.force(*c, k, v, 0.0),
            None => r.set_world(*c, key, v, 0.0),
        }
    }
    if random {
        for k in 0..cell.inputs.len() {
            let gap = r.flip_gap();
            r.events.push((gap, Event::Flip(k)));
        }
    }
    for Change {
        when,
        controller,
        key,
        value,
    } in &scenario.changes
    {
        let e = match r.forced(*controller, key) {
            Some(k) => Event::Force(*controller, k.clone(), value.clone()),
            None => Event::Input(*controller, key.clone(), value.clone()),
        };
        r.schedule(when, *controller, e);
    }
    for Restart { when, controller } in &scenario.restarts {
        r.schedule(when, *controller, Event::Restart(*controller));
    }
    r.main_loop();
    r.out
}

fn reset_vars(ctl: &mut Ctl, p: &Program) {
    ctl.vars.clear();
    for (n, v) in &p.init {
        ctl.vars.insert(n.clone(), v.clone());
    }
    ctl.counters.clear();
    for n in &p.counters {
        ctl.counters.insert(n.clone(), (0.0, ctl.t));
    }
    ctl.timers.clear();
    ctl.clocks.clear();
}

impl Run<'_> {
    /// Puts a scenario's change or restart of controller `c` in its place.
    fn schedule(&mut self, when: &When, c: usize, e: Event) {
        match when {
            When::At(t) => self.events.push((*t, e)),
            When::After(step) => self.pending_after.push((step.clone(), e, false)),
            When::AfterSteps(n) => self.pending_count.push((c, *n, e)),
        }
    }

    /// When controller `c`, at a wait since `since`, reads its condition next at or after `t`:
    /// `t` itself, or (a scenario's `poll`) the next instant of its polling after its last
    /// read (its clock now), never that read again.
    fn poll_at(&self, c: usize, since: f64, t: f64) -> f64 {
        let x = &self.ctls[c];
        let period = match x.poll {
            Poll::Exact => return t,
            Poll::Every(p) => p,
            Poll::Controller => match self.cell.controllers[c].language {
                crate::lang::Language::Krl => KRL_CYCLE_S,
                crate::lang::Language::UrScript => SYNC_S,
                crate::lang::Language::Rapid => match self.programs[c].ins.get(x.pc) {
                    Some((Ins::Wait { poll: Some(p), .. }, _)) => *p,
                    _ => RAPID_POLL_S,
                },
            },
        };
        if period <= 0.0 || t <= since {
            return t.max(since);
        }
        let k = ((t - since) / period - 1e-9).ceil().max(0.0);
        let at = since + k * period;
        // (A time a rounding puts on the instant of the last read: the next one.)
        if at <= x.t + 1e-12 && t > x.t {
            since + (k + 1.0) * period
        } else {
            at
        }
    }

    fn main_loop(&mut self) {
        loop {
            if self.out.statements >= self.statement_limit {
                self.limit(format!(
                    "stopped after {} statements (the limit): the programs run on without end",
                    self.statement_limit
                ));
                return;
            }
            if self.out.timeline.len() >= self.step_limit {
                self.out.end_time = self.now();
                if self.cell.endless {
                    self.out.repeats = true;
                } else if self.answering {
                    // Random inputs kept a loop going: no fault of the programs.
                    self.out.capped = true;
                } else {
                    self.limit(format!(
                        "stopped after {} steps (the limit) before the programs ended",
                        self.step_limit
                    ));
                }
                return;
            }
            let next = (0..self.ctls.len())
                .filter_map(|c| self.next_time(c).map(|t| (t, c)))
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            // Nobody waits for the world: its own changes (a random run's) do not matter.
            let world_matters = next.is_some()
                || self.events.iter().any(|e| !matches!(e.1, Event::Flip(_)))
                || self.waits_for_world();
            let next_event = self
                .events
                .iter()
                .filter(|e| world_matters || !matches!(e.1, Event::Flip(_)))
                .map(|e| e.0)
                .min_by(f64::total_cmp);
            match (next, next_event) {
                (Some((t, _)), Some(te)) if te <= t => self.fire_events(te),
                (None, Some(te)) => self.fire_events(te),
                (Some((t, c)), _) => {
                    if t > self.time_limit {
                        self.limit(format!(
                            "stopped at {:.1} s (the time limit) before the programs ended",
                            self.time_limit
                        ));
                        return;
                    }
                    self.exec(c);
                }
                (None, None) => {
                    if self.answering && self.answer() {
                        continue;
                    }
                    self.finish();
                    return;
                }
            }
        }
    }

    /// The inputs `x` reads on controller `c`, a computed one (URScript
    /// `get_standard_digital_in(From_A_1)`) by the number its argument has now.
    fn keys_of(&self, c: usize, x: &X, out: &mut Vec<Key>) {
        match x {
            X::In(k, _) => out.push(k.clone()),
            X::Group(ks) => out.extend(ks.iter().cloned()),
            X::InAt(f, a) => {
                if let Ok(n) = self.eval(c, a) {
                    out.push(format!("{f}({})", n.num().unwrap_or(-1.0) as i64));
                }
            }
            X::Not(a) | X::Neg(a) => self.keys_of(c, a, out),
            X::Bin(_, a, b) => {
                self.keys_of(c, a, out);
                self.keys_of(c, b, out);
            }
            _ => {}
        }
    }

    fn now(&self) -> f64 {
        self.ctls
            .iter()
            .map(|c| c.t.max(c.motion_end))
            .fold(0.0, f64::max)
    }

    fn next_time(&self, c: usize) -> Option<f64> {
        let x = &self.ctls[c];
        match &x.state {
            State::Running => Some(x.t),
            State::Blocked { wake, .. } => wake.map(|w| w.max(x.t)),
            State::Ended | State::Halted { .. } => None,
        }
    }

    fn step_time(&mut self, local_id: u64) -> f64 {
        let base = self
            .cell
            .steps
            .get(&local_id)
            .and_then(|s| s.duration)
            .unwrap_or(self.default_step);
        if self.jitter > 0.0 {
            (base * (1.0 + self.jitter * (2.0 * self.rng.unit() - 1.0))).max(0.0)
        } else {
            base
        }
    }

    /// Runs controller `c`'s next instruction.
    fn exec(&mut self, c: usize) {
        self.out.statements += 1;
        let programs = self.programs;
        let Some((ins, line)) = programs[c].ins.get(self.ctls[c].pc) else {
            self.ctls[c].state = State::Ended;
            return;
        };
        let line = *line;
        let pc_before = self.ctls[c].pc;
        // What a statement takes (a scenario's `statement_s`; none by default).
        let takes_time = self.ctls[c].statement_s > 0.0
            && matches!(
                ins,
                Ins::SetOut(..)
                    | Ins::SetOutAt(..)
                    | Ins::Assign(..)
                    | Ins::TimerSet(..)
                    | Ins::TimerStop(..)
                    | Ins::ClockReset(_)
                    | Ins::ClockStart(_)
                    | Ins::ClockStop(_)
                    | Ins::JumpIfNot(..)
                    | Ins::Jump(_)
                    | Ins::Wait { .. }
                    | Ins::Show(_)
                    | Ins::Clear
            );
        self.exec_one(c, ins, line);
        let x = &mut self.ctls[c];
        if takes_time && x.pc != pc_before && x.state == State::Running && !x.in_step {
            x.t += x.statement_s;
        }
    }

    /// [`Run::exec`]'s work: the instruction `ins` at `line` of controller `c`.
    fn exec_one(&mut self, c: usize, ins: &Ins, line: super::ir::Line) {
        // A wait whose time is up looks again.
        if let Some(wake) = self.wake_of(c)
            && self.ctls[c].t < wake
        {
            self.ctls[c].t = wake;
        }
        self.ctls[c].state = State::Running;
        match ins {
            Ins::Step { local_id, name } => {
                let dur = self.step_time(*local_id) * self.ctls[c].factor;
                if let Some(since) = self.ctls[c].shown {
                    let t = self.ctls[c].t;
                    self.problem_at(
                        c,
                        ProblemKind::Message,
                        line,
                        Some(*local_id),
                        format!(
                            "{} started step {name} at {t:.2} s while a wait's message shown since {since:.2} s was still on the pendant",
                            self.cell.controllers[c].name
                        ),
                    );
                }
                self.ctls[c].last_step = Some(*local_id);
                let x = &mut self.ctls[c];
                let start = x.t.max(x.motion_end);
                x.motion_end = start + dur;
                if self.cell.controllers[c].blocking {
                    x.t = start + dur;
                }
                let i = self.out.timeline.len();
                x.running = Some(i);
                self.out.timeline.push(StepRun {
                    controller: c,
                    local_id: *local_id,
                    name: name.clone(),
                    start,
                    end: start + dur,
                    cut: false,
                });
                self.check_order(i);
                self.last_run.insert(*local_id, i);
                // Changes and restarts "after" this step: when its motion ends.
                let key = crate::names::key(name);
                let id = local_id.to_string();
                for (after, e, done) in &mut self.pending_after {
                    if !*done && (crate::names::key(after) == key || *after == id) {
                        *done = true;
                        self.events.push((start + dur, e.clone()));
                    }
                }
                self.ctls[c].steps_run += 1;
                let n = self.ctls[c].steps_run;
                for (at_c, at_n, e) in &self.pending_count {
                    if *at_c == c && *at_n == n {
                        self.events.push((start + dur, e.clone()));
                    }
                }
                self.ctls[c].in_step = true;
                // A wait in the step's own code is the step's.
                self.ctls[c].note = Some(format!("in step {name} (localId {local_id})"));
                self.ctls[c].pc += 1;
            }
            Ins::StepEnd => {
                self.ctls[c].in_step = false;
                self.ctls[c].pc += 1;
            }
            Ins::Motion(undeclared) => {
                match undeclared.first() {
                    Some(n) => self.fault(
                        c,
                        line,
                        EvalError(format!(
                            "its motion goes to `{n}`, which the program does not declare (declared elsewhere, in `$config.dat` or a system module? the simulator reads only the program's own files)"
                        )),
                    ),
                    None => self.ctls[c].pc += 1,
                }
            }
            Ins::Unknown(_) => self.ctls[c].pc += 1,
            Ins::Note(n) => {
                self.check_tell(c, n, line);
                self.ctls[c].note = Some(n.clone());
                self.ctls[c].pc += 1;
            }
            Ins::Message(m) => {
                self.ctls[c].message = Some(m.clone());
                self.ctls[c].pc += 1;
            }
            Ins::Show(text) => {
                let x = &self.ctls[c];
                let (t, name) = (x.t, &self.cell.controllers[c].name);
                let why = if let Some(since) = x.shown {
                    Some(format!(
                        "{name} showed a second wait message at {t:.2} s while the one shown since {since:.2} s was still on the pendant"
                    ))
                } else if !x.timed_out {
                    Some(format!(
                        "{name} showed the wait message \"{text}\" at {t:.2} s although its wait had not lasted its time"
                    ))
                } else {
                    None
                };
                if let Some(why) = why {
                    self.problem_at(c, ProblemKind::Message, line, None, why);
                }
                let x = &mut self.ctls[c];
                x.shown = Some(x.t);
                x.pc += 1;
            }
            Ins::Clear => {
                let x = &mut self.ctls[c];
                if let Some(since) = x.shown.take() {
                    let t = x.t;
                    self.out.messages.push((c, since, t));
                }
                self.ctls[c].pc += 1;
            }
            Ins::Branch { transition, .. } => {
                let t = self.ctls[c].t;
                self.out.branches.push((c, *transition, t));
                self.ctls[c].pc += 1;
            }
            Ins::Wait {
                cond, settle, max, ..
            } => {
                let x = &mut self.ctls[c];
                if *settle == Settle::Yes && x.t < x.motion_end {
                    x.t = x.motion_end;
                    return;
                }
                let pc = x.pc;
                let since = match x.wait_at {
                    Some((p, s)) if p == pc => s,
                    _ => {
                        x.wait_at = Some((pc, x.t));
                        x.t
                    }
                };
                match self.eval(c, cond) {
                    Err(e) => self.fault(c, line, e),
                    Ok(v) if v.truth() => {
                        // Held for what it names, not for a time limit: the waiting is over.
                        let untimed = self.eval_untimed(c, cond);
                        if untimed {
                            self.ctls[c].waiting_since = None;
                        }
                        self.ctls[c].timed_out = !untimed;
                        if let Some((_, Some(flag))) = max {
                            self.ctls[c].vars.insert(flag.clone(), Val::Bool(false));
                        }
                        let x = &mut self.ctls[c];
                        x.wait_at = None;
                        x.pc += 1;
                    }
                    Ok(_) => {
                        let t = self.ctls[c].t;
                        let deadline = max.as_ref().map(|(s, _)| since + s);
                        if let Some(d) = deadline
                            && t >= d
                        {
                            match max {
                                Some((_, Some(flag))) => {
                                    self.ctls[c].vars.insert(flag.clone(), Val::Bool(true));
                                    let x = &mut self.ctls[c];
                                    x.timed_out = true;
                                    x.wait_at = None;
                                    x.pc += 1;
                                }
                                _ => {
                                    self.ctls[c].state = State::Halted {
                                        message: Some(
                                            "its wait's \\MaxTime ran out (ERR_WAIT_MAXTIME)"
                                                .into(),
                                        ),
                                        faulted: false,
                                    };
                                }
                            }
                            return;
                        }
                        let mut wake = deadline;
                        let mut th = Vec::new();
                        cond.thresholds(&mut th);
                        // A comparison flips when the clock reads its limit (`>=`, `<`) or
                        // one step past it (`>`, `<=`): both are times to look again.
                        for (clock, k) in th {
                            for k in [k, k + eval::resolution(&clock)] {
                                if let Some(w) = self.reaches(c, &clock, k)
                                    && w > t
                                {
                                    wake = Some(wake.map_or(w, |d: f64| d.min(w)));
                                }
                            }
                        }
                        let wake = wake.map(|w| self.poll_at(c, since, w));
                        let x = &mut self.ctls[c];
                        let since = *x.waiting_since.get_or_insert(since);
                        x.state = State::Blocked { since, wake };
                    }
                }
            }
            Ins::Sleep(e, settle) => {
                let x = &self.ctls[c];
                if *settle == Settle::Yes && x.t < x.motion_end {
                    self.ctls[c].t = x.motion_end;
                    return;
                }
                match self.eval(c, e).map(|v| v.num()) {
                    Ok(Some(s)) => {
                        let x = &mut self.ctls[c];
                        if !x.in_step {
                            x.t += s.max(0.0);
                        }
                        x.pc += 1;
                    }
                    Ok(None) => self.fault(c, line, EvalError("a time that is no number".into())),
                    Err(er) => self.fault(c, line, er),
                }
            }
            Ins::Sync => {
                let x = &mut self.ctls[c];
                if !x.in_step {
                    x.t += SYNC_S;
                }
                x.pc += 1;
            }
            Ins::SetOut(k, e) => match self.eval(c, e) {
                Ok(v) => self.set_out(c, k.clone(), v, line),
                Err(er) => self.fault(c, line, er),
            },
            Ins::SetOutAt(f, n, e) => match (self.eval(c, n), self.eval(c, e)) {
                (Ok(n), Ok(v)) => {
                    let k = format!("{f}({})", n.num().unwrap_or(-1.0) as i64);
                    self.set_out(c, k, v, line);
                }
                (Err(er), _) | (_, Err(er)) => self.fault(c, line, er),
            },
            Ins::Assign(n, e) => match self.eval(c, e) {
                Ok(v) => {
                    let x = &mut self.ctls[c];
                    if let Some(ct) = x.counters.get_mut(n) {
                        *ct = (v.num().unwrap_or(0.0), x.t);
                    } else if let Some(old) = x.vars.get_mut(n) {
                        *old = v;
                    } else {
                        x.vars.insert(n.clone(), v);
                    }
                    x.pc += 1;
                }
                Err(er) => self.fault(c, line, er),
            },
            Ins::TimerSet(n, e) => match self.eval(c, e) {
                Ok(v) => {
                    let x = &mut self.ctls[c];
                    let running = x.timers.get(n).is_some_and(|t| t.2);
                    x.timers.insert(*n, (v.num().unwrap_or(0.0), x.t, running));
                    x.pc += 1;
                }
                Err(er) => self.fault(c, line, er),
            },
            Ins::TimerStop(n, e) => match self.eval(c, e) {
                Ok(v) => {
                    let x = &mut self.ctls[c];
                    let now = x.t;
                    let cur = x.timers.get(n).copied().unwrap_or((0.0, now, false));
                    let ms = if cur.2 {
                        cur.0 + (now - cur.1) * 1000.0
                    } else {
                        cur.0
                    };
                    x.timers.insert(*n, (ms, now, !v.truth()));
                    x.pc += 1;
                }
                Err(er) => self.fault(c, line, er),
            },
            Ins::ClockReset(n) | Ins::ClockStart(n) | Ins::ClockStop(n) => {
                let x = &mut self.ctls[c];
                let now = x.t;
                let cur = x.clocks.get(n).copied().unwrap_or((0.0, now, false));
                let s = if cur.2 { cur.0 + (now - cur.1) } else { cur.0 };
                let v = match ins {
                    Ins::ClockReset(_) => (0.0, now, cur.2),
                    Ins::ClockStart(_) => (s, now, true),
                    _ => (s, now, false),
                };
                x.clocks.insert(n.clone(), v);
                x.pc += 1;
            }
            Ins::JumpIfNot(e, to) => match self.eval(c, e) {
                Ok(v) => {
                    let x = &mut self.ctls[c];
                    x.pc = if v.truth() { x.pc + 1 } else { *to };
                }
                Err(er) => self.fault(c, line, er),
            },
            Ins::Jump(to) => self.ctls[c].pc = *to,
            Ins::Halt => {
                let x = &mut self.ctls[c];
                x.state = State::Halted {
                    message: x.message.clone(),
                    faulted: false,
                };
                if let Some(i) = x.running.take() {
                    let _ = i;
                }
            }
            Ins::End => {
                if let Some(since) = self.ctls[c].shown {
                    let t = self.ctls[c].t;
                    self.problem_at(
                        c,
                        ProblemKind::Message,
                        line,
                        None,
                        format!(
                            "{} ended at {t:.2} s while a wait's message shown since {since:.2} s was still on the pendant",
                            self.cell.controllers[c].name
                        ),
                    );
                }
                let x = &mut self.ctls[c];
                x.t = x.t.max(x.motion_end);
                x.state = State::Ended;
                // The next cycle: the operator starts it again once the robot stands.
                if x.cycles_left > 0 {
                    x.cycles_left -= 1;
                    let at = x.t + self.cycle_pause * self.rng.unit();
                    self.events.push((at, Event::Restart(c)));
                }
            }
        }
    }

    /// When a blocked controller's time limit is up (it looks again then).
    fn wake_of(&self, c: usize) -> Option<f64> {
        match &self.ctls[c].state {
            State::Blocked { wake, .. } => *wake,
            _ => None,
        }
    }

    fn set_out(&mut self, c: usize, k: Key, v: Val, line: u32) {
        let t = self.ctls[c].t;
        // A digital output holds a truth (RAPID writes it as 0 or 1).
        let v = match v {
            Val::Num(n) if n == 0.0 || n == 1.0 => Val::Bool(n == 1.0),
            v => v,
        };
        let wire = self
            .cell
            .wires
            .iter()
            .find(|w| w.from.0 == c && w.from.1 == k);
        if let Some(wire) = wire
            && self.ctls[c].motion_end > t + 1e-9
        {
            let running = self.ctls[c].running.map(|i| &self.out.timeline[i]);
            let step = running.map(|s| s.name.clone()).unwrap_or_default();
            let local_id = running.map(|s| s.local_id);
            let message = format!(
                "{} sets wire {} at {t:.2} s while the motion of step {step} still runs (until {:.2} s)",
                self.cell.controllers[c].name, wire.name, self.ctls[c].motion_end
            );
            self.problem_at(c, ProblemKind::WireInMotion, line, local_id, message);
        }
        let outs = &mut self.ctls[c].outs;
        let changed = match outs.get_mut(&k) {
            Some(old) if *old == v => false,
            Some(old) => {
                *old = v.clone();
                true
            }
            None => {
                outs.insert(k.clone(), v.clone());
                true
            }
        };
        if changed {
            self.out.changes.push((t, c, k, v));
        }
        self.ctls[c].pc += 1;
        self.wake_all(t);
    }
}
