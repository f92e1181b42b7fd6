//! `-pO`: the execution order, one step per line; a cell's programs' handshakes too (for
//! `cell.rs`).

use std::fmt::Write as _;

use super::{CellView, condition, step_name};
use crate::model::Sfc;
use crate::plan::{Block, BranchEnd, Plan};

/// `-pO`: the execution order, one step per line with its number and localId; selections,
/// their branches' conditions and loops are shown around the steps they hold.
pub fn order(sfc: &Sfc, plan: &Plan) -> String {
    let mut o = String::new();
    order_lines(sfc, None, &plan.body, "", &mut 0, &mut o);
    o
}

/// The lines of `-pO` for `blocks`; with a cell's view, a program's handshakes too.
pub(super) fn order_lines(
    sfc: &Sfc,
    view: Option<&CellView>,
    blocks: &[Block],
    indent: &str,
    n: &mut usize,
    o: &mut String,
) {
    for b in blocks {
        match b {
            Block::Step(i) => {
                *n += 1;
                // Aligned with spaces (no tabs): numbers to 999, localIds to 99999.
                let _ = writeln!(
                    o,
                    "{indent} {:<4} {:<10} {}",
                    format!("#{n}"),
                    format!("(id={})", sfc.elements[*i].local_id),
                    step_name(sfc, *i)
                );
            }
            Block::Wait(t) => {
                let _ = writeln!(o, "{indent} wait for {}", condition(sfc, *t));
            }
            // Handshakes stand only in the programs of a cell.
            Block::Tell(m) | Block::Hear(m) => {
                if let Some(v) = view {
                    let tell = matches!(b, Block::Tell(_));
                    let _ = writeln!(o, "{indent} {}", v.handshake(sfc, m, tell));
                }
            }
            Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                for br in branches {
                    order_lines(sfc, view, br, indent, n, o);
                }
            }
            Block::Machine(states) => {
                for (k, st) in states.iter().enumerate() {
                    let _ = writeln!(
                        o,
                        "{indent} state {} (id={}):",
                        k + 1,
                        sfc.elements[st.entry].local_id
                    );
                    order_lines(sfc, view, &st.body, &format!("{indent}    "), n, o);
                }
            }
            Block::Goto { target, .. } => {
                let _ = writeln!(o, "{indent} go on at id={}", sfc.elements[*target].local_id);
            }
            Block::Choice {
                divergence,
                branches,
                ..
            }
            | Block::Follow {
                divergence,
                branches,
                ..
            } => {
                let decided = match (b, view) {
                    (Block::Follow { heard, .. }, Some(v)) => format!(
                        "wait for {}: the branch it takes",
                        v.controller(v.cell.channels[heard.channel].from)
                    ),
                    _ => "the first branch whose condition holds".to_owned(),
                };
                let _ = writeln!(
                    o,
                    "{indent} selection (id={}): {decided}",
                    sfc.elements[*divergence].local_id
                );
                let inner = format!("{indent}    ");
                for (k, br) in branches.iter().enumerate() {
                    let _ = writeln!(o, "{indent}  {}. if {}", k + 1, br.condition_text(sfc));
                    order_lines(sfc, view, &br.body, &inner, n, o);
                    match br.end {
                        BranchEnd::Join => {}
                        BranchEnd::Repeat(_) => {
                            let _ = writeln!(o, "{inner} round again");
                        }
                        BranchEnd::Leave => {
                            let _ = writeln!(o, "{inner} leave the loop");
                        }
                    }
                }
            }
            Block::Loop {
                head,
                body,
                endless,
                ..
            } => {
                let _ = writeln!(
                    o,
                    "{indent} loop{} (back to id={}):",
                    if *endless { ", endless" } else { "" },
                    sfc.elements[*head].local_id
                );
                order_lines(sfc, view, body, &format!("{indent}  "), n, o);
            }
        }
    }
}
