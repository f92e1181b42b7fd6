//! Selection branches: where they meet again, the selection that decides a loop, and the
//! selections before it whose other branches leave the loop early.

use super::*;

impl Walker<'_> {
    /// Selection branches from `div`: the block and the convergence to go on from, or, for the
    /// selection that decides the innermost loop, how the loop body ends.
    pub(super) fn selection(&mut self, div: usize, heads: Vec<usize>, depth: usize) -> Branches {
        let el = &self.sfc.elements;
        // Branches after an unconditional one are never taken (they are still checked).
        if let Some(k) = heads
            .iter()
            .position(|&h| matches!(el[h].kind, ElementKind::Transition(None)))
        {
            for &h in &heads[k + 1..] {
                self.diags.push(
                    Diagnostic::warning(
                        Code::BranchNeverTaken,
                        format!(
                            "this selection branch is never taken: the branch of transition localId {} before it (left of it) has no condition and always wins",
                            el[heads[k]].local_id
                        ),
                    )
                    .at(el[h].span.clone())
                    .element(format!("localId {}", el[h].local_id)),
                );
            }
        }
        let inner = self.loops.last().map(|l| (l.head, l.depth));
        // At the innermost loop's own level, this selection may decide the loop: branches
        // outside the loop's body leave it, and go on where the loop stands.
        let deciding = inner.is_some_and(|(_, d)| d == depth);
        // (transition, body, end, inside the loop) per branch, in priority order. A branch that
        // leaves the loop is walked later, if at all: one exit branch is the program's
        // continuation after the loop and is walked there, in the sequence that holds the loop
        // (not here: a chain of loops must not nest the walk).
        let inside_of: Vec<bool> = heads
            .iter()
            .map(|&h| !deciding || self.loops.last().is_some_and(|l| self.marks[h] == l.id))
            .collect();
        let n_outside = inside_of.iter().filter(|i| !**i).count();
        // One branch goes on in the loop, the others leave it: either this selection decides
        // the loop (the branch ends in the jump back) or it leaves the loop early and the branch
        // is the rest of the loop's own sequence. Either way it is walked at the loop's level.
        let single_inside = deciding && n_outside > 0 && n_outside + 1 == heads.len();
        if single_inside && let Some(l) = self.loops.last_mut() {
            l.mid_exits += n_outside;
        }
        let mut walked: Vec<(usize, Vec<Block>, End, bool)> = Vec::with_capacity(heads.len());
        for (h, inside) in heads.into_iter().zip(inside_of) {
            let (b, end) = if inside && single_inside {
                match self.after_head(h) {
                    Some(f) => self.seq(f, false, depth),
                    None => (Vec::new(), End::Done),
                }
            } else if inside {
                self.branch_walk(h, depth)
            } else {
                (Vec::new(), End::Endless)
            };
            if self.failed {
                return None;
            }
            walked.push((h, b, end, inside));
        }
        if single_inside {
            let k = walked.iter().position(|w| w.3).expect("one inside");
            if !matches!(walked[k].2, End::Decided { .. }) {
                // Not an early exit: these are this selection's own exits.
                if let Some(l) = self.loops.last_mut() {
                    l.mid_exits -= n_outside;
                }
            } else {
                return self.early_exit(div, walked, depth);
            }
        }
        let any_repeat = walked.iter().any(|(_, _, e, inside)| {
            *inside && matches!(e, End::Jump(j) if inner.is_some_and(|(h, _)| self.jumps[*j] == Some(h)))
        });
        let outside = walked.iter().filter(|w| !w.3).count();
        let mids = self.loops.last().map_or(0, |l| l.mid_exits);
        if !any_repeat || outside > 1 || (outside == 1 && mids > 0) {
            // The exits are walked here: to their convergence (or, without a jump back, as an
            // ordinary selection), outside the loop.
            for w in walked.iter_mut().filter(|w| !w.3) {
                let ctx = self.loops.pop().expect("deciding needs a loop");
                let (b, end) = self.branch_walk(w.0, depth);
                self.loops.push(ctx);
                if self.failed {
                    return None;
                }
                w.1 = b;
                w.2 = end;
            }
        }
        let repeats: Vec<bool> = walked
            .iter()
            .map(|(_, _, e, inside)| *inside && matches!(e, End::Jump(j) if inner.is_some_and(|(h, _)| self.jumps[*j] == Some(h))))
            .collect();
        // Jumps anywhere else cannot be structured.
        for (k, (_, _, e, _)) in walked.iter().enumerate() {
            if let End::Jump(j) = e
                && !repeats[k]
            {
                let why = match self.jumps[*j] {
                    Some(t) if self.loops.iter().any(|l| l.head == t) => {
                        "it leaves an inner loop as well (KRL's EXIT leaves one loop)"
                    }
                    _ => {
                        "it does not lead back to a step on every path to it (a forward jump, or into another branch)"
                    }
                };
                self.bad_jump(*j, why);
                return None;
            }
        }
        if !repeats.iter().any(|r| *r) {
            // An ordinary selection: every branch ends in one convergence (or goes to another
            // state).
            let joining: Vec<&End> = walked
                .iter()
                .map(|w| &w.2)
                // (A branch that goes to another state or repeats without end joins nothing.)
                .filter(|e| !matches!(e, End::Left | End::Endless))
                .collect();
            // The branches as a selection (without its convergence: those that do not go to
            // another state end in what follows it).
            let unjoined = |walked: Vec<(usize, Vec<Block>, End, bool)>| {
                let branches = walked
                    .into_iter()
                    .map(|(t, body, _, _)| Branch {
                        transition: t,
                        body,
                        end: BranchEnd::Join,
                    })
                    .collect();
                Box::new(Block::Choice {
                    divergence: div,
                    convergence: None,
                    branches,
                })
            };
            if joining.is_empty() {
                return Some(Err(End::Branched(unjoined(walked))));
            }
            let conv = match joining.first() {
                Some(End::Conv(c)) => Some(*c),
                _ => None,
            };
            if let (Some(c), 1) = (conv, joining.len())
                && matches!(el[c].kind, ElementKind::SimultaneousConvergence)
            {
                // The one branch that does not go to another state ends its simultaneous
                // branch.
                return Some(Err(End::BranchedAt(unjoined(walked), c)));
            }
            let joined = conv.is_some_and(|c| {
                joining.iter().all(|e| matches!(e, End::Conv(x) if *x == c))
                    && matches!(el[c].kind, ElementKind::SelectionConvergence)
                    && self.g.preds(c).len() == joining.len()
            });
            let Some(conv) = conv.filter(|_| joined) else {
                self.propose_meetings(&walked);
                self.fail(
                    div,
                    Code::UnbalancedBranch,
                    format!(
                        "selectionDivergence opens {} branches that do not all end in one selectionConvergence joining just them",
                        walked.len()
                    ),
                );
                return None;
            };
            let mut choice = unjoined(walked);
            if let Block::Choice { convergence, .. } = choice.as_mut() {
                *convergence = Some(conv);
            }
            return Some(Ok((*choice, conv)));
        }
        // The selection that decides the innermost loop: it must stand in the loop's own
        // sequence, not inside another branch of it, and its other branches must leave the loop.
        let first_repeat = walked
            .iter()
            .zip(&repeats)
            .find_map(|((_, _, e, _), r)| match e {
                End::Jump(j) if *r => Some(*j),
                _ => None,
            })
            .expect("a repeat");
        if !deciding {
            self.bad_jump(
                first_repeat,
                "its selection lies inside another branch of the loop; only a selection in the loop's own sequence can decide it (KRL's EXIT leaves one loop)",
            );
            return None;
        }
        if let Some(k) = (0..walked.len()).find(|&k| !repeats[k] && walked[k].3) {
            self.propose_loop();
            self.fail(
                walked[k].0,
                Code::BadJump,
                format!(
                    "this branch of the selection localId {} goes on in the loop while another branch jumps back: a loop is decided by one selection whose other branches leave it",
                    el[div].local_id
                ),
            );
            return None;
        }
        let exits: Vec<usize> = (0..walked.len())
            .filter(|&k| !repeats[k] && !matches!(walked[k].2, End::Left))
            .collect();
        let gone = (0..walked.len()).any(|k| matches!(walked[k].2, End::Left));
        let after = match exits.as_slice() {
            [] if gone && mids == 0 => After::Gone,
            [] => After::Nothing,
            // The one exit is walked as what follows the loop (unless earlier exits join it).
            [one] if mids == 0 => After::Continue(self.after_head(walked[*one].0)),
            several => {
                let conv = match &walked[several[0]].2 {
                    End::Conv(c) => Some(*c),
                    _ => None,
                };
                let joined = conv.is_some_and(|c| {
                    several
                        .iter()
                        .all(|&k| matches!(walked[k].2, End::Conv(x) if x == c))
                        && self.g.preds(c).len() == several.len() + mids
                });
                let Some(conv) = conv.filter(|_| joined) else {
                    self.propose_meetings(&walked);
                    self.propose_loop();
                    self.fail(
                        div,
                        Code::UnbalancedBranch,
                        format!(
                            "selectionDivergence decides a loop, and its {} branches that leave it (with {mids} that leave it earlier) do not end in one selectionConvergence joining just them",
                            several.len()
                        ),
                    );
                    return None;
                };
                After::From(conv)
            }
        };
        let branches = walked
            .into_iter()
            .enumerate()
            .map(|(k, (t, body, end, _))| Branch {
                transition: t,
                body,
                end: match end {
                    End::Jump(j) if repeats[k] => BranchEnd::Repeat(j),
                    End::Left => BranchEnd::Join,
                    _ => BranchEnd::Leave,
                },
            })
            .collect();
        Some(Err(End::Decided {
            choice: Box::new(Block::Choice {
                divergence: div,
                convergence: None,
                branches,
            }),
            after,
        }))
    }

    /// A selection before the loop's deciding one, with one branch going on in the loop (walked:
    /// it ended at the deciding selection, `walked[k].2` is `End::Decided`) and the others
    /// leaving it: they are walked to the convergence that joins every exit of the loop.
    pub(super) fn early_exit(
        &mut self,
        div: usize,
        mut walked: Vec<(usize, Vec<Block>, End, bool)>,
        depth: usize,
    ) -> Branches {
        let k = walked.iter().position(|w| w.3).expect("one inside");
        let End::Decided { choice, after } = std::mem::replace(&mut walked[k].2, End::Endless)
        else {
            unreachable!("checked by the caller")
        };
        let total = self.loops.last().map_or(0, |l| l.mid_exits);
        for w in walked.iter_mut().filter(|w| !w.3) {
            let ctx = self.loops.pop().expect("an early exit needs a loop");
            let (b, end) = self.branch_walk(w.0, depth);
            self.loops.push(ctx);
            if self.failed {
                return None;
            }
            if let End::Jump(j) = end {
                self.bad_jump(
                    j,
                    "it leaves a loop from a selection before the one that decides it; only its exits may follow",
                );
                return None;
            }
            if let End::Left = end {
                self.propose_loop();
                self.fail(
                    w.0,
                    Code::BadJump,
                    "this branch leaves the loop before the selection that decides it, to another state".to_owned(),
                );
                return None;
            }
            w.1 = b;
            w.2 = end;
        }
        let conv = walked.iter().find(|w| !w.3).and_then(|w| match w.2 {
            End::Conv(c) => Some(c),
            _ => None,
        });
        let joined = conv.is_some_and(|c| {
            walked
                .iter()
                .filter(|w| !w.3)
                .all(|w| matches!(w.2, End::Conv(x) if x == c))
                && match &after {
                    After::From(a) => *a == c,
                    // The deciding selection has no exits of its own: every exit is early.
                    After::Nothing => self.g.preds(c).len() == total,
                    After::Continue(_) | After::Gone => false,
                }
        });
        let Some(conv) = conv.filter(|_| joined) else {
            self.propose_meetings(&walked);
            self.propose_loop();
            self.fail(
                div,
                Code::UnbalancedBranch,
                format!(
                    "selectionDivergence leaves the loop before the selection that decides it; every branch that leaves the loop must end in one selectionConvergence (here {} of them)",
                    total + walked.len().saturating_sub(1)
                ),
            );
            return None;
        };
        let mut choice = Some(*choice);
        let branches = walked
            .into_iter()
            .map(|(t, mut body, _, inside)| {
                if inside && let Some(c) = choice.take() {
                    body.push(c);
                }
                Branch {
                    transition: t,
                    body,
                    end: if inside {
                        BranchEnd::Join
                    } else {
                        BranchEnd::Leave
                    },
                }
            })
            .collect();
        Some(Err(End::Decided {
            choice: Box::new(Block::Choice {
                divergence: div,
                convergence: None,
                branches,
            }),
            after: After::From(conv),
        }))
    }
}
