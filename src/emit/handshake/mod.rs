//! Handshakes between the programs of a cell (docs/CELLS.md), in each language's own I/O
//! statements, written inline where the program tree has a [`Block::Tell`] or
//! [`Block::Hear`] (see `plan::cell` for where they stand and why they are enough).
//!
//! One channel (controller A → controller B) is a strobe wire A → B, for a decision its data
//! wires A → B, and an acknowledgement wire B → A. Both sides keep a toggle per channel
//! (`skp_txN` on A, `skp_rxN` on B; every wire `FALSE` at the cell's start):
//!
//! - **tell** (A): wait until the acknowledgement equals `skp_txN` (B has read the last
//!   message; this wait also ends the motion before it: KRL's `WAIT FOR` stops the advance run,
//!   RAPID's `WaitUntil \InPos` waits for the robot to stand, URScript's moves return at
//!   their target), set the data wires, toggle `skp_txN` and put it on the strobe;
//! - **hear** (B): toggle `skp_rxN`, wait until the strobe equals it (and, like every wait of
//!   a handshake, until the motions before it have ended: no wire changes while a motion before
//!   it may still run), read the data wires into `skp_got`, put `skp_rxN` on the
//!   acknowledgement.
//!
//! A sender is never more than one message ahead on a channel, so no toggle is ever missed,
//! also across loop rounds.

mod forms;

use super::EmitInput;
use super::flow::Lines;
use crate::diag::{Code, Diagnostic, Diagnostics};
use crate::lang::Language;
use crate::model::{ElementKind, Signal, SignalKind};
use crate::plan::cell::{Cell, Kind, Link, Message};

/// The variable a decision is read into.
pub const DECISION_VAR: &str = "skp_got";

/// KRL's message of a stop (`KrlMsg_T`), its parameters, options and handle (`.dat`).
const MSG_VAR: &str = "skp_msg";
const PAR_VAR: &str = "skp_par";
const OPT_VAR: &str = "skp_opt";
const HANDLE_VAR: &str = "skp_handle";
/// KRL: what `Clr_KrlMsg` answers (`.dat`).
const CLEARED_VAR: &str = "skp_cleared";
/// KRL: the program's routines of its handshakes ([`Hand::routines`]).
const STOP: &str = "skp_stop";
const WATCH: &str = "skp_watch";
const SHOW: &str = "skp_show";
const HIDE: &str = "skp_hide";
/// RAPID: whether a watched wait ran out of time (`\TimeFlag`, module data).
const LATE_VAR: &str = "skp_late";
/// URScript: the seconds a watched wait has lasted (advanced by the program's clock thread).
pub const WATCH_VAR: &str = "skp_waited";

/// A program's place in its cell.
#[derive(Debug, Clone, Copy)]
pub struct CellView<'a> {
    pub cell: &'a Cell,
    /// This program's controller (index into `cell.controllers`).
    pub me: usize,
}

/// Writes one program's handshakes.
pub struct Hand<'a> {
    input: &'a EmitInput<'a>,
    view: CellView<'a>,
    lang: Language,
    /// What every handshake site repeats, made once (a cell of 10,000 steps has thousands of
    /// sites): each controller's name, transliterated; for each partner, its run wire read as
    /// "is `FALSE`" (the restart guard); for each channel of this program, the condition its
    /// tell (this program sends) or hear (it receives) waits for, and the name of the wire it
    /// reads there.
    names: Vec<String>,
    guards: Vec<String>,
    waits: Vec<(String, String)>,
    /// KRL and URScript: the name each wire on a numbered input or output (`$IN[n]`,
    /// `$OUT[n]`; URScript's standard digital I/O) goes by in the program, its signal's name in
    /// the blackboard as a KRL name (`SIGNAL` in the `.dat`, a URScript constant set at the
    /// program's start), keyed by the signal's address; in declaration order, with the
    /// address (`$IN[41]`; URScript the number).
    names_of_wires: Vec<(usize, String, String)>,
}

impl<'a> Hand<'a> {
    pub fn new(input: &'a EmitInput<'a>) -> Option<Self> {
        let mut h = Hand {
            input,
            view: input.cell?,
            lang: input.profile.language(),
            names: Vec::new(),
            guards: Vec::new(),
            waits: Vec::new(),
            names_of_wires: Vec::new(),
        };
        let cell = h.view.cell;
        let bb = input.blackboard;
        h.names_of_wires = h.name_wires();
        h.names = cell
            .controllers
            .iter()
            .map(|&c| crate::names::transliterate(&bb.resources[c].name.text))
            .collect();
        let partners: Vec<usize> = cell.partners(h.view.me).collect();
        h.guards = (0..cell.controllers.len())
            .map(|p| {
                if partners.contains(&p) {
                    h.is(&h.run_of(p), false)
                } else {
                    String::new()
                }
            })
            .collect();
        h.waits = (0..cell.channels.len())
            .map(|k| {
                let ch = &cell.channels[k];
                let (wire, var, p) = if ch.from == h.view.me {
                    (ch.ack, format!("skp_tx{}", k + 1), ch.to)
                } else if ch.to == h.view.me {
                    (ch.strobe, format!("skp_rx{}", k + 1), ch.from)
                } else {
                    return (String::new(), String::new());
                };
                let read = h.read_wire(wire);
                let cond = h.join("OR", &[h.equals(&read, &var), h.guards[p].clone()]);
                (cond, h.wire_name(wire))
            })
            .collect();
        Some(h)
    }

    fn signal(&self, wire: Option<usize>, sender_side: bool) -> Option<&'a Signal> {
        let bb = self.input.blackboard;
        let w = &bb.wires[wire?];
        let (r, s) = if sender_side { w.from } else { w.to };
        bb.resources.get(r)?.signals.get(s)
    }

    /// The run wire partner `p` drives to this program, as read here.
    fn run_of(&self, p: usize) -> String {
        self.link_read(p, |l| l.run)
    }

    /// The ready wire partner `p` drives to this program, as read here.
    fn ready_of(&self, p: usize) -> String {
        self.link_read(p, |l| l.ready)
    }

    fn link_read(&self, p: usize, wire: fn(&Link) -> Option<usize>) -> String {
        self.read_wire(self.view.cell.link(p, self.view.me).and_then(wire))
    }

    /// How this program reads a wire it receives (nothing when the wire is not there; `check`
    /// reports that).
    fn read_wire(&self, wire: Option<usize>) -> String {
        self.signal(wire, false)
            .and_then(|s| self.read(s).ok())
            .unwrap_or_default()
    }

    /// The lines that set this program's run (or ready) wire to each partner to `level`.
    fn set_links(
        &self,
        out: &mut Vec<(usize, String)>,
        wire: fn(&Link) -> Option<usize>,
        level: bool,
    ) {
        let v = if level { self.t() } else { self.f() };
        for p in self.view.cell.partners(self.view.me) {
            if let Some(s) = self
                .view
                .cell
                .link(self.view.me, p)
                .and_then(|l| self.signal(wire(l), true))
                && let Ok(l) = self.set(s, v)
            {
                out.push((0, l));
            }
        }
    }

    /// A handshake's wait until the wire `read` equals the toggle `var`, which also ends when
    /// partner `p` was started again (its run wire `FALSE`; see [`Hand::stop_unless_running`]).
    /// `text` and `short` say what it waits for on the pendant when the wait lasts
    /// ([`Hand::watched_wait`]).
    fn guarded_wait(
        &self,
        out: &mut Vec<(usize, String)>,
        channel: usize,
        (text, short): (&str, &str),
        nr: u64,
    ) {
        self.watched_wait(out, &self.waits[channel].0, text, short, nr);
    }

    /// A wire as this program names it, for a comment: KRL's `SIGNAL` or URScript's constant,
    /// RAPID's signal, else its signal's name in the blackboard (`sender_side`: the wire this
    /// program drives).
    fn label(&self, wire: Option<usize>, sender_side: bool) -> String {
        let Some(s) = self.signal(wire, sender_side) else {
            return String::new();
        };
        if let Some(n) = self.wire_named(s) {
            return n.to_owned();
        }
        match &s.kind {
            SignalKind::Address { text, .. } => forms::clean(text),
            _ => crate::names::transliterate(&s.name.text),
        }
    }

    /// The wires of one kind (`run`, `ready`) the partners drive to this program, for a
    /// comment: `From_A_3` or `From_A_3, From_B_3`.
    fn labels_of(&self, wire: fn(&Link) -> Option<usize>) -> String {
        self.view
            .cell
            .partners(self.view.me)
            .map(|p| self.label(self.view.cell.link(p, self.view.me).and_then(wire), false))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The name of the signal a received wire arrives at on this controller (for a message).
    fn wire_name(&self, wire: Option<usize>) -> String {
        self.signal(wire, false)
            .map(|s| crate::names::transliterate(&s.name.text))
            .unwrap_or_default()
    }

    /// When partner `p` was started again (its run wire `FALSE`), the program stops with a
    /// message (`text`, or where a message is short a shorter one about `m`) and stays stopped
    /// until it is started again itself. Read after the wires of a message: a start again sets
    /// the run wire `FALSE` before any other, so a message read while it is still `TRUE` is
    /// this run's.
    fn stop_unless_running(
        &self,
        out: &mut Vec<(usize, String)>,
        p: usize,
        text: &str,
        m: &Message,
    ) {
        let id = self.input.sfc.elements[m.about].local_id;
        let short = format!(
            "{} started again; this program waited at localId {id}",
            self.name(p)
        );
        self.stop_if(out, &self.guards[p], text, &short, id, "");
    }

    fn name(&self, c: usize) -> &str {
        &self.names[c]
    }

    /// The controller that tells `m`.
    pub fn teller(&self, m: &Message) -> String {
        self.name(self.view.cell.channels[m.channel].from)
            .to_owned()
    }

    /// What a message is about, for its comment.
    fn about(&self, m: &Message) -> String {
        let e = &self.input.sfc.elements[m.about];
        match &e.kind {
            ElementKind::Step(st) => format!(
                "step '{}' (localId {})",
                crate::names::transliterate(&st.name),
                e.local_id
            ),
            _ => format!("localId {}", e.local_id),
        }
    }

    /// The lines of a tell, each with its level relative to the block's.
    pub fn tell(&self, m: &Message) -> Vec<(usize, String)> {
        let ch = &self.view.cell.channels[m.channel];
        let var = format!("skp_tx{}", m.channel + 1);
        let mut out = Vec::new();
        let what = match m.kind {
            Kind::Done => format!("{} is done", self.about(m)),
            Kind::Passed(c) => format!("it {} {}", c.verb(), self.about(m)),
            Kind::Decision => format!(
                "branch {} was taken at the selection {}",
                m.value + 1,
                self.about(m)
            ),
        };
        out.push((
            0,
            format!(
                "{}handshake: tell {} that {what}: wait for {} = {var} (read) or {} FALSE (started again)",
                self.comment(),
                self.name(ch.to),
                self.label(ch.ack, false),
                self.label(self.view.cell.link(ch.to, self.view.me).and_then(|l| l.run), false),
            ),
        ));
        let stop = format!(
            "{} started again; this program was to tell it: {what}",
            self.name(ch.to)
        );
        let id = self.input.sfc.elements[m.about].local_id;
        let wire = &self.waits[m.channel].1;
        let to = self.name(ch.to);
        self.guarded_wait(
            &mut out,
            m.channel,
            (
                &format!("waits until {to} has read: {what}; wire {wire}"),
                &format!("waits for {to} to read (localId {id}, wire {wire})"),
            ),
            id,
        );
        self.stop_unless_running(&mut out, ch.to, &stop, m);
        if m.kind == Kind::Decision {
            for (bit, &w) in ch.data.iter().enumerate() {
                let on = (m.value >> bit) & 1 == 1;
                if let Some(s) = self.signal(Some(w), true)
                    && let Ok(l) = self.set(s, if on { self.t() } else { self.f() })
                {
                    out.push((0, l));
                }
            }
        }
        out.push((0, self.toggle(&var)));
        if let Some(s) = self.signal(ch.strobe, true)
            && let Ok(l) = self.set(s, &var)
        {
            out.push((0, l));
        }
        out
    }

    /// The lines of a hear (a decision read into [`DECISION_VAR`]).
    pub fn hear(&self, m: &Message) -> Vec<(usize, String)> {
        let ch = &self.view.cell.channels[m.channel];
        let var = format!("skp_rx{}", m.channel + 1);
        let mut out = Vec::new();
        let what = match m.kind {
            Kind::Done => format!("until {} has done {}", self.name(ch.from), self.about(m)),
            Kind::Passed(c) => format!(
                "until {} {} {}",
                self.name(ch.from),
                c.verb(),
                self.about(m)
            ),
            Kind::Decision => format!(
                "for the branch {} takes at the selection {}",
                self.name(ch.from),
                self.about(m)
            ),
        };
        out.push((
            0,
            format!(
                "{}handshake: wait {what}: for {} = NOT {var} (the next message) or {} FALSE (started again)",
                self.comment(),
                self.label(ch.strobe, false),
                self.label(self.view.cell.link(ch.from, self.view.me).and_then(|l| l.run), false),
            ),
        ));
        out.push((0, self.toggle(&var)));
        let stop = match m.kind {
            Kind::Done => format!(
                "{} started again; waited for its {}",
                self.name(ch.from),
                self.about(m)
            ),
            Kind::Decision => format!(
                "{} started again; waited for its branch at the selection {}",
                self.name(ch.from),
                self.about(m)
            ),
            Kind::Passed(c) => format!(
                "{} started again; waited until it {} {}",
                self.name(ch.from),
                c.verb(),
                self.about(m)
            ),
        };
        let id = self.input.sfc.elements[m.about].local_id;
        let wire = &self.waits[m.channel].1;
        self.guarded_wait(
            &mut out,
            m.channel,
            (
                &format!("waits {what}; wire {wire}"),
                &format!(
                    "waits for {} (localId {id}, wire {wire})",
                    self.name(ch.from)
                ),
            ),
            id,
        );
        if m.kind == Kind::Decision {
            out.push((0, self.assign(DECISION_VAR, "0")));
            for (bit, &w) in ch.data.iter().enumerate() {
                let Some(read) = self.signal(Some(w), false).and_then(|s| self.read(s).ok()) else {
                    continue;
                };
                let add = self.assign(DECISION_VAR, &format!("{DECISION_VAR} + {}", 1 << bit));
                match self.lang {
                    Language::Krl => {
                        out.push((0, format!("IF {read} THEN")));
                        out.push((1, add));
                        out.push((0, "ENDIF".to_owned()));
                    }
                    Language::Rapid => {
                        out.push((0, format!("IF {read} = 1 THEN")));
                        out.push((1, add));
                        out.push((0, "ENDIF".to_owned()));
                    }
                    Language::UrScript => {
                        out.push((0, format!("if {read}:")));
                        out.push((1, add));
                        out.push((0, "end".to_owned()));
                    }
                }
            }
        }
        self.stop_unless_running(&mut out, ch.from, &stop, m);
        if let Some(s) = self.signal(ch.ack, true)
            && let Ok(l) = self.set(s, &var)
        {
            out.push((0, l));
        }
        out
    }

    /// The channels this program sends on and hears on.
    fn own(&self) -> (Vec<usize>, Vec<usize>) {
        let chs = &self.view.cell.channels;
        (
            (0..chs.len())
                .filter(|&c| chs[c].from == self.view.me)
                .collect(),
            (0..chs.len())
                .filter(|&c| chs[c].to == self.view.me)
                .collect(),
        )
    }

    /// The lines at the program's start: its run wires `FALSE` first (a partner waiting
    /// for it sees at once that it was started again), then every other wire it drives and
    /// every toggle; then the start barrier: wait until every partner is at its start (run
    /// `FALSE`), say ready, wait until every partner is ready, say running, wait until every
    /// partner is running (or one is back at its start), stop unless every partner is running,
    /// take ready back.
    pub fn init(&self) -> Vec<(usize, String)> {
        let (tx, rx) = self.own();
        if tx.is_empty() && rx.is_empty() {
            return Vec::new();
        }
        let c = self.comment();
        let partners: Vec<usize> = self.view.cell.partners(self.view.me).collect();
        let names = partners
            .iter()
            .map(|&p| self.name(p))
            .collect::<Vec<_>>()
            .join(", ");
        let mut out = Vec::new();
        if self.lang == Language::UrScript && !self.names_of_wires.is_empty() {
            out.push((
                0,
                format!("{c}handshake: the wires, standard digital I/O by their signals' names in the blackboard"),
            ));
            out.extend(
                self.names_of_wires
                    .iter()
                    .map(|(_, name, n)| (0, format!("{name} = {n}"))),
            );
        }
        out.push((
            0,
            format!(
                "{c}handshake: the start of {}: its run wires FALSE first, then every wire it drives",
                self.name(self.view.me)
            ),
        ));
        self.set_links(&mut out, |l| l.run, false);
        self.set_links(&mut out, |l| l.ready, false);
        let chs = &self.view.cell.channels;
        for &ch in &tx {
            out.push((0, self.assign(&format!("skp_tx{}", ch + 1), self.f())));
            for w in chs[ch].strobe.iter().chain(&chs[ch].data) {
                if let Some(s) = self.signal(Some(*w), true)
                    && let Ok(l) = self.set(s, self.f())
                {
                    out.push((0, l));
                }
            }
        }
        for &ch in &rx {
            out.push((0, self.assign(&format!("skp_rx{}", ch + 1), self.f())));
            if let Some(s) = self.signal(chs[ch].ack, true)
                && let Ok(l) = self.set(s, self.f())
            {
                out.push((0, l));
            }
        }
        if self.lang == Language::UrScript && rx.iter().any(|&ch| chs[ch].decisions) {
            out.push((0, self.assign(DECISION_VAR, "0")));
        }
        let be = if partners.len() == 1 { "is" } else { "are" };
        let over = |op: &str, f: &dyn Fn(usize) -> String| -> String {
            self.join(op, &partners.iter().map(|&p| f(p)).collect::<Vec<_>>())
        };
        let all = |f: &dyn Fn(usize) -> String| over("AND", f);
        let any = |f: &dyn Fn(usize) -> String| over("OR", f);
        out.push((
            0,
            format!(
                "{c}handshake: start barrier: wait until {names} {be} at the start (run {} FALSE)",
                self.labels_of(|l| l.run)
            ),
        ));
        let short = format!("start barrier: waits for {names}");
        self.watched_wait(
            &mut out,
            &all(&|p| self.is(&self.run_of(p), false)),
            &format!("start barrier: waits until {names} {be} at the start (run wires FALSE)"),
            &short,
            0,
        );
        self.set_links(&mut out, |l| l.ready, true);
        out.push((
            0,
            format!(
                "{c}handshake: start barrier: wait until {names} {be} ready too (ready {} TRUE)",
                self.labels_of(|l| l.ready)
            ),
        ));
        self.watched_wait(
            &mut out,
            &all(&|p| self.is(&self.ready_of(p), true)),
            &format!("start barrier: waits until {names} {be} ready (ready wires TRUE)"),
            &short,
            0,
        );
        self.set_links(&mut out, |l| l.run, true);
        out.push((
            0,
            format!(
                "{c}handshake: start barrier: wait until {names} {be} running too (run {} TRUE; a partner's run and ready FALSE: started again, stop)",
                self.labels_of(|l| l.run)
            ),
        ));
        // A partner back at its start (run and ready FALSE) was started again inside the
        // barrier: waiting for it here could wait for ever (it waits for this program's run
        // wire to drop), going on could meet it mid-cycle; so stop.
        let restarted = any(&|p| {
            self.join(
                "AND",
                &[
                    self.is(&self.run_of(p), false),
                    self.is(&self.ready_of(p), false),
                ],
            )
        });
        let running = all(&|p| self.is(&self.run_of(p), true));
        self.watched_wait(
            &mut out,
            &self.join("OR", &[running, restarted]),
            &format!("start barrier: waits until {names} {be} running (run wires TRUE)"),
            &short,
            0,
        );
        let text = if partners.len() == 1 {
            format!("{names} was started again during the start barrier")
        } else {
            format!("one of {names} was started again during the start barrier")
        };
        // Read again: unless every partner is running now, one was started again (it may
        // already be ready again, so "back at its start" is not what to test here).
        let not_running = any(&|p| self.is(&self.run_of(p), false));
        self.stop_if(
            &mut out,
            &not_running,
            &text,
            "a partner was started again during the start barrier",
            0,
            " during the start barrier",
        );
        self.set_links(&mut out, |l| l.ready, false);
        out
    }

    /// The lines at the program's end: it waits until every partner has read its last
    /// message (or was started again), so that its next start cannot take a message back.
    pub fn finish(&self) -> Vec<(usize, String)> {
        let (tx, _) = self.own();
        let mut out = Vec::new();
        let chs = &self.view.cell.channels;
        for &ch in &tx {
            let to = chs[ch].to;
            out.push((
                0,
                format!(
                    "{}handshake: the end: wait until {} has read the last message: for {} = skp_tx{} or {} FALSE (started again)",
                    self.comment(),
                    self.name(to),
                    self.label(chs[ch].ack, false),
                    ch + 1,
                    self.label(self.view.cell.link(to, self.view.me).and_then(|l| l.run), false),
                ),
            ));
            let ack = self.read_wire(chs[ch].ack);
            let cond = self.join(
                "OR",
                &[
                    self.equals(&ack, &format!("skp_tx{}", ch + 1)),
                    self.is(&self.run_of(to), false),
                ],
            );
            let wire = self.wire_name(chs[ch].ack);
            let to = self.name(to);
            self.watched_wait(
                &mut out,
                &cond,
                &format!("the end: waits until {to} has read the last message; wire {wire}"),
                &format!("the end: waits for {to} (wire {wire})"),
                0,
            );
        }
        out
    }

    /// The declarations of the toggles and the decision variable (KRL `.dat`, RAPID module
    /// data; URScript assigns them in `init`).
    pub fn declarations(&self) -> Vec<String> {
        let (tx, rx) = self.own();
        let chs = &self.view.cell.channels;
        let decisions = rx.iter().any(|&c| chs[c].decisions);
        let mut out = Vec::new();
        let vars = tx
            .iter()
            .map(|c| format!("skp_tx{}", c + 1))
            .chain(rx.iter().map(|c| format!("skp_rx{}", c + 1)));
        match self.lang {
            Language::Krl => {
                out.extend(
                    self.names_of_wires
                        .iter()
                        .map(|(_, name, io)| format!("SIGNAL {name} {io}")),
                );
                out.extend(vars.map(|v| format!("DECL BOOL {v}=FALSE")));
                if decisions {
                    out.push(format!("DECL INT {DECISION_VAR}=0"));
                }
                if !tx.is_empty() || !rx.is_empty() {
                    out.push(format!(
                        "DECL KrlMsg_T {MSG_VAR}={{Modul[] \"skillpost\",Nr 1,Msg_Txt[] \" \"}}"
                    ));
                    out.push(format!("DECL KrlMsgPar_T {PAR_VAR}[3]"));
                    out.push(format!(
                        "DECL KrlMsgOpt_T {OPT_VAR}={{VL_Stop TRUE,Clear_P_Reset TRUE,Log_to_DB FALSE}}"
                    ));
                    out.push(format!("DECL INT {HANDLE_VAR}=0"));
                    if self.input.bound.watch.is_some() {
                        out.push(format!("DECL BOOL {CLEARED_VAR}=FALSE"));
                    }
                }
            }
            Language::Rapid => {
                out.extend(vars.map(|v| format!("VAR num {v} := 0;")));
                if decisions {
                    out.push(format!("VAR num {DECISION_VAR} := 0;"));
                }
                if self.input.bound.watch.is_some() && (!tx.is_empty() || !rx.is_empty()) {
                    out.push(format!("VAR bool {LATE_VAR} := FALSE;"));
                }
            }
            Language::UrScript => {}
        }
        out
    }

    /// `E209` for each wire this program drives or reads that its language cannot.
    pub fn check(&self, diags: &mut Diagnostics) {
        let chs = &self.view.cell.channels;
        let mut seen = std::collections::HashSet::new();
        let mut uses: Vec<(Option<usize>, bool, bool)> = Vec::new(); // (wire, sender side, write)
        for l in &self.view.cell.links {
            if l.from == self.view.me {
                uses.extend([(l.run, true, true), (l.ready, true, true)]);
            }
            if l.to == self.view.me {
                uses.extend([(l.run, false, false), (l.ready, false, false)]);
            }
        }
        for ch in chs {
            if ch.from == self.view.me {
                uses.push((ch.strobe, true, true));
                uses.extend(ch.data.iter().map(|&w| (Some(w), true, true)));
                uses.push((ch.ack, false, false));
            }
            if ch.to == self.view.me {
                uses.push((ch.strobe, false, false));
                uses.extend(ch.data.iter().map(|&w| (Some(w), false, false)));
                uses.push((ch.ack, true, true));
            }
        }
        for (w, side, write) in uses {
            let Some(s) = self.signal(w, side) else {
                continue;
            };
            let r = if write {
                self.set(s, self.t()).map(drop)
            } else {
                self.read(s).map(drop)
            };
            if let Err(why) = r
                && seen.insert((w, side))
            {
                diags.push(
                    Diagnostic::error(
                        Code::BadSignal,
                        format!(
                            "signal `{}`, a wire between controllers (InternalLink `{}`), in the {} program of `{}`: {why}",
                            s.name.text,
                            w.map(|w| self.input.blackboard.wires[w].name.as_str())
                                .unwrap_or_default(),
                            self.lang,
                            self.name(self.view.me)
                        ),
                    )
                    .at(s.name.span.clone())
                    .element(s.element.clone()),
                );
            }
        }
    }
}

/// Writes lines made by [`Hand`] at `level`.
pub fn write(out: &mut Lines, level: usize, lines: Vec<(usize, String)>) {
    for (extra, l) in lines {
        out.line(level + extra, &l);
    }
}

/// Writes a [`Block::Tell`](crate::plan::Block::Tell) or
/// [`Block::Hear`](crate::plan::Block::Hear) at `level`, for any writer (nothing outside a
/// cell).
pub fn write_block(hand: Option<&Hand>, out: &mut Lines, level: usize, b: &crate::plan::Block) {
    let Some(h) = hand else {
        return;
    };
    match b {
        crate::plan::Block::Tell(m) => write(out, level, h.tell(m)),
        crate::plan::Block::Hear(m) => write(out, level, h.hear(m)),
        _ => {}
    }
}
