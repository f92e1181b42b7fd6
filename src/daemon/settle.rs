//! When to compile: a quiet period after the last change, capped while changes keep coming, one
//! compile at a time per project, and exactly one follow-up for changes during a compile.
//!
//! A save that ends in a complete write (the writer closed the file, or renamed it into place)
//! is compiled after a short [`QUICK`] window instead of the quiet period, an *early* run, when
//! no other write completed within the quiet period before it (a stream of saves is coalesced
//! as before). An early run that fails reports nothing; [`Scheduler::confirm`] then compiles again
//! once the inputs have been quiet for the whole period, and that run reports (docs/DAEMON.md,
//! "When a change compiles").
//!
//! [`Scheduler`] is pure state: the caller passes the time (`tokio::time::Instant`, so tests run
//! under tokio's paused clock) and arms a timer at [`Scheduler::deadline`].

use std::time::Duration;
use tokio::time::Instant;

/// How long after a complete write (closed, or renamed into place) its compile starts: other
/// files of the same save (a tool writing the SFC and the blackboard in one go, an editor's
/// backup removed after its rename) arrive within it. Never longer than the quiet period.
pub const QUICK: Duration = Duration::from_millis(5);

/// What a compile the scheduler starts is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Run {
    /// After the quiet period (or at once: startup, rescan).
    Settled,
    /// After [`QUICK`]: the burst ended in a complete write. A failure is not reported; the
    /// caller calls [`Scheduler::confirm`].
    Early,
    /// The run after an early one that failed: the inputs were quiet for the whole period since
    /// a complete write.
    Confirm,
}

/// One project's compile schedule.
#[derive(Debug, Clone)]
pub struct Scheduler {
    settle: Duration,
    max_wait: Duration,
    /// The first change of the current burst.
    first: Option<Instant>,
    /// The last change of the current burst (or of the last run's, for [`Scheduler::confirm`]).
    last: Option<Instant>,
    /// When the burst is considered settled.
    deadline: Option<Instant>,
    /// What the run at the deadline will be.
    next: Run,
    /// What the running (or last) run is.
    current: Run,
    running: bool,
    /// A change arrived while compiling.
    pending: bool,
    /// When the last write was seen complete.
    last_complete: Option<Instant>,
}

impl Scheduler {
    /// `settle`: the quiet period; `max_wait`: the longest a burst can delay a compile.
    pub fn new(settle: Duration, max_wait: Duration) -> Self {
        Scheduler {
            settle,
            max_wait: max_wait.max(settle),
            first: None,
            last: None,
            deadline: None,
            next: Run::Settled,
            current: Run::Settled,
            running: false,
            pending: false,
            last_complete: None,
        }
    }

    fn quick(&self) -> Duration {
        QUICK.min(self.settle)
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
        self.last = Some(now);
        self.next = Run::Settled;
        self.deadline = Some((now + self.settle).min(first + self.max_wait));
    }

    /// A write was seen complete at `now` (the file closed after writing, or renamed into
    /// place) and no input is open for writing: compile after [`QUICK`], unless another change
    /// comes first. A change like any other during a compile, or when another write completed
    /// less than the quiet period before (the saves come in a stream, or a tool writes several
    /// files).
    pub fn completed(&mut self, now: Instant) {
        let stream = self.last_complete.is_some_and(|l| now < l + self.settle);
        self.last_complete = Some(now);
        if self.running || stream {
            self.change(now);
            return;
        }
        self.first.get_or_insert(now);
        self.last = Some(now);
        self.next = Run::Early;
        let quick = now + self.quick();
        self.deadline = Some(self.deadline.map_or(quick, |d| d.min(quick)));
    }

    /// An early run failed: compile again when the inputs have been quiet for the whole period
    /// since the burst's last change (at once if they have). A follow-up already scheduled by a
    /// change during the run stays what it is.
    pub fn confirm(&mut self, now: Instant) {
        if self.running || self.deadline.is_some() {
            return;
        }
        let at = self.last.map_or(now, |l| l + self.settle).max(now);
        self.first = Some(now);
        self.next = Run::Confirm;
        self.deadline = Some(at);
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
        self.last = Some(now);
        self.next = Run::Settled;
        self.deadline = Some(now + self.settle);
    }

    /// Try again after `delay` (a compile that ran short of descriptors or memory).
    pub fn retry_after(&mut self, now: Instant, delay: Duration) {
        if self.running {
            self.pending = true;
            return;
        }
        self.first.get_or_insert(now);
        self.last = Some(now);
        self.next = Run::Settled;
        self.deadline = Some(now + delay);
    }

    /// Compile now, without a quiet period (startup, rescan).
    pub fn immediately(&mut self, now: Instant) {
        if self.running {
            self.pending = true;
        } else {
            self.first.get_or_insert(now);
            self.next = Run::Settled;
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
                self.current = std::mem::replace(&mut self.next, Run::Settled);
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

    /// What the running (or last) compile is.
    pub fn run(&self) -> Run {
        self.current
    }

    /// When the inputs will have been quiet for the whole period since the last change seen
    /// (`now` when none was seen, or it is that long ago); `None` while a compile waits or runs.
    /// A deploy waits for it: a compile that read half of a save (the SFC saved, the blackboard
    /// still to come) is never deployed.
    pub fn quiet_at(&self, now: Instant) -> Option<Instant> {
        if self.is_busy() {
            return None;
        }
        Some(self.last.map_or(now, |l| (l + self.settle).max(now)))
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

    #[test]
    fn a_complete_write_compiles_after_the_quick_window() {
        let t = Instant::now();
        let mut s = Scheduler::new(S, S * 10);
        // An in-place save: its writes, then its close.
        s.change(t);
        s.completed(t + Duration::from_millis(2));
        assert_eq!(s.deadline(), Some(t + Duration::from_millis(2) + QUICK));
        assert!(s.fire(t + Duration::from_millis(2) + QUICK));
        assert_eq!(s.run(), Run::Early);
        assert!(!s.finished(t + Duration::from_millis(10)));
        assert_eq!(s.deadline(), None);
    }

    #[test]
    fn a_change_after_a_complete_write_waits_the_whole_period() {
        // A tool writes the SFC (closed), then starts on the blackboard.
        let t = Instant::now();
        let mut s = Scheduler::new(S, S * 10);
        s.completed(t);
        let later = t + Duration::from_millis(3);
        s.change(later);
        assert_eq!(s.deadline(), Some(later + S));
        assert!(s.fire(later + S));
        assert_eq!(s.run(), Run::Settled);
    }

    #[test]
    fn the_quick_window_is_never_longer_than_the_quiet_period() {
        let t = Instant::now();
        let mut s = Scheduler::new(Duration::from_millis(1), Duration::from_secs(1));
        s.completed(t);
        assert_eq!(s.deadline(), Some(t + Duration::from_millis(1)));
    }

    #[test]
    fn a_failed_early_run_is_confirmed_a_quiet_period_after_the_last_change() {
        let t = Instant::now();
        let mut s = Scheduler::new(S, S * 10);
        s.completed(t);
        assert!(s.fire(t + QUICK));
        let end = t + QUICK + Duration::from_millis(4);
        assert!(!s.finished(end));
        s.confirm(end);
        assert_eq!(
            s.deadline(),
            Some(t + S),
            "quiet for the period since the save"
        );
        assert!(s.fire(t + S));
        assert_eq!(s.run(), Run::Confirm);
        s.finished(t + S);
        // A long early run: quiet already when it ends, confirmed at once.
        s.completed(t + S * 2);
        assert!(s.fire(t + S * 2 + QUICK));
        let end = t + S * 4;
        s.finished(end);
        s.confirm(end);
        assert_eq!(s.deadline(), Some(end));
    }

    #[test]
    fn a_change_during_an_early_run_is_what_follows_it() {
        let t = Instant::now();
        let mut s = Scheduler::new(S, S * 10);
        s.completed(t);
        assert!(s.fire(t + QUICK));
        // The blackboard is being written while the early run compiles.
        s.change(t + QUICK + Duration::from_millis(1));
        let end = t + QUICK + Duration::from_millis(4);
        assert!(s.finished(end));
        s.confirm(end);
        assert_eq!(
            s.deadline(),
            Some(end + S),
            "the follow-up, not a confirmation"
        );
        assert!(s.fire(end + S));
        assert_eq!(s.run(), Run::Settled);
    }

    #[test]
    fn saves_in_a_stream_are_coalesced() {
        let t = Instant::now();
        let mut s = Scheduler::new(S, S * 10);
        s.completed(t);
        assert!(s.fire(t + QUICK));
        // Saved again during the compile, and 20 ms after that save.
        let second = t + QUICK + Duration::from_millis(1);
        s.completed(second);
        let end = t + QUICK + Duration::from_millis(4);
        assert!(s.finished(end));
        assert_eq!(s.deadline(), Some(end + S));
        let third = second + Duration::from_millis(20);
        s.completed(third);
        assert_eq!(s.deadline(), Some(third + S));
        assert!(s.fire(third + S));
        assert_eq!(s.run(), Run::Settled);
        s.finished(third + S);
        // A save a quiet period after the last one: early again.
        s.completed(third + S);
        assert_eq!(s.deadline(), Some(third + S + QUICK));
    }

    #[test]
    fn an_input_still_open_turns_an_early_run_into_a_settled_one() {
        let t = Instant::now();
        let mut s = Scheduler::new(S, S * 10);
        s.completed(t);
        s.postpone(t + QUICK);
        assert!(s.fire(t + QUICK + S));
        assert_eq!(s.run(), Run::Settled);
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

    #[test]
    fn the_inputs_are_quiet_a_whole_period_after_the_last_change_and_never_while_busy() {
        let t = Instant::now();
        let mut s = Scheduler::new(S, S * 10);
        assert_eq!(s.quiet_at(t), Some(t), "nothing seen: quiet now");
        s.completed(t);
        assert_eq!(s.quiet_at(t), None, "a compile waits");
        assert!(s.fire(t + QUICK));
        assert_eq!(s.quiet_at(t + QUICK), None, "a compile runs");
        // The second file of the save arrives during the early run.
        s.change(t + QUICK * 2);
        assert!(s.finished(t + QUICK * 3));
        assert_eq!(s.quiet_at(t + QUICK * 3), None, "its compile waits");
        assert!(s.fire(t + QUICK * 3 + S));
        assert!(!s.finished(t + QUICK * 4 + S));
        // Quiet a whole period after the follow-up was scheduled (the last change seen).
        assert_eq!(s.quiet_at(t + QUICK * 4 + S), Some(t + QUICK * 4 + S));
        let mut s = Scheduler::new(S, S * 10);
        s.completed(t);
        assert!(s.fire(t + QUICK));
        assert!(!s.finished(t + QUICK * 2));
        assert_eq!(
            s.quiet_at(t + QUICK * 2),
            Some(t + S),
            "a period after the save"
        );
    }
}
