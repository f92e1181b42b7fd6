//! The cell co-simulation (docs/CELLS.md): every program of a cell of several KUKA controllers runs
//! at the same time on a KRL machine of its own, with the blackboard's wires connecting one's
//! `$OUT` to the other's `$IN`, under random step durations, speeds, start delays and inputs
//! that change at random times. A discrete-event simulation: each controller has its own clock;
//! the controller whose clock is earliest runs its next statement (ties broken at random), so
//! a wire read sees every write made before it. KRL's advance run is modelled: a step's motion
//! is queued and the program runs on until a `WAIT` (an advance-run stop); an output set while a
//! motion before it still runs is a fault.
//!
//! A run passes when:
//! - the controllers did what one run of the chart does (`Chart::explain`: one choice at every
//!   selection for all of them, each controller's steps in its order; when all programs ended,
//!   the chart ends there too);
//! - no step started before a step the chart puts before it had ended (on any controller);
//! - no output was set while a motion before it still ran;
//! - no program waits for a handshake that can never come (a cycle of handshake waits, or one
//!   from a program that ended) — only a wait for a chart condition may stop a run early.

use std::collections::HashMap;

use crate::chart::{Chart, ChartGen};
use crate::krl::{KExpr, bits, code, kexpr};
use crate::machine::{Expr as MExpr, Op};
pub use crate::mutate::{Mutation, mutate};
use crate::{Lang, Phase, Rng, SIGNALS, repo, sequences};

/// An expression of a program: KRL's, or (RAPID, URScript) the machine's for conditions and
/// the few forms the handshakes and the structured writer use.
#[derive(Debug, Clone)]
pub enum X {
    K(KExpr),
    /// A condition as the language's reader of `flow_run` reads it; `true`: a boolean signal
    /// reads as the number 0 or 1 (RAPID).
    M(MExpr, bool),
    /// A wire input (its `Number` or `Address`) as a boolean.
    Wire(String),
    Num(i64),
    Truth(bool),
    Var(String),
    /// `v + k`, `1 - v`, `not v`, `a == b` (booleans and 0/1 numbers compare by truth).
    Add(String, i64),
    OneMinus(String),
    Not(Box<X>),
    Same(Box<X>, Box<X>),
    /// Every / any of the parts (a handshake's compound wait in RAPID and URScript).
    All(Vec<X>),
    Any(Vec<X>),
    /// The timer (KRL `$TIMER[n]`, URScript's `skp_waited`, RAPID's `\MaxTime`) has run at
    /// least this many milliseconds: a watched wait lasts too long.
    Late(String, f64),
}

impl From<KExpr> for X {
    fn from(k: KExpr) -> X {
        X::K(k)
    }
}

/// One statement of a program, flattened: blocks become jumps.
#[derive(Debug, Clone)]
pub enum Ins {
    /// A step's title: its motion.
    Step(String),
    /// A wait until the condition holds; `true`: the motions before end first (KRL's `WAIT FOR`
    /// stops the advance run, RAPID's `WaitUntil \InPos`, URScript's wait for `is_steady()`).
    WaitFor(X, bool),
    /// Ends the motions before (KRL's `WAIT SEC`).
    WaitSec,
    /// The program stops for good until it is started again (KRL `HALT` in a loop, RAPID
    /// `EXIT`, URScript `halt()`).
    Halt,
    /// An output (`Number` or `Address`) set.
    SetOut(String, X),
    /// A timer starts at 0 (KRL `$TIMER[n] = 0`, URScript `skp_waited = 0.0`, RAPID's
    /// `WaitUntil \MaxTime`).
    TimerStart(String),
    /// The message of a wait that lasts shows on the pendant (KRL `Set_KrlMsg(#WAITING …)`,
    /// RAPID `TPWrite`, URScript `textmsg` at its start) and is taken away (`Clr_KrlMsg`,
    /// `TPErase`, `textmsg` at its end).
    Show,
    Clear,
    Assign(String, X),
    /// A tell that step `name` is done begins (its comment): the program has started no
    /// other step since that one (a partner that waits for it would wait for more).
    Told(String),
    JumpIfNot(X, usize),
    Jump(usize),
    End,
}

enum Open {
    If {
        test: usize,
        to_end: Vec<usize>,
    },
    Loop {
        start: usize,
        exits: Vec<usize>,
    },
    Repeat {
        start: usize,
    },
    Switch {
        sel: KExpr,
        test: Option<usize>,
        to_end: Vec<usize>,
    },
}

/// Parses a KRL `.src` main program into flat statements.
/// The step a tell's comment (`handshake: tell R2 that step 'Grip' (localId 5) is done…`)
/// says is done: its name's first word, as a step title gives it.
fn told(comment: &str) -> Option<String> {
    let rest = comment.strip_prefix("handshake: tell ")?;
    let (_, after) = rest.split_once(" that step '")?;
    let (name, tail) = after.split_once('\'')?;
    tail.contains(") is done").then(|| {
        name.split_whitespace()
            .next()
            .unwrap_or_default()
            .to_owned()
    })
}

pub fn parse(src: &str) -> Vec<Ins> {
    let expanded = inline_routines(src);
    let lines: Vec<&str> = expanded.iter().map(String::as_str).collect();
    let mut i = lines
        .iter()
        .position(|l| l.trim_start().starts_with("DEF "))
        .expect("DEF")
        + 1;
    let mut out: Vec<Ins> = Vec::new();
    let mut open: Vec<Open> = Vec::new();
    let patch = |out: &mut Vec<Ins>, at: usize, to: usize| match &mut out[at] {
        Ins::JumpIfNot(_, t) | Ins::Jump(t) => *t = to,
        other => panic!("patching {other:?}"),
    };
    // Labels (`skp_s1:`) and the GOTOs to them, patched at the END.
    let mut labels: HashMap<String, usize> = HashMap::new();
    let mut gotos: Vec<(usize, String)> = Vec::new();
    while i < lines.len() {
        let raw = lines[i].trim();
        i += 1;
        if let Some(title) = raw.strip_prefix(";FOLD ") {
            if let Some(name) = crate::krl::fold(&lines, &mut i, title) {
                out.push(Ins::Step(name));
            }
            continue;
        }
        if let Some(name) = raw.strip_prefix(';').and_then(told) {
            out.push(Ins::Told(name));
            continue;
        }
        let c = code(raw);
        if c.is_empty() {
            continue;
        }
        let first = c.split_whitespace().next().unwrap().to_ascii_uppercase();
        match first.as_str() {
            "END" => {
                out.push(Ins::End);
                assert!(open.is_empty(), "END inside a block");
                for (at, l) in gotos {
                    let to = *labels
                        .get(&l)
                        .unwrap_or_else(|| panic!("GOTO {l}: no such label"));
                    patch(&mut out, at, to);
                }
                return out;
            }
            "GOTO" => {
                out.push(Ins::Jump(0));
                gotos.push((out.len() - 1, c[4..].trim().to_ascii_uppercase()));
            }
            _ if c.ends_with(':') && !c.contains(' ') => {
                // (The KRL check of the tests refuses a GOTO into a block.)
                labels.insert(c.trim_end_matches(':').to_ascii_uppercase(), out.len());
            }
            "HALT" => out.push(Ins::Halt),
            // A wait's message to the operator; a stop's (`#QUIT`) is not modelled.
            _ if c.contains("Set_KrlMsg(#WAITING") => out.push(Ins::Show),
            _ if c.contains("Clr_KrlMsg(") => out.push(Ins::Clear),
            _ if c.contains("Set_KrlMsg(") || c.contains("= {") => {}
            "WAIT" => {
                let rest = c[4..].trim_start();
                if rest.to_ascii_uppercase().starts_with("SEC") {
                    out.push(Ins::WaitSec);
                } else {
                    assert!(rest.to_ascii_uppercase().starts_with("FOR "));
                    let c = &rest[4..];
                    // A watched wait: `WAIT FOR (c) OR ($TIMER[n] >= ms)`.
                    let x = match c.rsplit_once(" OR ($TIMER[") {
                        Some((head, tail)) => {
                            let (n, ms) = tail
                                .strip_suffix(')')
                                .and_then(|t| t.split_once("] >= "))
                                .expect("a watched wait's timer");
                            X::Any(vec![
                                kexpr(head).into(),
                                X::Late(format!("$TIMER[{n}]"), ms.parse().unwrap()),
                            ])
                        }
                        None => kexpr(c).into(),
                    };
                    out.push(Ins::WaitFor(x, true));
                }
            }
            "IF" => {
                let cond = c[2..].trim().strip_suffix("THEN").unwrap();
                out.push(Ins::JumpIfNot(kexpr(cond).into(), 0));
                open.push(Open::If {
                    test: out.len() - 1,
                    to_end: Vec::new(),
                });
            }
            "ELSE" => {
                let Some(Open::If { test, to_end }) = open.last_mut() else {
                    panic!("ELSE outside IF")
                };
                out.push(Ins::Jump(0));
                to_end.push(out.len() - 1);
                let t = *test;
                let here = out.len();
                patch(&mut out, t, here);
                *test = usize::MAX;
            }
            "ENDIF" => {
                let Some(Open::If { test, to_end }) = open.pop() else {
                    panic!("ENDIF outside IF")
                };
                let here = out.len();
                if test != usize::MAX {
                    patch(&mut out, test, here);
                }
                for j in to_end {
                    patch(&mut out, j, here);
                }
            }
            "LOOP" => open.push(Open::Loop {
                start: out.len(),
                exits: Vec::new(),
            }),
            "EXIT" => {
                out.push(Ins::Jump(0));
                let at = out.len() - 1;
                let exits = open
                    .iter_mut()
                    .rev()
                    .find_map(|o| match o {
                        Open::Loop { exits, .. } => Some(exits),
                        _ => None,
                    })
                    .expect("EXIT outside LOOP");
                exits.push(at);
            }
            "ENDLOOP" => {
                let Some(Open::Loop { start, exits }) = open.pop() else {
                    panic!("ENDLOOP outside LOOP")
                };
                out.push(Ins::Jump(start));
                let here = out.len();
                for j in exits {
                    patch(&mut out, j, here);
                }
            }
            "REPEAT" => open.push(Open::Repeat { start: out.len() }),
            "UNTIL" => {
                let Some(Open::Repeat { start }) = open.pop() else {
                    panic!("UNTIL outside REPEAT")
                };
                out.push(Ins::JumpIfNot(kexpr(&c[5..]).into(), start));
            }
            "SWITCH" => open.push(Open::Switch {
                sel: kexpr(&c[6..]),
                test: None,
                to_end: Vec::new(),
            }),
            "CASE" | "DEFAULT" => {
                let Some(Open::Switch { sel, test, to_end }) = open.last_mut() else {
                    panic!("CASE outside SWITCH")
                };
                let sel = sel.clone();
                if let Some(t) = test.take() {
                    out.push(Ins::Jump(0));
                    to_end.push(out.len() - 1);
                    let here = out.len();
                    patch(&mut out, t, here);
                }
                if first == "CASE" {
                    let v: i64 = c[4..].trim().parse().unwrap();
                    out.push(Ins::JumpIfNot(
                        KExpr::Bin("==".into(), Box::new(sel), Box::new(KExpr::Int(v))).into(),
                        0,
                    ));
                    if let Some(Open::Switch { test, .. }) = open.last_mut() {
                        *test = Some(out.len() - 1);
                    }
                }
            }
            "ENDSWITCH" => {
                let Some(Open::Switch { test, to_end, .. }) = open.pop() else {
                    panic!("ENDSWITCH outside SWITCH")
                };
                let here = out.len();
                if let Some(t) = test {
                    patch(&mut out, t, here);
                }
                for j in to_end {
                    patch(&mut out, j, here);
                }
            }
            _ => {
                if let Some((lhs, rhs)) = c.split_once('=')
                    && !rhs.starts_with('=')
                {
                    let lhs = lhs.trim();
                    if lhs.starts_with("$TIMER[") && rhs.trim() == "0" {
                        out.push(Ins::TimerStart(lhs.to_owned()));
                    } else if let Some(n) =
                        lhs.strip_prefix("$OUT[").and_then(|r| r.strip_suffix(']'))
                    {
                        out.push(Ins::SetOut(n.to_owned(), kexpr(rhs).into()));
                    } else if lhs
                        .chars()
                        .all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
                    {
                        let e = match rhs.split_once('+') {
                            Some((a, b)) => {
                                KExpr::Bin("+".into(), Box::new(kexpr(a)), Box::new(kexpr(b)))
                            }
                            None => kexpr(rhs),
                        };
                        out.push(Ins::Assign(lhs.to_ascii_uppercase(), e.into()));
                    }
                }
            }
        }
    }
    panic!("no END");
}

/// The timer and time limit of a watched wait.
fn find_late(e: &X) -> Option<(String, f64)> {
    match e {
        X::Late(n, ms) => Some((n.clone(), *ms)),
        X::Any(v) | X::All(v) => v.iter().find_map(find_late),
        _ => None,
    }
}

/// A URScript program with each wire constant of its handshakes (`From_A_1 = 4`, in the lines
/// after the comment that opens them) put in its name's place in the digital I/O calls, and
/// the constants' lines left out.
pub fn ur_constants(text: &str) -> String {
    let mut names: Vec<(String, String)> = Vec::new();
    let mut out = String::with_capacity(text.len());
    let mut in_block = false;
    for line in text.split_inclusive('\n') {
        let t = line.trim();
        if t.starts_with("# handshake: the wires, standard digital I/O") {
            in_block = true;
            continue;
        }
        if in_block {
            if let Some((name, n)) = t.split_once(" = ")
                && n.bytes().all(|b| b.is_ascii_digit())
            {
                names.push((name.to_owned(), n.to_owned()));
                continue;
            }
            in_block = false;
        }
        out.push_str(line);
    }
    for (name, n) in &names {
        out = out
            .replace(
                &format!("get_standard_digital_in({name})"),
                &format!("get_standard_digital_in({n})"),
            )
            .replace(
                &format!("set_standard_digital_out({name},"),
                &format!("set_standard_digital_out({n},"),
            );
    }
    out
}

/// A KRL `.src` with each name of a single-bit `SIGNAL` of its `.dat` (a cell's wire,
/// `SIGNAL From_A_1 $IN[41]`) replaced by the bit, outside strings and comments.
pub fn krl_signals(src: &str, dat: &str) -> String {
    let bits: HashMap<String, String> = dat
        .lines()
        .filter_map(|l| {
            let w: Vec<&str> = code(l.trim()).split_whitespace().collect();
            (w.len() == 3 && w[0] == "SIGNAL").then(|| (w[1].to_ascii_uppercase(), w[2].to_owned()))
        })
        .collect();
    if bits.is_empty() {
        return src.to_owned();
    }
    let mut out = String::with_capacity(src.len());
    for line in src.split_inclusive('\n') {
        let (mut in_string, mut word) = (false, String::new());
        let mut chars = line.chars().peekable();
        while let Some(c) = chars.next() {
            let ident = c.is_ascii_alphanumeric() || c == '_' || c == '$';
            if !in_string && ident {
                word.push(c);
                if chars
                    .peek()
                    .is_some_and(|n| n.is_ascii_alphanumeric() || *n == '_')
                {
                    continue;
                }
                match bits.get(&word.to_ascii_uppercase()) {
                    Some(bit) => out.push_str(bit),
                    None => out.push_str(&word),
                }
                word.clear();
                continue;
            }
            if c == ';' && !in_string {
                out.push_str(
                    &line[line.len() - chars.clone().map(char::len_utf8).sum::<usize>() - 1..],
                );
                break;
            }
            if c == '"' {
                in_string = !in_string;
            }
            out.push(c);
        }
    }
    out
}

/// The lines of a KRL `.src` with each call in the main program of a routine defined after it
/// (`DEF name(…)` … `END`, the handshakes' `skp_stop`, `skp_watch`, …) replaced by that
/// routine's body (its declarations left out; its parameters are not read here).
fn inline_routines(src: &str) -> Vec<String> {
    let lines: Vec<&str> = src.lines().collect();
    let is_def = |l: &str| l.trim_start().to_ascii_uppercase().starts_with("DEF ");
    let is_end = |l: &str| code(l.trim()).eq_ignore_ascii_case("END");
    let main = lines.iter().position(|l| is_def(l)).expect("DEF");
    let main_end = main + lines[main..].iter().position(|l| is_end(l)).expect("END");
    let mut routines: HashMap<String, Vec<&str>> = HashMap::new();
    let mut i = main_end + 1;
    while i < lines.len() {
        if is_def(lines[i]) {
            let name = lines[i].trim()[4..]
                .split('(')
                .next()
                .unwrap()
                .trim()
                .to_ascii_uppercase();
            let end = i + lines[i..].iter().position(|l| is_end(l)).expect("END");
            let body = lines[i + 1..end]
                .iter()
                .copied()
                .filter(|l| !l.trim_start().to_ascii_uppercase().starts_with("DECL "))
                .collect();
            routines.insert(name, body);
            i = end;
        }
        i += 1;
    }
    let mut out = Vec::with_capacity(lines.len());
    for (k, l) in lines.iter().enumerate() {
        let c = code(l.trim());
        let callee = c
            .split('(')
            .next()
            .map(|n| n.trim().to_ascii_uppercase())
            .filter(|n| c.contains('(') && !c.contains('=') && routines.contains_key(n));
        match callee {
            Some(n) if k > main && k < main_end => {
                out.extend(routines[&n].iter().map(|b| (*b).to_owned()));
            }
            _ => out.push((*l).to_owned()),
        }
    }
    out
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Val {
    I(i64),
    B(bool),
}

impl Val {
    /// A boolean, or a 0/1 number (RAPID's digital values), as a truth.
    fn truth(self) -> bool {
        match self {
            Val::B(b) => b,
            Val::I(i) => i != 0,
        }
    }
}

/// Reads the `.dat`: `SIGNAL` groups and `DECL BOOL`/`DECL INT` variables.
fn read_dat(dat: &str) -> (HashMap<String, (u32, u32)>, HashMap<String, Val>) {
    let (signals, decls) = crate::krl::dat_entries(dat);
    let vars = decls
        .into_iter()
        .filter_map(|(name, ty, init)| {
            let v = match ty.as_str() {
                "BOOL" => Val::B(init == "TRUE"),
                "INT" => Val::I(init.parse().unwrap()),
                // A stop's message (`KrlMsg_T` and its kin) is not run here.
                t if t.starts_with("KrlMsg") => return None,
                // Named points and an inline form's data: the motions are not run here (the KRL
                // check holds them to their declarations).
                "E6POS" | "E6AXIS" | "FDAT" | "PDAT" | "LDAT" => return None,
                other => panic!("DECL {other}"),
            };
            Some((name, v))
        })
        .collect();
    (signals, vars)
}

/// Whether a KRL expression reads an input: `$IN`, `$CYCFLAG`, `$TIMER`, or a `SIGNAL` group.
fn reads_inputs(e: &KExpr, signals: &HashMap<String, (u32, u32)>) -> bool {
    match e {
        KExpr::Sys(s) => !s.starts_with("$OUT["),
        KExpr::Name(n) => signals.contains_key(n) || signals.contains_key(&n.to_ascii_uppercase()),
        KExpr::Not(a) | KExpr::Neg(a) => reads_inputs(a, signals),
        KExpr::Bin(_, a, b) => reads_inputs(a, signals) || reads_inputs(b, signals),
        KExpr::Int(_) | KExpr::Real(_) | KExpr::Bool(_) => false,
    }
}

/// One controller.
struct Ctl {
    ins: Vec<Ins>,
    pc: usize,
    vars: HashMap<String, Val>,
    signals: HashMap<String, (u32, u32)>,
    /// Its clock: when it runs its next statement.
    t: f64,
    /// When the last motion queued ends.
    motion_end: f64,
    /// Time a statement takes, and the factor of its motions.
    eps: f64,
    slow: f64,
    /// The outputs it drove, by `Number` or `Address`.
    outs: HashMap<String, bool>,
    ended: bool,
    /// Stopped after `cap` steps (an endless chart).
    capped: bool,
    blocked: bool,
    /// Steps run: name, start and end of the motion.
    steps: Vec<(String, f64, f64)>,
    /// What the advance run did while a motion still ran (an output set, an input tested):
    /// (what, the step whose motion ran).
    advance_faults: Vec<(String, String)>,
    /// Stopped by the program itself (a partner was started again): until it is started
    /// again.
    halted: bool,
    /// The runs before this one (each start again begins a new one): their steps, and the
    /// index of a step whose motion the start again cut short.
    past: Vec<(Vec<Step>, Option<usize>)>,
    /// When each start again took effect.
    restarts: Vec<f64>,
    /// The operator starts it again at this time (or when it gets there, if later).
    restart_at: Option<f64>,
    /// How many more times it is started again after its END (the next cycles).
    cycles_left: usize,
    /// Its moves return when the motion has ended (URScript): no advance run.
    blocking: bool,
    /// When each timer started (`Ins::TimerStart`).
    timers: HashMap<String, f64>,
    /// A watched wait that waits: when its time is up.
    wake: Option<f64>,
    /// The last watched wait's timer and time limit.
    watched: Option<(String, f64)>,
    /// Since when a wait's message shows on the pendant.
    shown: Option<f64>,
    /// The messages of waits: (shown, taken away).
    messages: Vec<(f64, f64)>,
    /// What went wrong with a message (shown too early, never taken away, taken away twice).
    message_faults: Vec<String>,
    /// The step it started last in this run ([`Ins::Told`]).
    last_step: Option<String>,
    /// The names of its own steps (a tell may also pass on a partner's step, or a round's end).
    own_steps: std::collections::HashSet<String>,
    /// A tell that came after another step than the one it reports.
    late_tells: Vec<String>,
}

/// A step run: its name, the start and end of its motion.
pub type Step = (String, f64, f64);

/// How the operator starts the programs of a cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scenario {
    /// Each program once.
    Once,
    /// `n` cycles: each program started again after its END, in any order, with any delay.
    Cycles(usize),
    /// One program started again at a random time (mid-cycle, a fault), every other one later
    /// at a random time (whatever it does then); then one whole cycle.
    Fault,
}

/// The world: each controller, the wires, the input phases and when each begins.
struct World<'w> {
    ctls: Vec<Ctl>,
    wires: &'w Wires,
    /// The phases as each signal's value, and as KRL's bits.
    seq: Vec<Phase>,
    phases: Vec<HashMap<String, bool>>,
    /// When phase k+1 begins.
    changes: Vec<f64>,
    /// Decides the inputs no phase names.
    salt: u64,
    /// Prints every statement run (`COSIM_TRACE_RUN=n`: run n of each co-simulation).
    trace: bool,
}

/// The wires of a cell: (controller, input) → (controller, output) that drives it, each side
/// by its signal's `Number` (as text) or else its `Address`, read from the blackboard's
/// `InternalLink`s.
#[derive(Debug, Default)]
pub struct Wires {
    pub from: HashMap<(usize, String), (usize, String)>,
}

impl Wires {
    /// Reads the wires between the controllers named `controllers` (each with the devices
    /// inside its element) from a blackboard: signals with `IoType` and `Number` or `Address`,
    /// links `<ID>:<name>` on either side.
    pub fn read(blackboard: &str, controllers: &[String]) -> Wires {
        let doc = roxmltree::Document::parse(blackboard).unwrap();
        let attr = |n: roxmltree::Node, name: &str| -> Option<String> {
            n.children()
                .find(|c| c.has_tag_name("Attribute") && c.attribute("Name") == Some(name))
                .and_then(|a| a.children().find(|c| c.has_tag_name("Value")))
                .and_then(|v| v.text())
                .map(|t| t.trim().to_owned())
        };
        // `<holder ID>:<name>` → (controller, output?, number or address)
        let mut signals: HashMap<String, (usize, bool, String)> = HashMap::new();
        for e in doc
            .descendants()
            .filter(|n| n.has_tag_name("InternalElement"))
        {
            let Some(c) = controllers
                .iter()
                .position(|c| Some(c.as_str()) == e.attribute("Name"))
            else {
                continue;
            };
            for i in e
                .descendants()
                .filter(|n| n.has_tag_name("ExternalInterface"))
            {
                let Some(io) = attr(i, "IoType") else {
                    continue;
                };
                let Some(id) = attr(i, "Number").or_else(|| attr(i, "Address")) else {
                    continue;
                };
                let holder = i.parent().and_then(|p| p.attribute("ID")).unwrap_or("");
                signals.insert(
                    format!("{holder}:{}", i.attribute("Name").unwrap()),
                    (c, io == "Output", id),
                );
            }
        }
        let mut from = HashMap::new();
        for l in doc.descendants().filter(|n| n.has_tag_name("InternalLink")) {
            let side = |a: &str| signals.get(l.attribute(a).unwrap_or("")).cloned();
            if let (Some(a), Some(b)) = (side("RefPartnerSideA"), side("RefPartnerSideB")) {
                let (out, inp) = if a.1 { (a, b) } else { (b, a) };
                if out.1 && !inp.1 && out.0 != inp.0 {
                    from.insert((inp.0, inp.2), (out.0, out.2));
                }
            }
        }
        Wires { from }
    }

    fn source(&self, me: usize, input: &str) -> Option<(usize, String)> {
        self.from.get(&(me, input.to_owned())).cloned()
    }

    fn drives(&self, me: usize, output: &str) -> bool {
        self.from.values().any(|v| v.0 == me && v.1 == output)
    }
}

impl World<'_> {
    fn phase_index(&self, t: f64) -> usize {
        let k = self.changes.iter().filter(|&&c| c <= t).count();
        k.min(self.phases.len() - 1)
    }

    fn phase_at(&self, t: f64) -> &HashMap<String, bool> {
        &self.phases[self.phase_index(t)]
    }

    /// An input a fixture has and the flow base has not: a bit of its own per phase.
    fn fixture_input(&self, c: usize, name: &str) -> bool {
        let k = self.phase_index(self.ctls[c].t) as u64;
        let h = name
            .bytes()
            .fold(self.salt ^ k.wrapping_mul(0x9E37), |h, b| {
                (h ^ b as u64).wrapping_mul(0x0100_0000_01B3)
            });
        h >> 7 & 1 == 1
    }

    /// A wire input of controller `c`: what its driver's output holds.
    fn wire(&self, c: usize, input: &str) -> bool {
        let (a, out) = self
            .wires
            .source(c, input)
            .unwrap_or_else(|| panic!("R{}: input {input} is no wire", c + 1));
        *self.ctls[a].outs.get(&out).unwrap_or(&false)
    }

    fn var(&self, c: usize, n: &str) -> Val {
        *self.ctls[c]
            .vars
            .get(&n.to_ascii_uppercase())
            .unwrap_or_else(|| panic!("R{}: `{n}` is read before it has a value", c + 1))
    }

    fn value(&self, c: usize, e: &X) -> Val {
        match e {
            X::K(k) => self.eval(c, k),
            X::M(m, numbers) => self.eval_m(c, m, *numbers),
            X::Wire(w) => Val::B(self.wire(c, w)),
            X::Num(i) => Val::I(*i),
            X::Truth(b) => Val::B(*b),
            X::Var(v) => self.var(c, v),
            X::Add(v, k) => match self.var(c, v) {
                Val::I(i) => Val::I(i + k),
                other => panic!("{other:?} + {k}"),
            },
            X::OneMinus(v) => match self.var(c, v) {
                Val::I(i) => Val::I(1 - i),
                other => panic!("1 - {other:?}"),
            },
            X::Not(a) => Val::B(!self.value(c, a).truth()),
            X::Same(a, b) => Val::B(self.value(c, a).truth() == self.value(c, b).truth()),
            X::All(v) => Val::B(v.iter().all(|x| self.value(c, x).truth())),
            X::Any(v) => Val::B(v.iter().any(|x| self.value(c, x).truth())),
            X::Late(n, ms) => {
                let x = &self.ctls[c];
                let start = x
                    .timers
                    .get(n)
                    .unwrap_or_else(|| panic!("R{}: timer {n} read before it was started", c + 1));
                // As `deadline` computes it (no rounding apart).
                Val::B(x.t >= start + ms)
            }
        }
    }

    /// When the watched wait `e` of controller `c` runs out of time.
    fn deadline(&self, c: usize, e: &X) -> Option<f64> {
        match e {
            X::Late(n, ms) => Some(self.ctls[c].timers.get(n)? + ms),
            X::Any(v) | X::All(v) => v.iter().find_map(|x| self.deadline(c, x)),
            _ => None,
        }
    }

    fn holds(&self, c: usize, e: &X) -> bool {
        match (e, self.value(c, e)) {
            (_, Val::B(b)) => b,
            (X::K(_), v) => panic!("a KRL condition evaluated to {v:?}"),
            (_, v) => panic!("a condition evaluated to {v:?}"),
        }
    }

    /// A condition of RAPID or URScript, read by the machine's parsers.
    fn eval_m(&self, c: usize, e: &MExpr, numbers: bool) -> Val {
        match e {
            MExpr::Int(i) => Val::I(*i),
            MExpr::Bool(b) => Val::B(*b),
            // No step times in a cell of several controllers (E316).
            MExpr::Real(_) | MExpr::ClkRead(_) => panic!("a step time in a cell: {e:?}"),
            MExpr::Var(n) => match self.ctls[c].vars.get(&n.to_ascii_uppercase()) {
                Some(v) => *v,
                // A signal of a fixture's own (RAPID reads one by its name): a bit of its own
                // per phase.
                None => {
                    let b = self.fixture_input(c, n);
                    if numbers { Val::I(b as i64) } else { Val::B(b) }
                }
            },
            MExpr::Signal(k) => {
                let s = &SIGNALS[*k];
                let phase = &self.seq[self.phase_index(self.ctls[c].t)];
                let v = phase.get(s.name).copied().unwrap_or(0);
                if s.integer || numbers {
                    Val::I(v)
                } else {
                    Val::B(v != 0)
                }
            }
            MExpr::Not(a) => match self.eval_m(c, a, numbers) {
                Val::B(b) => Val::B(!b),
                v => panic!("type error: NOT of {v:?}"),
            },
            MExpr::Neg(a) => match self.eval_m(c, a, numbers) {
                Val::I(i) => Val::I(-i),
                v => panic!("type error: - of {v:?}"),
            },
            MExpr::Bin(op, a, b) => {
                let (x, y) = (self.eval_m(c, a, numbers), self.eval_m(c, b, numbers));
                Val::B(match (op, x, y) {
                    (Op::Or, Val::B(x), Val::B(y)) => x || y,
                    (Op::Xor, Val::B(x), Val::B(y)) => x != y,
                    (Op::And, Val::B(x), Val::B(y)) => x && y,
                    (Op::Eq, x, y) => x == y,
                    (Op::Ne, x, y) => x != y,
                    (Op::Lt, Val::I(x), Val::I(y)) => x < y,
                    (Op::Gt, Val::I(x), Val::I(y)) => x > y,
                    (Op::Le, Val::I(x), Val::I(y)) => x <= y,
                    (Op::Ge, Val::I(x), Val::I(y)) => x >= y,
                    _ => panic!("type error: {x:?} {op:?} {y:?}"),
                })
            }
        }
    }

    fn eval(&self, c: usize, e: &KExpr) -> Val {
        let ctl = &self.ctls[c];
        match e {
            KExpr::Int(i) => Val::I(*i),
            KExpr::Bool(b) => Val::B(*b),
            KExpr::Real(_) => panic!("a step time in a cell: {e:?}"),
            KExpr::Sys(s) => {
                let n = |p: &str| -> Option<String> {
                    Some(s.strip_prefix(p)?.strip_suffix(']')?.to_owned())
                };
                if let Some(n) = n("$IN[")
                    && self.wires.source(c, &n).is_some()
                {
                    return Val::B(self.wire(c, &n));
                }
                if let Some(n) = n("$OUT[")
                    && self.wires.drives(c, &n)
                {
                    return Val::B(*ctl.outs.get(&n).unwrap_or(&false));
                }
                match self.phase_at(ctl.t).get(s) {
                    Some(v) => Val::B(*v),
                    // An input of a fixture's own: a bit of its own per phase.
                    None => Val::B(self.fixture_input(c, s)),
                }
            }
            KExpr::Name(n) => {
                if let Some((a, b)) = ctl.signals.get(n) {
                    let bits = self.phase_at(ctl.t);
                    let mut v = 0;
                    for (k, ix) in (*a..=*b).enumerate() {
                        if bits[&format!("$IN[{ix}]")] {
                            v |= 1 << k;
                        }
                    }
                    Val::I(v)
                } else {
                    self.var(c, n)
                }
            }
            KExpr::Not(a) => match self.eval(c, a) {
                Val::B(b) => Val::B(!b),
                v => panic!("NOT of {v:?}"),
            },
            KExpr::Neg(a) => match self.eval(c, a) {
                Val::I(i) => Val::I(-i),
                v => panic!("- of {v:?}"),
            },
            KExpr::Bin(op, a, b) => {
                let (x, y) = (self.eval(c, a), self.eval(c, b));
                if op == "+" {
                    return match (x, y) {
                        (Val::I(x), Val::I(y)) => Val::I(x + y),
                        _ => panic!("+ of {x:?} {y:?}"),
                    };
                }
                Val::B(match (op.as_str(), x, y) {
                    ("AND", Val::B(x), Val::B(y)) => x && y,
                    ("OR", Val::B(x), Val::B(y)) => x || y,
                    ("EXOR", Val::B(x), Val::B(y)) => x != y,
                    ("==", x, y) => x == y,
                    ("<>", x, y) => x != y,
                    ("<", Val::I(x), Val::I(y)) => x < y,
                    (">", Val::I(x), Val::I(y)) => x > y,
                    ("<=", Val::I(x), Val::I(y)) => x <= y,
                    (">=", Val::I(x), Val::I(y)) => x >= y,
                    _ => panic!("KRL type error: {x:?} {op} {y:?}"),
                })
            }
        }
    }

    /// Starts controller `c`'s program again at its clock (or `r`, if later): a motion still
    /// running is cut short, a step not begun yet never runs; its outputs keep their levels.
    fn restart(&mut self, c: usize, r: f64) {
        let x = &mut self.ctls[c];
        let now = x.t.max(r);
        x.steps.retain(|s| s.1 < now);
        let mut cut = None;
        if let Some(last) = x.steps.last_mut()
            && last.2 > now
        {
            last.2 = now;
            cut = Some(x.steps.len() - 1);
        }
        x.motion_end = x.motion_end.min(now);
        let steps = std::mem::take(&mut x.steps);
        x.past.push((steps, cut));
        x.restarts.push(now);
        x.pc = 0;
        x.t = now;
        x.last_step = None;
        x.ended = false;
        x.capped = false;
        x.blocked = false;
        x.halted = false;
        x.restart_at = None;
        x.wake = None;
        x.timers.clear();
        // A reset takes the program's messages away (`Clear_P_Reset`; RAPID and URScript
        // hold none while stopped).
        if let Some(since) = x.shown.take() {
            x.messages.push((since, now));
        }
        for other in &mut self.ctls {
            if other.blocked {
                other.blocked = false;
                other.t = other.t.max(now);
            }
        }
    }

    /// When controller `c` acts next: `None` while it waits, has stopped or ended (until
    /// it is started again).
    fn next_time(&self, c: usize) -> Option<f64> {
        let x = &self.ctls[c];
        if x.blocked
            && let Some(w) = x.wake
            && !(x.ended || x.capped || x.halted)
        {
            return Some(match x.restart_at {
                Some(r) => x.t.max(w).min(x.t.max(r)),
                None => x.t.max(w),
            });
        }
        let asleep = x.ended || x.capped || x.blocked || x.halted;
        match (x.restart_at, asleep) {
            (Some(r), true) => Some(x.t.max(r)),
            (_, false) => Some(x.t),
            (None, true) => None,
        }
    }

    /// Runs one statement of controller `c`.
    fn step(&mut self, c: usize, rng: &mut Rng, cap: usize) {
        if let Some(r) = self.ctls[c].restart_at {
            let x = &self.ctls[c];
            // A watched wait whose time is up before the start again shows its message first.
            let waking = x.blocked && x.wake.is_some_and(|w| w < r);
            if x.t >= r || x.ended || x.capped || (x.blocked && !waking) || x.halted {
                self.restart(c, r);
                return;
            }
        }
        // A watched wait whose time is up looks again.
        if self.ctls[c].blocked
            && let Some(w) = self.ctls[c].wake.take()
        {
            let x = &mut self.ctls[c];
            x.blocked = false;
            x.t = x.t.max(w);
        }
        let ins = self.ctls[c].ins[self.ctls[c].pc].clone();
        let eps = self.ctls[c].eps;
        match ins {
            Ins::Step(name) => {
                let ctl = &mut self.ctls[c];
                if ctl.shown.is_some() {
                    ctl.message_faults
                        .push(format!("step {name} started while a wait's message showed"));
                }
                if ctl.steps.len() >= cap {
                    ctl.capped = true;
                    return;
                }
                let dur = ctl.slow * (1 + rng.next() % 50) as f64;
                let start = ctl.t.max(ctl.motion_end);
                ctl.motion_end = start + dur;
                ctl.last_step = Some(name.clone());
                ctl.steps.push((name, start, start + dur));
                ctl.pc += 1;
                // URScript's `movel`/`movej` return when the motion has ended.
                ctl.t = if ctl.blocking {
                    start + dur
                } else {
                    ctl.t + eps
                };
            }
            Ins::WaitSec => {
                let ctl = &mut self.ctls[c];
                if ctl.t < ctl.motion_end {
                    ctl.t = ctl.motion_end;
                } else {
                    ctl.pc += 1;
                    ctl.t += eps;
                }
            }
            Ins::WaitFor(e, settle) => {
                if settle && self.ctls[c].t < self.ctls[c].motion_end {
                    // The motions end first.
                    self.ctls[c].t = self.ctls[c].motion_end;
                } else if self.holds(c, &e) {
                    self.ctls[c].pc += 1;
                    self.ctls[c].t += eps;
                } else {
                    let d = self.deadline(c, &e);
                    let x = &mut self.ctls[c];
                    x.blocked = true;
                    x.wake = d;
                }
                if let Some(late) = find_late(&e) {
                    self.ctls[c].watched = Some(late);
                }
            }
            Ins::Told(name) => {
                let x = &mut self.ctls[c];
                if x.own_steps.contains(&name) && x.last_step.as_deref() != Some(name.as_str()) {
                    x.late_tells.push(format!(
                        "told that step {name} is done only after step {} (a partner that waits for {name} waits for that too)",
                        x.last_step.as_deref().unwrap_or("(none)")
                    ));
                }
                x.pc += 1;
            }
            Ins::TimerStart(n) => {
                let x = &mut self.ctls[c];
                x.timers.insert(n, x.t);
                x.pc += 1;
                x.t += eps;
            }
            Ins::Show => {
                let x = &mut self.ctls[c];
                let (n, ms) = x.watched.clone().expect("a message after a watched wait");
                let waited = x.t - x.timers[&n];
                if x.t < x.timers[&n] + ms {
                    x.message_faults.push(format!(
                        "its wait's message showed at {:.3}, after {waited:.3} ms, before the {ms} ms were up",
                        x.t
                    ));
                }
                if x.shown.is_some() {
                    x.message_faults
                        .push(format!("a second message showed at {:.3}", x.t));
                }
                x.shown = Some(x.t);
                x.pc += 1;
                x.t += eps;
            }
            Ins::Clear => {
                let x = &mut self.ctls[c];
                match x.shown.take() {
                    Some(since) => x.messages.push((since, x.t)),
                    None => x.message_faults.push(format!(
                        "took a message away at {:.3} that was not shown",
                        x.t
                    )),
                }
                x.pc += 1;
                x.t += eps;
            }
            Ins::SetOut(n, e) => {
                let v = self.value(c, &e).truth();
                let now = self.ctls[c].t;
                let ctl = &mut self.ctls[c];
                if ctl.motion_end > now {
                    let step = ctl.steps.last().map(|s| s.0.clone()).unwrap_or_default();
                    ctl.advance_faults.push((format!("set $OUT[{n}]"), step));
                }
                ctl.outs.insert(n, v);
                ctl.pc += 1;
                ctl.t += eps;
                // Whoever waits looks again from now on.
                for other in &mut self.ctls {
                    if other.blocked {
                        other.blocked = false;
                        other.t = other.t.max(now);
                    }
                }
            }
            Ins::Assign(n, e) => {
                let v = self.value(c, &e);
                let ctl = &mut self.ctls[c];
                ctl.vars.insert(n, v);
                ctl.pc += 1;
                ctl.t += eps;
            }
            Ins::JumpIfNot(e, to) => {
                let v = self.holds(c, &e);
                let now = self.ctls[c].t;
                let ctl = &mut self.ctls[c];
                // KRL's advance run tests an IF early: a decision on inputs while a motion
                // before it still runs is taken too soon.
                if ctl.motion_end > now
                    && let X::K(k) = &e
                    && reads_inputs(k, &ctl.signals)
                {
                    let step = ctl.steps.last().map(|s| s.0.clone()).unwrap_or_default();
                    ctl.advance_faults
                        .push((format!("tested `{k:?}` in an IF"), step));
                }
                ctl.pc = if v { ctl.pc + 1 } else { to };
                ctl.t += eps;
            }
            Ins::Jump(to) => {
                self.ctls[c].pc = to;
                self.ctls[c].t += eps;
            }
            Ins::End => {
                let x = &mut self.ctls[c];
                if x.shown.is_some() {
                    x.message_faults
                        .push("ended while a wait's message showed".to_owned());
                }
                x.ended = true;
                if x.cycles_left > 0 && x.restart_at.is_none() {
                    x.cycles_left -= 1;
                    // The next cycle: started again once the robot stands, after a while.
                    x.restart_at = Some(x.t.max(x.motion_end) + (rng.next() % 300) as f64);
                }
            }
            Ins::Halt => self.ctls[c].halted = true,
        }
    }

    /// Runs every program until all have ended, stopped at `cap` steps or wait for good.
    fn run(&mut self, rng: &mut Rng, cap: usize) {
        let mut budget = 2_000_000usize;
        loop {
            budget -= 1;
            assert!(budget > 0, "the co-simulation runs away");
            let runnable: Vec<usize> = (0..self.ctls.len())
                .filter(|&c| self.next_time(c).is_some())
                .collect();
            if runnable.is_empty() {
                // The inputs may still change: whoever waits looks again then.
                let latest = self
                    .ctls
                    .iter()
                    .filter(|x| x.blocked)
                    .map(|x| x.t)
                    .fold(f64::MIN, f64::max);
                match self.changes.iter().find(|&&t| t > latest) {
                    Some(&t) if self.ctls.iter().any(|x| x.blocked) => {
                        for x in &mut self.ctls {
                            if x.blocked {
                                x.blocked = false;
                                x.t = x.t.max(t);
                            }
                        }
                        continue;
                    }
                    _ => return,
                }
            }
            let earliest = runnable
                .iter()
                .map(|&c| self.next_time(c).unwrap())
                .fold(f64::MAX, f64::min);
            let ties: Vec<usize> = runnable
                .into_iter()
                .filter(|&c| self.next_time(c) == Some(earliest))
                .collect();
            let c = ties[(rng.next() % ties.len() as u64) as usize];
            if self.trace {
                let x = &self.ctls[c];
                eprintln!(
                    "R{} t={:.3} pc={} {:?} outs={:?}",
                    c + 1,
                    earliest,
                    x.pc,
                    x.ins.get(x.pc),
                    x.outs
                );
            }
            self.step(c, rng, cap);
        }
    }

    /// A program that waits for a handshake that never comes: a cycle of handshake waits, or
    /// one from a program that ended.
    fn deadlock(&self) -> Option<String> {
        let waits_on = |c: usize| -> Option<usize> {
            let x = &self.ctls[c];
            if !x.blocked {
                return None;
            }
            let Ins::WaitFor(e, _) = &x.ins[x.pc] else {
                return None;
            };
            fn krl_wire(e: &KExpr, w: &Wires, c: usize) -> Option<usize> {
                match e {
                    KExpr::Sys(s) => {
                        let n = s.strip_prefix("$IN[")?.strip_suffix(']')?;
                        w.source(c, n).map(|(a, _)| a)
                    }
                    KExpr::Not(a) | KExpr::Neg(a) => krl_wire(a, w, c),
                    KExpr::Bin(_, a, b) => krl_wire(a, w, c).or_else(|| krl_wire(b, w, c)),
                    _ => None,
                }
            }
            fn wire(e: &X, w: &Wires, c: usize) -> Option<usize> {
                match e {
                    X::K(k) => krl_wire(k, w, c),
                    X::Wire(n) => w.source(c, n).map(|(a, _)| a),
                    X::Not(a) => wire(a, w, c),
                    X::Same(a, b) => wire(a, w, c).or_else(|| wire(b, w, c)),
                    X::All(v) | X::Any(v) => v.iter().find_map(|x| wire(x, w, c)),
                    _ => None,
                }
            }
            wire(e, self.wires, c)
        };
        for start in 0..self.ctls.len() {
            let mut c = start;
            let mut seen = vec![false; self.ctls.len()];
            while let Some(next) = waits_on(c) {
                if seen[c] {
                    return Some(format!("R{} waits in a cycle of handshakes", start + 1));
                }
                seen[c] = true;
                if self.ctls[next].ended {
                    return Some(format!(
                        "R{} waits for a handshake from R{}, which has ended",
                        c + 1,
                        next + 1
                    ));
                }
                c = next;
            }
        }
        None
    }
}

/// Reads the main routine of a RAPID module (`PROC main()` … `ENDPROC`) or a URScript program
/// (`def P():` … `end`) into flat statements. Conditions are read by `flow_run`'s own readers
/// of the language; a wire input (`wires`: controller `me`'s) only in the handshakes' forms
/// (RAPID `DInput(di_x) = v`, URScript `get_standard_digital_in(n) != v` in a wait, a data
/// bit's `DInput(di_x) = 1` / `get_standard_digital_in(n)`).
pub fn parse_structured(text: &str, lang: Lang, wires: &Wires, me: usize) -> Vec<Ins> {
    let rapid = lang == Lang::Rapid;
    let lines: Vec<&str> = text.lines().map(str::trim).collect();
    let start = lines
        .iter()
        .position(|l| {
            if rapid {
                *l == "PROC main()"
            } else {
                l.starts_with("def ")
            }
        })
        .expect("the main routine")
        + 1;
    let is_wire = |id: &str| wires.source(me, id).is_some();
    // A wire read: `DInput(x)` (RAPID), `get_standard_digital_in(n)` (URScript).
    let wire_of = |t: &str| -> Option<String> {
        let t = t.trim();
        // A wire read by its `Address` (URScript `read_input_boolean_register(5)`).
        if !rapid && is_wire(t) {
            return Some(t.to_owned());
        }
        let inner = if rapid {
            t.strip_prefix("DInput(")?.strip_suffix(')')?
        } else {
            t.strip_prefix("get_standard_digital_in(")?
                .strip_suffix(')')?
        };
        is_wire(inner).then(|| inner.to_owned())
    };
    let atom = |c: &str| -> Option<X> {
        let c = c.trim();
        match c {
            "FALSE" | "False" => return Some(X::Truth(false)),
            "TRUE" | "True" => return Some(X::Truth(true)),
            _ => {}
        }
        // The handshakes' forms.
        for (op, negate) in [(" != ", true), (" == ", false), (" = ", false)] {
            if let Some((a, b)) = c.split_once(op)
                && let Some(w) = wire_of(a)
            {
                let rhs = match b.trim() {
                    "1" | "True" | "TRUE" => X::Truth(true),
                    "0" | "False" | "FALSE" => X::Truth(false),
                    v => X::Var(v.to_owned()),
                };
                let same = X::Same(Box::new(X::Wire(w)), Box::new(rhs));
                return Some(if negate { X::Not(Box::new(same)) } else { same });
            }
        }
        wire_of(c).map(X::Wire)
    };
    // A condition made of wire reads only, with AND, OR, NOT and parentheses (the handshakes'
    // compound waits); `None` for anything else.
    fn compound(c: &str, atom: &dyn Fn(&str) -> Option<X>) -> Option<X> {
        let c = c.trim();
        // Splits at `op` outside parentheses.
        let split = |op: &str| -> Vec<&str> {
            let (mut depth, mut parts, mut from) = (0i32, Vec::new(), 0);
            let b = c.as_bytes();
            let mut i = 0;
            while i < b.len() {
                match b[i] {
                    b'(' => depth += 1,
                    b')' => depth -= 1,
                    _ if depth == 0 && c[i..].starts_with(op) => {
                        parts.push(&c[from..i]);
                        i += op.len();
                        from = i;
                        continue;
                    }
                    _ => {}
                }
                i += 1;
            }
            parts.push(&c[from..]);
            parts
        };
        for (op, any) in [
            (" OR ", true),
            (" or ", true),
            (" AND ", false),
            (" and ", false),
        ] {
            let parts = split(op);
            if parts.len() > 1 {
                let xs = parts
                    .iter()
                    .map(|p| compound(p, atom))
                    .collect::<Option<Vec<X>>>()?;
                return Some(if any { X::Any(xs) } else { X::All(xs) });
            }
        }
        if let Some(inner) = c.strip_prefix("NOT ").or_else(|| c.strip_prefix("not ")) {
            return compound(inner, atom).map(|x| X::Not(Box::new(x)));
        }
        if let Some(inner) = c.strip_prefix('(').and_then(|r| r.strip_suffix(')')) {
            // Only when the parentheses enclose it all.
            let mut depth = 0i32;
            let whole = inner.bytes().all(|b| {
                match b {
                    b'(' => depth += 1,
                    b')' => depth -= 1,
                    _ => {}
                }
                depth >= 0
            });
            if whole {
                return compound(inner, atom);
            }
        }
        atom(c)
    }
    let cond = |c: &str| -> X {
        let c = c.trim();
        if let Some(x) = compound(c, &atom) {
            return x;
        }
        if rapid {
            X::M(crate::rapid::expr(c), true)
        } else {
            X::M(crate::urscript::expr(c), false)
        }
    };
    let value = |v: &str| -> X {
        let v = v.trim();
        if let Some(x) = v.strip_prefix("1 - ") {
            return X::OneMinus(x.trim().to_owned());
        }
        if let Some(x) = v.strip_prefix("not ") {
            return X::Not(Box::new(X::Var(x.trim().to_owned())));
        }
        if let Some((a, k)) = v.split_once(" + ")
            && let Ok(k) = k.trim().parse()
        {
            return X::Add(a.trim().to_owned(), k);
        }
        match v {
            "TRUE" | "True" => X::Truth(true),
            "FALSE" | "False" => X::Truth(false),
            _ if v.parse::<i64>().is_ok() => X::Num(v.parse().unwrap()),
            _ if v.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') => X::Var(v.to_owned()),
            _ => cond(v),
        }
    };
    enum Block {
        If {
            test: usize,
            to_end: Vec<usize>,
        },
        While {
            start: usize,
            test: usize,
            breaks: Vec<usize>,
        },
    }
    let patch = |out: &mut Vec<Ins>, at: usize, to: usize| match &mut out[at] {
        Ins::JumpIfNot(_, t) | Ins::Jump(t) => *t = to,
        other => panic!("patching {other:?}"),
    };
    let mut out: Vec<Ins> = Vec::new();
    let mut open: Vec<Block> = Vec::new();
    let mut i = start;
    while i < lines.len() {
        let l = lines[i];
        i += 1;
        if l.is_empty() {
            continue;
        }
        let comment = if rapid { "!" } else { "#" };
        if let Some(c) = l.strip_prefix(comment) {
            if let Some(title) = c.trim_start().strip_prefix("step ") {
                out.push(Ins::Step(crate::machine::step_name(title)));
            } else if let Some(name) = told(c.trim_start()) {
                out.push(Ins::Told(name));
            }
            continue;
        }
        // The end of the routine.
        if (rapid && l == "ENDPROC") || (!rapid && l == "end" && open.is_empty()) {
            out.push(Ins::End);
            return out;
        }
        let head = l.split(['(', ' ', ',', ':', ';']).next().unwrap_or("");
        if rapid {
            if let Some(decl) = l.strip_prefix("VAR ") {
                let (head, init) = decl
                    .trim_end_matches(';')
                    .split_once(" := ")
                    .expect("an initial value");
                let name = head.split_whitespace().nth(1).unwrap();
                out.push(Ins::Assign(name.to_ascii_uppercase(), value(init)));
                continue;
            }
            if l == "EXIT;" {
                out.push(Ins::Halt);
                continue;
            }
            // The robot stands (before a decision): the motions before end.
            if l == "WaitTime \\InPos, 0;" {
                out.push(Ins::WaitSec);
                continue;
            }
            if let Some(c) = l.strip_prefix("WaitUntil ") {
                let c = c.trim_end_matches(';');
                let c = c.strip_suffix(" \\PollRate:=0.04").unwrap_or(c);
                let (c, settle) = match c.strip_prefix("\\InPos, ") {
                    Some(c) => (c, true),
                    None => (c, false),
                };
                // A watched wait: `c \MaxTime:=s \TimeFlag:=v` (its time counted once the
                // robot stands).
                if let Some((c, rest)) = c.split_once(" \\MaxTime:=") {
                    let (s, flag) = rest.split_once(" \\TimeFlag:=").expect("\\TimeFlag");
                    let timer = "\\MaxTime".to_owned();
                    if settle {
                        out.push(Ins::WaitSec);
                    }
                    out.push(Ins::TimerStart(timer.clone()));
                    let ms = s.parse::<f64>().unwrap() * 1000.0;
                    out.push(Ins::WaitFor(
                        X::Any(vec![cond(c), X::Late(timer, ms)]),
                        settle,
                    ));
                    out.push(Ins::Assign(
                        flag.to_ascii_uppercase(),
                        X::Not(Box::new(cond(c))),
                    ));
                    continue;
                }
                out.push(Ins::WaitFor(cond(c), settle));
                continue;
            }
            if l.starts_with("TPWrite ") {
                out.push(Ins::Show);
                continue;
            }
            if l == "TPErase;" {
                out.push(Ins::Clear);
                continue;
            }
            if let Some(rest) = l.strip_prefix("SetDO ") {
                let (sig, v) = rest.trim_end_matches(';').split_once(", ").unwrap();
                // A wire; any other output is a step's own code.
                if wires.drives(me, sig) {
                    out.push(Ins::SetOut(sig.to_owned(), value(v)));
                }
                continue;
            }
        } else {
            if let Some(rest) = l.strip_prefix("set_standard_digital_out(") {
                let (n, v) = rest.trim_end_matches(')').split_once(", ").unwrap();
                // A wire; any other output is a step's own code.
                if wires.drives(me, n) {
                    out.push(Ins::SetOut(n.to_owned(), value(v)));
                }
                continue;
            }
            if l == "sync()" {
                continue;
            }
            if l == "halt" {
                out.push(Ins::Halt);
                continue;
            }
            // The clock thread (`skp_waited` is a timer here): `thread skp_clock():`
            // `while True:` … `end` `end`, and its start.
            if l == "thread skp_clock():" {
                let mut ends = 0;
                while ends < 2 {
                    ends += usize::from(lines[i] == "end");
                    i += 1;
                }
                continue;
            }
            if l == "skp_clock_thread = run skp_clock()" {
                continue;
            }
            if l == "skp_waited = 0.0" {
                out.push(Ins::TimerStart("skp_waited".to_owned()));
                continue;
            }
            // A wait's message in the log: at its start, and when it has ended.
            if l.starts_with("textmsg(\"skillpost: ") {
                out.push(if l.ends_with("the wait has ended\")") {
                    Ins::Clear
                } else {
                    Ins::Show
                });
                continue;
            }
            // A wait: `while c:` `sync()` `end`.
            if let Some(c) = l.strip_prefix("while ").and_then(|c| c.strip_suffix(':'))
                && lines.get(i) == Some(&"sync()")
                && lines.get(i + 1) == Some(&"end")
            {
                i += 2;
                // A watched wait: `while not ((c) or (skp_waited >= s)):`.
                let watched = c
                    .strip_prefix("not (")
                    .and_then(|c| c.strip_suffix(")"))
                    .and_then(|c| c.rsplit_once(" or (skp_waited >= "));
                if let Some((head, s)) = watched {
                    let ms = s.trim_end_matches(')').parse::<f64>().unwrap() * 1000.0;
                    out.push(Ins::WaitFor(
                        X::Any(vec![cond(head), X::Late("skp_waited".to_owned(), ms)]),
                        false,
                    ));
                } else if c == "not is_steady()" {
                    out.push(Ins::WaitSec);
                } else {
                    out.push(Ins::WaitFor(X::Not(Box::new(cond(c))), false));
                }
                continue;
            }
        }
        let upper = head.to_ascii_uppercase();
        match (rapid, upper.as_str()) {
            (true, "IF") | (false, "IF") => {
                let c = if rapid {
                    l[3..].strip_suffix(" THEN").unwrap()
                } else {
                    l[3..].strip_suffix(':').unwrap()
                };
                out.push(Ins::JumpIfNot(cond(c), 0));
                open.push(Block::If {
                    test: out.len() - 1,
                    to_end: Vec::new(),
                });
            }
            (true, "ELSEIF") | (false, "ELIF") => {
                let c = if rapid {
                    l[7..].strip_suffix(" THEN").unwrap()
                } else {
                    l[5..].strip_suffix(':').unwrap()
                };
                let Some(Block::If { test, to_end }) = open.last_mut() else {
                    panic!("ELSEIF outside IF")
                };
                out.push(Ins::Jump(0));
                to_end.push(out.len() - 1);
                let (t, here) = (*test, out.len());
                out.push(Ins::JumpIfNot(cond(c), 0));
                *test = here;
                patch(&mut out, t, here);
            }
            (true, "ELSE") | (false, "ELSE") => {
                let Some(Block::If { test, to_end }) = open.last_mut() else {
                    panic!("ELSE outside IF")
                };
                out.push(Ins::Jump(0));
                to_end.push(out.len() - 1);
                let (t, here) = (*test, out.len());
                *test = usize::MAX;
                patch(&mut out, t, here);
            }
            (true, "ENDIF") | (true, "ENDWHILE") | (false, "END") => {
                let here_after = |out: &Vec<Ins>| out.len();
                match open.pop().expect("an end without a block") {
                    Block::If { test, to_end } => {
                        let here = here_after(&out);
                        if test != usize::MAX {
                            patch(&mut out, test, here);
                        }
                        for j in to_end {
                            patch(&mut out, j, here);
                        }
                    }
                    Block::While {
                        start,
                        test,
                        breaks,
                    } => {
                        out.push(Ins::Jump(start));
                        let here = out.len();
                        patch(&mut out, test, here);
                        for j in breaks {
                            patch(&mut out, j, here);
                        }
                    }
                }
            }
            (true, "WHILE") | (false, "WHILE") => {
                let c = if rapid {
                    l[6..].strip_suffix(" DO").unwrap()
                } else {
                    l[6..].strip_suffix(':').unwrap()
                };
                let start = out.len();
                out.push(Ins::JumpIfNot(cond(c), 0));
                open.push(Block::While {
                    start,
                    test: start,
                    breaks: Vec::new(),
                });
            }
            (false, "BREAK") => {
                out.push(Ins::Jump(0));
                let at = out.len() - 1;
                let breaks = open
                    .iter_mut()
                    .rev()
                    .find_map(|b| match b {
                        Block::While { breaks, .. } => Some(breaks),
                        _ => None,
                    })
                    .expect("break outside while");
                breaks.push(at);
            }
            _ => {
                // `x := v;` (RAPID), `x = v` (URScript); anything else is a step's code.
                let assign = if rapid {
                    l.strip_suffix(';').and_then(|a| a.split_once(" := "))
                } else {
                    l.split_once(" = ")
                };
                if let Some((lhs, rhs)) = assign
                    && lhs.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                {
                    out.push(Ins::Assign(lhs.to_ascii_uppercase(), value(rhs)));
                }
            }
        }
    }
    panic!("the main routine does not end");
}

/// The flow base's blackboard with a robot `R1`, `R2`, … per language of `langs`, each on a
/// controller of its own with the base's signals and skills (readable in its language, its IRL
/// file `kr15-2-<language>.irl`), and `m` wires from each to each other
/// (`benches/common/cell.rs`): robot `k`'s output `To_R<p>_<j>` drives robot `p`'s input
/// `From_R<k>_<j>`. KRL: `$OUT[100 + 10 p + j]` and `$IN[200 + 10 k + j]`; RAPID: `Address`
/// `do_To_R<p>_<j>`, `di_From_R<k>_<j>`; URScript (one peer at most, `m` ≤ 7): standard digital
/// output `j`, input `j + 3`.
pub fn cell_blackboard(langs: &[Lang], m: usize) -> String {
    let n = langs.len();
    let raw = std::fs::read_to_string(repo().join("fixtures/base/flow/Blackboard.aml")).unwrap();
    assert!(
        !langs.contains(&Lang::UrScript) || n == 2,
        "a UR robot has one peer"
    );
    crate::cell::cell_blackboard(
        "KUKA KR15-2",
        n,
        m,
        &|k| langs[k - 1].blackboard(&raw),
        &|k, p, j| {
            let number = |v: usize| ("Number", v.to_string());
            match langs[k - 1] {
                Lang::Krl => (number(100 + 10 * p + j), number(200 + 10 * p + j)),
                Lang::Rapid => (
                    ("Address", format!("do_To_R{p}_{j}")),
                    ("Address", format!("di_From_R{p}_{j}")),
                ),
                // Standard digital inputs 4-7, then boolean input registers (a fieldbus).
                Lang::UrScript if j + 3 <= 7 => (number(j), number(j + 3)),
                Lang::UrScript => (
                    number(j),
                    ("Address", format!("read_input_boolean_register({j})")),
                ),
            }
        },
        &|k, text| {
            let mut text = text.replace(
                "<Value>kr15-2.irl</Value>",
                &format!("<Value>kr15-2-{}.irl</Value>", langs[k - 1].ext()),
            );
            // A wait on a partner shows on the pendant after 50 ms (steps here take 0.1 to
            // 500 ms: the default 10 s would never show).
            let at = text.find('\n').unwrap();
            text.insert_str(
                at,
                &format!("\n<Attribute Name=\"HandshakeTimeout\" AttributeDataType=\"xs:double\"><Value>{HANDSHAKE_TIMEOUT_S}</Value></Attribute>"),
            );
            text
        },
    )
}

/// The `HandshakeTimeout` of the robots of [`cell_blackboard`], in seconds.
pub const HANDSHAKE_TIMEOUT_S: f64 = 0.05;

/// Puts each skill step of a chart on one of `n` robots at random; returns the chart and each
/// step's robot (from 0), by step name.
pub fn spread(chart: &str, n: usize, rng: &mut Rng) -> (String, HashMap<String, usize>) {
    let mut out = String::new();
    let mut of = HashMap::new();
    let mut rest = chart;
    let mut step_name = String::new();
    let marker = "<ressource name=\"KUKA KR15-2\"/>";
    loop {
        let next_step = rest.find("<step ");
        let next_res = rest.find(marker);
        match (next_step, next_res) {
            (Some(s), r) if r.is_none_or(|r| s < r) => {
                let name_at = rest[s..].find("name=\"").unwrap() + s + 6;
                let name_end = rest[name_at..].find('"').unwrap() + name_at;
                step_name = rest[name_at..name_end].to_owned();
                out.push_str(&rest[..name_end]);
                rest = &rest[name_end..];
            }
            (_, Some(r)) => {
                let k = (rng.next() % n as u64) as usize;
                of.insert(step_name.clone(), k);
                out.push_str(&rest[..r]);
                out.push_str(&format!("<ressource name=\"R{}\"/>", k + 1));
                rest = &rest[r + marker.len()..];
            }
            _ => break,
        }
    }
    out.push_str(rest);
    (out, of)
}

/// A compiled cell: each robot's program (`None` for a robot without steps: its main file,
/// KRL's `.dat`), its language, the wires.
pub struct CellPrograms {
    pub programs: Vec<Option<(String, String)>>,
    pub langs: Vec<Lang>,
    pub wires: Wires,
}

/// Writes the project (robots in `langs`) and compiles it with the binary.
pub fn compile_cell(
    dir: &std::path::Path,
    chart: &str,
    langs: &[Lang],
    m: usize,
) -> Result<CellPrograms, String> {
    // A fresh project: no program of an earlier one left.
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("Blackboard.aml"), cell_blackboard(langs, m)).unwrap();
    let irl = std::fs::read_to_string(repo().join("fixtures/base/flow/kr15-2.irl")).unwrap();
    for lang in langs {
        std::fs::write(
            dir.join(format!("kr15-2-{}.irl", lang.ext())),
            lang.irl(&irl),
        )
        .unwrap();
    }
    std::fs::write(dir.join("sfc.xml"), chart).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["--lf", "Blackboard.aml", "Cell"])
        .current_dir(dir)
        .output()
        .unwrap();
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).into_owned());
    }
    product_simulator_agrees(dir);
    let programs = (1..=langs.len())
        .zip(langs)
        .map(|(k, lang)| {
            let read =
                |ext: &str| std::fs::read_to_string(dir.join(format!("Cell_R{k}.{ext}"))).ok();
            let main = read(lang.ext())?;
            let dat = if *lang == Lang::Krl {
                read("dat")?
            } else {
                String::new()
            };
            Some(crate::parts::follow(*lang, dir, main, dat))
        })
        .collect();
    let names: Vec<String> = (1..=langs.len()).map(|k| format!("R{k}")).collect();
    let wires = Wires::read(
        &std::fs::read_to_string(dir.join("Blackboard.aml")).unwrap(),
        &names,
    );
    Ok(CellPrograms {
        programs,
        langs: langs.to_vec(),
        wires,
    })
}

/// The product's simulator (`skillpost simulate`, docs/SIMULATE.md) runs the same cell 5
/// times under random inputs and timing: no run may have a problem (a deadlock, a step out of
/// the chart's order, a wire set while a motion ran, controllers deciding differently), and
/// every run ends, runs the chart's rounds or stops at its step limit (random inputs that keep
/// a loop going). One kind is allowed: `stuck` — the flow base's
/// `Gripper_Closed` is an output of the robot, which this co-simulation's world sets and the
/// product's does not (nothing in the programs sets it).
fn product_simulator_agrees(dir: &std::path::Path) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args([
            "simulate",
            "Blackboard.aml",
            "Cell",
            "--runs",
            "10",
            "--format",
            "json",
        ])
        .current_dir(dir)
        .output()
        .unwrap();
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "skillpost simulate in {}: not JSON ({e}): {}",
            dir.display(),
            String::from_utf8_lossy(&out.stderr)
        )
    });
    assert!(
        matches!(out.status.code(), Some(0 | 1)),
        "skillpost simulate in {}: {}",
        dir.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    for run in report["runs"].as_array().unwrap() {
        let problems = run["problems"].as_array().unwrap();
        let other: Vec<&serde_json::Value> =
            problems.iter().filter(|p| p["kind"] != "stuck").collect();
        // `SKILLPOST_KEEP_FAILED=DIR`: the project is copied there to look at.
        if !other.is_empty()
            && let Some(keep) = std::env::var_os("SKILLPOST_KEEP_FAILED")
        {
            static N: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
            let n = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let keep = std::path::Path::new(&keep).join(n.to_string());
            let keep = keep.as_path();
            let _ = std::fs::create_dir_all(keep);
            for e in std::fs::read_dir(dir).unwrap().flatten() {
                let _ = std::fs::copy(e.path(), keep.join(e.file_name()));
            }
        }
        assert!(
            other.is_empty(),
            "skillpost simulate found a problem in {}: {other:#?}",
            dir.display()
        );
        assert!(
            run["ended"] == true
                || run["repeats"] == true
                || run["capped"] == true
                || !problems.is_empty(),
            "{}: {run:#}",
            dir.display()
        );
    }
}

/// Runs a compiled cell `runs` times with random timing and inputs; the first failure, if any.
pub fn co_simulate(
    chart: &Chart,
    cell: &CellPrograms,
    robot_of: &HashMap<String, usize>,
    seed: u64,
    runs: usize,
    mutation: Mutation,
    only: Option<Lang>,
) -> Result<Report, String> {
    co_simulate_in(
        chart,
        cell,
        robot_of,
        seed,
        runs,
        mutation,
        only,
        Scenario::Once,
    )
}

/// The pairs of controllers whose programs read a wire of the other (partners: they meet at
/// the start barrier), both ways round.
fn partners(
    parsed: &[Option<(Vec<Ins>, String)>],
    wires: &Wires,
) -> std::collections::BTreeSet<(usize, usize)> {
    fn krl(e: &KExpr, out: &mut Vec<String>) {
        match e {
            KExpr::Sys(s) => {
                if let Some(n) = s.strip_prefix("$IN[").and_then(|r| r.strip_suffix(']')) {
                    out.push(n.to_owned());
                }
            }
            KExpr::Not(a) | KExpr::Neg(a) => krl(a, out),
            KExpr::Bin(_, a, b) => {
                krl(a, out);
                krl(b, out);
            }
            _ => {}
        }
    }
    fn reads(e: &X, out: &mut Vec<String>) {
        match e {
            X::K(k) => krl(k, out),
            X::Wire(w) => out.push(w.clone()),
            X::Not(a) => reads(a, out),
            X::Same(a, b) => {
                reads(a, out);
                reads(b, out);
            }
            X::All(v) | X::Any(v) => v.iter().for_each(|x| reads(x, out)),
            _ => {}
        }
    }
    let mut pairs = std::collections::BTreeSet::new();
    for (a, p) in parsed.iter().enumerate() {
        let Some((ins, _)) = p else { continue };
        let mut names = Vec::new();
        for i in ins {
            match i {
                Ins::WaitFor(e, _) | Ins::JumpIfNot(e, _) => reads(e, &mut names),
                _ => {}
            }
        }
        for n in names {
            if let Some((b, _)) = wires.source(a, &n) {
                pairs.insert((a, b));
                pairs.insert((b, a));
            }
        }
    }
    pairs
}

/// One run of the chart by the controllers (the steps of one run of each program): the chart
/// explains it (`ended`: all programs ended, so the chart ends there too), and no step started
/// before a step the chart puts before it had ended — or at all, when that step was cut short.
fn check_run(
    chart: &Chart,
    runs: &[(&[Step], Option<usize>)],
    robot_of: &HashMap<String, usize>,
    ended: bool,
) -> Result<(), String> {
    let seen: Vec<Vec<String>> = runs
        .iter()
        .map(|(steps, _)| steps.iter().map(|s| s.0.clone()).collect())
        .collect();
    let Some(explained) = chart.explain(&seen, &|name| robot_of[name], ended) else {
        return Err(format!(
            "the controllers did not do what one run of the chart does: {seen:?} (all ended: {ended})"
        ));
    };
    // Each action of the run: its robot's how-manieth step.
    let mut counts = vec![0usize; runs.len()];
    let place: Vec<(usize, usize)> = explained
        .iter()
        .map(|(name, _)| {
            let c = robot_of[name];
            counts[c] += 1;
            (c, counts[c] - 1)
        })
        .collect();
    for (i, (name, preds)) in explained.iter().enumerate() {
        let (c, k) = place[i];
        let start = runs[c].0[k].1;
        for &p in preds {
            let (pc, pk) = place[p];
            let end = runs[pc].0[pk].2;
            if runs[pc].1 == Some(pk) {
                return Err(format!(
                    "step {name} on R{} started at {start:.3} after step {} on R{} was cut short by a start again",
                    c + 1,
                    explained[p].0,
                    pc + 1
                ));
            }
            if end > start {
                return Err(format!(
                    "step {name} on R{} started at {start:.3}, before step {} on R{} ended at {end:.3}",
                    c + 1,
                    explained[p].0,
                    pc + 1
                ));
            }
        }
    }
    Ok(())
}

/// What the co-simulation saw besides the faults it reports.
#[derive(Debug, Default, Clone)]
pub struct Report {
    /// The messages of waits on partners that lasted (shown and taken away again), by the
    /// language of the program that showed them.
    pub messages: std::collections::BTreeMap<String, usize>,
}

/// [`co_simulate`] with the operator starting the programs as `scenario` says.
#[allow(clippy::too_many_arguments)]
pub fn co_simulate_in(
    chart: &Chart,
    cell: &CellPrograms,
    robot_of: &HashMap<String, usize>,
    seed: u64,
    runs: usize,
    mutation: Mutation,
    only: Option<Lang>,
    scenario: Scenario,
) -> Result<Report, String> {
    let mut report = Report::default();
    let parsed: Vec<Option<(Vec<Ins>, String)>> = cell
        .programs
        .iter()
        .zip(&cell.langs)
        .enumerate()
        .map(|(k, (p, &lang))| {
            p.as_ref().map(|(main, dat)| {
                // Only the programs of one language are broken, when one is named.
                let m = match mutation {
                    Mutation::None => Mutation::None,
                    _ if only.is_some_and(|l| l != lang) => Mutation::None,
                    m => m,
                };
                let text = mutate(main, m, lang);
                let ins = match lang {
                    Lang::Krl => parse(&krl_signals(&text, dat)),
                    _ => parse_structured(&ur_constants(&text), lang, &cell.wires, k),
                };
                (ins, dat.clone())
            })
        })
        .collect();
    let pairs = partners(&parsed, &cell.wires);
    let mut rng = Rng(seed | 1);
    let cap = 25;
    for run in 0..runs {
        let seq: Vec<Phase> = sequences(rng.next(), 1).remove(0);
        let phases: Vec<HashMap<String, bool>> = seq.iter().map(bits).collect();
        let mut t = 0.0;
        let changes: Vec<f64> = (1..phases.len())
            .map(|_| {
                t += (rng.next() % 400) as f64;
                t
            })
            .collect();
        let cycles = match scenario {
            Scenario::Cycles(n) => n.max(1),
            _ => 1,
        };
        let ctls: Vec<Ctl> = parsed
            .iter()
            .map(|p| {
                let (ins, dat) = p.clone().unwrap_or((vec![Ins::End], String::new()));
                let (signals, vars) = read_dat(&dat);
                let slow = [0.1, 1.0, 3.0, 10.0][(rng.next() % 4) as usize];
                let own_steps = ins
                    .iter()
                    .filter_map(|i| match i {
                        Ins::Step(n) => Some(n.clone()),
                        _ => None,
                    })
                    .collect();
                Ctl {
                    ins,
                    pc: 0,
                    own_steps,
                    vars,
                    signals,
                    t: (rng.next() % 200) as f64,
                    motion_end: 0.0,
                    eps: [0.001, 0.1, 1.0][(rng.next() % 3) as usize],
                    slow,
                    outs: HashMap::new(),
                    ended: false,
                    capped: false,
                    blocked: false,
                    steps: Vec::new(),
                    advance_faults: Vec::new(),
                    halted: false,
                    past: Vec::new(),
                    restarts: Vec::new(),
                    restart_at: None,
                    cycles_left: cycles - 1,
                    blocking: false,
                    timers: HashMap::new(),
                    wake: None,
                    watched: None,
                    shown: None,
                    messages: Vec::new(),
                    message_faults: Vec::new(),
                    last_step: None,
                    late_tells: Vec::new(),
                }
            })
            .collect();
        let mut ctls = ctls;
        for (x, lang) in ctls.iter_mut().zip(&cell.langs) {
            x.blocking = *lang == Lang::UrScript;
        }
        let mut w = World {
            ctls,
            wires: &cell.wires,
            seq,
            phases,
            changes,
            salt: rng.next(),
            trace: std::env::var("COSIM_TRACE_RUN").is_ok_and(|v| v == run.to_string()),
        };
        let n = w.ctls.len();
        let mut victim = None;
        if scenario == Scenario::Fault {
            // One started again at a random time once all have started (every program starts
            // before 200), the others later, each at a random time.
            let v = (rng.next() % n as u64) as usize;
            let at = 300.0 + (rng.next() % 400) as f64;
            for c in 0..n {
                w.ctls[c].restart_at = Some(if c == v {
                    at
                } else {
                    at + 1.0 + (rng.next() % 600) as f64
                });
            }
            victim = Some(v);
        }
        w.run(&mut rng, cap);
        let fail = |why: String| Err(format!("run {run} ({scenario:?}): {why}"));
        for (c, x) in w.ctls.iter().enumerate() {
            if let Some((out, step)) = x.advance_faults.first() {
                return fail(format!(
                    "R{} {out} while the motion of step {step} still ran (the advance run)",
                    c + 1
                ));
            }
            if x.halted {
                return fail(format!(
                    "R{} stopped (a partner was started again) and nobody started it again",
                    c + 1
                ));
            }
            if let Some(why) = x.message_faults.first() {
                return fail(format!("R{} {why}", c + 1));
            }
            if let Some(why) = x.late_tells.first() {
                return fail(format!("R{} {why}", c + 1));
            }
            if x.restart_at.is_some() {
                return fail(format!("R{} was never started again as planned", c + 1));
            }
        }
        if let Some(why) = w.deadlock() {
            return fail(why);
        }
        for (x, lang) in w.ctls.iter().zip(&cell.langs) {
            *report.messages.entry(format!("{lang:?}")).or_default() += x.messages.len();
        }
        let ended = w.ctls.iter().all(|x| x.ended);
        // Every run of each program: the past ones, then this one.
        let sessions: Vec<Vec<(&[Step], Option<usize>)>> = w
            .ctls
            .iter()
            .map(|x| {
                x.past
                    .iter()
                    .map(|(s, cut)| (s.as_slice(), *cut))
                    .chain([(x.steps.as_slice(), None)])
                    .collect()
            })
            .collect();
        match scenario {
            Scenario::Once => {
                let r: Vec<_> = sessions.iter().map(|s| s[0]).collect();
                if let Err(e) = check_run(chart, &r, robot_of, ended) {
                    return fail(e);
                }
            }
            Scenario::Cycles(_) => {
                let k_max = sessions.iter().map(Vec::len).max().unwrap_or(1);
                for k in 0..k_max {
                    // A program that ran fewer cycles (an endless chart, capped): nothing.
                    let r: Vec<(&[Step], Option<usize>)> = sessions
                        .iter()
                        .map(|s| s.get(k).copied().unwrap_or((&[][..], None)))
                        .collect();
                    // Every program ended this cycle (a capped one did not).
                    let done = w
                        .ctls
                        .iter()
                        .all(|x| k < x.past.len() || (k == x.past.len() && x.ended));
                    if let Err(e) = check_run(chart, &r, robot_of, done) {
                        return fail(format!("cycle {}: {e}", k + 1));
                    }
                }
                // A partner's next cycle begins after this one's steps have ended.
                for &(a, b) in &pairs {
                    for k in 1..k_max {
                        let (Some(prev), Some(next)) = (sessions[b].get(k - 1), sessions[a].get(k))
                        else {
                            continue;
                        };
                        let done = prev.0.iter().map(|s| s.2).fold(f64::MIN, f64::max);
                        if let Some(s) = next.0.iter().find(|s| s.1 < done) {
                            return fail(format!(
                                "cycle {}: step {} on R{} started at {:.3}, before R{} ended cycle {k} at {done:.3}",
                                k + 1,
                                s.0,
                                a + 1,
                                s.1,
                                b + 1
                            ));
                        }
                    }
                }
            }
            Scenario::Fault => {
                // Before the starts again: a part of one run of the chart, no step after one
                // cut short.
                let first: Vec<_> = sessions.iter().map(|s| s[0]).collect();
                if let Err(e) = check_run(chart, &first, robot_of, false) {
                    return fail(format!(
                        "before the starts again (R{} first): {e}",
                        victim.unwrap() + 1
                    ));
                }
                // After: no step before every partner was started again, then one whole run.
                for &(a, b) in &pairs {
                    let Some(&again) = w.ctls[b].restarts.last() else {
                        continue;
                    };
                    if let Some(s) = sessions[a].last().unwrap().0.iter().find(|s| s.1 < again) {
                        return fail(format!(
                            "R{} started step {} at {:.3}, before its partner R{} was started again at {again:.3}",
                            a + 1,
                            s.0,
                            s.1,
                            b + 1
                        ));
                    }
                }
                let last: Vec<_> = sessions.iter().map(|s| *s.last().unwrap()).collect();
                if let Err(e) = check_run(chart, &last, robot_of, ended) {
                    return fail(format!(
                        "after the starts again (R{} first): {e}",
                        victim.unwrap() + 1
                    ));
                }
            }
        }
    }
    Ok(report)
}

/// Wires from each robot of a random cell to each other: a strobe, the data bits of the
/// largest decision, an acknowledgement, the run and the ready wire.
pub const WIRES: usize = 7;

/// A random chart on 2 to 4 robots, compiled; `None` when it uses fewer than two robots.
pub fn random_cell(
    dir: &std::path::Path,
    seed: u64,
) -> Option<(Chart, CellPrograms, HashMap<String, usize>, usize)> {
    match random_cell_of(dir, seed, &ChartGen::chart(seed)) {
        Ok(cell) => cell,
        Err(e) => panic!(
            "seed {seed}: the cell does not compile: {e}\n{}",
            ChartGen::chart(seed)
        ),
    }
}

/// [`random_cell`] of the chart `text` (the random chart of `seed`, changed): `Err` when the
/// cell does not compile.
pub type RandomCell = (Chart, CellPrograms, HashMap<String, usize>, usize);
pub fn random_cell_of(
    dir: &std::path::Path,
    seed: u64,
    text: &str,
) -> Result<Option<RandomCell>, String> {
    let mut rng = Rng(seed.wrapping_mul(0x2545_F491_4F6C_DD1D) | 1);
    // KUKA cells, ABB cells, KUKA and ABB mixed, a UR with a robot of any kind.
    let any = |rng: &mut Rng| [Lang::Krl, Lang::Rapid][(rng.next() % 2) as usize];
    let langs: Vec<Lang> = match seed % 4 {
        0..=2 => {
            let n = 2 + (rng.next() % 3) as usize;
            (0..n)
                .map(|_| match seed % 4 {
                    0 => Lang::Krl,
                    1 => Lang::Rapid,
                    _ => any(&mut rng),
                })
                .collect()
        }
        _ => vec![
            Lang::UrScript,
            [Lang::Krl, Lang::Rapid, Lang::UrScript][(rng.next() % 3) as usize],
        ],
    };
    let n = langs.len();
    let (chart, robot_of) = spread(text, n, &mut rng);
    let used: std::collections::BTreeSet<usize> = robot_of.values().copied().collect();
    if used.len() < 2 {
        return Ok(None);
    }
    let cell = compile_cell(dir, &chart, &langs, WIRES)?;
    Ok(Some((Chart::read(&dir.join("sfc.xml")), cell, robot_of, n)))
}

/// A cell fixture (`fixtures/ok/<case>`) compiled with the binary: its programs (name and
/// language) in the order of `controllers`, each step's program (by the step titles of each),
/// its chart.
pub fn fixture_cell(
    dir: &std::path::Path,
    case: &str,
    programs: &[(&str, Lang)],
    controllers: &[&str],
) -> (Chart, CellPrograms, HashMap<String, usize>) {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
    let toml: toml::Value = toml::from_str(
        &std::fs::read_to_string(repo().join("fixtures/ok").join(case).join("case.toml")).unwrap(),
    )
    .unwrap();
    let program = toml["program"].as_str().unwrap().to_owned();
    let bases: Vec<&str> = match toml.get("base") {
        Some(toml::Value::String(b)) => vec![b.as_str()],
        Some(toml::Value::Array(v)) => v.iter().map(|b| b.as_str().unwrap()).collect(),
        _ => Vec::new(),
    };
    for base in bases {
        crate::copy_dir(&repo().join("fixtures/base").join(base), dir);
    }
    crate::copy_dir(&repo().join("fixtures/ok").join(case), dir);
    let bb_name = match toml.get("blackboard") {
        Some(b) => b.as_str().unwrap().to_owned(),
        None => std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .find(|n| n.ends_with(".aml"))
            .unwrap(),
    };
    // The case's own arguments too (`--max-lines` of a split cell).
    let args: Vec<String> = toml
        .get("args")
        .and_then(|a| a.as_array())
        .map(|a| a.iter().map(|v| v.as_str().unwrap().to_owned()).collect())
        .unwrap_or_default();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["--lf", &bb_name, &program])
        .args(&args)
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{case}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let names: Vec<String> = controllers.iter().map(|c| c.to_string()).collect();
    let wires = Wires::read(
        &std::fs::read_to_string(dir.join(&bb_name)).unwrap(),
        &names,
    );
    let mut robot_of = HashMap::new();
    let texts: Vec<Option<(String, String)>> = programs
        .iter()
        .enumerate()
        .map(|(k, (p, lang))| {
            let main = std::fs::read_to_string(dir.join(format!("{p}.{}", lang.ext()))).unwrap();
            let dat = match lang {
                Lang::Krl => std::fs::read_to_string(dir.join(format!("{p}.dat"))).unwrap(),
                _ => String::new(),
            };
            // A split program's calls of its parts followed.
            let (main, dat) = crate::parts::follow(*lang, dir, main, dat);
            let ins = match lang {
                Lang::Krl => parse(&krl_signals(&main, &dat)),
                _ => parse_structured(&ur_constants(&main), *lang, &wires, k),
            };
            for i in ins {
                if let Ins::Step(name) = i {
                    robot_of.insert(name, k);
                }
            }
            Some((main, dat))
        })
        .collect();
    (
        Chart::read(&dir.join("sfc.xml")),
        CellPrograms {
            programs: texts,
            langs: programs.iter().map(|p| p.1).collect(),
            wires,
        },
        robot_of,
    )
}
