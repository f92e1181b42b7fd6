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
//!
//! [`Block::Tell`]: crate::plan::Block::Tell
//! [`Block::Hear`]: crate::plan::Block::Hear

mod forms;

use super::EmitInput;
use super::flow::Lines;
use crate::diag::{Code, Diagnostic, Diagnostics};
use crate::lang::Language;
use crate::model::{ElementKind, Signal, SignalKind};
use crate::plan::cell::{Cell, Kind, Link, Message};
use std::fmt::Arguments;

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

/// Where a handshake's lines go: the program's lines, at the level of the block that holds it.
/// Each line is written straight into the program's text.
pub struct At<'o, 'l> {
    out: &'o mut Lines<'l>,
    level: usize,
}

impl<'o, 'l> At<'o, 'l> {
    pub fn new(out: &'o mut Lines<'l>, level: usize) -> Self {
        At { out, level }
    }

    /// A line `extra` levels below the block's.
    fn line(&mut self, extra: usize, text: &str) {
        self.out.line(self.level + extra, text);
    }

    /// A line `extra` levels below the block's, from its pieces.
    fn put(&mut self, extra: usize, text: std::fmt::Arguments) {
        self.out.line_fmt(self.level + extra, text);
    }

    /// The lines one level deeper (the wait inside a watched wait's message block).
    fn deeper(&mut self) -> At<'_, 'l> {
        At {
            out: self.out,
            level: self.level + 1,
        }
    }
}

/// What every tell (this program sends on the channel) or hear (it receives) repeats, made
/// once per channel.
#[derive(Default)]
struct ChannelText {
    /// The toggle: `skp_txN` where this program sends, `skp_rxN` where it receives.
    var: String,
    /// The condition the handshake waits for: the wire it reads (the acknowledgement, the
    /// strobe) equals the toggle, or the partner was started again.
    cond: String,
    /// The name of the signal that wire arrives at (for a message).
    wire: String,
    /// For a comment: that wire, and the partner's run wire, as the program names them.
    label: String,
    run_label: String,
    /// The line that puts the toggle on the wire this side drives (the strobe, the
    /// acknowledgement); `None` when the language cannot (reported by [`Hand::check`]).
    set_toggle: Option<String>,
}

/// Writes one program's handshakes.
pub struct Hand<'a> {
    input: &'a EmitInput<'a>,
    view: CellView<'a>,
    lang: Language,
    /// What every handshake site repeats, made once (a cell of 10,000 steps has thousands of
    /// sites): each controller's name, transliterated; for each partner, its run wire read as
    /// "is `FALSE`" (the restart guard); for each channel, what its tells or hears repeat
    /// (empty for a channel of two other programs).
    names: Vec<String>,
    guards: Vec<String>,
    channels: Vec<ChannelText>,
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
            channels: Vec::new(),
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
        h.channels = (0..cell.channels.len())
            .map(|k| {
                let ch = &cell.channels[k];
                // The wire read, the wire driven, the partner.
                let (read, drive, var, p) = if ch.from == h.view.me {
                    (ch.ack, ch.strobe, format!("skp_tx{}", k + 1), ch.to)
                } else if ch.to == h.view.me {
                    (ch.strobe, ch.ack, format!("skp_rx{}", k + 1), ch.from)
                } else {
                    return ChannelText::default();
                };
                let cond = h.join(
                    "OR",
                    &[h.equals(&h.read_wire(read), &var), h.guards[p].clone()],
                );
                ChannelText {
                    cond,
                    wire: h.wire_name(read),
                    label: h.label(read, false),
                    run_label: h.label(cell.link(p, h.view.me).and_then(|l| l.run), false),
                    set_toggle: h.signal(drive, true).and_then(|s| h.set(s, &var).ok()),
                    var,
                }
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
    fn set_links(&self, out: &mut At, wire: fn(&Link) -> Option<usize>, level: bool) {
        let v = if level { self.t() } else { self.f() };
        for p in self.view.cell.partners(self.view.me) {
            if let Some(s) = self
                .view
                .cell
                .link(self.view.me, p)
                .and_then(|l| self.signal(wire(l), true))
                && let Ok(l) = self.set(s, v)
            {
                out.line(0, &l);
            }
        }
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
            SignalKind::Address { text, .. } => forms::clean(text).into_owned(),
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
    fn stop_unless_running(&self, out: &mut At, p: usize, text: Arguments, m: &Message) {
        let id = self.input.sfc.elements[m.about].local_id;
        let short = format_args!(
            "{} started again; this program waited at localId {id}",
            self.name(p)
        );
        self.stop_if(out, &self.guards[p], text, short, id, "");
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

    /// A tell, at the block's level.
    pub fn tell(&self, out: &mut At, m: &Message) {
        let ch = &self.view.cell.channels[m.channel];
        let t = &self.channels[m.channel];
        let about = self.about(m);
        let what = match m.kind {
            Kind::Done => format!("{about} is done"),
            Kind::Passed(c) => format!("it {} {about}", c.verb()),
            Kind::Decision => format!("branch {} was taken at the selection {about}", m.value + 1),
        };
        let (to, var, wire) = (self.name(ch.to), &t.var, &t.wire);
        out.put(
            0,
            format_args!(
                "{}handshake: tell {to} that {what}: wait for {} = {var} (read) or {} FALSE (started again)",
                self.comment(),
                t.label,
                t.run_label,
            ),
        );
        let id = self.input.sfc.elements[m.about].local_id;
        self.watched_wait(
            out,
            &t.cond,
            format_args!("waits until {to} has read: {what}; wire {wire}"),
            format_args!("waits for {to} to read (localId {id}, wire {wire})"),
            id,
        );
        self.stop_unless_running(
            out,
            ch.to,
            format_args!("{to} started again; this program was to tell it: {what}"),
            m,
        );
        if m.kind == Kind::Decision {
            for (bit, &w) in ch.data.iter().enumerate() {
                let on = (m.value >> bit) & 1 == 1;
                if let Some(s) = self.signal(Some(w), true)
                    && let Ok(l) = self.set(s, if on { self.t() } else { self.f() })
                {
                    out.line(0, &l);
                }
            }
        }
        self.toggle(out, var);
        if let Some(l) = &t.set_toggle {
            out.line(0, l);
        }
    }

    /// A hear (a decision read into [`DECISION_VAR`]), at the block's level.
    pub fn hear(&self, out: &mut At, m: &Message) {
        let ch = &self.view.cell.channels[m.channel];
        let t = &self.channels[m.channel];
        let about = self.about(m);
        let from = self.name(ch.from);
        let what = match m.kind {
            Kind::Done => format!("until {from} has done {about}"),
            Kind::Passed(c) => format!("until {from} {} {about}", c.verb()),
            Kind::Decision => format!("for the branch {from} takes at the selection {about}"),
        };
        let (var, wire) = (&t.var, &t.wire);
        out.put(
            0,
            format_args!(
                "{}handshake: wait {what}: for {} = NOT {var} (the next message) or {} FALSE (started again)",
                self.comment(),
                t.label,
                t.run_label,
            ),
        );
        self.toggle(out, var);
        let id = self.input.sfc.elements[m.about].local_id;
        self.watched_wait(
            out,
            &t.cond,
            format_args!("waits {what}; wire {wire}"),
            format_args!("waits for {from} (localId {id}, wire {wire})"),
            id,
        );
        if m.kind == Kind::Decision {
            out.line(0, &self.assign(DECISION_VAR, "0"));
            for (bit, &w) in ch.data.iter().enumerate() {
                let Some(read) = self.signal(Some(w), false).and_then(|s| self.read(s).ok()) else {
                    continue;
                };
                let add = self.assign(DECISION_VAR, &format!("{DECISION_VAR} + {}", 1 << bit));
                match self.lang {
                    Language::Krl => {
                        out.put(0, format_args!("IF {read} THEN"));
                        out.line(1, &add);
                        out.line(0, "ENDIF");
                    }
                    Language::Rapid => {
                        out.put(0, format_args!("IF {read} = 1 THEN"));
                        out.line(1, &add);
                        out.line(0, "ENDIF");
                    }
                    Language::UrScript => {
                        out.put(0, format_args!("if {read}:"));
                        out.line(1, &add);
                        out.line(0, "end");
                    }
                }
            }
        }
        let stop = match m.kind {
            Kind::Done => format_args!("{from} started again; waited for its {about}"),
            Kind::Decision => {
                format_args!("{from} started again; waited for its branch at the selection {about}")
            }
            Kind::Passed(c) => {
                format_args!("{from} started again; waited until it {} {about}", c.verb())
            }
        };
        self.stop_unless_running(out, ch.from, stop, m);
        if let Some(l) = &t.set_toggle {
            out.line(0, l);
        }
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
    pub fn init(&self, out: &mut At) {
        let (tx, rx) = self.own();
        if tx.is_empty() && rx.is_empty() {
            return;
        }
        let c = self.comment();
        let partners: Vec<usize> = self.view.cell.partners(self.view.me).collect();
        let names = partners
            .iter()
            .map(|&p| self.name(p))
            .collect::<Vec<_>>()
            .join(", ");
        if self.lang == Language::UrScript && !self.names_of_wires.is_empty() {
            out.line(
                0,
                &format!("{c}handshake: the wires, standard digital I/O by their signals' names in the blackboard"),
            );
            for (_, name, n) in &self.names_of_wires {
                out.put(0, format_args!("{name} = {n}"));
            }
        }
        out.put(0, format_args!(
                "{c}handshake: the start of {}: its run wires FALSE first, then every wire it drives",
                self.name(self.view.me)
            ),
        );
        self.set_links(out, |l| l.run, false);
        self.set_links(out, |l| l.ready, false);
        let chs = &self.view.cell.channels;
        for &ch in &tx {
            out.line(0, &self.assign(&format!("skp_tx{}", ch + 1), self.f()));
            for w in chs[ch].strobe.iter().chain(&chs[ch].data) {
                if let Some(s) = self.signal(Some(*w), true)
                    && let Ok(l) = self.set(s, self.f())
                {
                    out.line(0, &l);
                }
            }
        }
        for &ch in &rx {
            out.line(0, &self.assign(&format!("skp_rx{}", ch + 1), self.f()));
            if let Some(s) = self.signal(chs[ch].ack, true)
                && let Ok(l) = self.set(s, self.f())
            {
                out.line(0, &l);
            }
        }
        if self.lang == Language::UrScript && rx.iter().any(|&ch| chs[ch].decisions) {
            out.line(0, &self.assign(DECISION_VAR, "0"));
        }
        let be = if partners.len() == 1 { "is" } else { "are" };
        let over = |op: &str, f: &dyn Fn(usize) -> String| -> String {
            self.join(op, &partners.iter().map(|&p| f(p)).collect::<Vec<_>>())
        };
        let all = |f: &dyn Fn(usize) -> String| over("AND", f);
        let any = |f: &dyn Fn(usize) -> String| over("OR", f);
        out.put(
            0,
            format_args!(
                "{c}handshake: start barrier: wait until {names} {be} at the start (run {} FALSE)",
                self.labels_of(|l| l.run)
            ),
        );
        let short = format!("start barrier: waits for {names}");
        self.watched_wait(
            out,
            &all(&|p| self.is(&self.run_of(p), false)),
            format_args!("start barrier: waits until {names} {be} at the start (run wires FALSE)"),
            format_args!("{short}"),
            0,
        );
        self.set_links(out, |l| l.ready, true);
        out.put(
            0,
            format_args!(
                "{c}handshake: start barrier: wait until {names} {be} ready too (ready {} TRUE)",
                self.labels_of(|l| l.ready)
            ),
        );
        self.watched_wait(
            out,
            &all(&|p| self.is(&self.ready_of(p), true)),
            format_args!("start barrier: waits until {names} {be} ready (ready wires TRUE)"),
            format_args!("{short}"),
            0,
        );
        self.set_links(out, |l| l.run, true);
        out.put(0, format_args!(
                "{c}handshake: start barrier: wait until {names} {be} running too (run {} TRUE; a partner's run and ready FALSE: started again, stop)",
                self.labels_of(|l| l.run)
            ),
        );
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
            out,
            &self.join("OR", &[running, restarted]),
            format_args!("start barrier: waits until {names} {be} running (run wires TRUE)"),
            format_args!("{short}"),
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
            out,
            &not_running,
            format_args!("{text}"),
            format_args!("a partner was started again during the start barrier"),
            0,
            " during the start barrier",
        );
        self.set_links(out, |l| l.ready, false);
    }

    /// The lines at the program's end: it waits until every partner has read its last
    /// message (or was started again), so that its next start cannot take a message back.
    pub fn finish(&self, out: &mut At) {
        let (tx, _) = self.own();
        let chs = &self.view.cell.channels;
        for &ch in &tx {
            let to = chs[ch].to;
            out.put(0, format_args!(
                    "{}handshake: the end: wait until {} has read the last message: for {} = skp_tx{} or {} FALSE (started again)",
                    self.comment(),
                    self.name(to),
                    self.label(chs[ch].ack, false),
                    ch + 1,
                    self.label(self.view.cell.link(to, self.view.me).and_then(|l| l.run), false),
                ),
            );
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
                out,
                &cond,
                format_args!("the end: waits until {to} has read the last message; wire {wire}"),
                format_args!("the end: waits for {to} (wire {wire})"),
                0,
            );
        }
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

/// Writes a [`Block::Tell`](crate::plan::Block::Tell) or
/// [`Block::Hear`](crate::plan::Block::Hear) at `level`, for any writer (nothing outside a
/// cell).
pub fn write_block(hand: Option<&Hand>, out: &mut Lines, level: usize, b: &crate::plan::Block) {
    let Some(h) = hand else {
        return;
    };
    match b {
        crate::plan::Block::Tell(m) => h.tell(&mut At::new(out, level), m),
        crate::plan::Block::Hear(m) => h.hear(&mut At::new(out, level), m),
        _ => {}
    }
}
