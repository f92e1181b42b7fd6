//! The world around the programs: the inputs it sets (by the scenario, or at random), the
//! outputs it forces, the programs it starts again, and who it wakes.

use super::{Event, Ins, Key, Run, State, Val, reset_vars};

impl Run<'_> {
    /// Whether a program waits for an input of the world that a random run's world changes
    /// now and then (one the blackboard declares; no wire drives it). A wait for one it does
    /// not declare (`WaitDI di_WeldDone` in a step's code) is answered when every program
    /// waits ([`Run::answer`]), not by waiting for the other inputs to change.
    pub(super) fn waits_for_world(&self) -> bool {
        self.ctls.iter().enumerate().any(|(c, x)| {
            matches!(x.state, State::Blocked { .. })
                && match self.programs[c].ins.get(x.pc) {
                    Some((Ins::Wait { cond, .. }, _)) => {
                        let mut keys = Vec::new();
                        self.keys_of(c, cond, &mut keys);
                        keys.iter().any(|k| {
                            !self.wired[c].contains_key(k)
                                && self
                                    .cell
                                    .inputs
                                    .iter()
                                    .any(|i| i.controller == c && i.key.contains(k))
                        })
                    }
                    _ => false,
                }
        })
    }

    /// The time until a random run's world changes an input again: exponential, with a mean
    /// of three steps' time (1 s without step times).
    pub(super) fn flip_gap(&mut self) -> f64 {
        -self.flip_mean * (1.0 - self.rng.unit()).ln()
    }

    /// Applies every world event at time `t`.
    pub(super) fn fire_events(&mut self, t: f64) {
        let mut now = Vec::new();
        self.events.retain(|(te, e)| {
            if *te <= t {
                now.push(e.clone());
                false
            } else {
                true
            }
        });
        for e in now {
            match e {
                Event::Input(c, k, v) => {
                    self.set_world(c, &k, &v, t);
                    self.wake_all(t);
                }
                Event::Force(c, k, v) => {
                    self.force(c, &k, &v, t);
                    self.wake_all(t);
                }
                Event::Restart(c) => self.restart(c, t),
                Event::Flip(k) => {
                    let inp = &self.cell.inputs[k];
                    let (c, keys, integer) = (inp.controller, inp.key.clone(), inp.integer);
                    let old = keys
                        .first()
                        .and_then(|k0| self.world[c].get(k0))
                        .cloned()
                        .unwrap_or(Val::Bool(false));
                    let v = if integer || keys.len() > 1 {
                        self.random_number(k)
                    } else {
                        Val::Bool(!old.truth())
                    };
                    self.set_world(c, &keys, &v, t);
                    self.wake_all(t);
                    let gap = self.flip_gap();
                    self.events.push((t + gap, Event::Flip(k)));
                }
            }
        }
    }

    /// A program started again from the top at `t`: a motion that runs is cut short, its
    /// outputs keep their levels, its variables their first values.
    pub(super) fn restart(&mut self, c: usize, t: f64) {
        let p = &self.programs[c];
        let now = t;
        // Motions the advance run queued that have not begun never run; the one that runs is
        // cut short.
        if self
            .out
            .timeline
            .iter()
            .any(|s| s.controller == c && s.start > now + 1e-12)
        {
            self.drop_queued(c, now);
        }
        let x = &mut self.ctls[c];
        if let Some(i) = x.running.take()
            && self.out.timeline[i].end > now
        {
            self.out.timeline[i].end = now;
            self.out.timeline[i].cut = true;
        }
        x.t = now;
        x.motion_end = now;
        x.pc = 0;
        x.state = State::Running;
        x.wait_at = None;
        x.waiting_since = None;
        x.note = None;
        x.message = None;
        x.in_step = false;
        x.timed_out = false;
        x.last_step = None;
        // A reset takes the program's messages away (KRL `Clear_P_Reset`; RAPID and URScript
        // show none while stopped).
        if let Some(since) = x.shown.take() {
            self.out.messages.push((c, since, now));
        }
        reset_vars(x, p);
        self.out.restarts.push((c, now));
        self.wake_all(now);
    }

    /// Takes controller `c`'s steps that begin after `now` out of the timeline (the indices
    /// the run keeps into it follow).
    pub(super) fn drop_queued(&mut self, c: usize, now: f64) {
        let mut new_index = Vec::with_capacity(self.out.timeline.len());
        let mut kept = 0usize;
        for s in &self.out.timeline {
            if s.controller == c && s.start > now + 1e-12 {
                new_index.push(None);
            } else {
                new_index.push(Some(kept));
                kept += 1;
            }
        }
        let mut k = 0;
        self.out.timeline.retain(|_| {
            k += 1;
            new_index[k - 1].is_some()
        });
        for x in &mut self.ctls {
            x.running = x.running.and_then(|i| new_index[i]);
        }
        // The running step of `c` is its last one begun.
        self.ctls[c].running = self.out.timeline.iter().rposition(|s| s.controller == c);
        self.last_run.clear();
        for (i, s) in self.out.timeline.iter().enumerate() {
            self.last_run.insert(s.local_id, i);
        }
    }

    /// Wakes every waiting program at `t` to read its condition again (a polling one at its
    /// next poll).
    pub(super) fn wake_all(&mut self, t: f64) {
        for c in 0..self.ctls.len() {
            if matches!(self.ctls[c].state, State::Blocked { .. }) {
                let at = match self.ctls[c].wait_at {
                    Some((_, since)) => self.poll_at(c, since, t),
                    None => t,
                };
                let x = &mut self.ctls[c];
                x.state = State::Running;
                x.t = x.t.max(at);
            }
        }
    }

    /// A random value of integer input `k` of [`Cell::inputs`]: 0, or a number the programs
    /// compare it with, or one next to it (so a wait for `Count >= 5` can end).
    ///
    /// [`Cell::inputs`]: crate::simulate::Cell::inputs
    pub(super) fn random_number(&mut self, k: usize) -> Val {
        let values = self.cell.input_values.get(k).map_or(&[][..], Vec::as_slice);
        let n = values.len() as u64 * 3 + 1;
        let pick = self.rng.next_u64() % n;
        if pick == 0 {
            return Val::Num(0.0);
        }
        let (i, d) = ((pick - 1) / 3, (pick - 1) % 3);
        Val::Num((values[i as usize] + d as f64 - 1.0).max(0.0))
    }

    /// All programs wait: the world (a random run) sets an input one of them waits for, a
    /// moment later. `false` when no wait reads an input of the world.
    pub(super) fn answer(&mut self) -> bool {
        let mut cands: Vec<(usize, Key, f64)> = Vec::new();
        for (c, x) in self.ctls.iter().enumerate() {
            if let State::Blocked { .. } = x.state
                && let Some((Ins::Wait { cond, .. }, _)) = self.programs[c].ins.get(x.pc)
            {
                let mut keys = Vec::new();
                self.keys_of(c, cond, &mut keys);
                for k in keys {
                    if !self.wired[c].contains_key(&k) && !k.ends_with("(?)") {
                        cands.push((c, k, x.t));
                    }
                }
            }
        }
        if cands.is_empty() {
            return false;
        }
        let (c, k, t) = cands[(self.rng.next_u64() % cands.len() as u64) as usize].clone();
        let old = self.world[c].get(&k).cloned().unwrap_or(Val::Bool(false));
        let v = match old {
            Val::Bool(b) => Val::Bool(!b),
            Val::Num(n) => Val::Num(((n as u64 + 1 + self.rng.next_u64() % 3) % 4) as f64),
            s => s,
        };
        let at = t + 0.1 + self.rng.unit();
        self.events.push((at, Event::Input(c, vec![k], v)));
        true
    }

    /// The output of controller `c` that a scenario's `keys` name (decided once, when the
    /// scenario is set up; the world's own inputs are never outputs).
    pub(super) fn forced<'k>(&self, c: usize, keys: &'k [Key]) -> Option<&'k Key> {
        match keys {
            [k] if self
                .cell
                .outputs
                .iter()
                .any(|o| o.controller == c && o.key == keys) =>
            {
                Some(k)
            }
            _ => None,
        }
    }

    /// Forces output `k` of controller `c`, as from the pendant's I/O display.
    pub(super) fn force(&mut self, c: usize, k: &Key, v: &Val, t: f64) {
        let old = self.ctls[c].outs.insert(k.clone(), v.clone());
        if old.as_ref() != Some(v) || t == 0.0 {
            self.out.changes.push((t, c, k.clone(), v.clone()));
        }
    }

    /// Sets an input of the world (a KRL group: each bit of the value).
    pub(super) fn set_world(&mut self, c: usize, keys: &[Key], v: &Val, t: f64) {
        if keys.len() == 1 {
            let old = self.world[c].insert(keys[0].clone(), v.clone());
            if old.as_ref() != Some(v) || t == 0.0 {
                self.out.changes.push((t, c, keys[0].clone(), v.clone()));
            }
            return;
        }
        let n = v.num().unwrap_or(0.0).max(0.0) as u64;
        for (i, k) in keys.iter().enumerate() {
            let b = Val::Bool(i < 64 && (n >> i) & 1 == 1);
            let old = self.world[c].insert(k.clone(), b.clone());
            if old.as_ref() != Some(&b) || t == 0.0 {
                self.out.changes.push((t, c, k.clone(), b));
            }
        }
    }
}
