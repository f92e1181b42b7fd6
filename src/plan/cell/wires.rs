//! The wires of a cell's handshakes (docs/CELLS.md): how many each pair of controllers needs
//! (strobe, data, acknowledgement, run and ready), which the blackboard declares between them,
//! and each channel and link given its own, in document order; too few is an error at the first
//! handshake between the pair.

use super::Cell;
use crate::diag::{Code, Diagnostic, Diagnostics};
use crate::model::{Blackboard, Sfc};

/// What each ordered pair of controllers needs and has: `(from, to)` → (wires needed, wires
/// declared).
pub fn wire_counts(cell: &Cell, bb: &Blackboard) -> Vec<((usize, usize), usize, usize)> {
    let mut pairs: Vec<(usize, usize)> = Vec::new();
    for ch in &cell.channels {
        for p in [(ch.from, ch.to), (ch.to, ch.from)] {
            if !pairs.contains(&p) {
                pairs.push(p);
            }
        }
    }
    pairs
        .into_iter()
        .map(|(a, b)| {
            let need = needed(cell, a, b).iter().sum();
            let have = declared(cell, bb, a, b).len();
            ((a, b), need, have)
        })
        .collect()
}

/// Wires needed from `a` to `b`: (strobes, data bits, acknowledgements, run and ready).
fn needed(cell: &Cell, a: usize, b: usize) -> [usize; 4] {
    let mut n = [0; 4];
    if cell.link(a, b).is_some() {
        n[3] = 2;
    }
    for ch in &cell.channels {
        if (ch.from, ch.to) == (a, b) {
            n[0] += 1;
            n[1] += ch.data_bits();
        }
        if (ch.from, ch.to) == (b, a) {
            n[2] += 1;
        }
    }
    n
}

/// What the wires from `a` to `b` that [`needed`] counts are for, as words.
fn purposes(need: &[usize; 4], a: &str, b: &str) -> Vec<String> {
    let mut what = Vec::new();
    if need[0] > 0 {
        what.push(format!("1 to tell `{b}` that a step is done"));
    }
    if need[1] > 0 {
        what.push(format!("{} for the branch `{a}` decided", need[1]));
    }
    if need[2] > 0 {
        what.push(format!("{} to acknowledge what `{b}` tells `{a}`", need[2]));
    }
    if need[3] > 0 {
        what.push(format!(
            "2 for the start barrier and the restart check (`{a}` running, `{a}` ready)"
        ));
    }
    what
}

/// The wires from controller `a`'s resources to `b`'s, in document order.
fn declared(cell: &Cell, bb: &Blackboard, a: usize, b: usize) -> Vec<usize> {
    (0..bb.wires.len())
        .filter(|&w| {
            let wire = &bb.wires[w];
            bb.controller_of(wire.from.0) == cell.controllers[a]
                && bb.controller_of(wire.to.0) == cell.controllers[b]
        })
        .collect()
}

/// Gives every channel its wires, from the blackboard's wires between its two controllers in
/// document order (the strobe, then the data bits; the acknowledgements of the other way
/// after those; last the run and the ready wire of the pair's [`Link`](super::Link)). Too few wires between two controllers: `E212`, saying how many are missing
/// from which controller to which.
pub fn assign_wires(cell: &mut Cell, bb: &Blackboard, sfc: &Sfc, diags: &mut Diagnostics) {
    let n = cell.controllers.len();
    for a in 0..n {
        for b in 0..n {
            if a == b {
                continue;
            }
            let need = needed(cell, a, b);
            let total: usize = need.iter().sum();
            if total == 0 {
                continue;
            }
            let have = declared(cell, bb, a, b);
            let name = |c: usize| bb.resources[cell.controllers[c]].name.text.to_string();
            // An error about the pair stands at the first step (or selection) a handshake
            // between them reports.
            let place = |d: Diagnostic| {
                let about = cell
                    .channels
                    .iter()
                    .find(|c| (c.from, c.to) == (a, b) || (c.from, c.to) == (b, a))
                    .map(|c| c.first_about);
                match about {
                    Some(e) => d
                        .at(sfc.elements[e].span.clone())
                        .element(format!("localId {}", sfc.elements[e].local_id)),
                    None => d,
                }
            };
            // No wire at all between the two, either way: most likely one is a device on the
            // other's controller that the blackboard does not put there. One error for the
            // pair, which says how to put it there.
            let back = declared(cell, bb, b, a);
            if have.is_empty() && back.is_empty() {
                if a > b && needed(cell, b, a).iter().sum::<usize>() > 0 {
                    continue; // said with (b, a)
                }
                let back_need = needed(cell, b, a);
                let back_total: usize = back_need.iter().sum();
                let list = |need: &[usize; 4], from: &str, to: &str| {
                    let w = purposes(need, from, to);
                    if w.is_empty() {
                        String::new()
                    } else {
                        format!(" ({})", w.join(", "))
                    }
                };
                let (x, y) = (name(a), name(b));
                let d = Diagnostic::error(
                    Code::TooFewWires,
                    format!(
                        "controllers `{x}` and `{y}` run steps of one plan, so they must tell each other where they are: the plan needs {total} wire{} from `{x}` to `{y}`{} and {back_total} from `{y}` to `{x}`{}; the blackboard declares none between them",
                        if total == 1 { "" } else { "s" },
                        list(&need, &x, &y),
                        list(&back_need, &y, &x),
                    ),
                )
                .note(format!(
                    "if `{y}` is a device on `{x}`'s controller (a gripper, a welding source wired to the robot), put it there, and its steps go into `{x}`'s program without any wire: give `{y}` the attribute `<Attribute Name=\"Controller\"><Value>{x}</Value></Attribute>` (or move its InternalElement inside `{x}`'s); the other way round, give `{x}` one naming `{y}`"
                ))
                .note(format!(
                    "if they are two controllers, wire them: InternalLinks from Output signals of `{x}` to Input signals of `{y}` and back"
                ));
                diags.push(place(d));
                continue;
            }
            if have.len() < total {
                let what = purposes(&need, &name(a), &name(b));
                let d = Diagnostic::error(
                    Code::TooFewWires,
                    format!(
                        "the plan needs {total} wire{} from controller `{}` to controller `{}` ({}); the blackboard declares {}: {} missing. Add {} InternalLink{} from an Output signal of `{}` (or a device on it) to an Input signal of `{}`",
                        if total == 1 { "" } else { "s" },
                        name(a),
                        name(b),
                        what.join(", "),
                        have.len(),
                        total - have.len(),
                        total - have.len(),
                        if total - have.len() == 1 { "" } else { "s" },
                        name(a),
                        name(b)
                    ),
                );
                diags.push(place(d));
                continue;
            }
            let mut next = have.into_iter();
            for ch in cell.channels.iter_mut() {
                if (ch.from, ch.to) == (a, b) {
                    ch.strobe = next.next();
                    let bits = ch.data_bits();
                    ch.data = next.by_ref().take(bits).collect();
                }
            }
            for ch in cell.channels.iter_mut() {
                if (ch.from, ch.to) == (b, a) {
                    ch.ack = next.next();
                }
            }
            if let Some(l) = cell.links.iter_mut().find(|l| (l.from, l.to) == (a, b)) {
                l.run = next.next();
                l.ready = next.next();
            }
        }
    }
}
