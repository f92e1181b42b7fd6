//! What a run finds wrong: the end of a run told apart (ended, a deadlock, a wait for what
//! nothing sets), the order of steps across controllers, tells, faults and limits.

use super::eval::EvalError;
use super::{Ins, ProblemKind, Run, State};
use crate::simulate::Problem;

impl Run<'_> {
    pub(super) fn limit(&mut self, what: String) {
        self.out.end_time = self.now();
        self.out.problems.push(Problem {
            kind: ProblemKind::Limit,
            time: self.out.end_time,
            controller: None,
            line: None,
            local_id: None,
            message: what,
        });
    }

    /// Nothing can move any more: ended, or a deadlock, or a wait for an input nothing sets.
    pub(super) fn finish(&mut self) {
        self.out.end_time = self.now();
        self.out.ended = self.ctls.iter().all(|x| x.state == State::Ended);
        let names = |c: usize| self.cell.controllers[c].name.clone();
        let mut waits = Vec::new();
        for (c, x) in self.ctls.iter().enumerate() {
            match &x.state {
                State::Blocked { since, .. } => {
                    let Some((Ins::Wait { cond, .. }, line)) = self.programs[c].ins.get(x.pc)
                    else {
                        continue;
                    };
                    let mut keys = Vec::new();
                    self.keys_of(c, cond, &mut keys);
                    cond.outputs(&mut keys);
                    let partners: Vec<usize> = keys
                        .iter()
                        .filter_map(|k| self.wired[c].get(k).map(|w| w.0))
                        .collect();
                    waits.push((c, *since, *line, partners, keys));
                }
                State::Halted { faulted: true, .. } => {}
                State::Halted { message, .. } => {
                    let line = self.programs[c].ins.get(x.pc).map(|i| i.1);
                    self.out.problems.push(Problem {
                        kind: ProblemKind::Stopped,
                        time: x.t,
                        controller: Some(c),
                        line,
                        local_id: x.note.as_deref().and_then(crate::simulate::ir::local_id_in),
                        message: format!(
                            "{} stopped at {:.2} s: {}",
                            names(c),
                            x.t,
                            message
                                .clone()
                                .unwrap_or_else(|| "its program stopped itself".to_owned())
                        ),
                    });
                }
                _ => {}
            }
        }
        if waits.is_empty() {
            return;
        }
        // Stuck: a program that waits for the world (nothing sets what it reads), and every
        // program that waits for a stuck one. The others wait for each other, or for a partner
        // that ended or stopped: a deadlock.
        let mut stuck: Vec<usize> = waits
            .iter()
            .filter(|w| w.3.is_empty())
            .map(|w| w.0)
            .collect();
        loop {
            let more: Vec<usize> = waits
                .iter()
                .filter(|w| !stuck.contains(&w.0) && w.3.iter().any(|p| stuck.contains(p)))
                .map(|w| w.0)
                .collect();
            if more.is_empty() {
                break;
            }
            stuck.extend(more);
        }
        for (c, since, line, partners, keys) in waits {
            let x = &self.ctls[c];
            let what = x
                .note
                .as_deref()
                .map(|n| n.trim_start_matches("handshake:").trim().to_owned());
            let message = if !partners.is_empty() {
                let mut ps: Vec<String> = partners
                    .iter()
                    .map(|&p| {
                        let state = match &self.ctls[p].state {
                            State::Ended => "which has ended".to_owned(),
                            State::Halted { .. } => "which has stopped (start it again)".to_owned(),
                            State::Blocked { .. } if stuck.contains(&p) => format!(
                                "which waits for what nothing sets (line {})",
                                self.programs[p].ins.get(self.ctls[p].pc).map_or(0, |i| i.1)
                            ),
                            State::Blocked { .. } => format!(
                                "which waits too (line {})",
                                self.programs[p].ins.get(self.ctls[p].pc).map_or(0, |i| i.1)
                            ),
                            State::Running => "which runs".to_owned(),
                        };
                        format!("{} {state}", names(p))
                    })
                    .collect();
                ps.dedup();
                format!(
                    "{} waits since {since:.2} s at line {line}{}: for {}",
                    names(c),
                    what.map(|w| format!(" ({w})")).unwrap_or_default(),
                    ps.join(", ")
                )
            } else {
                let inputs: Vec<String> = keys.iter().map(|k| self.cell.input_name(c, k)).collect();
                format!(
                    "{} waits for {}, which nothing sets, since {since:.2} s (line {line})",
                    names(c),
                    inputs.join(", ")
                )
            };
            self.out.problems.push(Problem {
                kind: if stuck.contains(&c) {
                    ProblemKind::Stuck
                } else {
                    ProblemKind::Deadlock
                },
                time: since,
                controller: Some(c),
                line: Some(line),
                local_id: x.note.as_deref().and_then(crate::simulate::ir::local_id_in),
                message,
            });
        }
    }

    pub(super) fn problem_at(
        &mut self,
        c: usize,
        kind: ProblemKind,
        line: u32,
        local_id: Option<u64>,
        message: String,
    ) {
        let time = self.ctls[c].t;
        self.out.problems.push(Problem {
            kind,
            time,
            controller: Some(c),
            line: Some(line),
            local_id,
            message,
        });
    }

    /// A tell that a step is done (the writer's `handshake: tell R2 that step 'Grip' (localId
    /// 5) is done`) must come before the teller's next step: a partner that waits for the step
    /// would otherwise wait for that one too.
    pub(super) fn check_tell(&mut self, c: usize, note: &str, line: u32) {
        let Some(rest) = note.strip_prefix("handshake: tell ") else {
            return;
        };
        let Some((_, step)) = rest.split_once(" that step '") else {
            return;
        };
        if !step.contains(") is done") {
            return;
        }
        let Some(id) = crate::simulate::ir::local_id_in(step) else {
            return;
        };
        let last = self.ctls[c].last_step;
        if self.own_steps[c].contains(&id) && last != Some(id) {
            let name = step.split('\'').next().unwrap_or_default().to_owned();
            let after = last
                .and_then(|l| {
                    self.out
                        .timeline
                        .iter()
                        .rev()
                        .find(|s| s.local_id == l && s.controller == c)
                })
                .map_or_else(|| "none".to_owned(), |s| s.name.clone());
            self.problem_at(
                c,
                ProblemKind::LateTell,
                line,
                Some(id),
                format!(
                    "{} tells that step {name} (localId {id}) is done only after its step {after} started: a partner that waits for {name} waits for {after} too",
                    self.cell.controllers[c].name
                ),
            );
        }
    }

    pub(super) fn fault(&mut self, c: usize, line: u32, e: EvalError) {
        let message = format!(
            "{} cannot run line {line}: {}",
            self.cell.controllers[c].name, e.0
        );
        self.problem_at(c, ProblemKind::Fault, line, None, message);
        self.ctls[c].state = State::Halted {
            message: Some(format!("a fault at line {line}")),
            faulted: true,
        };
    }

    /// A step of the timeline started before a step the chart puts before it had ended.
    pub(super) fn check_order(&mut self, i: usize) {
        let s = &self.out.timeline[i];
        let Some(preds) = self.cell.preds.get(&s.local_id) else {
            return;
        };
        for p in preds {
            if let Some(r) = self.last_run.get(p).map(|&k| &self.out.timeline[k])
                && r.controller != s.controller
                && r.end > s.start + 1e-9
                && r.start <= s.start
            {
                let names = &self.cell.controllers;
                self.out.problems.push(Problem {
                    kind: ProblemKind::Order,
                    time: s.start,
                    controller: Some(s.controller),
                    line: None,
                    local_id: Some(s.local_id),
                    message: format!(
                        "step {} (localId {}) on {} started at {:.2} s, before step {} (localId {}) on {}, which the chart puts before it, ended at {:.2} s",
                        s.name,
                        s.local_id,
                        names[s.controller].name,
                        s.start,
                        r.name,
                        r.local_id,
                        names[r.controller].name,
                        r.end
                    ),
                });
            }
        }
    }
}
