//! The event stream as a protocol (issue 10, "Events"): over a long mixed run — many projects,
//! edits, files caught half-written, failures, reloads adding and removing projects, a
//! blackboard shared by an alias, a project without a blackboard, folders deleted and created
//! again, a root project forgotten and found again — every invariant a consumer relies on holds:
//!
//! - `seq` from 1 without gaps (nothing was dropped here);
//! - one `instance` (the run's identity) in every event;
//! - `started.config` is absolute;
//! - every `compile-started` gets exactly one outcome (`compile-succeeded`, `compile-failed`,
//!   `compile-retrying`) before the project's next `compile-started`, and every outcome has its
//!   `compile-started`; `write-back` belongs to the run that just succeeded;
//! - `run_id`s count 1, 2, 3, … per project, across reloads that drop and add it again; only a
//!   forgotten root project starts again at 1;
//! - the first run of a project added by a reload has trigger `reload`;
//! - every `watch-degraded` has a `backend`; after one with `backend: "none"` the folder's next
//!   `watching` says why it is watched again (`reason`), unless the project was forgotten
//!   (found again, it is a new project).

mod inproc;

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::Path;
use std::thread::sleep;
use std::time::{Duration, Instant};

use inproc::*;
use serde_json::Value;

/// What the checker counted, to show that the run exercised every kind of path.
#[derive(Debug, Default)]
struct Seen {
    runs: usize,
    succeeded: usize,
    failed: usize,
    retrying: usize,
    shared_blackboard: usize,
    no_blackboard: usize,
    reload_triggers: usize,
    retry_triggers: usize,
    forgotten: usize,
    came_back: usize,
}

#[derive(Default)]
struct ProjectState {
    last_run: u64,
    open: Option<u64>,
    last_succeeded: Option<u64>,
    /// Added by a reload: its next run must have trigger `reload`.
    reload_pending: bool,
}

/// Checks the invariants over a whole stream; panics with the stream and the broken rule.
fn check_invariants(evs: &[Value]) -> Seen {
    let fail = |i: usize, why: String| -> ! {
        let from = i.saturating_sub(40);
        panic!(
            "invariant broken at event {i}: {why}\n{}",
            dump(&evs[from..(i + 5).min(evs.len())])
        )
    };
    let mut seen = Seen::default();
    let mut projects: BTreeMap<String, ProjectState> = BTreeMap::new();
    let mut degraded: BTreeSet<String> = BTreeSet::new();
    // Projects whose last run was `compile-retrying`: the next run has trigger `retry`.
    let mut retrying: BTreeSet<String> = BTreeSet::new();
    for (i, e) in evs.iter().enumerate() {
        if seq(e) != i as u64 + 1 {
            fail(i, format!("seq {} at position {}", seq(e), i + 1));
        }
        if !e["instance"].is_string() || e["instance"] != evs[0]["instance"] {
            fail(
                i,
                format!(
                    "instance {} in a run of {}",
                    e["instance"], evs[0]["instance"]
                ),
            );
        }
        let name = e["event"].as_str().unwrap();
        let project = e["project"].as_str().map(str::to_owned);
        let folder = project
            .clone()
            .or_else(|| e["root"].as_str().map(str::to_owned));
        let st = project
            .as_ref()
            .map(|p| projects.entry(p.clone()).or_default());
        match name {
            "started" => {
                let config = e["config"].as_str().unwrap_or("/");
                if !Path::new(config).is_absolute() {
                    fail(i, format!("started.config {config:?} is not absolute"));
                }
            }
            "watch-degraded" => {
                if !e["backend"].is_string() {
                    fail(i, "watch-degraded without backend".into());
                }
                if e["backend"] == "none" {
                    degraded.insert(folder.clone().unwrap());
                }
                if e["reason"].as_str().unwrap().contains("forgotten") {
                    let st = st.unwrap();
                    if st.open.is_some() {
                        fail(i, "forgotten during a run".into());
                    }
                    *st = ProjectState::default();
                    retrying.remove(project.as_ref().unwrap());
                    // Found again later, it is a new project (its first `watching`).
                    degraded.remove(&folder.clone().unwrap());
                    seen.forgotten += 1;
                }
            }
            "watching" => {
                let f = folder.unwrap();
                if degraded.remove(&f) {
                    if !e["reason"].is_string() {
                        fail(
                            i,
                            format!("`watching` {f} after watch-degraded without a reason"),
                        );
                    }
                    seen.came_back += 1;
                }
            }
            "reloaded" => {
                for a in e["added"].as_array().unwrap() {
                    projects
                        .entry(a.as_str().unwrap().to_owned())
                        .or_default()
                        .reload_pending = true;
                }
                for r in e["removed"].as_array().unwrap() {
                    if let Some(st) = projects.get_mut(r.as_str().unwrap()) {
                        st.reload_pending = false;
                    }
                    // Its pending retry went with it: added again, its first run is `reload`.
                    retrying.remove(r.as_str().unwrap());
                }
            }
            "compile-started" => {
                let st = st.unwrap();
                let run = e["run_id"].as_u64().unwrap();
                if let Some(open) = st.open {
                    fail(i, format!("run {run} started while run {open} is open"));
                }
                if run != st.last_run + 1 {
                    fail(i, format!("run_id {run} after {}", st.last_run));
                }
                let trigger = e["trigger"].as_str().unwrap();
                if retrying.remove(project.as_ref().unwrap()) && trigger != "retry" {
                    fail(
                        i,
                        format!("the run after compile-retrying has trigger {trigger}"),
                    );
                }
                if st.reload_pending && trigger != "reload" {
                    fail(
                        i,
                        format!("first run after the reload has trigger {trigger}"),
                    );
                }
                seen.reload_triggers += usize::from(trigger == "reload");
                seen.retry_triggers += usize::from(trigger == "retry");
                st.reload_pending = false;
                st.last_run = run;
                st.open = Some(run);
                seen.runs += 1;
            }
            "compile-succeeded" | "compile-failed" | "compile-retrying" => {
                let st = st.unwrap();
                let run = e["run_id"].as_u64().unwrap();
                if st.open != Some(run) {
                    fail(i, format!("outcome of run {run}, open run {:?}", st.open));
                }
                st.open = None;
                st.last_succeeded = (name == "compile-succeeded").then_some(run);
                match name {
                    "compile-succeeded" => seen.succeeded += 1,
                    "compile-retrying" => {
                        seen.retrying += 1;
                        retrying.insert(project.clone().unwrap());
                    }
                    _ => {
                        seen.failed += 1;
                        let text = e.to_string();
                        seen.shared_blackboard += usize::from(text.contains("E701"));
                        seen.no_blackboard += usize::from(text.contains("no blackboard"));
                    }
                }
            }
            "write-back" => {
                let st = st.unwrap();
                let run = e["run_id"].as_u64().unwrap();
                if st.last_succeeded != Some(run) || st.open.is_some() {
                    fail(i, format!("write-back of run {run} not after its success"));
                }
            }
            _ => {}
        }
    }
    for (p, st) in &projects {
        assert!(st.open.is_none(), "{p}: run {:?} has no outcome", st.open);
    }
    seen
}

/// A tiny deterministic generator (the run is the same every time, timing aside).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self, n: usize) -> usize {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 33) % n as u64) as usize
    }
}

/// Waits until the stream has been quiet for `quiet` (bounded).
fn wait_quiet(d: &InProc, quiet: Duration, limit: Duration) {
    let deadline = Instant::now() + limit;
    let mut last = d.mark();
    let mut since = Instant::now();
    while Instant::now() < deadline {
        sleep(Duration::from_millis(50));
        let now = d.mark();
        if now != last {
            last = now;
            since = Instant::now();
        } else if since.elapsed() >= quiet {
            return;
        }
    }
}

fn config_text(explicit: &[&str]) -> String {
    let mut t = String::from(
        "forget_after_s = 1\n[[root]]\npath = \"root\"\n[[root]]\npath = \"later/root\"\n",
    );
    for p in explicit {
        t.push_str(&format!("[[project]]\npath = \"ws/{p}\"\n"));
    }
    t
}

#[test]
fn event_invariants_hold_over_a_long_mixed_run() {
    let w = Workspace::new();
    let names = ["P0", "P1", "P2", "P3", "P4"];
    let ps: Vec<_> = names.iter().map(|n| w.project(n)).collect();
    let root = w.root.join("root");
    for r in ["R0", "R1", "R2"] {
        copy_project(&root.join(r));
    }
    fs::create_dir(w.ws().join("Empty")).unwrap(); // no blackboard
    let late = w.ws().join("Late"); // missing until later
    std::os::unix::fs::symlink(&ps[0], w.ws().join("P0link")).unwrap();

    let mut explicit = vec!["P0", "P1", "P2", "P3", "P4", "Empty", "Late"];
    let cfg = w.config(&config_text(&explicit));
    let d = InProc::with_config(&cfg);
    d.startup(&[&ps[0], &ps[1], &ps[2], &ps[3], &ps[4]]);

    let mut rng = Lcg(10);
    let mut x = 1000;
    let edit = |p: &Path, x: u32| fs::write(p.join("sfc.xml"), sfc_with_x(x)).unwrap();
    let all_sfc = sfc_with_x(1);
    let cut = all_sfc.find("<transition localId=\"4\">").unwrap() + 5;
    for round in 0..6 {
        // Edits of a few projects.
        for _ in 0..3 {
            x += 1;
            edit(&ps[rng.next(ps.len())], x);
        }
        // A file caught half-written, completed a moment later.
        let p = &ps[rng.next(ps.len())];
        x += 1;
        let content = sfc_with_x(x);
        fs::write(p.join("sfc.xml"), &content.as_bytes()[..cut]).unwrap();
        sleep(Duration::from_millis(SETTLE_MS * 2));
        fs::write(p.join("sfc.xml"), &content).unwrap();
        // A failure, fixed in the next round.
        let broken = &ps[rng.next(ps.len())];
        fs::write(
            broken.join("sfc.xml"),
            sfc_with_x(x).replace("</SFC>", "</SFX>"),
        )
        .unwrap();
        sleep(Duration::from_millis(SETTLE_MS * 4));
        match round {
            0 => {
                // A reload adding a project and an alias of P0 (E701), removing P4.
                explicit.retain(|p| *p != "P4");
                explicit.push("P0link");
                copy_project(&w.ws().join("P5"));
                explicit.push("P5");
                fs::write(&cfg, config_text(&explicit)).unwrap();
                d.reload();
            }
            1 => {
                // A project folder deleted and created again.
                fs::remove_dir_all(&ps[1]).unwrap();
                sleep(Duration::from_millis(300));
                copy_project(&ps[1]);
            }
            2 => {
                // The missing folder appears; a new root project too; the missing root with a
                // project.
                copy_project(&late);
                copy_project(&root.join("R3"));
                copy_project(&w.root.join("later/root/L0"));
            }
            3 => {
                // A root project gone long enough to be forgotten, then back (a new project).
                fs::remove_dir_all(root.join("R0")).unwrap();
                let mark = d.mark();
                let r0 = root.join("R0");
                d.wait_for("R0 forgotten", Duration::from_secs(8), |e| {
                    seq(e) > mark
                        && is_for(e, "watch-degraded", &r0)
                        && e["reason"].as_str().unwrap().contains("forgotten")
                });
                copy_project(&r0);
            }
            4 => {
                // P4 back, the alias and P5 gone (P4's run_ids go on where they were).
                explicit.retain(|p| *p != "P0link" && *p != "P5");
                explicit.push("P4");
                fs::write(&cfg, config_text(&explicit)).unwrap();
                d.reload();
            }
            _ => {
                // An invalid configuration: reload-failed, nothing changes.
                fs::write(&cfg, "settle_ms = 0\n").unwrap();
                d.reload();
                sleep(Duration::from_millis(100));
                fs::write(&cfg, config_text(&explicit)).unwrap();
            }
        }
        // Fix the broken project.
        x += 1;
        edit(broken, x);
    }
    // Every project compiles one last edit, so the run ends in a known state.
    wait_quiet(&d, Duration::from_millis(1500), Duration::from_secs(20));
    let mark = d.mark();
    x += 1;
    for p in &ps {
        edit(p, x);
    }
    for p in &ps {
        d.wait_for(&format!("last edit of {}", p.display()), WAIT, |e| {
            is_after(e, "compile-succeeded", p, mark)
        });
    }
    wait_quiet(&d, Duration::from_millis(1000), Duration::from_secs(10));
    // The stop adds only `stopped`.
    let evs = d.events();
    d.stop(WAIT);
    let seen = check_invariants(&evs);
    eprintln!("{} events: {seen:?}", evs.len());
    assert!(seen.runs >= 40, "{seen:?}");
    assert!(seen.succeeded > 0 && seen.failed > 0, "{seen:?}");
    assert!(seen.retrying > 0 && seen.retry_triggers > 0, "{seen:?}");
    assert!(seen.shared_blackboard > 0, "{seen:?}");
    assert!(seen.no_blackboard > 0, "{seen:?}");
    assert!(seen.reload_triggers >= 2, "{seen:?}");
    assert!(seen.forgotten > 0 && seen.came_back >= 3, "{seen:?}");
    let later = w.root.join("later/root");
    let root_degraded = evs
        .iter()
        .find(|e| is(e, "watch-degraded") && e["root"] == later.to_str().unwrap())
        .unwrap_or_else(|| panic!("{}", dump(&evs)));
    assert_eq!(root_degraded["backend"], "none", "{root_degraded}");
    assert!(
        evs.iter()
            .any(|e| is_for(e, "compile-succeeded", &later.join("L0"))),
        "{}",
        dump(&evs)
    );
    for p in &ps {
        assert!(read_string(&src_of(p)).contains(&ptp_with_x(x)));
    }
}
