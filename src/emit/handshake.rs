//! Handshakes between the programs of a cell (SPEC.md 9), in each language's own I/O
//! statements, written inline where the program tree has a [`Block::Tell`] or
//! [`Block::Hear`] (see `plan::cell` for where they stand and why they are enough).
//!
//! One channel (controller A → controller B) is a strobe wire A → B, for a decision its data
//! wires A → B, and an acknowledgement wire B → A. Both sides keep a toggle per channel
//! (`skp_txN` on A, `skp_rxN` on B; every wire `FALSE` at the cell's start):
//!
//! - **tell** (A): wait until the acknowledgement equals `skp_txN` (B has read the last
//!   message; this wait also ends the motion before it: KRL's `WAIT FOR` stops the advance run,
//!   RAPID's `WaitUntil \InPos` waits for the robot to stand, URScript waits for
//!   `is_steady()` first), set the data wires, toggle `skp_txN` and put it on the strobe;
//! - **hear** (B): toggle `skp_rxN`, wait until the strobe equals it (and, like every wait of
//!   a handshake, until the motions before it have ended: no wire changes while a motion before
//!   it may still run), read the data wires into `skp_got`, put `skp_rxN` on the
//!   acknowledgement.
//!
//! A sender is never more than one message ahead on a channel, so no toggle is ever missed,
//! also across loop rounds.

use super::EmitInput;
use super::flow::Lines;
use crate::diag::{Code, Diagnostic, Diagnostics};
use crate::lang::Language;
use crate::model::{ElementKind, Signal, SignalKind};
use crate::plan::cell::{Cell, Kind, Message};

/// The variable a decision is read into.
pub const DECISION_VAR: &str = "skp_got";

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
}

impl<'a> Hand<'a> {
    pub fn new(input: &'a EmitInput<'a>) -> Option<Self> {
        Some(Hand {
            input,
            view: input.cell?,
            lang: input.profile.language(),
        })
    }

    fn comment(&self) -> &'static str {
        match self.lang {
            Language::Krl => ";",
            Language::Rapid => "! ",
            Language::UrScript => "# ",
        }
    }

    fn signal(&self, wire: Option<usize>, sender_side: bool) -> Option<&'a Signal> {
        let bb = self.input.blackboard;
        let w = &bb.wires[wire?];
        let (r, s) = if sender_side { w.from } else { w.to };
        bb.resources.get(r)?.signals.get(s)
    }

    /// How this language reads an input wire as a boolean value.
    fn read(&self, s: &Signal) -> Result<String, String> {
        match (self.lang, &s.kind) {
            (Language::Krl, SignalKind::Bit(n)) => Ok(format!("$IN[{n}]")),
            (Language::Krl, SignalKind::Address { text, .. }) if !text.contains('(') => {
                Ok(text.clone())
            }
            (
                Language::Rapid,
                SignalKind::Address {
                    text,
                    integer: false,
                },
            ) => Ok(format!("DInput({text})")),
            (Language::UrScript, SignalKind::Bit(n)) if *n <= 7 => {
                Ok(format!("get_standard_digital_in({n})"))
            }
            (Language::UrScript, SignalKind::Address { text, .. })
                if !text.starts_with('$') && !text.contains('[') =>
            {
                Ok(text.clone())
            }
            _ => Err(self.cannot("read")),
        }
    }

    /// How this language sets an output wire to `value` (a boolean expression).
    fn set(&self, s: &Signal, value: &str) -> Result<String, String> {
        match (self.lang, &s.kind) {
            (Language::Krl, SignalKind::Bit(n)) => Ok(format!("$OUT[{n}] = {value}")),
            (Language::Krl, SignalKind::Address { text, .. })
                if !text.contains('(') && !text.contains("$IN") =>
            {
                Ok(format!("{text} = {value}"))
            }
            (
                Language::Rapid,
                SignalKind::Address {
                    text,
                    integer: false,
                },
            ) => Ok(format!("SetDO {text}, {value};")),
            (Language::UrScript, SignalKind::Bit(n)) if *n <= 7 => {
                Ok(format!("set_standard_digital_out({n}, {value})"))
            }
            _ => Err(self.cannot("write")),
        }
    }

    fn cannot(&self, what: &str) -> String {
        match self.lang {
            Language::Krl => format!(
                "KRL cannot {what} this wire: give it a `Number` (`$IN[n]`/`$OUT[n]`) or an `Address` that is a BOOL name or system variable"
            ),
            Language::Rapid => format!(
                "RAPID cannot {what} this wire: give it an `Address` with the digital signal's configured name (`do_Ready`, `di_Ready`)"
            ),
            Language::UrScript => format!(
                "URScript cannot {what} this wire: give it a `Number` of the standard digital I/O (0 to 7){}",
                if what == "read" {
                    " or an `Address` call (`read_input_boolean_register(3)`)"
                } else {
                    ""
                }
            ),
        }
    }

    fn t(&self) -> &'static str {
        match self.lang {
            Language::Krl => "TRUE",
            Language::Rapid => "1",
            Language::UrScript => "True",
        }
    }

    fn f(&self) -> &'static str {
        match self.lang {
            Language::Krl => "FALSE",
            Language::Rapid => "0",
            Language::UrScript => "False",
        }
    }

    fn assign(&self, var: &str, value: &str) -> String {
        match self.lang {
            Language::Krl => format!("{var} = {value}"),
            Language::Rapid => format!("{var} := {value};"),
            Language::UrScript => format!("{var} = {value}"),
        }
    }

    fn toggle(&self, var: &str) -> String {
        match self.lang {
            Language::Krl => format!("{var} = NOT {var}"),
            Language::Rapid => format!("{var} := 1 - {var};"),
            Language::UrScript => format!("{var} = not {var}"),
        }
    }

    /// A wait until `read` (a wire) equals `var`; `settle`: the robot stands first.
    fn wait_equal(&self, lines: &mut Vec<(usize, String)>, read: &str, var: &str, settle: bool) {
        match self.lang {
            Language::Krl => lines.push((0, format!("WAIT FOR {read} == {var}"))),
            Language::Rapid => {
                let pos = if settle { "\\InPos, " } else { "" };
                lines.push((0, format!("WaitUntil {pos}{read} = {var};")));
            }
            Language::UrScript => {
                if settle {
                    lines.push((0, "while not is_steady():".to_owned()));
                    lines.push((1, "sync()".to_owned()));
                    lines.push((0, "end".to_owned()));
                }
                lines.push((0, format!("while {read} != {var}:")));
                lines.push((1, "sync()".to_owned()));
                lines.push((0, "end".to_owned()));
            }
        }
    }

    fn name(&self, c: usize) -> String {
        let bb = self.input.blackboard;
        crate::names::transliterate(&bb.resources[self.view.cell.controllers[c]].name.text)
    }

    /// The controller that tells `m`.
    pub fn teller(&self, m: &Message) -> String {
        self.name(self.view.cell.channels[m.channel].from)
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
            Kind::Decision => format!(
                "branch {} was taken at the selection {}",
                m.value + 1,
                self.about(m)
            ),
        };
        out.push((
            0,
            format!(
                "{}handshake: tell {} that {what}",
                self.comment(),
                self.name(ch.to)
            ),
        ));
        let ack = self
            .signal(ch.ack, false)
            .and_then(|s| self.read(s).ok())
            .unwrap_or_default();
        self.wait_equal(&mut out, &ack, &var, true);
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
            Kind::Decision => format!(
                "for the branch {} takes at the selection {}",
                self.name(ch.from),
                self.about(m)
            ),
        };
        out.push((0, format!("{}handshake: wait {what}", self.comment())));
        out.push((0, self.toggle(&var)));
        let strobe = self
            .signal(ch.strobe, false)
            .and_then(|s| self.read(s).ok())
            .unwrap_or_default();
        self.wait_equal(&mut out, &strobe, &var, true);
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

    /// The lines at the program's start: every toggle and every wire this program drives
    /// `FALSE`.
    pub fn init(&self) -> Vec<(usize, String)> {
        let (tx, rx) = self.own();
        if tx.is_empty() && rx.is_empty() {
            return Vec::new();
        }
        let mut out = vec![(
            0,
            format!(
                "{}handshake: every wire of {} FALSE at the start",
                self.comment(),
                self.name(self.view.me)
            ),
        )];
        let chs = &self.view.cell.channels;
        for &c in &tx {
            out.push((0, self.assign(&format!("skp_tx{}", c + 1), self.f())));
            for w in chs[c].strobe.iter().chain(&chs[c].data) {
                if let Some(s) = self.signal(Some(*w), true)
                    && let Ok(l) = self.set(s, self.f())
                {
                    out.push((0, l));
                }
            }
        }
        for &c in &rx {
            out.push((0, self.assign(&format!("skp_rx{}", c + 1), self.f())));
            if let Some(s) = self.signal(chs[c].ack, true)
                && let Ok(l) = self.set(s, self.f())
            {
                out.push((0, l));
            }
        }
        if self.lang == Language::UrScript && rx.iter().any(|&c| chs[c].decisions) {
            out.push((0, self.assign(DECISION_VAR, "0")));
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
                out.extend(vars.map(|v| format!("DECL BOOL {v}=FALSE")));
                if decisions {
                    out.push(format!("DECL INT {DECISION_VAR}=0"));
                }
            }
            Language::Rapid => {
                out.extend(vars.map(|v| format!("VAR num {v} := 0;")));
                if decisions {
                    out.push(format!("VAR num {DECISION_VAR} := 0;"));
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
        for ch in chs {
            let mut uses: Vec<(Option<usize>, bool, bool)> = Vec::new(); // (wire, sender side, write)
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
