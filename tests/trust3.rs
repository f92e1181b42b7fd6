//! Issue 37 (Trust III): the attacks a fourth review found against the picture, the deploy hook
//! and the names of projects, each through the entry point a user uses: the binary or the
//! daemon in this process. (The hooks' descriptors and process trees, foreign locks and hook
//! programs are in tests/trust.rs and tests/daemon_deploy.rs; memory budgets in tests/cli.rs.)

#[path = "../benches/common/generator.rs"]
mod generator;
mod inproc;

use std::fs;
use std::path::Path;
use std::time::Duration;

use inproc::{InProc, Workspace, is_for};

/// Spins until `file` exists (at most `limit`), then replaces its folder `p` by a link to
/// `to` (`mv P P.real; ln -s OUT P`). Whether it swapped.
fn swap_when_it_lands(file: &Path, p: &Path, to: &Path, limit: Duration) -> bool {
    let deadline = std::time::Instant::now() + limit;
    while std::time::Instant::now() < deadline {
        if fs::symlink_metadata(file).is_ok() {
            fs::rename(p, p.with_extension("real")).unwrap();
            std::os::unix::fs::symlink(to, p).unwrap();
            return true;
        }
        std::thread::yield_now();
    }
    false
}

/// Finding 1: the project folder swapped for a link right after the program lands. The
/// picture goes where the programs went (the folder the inputs were read from, `P.real` now);
/// a file in the link's target is never replaced.
#[test]
fn the_picture_never_lands_in_a_folder_swapped_in_after_the_program() {
    let mut swapped_before_the_end = 0;
    for trial in 0..3 {
        let w = Workspace::new();
        let p = w.ws().join("P");
        let out = w.root.join("OUT");
        generator::write_project(&p, &generator::Spec::flat(20_000)).unwrap();
        fs::create_dir(&out).unwrap();
        fs::write(out.join("Blackboard.svg"), "a planner's file").unwrap();
        let cfg = w.config(&format!(
            "picture = true\n[[project]]\npath = \"{}\"\n",
            p.display()
        ));
        let (src, p2, out2) = (p.join("Blackboard.src"), p.clone(), out.clone());
        let swapper = std::thread::spawn(move || {
            swap_when_it_lands(&src, &p2, &out2, Duration::from_secs(60))
        });
        let d = InProc::with_config(&cfg);
        assert!(swapper.join().unwrap(), "trial {trial}: no program landed");
        let evs = d.wait_for("the first compile", Duration::from_secs(60), |e| {
            is_for(e, "compile-succeeded", &p) || is_for(e, "compile-failed", &p)
        });
        // The swap came before the compile's end (the picture is written after the programs).
        let done = evs
            .iter()
            .find(|e| is_for(e, "compile-succeeded", &p))
            .expect("the compile succeeded");
        let svg = done["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .any(|o| o["path"].as_str().is_some_and(|s| s.ends_with(".svg")));
        assert!(svg, "no picture among the outputs: {done}");
        if fs::symlink_metadata(p.with_extension("real").join("Blackboard.svg")).is_ok() {
            swapped_before_the_end += 1;
        }
        d.stop(Duration::from_secs(10));
        assert!(
            fs::read(out.join("Blackboard.svg")).unwrap() == b"a planner's file",
            "trial {trial}: the picture replaced a file in the folder the link leads to"
        );
        assert_eq!(
            fs::read_dir(&out).unwrap().count(),
            1,
            "trial {trial}: something was written into OUT"
        );
    }
    assert!(
        swapped_before_the_end > 0,
        "no trial swapped the folder before the picture was written"
    );
}
