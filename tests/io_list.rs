//! Issue 38, item 3: the I/O list of each program (`<P>.io.csv`), through the binary on a
//! two-controller cell, and the deploy hook's `{io}` through the daemon.

mod inproc;

use std::collections::BTreeSet;
use std::fs;
use std::process::Command;
use std::time::Duration;

use inproc::{InProc, Workspace, is_for};

/// The rows of an I/O list: (direction, signal, number, partner, purpose).
fn rows(csv: &str) -> Vec<Vec<String>> {
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("direction,signal,number,address,type,partner,purpose")
    );
    lines
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect()
}

#[test]
fn each_program_of_a_cell_lists_its_wires_with_their_partner_and_every_signal_it_uses() {
    let w = Workspace::new();
    let p = w.ws().join("Cell");
    inproc::copy_fixture_layers(&p, &inproc::TWO_CONTROLLER_CELL);
    let o = Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["Blackboard.aml", "P"])
        .current_dir(&p)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    let (a, b) = ("P_KUKA_KR15_2", "P_KUKA_KR16_2");
    for prog in [a, b] {
        assert!(stdout.contains(&format!("wrote {prog}.io.csv")), "{stdout}");
    }
    let list = |prog: &str| rows(&fs::read_to_string(p.join(format!("{prog}.io.csv"))).unwrap());
    let (ra, rb) = (list(a), list(b));
    // A wire is on both lists, set by one program and read by the other, each naming the other.
    let wires = |r: &[Vec<String>], partner: &str| -> BTreeSet<(String, String)> {
        r.iter()
            .filter(|row| row[5] == partner)
            .map(|row| (row[0].clone(), row[6].clone()))
            .collect()
    };
    let from_a = wires(&ra, "KUKA KR16-2");
    let from_b = wires(&rb, "KUKA KR15-2");
    assert!(from_a.len() >= 5, "{ra:?}");
    assert_eq!(from_a.len(), from_b.len(), "{ra:?}\n{rb:?}");
    let outs_a = ra
        .iter()
        .filter(|r| r[0] == "out" && !r[5].is_empty())
        .count();
    let ins_b = rb
        .iter()
        .filter(|r| r[0] == "in" && !r[5].is_empty())
        .count();
    assert_eq!(outs_a, ins_b, "each wire A sets, B reads");
    for purpose in ["start barrier: run", "start barrier: ready"] {
        assert!(
            ra.iter().any(|r| r[0] == "out" && r[6] == purpose),
            "{ra:?}"
        );
        assert!(ra.iter().any(|r| r[0] == "in" && r[6] == purpose), "{ra:?}");
    }
    // Every signal the KRL program declares for its wires (`SIGNAL name $IN[n]`) is on its list
    // with that number and direction.
    for prog in [a, b] {
        let dat = fs::read_to_string(p.join(format!("{prog}.dat"))).unwrap();
        let r = list(prog);
        for l in dat
            .lines()
            .filter(|l| l.trim_start().starts_with("SIGNAL "))
        {
            let parts: Vec<&str> = l.split_whitespace().collect();
            let io = parts[2];
            let (dir, n) = if let Some(n) = io.strip_prefix("$IN[") {
                ("in", n.trim_end_matches(']'))
            } else {
                ("out", io.trim_start_matches("$OUT[").trim_end_matches(']'))
            };
            assert!(
                r.iter().any(|row| row[0] == dir && row[2] == n),
                "{prog}: `{l}` is not on the I/O list:\n{r:?}"
            );
        }
    }
    // The condition's signal (`More_Parts`) is read by the controller that decides.
    assert!(
        ra.iter()
            .chain(&rb)
            .any(|r| r[1] == "More_Parts" && r[6].starts_with("condition")),
        "{ra:?}\n{rb:?}"
    );
}

/// The hook's `{io}`: the daemon's copy of the I/O list, like the program's files; `{outputs}`
/// does not hold it.
#[test]
fn the_hook_gets_the_io_list_by_its_own_placeholder() {
    let w = Workspace::new();
    let p = w.project("P");
    let share = w.root.join("share");
    fs::create_dir(&share).unwrap();
    let cfg = w.config(&format!(
        "on_success = [\"sh\", \"-c\", \"cp \\\"$1\\\" \\\"$0/\\\"; shift; echo \\\"$@\\\" > \\\"$0/outputs\\\"\", \"{}\", \"{{io}}\", \"{{outputs}}\"]\n\
         [[project]]\npath = \"{}\"\n",
        share.display(),
        p.display()
    ));
    let d = InProc::with_config(&cfg);
    let evs = d.wait_for("the deploy", Duration::from_secs(10), |e| {
        is_for(e, "deploy-succeeded", &p) || is_for(e, "deploy-failed", &p)
    });
    assert!(
        evs.iter().any(|e| is_for(e, "deploy-succeeded", &p)),
        "{}",
        inproc::dump(&evs)
    );
    assert_eq!(
        fs::read(share.join("Blackboard.io.csv")).unwrap(),
        fs::read(p.join("Blackboard.io.csv")).unwrap()
    );
    let outputs = fs::read_to_string(share.join("outputs")).unwrap();
    assert!(outputs.contains("Blackboard.src") && outputs.contains("Blackboard.dat"));
    assert!(!outputs.contains("io.csv"), "{outputs}");
    let compiled = evs
        .iter()
        .find(|e| is_for(e, "compile-succeeded", &p))
        .unwrap();
    assert!(
        compiled["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .any(|o| o["path"].as_str().unwrap().ends_with("Blackboard.io.csv")),
        "{compiled}"
    );
}
