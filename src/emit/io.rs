//! The I/O list of a program, for commissioning (docs/LANGUAGES.md, "The I/O list"): every
//! signal the program reads or writes, written beside it as `<program>.io.csv`, and for a RAPID
//! module the `EIO.cfg` fragment declaring those signals (`<program>.eio.cfg`), so that the
//! module links once the fragment is loaded.
//!
//! A row is a signal the transition conditions read, or a wire of the program's handshakes with
//! its partners (docs/CELLS.md): the strobe and the data bits of a channel, its acknowledgement,
//! and the run and ready wires of the start barrier. Its direction is this program's (`in`: it
//! reads it, `out`: it sets it).

use super::EmitInput;
use crate::model::{Signal, SignalKind};

/// One signal of the list.
#[derive(Debug, Clone)]
pub struct Row<'a> {
    /// `in` or `out`.
    pub output: bool,
    pub signal: &'a Signal,
    /// The partner controller's resource (a wire), or `None` (a signal a condition reads).
    pub partner: Option<&'a str>,
    pub purpose: String,
}

/// The rows of the program's I/O list: the wires (by channel, then the start barrier's links),
/// then the signals its conditions read, each signal once per purpose.
pub fn rows<'a>(input: &'a EmitInput<'a>) -> Vec<Row<'a>> {
    let bb = input.blackboard;
    let mut out: Vec<Row<'a>> = Vec::new();
    // Each signal once per purpose; a set, so that 30,000 signals cost no more than linear.
    let mut seen: std::collections::HashSet<(*const Signal, bool, String)> =
        std::collections::HashSet::new();
    let mut push = |row: Row<'a>| {
        if seen.insert((row.signal as *const Signal, row.output, row.purpose.clone())) {
            out.push(row);
        }
    };
    if let Some(view) = &input.cell {
        let cell = view.cell;
        let name_of = |k: usize| -> &'a str { &bb.resources[cell.controllers[k]].name.text };
        // This program's side of wire `w`: the sender's output or the receiver's input.
        let side = |w: usize, sender: bool| -> Option<&'a Signal> {
            let wire = bb.wires.get(w)?;
            let (r, s) = if sender { wire.from } else { wire.to };
            bb.resources.get(r)?.signals.get(s)
        };
        for ch in &cell.channels {
            let (sends, partner) = if ch.from == view.me {
                (true, ch.to)
            } else if ch.to == view.me {
                (false, ch.from)
            } else {
                continue;
            };
            let partner = Some(name_of(partner));
            let mut wire = |w: Option<usize>, sender_side: bool, purpose: String| {
                if let Some(s) = w.and_then(|w| side(w, sender_side)) {
                    push(Row {
                        output: sender_side,
                        signal: s,
                        partner,
                        purpose,
                    });
                }
            };
            let of = if sends {
                "of the messages to the partner"
            } else {
                "of the messages from the partner"
            };
            wire(ch.strobe, sends, format!("handshake: strobe {of}"));
            for (k, &d) in ch.data.iter().enumerate() {
                wire(
                    Some(d),
                    sends,
                    format!("handshake: decision data bit {} {of}", k + 1),
                );
            }
            wire(ch.ack, !sends, format!("handshake: acknowledgement {of}"));
        }
        for l in &cell.links {
            let (drives, partner) = if l.from == view.me {
                (true, l.to)
            } else if l.to == view.me {
                (false, l.from)
            } else {
                continue;
            };
            for (w, what) in [(l.run, "run"), (l.ready, "ready")] {
                if let Some(s) = w.and_then(|w| side(w, drives)) {
                    push(Row {
                        output: drives,
                        signal: s,
                        partner: Some(name_of(partner)),
                        purpose: format!("start barrier: {what}"),
                    });
                }
            }
        }
    }
    // The other signals of the resources whose skills the program runs (a gripper's valves):
    // its IRL code may set or read them.
    let conditions: std::collections::HashSet<*const Signal> = input
        .bound
        .resource
        .map(|r| {
            input
                .bound
                .signals
                .iter()
                .filter_map(|&s| bb.resources[r].signals.get(s))
                .map(|s| s as *const Signal)
                .collect()
        })
        .unwrap_or_default();
    if let Some(r) = input.bound.resource {
        for &s in &input.bound.signals {
            if let Some(sig) = bb.resources[r].signals.get(s) {
                push(Row {
                    output: sig.output,
                    signal: sig,
                    partner: None,
                    purpose: "condition (a transition reads it)".to_owned(),
                });
            }
        }
    }
    let listed: std::collections::HashSet<*const Signal> =
        out.iter().map(|r| r.signal as *const Signal).collect();
    for r in input.bound.resources() {
        let res = &bb.resources[r];
        for sig in &res.signals {
            let at = sig as *const Signal;
            if !listed.contains(&at) && !conditions.contains(&at) {
                out.push(Row {
                    output: sig.output,
                    signal: sig,
                    partner: None,
                    purpose: format!("signal of {} (its skills' code may use it)", res.name.text),
                });
            }
        }
    }
    out
}

/// A CSV field (RFC 4180): quoted when it holds a comma, a quote or a line break.
fn field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_owned()
    }
}

/// The I/O list as CSV (a header, then one row per signal), lines ended by `nl`.
pub fn csv(rows: &[Row], nl: &str) -> String {
    let mut out = format!("direction,signal,number,address,type,partner,purpose{nl}");
    for r in rows {
        let (number, address) = match &r.signal.kind {
            SignalKind::Bit(n) => (n.to_string(), String::new()),
            SignalKind::Group { number, length } => {
                (format!("{number}-{}", number + length - 1), String::new())
            }
            SignalKind::Address { text, .. } => (String::new(), text.clone()),
        };
        let ty = match &r.signal.kind {
            SignalKind::Group { length, .. } => format!("integer ({length} bits)"),
            SignalKind::Address { integer: true, .. } => "integer".to_owned(),
            _ => "boolean".to_owned(),
        };
        let cells = [
            if r.output { "out" } else { "in" }.to_owned(),
            r.signal.name.text.to_string(),
            number,
            address,
            ty,
            r.partner.unwrap_or("").to_owned(),
            r.purpose.clone(),
        ];
        let line: Vec<String> = cells.iter().map(|c| field(c)).collect();
        out.push_str(&line.join(","));
        out.push_str(nl);
    }
    out
}

/// A RAPID module's `EIO.cfg` fragment: an `EIO_SIGNAL` per signal it reads or sets, by the
/// name the module uses (its `Address`), `DI`/`DO`, or `GI`/`GO` for an integer one. The
/// signals carry no `-Device`/`-DeviceMap`: the commissioning engineer maps them onto the
/// fieldbus; loaded as they are, they are simulated signals the module links against.
pub fn eio(rows: &[Row], nl: &str) -> String {
    let mut out = format!("EIO:CFG_1.0:6:1::{nl}#{nl}EIO_SIGNAL:{nl}{nl}");
    let mut seen: Vec<&str> = Vec::new();
    for r in rows {
        let SignalKind::Address { text, integer } = &r.signal.kind else {
            continue;
        };
        if seen.contains(&text.as_str()) {
            continue;
        }
        seen.push(text);
        let ty = match (integer, r.output) {
            (false, false) => "DI",
            (false, true) => "DO",
            (true, false) => "GI",
            (true, true) => "GO",
        };
        let label: String = format!("{}: {}", r.signal.name.text, r.purpose)
            .chars()
            .filter(|c| c.is_ascii() && !c.is_ascii_control() && *c != '"' && *c != '\\')
            .take(80)
            .collect();
        out.push_str(&format!(
            "      -Name \"{text}\" -SignalType \"{ty}\" -Access \"All\" -Label \"{label}\"{nl}{nl}"
        ));
    }
    out
}
