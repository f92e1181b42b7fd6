//! When to compile: a quiet period after the last change, capped while changes keep coming, one
//! compile at a time per project, and exactly one follow-up for changes during a compile.
//!
//! [`Scheduler`] is pure state: the caller passes the time (`tokio::time::Instant`, so tests run
//! under tokio's paused clock) and arms a timer at [`Scheduler::deadline`].

use std::time::Duration;
use tokio::time::Instant;

/// One project's compile schedule.
#[derive(Debug, Clone)]
pub struct Scheduler {
    settle: Duration,
    max_wait: Duration,
    /// The first change of the current burst.
    first: Option<Instant>,
    /// When the burst is considered settled.
    deadline: Option<Instant>,
    running: bool,
    /// A change arrived while compiling.
    pending: bool,
}

impl Scheduler {
    /// `settle`: the quiet period; `max_wait`: the longest a burst can delay a compile.
    pub fn new(settle: Duration, max_wait: Duration) -> Self {
        Scheduler {
            settle,
            max_wait: max_wait.max(settle),
            first: None,
            deadline: None,
            running: false,
            pending: false,
        }
    }

    /// Takes a new quiet period and cap (a reloaded configuration); the state stays.
    pub fn set_timing(&mut self, settle: Duration, max_wait: Duration) {
        self.settle = settle;
        self.max_wait = max_wait.max(settle);
    }

    /// A relevant change was seen at `now`.
    pub fn change(&mut self, now: Instant) {
        if self.running {
            self.pending = true;
            return;
        }
        let first = *self.first.get_or_insert(now);
        self.deadline = Some((now + self.settle).min(first + self.max_wait));
    }

    /// Wait again before compiling (a file still being written): one more quiet period, still
    /// within the cap of the burst.
    pub fn postpone(&mut self, now: Instant) {
        if self.running {
            self.pending = true;
            return;
        }
        // Always a quiet period from now: past the cap of the burst a deadline at the cap is
        // already due, and the event loop would wake for it again and again (it did, about a
        // hundred times a second while a program kept an input open for writing).
        self.first.get_or_insert(now);
        self.deadline = Some(now + self.settle);
    }

    /// Compile now, without a quiet period (startup, rescan).
    pub fn immediately(&mut self, now: Instant) {
        if self.running {
            self.pending = true;
        } else {
            self.first.get_or_insert(now);
            self.deadline = Some(now);
        }
    }

    /// When to call [`Scheduler::fire`] next, if anything is waiting.
    pub fn deadline(&self) -> Option<Instant> {
        if self.running { None } else { self.deadline }
    }

    /// Whether the burst has settled whose compile should start now; marks it running.
    pub fn fire(&mut self, now: Instant) -> bool {
        match self.deadline {
            Some(d) if !self.running && now >= d => {
                self.deadline = None;
                self.first = None;
                self.running = true;
                true
            }
            _ => false,
        }
    }

    /// The compile ended at `now`; a change during it schedules exactly one follow-up (after a
    /// quiet period). Returns whether one was scheduled.
    pub fn finished(&mut self, now: Instant) -> bool {
        self.running = false;
        if std::mem::take(&mut self.pending) {
            self.change(now);
            true
        } else {
            false
        }
    }

    pub fn is_running(&self) -> bool {
        self.running
    }

    /// Whether a compile is waiting or running.
    pub fn is_busy(&self) -> bool {
        self.running || self.deadline.is_some() || self.pending
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::time::{advance, sleep_until};

    const S: Duration = Duration::from_millis(100);

    /// Drives a scheduler like the daemon does: changes at the given offsets (ms), compiles that
    /// take `compile` each; returns the start times (ms after the beginning) of the compiles.
    async fn drive(changes: &[u64], compile: Duration, max_wait: Duration) -> Vec<u64> {
        let t0 = Instant::now();
        let mut s = Scheduler::new(S, max_wait);
        let mut changes: Vec<Instant> = changes
            .iter()
            .map(|ms| t0 + Duration::from_millis(*ms))
            .collect();
        changes.reverse();
        let mut running_until: Option<Instant> = None;
        let mut starts = Vec::new();
        loop {
            let next_change = changes.last().copied();
            let next = [next_change, s.deadline(), running_until]
                .into_iter()
                .flatten()
                .min();
            let Some(next) = next else { break };
            sleep_until(next).await;
            let now = Instant::now();
            if running_until.is_some_and(|r| r <= now) {
                running_until = None;
                s.finished(now);
            }
            while changes.last().is_some_and(|c| *c <= now) {
                changes.pop();
                s.change(now);
            }
            if s.fire(now) {
                starts.push((now - t0).as_millis() as u64);
                running_until = Some(now + compile);
            }
        }
        starts
    }

    #[tokio::test(start_paused = true)]
    async fn one_change_compiles_after_the_quiet_period() {
        assert_eq!(
            drive(&[0], Duration::from_millis(10), S * 10).await,
            vec![100]
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_burst_is_one_compile_after_it_settles() {
        // 10 changes 20 ms apart: quiet from 180 ms on.
        let changes: Vec<u64> = (0..10).map(|i| i * 20).collect();
        assert_eq!(
            drive(&changes, Duration::from_millis(10), S * 10).await,
            vec![280]
        );
    }

    #[tokio::test(start_paused = true)]
    async fn an_endless_burst_is_capped() {
        // A change every 50 ms for 3 s: compiles at most every max_wait (1 s).
        let changes: Vec<u64> = (0..60).map(|i| i * 50).collect();
        let starts = drive(&changes, Duration::from_millis(10), S * 10).await;
        assert_eq!(starts[0], 1000, "{starts:?}");
        assert!(starts.len() <= 4, "{starts:?}");
        assert_eq!(*starts.last().unwrap(), 3050, "{starts:?}");
    }

    #[test]
    fn postponing_past_the_cap_waits_a_quiet_period_from_now() {
        // A writer keeps a file open past the cap of the burst: each postpone must give a
        // deadline in the future, or the event loop wakes for it at once, again and again.
        let t = Instant::now();
        let mut s = Scheduler::new(S, S * 10);
        s.change(t);
        for ms in [1500, 1600, 5000] {
            let now = t + Duration::from_millis(ms);
            s.postpone(now);
            assert_eq!(s.deadline(), Some(now + S), "at {ms} ms");
        }
    }

    #[tokio::test(start_paused = true)]
    async fn changes_during_a_compile_give_exactly_one_follow_up() {
        // Compile runs 100..600 ms; three changes during it.
        let starts = drive(&[0, 200, 300, 400], Duration::from_millis(500), S * 10).await;
        assert_eq!(starts, vec![100, 700]);
    }

    #[tokio::test(start_paused = true)]
    async fn immediately_skips_the_quiet_period_but_not_a_running_compile() {
        let mut s = Scheduler::new(S, S * 10);
        let t = Instant::now();
        s.immediately(t);
        assert!(s.fire(t));
        s.immediately(t);
        assert!(!s.fire(t), "one compile at a time");
        advance(Duration::from_millis(5)).await;
        assert!(s.finished(Instant::now()));
        assert!(s.is_busy());
    }
}
