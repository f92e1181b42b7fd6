//! A large SFC is tokenized on a second thread (`skillpost::read::tape`, named `skillpost-sfc`).
//! When the reading returns, that thread is gone: not only has its work ended, its thread-local
//! storage is freed too. Otherwise a leak checker that looks right after the reading (the fuzz
//! targets under LeakSanitizer) finds the thread's channel context still allocated and stops
//! the run, and a daemon that reads many files could briefly hold a thread per reading.
//!
//! This file holds one test, so no other test of its process starts such a thread meanwhile.

use std::path::Path;

use skillpost::diag::Diagnostics;
use skillpost::read::sfc::read_sfc_stream_with;
use skillpost::read::tape::Pipeline;

mod common;

/// The threads of this process named `skillpost-sfc`.
fn producers() -> usize {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0;
    };
    tasks
        .filter_map(Result::ok)
        .filter(|t| {
            std::fs::read_to_string(t.path().join("comm"))
                .is_ok_and(|c| c.trim() == "skillpost-sfc")
        })
        .count()
}

#[test]
fn the_producer_thread_is_gone_when_the_reading_returns() {
    if !Path::new("/proc/self/task").is_dir() {
        // Linux only: elsewhere there is no list of threads to look at.
        return common::skip("/proc/self/task is missing");
    }
    let text = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ok/reference-sample/sfc.xml"),
    )
    .unwrap();
    // Batches of 64 bytes: the producer fills the queue and waits in the channel, so its
    // thread-local channel context is made (what LeakSanitizer found still allocated).
    for round in 0..200 {
        let mut diags = Diagnostics::default();
        let sfc = read_sfc_stream_with(
            &text[..],
            0,
            text.len() as u64,
            None,
            &mut diags,
            Pipeline::Threaded,
            64,
        );
        assert!(sfc.is_ok(), "{:?}", diags.into_vec());
        // The reading joined the thread: its thread-local storage is freed (glibc runs the
        // destructors before the thread ends). The kernel may list the ended task for a moment
        // after the join returns (the join wakes when the task clears its tid, before the task
        // is reaped): a thread still there after a second was not joined.
        let since = std::time::Instant::now();
        let mut left = producers();
        while left > 0 && since.elapsed() < std::time::Duration::from_secs(1) {
            std::thread::sleep(std::time::Duration::from_millis(1));
            left = producers();
        }
        assert_eq!(
            left, 0,
            "round {round}: {left} producer thread(s) still there a second after the reading"
        );
    }
}
