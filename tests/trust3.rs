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

fn skillpost(args: &[&str], cwd: &Path) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

/// Finding 12: `--svg` naming one of the program's own files is refused before anything is
/// written (before, the picture went over `P.src` and a failed write of the pair left it there).
#[test]
fn a_picture_named_like_a_program_file_is_refused_and_nothing_is_written() {
    let w = Workspace::new();
    let p = w.project("P");
    let before = fs::read_dir(&p).unwrap().count();
    let o = skillpost(&["--svg", "out.src", "Blackboard.aml", "out"], &p);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("error[E604]") && err.contains("--svg"),
        "{err}"
    );
    assert!(
        err.contains("out.svg"),
        "the message suggests a name: {err}"
    );
    assert_eq!(
        fs::read_dir(&p).unwrap().count(),
        before,
        "a file was written"
    );
}

/// Finding 12: when the programs cannot be written, neither is the picture, so "nothing was
/// written" is true.
#[test]
fn a_picture_is_not_written_when_the_programs_are_not() {
    let w = Workspace::new();
    let p = w.project("P");
    // The `.dat` cannot be written: a folder stands at its name.
    fs::create_dir(p.join("out.dat")).unwrap();
    let o = skillpost(&["--svg", "plan.svg", "Blackboard.aml", "out"], &p);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("nothing was written"), "{err}");
    assert!(
        !p.join("plan.svg").exists(),
        "the picture was written: {err}"
    );
    assert!(!p.join("out.src").exists());
    // And with the programs written, the picture is too.
    fs::remove_dir(p.join("out.dat")).unwrap();
    let o = skillpost(&["--svg", "plan.svg", "Blackboard.aml", "out"], &p);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains("wrote plan.svg"));
    assert!(
        fs::read_to_string(p.join("plan.svg"))
            .unwrap()
            .starts_with("<svg")
    );
}
