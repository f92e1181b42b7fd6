//! The end of the daemon: after a [`super::Control::Stop`], the running compiles are waited for
//! at most [`STOP_TIMEOUT`] (a second stop ends the wait at once), `stopped` is emitted, and the
//! last events are flushed with a bounded wait ([`super::events::FLUSH_TIMEOUT`]), so that
//! neither a hung compile nor a stalled reader of the event stream can hold the process.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::time::Instant;

use super::events::{self, Event};
use super::job::Report;
use super::{Control, Daemon};

/// How long a stop (`SIGTERM`, `SIGINT`) waits for running compiles before it gives up on them
/// (`stopped` with reason `timeout`, exit status 2); `SKILLPOST_STOP_TIMEOUT_MS` changes it.
/// systemd's `TimeoutStopSec` must be longer than this plus [`events::FLUSH_TIMEOUT`] (a test
/// checks the unit).
pub const STOP_TIMEOUT: Duration = Duration::from_secs(10);

/// The stop timeout: `SKILLPOST_STOP_TIMEOUT_MS`, else [`STOP_TIMEOUT`].
fn stop_timeout() -> Duration {
    std::env::var("SKILLPOST_STOP_TIMEOUT_MS")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .map_or(STOP_TIMEOUT, Duration::from_millis)
}

/// Test hooks, not for production use: a compile sleeps for the milliseconds the variable `var`
/// gives, if set. `SKILLPOST_TEST_HANG_MS` before it starts (a hung compile for the stop tests
/// in tests/events.rs); `SKILLPOST_TEST_REPORT_LAG_MS` between its outcome's event and its
/// report to the daemon's loop (the window in which a file's change arrives while the loop
/// still takes the compile for running, for tests/trust.rs).
pub(super) fn test_hook_sleep(var: &str) {
    if let Some(ms) = std::env::var(var).ok().and_then(|v| v.parse().ok()) {
        std::thread::sleep(Duration::from_millis(ms));
    }
}

impl Daemon {
    /// Finishes the running compiles (bounded), starts no new ones, emits `stopped`, flushes
    /// the events (bounded). `Err` when compiles were still running (exit status 2).
    pub(super) async fn stop(
        mut self,
        reason: String,
        mut done: mpsc::UnboundedReceiver<Report>,
        mut control: mpsc::UnboundedReceiver<Control>,
    ) -> Result<(), String> {
        let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
        let queued: BTreeSet<PathBuf> = self.queue.drain(..).collect();
        let timeout = stop_timeout();
        let deadline = Instant::now() + timeout;
        // Running deploy hooks are ended (SIGTERM to their process group, SIGKILL 2 s later)
        // while the compiles finish; waited for within the same timeout.
        self.deploy_stop.send_replace(true);
        let hooks: Vec<_> = std::mem::take(&mut self.deploys)
            .into_values()
            .map(|w| w.into_task())
            .collect();
        while self.running > 0 {
            tokio::select! {
                r = done.recv() => match r {
                    Some(r) => {
                        self.running -= 1;
                        self.finish_report(r, Instant::now());
                    }
                    None => break,
                },
                _ = tokio::time::sleep_until(deadline) => break,
                Some(Control::Stop(_)) = control.recv() => break,
            }
        }
        for h in hooks {
            let _ = tokio::time::timeout_at(deadline, h).await;
        }
        let result = if self.running == 0 {
            tracing::info!(reason = %reason, "stopped");
            self.sink.emit(
                None,
                Event::Stopped {
                    reason,
                    requested: None,
                    compiling: None,
                },
            );
            Ok(())
        } else {
            let compiling: Vec<String> = self
                .projects
                .iter()
                .filter(|(k, p)| p.sched.is_running() && !queued.contains(*k))
                .map(|(k, _)| k.display().to_string())
                .collect();
            let message = format!(
                "stopped with {} compile(s) still running: {}",
                self.running,
                compiling.join(", ")
            );
            tracing::error!(reason = %reason, "{message}");
            self.sink.emit(
                None,
                Event::Stopped {
                    reason: "timeout".into(),
                    requested: Some(reason),
                    compiling: Some(compiling),
                },
            );
            Err(format!("{message} (stop timeout {timeout:?})"))
        };
        // The last events out, bounded: a stalled reader of the stream cannot hold the process.
        let waiting = self.sink.flush(events::FLUSH_TIMEOUT);
        if waiting > 0 {
            tracing::error!("{waiting} event(s) not written: the event stream is stalled");
        }
        result
    }
}
