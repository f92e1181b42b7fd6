//! Issue 37, item 6: a compile that failed because the process ran out of descriptors is tried
//! again, not reported as the project's failure for good. Its own test binary: it lowers the
//! open-file limit of this process and fills its descriptor table, which would break any test
//! running beside it.

mod inproc;

use std::fs;
use std::time::Duration;

use inproc::*;

#[test]
fn a_compile_that_ran_out_of_descriptors_is_tried_again() {
    use rustix::process::{Resource, Rlimit, setrlimit};
    // Room for the lock of the project folder beside the 256 kept for the compiles and the
    // hooks' share, not much more: the descriptor table can be filled quickly.
    let limit = 600;
    setrlimit(
        Resource::Nofile,
        Rlimit {
            current: Some(limit),
            maximum: Some(limit),
        },
    )
    .unwrap();
    let w = Workspace::new();
    let a = w.project("A");
    let d = InProc::with_dirs(&[&a]);
    d.wait_for("the first compile", WAIT, |e| {
        is_for(e, "compile-succeeded", &a)
    });
    // The edit is written beside the workspace first and renamed over the chart once every
    // descriptor is taken: the daemon sees one complete new file (an in-place save would show it
    // an empty file first, which it rightly takes for a save in progress, not for a shortage).
    let staged = w.root.join("sfc.xml.new");
    fs::write(&staged, sfc_with_x(777)).unwrap();
    let mut filler = Vec::new();
    while let Ok(f) = fs::File::open("/dev/null") {
        filler.push(f);
    }
    let mark = d.mark();
    fs::rename(&staged, a.join("sfc.xml")).unwrap();
    let evs = d.wait_for("the retry", Duration::from_secs(30), |e| {
        is_after(e, "compile-retrying", &a, mark) || is_after(e, "compile-failed", &a, mark)
    });
    drop(filler);
    let r = evs
        .iter()
        .find(|e| {
            is_after(e, "compile-retrying", &a, mark) || is_after(e, "compile-failed", &a, mark)
        })
        .unwrap()
        .clone();
    assert_eq!(r["event"], "compile-retrying", "{}", dump(&evs));
    assert!(
        r["reason"]
            .as_str()
            .unwrap_or("")
            .contains("Too many open files"),
        "{r}"
    );
    d.wait_for(
        "the compile after the retry",
        Duration::from_secs(30),
        |e| is_after(e, "compile-succeeded", &a, mark),
    );
    let src = read_string(&src_of(&a));
    assert!(src.contains(&ptp_with_x(777)), "{src}");
    d.stop(WAIT);
}
