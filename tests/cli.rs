//! The command line as a user runs it: modes, print options, formats, exit statuses.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_skillpost"))
}

fn sample() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ok/reference-sample")
}

/// A fresh copy of the reference sample.
fn project() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for e in std::fs::read_dir(sample()).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), dir.path().join(e.file_name())).unwrap();
        }
    }
    dir
}

fn run(args: &[&str], cwd: &Path) -> Output {
    bin().args(args).current_dir(cwd).output().unwrap()
}

fn stdout(o: &Output) -> String {
    String::from_utf8(o.stdout.clone()).unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8(o.stderr.clone()).unwrap()
}

/// A temporary copy of `fixtures/base/<base>` with the input files of `fixtures/ok/<case>` (those
/// it has) laid over it.
fn base_with_case(base: &str, case: &str) -> tempfile::TempDir {
    bases_with_case(&[base], case)
}

/// `fixtures/base/<each of bases>` in order, then `fixtures/ok/<case>` over them.
fn bases_with_case(bases: &[&str], case: &str) -> tempfile::TempDir {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let t = tempfile::tempdir().unwrap();
    let dirs = bases
        .iter()
        .map(|b| root.join("base").join(b))
        .chain([root.join("ok").join(case)]);
    for dir in dirs {
        for e in std::fs::read_dir(dir).unwrap() {
            let e = e.unwrap();
            let name = e.file_name();
            if name != "case.toml" && name != "README.txt" {
                std::fs::copy(e.path(), t.path().join(name)).unwrap();
            }
        }
    }
    t
}

#[test]
fn compile_writes_outputs_and_reports_them() {
    let p = project();
    let o = run(&["Blackboard.aml", "Demo_1"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = std::fs::read_to_string(p.path().join("Demo_1.src")).unwrap();
    assert!(src.contains("DEF Demo_1( )\r\n"));
    assert!(src.contains("SetVelCP (0.5)\r\n"));
    assert!(p.path().join("Demo_1.dat").exists());
    // The outcome is the run's result: on stdout.
    assert!(stdout(&o).contains("wrote"), "{}", stdout(&o));
    let bb = std::fs::read_to_string(p.path().join("Blackboard.aml")).unwrap();
    assert!(bb.contains("<Value>Demo_1.src</Value>"));
}

/// `SKILLPOST_TIMINGS=1` (docs/COMMAND-LINE.md): each stage's time and, on Linux, the
/// process's peak memory by then, the write last; the run itself is unchanged.
#[test]
fn timings_name_each_stage_its_time_and_the_peak_memory() {
    let p = project();
    let o = bin()
        .args(["Blackboard.aml", "Demo_1"])
        .current_dir(p.path())
        .env("SKILLPOST_TIMINGS", "1")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(p.path().join("Demo_1.src").exists());
    let err = stderr(&o);
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("timing: ")).collect();
    let stages: Vec<&str> = lines
        .iter()
        .map(|l| l["timing: ".len()..].split_whitespace().next().unwrap())
        .collect();
    for s in ["read-sfc", "plan", "bind", "emit", "check"] {
        assert!(stages.contains(&s), "{s} missing: {err}");
    }
    assert_eq!(stages.last(), Some(&"write"), "{err}");
    let mut last_peak = 0.0;
    for l in &lines {
        assert!(l.contains(" ms"), "{l}");
        if cfg!(target_os = "linux") {
            let (_, peak) = l.split_once(" peak ").unwrap_or_else(|| panic!("{l}"));
            let mib: f64 = peak
                .trim()
                .strip_suffix(" MiB")
                .unwrap()
                .trim()
                .parse()
                .unwrap();
            // A peak never goes down, and a compile takes more than a MiB.
            assert!(mib >= last_peak && mib > 1.0, "{l}");
            last_peak = mib;
        }
    }
    // Without the variable, no timing.
    let quiet = run(&["Blackboard.aml", "Demo_1"], p.path());
    assert!(!stderr(&quiet).contains("timing: "), "{}", stderr(&quiet));
}

#[test]
fn lf_option_writes_lf_only() {
    let p = project();
    let o = run(&["--lf", "Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = std::fs::read(p.path().join("out.src")).unwrap();
    assert!(!src.contains(&b'\r'));
    assert!(src.ends_with(b"END\n"));
}

#[test]
fn validate_writes_nothing_and_shows_warnings() {
    let p = project();
    let before = std::fs::read(p.path().join("Blackboard.aml")).unwrap();
    let o = run(&["--validate", "Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(0));
    assert!(!p.path().join("out.src").exists());
    assert!(!p.path().join("out.dat").exists());
    assert_eq!(
        std::fs::read(p.path().join("Blackboard.aml")).unwrap(),
        before
    );
    // The sample's steps carry a JointConfig variable no skill uses: a warning.
    let e = stderr(&o);
    assert!(e.contains("warning[W303]"), "{e}");
    assert!(stdout(&o).contains("Input validation successful!"), "{e}");
    // One warning per skill and unused variable, not one per step.
    assert_eq!(e.matches("warning[W303]").count(), 3, "{e}");
    assert!(
        e.contains(
            "variable `JointConfig` is not used by skill `Move PTP` (at 2 steps: localId 3, 6)"
        ),
        "{e}"
    );
}

#[test]
fn warnings_hidden_without_warn() {
    let p = project();
    let written = || {
        ["out.src", "out.dat", "Blackboard.aml"].map(|f| std::fs::read(p.path().join(f)).unwrap())
    };
    let o = run(&["Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(0));
    assert!(!stderr(&o).contains("W303"));
    let quiet = written();
    // The warnings are not even built without `--warn`: what is written is the same.
    let o = run(&["--warn", "Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(0));
    assert!(stderr(&o).contains("W303"));
    let shown = written();
    assert!(quiet == shown, "the outputs differ with --warn");
}

#[test]
fn print_order_and_flow() {
    let p = project();
    let o = run(
        &["--validate", "-pO", "-pF", "Blackboard.aml", "out"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0));
    let out = stdout(&o);
    // Execution order: branch heads left to right by x; equal x → document order (8 before 6).
    let order: Vec<&str> = out.lines().filter(|l| l.starts_with(" #")).collect();
    assert_eq!(order.len(), 5, "{out}");
    assert!(order[0].contains("(id=1)") && order[0].contains("Start"));
    assert!(order[1].contains("(id=3)"));
    assert!(order[2].contains("(id=8)") && order[2].contains("LIN"));
    assert!(order[3].contains("(id=6)"));
    assert!(order[4].contains("(id=12)") && order[4].contains("End"));
    // The flow: both branches start at 1.5 s; the block ends with the longer one (2 s).
    assert!(
        out.contains(
            "{\n | id=   8, [@1.5    +      2], LIN\n +\n | id=   6, [@1.5    +      1], P2P\n}"
        ),
        "{out}"
    );
    assert!(out.contains("id=  12, [@3.5    +      0], End"), "{out}");
    assert!(out.contains("total: 3.5 seconds"), "{out}");
    // Aligned with spaces, no tabs.
    assert!(!out.contains('\t'), "{out}");
    assert!(out.contains(" #3   (id=8)     LIN\n"), "{out}");
    assert!(out.contains(" #5   (id=12)    End\n"), "{out}");
    // -p0 is accepted for -pO.
    let o = run(&["--validate", "-p0", "Blackboard.aml", "out"], p.path());
    assert_eq!(
        stdout(&o).lines().filter(|l| l.starts_with(" #")).count(),
        5
    );
}

#[test]
fn print_blackboard_and_sfc() {
    let p = project();
    let o = run(
        &["--validate", "-pB", "-pS", "Blackboard.aml", "out"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0));
    let out = stdout(&o);
    assert!(out.contains("KUKA KR15-2"));
    assert!(out.contains("(Skill) Move PTP"));
    assert!(
        out.contains("-> SetToolPathVelocity (Velocity)   [order 0]"),
        "{out}"
    );
    assert!(out.contains("(Func)  SetToolPathVelocity"));
    assert!(
        out.contains("-> IRL-File:  kr15-2.irl   (command PTP)"),
        "{out}"
    );
    // Aligned with spaces: no tabs in any listing.
    assert!(!out.contains('\t'), "{out}");
    // One second, singular.
    assert!(out.contains("Duration:   1 second\n"), "{out}");
    assert!(out.contains("Duration:   1.5 seconds\n"), "{out}");
    assert!(out.contains("iwb, DemoProduct, 1, 2015-05-26T12:00:00"));
    assert!(out.contains("4 -> [ 5 ] -> 8, 6"), "{out}");
    assert!(
        out.contains("FRAME:              (List)     = [ 100, 200, 300, 0, 90, 0 ]"),
        "{out}"
    );
}

#[test]
fn sfc_mode_checks_the_sfc_alone() {
    let p = project();
    let o = run(&["--sfc", "-pO", "sfc.xml"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("(id=12)"));
    assert!(stdout(&o).contains("SFC validation successful!"));
    // A broken flow: exit 1, located.
    let sfc = std::fs::read_to_string(p.path().join("sfc.xml")).unwrap();
    std::fs::write(
        p.path().join("bad.xml"),
        sfc.replacen("refLocalId=\"2\"", "refLocalId=\"77\"", 1),
    )
    .unwrap();
    let o = run(&["--sfc", "--format", "short", "bad.xml"], p.path());
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.contains("bad.xml:31:58: error[E303]: refLocalId 77 names no element"),
        "{e}"
    );
}

#[test]
fn info_lists_skills_and_their_variables() {
    let o = run(&["--info"], &sample());
    assert_eq!(o.status.code(), Some(0));
    assert!(stdout(&o).starts_with("skillpost v"));
    let o = run(&["--info", "Blackboard.aml"], &sample());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("KUKA KR15-2"));
    let ptp = out.lines().find(|l| l.contains("Move PTP")).unwrap();
    assert!(ptp.contains("variables: Velocity, Frame"), "{out}");
    let lin = out.lines().find(|l| l.contains("Move LIN")).unwrap();
    assert!(lin.ends_with("variables: Frame"), "{out}");
}

#[test]
fn exit_status_two_for_usage_and_io() {
    let d = tempfile::tempdir().unwrap();
    assert_eq!(run(&[], d.path()).status.code(), Some(2));
    assert_eq!(run(&["only-one"], d.path()).status.code(), Some(2));
    assert_eq!(run(&["--bogus", "a", "b"], d.path()).status.code(), Some(2));
    assert_eq!(run(&["-pX", "a", "b"], d.path()).status.code(), Some(2));
    let o = run(&["missing.aml", "out"], d.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("missing.aml"), "{}", stderr(&o));
    assert_eq!(run(&["--help"], d.path()).status.code(), Some(0));
}

#[test]
fn output_folder_not_writable_is_an_io_failure() {
    // A blackboard whose folder holds a directory where the output file should go.
    let p = project();
    std::fs::create_dir(p.path().join("out.src")).unwrap();
    let before = std::fs::read(p.path().join("Blackboard.aml")).unwrap();
    let o = run(&["Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("out.src"), "{}", stderr(&o));
    // The write-back comes last and did not happen.
    assert_eq!(
        std::fs::read(p.path().join("Blackboard.aml")).unwrap(),
        before
    );
}

#[test]
fn json_format_is_one_object_per_line_on_stdout() {
    let p = project();
    let o = run(
        &["--format", "json", "--warn", "Blackboard.aml", "9bad"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(1));
    let lines: Vec<serde_json::Value> = stdout(&o)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let e = lines
        .iter()
        .find(|v| v["code"] == "E601")
        .expect("bad program name reported");
    assert_eq!(e["severity"], "error");
    assert!(e["message"].as_str().unwrap().contains("9bad"));
    // Warnings come along with --warn, located.
    let w = lines.iter().find(|v| v["code"] == "W303").unwrap();
    assert_eq!(w["severity"], "warning");
    assert!(w["file"].as_str().unwrap().ends_with("sfc.xml"));
    assert!(w["line"].as_u64().unwrap() > 0 && w["column"].as_u64().unwrap() > 0);
    assert!(!p.path().join("9bad.src").exists());
}

#[test]
fn user_template_replaces_the_builtin_one() {
    let p = project();
    let builtin =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("templates/krl.toml"))
            .unwrap();
    let mine = builtin.replace(
        "END\n{{definitions}}",
        "  PTP $H_POS ; home again\nEND\n{{definitions}}",
    );
    assert_ne!(mine, builtin);
    std::fs::write(p.path().join("mine.toml"), mine).unwrap();
    let o = run(
        &["--template", "mine.toml", "Blackboard.aml", "out"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = std::fs::read_to_string(p.path().join("out.src")).unwrap();
    assert!(
        src.contains("  PTP $H_POS ; home again\r\nEND\r\n"),
        "{src}"
    );
}

#[test]
fn refuri_naming_a_fifo_or_a_device_is_an_error_not_a_hang() {
    let p = project();
    let fifo = p.path().join("pipe.xml");
    let st = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(st.success());
    let bb = p.path().join("Blackboard.aml");
    let original = std::fs::read_to_string(&bb).unwrap();
    for target in ["pipe.xml", "/dev/zero"] {
        std::fs::write(
            &bb,
            original.replace(
                "<Value>sfc.xml</Value>",
                &format!("<Value>{target}</Value>"),
            ),
        )
        .unwrap();
        let t = std::time::Instant::now();
        let o = run(&["--format", "short", "Blackboard.aml", "out"], p.path());
        assert!(t.elapsed() < std::time::Duration::from_secs(5), "{target}");
        assert_eq!(o.status.code(), Some(1), "{target}: {}", stderr(&o));
        let e = stderr(&o);
        assert!(
            e.contains("error[E101]") && e.contains("not a regular file"),
            "{e}"
        );
        assert!(e.contains("Blackboard.aml:"), "located at the refURI: {e}");
        assert!(!p.path().join("out.src").exists());
    }
}

/// Hostile inputs: each a clear, located error (or a normal result), quickly, never a crash.
#[test]
fn hostile_inputs_give_clear_errors_quickly() {
    let p = project();
    let sfc_path = p.path().join("sfc.xml");
    let bb_path = p.path().join("Blackboard.aml");
    let sfc = std::fs::read_to_string(&sfc_path).unwrap();
    let bb = std::fs::read_to_string(&bb_path).unwrap();
    let check = |what: &str, code: Option<&str>| {
        let t = std::time::Instant::now();
        let o = run(&["--format", "short", "Blackboard.aml", "out"], p.path());
        assert!(
            t.elapsed() < std::time::Duration::from_secs(10),
            "{what}: too slow"
        );
        let e = stderr(&o);
        assert!(!e.contains("panicked"), "{what}: {e}");
        match code {
            Some(c) => {
                assert_eq!(o.status.code(), Some(1), "{what}: {e}");
                assert!(e.contains(&format!("error[{c}]")), "{what}: {e}");
            }
            None => assert!(matches!(o.status.code(), Some(0 | 1)), "{what}: {e}"),
        }
    };
    // 200,000 nested elements inside a step's addData: the readers do not recurse.
    let deep = format!("{}{}", "<x>".repeat(200_000), "</x>".repeat(200_000));
    std::fs::write(
        &sfc_path,
        sfc.replacen("<addData>", &format!("<addData>{deep}"), 1),
    )
    .unwrap();
    check("deep nesting", None);
    // A localId that does not fit in 64 bits.
    std::fs::write(
        &sfc_path,
        sfc.replacen("localId=\"3\"", "localId=\"99999999999999999999999\"", 1),
    )
    .unwrap();
    check("huge localId", Some("E302"));
    std::fs::write(&sfc_path, &sfc).unwrap();
    // A list index that does not fit in a machine word.
    std::fs::write(
        &bb_path,
        bb.replacen("<Value>0</Value>", "<Value>18446744073709551616</Value>", 1),
    )
    .unwrap();
    check("huge index", Some("E205"));
    // Billion laughs: a DTD is refused before any entity is expanded.
    let laughs = "<!DOCTYPE lolz [<!ENTITY lol \"lol\"><!ENTITY lol2 \"&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;\"><!ENTITY lol3 \"&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;\">]>";
    std::fs::write(&bb_path, bb.replacen("?>", &format!("?>{laughs}"), 1)).unwrap();
    check("billion laughs in the blackboard", Some("E102"));
    std::fs::write(&bb_path, &bb).unwrap();
    std::fs::write(&sfc_path, sfc.replacen("?>", &format!("?>{laughs}"), 1)).unwrap();
    check("billion laughs in the SFC", Some("E102"));
    // A list value nested beyond the limit.
    std::fs::write(
        &sfc_path,
        sfc.replacen(
            "Value=\"(100, 200, 300, 0, 90, 0)\"",
            &format!("Value=\"{}1{}\"", "(".repeat(10_000), ")".repeat(10_000)),
            1,
        ),
    )
    .unwrap();
    check("deep list", Some("E315"));
    // 50,000 initial steps with nothing between them: each would be a sequence of its own.
    let lone: String = (0..50_000)
        .map(|k| {
            format!(
                "<step localId=\"{}\" name=\"L{k}\" initialStep=\"true\"><position x=\"0\" y=\"0\"/></step>",
                900_000 + k
            )
        })
        .collect();
    std::fs::write(
        &sfc_path,
        sfc.replacen("</SFC>", &format!("{lone}</SFC>"), 1),
    )
    .unwrap();
    check("50,000 initial steps", Some("E307"));
}

#[test]
fn input_larger_than_the_limit_is_refused() {
    let p = project();
    let sfc_path = p.path().join("sfc.xml");
    let sfc = std::fs::read_to_string(&sfc_path).unwrap();
    let padding = format!("<!-- {} -->", "x".repeat(1_200_000));
    std::fs::write(&sfc_path, sfc.replacen("?>", &format!("?>{padding}"), 1)).unwrap();
    // Under the default limit (256 MiB) it compiles.
    let o = run(&["--validate", "Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // With a 1 MiB limit: a located error, nothing written.
    let o = run(
        &[
            "--max-file-size",
            "1",
            "--format",
            "short",
            "Blackboard.aml",
            "out",
        ],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.contains("error[E101]") && e.contains("limit of 1048576 bytes"),
        "{e}"
    );
    assert!(e.contains("Blackboard.aml:"), "located at the refURI: {e}");
    assert!(!p.path().join("out.src").exists());
}

#[test]
fn flow_listings_say_why_they_are_empty() {
    let p = project();
    // Two start steps: the flow cannot be planned.
    let sfc = std::fs::read_to_string(p.path().join("sfc.xml")).unwrap();
    let broken = sfc.replacen(
        "<connectionPointIn><connection refLocalId=\"2\"/></connectionPointIn>",
        "",
        1,
    );
    std::fs::write(p.path().join("sfc.xml"), broken).unwrap();
    let o = run(&["--sfc", "-pF", "-pO", "sfc.xml"], p.path());
    assert_eq!(o.status.code(), Some(1));
    let out = stdout(&o);
    assert!(
        out.contains("-pF: nothing to print: the SFC's flow has errors"),
        "{out}"
    );
    assert!(out.contains("-pO: nothing to print"), "{out}");
}

#[test]
fn info_reports_what_it_can() {
    let p = project();
    // No Process Sequence: an error for a compile, but `--info` does not need it.
    let bb = std::fs::read_to_string(p.path().join("Blackboard.aml")).unwrap();
    let cut = bb.replace("Name=\"Process Sequenz\"", "Name=\"Somewhere else\"");
    std::fs::write(p.path().join("Blackboard.aml"), cut).unwrap();
    let o = run(&["--info", "Blackboard.aml"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("Move PTP"), "{}", stdout(&o));
    assert!(stderr(&o).contains("E203"), "{}", stderr(&o));
}

#[test]
fn action_blocks_are_one_warning_per_chart() {
    let p = project();
    let sfc = std::fs::read_to_string(p.path().join("sfc.xml")).unwrap();
    let blocks = "<actionBlock localId=\"90\"><position x=\"0\" y=\"0\"/></actionBlock>\
                  <actionBlock><position x=\"0\" y=\"0\"/></actionBlock>\
                  <actionBlock localId=\"92\"><position x=\"0\" y=\"0\"/></actionBlock>";
    std::fs::write(
        p.path().join("sfc.xml"),
        sfc.replacen("</SFC>", &format!("{blocks}</SFC>"), 1),
    )
    .unwrap();
    let o = run(&["--sfc", "--format", "short", "sfc.xml"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let e = stderr(&o);
    assert_eq!(e.matches("W304").count(), 1, "{e}");
    assert!(
        e.contains(
            "3 action blocks ignored (localId 90, actionBlock no. 2 of the SFC body, localId 92)"
        ),
        "{e}"
    );
}

/// An SFC file with three POUs with SFC bodies (a function block first) and one without.
fn three_pous(dir: &Path) {
    let body = |start: &str| {
        format!(
            "<body><SFC><step localId=\"1\" name=\"{start}\" initialStep=\"true\"><position x=\"0\" y=\"0\"/></step>\
             <transition localId=\"2\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"1\"/></connectionPointIn></transition>\
             <step localId=\"3\" name=\"End\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"2\"/></connectionPointIn></step></SFC></body>"
        )
    };
    let text = format!(
        "<project><types><pous>\
         <pou name=\"Helper\" pouType=\"functionBlock\">{}</pou>\
         <pou name=\"NoChart\" pouType=\"program\"><body><ST/></body></pou>\
         <pou name=\"Main\" pouType=\"program\">{}</pou>\
         <pou name=\"Other\" pouType=\"program\">{}</pou>\
         </pous></types></project>",
        body("HelperStart"),
        body("MainStart"),
        body("OtherStart")
    );
    std::fs::write(dir.join("pous.xml"), text).unwrap();
}

#[test]
fn pou_choice() {
    let p = project();
    three_pous(p.path());
    let o = run(&["--sfc", "-pS", "--format", "short", "pous.xml"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("POU: Main"), "{}", stdout(&o));
    let e = stderr(&o);
    assert!(
        e.contains("W305")
            && e.contains(
                "3 POUs have an SFC body; `Main` is used (the first program), not `Helper`, `Other`"
            ),
        "{e}"
    );
    let o = run(
        &[
            "--sfc", "-pS", "--pou", "other", "--format", "short", "pous.xml",
        ],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("POU: Other"), "{}", stdout(&o));
    assert!(!stderr(&o).contains("W305"), "{}", stderr(&o));
    let o = run(
        &["--sfc", "--pou", "Nope", "--format", "short", "pous.xml"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains(
            "no POU named `Nope` with an SFC body; the POUs with one: `Helper`, `Main`, `Other`"
        ),
        "{}",
        stderr(&o)
    );
    // The blackboard's reference names the POU with a #fragment.
    let bb = std::fs::read_to_string(p.path().join("Blackboard.aml")).unwrap();
    std::fs::write(
        p.path().join("Blackboard.aml"),
        bb.replace("<Value>sfc.xml</Value>", "<Value>pous.xml#Helper</Value>"),
    )
    .unwrap();
    let o = run(&["--validate", "-pS", "Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("POU: Helper"), "{}", stdout(&o));
}

#[test]
fn no_sfc_body_names_the_pous_considered() {
    let p = project();
    std::fs::write(
        p.path().join("none.xml"),
        "<project><types><pous><pou name=\"A\" pouType=\"program\"><body><ST/></body></pou>\
         <pou name=\"B\" pouType=\"functionBlock\"><body><FBD/></body></pou></pous></types></project>",
    )
    .unwrap();
    let o = run(&["--sfc", "--format", "short", "none.xml"], p.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("none of the 2 POUs (`A`, `B`) has an SFC body"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn resources_below_grouping_elements_are_found() {
    let p = project();
    let bb = std::fs::read_to_string(p.path().join("Blackboard.aml")).unwrap();
    // Ressourcen/Building/Line/KUKA KR15-2, and an empty grouping element beside it.
    let open = "<InternalElement Name=\"KUKA KR15-2\"";
    let at = bb.find(open).unwrap();
    let close_at = bb[at..]
        .find("\n    </InternalElement>\n    <InternalElement Name=\"Process")
        .unwrap()
        + at;
    let nested = format!(
        "{}<InternalElement Name=\"Building\"><InternalElement Name=\"Line 1\">{}</InternalElement></InternalElement>{}",
        &bb[..at],
        &bb[at..close_at],
        &bb[close_at..]
    );
    std::fs::write(p.path().join("Blackboard.aml"), nested).unwrap();
    let o = run(&["--validate", "Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let o = run(&["--info", "Blackboard.aml"], p.path());
    assert!(stdout(&o).contains("KUKA KR15-2\n"), "{}", stdout(&o));
    assert!(!stdout(&o).contains("Building"), "{}", stdout(&o));
}

#[test]
fn branches_right_of_an_unconditional_one_are_never_taken() {
    let p = project();
    let sfc = "<project><types><pous><pou name=\"P\" pouType=\"program\"><body><SFC>\
        <step localId=\"1\" name=\"Start\" initialStep=\"true\"><position x=\"0\" y=\"0\"/></step>\
        <selectionDivergence localId=\"2\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"1\"/></connectionPointIn></selectionDivergence>\
        <transition localId=\"3\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"2\"/></connectionPointIn><condition><inline name=\"\"><ST>a</ST></inline></condition></transition>\
        <transition localId=\"4\"><position x=\"10\" y=\"0\"/><connectionPointIn><connection refLocalId=\"2\"/></connectionPointIn></transition>\
        <transition localId=\"5\"><position x=\"20\" y=\"0\"/><connectionPointIn><connection refLocalId=\"2\"/></connectionPointIn><condition><inline name=\"\"><ST>b</ST></inline></condition></transition>\
        <selectionConvergence localId=\"6\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"3\"/><connection refLocalId=\"4\"/><connection refLocalId=\"5\"/></connectionPointIn></selectionConvergence>\
        <step localId=\"7\" name=\"End\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"6\"/></connectionPointIn></step>\
        </SFC></body></pou></pous></types></project>";
    std::fs::write(p.path().join("sel.xml"), sfc).unwrap();
    let o = run(&["--sfc", "--format", "short", "sel.xml"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let e = stderr(&o);
    assert_eq!(e.matches("W306").count(), 1, "{e}");
    assert!(
        e.contains("[localId 5]") && e.contains("transition localId 4"),
        "{e}"
    );
}

/// A KRL program of a cell calls the routines of its handshakes (`skp_stop`, `skp_show`, …),
/// written where the template says `{{definitions}}`: a template without that line is `E603`,
/// and no program of the cell is written.
#[test]
fn a_template_without_definitions_cannot_take_a_cells_routines() {
    let p = bases_with_case(&["cell", "cell2"], "cell-two-robots-weld");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let krl = std::fs::read_to_string(root.join("templates/krl.toml")).unwrap();
    std::fs::write(p.path().join("t.toml"), &krl).unwrap();
    let o = run(
        &["--template", "t.toml", "Blackboard.aml", "Cell"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = std::fs::read_to_string(p.path().join("Cell_KUKA_KR15_2.src")).unwrap();
    assert!(src.contains("\r\nDEF skp_stop(nr:IN)\r\n"), "{src}");
    for f in ["Cell_KUKA_KR15_2.src", "Cell_KUKA_KR16_2.src"] {
        std::fs::remove_file(p.path().join(f)).unwrap();
    }
    std::fs::write(
        p.path().join("t.toml"),
        krl.replace("{{definitions}}\n", ""),
    )
    .unwrap();
    let o = run(
        &[
            "--format",
            "short",
            "--template",
            "t.toml",
            "Blackboard.aml",
            "Cell",
        ],
        p.path(),
    );
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("E603") && e.contains("`{{definitions}}`"), "{e}");
    for f in ["Cell_KUKA_KR15_2.src", "Cell_KUKA_KR16_2.src"] {
        assert!(!p.path().join(f).exists(), "{f}");
    }
}

#[test]
fn a_template_without_declarations_cannot_take_them() {
    // The two-way selection needs the SKP_BRANCH variable in the .dat.
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    for from in [
        root.join("base/flow"),
        root.join("ok/flow-selection-two-way"),
    ] {
        for e in std::fs::read_dir(from).unwrap() {
            let e = e.unwrap();
            std::fs::copy(e.path(), dir.path().join(e.file_name())).unwrap();
        }
    }
    let template = std::fs::read_to_string(root.join("../templates/krl.toml"))
        .unwrap()
        .replace("{{declarations}}\n", "");
    std::fs::write(dir.path().join("t.toml"), template).unwrap();
    let o = run(
        &[
            "--format",
            "short",
            "--template",
            "t.toml",
            "Blackboard.aml",
            "out",
        ],
        dir.path(),
    );
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("E603")
            && e.contains("DECL INT SKP_BRANCH=0")
            && e.contains("`{{declarations}}`"),
        "{e}"
    );
    assert!(!dir.path().join("out.src").exists());
}

#[test]
fn sfc_check_reports_what_the_literals_tell() {
    let p = project();
    let sfc = std::fs::read_to_string(p.path().join("sfc.xml")).unwrap();
    std::fs::write(
        p.path().join("sfc.xml"),
        sfc.replacen(
            "<xhtml:p>TRUE</xhtml:p>",
            "<xhtml:p>Part_OK AND 3</xhtml:p>",
            1,
        ),
    )
    .unwrap();
    let o = run(&["--sfc", "--format", "short", "sfc.xml"], p.path());
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.contains("E316") && e.contains("`AND` needs a boolean"),
        "{e}"
    );
    // Names alone are not resolved without a blackboard.
    std::fs::write(
        p.path().join("sfc.xml"),
        sfc.replacen(
            "<xhtml:p>TRUE</xhtml:p>",
            "<xhtml:p>Part_OK AND NOT Unknown</xhtml:p>",
            1,
        ),
    )
    .unwrap();
    let o = run(&["--sfc", "sfc.xml"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

#[test]
fn validate_needs_no_program_name() {
    let p = project();
    let before = std::fs::read(p.path().join("Blackboard.aml")).unwrap();
    let o = run(&["--validate", "-pO", "Blackboard.aml"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let (out, err) = (stdout(&o), stderr(&o));
    assert!(out.contains("Input validation successful!"), "{out}");
    assert!(out.contains("(id=12)"), "listings work: {out}");
    assert!(err.contains("warning[W303]"), "{err}");
    assert!(!err.contains("E601"), "{err}");
    // Nothing written: the folder holds what it held, the blackboard is unchanged.
    let names: Vec<_> = std::fs::read_dir(p.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert!(
        !names.iter().any(|n| n.to_string_lossy().ends_with(".src")),
        "{names:?}"
    );
    assert_eq!(
        std::fs::read(p.path().join("Blackboard.aml")).unwrap(),
        before
    );
    // The template is still read (the code is generated to be checked): a missing one is exit 2.
    let o = run(
        &["--validate", "--template", "nope.toml", "Blackboard.aml"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    // Without --validate the name is needed; --validate takes at most two arguments.
    assert_eq!(run(&["Blackboard.aml"], p.path()).status.code(), Some(2));
    let o = run(&["--validate", "Blackboard.aml", "a", "b"], p.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("--validate takes a blackboard"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn missing_or_unreadable_template_is_exit_two() {
    let p = project();
    let o = run(
        &["--template", "missing.toml", "Blackboard.aml", "out"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("missing.toml"), "{}", stderr(&o));
    assert!(!p.path().join("out.src").exists());
    // A folder named as the template: unreadable too.
    std::fs::create_dir(p.path().join("tpl")).unwrap();
    let o = run(&["--template", "tpl", "Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let o = run(
        &["--validate", "--template", "missing.toml", "Blackboard.aml"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    // A readable template with errors stays an input error (1).
    std::fs::write(p.path().join("bad.toml"), "this is = = not toml").unwrap();
    let o = run(
        &["--template", "bad.toml", "Blackboard.aml", "out"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
}

/// A copy of the reference sample without its write-back target (the `Code` element renamed).
fn project_without_write_back() -> tempfile::TempDir {
    let p = project();
    let bb = std::fs::read_to_string(p.path().join("Blackboard.aml")).unwrap();
    let bb = bb.replace(
        "<InternalElement Name=\"Code\"",
        "<InternalElement Name=\"Notes\"",
    );
    std::fs::write(p.path().join("Blackboard.aml"), bb).unwrap();
    p
}

#[test]
fn no_write_back_target_is_said_on_stdout() {
    let p = project_without_write_back();
    let before = std::fs::read(p.path().join("Blackboard.aml")).unwrap();
    let o = run(&["Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(
        out.contains("blackboard not updated: Blackboard.aml: no write-back target"),
        "{out}"
    );
    assert!(!stderr(&o).contains("W204"), "a warning only with --warn");
    assert_eq!(
        std::fs::read(p.path().join("Blackboard.aml")).unwrap(),
        before
    );
    // JSON: stdout stays JSON Lines; the notice is an object.
    let o = run(&["--format", "json", "Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let lines: Vec<serde_json::Value> = stdout(&o)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect();
    assert_eq!(
        lines,
        [serde_json::json!({
            "outcome": "blackboard-not-updated",
            "blackboard": "Blackboard.aml",
            "cause": "no-target",
            "reason": "no write-back target (Code -> KRL code -> refURI; W204 with --warn shows where)"
        })]
    );
    // With a target, no such line.
    let p = project();
    let o = run(&["Blackboard.aml", "out"], p.path());
    assert!(!stdout(&o).contains("not updated"), "{}", stdout(&o));
    // A write-back that is skipped says so too: a hard-linked blackboard is not split.
    std::fs::hard_link(p.path().join("Blackboard.aml"), p.path().join("Other.aml")).unwrap();
    let o = run(&["Blackboard.aml", "again"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(
        out.contains("blackboard not updated: Blackboard.aml: it has several names (hard links)"),
        "{out}"
    );
    assert!(out.contains("(`again.src` not written)"), "{out}");
    let o = run(&["--format", "json", "Blackboard.aml", "again"], p.path());
    let lines: Vec<serde_json::Value> = stdout(&o)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 1, "{lines:?}");
    assert_eq!(lines[0]["cause"], "hard-linked");
    assert_eq!(lines[0]["value"], "again.src");
}

#[test]
fn blackboard_given_with_leading_parents_from_a_subfolder() {
    // tmp/p holds the project; the user runs from tmp/x/y.
    let tmp = tempfile::tempdir().unwrap();
    let p = project();
    std::fs::create_dir(tmp.path().join("p")).unwrap();
    for e in std::fs::read_dir(p.path()).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), tmp.path().join("p").join(e.file_name())).unwrap();
    }
    let cwd = tmp.path().join("x/y");
    std::fs::create_dir_all(&cwd).unwrap();
    let o = run(&["--validate", "../../p/Blackboard.aml"], &cwd);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let o = run(&["../../p/Blackboard.aml", "Up"], &cwd);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(tmp.path().join("p/Up.src").exists());
    assert!(
        stdout(&o).contains("wrote ../../p/Up.src"),
        "{}",
        stdout(&o)
    );
    // An IRL file named with leading `..` from the blackboard's folder.
    std::fs::create_dir(tmp.path().join("lib")).unwrap();
    std::fs::rename(
        tmp.path().join("p/kr15-2.irl"),
        tmp.path().join("lib/kr15-2.irl"),
    )
    .unwrap();
    let bb = std::fs::read_to_string(tmp.path().join("p/Blackboard.aml")).unwrap();
    std::fs::write(
        tmp.path().join("p/Blackboard.aml"),
        bb.replace(
            "<Value>kr15-2.irl</Value>",
            "<Value>../lib/kr15-2.irl</Value>",
        ),
    )
    .unwrap();
    let o = run(&["--validate", "../../p/Blackboard.aml"], &cwd);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

/// Every stdout line of a `--format json` run, parsed (each must be one JSON object).
fn json_lines(o: &Output) -> Vec<serde_json::Value> {
    stdout(o)
        .lines()
        .map(|l| {
            let v: serde_json::Value =
                serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}"));
            assert!(v.is_object(), "{l}");
            v
        })
        .collect()
}

fn listing<'a>(lines: &'a [serde_json::Value], name: &str) -> &'a serde_json::Value {
    lines
        .iter()
        .find(|l| l["listing"] == name)
        .unwrap_or_else(|| panic!("no {name} listing in {lines:?}"))
}

#[test]
fn json_format_prints_listings_as_objects() {
    let p = project();
    let o = run(
        &[
            "--validate",
            "--format",
            "json",
            "-pB",
            "-pS",
            "-pF",
            "-pO",
            "Blackboard.aml",
        ],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let lines = json_lines(&o);
    // Listings and diagnostics mixed, each saying what it is.
    assert!(
        lines
            .iter()
            .all(|l| l.get("listing").is_some() || l.get("severity").is_some())
    );
    assert!(lines.iter().any(|l| l["code"] == "W303"), "{lines:?}");
    assert_eq!(
        lines.iter().filter(|l| l.get("listing").is_some()).count(),
        4
    );

    let bb = listing(&lines, "blackboard");
    let r = &bb["resources"][0];
    assert_eq!(r["name"], "KUKA KR15-2");
    let ptp = r["skills"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == "Move PTP")
        .unwrap();
    assert_eq!(
        ptp["calls"][0],
        serde_json::json!({"function": "SetToolPathVelocity", "arguments": ["Velocity"], "order": 0})
    );
    let f = r["functions"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["name"] == "SetToolPathVelocity")
        .unwrap();
    assert_eq!(f["irl"], "kr15-2.irl");
    assert!(r["signals"].is_array());

    let sfc = listing(&lines, "sfc");
    assert_eq!(sfc["header"]["company_name"], "iwb");
    assert!(sfc["pou"].is_string());
    let objects = sfc["objects"].as_array().unwrap();
    let five = objects.iter().find(|o| o["local_id"] == 5).unwrap();
    assert_eq!(five["inputs"], serde_json::json!([4]));
    assert_eq!(five["outputs"], serde_json::json!([8, 6]));
    let step = objects
        .iter()
        .find(|o| o["kind"] == "step" && o["variables"].as_array().is_some_and(|v| !v.is_empty()))
        .unwrap();
    assert!(step["variables"][0]["value"].is_array() || step["variables"][0]["value"].is_string());
    assert!(
        objects
            .iter()
            .any(|o| o["kind"] == "transition" && o["condition"].is_string())
    );

    // The flow: both simultaneous branches start at 1.5 s, the block ends with the longer (3.5).
    let flow = listing(&lines, "flow");
    assert_eq!(flow["total"]["seconds"], 3.5);
    let par = flow["blocks"]
        .as_array()
        .unwrap()
        .iter()
        .find(|b| b["kind"] == "parallel")
        .unwrap();
    assert_eq!(par["start"], 1.5);
    assert_eq!(par["end"], 3.5);
    assert_eq!(par["branches"][0]["blocks"][0]["local_id"], 8);
    assert_eq!(par["branches"][0]["blocks"][0]["duration"], 2.0);
    assert_eq!(par["branches"][1]["blocks"][0]["start"], 1.5);

    let order = listing(&lines, "order");
    assert_eq!(order["steps"], 5);
    let ids: Vec<_> = order["blocks"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|b| b["kind"] == "step")
        .map(|b| {
            (
                b["number"].as_u64().unwrap(),
                b["local_id"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(ids, [(1, 1), (2, 3), (3, 8), (4, 6), (5, 12)]);

    // Human mode is unchanged: text, not JSON.
    let o = run(&["--validate", "-pO", "Blackboard.aml"], p.path());
    assert!(stdout(&o).contains(" #1"), "{}", stdout(&o));
}

#[test]
fn json_listings_of_a_loop_and_of_a_broken_flow() {
    let d = base_with_case("flow", "flow-loop-exit");
    let o = run(
        &[
            "--validate",
            "--format",
            "json",
            "-pF",
            "-pO",
            "Blackboard.aml",
        ],
        d.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let lines = json_lines(&o);
    let flow = listing(&lines, "flow");
    let lp = flow["blocks"]
        .as_array()
        .unwrap()
        .iter()
        .find(|b| b["kind"] == "loop")
        .unwrap();
    assert_eq!(lp["endless"], false);
    let sel = lp["blocks"]
        .as_array()
        .unwrap()
        .iter()
        .find(|b| b["kind"] == "selection")
        .unwrap();
    assert_eq!(sel["branches"][0]["then"], "repeat");
    assert_eq!(sel["branches"][1]["then"], "leave");
    assert_eq!(sel["branches"][1]["condition"], "Magazine_Empty");
    assert_eq!(flow["total"]["at_least"], true);
    assert_eq!(flow["total"]["longest_alternative"], true);
    assert!(listing(&lines, "order")["blocks"].is_array());

    // --sfc with a flow that cannot be planned: the listings say so, as objects.
    let p = project();
    let sfc = std::fs::read_to_string(p.path().join("sfc.xml")).unwrap();
    let broken = sfc.replacen(
        "<connectionPointIn><connection refLocalId=\"2\"/></connectionPointIn>",
        "",
        1,
    );
    std::fs::write(p.path().join("sfc.xml"), broken).unwrap();
    let o = run(
        &["--sfc", "--format", "json", "-pS", "-pF", "-pO", "sfc.xml"],
        p.path(),
    );
    assert_eq!(o.status.code(), Some(1));
    let lines = json_lines(&o);
    assert_eq!(listing(&lines, "flow")["available"], false);
    assert_eq!(
        listing(&lines, "order")["reason"],
        "the SFC's flow has errors"
    );
    assert!(listing(&lines, "sfc")["objects"].is_array());
    assert!(lines.iter().any(|l| l["severity"] == "error"));
}

#[test]
fn help_names_the_arguments() {
    let d = tempfile::tempdir().unwrap();
    let o = run(&["--help"], d.path());
    assert_eq!(o.status.code(), Some(0));
    let h = stdout(&o);
    assert!(
        h.contains("Usage: skillpost [OPTIONS] <BLACKBOARD> <PROGRAM>"),
        "{h}"
    );
    assert!(
        h.contains("skillpost --validate [OPTIONS] <BLACKBOARD> [<PROGRAM>]"),
        "{h}"
    );
    assert!(h.contains("[BLACKBOARD]") && h.contains("[PROGRAM]"), "{h}");
    assert!(!h.contains("FILES"), "{h}");
    // More arguments than the mode takes: our usage error, exit 2.
    let o = run(&["a.aml", "P", "extra"], d.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("expected a blackboard and a program name"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn one_second_is_singular_in_the_flow_total() {
    let d = project();
    // Every step 0 s except one of 1 s.
    let sfc = std::fs::read_to_string(d.path().join("sfc.xml")).unwrap();
    let mut n = 0;
    let sfc = regex_free_replace_durations(&sfc, &mut n);
    std::fs::write(d.path().join("sfc.xml"), sfc).unwrap();
    let o = run(&["--sfc", "-pF", "sfc.xml"], d.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("total: 1 second\n"), "{}", stdout(&o));
}

/// Sets the first `duration="…"` to 1 and every other to 0.
fn regex_free_replace_durations(s: &str, n: &mut usize) -> String {
    let mut out = String::new();
    let mut rest = s;
    while let Some(i) = rest.find("duration=\"") {
        out.push_str(&rest[..i + 10]);
        rest = &rest[i + 10..];
        let j = rest.find('"').unwrap();
        out.push_str(if *n == 0 { "1" } else { "0" });
        *n += 1;
        rest = &rest[j..];
    }
    out.push_str(rest);
    out
}

/// A fresh copy of a fixture base (`fixtures/base/<name>`: `abb`, `ur`).
fn cell(name: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let from = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/base")
        .join(name);
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), dir.path().join(e.file_name())).unwrap();
    }
    dir
}

#[test]
fn listings_show_each_resources_language_and_where_it_comes_from() {
    // The ABB cell says RAPID in its resource; the UR cell only in its IRL file.
    let abb = cell("abb");
    let o = run(&["--validate", "-pB", "Cell.aml", "P"], abb.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("(Language) RAPID (Language attribute)"),
        "{}",
        stdout(&o)
    );
    let ur = cell("ur");
    let o = run(&["--validate", "-pB", "Cell.aml", "P"], ur.path());
    assert!(
        stdout(&o).contains("(Language) URScript (IRL files, else the default)"),
        "{}",
        stdout(&o)
    );
    let o = run(
        &["--format", "json", "--validate", "-pB", "Cell.aml", "P"],
        ur.path(),
    );
    let listing: serde_json::Value = stdout(&o)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .find(|v| v["listing"] == "blackboard")
        .unwrap();
    assert_eq!(listing["resources"][0]["language"], "URScript");
    // --info reads only the blackboard: the attribute, or where the language will come from.
    let o = run(&["--info", "Cell.aml"], abb.path());
    assert!(
        stdout(&o).contains("  language RAPID (Language attribute)"),
        "{}",
        stdout(&o)
    );
    let o = run(&["--info", "Cell.aml"], ur.path());
    assert!(
        stdout(&o).contains("  language KRL unless its IRL files say otherwise"),
        "{}",
        stdout(&o)
    );
    let o = run(&["--info"], ur.path());
    assert!(stdout(&o).contains("ABB RAPID (.mod)"), "{}", stdout(&o));
}

#[test]
fn a_rapid_program_writes_one_module_and_refuses_a_krl_template() {
    let abb = cell("abb");
    let o = run(&["Cell.aml", "Palletize"], abb.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("wrote Palletize.mod"), "{}", stdout(&o));
    assert!(!abb.path().join("Palletize.src").exists());
    // CRLF by default, LF with --lf, as for KRL.
    let m = std::fs::read_to_string(abb.path().join("Palletize.mod")).unwrap();
    assert!(m.starts_with("MODULE Palletize\r\n"), "{m}");
    let o = run(&["--lf", "Cell.aml", "Palletize"], abb.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let m = std::fs::read_to_string(abb.path().join("Palletize.mod")).unwrap();
    assert!(
        m.starts_with("MODULE Palletize\n") && !m.contains('\r'),
        "{m}"
    );
    // A KRL template for a RAPID program is a located error, and nothing is written.
    let krl = Path::new(env!("CARGO_MANIFEST_DIR")).join("templates/krl.toml");
    std::fs::copy(krl, abb.path().join("krl.toml")).unwrap();
    let before = std::fs::read(abb.path().join("Palletize.mod")).unwrap();
    let o = run(
        &["--template", "krl.toml", "Cell.aml", "Palletize"],
        abb.path(),
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("E603"), "{}", stderr(&o));
    assert!(stderr(&o).contains("another language"), "{}", stderr(&o));
    assert_eq!(
        std::fs::read(abb.path().join("Palletize.mod")).unwrap(),
        before
    );
}

/// Issue 25, items 1 and 2: a gripper mounted on the robot (or naming it in `Controller`) runs
/// on the robot's controller: one program holds both resources' steps, and `-pB` says which
/// controller runs each resource (text and JSON).
#[test]
fn a_robot_and_its_gripper_make_one_program() {
    for (case, how) in [
        ("cell-robot-gripper", "mounted on it"),
        (
            "cell-gripper-controller-attribute",
            "its Controller attribute",
        ),
    ] {
        let t = base_with_case("cell", case);
        let o = run(&["Blackboard.aml", "Cell"], t.path());
        assert_eq!(o.status.code(), Some(0), "{case}: {}", stderr(&o));
        let src = std::fs::read_to_string(t.path().join("Cell.src")).unwrap();
        assert!(
            src.contains("GripClose (40)") && src.contains("LIN XLIN"),
            "{case}: {src}"
        );
        let dat = std::fs::read_to_string(t.path().join("Cell.dat")).unwrap();
        assert!(dat.contains("DECL E6POS XLIN={X 8, "), "{case}: {dat}");
        let o = run(&["--validate", "-pB", "Blackboard.aml"], t.path());
        assert!(
            stdout(&o).contains(&format!("(Controller) runs on KUKA KR15-2 ({how})")),
            "{case}: {}",
            stdout(&o)
        );
        let o = run(
            &["--validate", "-pB", "--format", "json", "Blackboard.aml"],
            t.path(),
        );
        let listing = stdout(&o)
            .lines()
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
            .find(|v| v["resources"].is_array())
            .unwrap_or_else(|| panic!("{case}: no -pB object: {}", stdout(&o)));
        let gripper = listing["resources"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["name"] == "Greifer G1")
            .unwrap();
        assert_eq!(gripper["controller"], "KUKA KR15-2", "{case}");
    }
}

/// Issue 25, item 4 (the wires' reading): InternalLinks between an Output of one controller and
/// an Input of another are wires, listed by `-pB` in text and JSON; a link to something that is
/// no signal is none.
#[test]
fn wires_between_controllers_are_listed() {
    let t = base_with_case("cell", "cell-two-robots-wired");
    let o = run(&["--validate", "-pB", "Blackboard.aml"], t.path());
    let text = stdout(&o);
    let wires: Vec<&str> = text.lines().filter(|l| l.starts_with("(Wire)")).collect();
    assert_eq!(
        wires,
        [
            "(Wire) KUKA KR15-2: Done_A -> KUKA KR16-2: Go_B   (InternalLink A done to B)",
            "(Wire) KUKA KR16-2: Done_B -> KUKA KR15-2: Go_A   (InternalLink B done to A)",
        ],
        "{text}"
    );
    let o = run(
        &["--validate", "-pB", "--format", "json", "Blackboard.aml"],
        t.path(),
    );
    let listing = stdout(&o)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .find(|v| v["listing"] == "blackboard")
        .unwrap();
    assert_eq!(listing["wires"].as_array().unwrap().len(), 2);
    assert_eq!(listing["wires"][0]["from"]["signal"], "Done_A");
    assert_eq!(listing["wires"][0]["to"]["controller"], "KUKA KR16-2");
}

/// Issue 25, item 6: a cell's listings. `-pO` lists each program's order with its handshakes;
/// `-pF` one lane per controller with the waits between them and the cell's time; both as JSON.
#[test]
fn a_cells_listings_show_each_program_and_the_lanes() {
    let t = bases_with_case(&["cell", "abb", "ur", "mixed"], "cell-kuka-abb-ur");
    // -pB says what each wire the handshakes use does; a spare wire is only a wire.
    let o = run(&["-pB", "Blackboard.aml", "Mix"], t.path());
    let text = stdout(&o);
    assert!(
        text.contains("(Wire) KUKA KR15-2: To_ABB_1 -> ABB IRB 1200: From_KUKA_1   (InternalLink KUKA to ABB 1, handshake: strobe of KUKA KR15-2 -> ABB IRB 1200)"),
        "{text}"
    );
    // The start barrier's and the restart check's wires, each way.
    for line in [
        "(Wire) UR10e: To_ABB_2 -> ABB IRB 1200: From_UR_2   (InternalLink UR to ABB 2, handshake: run of UR10e -> ABB IRB 1200 (start barrier, restart check))\n",
        "(Wire) UR10e: To_ABB_3 -> ABB IRB 1200: From_UR_3   (InternalLink UR to ABB 3, handshake: ready of UR10e -> ABB IRB 1200 (start barrier))\n",
        "(Wire) ABB IRB 1200: To_UR_3 -> UR10e: From_ABB_3   (InternalLink ABB to UR 3, handshake: run of ABB IRB 1200 -> UR10e (start barrier, restart check))\n",
    ] {
        assert!(text.contains(line), "{line}\n{text}");
    }
    assert!(
        text.contains(
            "(Wire) UR10e: To_ABB_4 -> ABB IRB 1200: From_UR_4   (InternalLink UR to ABB 4)\n"
        ),
        "{text}"
    );
    let o = run(&["-pO", "Blackboard.aml", "Mix"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = stdout(&o);
    let ur: Vec<&str> = text
        .lines()
        .skip_while(|l| !l.starts_with("program Mix_UR10e"))
        .take_while(|l| !l.starts_with("unchanged") && !l.starts_with("wrote"))
        .filter(|l| !l.trim().is_empty())
        .collect();
    assert_eq!(
        ur,
        [
            "program Mix_UR10e (controller UR10e):",
            "  selection (id=8): wait for ABB IRB 1200: the branch it takes",
            "   1. if Part_Present",
            "      #1   (id=11)    Place",
            "      #2   (id=13)    Release",
            "   2. if NOT Part_Present",
        ],
        "{text}"
    );
    assert!(
        text.contains("  wait for KUKA KR15-2: step Grip (id=5) done\n  #1   (id=7)     Take"),
        "{text}"
    );
    let o = run(&["-pF", "Blackboard.aml", "Mix"], t.path());
    let text = stdout(&o);
    let header = text.lines().next().unwrap();
    for c in ["time", "KUKA KR15-2", "ABB IRB 1200", "UR10e"] {
        assert!(header.contains(c), "{text}");
    }
    // The UR places while the KUKA retreats: both start at 4.5 s, after the ABB's Take.
    let at = |t: &str| -> Vec<String> {
        text.lines()
            .filter(|l| l.starts_with(&format!("{t} ")))
            .map(|l| l.split('|').map(str::trim).collect::<Vec<_>>().join("|"))
            .collect()
    };
    assert_eq!(
        at("4.5"),
        ["4.5|Retreat (id=14) + 2||", "4.5|||Place (id=11) + 2",],
        "{text}"
    );
    assert!(
        at("0").contains(&"0||waits for KUKA KR15-2 (id=5)|".to_owned()),
        "{text}"
    );
    assert!(text.contains("cell time: 7.5 seconds"), "{text}");
    // JSON.
    let o = run(
        &["-pF", "-pO", "--format", "json", "Blackboard.aml", "Mix"],
        t.path(),
    );
    let listings: Vec<serde_json::Value> = stdout(&o)
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect();
    let flow = listings.iter().find(|v| v["listing"] == "flow").unwrap();
    assert_eq!(flow["total"], 7.5, "{flow}");
    assert_eq!(flow["lanes"].as_array().unwrap().len(), 3);
    assert_eq!(flow["lanes"][1]["items"][0]["kind"], "wait", "{flow}");
    assert_eq!(
        flow["lanes"][1]["items"][0]["for_controller"],
        "KUKA KR15-2"
    );
    let order = listings.iter().find(|v| v["listing"] == "order").unwrap();
    let programs = order["programs"].as_array().unwrap();
    assert_eq!(programs.len(), 3, "{order}");
    assert_eq!(programs[1]["program"], "Mix_ABB_IRB_1200");
    assert_eq!(
        programs[2]["blocks"][0]["decided_by"], "ABB IRB 1200",
        "{order}"
    );
    assert_eq!(programs[0]["blocks"][2]["kind"], "tell", "{order}");
}

/// Issue 25, item 3: a cell's program names. `<PROGRAM>_<controller>` by default; the
/// controller's `Program` attribute names its program; a name used twice, or too long for its
/// language, is an error that says to set `Program`, and nothing is written. A controller without
/// a `Code` interface of its name gets its program all the same, with `W205`.
#[test]
fn a_cells_program_names_come_from_program_attributes() {
    let t = bases_with_case(&["cell", "cell2"], "cell-two-robots-weld");
    let bb = t.path().join("Blackboard.aml");
    let original = std::fs::read_to_string(&bb).unwrap();
    let robot_b =
        "<InternalElement Name=\"KUKA KR16-2\" ID=\"{00000000-0000-0000-0001-000000000002}\">";
    assert!(original.contains(robot_b));
    let with_program = |name: &str| {
        original.replacen(
            robot_b,
            &format!("{robot_b}\n<Attribute Name=\"Program\"><Value>{name}</Value></Attribute>"),
            1,
        )
    };
    // The attribute names the program.
    std::fs::write(&bb, with_program("Welder")).unwrap();
    let o = run(&["Blackboard.aml", "Cell"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(t.path().join("Welder.src").is_file());
    assert!(t.path().join("Cell_KUKA_KR15_2.src").is_file());
    assert!(
        std::fs::read_to_string(&bb)
            .unwrap()
            .contains("<Value>Welder.src</Value>")
    );
    // The other program's name used twice.
    let dir2 = bases_with_case(&["cell", "cell2"], "cell-two-robots-weld");
    std::fs::write(
        dir2.path().join("Blackboard.aml"),
        with_program("Cell_KUKA_KR15_2"),
    )
    .unwrap();
    let o = run(&["Blackboard.aml", "Cell"], dir2.path());
    assert_eq!(o.status.code(), Some(1), "{}", stdout(&o));
    let err = stderr(&o);
    assert!(
        err.contains("E601")
            && err.contains("the name of another controller's program too")
            && err.contains("set the controller's `Program` attribute"),
        "{err}"
    );
    assert!(!dir2.path().join("Cell_KUKA_KR15_2.src").exists());
    // Too long for KRL (24 characters) by default.
    let dir3 = bases_with_case(&["cell", "cell2"], "cell-two-robots-weld");
    let o = run(&["Blackboard.aml", "A_Long_Program_Name"], dir3.path());
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(
        err.contains("E601") && err.contains("A_Long_Program_Name_KUKA_KR15_2"),
        "{err}"
    );
    // No Code interface for the second controller: W205, the program written all the same.
    let dir4 = bases_with_case(&["cell", "cell2"], "cell-two-robots-weld");
    let no_code = original.replace(
        "ExternalInterface Name=\"KUKA KR16-2\"",
        "ExternalInterface Name=\"Other\"",
    );
    std::fs::write(dir4.path().join("Blackboard.aml"), no_code).unwrap();
    let o = run(&["--warn", "Blackboard.aml", "Cell"], dir4.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains("W205"), "{}", stderr(&o));
    assert!(dir4.path().join("Cell_KUKA_KR16_2.src").is_file());
}

/// A reader that goes away (`skillpost … | head`) makes no panic: the listing is cut, the run
/// ends as it would.
#[test]
fn a_closed_stdout_is_no_panic() {
    let t = bases_with_case(&["cell", "abb", "ur", "mixed"], "cell-kuka-abb-ur");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["--validate", "-pB", "-pO", "-pF", "Blackboard.aml"])
        .current_dir(t.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Closed before the compile has printed anything.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(out.status.code(), Some(0), "{err}");
}

/// Issue 26, item 4: IEC 61131-3 literals and Unicode names in conditions, through the binary:
/// `1` as a condition, `BOOL#TRUE`, a based literal compared with an integer signal, `_` in a
/// number, and a signal named `Störung` in the blackboard.
#[test]
fn iec_literals_and_unicode_signal_names_compile() {
    let t = base_with_case("flow", "flow-guarded-sequence");
    let bb = t.path().join("Blackboard.aml");
    let text = std::fs::read_to_string(&bb).unwrap();
    let part_ok = "<ExternalInterface Name=\"Part_OK\"";
    assert!(text.contains(part_ok));
    std::fs::write(
        &bb,
        text.replacen(
            part_ok,
            "<ExternalInterface Name=\"Störung\" ID=\"{s-1}\" RefBaseClassPath=\"AutomationMLInterfaceClassLib/AutomationMLBaseInterface/Communication/SignalInterface\"><Attribute Name=\"Number\" AttributeDataType=\"xs:integer\"><Value>7</Value></Attribute></ExternalInterface>\n        <ExternalInterface Name=\"Part_OK\"",
            1,
        ),
    )
    .unwrap();
    let sfc = t.path().join("sfc.xml");
    let chart = std::fs::read_to_string(&sfc)
        .unwrap()
        .replace("<xhtml:p>TRUE</xhtml:p>", "<xhtml:p>1</xhtml:p>")
        .replace(
            "Part_OK (* the part is there;",
            "NOT störung AND BOOL#TRUE (* the part is there;",
        )
        .replace(
            "Gripper_Closed = TRUE",
            "Variant = 16#A OR Variant &lt; 1_0",
        );
    std::fs::write(&sfc, chart).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "Lit"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = std::fs::read_to_string(t.path().join("Lit.src")).unwrap();
    assert!(src.contains("WAIT FOR (NOT $IN[7]) AND TRUE"), "{src}");
    assert!(
        src.contains("WAIT FOR (Variant == 10) OR (Variant < 10)"),
        "{src}"
    );
    // `1` always fires: no wait for it.
    assert!(!src.contains("WAIT FOR 1"), "{src}");
}

/// Issue 26, item 1: a chart drawn as a closed circle (a connection back to an earlier step, as
/// Beremiz and OpenPLC draw sequence loops) is the loop a jump to that step is: the same
/// program, but for the loop's comment. Also when the connection leads back to the initial
/// step, which then has a predecessor.
#[test]
fn a_connection_back_to_a_step_is_a_loop_like_a_jump() {
    let t = base_with_case("flow", "flow-cyclic");
    let compile = |sfc: &str| -> String {
        std::fs::write(t.path().join("sfc.xml"), sfc).unwrap();
        let o = run(&["--lf", "Blackboard.aml", "Loopy"], t.path());
        assert_eq!(o.status.code(), Some(0), "{}\n{sfc}", stderr(&o));
        std::fs::read_to_string(t.path().join("Loopy.src")).unwrap()
    };
    let with_jump = std::fs::read_to_string(t.path().join("sfc.xml")).unwrap();
    let jump = &with_jump[with_jump.find("<jumpStep").unwrap()
        ..with_jump.find("</jumpStep>").unwrap() + "</jumpStep>".len()];
    assert!(jump.contains("targetName=\"Cycle\""), "{jump}");
    // Cycle (localId 5) gets the last transition (8) as a second input instead of the jump.
    let circle = with_jump.replace(jump, "").replacen(
        "<connectionPointIn><connection refLocalId=\"4\"/></connectionPointIn>",
        "<connectionPointIn><connection refLocalId=\"4\"/><connection refLocalId=\"8\"/></connectionPointIn>",
        1,
    );
    let a = compile(&with_jump);
    let b = compile(&circle);
    let without_loop_comment = |s: &str| -> Vec<String> {
        s.lines()
            .filter(|l| !l.trim_start().starts_with(";loop back"))
            .map(str::to_owned)
            .collect()
    };
    assert_eq!(without_loop_comment(&a), without_loop_comment(&b));
    assert!(
        b.contains(";loop back to step localId 5 (connection back from localId 8), endless"),
        "{b}"
    );
    // Through a selection convergence before the step (as editors draw a second input).
    let via_convergence = with_jump
        .replace(jump, "")
        .replacen(
            "<connectionPointIn><connection refLocalId=\"4\"/></connectionPointIn>",
            "<connectionPointIn><connection refLocalId=\"20\"/></connectionPointIn>",
            1,
        )
        .replacen(
            "<step localId=\"5\"",
            "<selectionConvergence localId=\"20\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"4\"/></connectionPointIn><connectionPointIn><connection refLocalId=\"8\"/></connectionPointIn></selectionConvergence><step localId=\"5\"",
            1,
        );
    assert_eq!(compile(&via_convergence), b);
    // Back to the initial step: Init (localId 1, marked) gets the last transition as its input.
    let to_init = with_jump
        .replace(jump, "")
        .replacen(
            "name=\"Init\" initialStep=\"true\">",
            "name=\"Init\" initialStep=\"true\"><connectionPointIn><connection refLocalId=\"8\"/></connectionPointIn>",
            1,
        );
    let c = compile(&to_init);
    assert!(
        c.contains(";loop back to step localId 1 (connection back from localId 8), endless"),
        "{c}"
    );
}

/// Issue 26, item 3: a condition that references a named transition of the POU (its
/// `transitions` list) takes that transition's body: ST (an expression, or an assignment to its
/// name), or LD/FBD (what its coil or output variable of the transition's name is wired from).
#[test]
fn a_named_transition_gives_its_st_body() {
    let t = base_with_case("flow", "flow-guarded-sequence");
    let sfc = std::fs::read_to_string(t.path().join("sfc.xml")).unwrap();
    let transitions = r#"<transitions>
          <transition name="PartThere"><body><ST><xhtml:p>PartThere := Part_OK AND NOT Magazine_Empty; (* both &amp; *)</xhtml:p></ST></body></transition>
          <transition name="Ladder"><body><LD><leftPowerRail localId="90"/></LD></body></transition>
          <transition name="Rung"><body><LD>
            <leftPowerRail localId="91"><connectionPointOut formalParameter=""/></leftPowerRail>
            <contact localId="92"><connectionPointIn><connection refLocalId="91"/></connectionPointIn><variable>Part_OK</variable></contact>
            <contact localId="93" negated="true"><connectionPointIn><connection refLocalId="91"/></connectionPointIn><variable>Magazine_Empty</variable></contact>
            <coil localId="94"><connectionPointIn><connection refLocalId="92"/><connection refLocalId="93"/></connectionPointIn><variable>Rung</variable></coil>
            <rightPowerRail localId="95"><connectionPointIn><connection refLocalId="94"/></connectionPointIn></rightPowerRail>
          </LD></body></transition>
        </transitions>
        <body>"#;
    let with_named = sfc.replacen("<body>", transitions, 1).replacen(
        "<inline name=\"\"><ST><xhtml:p>Part_OK (* the part is there;\n                checked by the camera *)</xhtml:p></ST></inline>",
        "<reference name=\"partthere\"/>",
        1,
    );
    assert!(
        with_named.contains("<reference name=\"partthere\"/>"),
        "the fixture changed"
    );
    std::fs::write(t.path().join("sfc.xml"), &with_named).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "Named"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = std::fs::read_to_string(t.path().join("Named.src")).unwrap();
    assert!(src.contains("WAIT FOR $IN[1] AND (NOT $IN[2])"), "{src}");
    // The textual form of IEC 61131-3 (`TRANSITION … := expression; END_TRANSITION`), as some
    // tools export the body: the same.
    let bare = with_named.replace("PartThere := Part_OK", ":= Part_OK");
    assert_ne!(bare, with_named, "the fixture changed");
    std::fs::write(t.path().join("sfc.xml"), &bare).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "Named"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = std::fs::read_to_string(t.path().join("Named.src")).unwrap();
    assert!(src.contains("WAIT FOR $IN[1] AND (NOT $IN[2])"), "{src}");
    // A named transition in LD: its coil of the transition's name is wired from two contacts
    // in parallel (an OR).
    let named = |which: &str| {
        with_named.replace(
            "<reference name=\"partthere\"/>",
            &format!("<reference name=\"{which}\"/>"),
        )
    };
    std::fs::write(t.path().join("sfc.xml"), named("Rung")).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "Named"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = std::fs::read_to_string(t.path().join("Named.src")).unwrap();
    assert!(src.contains("WAIT FOR $IN[1] OR (NOT $IN[2])"), "{src}");
    // One without a coil of its name: an error naming it.
    std::fs::write(t.path().join("sfc.xml"), named("Ladder")).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "Named"], t.path());
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(
        err.contains("E316")
            && err.contains(
                "the named transition `Ladder` has no coil or output variable named `Ladder`"
            ),
        "{err}"
    );
}

/// Issue 26, item 7: SFC bodies of actions are charts named `POU.ACTION`: used when no POU has
/// one, or when named (`--pou POU.ACTION`); a POU's own chart comes first.
#[test]
fn an_actions_sfc_body_is_a_chart_named_pou_dot_action() {
    let t = base_with_case("flow", "flow-guarded-sequence");
    let sfc = std::fs::read_to_string(t.path().join("sfc.xml")).unwrap();
    let (a, b) = (
        sfc.find("<body>").unwrap(),
        sfc.find("</body>").unwrap() + 7,
    );
    let in_action = format!(
        "{}<actions><action name=\"Idle\"><body><ST><xhtml:p>x := 1;</xhtml:p></ST></body></action><action name=\"Run\">{}</action></actions><body><ST><xhtml:p>Run();</xhtml:p></ST></body>{}",
        &sfc[..a],
        &sfc[a..b],
        &sfc[b..]
    )
    .replace("pouType=\"program\"", "pouType=\"functionBlock\"");
    let file = t.path().join("actions.xml");
    std::fs::write(&file, &in_action).unwrap();
    let o = run(&["--sfc", "-pS", "actions.xml"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("POU: GuardedSequence.Run"),
        "{}",
        stdout(&o)
    );
    let o = run(
        &["--sfc", "--pou", "guardedsequence.run", "actions.xml"],
        t.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let o = run(
        &["--sfc", "--pou", "GuardedSequence.Idle", "actions.xml"],
        t.path(),
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("the POUs with one: `GuardedSequence.Run`"),
        "{}",
        stderr(&o)
    );
    // A program's own chart besides: it is used, with a warning naming the action's.
    let both = in_action.replacen(
        "</pous>",
        &format!(
            "<pou name=\"Main\" pouType=\"program\">{}</pou></pous>",
            &sfc[a..b]
        ),
        1,
    );
    std::fs::write(&file, both).unwrap();
    let o = run(&["--sfc", "-pS", "--warn", "actions.xml"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("POU: Main"), "{}", stdout(&o));
    assert!(stderr(&o).contains("W305"), "{}", stderr(&o));
}

/// Issue 26, item 2: conditions drawn instead of written. An LD network (power rail, a contact,
/// a negated contact in series) and an FBD network (an OR block over two variables, into an AND
/// block with a third) give the programs of their inline ST twins; a block outside the
/// list of docs/INPUTS.md (a timer) is an error at it, naming it.
#[test]
fn wired_conditions_are_their_inline_twins() {
    let t = base_with_case("flow", "flow-guarded-sequence");
    let sfc = std::fs::read_to_string(t.path().join("sfc.xml")).unwrap();
    let cond4 = "<condition><inline name=\"\"><ST><xhtml:p>Part_OK (* the part is there;\n                checked by the camera *)</xhtml:p></ST></inline></condition>";
    let cond6 = "<condition><inline name=\"\"><ST><xhtml:p>NOT Magazine_Empty AND (Release OR Door_Closed)</xhtml:p></ST></inline></condition>";
    assert!(
        sfc.contains(cond4) && sfc.contains(cond6),
        "the fixture changed"
    );
    let compile = |text: &str| -> Result<Vec<String>, String> {
        std::fs::write(t.path().join("sfc.xml"), text).unwrap();
        let o = run(&["--lf", "Blackboard.aml", "Wired"], t.path());
        if o.status.code() != Some(0) {
            return Err(stderr(&o));
        }
        let src = std::fs::read_to_string(t.path().join("Wired.src")).unwrap();
        Ok(src
            .lines()
            .filter(|l| l.starts_with("WAIT"))
            .map(str::to_owned)
            .collect())
    };
    let twin = sfc
        .replace(cond4, "<condition><inline name=\"\"><ST>Part_OK AND NOT Magazine_Empty</ST></inline></condition>")
        .replace(cond6, "<condition><inline name=\"\"><ST>(Release OR Door_Closed) AND NOT Magazine_Empty</ST></inline></condition>");
    let networks = r#"
            <leftPowerRail localId="100"><position x="0" y="0"/><connectionPointOut formalParameter=""/></leftPowerRail>
            <contact localId="101"><position x="0" y="0"/><connectionPointIn><connection refLocalId="100"/></connectionPointIn><variable>Part_OK</variable></contact>
            <contact localId="102" negated="true"><position x="0" y="0"/><connectionPointIn><connection refLocalId="101"/></connectionPointIn><variable>Magazine_Empty</variable></contact>
            <inVariable localId="110"><position x="0" y="0"/><expression>Release</expression></inVariable>
            <inVariable localId="111"><position x="0" y="0"/><expression>Door_Closed</expression></inVariable>
            <inVariable localId="112"><position x="0" y="0"/><expression>NOT Magazine_Empty</expression></inVariable>
            <block localId="113" typeName="OR"><position x="0" y="0"/><inputVariables>
              <variable formalParameter="IN1"><connectionPointIn><connection refLocalId="110"/></connectionPointIn></variable>
              <variable formalParameter="IN2"><connectionPointIn><connection refLocalId="111"/></connectionPointIn></variable>
            </inputVariables><inOutVariables/><outputVariables><variable formalParameter="OUT"><connectionPointOut/></variable></outputVariables></block>
            <block localId="114" typeName="AND"><position x="0" y="0"/><inputVariables>
              <variable formalParameter="IN1"><connectionPointIn><connection refLocalId="113" formalParameter="OUT"/></connectionPointIn></variable>
              <variable formalParameter="IN2"><connectionPointIn><connection refLocalId="112"/></connectionPointIn></variable>
            </inputVariables><inOutVariables/><outputVariables><variable formalParameter="OUT"><connectionPointOut/></variable></outputVariables></block>
            <block localId="115" typeName="TON"><position x="0" y="0"/><inputVariables>
              <variable formalParameter="IN"><connectionPointIn><connection refLocalId="110"/></connectionPointIn></variable>
            </inputVariables><inOutVariables/><outputVariables><variable formalParameter="Q"><connectionPointOut/></variable></outputVariables></block>
          </SFC>"#;
    let wired = sfc
        .replace(cond4, "<condition><connectionPointIn><connection refLocalId=\"102\"/></connectionPointIn></condition>")
        .replace(cond6, "<condition><connectionPointIn><connection refLocalId=\"114\" formalParameter=\"OUT\"/></connectionPointIn></condition>")
        .replacen("</SFC>", networks, 1);
    let expected = compile(&twin).unwrap();
    assert_eq!(compile(&wired).unwrap(), expected);
    assert!(
        expected.iter().any(|l| l.contains("$IN[1]")),
        "{expected:?}"
    );
    // Arithmetic (the ADD, SUB, MUL of docs/INPUTS.md): the wired net and its ST call twin.
    let arith_net = r#"
            <inVariable localId="120"><position x="0" y="0"/><expression>Variant</expression></inVariable>
            <inVariable localId="121"><position x="0" y="0"/><expression>3</expression></inVariable>
            <block localId="122" typeName="MUL"><position x="0" y="0"/><inputVariables>
              <variable formalParameter="IN1"><connectionPointIn><connection refLocalId="120"/></connectionPointIn></variable>
              <variable formalParameter="IN2"><connectionPointIn><connection refLocalId="121"/></connectionPointIn></variable>
            </inputVariables><inOutVariables/><outputVariables><variable formalParameter="OUT"><connectionPointOut/></variable></outputVariables></block>
            <block localId="123" typeName="SUB"><position x="0" y="0"/><inputVariables>
              <variable formalParameter="IN1"><connectionPointIn><connection refLocalId="122"/></connectionPointIn></variable>
              <variable formalParameter="IN2"><connectionPointIn><connection refLocalId="120"/></connectionPointIn></variable>
            </inputVariables><inOutVariables/><outputVariables><variable formalParameter="OUT"><connectionPointOut/></variable></outputVariables></block>
            <block localId="124" typeName="GE"><position x="0" y="0"/><inputVariables>
              <variable formalParameter="IN1"><connectionPointIn><connection refLocalId="123"/></connectionPointIn></variable>
              <variable formalParameter="IN2"><connectionPointIn><connection refLocalId="121"/></connectionPointIn></variable>
            </inputVariables><inOutVariables/><outputVariables><variable formalParameter="OUT"><connectionPointOut/></variable></outputVariables></block>
          </SFC>"#;
    let arith_wired = sfc
        .replace(cond4, "<condition><connectionPointIn><connection refLocalId=\"124\"/></connectionPointIn></condition>")
        .replacen("</SFC>", arith_net, 1);
    let arith_twin = sfc.replace(
        cond4,
        "<condition><inline name=\"\"><ST>GE(SUB(MUL(Variant, 3), Variant), 3)</ST></inline></condition>",
    );
    let expected = compile(&arith_twin).unwrap();
    assert_eq!(compile(&arith_wired).unwrap(), expected);
    assert!(
        expected
            .iter()
            .any(|l| l == "WAIT FOR ((VARIANT * 3) - VARIANT) >= 3"
                || l == "WAIT FOR ((Variant * 3) - Variant) >= 3"),
        "{expected:?}"
    );
    // A timer: an error at the block, naming it.
    let timer = wired.replace(
        "<connection refLocalId=\"114\" formalParameter=\"OUT\"/>",
        "<connection refLocalId=\"115\" formalParameter=\"Q\"/>",
    );
    let err = compile(&timer).unwrap_err();
    assert!(
        err.contains("E316") && err.contains("block TON localId 115"),
        "{err}"
    );
    // A rising-edge contact: an error at it.
    let edge = wired.replace(
        "<contact localId=\"101\">",
        "<contact localId=\"101\" edge=\"rising\">",
    );
    assert_ne!(edge, wired);
    let err = compile(&edge).unwrap_err();
    assert!(
        err.contains("contact localId 101 detects a rising edge"),
        "{err}"
    );
}

/// Issue 26: a qualified name in a condition (`GVL.Part_OK`, as CODESYS writes conditions) is
/// one name, matched to the signal of that name; `--sfc` takes it unresolved.
#[test]
fn qualified_names_are_signals_of_that_name() {
    let t = base_with_case("flow", "flow-guarded-sequence");
    let bb = t.path().join("Blackboard.aml");
    let text = std::fs::read_to_string(&bb).unwrap();
    let part_ok = "<ExternalInterface Name=\"Part_OK\"";
    std::fs::write(
        &bb,
        text.replacen(
            part_ok,
            "<ExternalInterface Name=\"GVL.Part_OK\" ID=\"{q-1}\" RefBaseClassPath=\"AutomationMLInterfaceClassLib/AutomationMLBaseInterface/Communication/SignalInterface\"><Attribute Name=\"Number\" AttributeDataType=\"xs:integer\"><Value>7</Value></Attribute></ExternalInterface>\n        <ExternalInterface Name=\"Part_OK\"",
            1,
        ),
    )
    .unwrap();
    let sfc = t.path().join("sfc.xml");
    let chart = std::fs::read_to_string(&sfc).unwrap().replace(
        "Part_OK (* the part is there;",
        "gvl.part_ok AND NOT Magazine_Empty (* the part is there;",
    );
    std::fs::write(&sfc, &chart).unwrap();
    let o = run(&["--sfc", "sfc.xml"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let o = run(&["--lf", "Blackboard.aml", "Qual"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = std::fs::read_to_string(t.path().join("Qual.src")).unwrap();
    assert!(src.contains("WAIT FOR $IN[7] AND (NOT $IN[2])"), "{src}");
    // An unknown qualified name says where to declare it.
    std::fs::write(&sfc, chart.replace("gvl.part_ok", "Timer.Q")).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "Qual"], t.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("`Timer.Q`, which is not a signal"),
        "{}",
        stderr(&o)
    );
}

/// Issue 26: a wired condition through a block outside the list of docs/INPUTS.md is one error at that
/// block, naming its type and localId, whatever is wired around it: a TON in a feedback loop
/// through an SR (the Beremiz traffic light), a TON whose `PT` is not a condition's text (the
/// andisama chart), an edge detector, arithmetic other than `ADD`, `SUB`, `MUL` (which are
/// read).
/// A loop through listed blocks only, and an unconnected input, name the block too.
#[test]
fn wired_conditions_name_the_block_that_is_refused() {
    let t = base_with_case("flow", "flow-guarded-sequence");
    let sfc = std::fs::read_to_string(t.path().join("sfc.xml")).unwrap();
    let cond4 = "<condition><inline name=\"\"><ST><xhtml:p>Part_OK (* the part is there;\n                checked by the camera *)</xhtml:p></ST></inline></condition>";
    assert!(sfc.contains(cond4), "the fixture changed");
    let block = |id: u64, ty: &str, ins: &[(&str, Option<u64>)]| -> String {
        let ins: String = ins
            .iter()
            .map(|(f, r)| match r {
                Some(r) => format!(
                    "<variable formalParameter=\"{f}\"><connectionPointIn><connection refLocalId=\"{r}\"/></connectionPointIn></variable>"
                ),
                None => format!(
                    "<variable formalParameter=\"{f}\"><connectionPointIn/></variable>"
                ),
            })
            .collect();
        format!(
            "<block localId=\"{id}\" typeName=\"{ty}\"><position x=\"0\" y=\"0\"/><inputVariables>{ins}</inputVariables><inOutVariables/><outputVariables><variable formalParameter=\"OUT\"><connectionPointOut/></variable></outputVariables></block>"
        )
    };
    let var = |id: u64, text: &str| {
        format!(
            "<inVariable localId=\"{id}\"><position x=\"0\" y=\"0\"/><connectionPointOut/><expression>{text}</expression></inVariable>"
        )
    };
    // The errors of `--sfc` on the chart whose transition 4 is wired from `last` in `net`.
    let errors = |net: String, last: u64| -> Vec<String> {
        let text = sfc
            .replace(
                cond4,
                &format!("<condition><connectionPointIn><connection refLocalId=\"{last}\"/></connectionPointIn></condition>"),
            )
            .replacen("</SFC>", &format!("{net}</SFC>"), 1);
        std::fs::write(t.path().join("sfc.xml"), text).unwrap();
        let o = run(&["--sfc", "--format", "short", "sfc.xml"], t.path());
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        stderr(&o)
            .lines()
            .filter(|l| l.contains("error["))
            .map(str::to_owned)
            .collect()
    };
    let one = |net: String, last: u64, want: &str| {
        let e = errors(net, last);
        assert!(
            e.len() == 1 && e[0].contains("E316") && e[0].contains(want),
            "want one error with {want:?}: {e:#?}"
        );
        e.into_iter().next().unwrap()
    };
    // The Beremiz shape: OR(TON.Q, Door_Closed), the TON's IN from an SR reset by TON.Q.
    let feedback = [
        block(300, "OR", &[("IN1", Some(301)), ("IN2", Some(304))]),
        block(301, "TON", &[("IN", Some(302)), ("PT", Some(303))]),
        block(302, "SR", &[("S1", Some(305)), ("R", Some(301))]),
        var(303, "T#2s"),
        var(304, "Door_Closed"),
        var(305, "Release"),
    ]
    .concat();
    let e = one(
        feedback.clone(),
        300,
        "a wired condition uses block TON localId 301 (a timer): a wired condition may use only the blocks AND, OR, XOR, NOT, EQ, NE, GT, GE, LT, LE, ADD, SUB, MUL, SEL and MOVE; to wait a time after a step, write the step's time in the condition instead (`Step.t >= T#8s`)",
    );
    assert!(!e.contains("loops back"), "{e}");
    // Reached at the SR first (the condition wired from the SR): the SR is named.
    one(
        feedback,
        302,
        "a wired condition uses block SR localId 302 (a bistable, which keeps a state)",
    );
    // A TON whose PT is no condition's text: the TON, once, not its input.
    let e = one(
        [
            block(310, "TON", &[("IN", Some(311)), ("PT", Some(312))]),
            var(311, "Part_OK"),
            var(312, "Delay * 2"),
        ]
        .concat(),
        310,
        "a wired condition uses block TON localId 310 (a timer)",
    );
    assert!(!e.contains("312"), "{e}");
    // An edge detector; a user block, named as written.
    one(
        [
            block(320, "R_TRIG", &[("CLK", Some(321))]),
            var(321, "Part_OK"),
        ]
        .concat(),
        320,
        "block R_TRIG localId 320 (an edge detector): a wired condition may use only the blocks AND, OR, XOR, NOT, EQ, NE, GT, GE, LT, LE, ADD, SUB, MUL, SEL and MOVE; an edge is not a condition",
    );
    one(
        [
            block(325, "comparison", &[("IN", Some(326))]),
            var(326, "Part_OK"),
        ]
        .concat(),
        325,
        "a wired condition uses block comparison localId 325: a wired condition may use only the blocks",
    );
    // ADD, SUB, MUL are read (docs/INPUTS.md); DIV is not.
    for (ty, want) in [
        ("ADD", "wait for ADD(Variant, 2) > 2"),
        ("SUB", "wait for SUB(Variant, 2) > 2"),
        ("MUL", "wait for MUL(Variant, 2) > 2"),
    ] {
        let net = [
            block(330, "GT", &[("IN1", Some(331)), ("IN2", Some(333))]),
            block(331, ty, &[("IN1", Some(332)), ("IN2", Some(333))]),
            var(332, "Variant"),
            var(333, "2"),
        ]
        .concat();
        let text = sfc
            .replace(
                cond4,
                "<condition><connectionPointIn><connection refLocalId=\"330\"/></connectionPointIn></condition>",
            )
            .replacen("</SFC>", &format!("{net}</SFC>"), 1);
        std::fs::write(t.path().join("sfc.xml"), text).unwrap();
        let o = run(&["--sfc", "-pO", "sfc.xml"], t.path());
        assert_eq!(o.status.code(), Some(0), "{ty}: {}", stderr(&o));
        assert!(stdout(&o).contains(want), "{ty}: {}", stdout(&o));
    }
    one(
        [
            block(330, "GT", &[("IN1", Some(331)), ("IN2", Some(333))]),
            block(331, "DIV", &[("IN1", Some(332)), ("IN2", Some(333))]),
            var(332, "Variant"),
            var(333, "2"),
        ]
        .concat(),
        330,
        "a wired condition uses block DIV localId 331 (arithmetic): a wired condition may use only the blocks AND, OR, XOR, NOT, EQ, NE, GT, GE, LT, LE, ADD, SUB, MUL, SEL and MOVE; of arithmetic",
    );
    // A loop through listed blocks only: the loop, at the block it comes back to, named.
    one(
        [
            block(340, "AND", &[("IN1", Some(341)), ("IN2", Some(342))]),
            block(341, "OR", &[("IN1", Some(340)), ("IN2", Some(342))]),
            var(342, "Part_OK"),
        ]
        .concat(),
        340,
        "the wiring of the condition loops back to block AND localId 340",
    );
    // An unconnected input of a listed block: the block and the input, named.
    one(
        [
            block(350, "AND", &[("IN1", Some(351)), ("IN2", None)]),
            var(351, "Part_OK"),
        ]
        .concat(),
        350,
        "input IN2 of block AND localId 350 is not connected",
    );
}

/// A hostile wired condition (docs/INPUTS.md) is a clear error, not a stack overflow or a run
/// without end: a chain of 5,000 contacts in series, and 30 AND blocks each wired twice from
/// the one before (2^30 paths through the net).
#[test]
fn hostile_wired_conditions_are_errors() {
    let t = base_with_case("flow", "flow-guarded-sequence");
    let sfc = std::fs::read_to_string(t.path().join("sfc.xml")).unwrap();
    let cond4 = "<condition><inline name=\"\"><ST><xhtml:p>Part_OK (* the part is there;\n                checked by the camera *)</xhtml:p></ST></inline></condition>";
    assert!(sfc.contains(cond4), "the fixture changed");
    let check = |net: String, last: u64, want: &str| {
        let text = sfc
            .replace(
                cond4,
                &format!("<condition><connectionPointIn><connection refLocalId=\"{last}\"/></connectionPointIn></condition>"),
            )
            .replacen("</SFC>", &format!("{net}</SFC>"), 1);
        std::fs::write(t.path().join("sfc.xml"), text).unwrap();
        let o = run(&["--sfc", "sfc.xml"], t.path());
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        assert!(stderr(&o).contains(want), "{}", stderr(&o));
    };
    let mut chain = String::from("<leftPowerRail localId=\"1000\"/>");
    for k in 1..=5000u64 {
        chain.push_str(&format!(
            "<contact localId=\"{}\"><connectionPointIn><connection refLocalId=\"{}\"/></connectionPointIn><variable>Part_OK</variable></contact>",
            1000 + k,
            999 + k
        ));
    }
    check(chain, 6000, "drawn through more than 64 elements in a row");
    let mut fan =
        String::from("<inVariable localId=\"2000\"><expression>Part_OK</expression></inVariable>");
    for k in 1..=30u64 {
        let prev = 1999 + k;
        fan.push_str(&format!(
            "<block localId=\"{}\" typeName=\"AND\"><inputVariables><variable formalParameter=\"IN1\"><connectionPointIn><connection refLocalId=\"{prev}\"/></connectionPointIn></variable><variable formalParameter=\"IN2\"><connectionPointIn><connection refLocalId=\"{prev}\"/></connectionPointIn></variable></inputVariables></block>",
            2000 + k
        ));
    }
    check(fan, 2030, "drawn from more than 1024 elements");
}

/// Issue 26, item 5: flow the structured forms cannot express (here a jump forward into the
/// other branch of a selection) compiles: KRL goes on at a label, `--warn` says where (W307),
/// and the listings show the states.
#[test]
fn a_forward_jump_compiles_with_a_label_and_says_where() {
    let t = base_with_case("flow", "flow-jump-forward");
    let o = run(
        &[
            "--warn",
            "--format",
            "short",
            "-pO",
            "-pF",
            "Blackboard.aml",
            "JumpForward",
        ],
        t.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("sfc.xml:49:13: warning[W307]: this jump to step localId 10")
            && err.contains("[localId 6]"),
        "{err}"
    );
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains(" state 2 (id=10):"), "{out}");
    assert!(out.contains("go on at id=10"), "{out}");
    assert!(out.contains("[ state 2 at id=10:"), "{out}");
    assert!(
        out.contains("at least (loops and states counted once)"),
        "{out}"
    );
    let src = std::fs::read_to_string(t.path().join("JumpForward.src")).unwrap();
    let lines: Vec<&str> = src.lines().map(str::trim).collect();
    let label = lines.iter().position(|l| *l == "skp_s2:").expect("a label");
    let gotos: Vec<usize> = (0..lines.len())
        .filter(|&k| lines[k] == "GOTO skp_s2")
        .collect();
    // Both branches go on at Place: the jump and the branch through Mid.
    assert_eq!(gotos.len(), 2, "{src}");
    assert!(gotos.iter().all(|&g| g < label), "{src}");
    // Without --warn: no warning.
    let o = run(
        &["--format", "short", "Blackboard.aml", "JumpForward"],
        t.path(),
    );
    assert_eq!(o.status.code(), Some(0));
    assert!(!stderr(&o).contains("W307"), "{}", stderr(&o));
}

/// Issue 26, item 6: a macro step's body runs in its place, also when the body holds another
/// macro step (nested bodies keep their own initial and end steps).
#[test]
fn a_macro_step_nested_in_a_macro_step_runs_in_its_place() {
    let t = base_with_case("flow", "flow-macro-step");
    let sfc = std::fs::read_to_string(t.path().join("sfc.xml")).unwrap();
    let start = sfc
        .find("<step localId=\"103\"")
        .expect("the fixture's Grip");
    let end = start + sfc[start..].find("</step>").unwrap() + "</step>".len();
    let step = |id: u32, name: &str, input: Option<u32>| {
        let input = input
            .map(|i| {
                format!("<connectionPointIn><connection refLocalId=\"{i}\"/></connectionPointIn>")
            })
            .unwrap_or_default();
        let initial = if input.is_empty() {
            " initialStep=\"true\""
        } else {
            ""
        };
        format!(
            "<step localId=\"{id}\" name=\"{name}\"{initial}><position x=\"0\" y=\"0\"/>{input}<connectionPointOut formalParameter=\"\"/><addData><data name=\"iwb\" handleUnknown=\"preserve\"><iwb><time duration=\"1\"/><ressources><ressource name=\"KUKA KR15-2\"/></ressources><skill name=\"Move LIN\"/><Variable name=\"Frame\" Value=\"({id}, 0, 0, 0, 0, 0)\"/></iwb></data></addData></step>"
        )
    };
    let inner = format!(
        "<macroStep localId=\"103\" name=\"GripMacro\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"102\"/></connectionPointIn><connectionPointOut/><body><SFC>{}<transition localId=\"202\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"201\"/></connectionPointIn><connectionPointOut/><condition><inline name=\"\"><ST><xhtml:p>Door_Closed</xhtml:p></ST></inline></condition></transition>{}</SFC></body></macroStep>",
        step(201, "Close", None),
        step(203, "Check", Some(202))
    );
    let nested = format!("{}{inner}{}", &sfc[..start], &sfc[end..]);
    std::fs::write(t.path().join("sfc.xml"), &nested).unwrap();
    let o = run(
        &["--format", "short", "-pO", "Blackboard.aml", "Macro"],
        t.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let order: Vec<&str> = out
        .lines()
        .filter(|l| l.trim_start().starts_with('#'))
        .filter_map(|l| l.split_whitespace().nth(2))
        .collect();
    assert_eq!(
        order,
        [
            "Start", "Pick", "Approach", "Close", "Check", "Lift", "Place", "End"
        ],
        "{out}"
    );
    let src = std::fs::read_to_string(t.path().join("Macro.src")).unwrap();
    let wait = src
        .find("WAIT FOR $CYCFLAG[3]")
        .expect("Door_Closed's wait");
    assert!(
        src.find("Close").unwrap() < wait && wait < src.find("Check").unwrap(),
        "{src}"
    );
}

/// Macro steps nest up to the limit branches have (docs/INPUTS.md): 100 deep compile, 140 deep are
/// one E313 at the first macro step too deep.
#[test]
fn macro_steps_nest_up_to_the_limit() {
    fn macro_chart(depth: u32, i: u32) -> String {
        let step = |id: u32, name: &str, input: Option<u32>| {
            let input = input
                .map(|r| {
                    format!(
                        "<connectionPointIn><connection refLocalId=\"{r}\"/></connectionPointIn>"
                    )
                })
                .unwrap_or_default();
            let initial = if input.is_empty() {
                " initialStep=\"true\""
            } else {
                ""
            };
            format!(
                "<step localId=\"{id}\" name=\"{name}{id}\"{initial}><position x=\"0\" y=\"0\"/>{input}<connectionPointOut formalParameter=\"\"/></step>"
            )
        };
        let tr = |id: u32, input: u32| {
            format!(
                "<transition localId=\"{id}\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"{input}\"/></connectionPointIn><condition><inline name=\"\"><ST>TRUE</ST></inline></condition></transition>"
            )
        };
        if depth == 0 {
            return step(i, "S", None);
        }
        format!(
            "{}{}<macroStep localId=\"{}\" name=\"M\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"{}\"/></connectionPointIn><body><SFC>{}</SFC></body></macroStep>{}{}",
            step(i, "B", None),
            tr(i + 1, i),
            i + 2,
            i + 1,
            macro_chart(depth - 1, i + 10),
            tr(i + 3, i + 2),
            step(i + 4, "E", Some(i + 3))
        )
    }
    let t = tempfile::tempdir().unwrap();
    for (depth, ok) in [(100, true), (140, false)] {
        let text = format!(
            "<project xmlns=\"http://www.plcopen.org/xml/tc6_0201\"><types><pous><pou name=\"P\" pouType=\"program\"><body><SFC>{}</SFC></body></pou></pous></types></project>",
            macro_chart(depth, 10)
        );
        std::fs::write(t.path().join("deep.xml"), text).unwrap();
        let o = run(&["--sfc", "--format", "short", "deep.xml"], t.path());
        let err = stderr(&o);
        if ok {
            assert_eq!(o.status.code(), Some(0), "{err}");
        } else {
            assert_eq!(o.status.code(), Some(1), "{err}");
            assert_eq!(err.matches("error[").count(), 1, "{err}");
            assert!(
                err.contains("error[E313]: macro steps nested deeper than 128 levels"),
                "{err}"
            );
        }
    }
}

/// A chart of `elements` (SFC element XML) in a POU `P`.
fn chart(elements: &str) -> String {
    format!(
        "<project><types><pous><pou name=\"P\" pouType=\"program\"><body><SFC>{elements}</SFC></body></pou></pous></types></project>"
    )
}

#[test]
fn step_times_are_checked_without_a_blackboard() {
    // `Work.t` after Work: fine; `Start.t` after Work: the program would not know it.
    let els = |cond: &str| {
        format!(
            "<step localId=\"1\" name=\"Start\" initialStep=\"true\"><position x=\"0\" y=\"0\"/></step>\
            <transition localId=\"2\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"1\"/></connectionPointIn><condition><inline name=\"\"><ST>TRUE</ST></inline></condition></transition>\
            <step localId=\"3\" name=\"Work\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"2\"/></connectionPointIn></step>\
            <transition localId=\"4\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"3\"/></connectionPointIn><condition><inline name=\"\"><ST>{cond}</ST></inline></condition></transition>\
            <step localId=\"5\" name=\"End\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"4\"/></connectionPointIn></step>"
        )
    };
    let p = project();
    for (cond, ok, expect) in [
        (
            "Work.t &gt; T#1s500ms OR Part_OK",
            true,
            "wait for Work.t > T#1s500ms",
        ),
        (
            "AND(Work.T &gt;= t#0.25s, GT(n, 2))",
            true,
            "wait for AND(Work.T >= t#0.25s",
        ),
        ("Start.t &gt; T#1s", false, "does not follow that step"),
        ("Work.t &gt; 5", false, "needs a time, this is a number"),
        (
            "Work.t AND Part_OK",
            false,
            "needs a boolean, this is a time",
        ),
        ("Work.t &gt; T#5", false, "is not a unit"),
    ] {
        std::fs::write(p.path().join("t.xml"), chart(&els(cond))).unwrap();
        let o = run(&["--sfc", "-pO", "--format", "short", "t.xml"], p.path());
        let all = format!("{}{}", stdout(&o), stderr(&o));
        assert_eq!(
            o.status.code(),
            Some(if ok { 0 } else { 1 }),
            "{cond}: {all}"
        );
        assert!(all.contains(expect), "{cond}: {all}");
    }
}

/// A KRL program of a cell reads and drives its wires by their signals' names in the
/// blackboard: a `SIGNAL` per wire in the `.dat` (inputs, then outputs, by number), the name
/// made a KRL name (`Eingang Öl 1` → `Eingang_Oel_1`), unique without regard to case, and never
/// one of the program's own (`skp_rx1` becomes `w_skp_rx1`); the code reads `Eingang_Oel_1`, not
/// `$IN[41]`.
#[test]
fn a_cells_krl_wires_go_by_their_signals_names() {
    let p = bases_with_case(&["cell", "cell2"], "cell-two-robots-weld");
    let bb = std::fs::read_to_string(p.path().join("Blackboard.aml")).unwrap();
    let bb = bb
        .replace("From_A_1", "Eingang Öl 1")
        .replace("From_A_2", "skp_rx1")
        .replace("From_A_4", "eingang_oel_1");
    std::fs::write(p.path().join("Blackboard.aml"), bb).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "Cell"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let dat = std::fs::read_to_string(p.path().join("Cell_KUKA_KR16_2.dat")).unwrap();
    let signals: Vec<&str> = dat.lines().filter(|l| l.starts_with("SIGNAL ")).collect();
    assert_eq!(
        signals,
        [
            "SIGNAL Eingang_Oel_1 $IN[41]",
            "SIGNAL w_skp_rx1 $IN[42]",
            "SIGNAL From_A_3 $IN[43]",
            "SIGNAL eingang_oel_1_2 $IN[44]",
            "SIGNAL To_A_1 $OUT[31]",
            "SIGNAL To_A_2 $OUT[32]",
            "SIGNAL To_A_3 $OUT[33]",
            "SIGNAL To_A_4 $OUT[34]",
            "SIGNAL To_A_5 $OUT[35]",
        ],
        "{dat}"
    );
    let src = std::fs::read_to_string(p.path().join("Cell_KUKA_KR16_2.src")).unwrap();
    assert!(
        src.contains("(Eingang_Oel_1 == skp_rx1) OR (NOT From_A_3)"),
        "{src}"
    );
    assert!(src.contains("To_A_3 = skp_rx1"), "{src}");
    assert!(!src.contains("$IN[4") && !src.contains("$OUT[3"), "{src}");
    // The pendant message names the wire as the blackboard does, transliterated.
    assert!(src.contains("; wire Eingang Oel 1\""), "{src}");
}

/// An IRL definition goes into the program when the program's code calls the routine it
/// defines (RAPID: `ArcSeam 10;`, no parentheses), by the routine's own name, whatever the
/// definition is named, and transitively through the definitions already in; a definition
/// nothing calls stays out with `W308` naming it, and the rest of the program is written.
#[test]
fn definitions_go_in_when_the_code_calls_their_routines() {
    let p = bases_with_case(&["abb"], "abb-irb1200");
    let irl = std::fs::read_to_string(p.path().join("irb1200.irl")).unwrap();
    let irl = irl
        .replace("<definition name=\"GoHome\">", "<definition name=\"Moves\">")
        .replace(
            "MoveAbsJ [[0, 0, 0, 0, 30, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]], v500, fine, tool0;",
            "MoveAbsJ [[0, 0, 0, 0, 30, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]], v500, fine, tool0;\n\t\t\t  ArcSeam 10;",
        )
        .replace(
            "\t</def>",
            "\t\t<definition name=\"Weld\">\n\t\t\tPROC ArcSeam(num speed)\n\t\t\t  SetDO do_Arc, 1;\n\t\t\tENDPROC\n\t\t</definition>\n\t\t<definition name=\"Spare\">\n\t\t\tPROC Calibrate()\n\t\t\t  SetDO do_Arc, 0;\n\t\t\tENDPROC\n\t\t</definition>\n\t</def>",
        );
    std::fs::write(p.path().join("irb1200.irl"), irl).unwrap();
    let o = run(&["--warn", "--lf", "Cell.aml", "Palletize"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let m = std::fs::read_to_string(p.path().join("Palletize.mod")).unwrap();
    assert!(m.contains("PROC GoHome()"), "{m}");
    assert!(m.contains("PROC ArcSeam(num speed)"), "{m}");
    assert!(m.find("PROC GoHome()") < m.find("PROC ArcSeam("), "{m}");
    assert!(!m.contains("Calibrate"), "{m}");
    let e = stderr(&o);
    assert!(
        e.contains("W308")
            && e.contains(
                "definition `Spare` is not written into any program: no program calls `Calibrate`"
            ),
        "{e}"
    );
    assert!(!e.contains("`ArcSeam`") && !e.contains("`GoHome`"), "{e}");
}

/// A program of a cell whose code calls a routine that only another controller's IRL file
/// defines (the weld source's call uses the gripper's `GripClose`, and the gripper is on the
/// other robot) would not load: `E606` names the routine, the IRL file and its definition, and
/// nothing is written.
#[test]
fn a_call_to_another_controllers_routine_is_e606() {
    let p = bases_with_case(&["cell", "cell2"], "cell-two-robots-weld");
    let irl = std::fs::read_to_string(p.path().join("schweiss.irl")).unwrap();
    let irl = irl.replace(
        "\t\t\tWeldSeam (CURRENT)\n",
        "\t\t\tWeldSeam (CURRENT)\n\t\t\tGripClose (CURRENT)\n",
    );
    std::fs::write(p.path().join("schweiss.irl"), irl).unwrap();
    let before: Vec<_> = std::fs::read_dir(p.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    let o = run(&["--lf", "Blackboard.aml", "Cell"], p.path());
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("E606") && e.contains("calls `GripClose` but does not hold it: greifer.irl defines it (definition `GripClose`)"),
        "{e}"
    );
    let after: Vec<_> = std::fs::read_dir(p.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(before.len(), after.len(), "nothing is written: {after:?}");
}

/// A URScript program of a cell names its wires as the blackboard does: a constant per wire of
/// the standard digital I/O at the program's start, used in every read and set; never a
/// keyword or function URScript code calls (`sleep`) nor a word of the program's IRL code (`v`
/// of `movel(…, v=0.25)`): a snippet's assignment would change the wire silently.
#[test]
fn a_cells_urscript_wires_are_named_constants() {
    let p = bases_with_case(&["cell", "abb", "ur", "mixed"], "cell-kuka-abb-ur");
    let bb = std::fs::read_to_string(p.path().join("Blackboard.aml")).unwrap();
    let ur = "{20000000-0000-0000-0000-000000000002}";
    let bb = bb
        .replace(
            "Name=\"From_ABB_1\" ID=\"{u-in-1}\"",
            "Name=\"sleep\" ID=\"{u-in-1}\"",
        )
        .replace(&format!("{ur}:From_ABB_1\""), &format!("{ur}:sleep\""))
        .replace(
            "Name=\"From_ABB_2\" ID=\"{u-in-2}\"",
            "Name=\"v\" ID=\"{u-in-2}\"",
        )
        .replace(&format!("{ur}:From_ABB_2\""), &format!("{ur}:v\""));
    std::fs::write(p.path().join("Blackboard.aml"), bb).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "Mix"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let script = std::fs::read_to_string(p.path().join("Mix_UR10e.script")).unwrap();
    for constant in ["sleep_2 = 4", "v_2 = 5", "From_ABB_3 = 6", "To_ABB_1 = 1"] {
        assert!(
            script.lines().any(|l| l.trim() == constant),
            "{constant}: {script}"
        );
    }
    assert!(
        script.contains("while not (((get_standard_digital_in(sleep_2) == skp_rx3) or (not get_standard_digital_in(From_ABB_3)))"),
        "{script}"
    );
    assert!(
        script.contains("if get_standard_digital_in(v_2):"),
        "{script}"
    );
    assert!(
        script.contains("set_standard_digital_out(To_ABB_1, skp_rx3)"),
        "{script}"
    );
    assert!(
        script.contains("movel(") && script.contains("sleep(0.3)"),
        "{script}"
    );
    assert!(
        !script.contains("digital_in(4)") && !script.contains("digital_out(1,"),
        "{script}"
    );
    // Each handshake comment says the level it waits for, by the wires' names.
    assert!(
        script.contains("# handshake: wait for the branch ABB IRB 1200 takes at the selection localId 8: for sleep_2 = NOT skp_rx3 (the next message) or From_ABB_3 FALSE (started again)"),
        "{script}"
    );
}

/// A controller's `HandshakeTimeout` (seconds) says when a wait on a partner shows on the
/// pendant: `2.5` is `$TIMER[16] >= 2500` in KRL (the last of the controller's `Timers`), and
/// `0` turns the message off (a plain `WAIT FOR`). A step time in a cell whose `Timers` holds
/// one timer has none left (`E214` says that the waits use it); a value with a unit is `E215`
/// at the attribute, and nothing is written.
#[test]
fn handshake_timeout_says_when_a_wait_shows_on_the_pendant() {
    let p = bases_with_case(&["cell", "cell2"], "cell-two-robots-weld");
    let bb = std::fs::read_to_string(p.path().join("Blackboard.aml")).unwrap();
    let with = |attrs: &str| {
        let at = bb.find("<InternalElement Name=\"KUKA KR16-2\"").unwrap();
        let at = at + bb[at..].find('\n').unwrap();
        let text = format!("{}\n{attrs}{}", &bb[..at], &bb[at..]);
        std::fs::write(p.path().join("Blackboard.aml"), text).unwrap();
    };
    let attr = |name: &str, v: &str| {
        format!(
            "<Attribute Name=\"{name}\" AttributeDataType=\"xs:string\"><Value>{v}</Value></Attribute>"
        )
    };
    let b = || std::fs::read_to_string(p.path().join("Cell_KUKA_KR16_2.src")).unwrap();
    with(&attr("HandshakeTimeout", "2.5"));
    let o = run(&["--lf", "Blackboard.aml", "Cell"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = b();
    assert!(src.contains("OR ($TIMER[16] >= 2500)"), "{src}");
    assert!(src.contains("Set_KrlMsg(#WAITING"), "{src}");
    // The other controller keeps the default, 10 s.
    let a = std::fs::read_to_string(p.path().join("Cell_KUKA_KR15_2.src")).unwrap();
    assert!(a.contains("OR ($TIMER[16] >= 10000)"), "{a}");
    assert!(!a.contains(">= 2500"), "{a}");
    with(&attr("HandshakeTimeout", "0"));
    let o = run(&["--lf", "Blackboard.aml", "Cell"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let src = b();
    assert!(
        !src.contains("$TIMER") && !src.contains("#WAITING"),
        "{src}"
    );
    assert!(
        src.contains("WAIT FOR (From_A_") && !src.contains("skp_watch"),
        "{src}"
    );
    // `Timers` of one timer: the handshakes' own, none left for a step time.
    let sfc = std::fs::read_to_string(p.path().join("sfc.xml")).unwrap();
    let at = sfc.find("<transition localId=\"8\">").unwrap();
    let c = sfc[at..].find("<xhtml:p>TRUE</xhtml:p>").unwrap() + at;
    let timed = format!(
        "{}<xhtml:p>Weld.t &gt; T#2s</xhtml:p>{}",
        &sfc[..c],
        &sfc[c + "<xhtml:p>TRUE</xhtml:p>".len()..]
    );
    std::fs::write(p.path().join("sfc.xml"), &timed).unwrap();
    with(&attr("Timers", "12"));
    std::fs::remove_file(p.path().join("Cell_KUKA_KR16_2.src")).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "Cell"], p.path());
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("E214"), "{e}");
    assert!(
        e.contains("holds 0")
            && e.contains("`$TIMER[12]` measures the waits on the other controllers"),
        "{e}"
    );
    assert!(!p.path().join("Cell_KUKA_KR16_2.src").exists());
    // Without the message, the one timer is the step time's.
    with(&format!(
        "{}{}",
        attr("Timers", "12"),
        attr("HandshakeTimeout", "0")
    ));
    let o = run(&["--lf", "Blackboard.aml", "Cell"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(b().contains("WAIT FOR $TIMER[12] > 2000"), "{}", b());
    // A unit after the number: E215 at the attribute.
    std::fs::write(p.path().join("sfc.xml"), &sfc).unwrap();
    with(&attr("HandshakeTimeout", "10 s"));
    std::fs::remove_file(p.path().join("Cell_KUKA_KR16_2.src")).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "Cell"], p.path());
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("E215") && e.contains("Blackboard.aml:"), "{e}");
    assert!(e.contains("`HandshakeTimeout` is `10 s`"), "{e}");
    assert!(!p.path().join("Cell_KUKA_KR16_2.src").exists());
}

/// In a cell, a condition may read the time of a step its own controller runs: the controller
/// that waits for the transition (the one of the step after it, else the one in charge) starts
/// the step's timer and reads it. A step of another controller is refused: step times are not
/// shared between controllers.
#[test]
fn step_times_in_a_cell_are_read_on_the_steps_controller() {
    let p = bases_with_case(&["cell", "cell2"], "cell-two-robots-weld");
    let sfc = std::fs::read_to_string(p.path().join("sfc.xml")).unwrap();
    let with = |sfc: &str, t: u32, cond: &str| -> String {
        let at = sfc.find(&format!("<transition localId=\"{t}\">")).unwrap();
        let c = sfc[at..].find("<xhtml:p>TRUE</xhtml:p>").unwrap() + at;
        format!(
            "{}<xhtml:p>{cond}</xhtml:p>{}",
            &sfc[..c],
            &sfc[c + "<xhtml:p>TRUE</xhtml:p>".len()..]
        )
    };
    // After Weld (KR16-2's weld source), before the simultaneous branches: KR16-2 waits.
    std::fs::write(p.path().join("sfc.xml"), with(&sfc, 8, "Weld.t &gt; T#2s")).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "Cell"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let b = std::fs::read_to_string(p.path().join("Cell_KUKA_KR16_2.src")).unwrap();
    let start = b.find("$TIMER[9] = 0").expect("the timer starts");
    let weld = b.find("WeldSeam (180)").unwrap();
    let read = b
        .find("WAIT FOR $TIMER[9] > 2000")
        .expect("the wait reads it");
    assert!(start < weld && weld < read, "{b}");
    // The waits on the partner are measured with the last of the timers (16), the step
    // times use the others.
    assert!(
        b.contains("$TIMER[16] = 0") && !b.contains("$TIMER[16] > "),
        "{b}"
    );
    let a = std::fs::read_to_string(p.path().join("Cell_KUKA_KR15_2.src")).unwrap();
    assert!(!a.contains("$TIMER[9]"), "{a}");
    // KR15-2 goes on when KR16-2 tells it that the transition fired.
    assert!(
        a.contains(";handshake: wait until KUKA KR16-2 has done localId 8"),
        "{a}"
    );
    // After Grip (KR15-2's gripper), waited for by Weld's controller (KR16-2): refused.
    std::fs::remove_file(p.path().join("Cell_KUKA_KR15_2.src")).unwrap();
    std::fs::write(p.path().join("sfc.xml"), with(&sfc, 6, "Grip.t &gt; T#1s")).unwrap();
    let before = std::fs::read(p.path().join("Blackboard.aml")).unwrap();
    let o = run(&["--format", "short", "Blackboard.aml", "Cell"], p.path());
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("E316") && e.contains("which runs on another controller"),
        "{e}"
    );
    assert_eq!(
        std::fs::read(p.path().join("Blackboard.aml")).unwrap(),
        before
    );
    assert!(!p.path().join("Cell_KUKA_KR15_2.src").exists());
}

#[test]
fn convergences_that_gather_only_jumps_are_not_part_of_the_flow() {
    // As CODESYS exports them: both branches end in jumps drawn into a selectionConvergence,
    // which is drawn into another one with nothing after it.
    let els = "<step localId=\"1\" name=\"Init\" initialStep=\"true\"><position x=\"0\" y=\"0\"/></step>\
        <transition localId=\"2\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"1\"/></connectionPointIn><condition><inline name=\"\"><ST>go</ST></inline></condition></transition>\
        <step localId=\"3\" name=\"Work\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"2\"/></connectionPointIn></step>\
        <selectionDivergence localId=\"4\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"3\"/></connectionPointIn></selectionDivergence>\
        <transition localId=\"5\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"4\"/></connectionPointIn><condition><inline name=\"\"><ST>again</ST></inline></condition></transition>\
        <jumpStep localId=\"6\" targetName=\"Init\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"5\"/></connectionPointIn></jumpStep>\
        <transition localId=\"7\"><position x=\"10\" y=\"0\"/><connectionPointIn><connection refLocalId=\"4\"/></connectionPointIn><condition><inline name=\"\"><ST>NOT again</ST></inline></condition></transition>\
        <jumpStep localId=\"8\" targetName=\"Done\"><position x=\"10\" y=\"0\"/><connectionPointIn><connection refLocalId=\"7\"/></connectionPointIn></jumpStep>\
        <selectionConvergence localId=\"9\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"6\"/></connectionPointIn><connectionPointIn><connection refLocalId=\"8\"/></connectionPointIn></selectionConvergence>\
        <selectionConvergence localId=\"10\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"9\"/></connectionPointIn></selectionConvergence>\
        <step localId=\"11\" name=\"Done\"><position x=\"0\" y=\"0\"/></step>\
        <transition localId=\"12\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"11\"/></connectionPointIn><condition><inline name=\"\"><ST>reset</ST></inline></condition></transition>\
        <jumpStep localId=\"13\" targetName=\"Init\"><position x=\"0\" y=\"0\"/><connectionPointIn><connection refLocalId=\"12\"/></connectionPointIn></jumpStep>";
    let p = project();
    std::fs::write(p.path().join("j.xml"), chart(els)).unwrap();
    let o = run(&["--sfc", "-pO", "--format", "short", "j.xml"], p.path());
    let out = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{}{out}", stderr(&o));
    for step in ["Init", "Work", "Done"] {
        assert!(out.contains(step), "{out}");
    }
}

#[test]
fn a_misspelled_start_tag_is_pointed_at() {
    let p = project();
    let path = p.path().join("Blackboard.aml");
    let bb = std::fs::read_to_string(&path).unwrap();
    let line7 = bb.lines().nth(6).unwrap();
    assert!(
        line7.contains("<InternalElement Name=\"Skills\""),
        "{line7}"
    );
    let bb = bb.replacen(
        "<InternalElement Name=\"Skills\"",
        "<InternalElment Name=\"Skills\"",
        1,
    );
    std::fs::write(&path, bb).unwrap();
    let o = run(&["Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    // The parser finds the mismatch at the end tag; the start tag is shown too.
    assert!(e.contains("Blackboard.aml:70:9"), "{e}");
    assert!(
        e.contains(
            "the start tag `<InternalElment>` on line 7 does not match `</InternalElement>`"
        ),
        "{e}"
    );
    assert!(
        e.contains(" 7 │         <InternalElment Name=\"Skills\""),
        "{e}"
    );
    let o = run(&["--format", "json", "Blackboard.aml", "out"], p.path());
    let d = &json_lines(&o)[0];
    assert_eq!(d["code"], "E102");
    assert!(
        d["notes"][0]
            .as_str()
            .unwrap()
            .starts_with("Blackboard.aml:7:9: the start tag `<InternalElment>`"),
        "{d}"
    );

    // The same in an IRL file.
    let p = project();
    let irl = p.path().join("kr15-2.irl");
    let text = std::fs::read_to_string(&irl).unwrap();
    std::fs::write(&irl, text.replacen("<def>", "<deff>", 1)).unwrap();
    let e = stderr(&run(&["Blackboard.aml", "out"], p.path()));
    assert!(
        e.contains("the start tag `<deff>` on line 3 does not match `</def>`"),
        "{e}"
    );
}

#[test]
fn a_misspelled_instance_hierarchy_is_named() {
    let p = project();
    let path = p.path().join("Blackboard.aml");
    let bb = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, bb.replace("InstanceHierarchy", "InstanceHierachy")).unwrap();
    let o = run(&["--format", "short", "Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).starts_with(
            "Blackboard.aml:4:3: error[E201]: the blackboard has no InstanceHierarchy: found \
             `InstanceHierachy` at 4:3: did you mean `InstanceHierarchy`?"
        ),
        "{}",
        stderr(&o)
    );
}

#[test]
fn unknown_caex_elements_are_warned_about_with_the_closest_name() {
    let p = project();
    let path = p.path().join("Blackboard.aml");
    let bb = std::fs::read_to_string(&path).unwrap();
    // Both `Order` attributes of one skill misspelled; any content of AdditionalInformation and
    // elements of another namespace are no CAEX elements to check.
    let bb = bb
        .replace(
            "<Attribute Name=\"Order\"><Description>Execution order of function</Description><Value>0</Value></Attribute>",
            "<Atribute Name=\"Order\"><Description>Execution order of function</Description><Value>0</Value></Atribute>",
        )
        .replace(
            "<Attribute Name=\"Order\"><Value>1</Value></Attribute>",
            "<Atribute Name=\"Order\"><Value>1</Value></Atribute>",
        )
        .replacen(
            "<InstanceHierarchy",
            "<AdditionalInformation><Writer><Atribute/></Writer></AdditionalInformation>\
             <x:Extra xmlns:x=\"urn:x\"><x:Atribute/></x:Extra><InstanceHierarchy",
            1,
        );
    std::fs::write(&path, bb).unwrap();
    // Without --warn the run goes on as before.
    let o = run(&["Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!stderr(&o).contains("W206"));
    let quiet = stderr(&o);
    let o = run(&["--validate", "Blackboard.aml"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let e = stderr(&o);
    assert_eq!(e.matches("warning[W206]").count(), 1, "{e}");
    // ... but counts it with the others (the sample's W303, a W203 the misspelling brings).
    let shown = e.matches("warning[").count();
    assert!(shown > 4, "{e}");
    assert_eq!(quiet, format!("{shown} warnings; --warn shows them\n"));
    assert!(
        e.contains(
            "warning[W206]: `Atribute` is no CAEX element: it is ignored, with what it holds; \
             did you mean `Attribute`?"
        ),
        "{e}"
    );
    assert!(e.contains("┌─ Blackboard.aml:25:15"), "{e}");
    assert!(
        e.contains("`Atribute` stands 2 times in the blackboard; this is the first"),
        "{e}"
    );
    // The unmodified sample has none.
    let q = project();
    let e = stderr(&run(&["--validate", "Blackboard.aml"], q.path()));
    assert!(!e.contains("W206"), "{e}");
}

#[test]
fn empty_inputs_say_they_are_empty() {
    for file in ["Blackboard.aml", "sfc.xml", "kr15-2.irl"] {
        let p = project();
        std::fs::write(p.path().join(file), "").unwrap();
        let o = run(&["--format", "short", "Blackboard.aml", "out"], p.path());
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        assert!(
            stderr(&o).starts_with(&format!(
                "{file}:1:1: error[E102]: `{file}` is empty: it holds no XML document\n"
            )),
            "{}",
            stderr(&o)
        );
    }
    let p = project();
    std::fs::write(p.path().join("Blackboard.aml"), " \n\t\n").unwrap();
    let e = stderr(&run(&["Blackboard.aml", "out"], p.path()));
    assert!(
        e.contains("`Blackboard.aml` is empty (white space only)"),
        "{e}"
    );
    std::fs::write(p.path().join("sfc.xml"), "").unwrap();
    let e = stderr(&run(&["--sfc", "sfc.xml"], p.path()));
    assert!(e.contains("`sfc.xml` is empty"), "{e}");
}

/// The last line a failing run prints on stderr.
fn last_line(o: &Output) -> String {
    stderr(o).lines().last().unwrap_or_default().to_owned()
}

#[test]
fn a_folder_given_as_the_blackboard_gets_a_hint() {
    let p = project();
    let parent = p.path().parent().unwrap();
    let name = p.path().file_name().unwrap().to_str().unwrap();
    let o = run(&[name, "prog"], parent);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains(&format!("cannot read `{name}`: is a directory")),
        "{e}"
    );
    // Its only blackboard is named, and the daemon that keeps a folder compiled.
    assert!(
        e.contains(&format!("did you mean `{name}/Blackboard.aml`?")),
        "{e}"
    );
    assert!(e.contains(&format!("`skillpost watch {name}`")), "{e}");
    assert_eq!(last_line(&o), "error: 1 error found; nothing was written");
    assert!(!p.path().join("prog.src").exists());

    // A folder of several blackboards, or none: name one.
    std::fs::copy(p.path().join("Blackboard.aml"), p.path().join("Other.aml")).unwrap();
    let e = stderr(&run(&[name, "prog"], parent));
    assert!(e.contains("name the blackboard (`.aml`); it holds"), "{e}");
    assert!(e.contains("Other.aml"), "{e}");
    let empty = tempfile::tempdir_in(p.path()).unwrap();
    let o = run(&[empty.path().to_str().unwrap(), "prog"], p.path());
    assert!(
        stderr(&o).contains("it holds no `.aml` file; name the blackboard (`.aml`)"),
        "{}",
        stderr(&o)
    );
    // The same hint with --validate, in JSON as notes.
    let o = run(&["--validate", "--format", "json", name], parent);
    assert_eq!(o.status.code(), Some(2));
    let lines = json_lines(&o);
    let notes = lines[0]["notes"].to_string();
    assert_eq!(lines[0]["code"], "E101");
    assert!(notes.contains("skillpost watch"), "{notes}");
}

#[test]
fn a_missing_file_ends_with_the_error_count_like_other_failures() {
    let d = tempfile::tempdir().unwrap();
    for format in ["human", "short"] {
        let o = run(&["--format", format, "missing.aml", "out"], d.path());
        assert_eq!(o.status.code(), Some(2));
        assert!(stderr(&o).contains("E101"), "{}", stderr(&o));
        assert_eq!(last_line(&o), "error: 1 error found; nothing was written");
    }
    let o = run(&["--sfc", "missing.xml"], d.path());
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(last_line(&o), "error: 1 error found; nothing was written");
    // JSON counts no errors: stdout holds the diagnostic only.
    let o = run(&["--format", "json", "missing.aml", "out"], d.path());
    assert_eq!(json_lines(&o)[0]["code"], "E101");
    assert!(!stderr(&o).contains("errors found"), "{}", stderr(&o));
}

#[test]
fn an_unwritable_output_is_an_e604_diagnostic() {
    let p = project();
    std::fs::create_dir(p.path().join("out.src")).unwrap();
    let o = run(&["--format", "json", "Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(2));
    // On stdout as a JSON object like every diagnostic, nothing on stderr.
    let lines = json_lines(&o);
    assert_eq!(lines.len(), 1, "{}", stdout(&o));
    assert_eq!(lines[0]["severity"], "error");
    assert_eq!(lines[0]["code"], "E604");
    let m = lines[0]["message"].as_str().unwrap();
    assert!(m.contains("cannot write") && m.contains("out.src"), "{m}");
    assert_eq!(stderr(&o), "");
    // The text formats: the code, and the count last.
    let o = run(&["Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("error[E604]: cannot write"),
        "{}",
        stderr(&o)
    );
    assert_eq!(last_line(&o), "error: 1 error found; nothing was written");
    let o = run(&["--format", "short", "Blackboard.aml", "out"], p.path());
    // After the compile's count of warnings not shown (three of the sample's SFC; W210: its
    // points are no inline forms, as its SetVelCP sets the velocity; W211: its robot moves
    // without a tool, base or load), the write's error.
    assert!(
        stderr(&o)
            .strip_prefix("5 warnings; --warn shows them\n")
            .is_some_and(|e| e.starts_with("error[E604]: cannot write")),
        "{}",
        stderr(&o)
    );
}

#[test]
fn print_options_compile_and_write_unless_validating() {
    let p = project();
    let o = run(&["-pB", "Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("wrote"), "{}", stdout(&o));
    assert!(p.path().join("out.src").exists());
    let o = run(&["--validate", "-pB", "Blackboard.aml", "other"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!p.path().join("other.src").exists());
    let help = stdout(&run(&["--help"], p.path()));
    assert!(
        help.contains("Printing does not stop the compile: it still writes the outputs"),
        "{help}"
    );
    assert!(
        help.contains("`--validate -pB` (any -p with --validate) only prints"),
        "{help}"
    );
}

/// docs/INPUTS.md: several steps marked `initialStep="true"`, nothing connecting them, are sequences
/// that run at the same time, each on controllers of its own. Each program holds its own
/// sequence only and waits for nothing from the other: no handshake wire is read or set.
#[test]
fn several_initial_steps_are_sequences_on_controllers_of_their_own() {
    let t = bases_with_case(&["cell", "cell2"], "cell-two-sequences");
    // The chart alone: valid, and the flow listing shows both sequences side by side.
    let o = run(&["--sfc", "--format", "json", "-pF", "sfc.xml"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let lines = json_lines(&o);
    let flow = listing(&lines, "flow");
    let blocks = flow["blocks"].as_array().unwrap();
    assert_eq!(blocks.len(), 1, "{flow}");
    assert_eq!(blocks[0]["kind"], "sequences", "{flow}");
    assert_eq!(
        blocks[0]["sequences"].as_array().unwrap().len(),
        2,
        "{flow}"
    );
    let o = run(&["--lf", "Blackboard.aml", "Cell"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let a = std::fs::read_to_string(t.path().join("Cell_KUKA_KR15_2.src")).unwrap();
    let b = std::fs::read_to_string(t.path().join("Cell_KUKA_KR16_2.src")).unwrap();
    for (prog, mine, theirs) in [
        (
            &a,
            &["Pick", "Grip", "PlaceA"][..],
            &["Weld", "RetreatB"][..],
        ),
        (
            &b,
            &["Weld", "RetreatB"][..],
            &["Pick", "Grip", "PlaceA"][..],
        ),
    ] {
        for s in mine {
            assert!(prog.contains(&format!(" {s}: ")), "{s} missing:\n{prog}");
        }
        for s in theirs {
            assert!(!prog.contains(&format!(" {s}: ")), "{s} in:\n{prog}");
        }
        // The wires between the robots: $OUT[11..13] and $IN[21..23] on both.
        for io in [
            "$OUT[11]", "$OUT[12]", "$OUT[13]", "$IN[21]", "$IN[22]", "$IN[23]",
        ] {
            assert!(!prog.contains(io), "a handshake on {io}:\n{prog}");
        }
    }
    // The second robot's sequence repeats without end, waiting for its part each round.
    let wait = b.find("WAIT FOR $IN[5]").expect("the wait for More_Parts");
    let lp = b.find("\nLOOP").expect("an endless loop");
    assert!(lp < wait && wait < b.find("ENDLOOP").unwrap(), "{b}");
    // Both paths written back.
    let bb = std::fs::read_to_string(t.path().join("Blackboard.aml")).unwrap();
    assert!(bb.contains("Cell_KUKA_KR15_2.src") && bb.contains("Cell_KUKA_KR16_2.src"));
}

/// A further initial step whose sequence runs no robot's code (a lone step, or steps without
/// skills between a start and an end: a PLC's own sequence) is left out: the program is the
/// one of the chart without it. With robot steps on the same controller it is an error.
#[test]
fn a_sequence_without_robot_steps_is_left_out() {
    let t = base_with_case("flow", "flow-guarded-sequence");
    let sfc = std::fs::read_to_string(t.path().join("sfc.xml")).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "GuardedSequence"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let alone = std::fs::read_to_string(t.path().join("GuardedSequence.src")).unwrap();
    let idle = "<step localId=\"900\" name=\"Idle\" initialStep=\"true\"><position x=\"500\" y=\"0\"/></step>\
        <transition localId=\"901\"><position x=\"500\" y=\"1\"/><connectionPointIn><connection refLocalId=\"900\"/></connectionPointIn>\
        <condition><inline name=\"\"><ST><xhtml:p>TRUE</xhtml:p></ST></inline></condition></transition>\
        <step localId=\"902\" name=\"Done\"><position x=\"500\" y=\"2\"/><connectionPointIn><connection refLocalId=\"901\"/></connectionPointIn></step>\
        <step localId=\"903\" name=\"Lone\" initialStep=\"true\"><position x=\"600\" y=\"0\"/></step>";
    let with_idle = sfc.replacen("</SFC>", &format!("{idle}</SFC>"), 1);
    assert_ne!(with_idle, sfc, "the fixture changed");
    std::fs::write(t.path().join("sfc.xml"), &with_idle).unwrap();
    std::fs::remove_file(t.path().join("GuardedSequence.src")).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "GuardedSequence"], t.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(t.path().join("GuardedSequence.src")).unwrap(),
        alone
    );
    // A robot step in the further sequence, on the only controller: refused, nothing written.
    let busy = with_idle.replacen(
        "<step localId=\"902\" name=\"Done\"><position x=\"500\" y=\"2\"/><connectionPointIn><connection refLocalId=\"901\"/></connectionPointIn></step>",
        &{
            let step = &sfc[sfc.find("<step localId=\"3\"").unwrap()..];
            let step = &step[..step.find("</step>").unwrap() + "</step>".len()];
            let moved = step
                .replacen("localId=\"3\"", "localId=\"902\"", 1)
                .replacen("refLocalId=\"2\"", "refLocalId=\"901\"", 1);
            format!("{moved}<transition localId=\"904\"><position x=\"500\" y=\"3\"/><connectionPointIn><connection refLocalId=\"902\"/></connectionPointIn></transition><step localId=\"905\" name=\"Done\"><position x=\"500\" y=\"4\"/><connectionPointIn><connection refLocalId=\"904\"/></connectionPointIn></step>")
        },
        1,
    );
    assert_ne!(busy, with_idle, "the fixture changed");
    std::fs::write(t.path().join("sfc.xml"), &busy).unwrap();
    let before = std::fs::read(t.path().join("Blackboard.aml")).unwrap();
    std::fs::remove_file(t.path().join("GuardedSequence.src")).unwrap();
    let o = run(&["--lf", "Blackboard.aml", "GuardedSequence"], t.path());
    assert_eq!(o.status.code(), Some(1), "{}", stdout(&o));
    assert!(
        stderr(&o).contains("both run on controller"),
        "{}",
        stderr(&o)
    );
    assert!(!t.path().join("GuardedSequence.src").exists());
    assert_eq!(
        std::fs::read(t.path().join("Blackboard.aml")).unwrap(),
        before
    );
}

/// A wire whose partner interface does not exist (`Go_b` misspelled `Go_X`) is not left out
/// silently: a warning at the link says which side names nothing and the near name, and the
/// cell then lacks the wire (`E212`).
#[test]
fn an_internal_link_to_a_missing_interface_is_a_warning_at_the_link() {
    let p = base_with_case("cell", "cell-two-robots-wired");
    let path = p.path().join("Blackboard.aml");
    let bb = std::fs::read_to_string(&path).unwrap();
    std::fs::write(
        &path,
        bb.replace("000000000051}:Go_B\"", "000000000051}:Go_X\""),
    )
    .unwrap();
    let o = run(&["--warn", "Blackboard.aml", "output"], p.path());
    let e = stderr(&o);
    assert!(
        e.contains(
            "warning[W207]: InternalLink `A done to B` is left out: side B names `{00000000-0000-0000-0000-000000000051}:Go_X`, but the element with the ID `{00000000-0000-0000-0000-000000000051}` has no signal `Go_X`; did you mean `Go_B`?"
        ),
        "{e}"
    );
    assert!(e.contains("┌─ Blackboard.aml:143:7"), "{e}");
    // This cell has a spare wire each way: it still compiles.
    assert_eq!(o.status.code(), Some(0), "{e}");
    // The fixture's link `not a wire` names an interface `Somewhere` that is not there either.
    assert!(
        e.contains("warning[W207]: InternalLink `not a wire` is left out: side A names `{00000000-0000-0000-0000-000000000002}:Somewhere`, but no element with the ID `{00000000-0000-0000-0000-000000000002}` holds a signal"),
        "{e}"
    );
    assert_eq!(e.matches("warning[W207]").count(), 2, "{e}");
    // Once `Somewhere` is there (an interface, no signal), that link is no wire and not
    // skillpost's: no warning.
    let start = "ID=\"{00000000-0000-0000-0000-000000000002}\">";
    assert!(bb.contains(start));
    std::fs::write(
        &path,
        bb.replacen(
            start,
            &format!("{start}<ExternalInterface Name=\"Somewhere\" ID=\"{{x-somewhere}}\" RefBaseClassPath=\"AutomationMLInterfaceClassLib/AutomationMLBaseInterface\"/>"),
            1,
        ),
    )
    .unwrap();
    let e = stderr(&run(&["--warn", "Blackboard.aml", "output"], p.path()));
    assert!(!e.contains("W207"), "{e}");
}

/// A resource attribute misspelled (`Controler`) is not read, and said so with the name meant;
/// here the gripper then stands beside its robot as a controller of its own (E212).
#[test]
fn a_misspelled_resource_attribute_is_a_warning_naming_the_one_meant() {
    let p = base_with_case("cell", "cell-gripper-controller-attribute");
    let path = p.path().join("Blackboard.aml");
    let bb = std::fs::read_to_string(&path).unwrap();
    assert!(bb.contains("<Attribute Name=\"Controller\""));
    std::fs::write(
        &path,
        bb.replace(
            "<Attribute Name=\"Controller\"",
            "<Attribute Name=\"Controler\"",
        ),
    )
    .unwrap();
    let o = run(&["--warn", "Blackboard.aml", "output"], p.path());
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("warning[W208]: attribute `Controler` is not read: did you mean `Controller`?"),
        "{e}"
    );
    assert!(e.contains("┌─ Blackboard.aml:97:9"), "{e}");
    assert!(e.contains("error[E212]"), "{e}");
    // The sample's other attributes (`Steuerung` on the robot, vendor data) are no warning.
    assert_eq!(e.matches("warning[W208]").count(), 1, "{e}");
}

/// The count of warnings not shown is the number `--warn` shows also where many unused
/// variables are only counted: steps with more than a handful of variables (looked up by
/// hash), more groups than the scan holds, the same variable at several steps and in another
/// case (one warning per skill and variable).
#[test]
fn many_unused_variables_are_counted_as_warn_shows_them() {
    let p = project();
    let path = p.path().join("sfc.xml");
    let sfc = std::fs::read_to_string(&path).unwrap();
    let extra = |case_upper: bool| -> String {
        (0..30)
            .map(|i| {
                let name = if case_upper && i % 2 == 0 {
                    format!("EXTRA_{i}")
                } else {
                    format!("extra_{i}")
                };
                format!("<Variable name=\"{name}\" Value=\"{i}\"/>")
            })
            .collect()
    };
    let mut n = 0;
    let sfc: String = sfc
        .split_inclusive('\n')
        .map(|l| {
            if l.contains("<Variable name=\"JointConfig\" Value=\"(2, 35)\"/>") {
                n += 1;
                format!("{l}{}\n", extra(n == 2))
            } else {
                l.to_owned()
            }
        })
        .collect();
    assert_eq!(n, 3);
    std::fs::write(&path, sfc).unwrap();
    let shown = stderr(&run(&["--warn", "Blackboard.aml", "out"], p.path()))
        .matches("warning[")
        .count();
    assert!(shown > 60, "{shown}");
    let o = run(&["Blackboard.aml", "out"], p.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(stderr(&o), format!("{shown} warnings; --warn shows them\n"));
}

/// A step time that is not a number of seconds of at least 0 (`-2.75`, `2 s`) is a warning at
/// the attribute, and the step has no time (it passed silently before).
#[test]
fn a_negative_or_unreadable_step_time_is_a_warning_at_the_attribute() {
    for (bad, shown) in [("-2.75", "`-2.75`"), ("2 s", "`2 s`")] {
        let p = project();
        let path = p.path().join("sfc.xml");
        let sfc = std::fs::read_to_string(&path).unwrap();
        assert!(sfc.contains("<time duration=\"1.5\"/>"));
        std::fs::write(
            &path,
            sfc.replacen(
                "<time duration=\"1.5\"/>",
                &format!("<time duration=\"{bad}\"/>"),
                1,
            ),
        )
        .unwrap();
        let o = run(&["--warn", "Blackboard.aml", "out"], p.path());
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(0), "{e}");
        assert!(e.contains("warning[W309]"), "{e}");
        assert!(e.contains(&format!("`time@duration` is {shown}")), "{e}");
        assert!(e.contains("sfc.xml:"), "{e}");
    }
}

/// `Number` 0 is URScript's first standard digital input (`get_standard_digital_in(0)`), so it
/// is read; a KRL program that would read it gets E209 saying KRL counts from 1.
#[test]
fn number_0_is_a_urscript_input_and_an_error_for_krl() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    for e in std::fs::read_dir(repo.join("fixtures/base/ur")).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), dir.path().join(e.file_name())).unwrap();
    }
    let bb = dir.path().join("Cell.aml");
    let text = std::fs::read_to_string(&bb).unwrap();
    let one =
        "<Attribute Name=\"Number\" AttributeDataType=\"xs:integer\"><Value>1</Value></Attribute>";
    assert!(text.contains(one));
    std::fs::write(&bb, text.replacen(one, &one.replace(">1<", ">0<"), 1)).unwrap();
    let o = run(&["Cell.aml", "Palletize"], dir.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let script = std::fs::read_to_string(dir.path().join("Palletize.script")).unwrap();
    assert!(script.contains("get_standard_digital_in(0)"), "{script}");
    // The same Number on a KUKA robot: a condition reading it is refused (E209), at Number 1
    // it compiles.
    for (number, ok) in [("0", false), ("1", true)] {
        let p = project();
        let bb = p.path().join("Blackboard.aml");
        let text = std::fs::read_to_string(&bb).unwrap();
        let skills = "<InternalElement Name=\"Skills\"";
        assert!(text.contains(skills));
        let signals = format!(
            "<InternalElement Name=\"Signals\" ID=\"{{5a000000-0000-0000-0000-000000000001}}\"><ExternalInterface Name=\"Part_OK\" ID=\"{{5a000000-0000-0000-0000-000000000002}}\" RefBaseClassPath=\"AutomationMLInterfaceClassLib/AutomationMLBaseInterface/Communication/SignalInterface\"><Attribute Name=\"Number\" AttributeDataType=\"xs:integer\"><Value>{number}</Value></Attribute></ExternalInterface></InternalElement>"
        );
        std::fs::write(&bb, text.replacen(skills, &format!("{signals}{skills}"), 1)).unwrap();
        let sfc = p.path().join("sfc.xml");
        let s = std::fs::read_to_string(&sfc).unwrap();
        let cond = "<xhtml:p>TRUE</xhtml:p>";
        assert!(s.contains(cond), "the sample has a condition");
        std::fs::write(&sfc, s.replacen(cond, "<xhtml:p>Part_OK</xhtml:p>", 1)).unwrap();
        let o = run(&["Blackboard.aml", "out"], p.path());
        let e = stderr(&o);
        if ok {
            assert_eq!(o.status.code(), Some(0), "{e}");
            let src = std::fs::read_to_string(p.path().join("out.src")).unwrap();
            assert!(src.contains("$IN[1]"), "{src}");
        } else {
            assert_eq!(o.status.code(), Some(1), "{e}");
            assert!(
                e.contains("error[E209]") && e.contains("KRL counts inputs and outputs from 1"),
                "{e}"
            );
            assert!(!p.path().join("out.src").exists());
        }
    }
}
