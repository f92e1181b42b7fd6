//! `-pF`: the flow as a pseudo-graphic, each step with its start time and duration, and the
//! total.

use std::fmt::Write as _;

use super::{Totals, condition, duration, fmt_num, seconds, step_name};
use crate::model::Sfc;
use crate::plan::{Block, BranchEnd, Plan};

/// `-pF`: the flow as a pseudo-graphic: one line per step with its start time and duration;
/// simultaneous branches drawn as `{ | … + | … }` (so are the sequences of several initial
/// steps, with a title), selection branches as `< | ? cond … + … >`,
/// a loop as `[ loop … ]` with one round of its body. A block of branches ends when its longest
/// branch ends (simultaneous branches run in parallel in the plan, even though one robot runs
/// them in turn; of alternatives the longest is counted). A loop counts one round.
pub fn flow(sfc: &Sfc, plan: &Plan) -> String {
    fn walk(
        sfc: &Sfc,
        blocks: &[Block],
        t: f64,
        indent: &str,
        o: &mut String,
        tot: &mut Totals,
    ) -> f64 {
        let mut t = t;
        for b in blocks {
            match b {
                // Handshakes stand only in the programs of a cell, not in the chart's plan.
                Block::Tell(_) | Block::Hear(_) | Block::Follow { .. } => {}
                Block::Step(i) => {
                    let d = duration(sfc, *i);
                    let _ = writeln!(
                        o,
                        "{indent}id={:>4}, [@{:<6} + {:>6}], {}",
                        sfc.elements[*i].local_id,
                        fmt_num(t),
                        fmt_num(d),
                        step_name(sfc, *i)
                    );
                    t += d;
                }
                Block::Wait(tr) => {
                    let _ = writeln!(
                        o,
                        "{indent}wait for {} (transition id={})",
                        condition(sfc, *tr),
                        sfc.elements[*tr].local_id
                    );
                }
                Block::Parallel { branches, .. } | Block::Sequences(branches) => {
                    if matches!(b, Block::Sequences(_)) {
                        let _ = writeln!(
                            o,
                            "{indent}{{ {} sequences at the same time, each from an initial step:",
                            branches.len()
                        );
                    } else {
                        let _ = writeln!(o, "{indent}{{");
                    }
                    let inner = format!("{indent} | ");
                    let mut end = t;
                    for (k, br) in branches.iter().enumerate() {
                        if k > 0 {
                            let _ = writeln!(o, "{indent} +");
                        }
                        end = end.max(walk(sfc, br, t, &inner, o, tot));
                    }
                    let _ = writeln!(o, "{indent}}}");
                    t = end;
                }
                Block::Choice {
                    divergence,
                    branches,
                    ..
                } => {
                    tot.choices = true;
                    let _ = writeln!(
                        o,
                        "{indent}< selection id={}, the longest branch counts",
                        sfc.elements[*divergence].local_id
                    );
                    let inner = format!("{indent} | ");
                    let mut end = t;
                    for (k, br) in branches.iter().enumerate() {
                        if k > 0 {
                            let _ = writeln!(o, "{indent} +");
                        }
                        let _ = writeln!(
                            o,
                            "{inner}? {} (transition id={})",
                            br.condition_text(sfc),
                            sfc.elements[br.transition].local_id
                        );
                        end = end.max(walk(sfc, &br.body, t, &inner, o, tot));
                        match br.end {
                            BranchEnd::Join => {}
                            BranchEnd::Repeat(j) => {
                                let how = match sfc.closed.iter().find(|c| c.jump == j) {
                                    Some(c) => format!(
                                        "connection back from id={}",
                                        sfc.elements[c.from].local_id
                                    ),
                                    None => format!("jump id={}", sfc.elements[j].local_id),
                                };
                                let _ = writeln!(o, "{inner}-> round again ({how})");
                            }
                            BranchEnd::Leave => {
                                let _ = writeln!(o, "{inner}-> leave the loop");
                            }
                        }
                    }
                    let _ = writeln!(o, "{indent}>");
                    t = end;
                }
                Block::Machine(states) => {
                    tot.states = true;
                    for (k, st) in states.iter().enumerate() {
                        let _ = writeln!(
                            o,
                            "{indent}[ state {} at id={}:",
                            k + 1,
                            sfc.elements[st.entry].local_id
                        );
                        let inner = format!("{indent} : ");
                        t = walk(sfc, &st.body, t, &inner, o, tot);
                        let _ = writeln!(o, "{indent}]");
                    }
                }
                Block::Goto { target, .. } => {
                    let _ = writeln!(
                        o,
                        "{indent}-> go on at id={}",
                        sfc.elements[*target].local_id
                    );
                }
                Block::Loop {
                    head,
                    body,
                    endless,
                    ..
                } => {
                    tot.loops = true;
                    tot.endless |= *endless;
                    let _ = writeln!(
                        o,
                        "{indent}[ loop back to id={}{}, one round:",
                        sfc.elements[*head].local_id,
                        if *endless { ", endless" } else { "" }
                    );
                    let inner = format!("{indent} : ");
                    t = walk(sfc, body, t, &inner, o, tot);
                    let _ = writeln!(o, "{indent}]");
                }
            }
        }
        t
    }
    let mut o = String::new();
    let mut tot = Totals::default();
    let total = walk(sfc, &plan.body, 0.0, "", &mut o, &mut tot);
    let what = if tot.endless {
        " per round (the program repeats without end)"
    } else if tot.states {
        " at least (loops and states counted once)"
    } else if tot.loops {
        " at least (loops counted once)"
    } else {
        ""
    };
    let longest = if tot.choices {
        ", the longest alternative counted"
    } else {
        ""
    };
    let _ = writeln!(o, "total: {}{what}{longest}", seconds(total));
    o
}
