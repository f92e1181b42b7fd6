//! Projects that must compile: every folder under `fixtures/ok/` is copied to a temporary folder
//! and compiled with the binary (`skillpost --warn [args] <BLACKBOARD> <PROGRAM>`).
//!
//! Each case folder holds the project's files and a `case.toml`:
//!
//! ```toml
//! base = "flow"                # optional: fixtures/base/<base>/ is copied first (a list:
//!                              # each in order, later over earlier), the case's
//!                              # files over it (a case keeps only what it changes)
//! program = "Name"             # the <PROGRAM> argument
//! language = "RAPID"           # optional: the program's language (KRL by default), which
//!                              # decides the outputs: KRL .src + .dat, RAPID .mod, URScript .script
//! blackboard = "Cell.aml"      # optional; default: the single *.aml in the folder
//! args = ["--lf"]              # optional extra arguments
//! tc6_valid = ["sfc.xml"]      # optional; SFC files that must validate against tc6_xml_v201.xsd
//! stderr_contains = ["W204"]   # optional; text the compiler's stderr must contain
//! stdout_contains = ["wrote"]  # optional; text the compiler's stdout must contain
//! parts = ["P_1", "P_2"]      # optional: the files of a split program's parts (their stems;
//!                              # the language of the program whose name they extend: KRL
//!                              # .src + .dat, RAPID .mod), checked and snapshot like a program's
//! cell = [                     # optional: a cell of several controllers (docs/CELLS.md), one
//!   { program = "P_A" },       # program each (the written-back one first), each in its
//!   { program = "P_B", language = "URScript" },  # language; snapshots named by program
//! ]
//! ```
//!
//! For every case the test checks, through the binary only:
//! - exit status 0, and exactly the language's outputs (`<PROGRAM>.src` and `<PROGRAM>.dat`,
//!   `<PROGRAM>.mod`, `<PROGRAM>.script`) added to the folder;
//! - snapshots (`tests/snapshots/`) of each output (line ends made visible: `⏎` marks a
//!   CRLF) and the region of the blackboard the write-back changed;
//! - the blackboard differs from the input only inside the write-back target's `<Value>`, which
//!   now holds `<PROGRAM>.src` (or only by the inserted `<Value>` element when the target had
//!   none; or not at all when there is no target);
//! - the blackboard before and after, and the `tc6_valid` SFC files, validate against the XSDs in
//!   `../shared/schemas/` with `xmllint` (skipped, with a note, when either is missing);
//! - a second run over unchanged inputs exits 0 and rewrites nothing (modification times kept);
//! - the `.src`/`.dat` pass a KRL structure check ([`check_krl`]); a `.mod` passes `rapidchecker`;
//!   a `.script` passes the URScript block-structure check.

mod common;

use std::collections::BTreeMap;
use std::fs;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, SystemTime};

use serde::Deserialize;

/// One `case.toml`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CaseToml {
    base: Option<common::Bases>,
    program: String,
    language: Option<String>,
    blackboard: Option<String>,
    #[serde(default)]
    args: Vec<String>,
    #[serde(default)]
    tc6_valid: Vec<String>,
    #[serde(default)]
    stderr_contains: Vec<String>,
    #[serde(default)]
    stdout_contains: Vec<String>,
    #[serde(default)]
    parts: Vec<String>,
    #[serde(default)]
    cell: Vec<CellProgram>,
}

/// One program of a cell case.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CellProgram {
    program: String,
    language: Option<String>,
    /// The `Code` interface its path is written into (the first program's: the write-back
    /// target); none: not written back.
    code: Option<String>,
}

/// A RAPID module links only when every signal it names is configured: each signal of its I/O
/// list that goes by an `Address` is declared in its EIO.cfg fragment, with the type its
/// direction and kind ask for.
fn check_eio(name: &str, module: &str, io: &str, eio: &str) {
    assert!(
        eio.starts_with("EIO:CFG_1.0:"),
        "{name}: EIO.cfg header:\n{eio}"
    );
    let declared: Vec<(&str, &str)> = eio
        .lines()
        .filter_map(|l| {
            let rest = l.trim().strip_prefix("-Name \"")?;
            let (n, rest) = rest.split_once('"')?;
            let t = rest.split("-SignalType \"").nth(1)?.split('"').next()?;
            Some((n, t))
        })
        .collect();
    for row in io.lines().skip(1) {
        let cells: Vec<&str> = row.split(',').collect();
        let (dir, address, ty) = (cells[0], cells[3], cells[4]);
        if address.is_empty() {
            continue;
        }
        let want = match (ty.starts_with("integer"), dir) {
            (false, "in") => "DI",
            (false, _) => "DO",
            (true, "in") => "GI",
            (true, _) => "GO",
        };
        assert!(
            declared.contains(&(address, want)),
            "{name}: `{address}` ({want}) is not declared in the EIO.cfg fragment:\n{eio}"
        );
    }
    // Every wire and condition signal the module reads or sets is among them.
    let rows_named = io
        .lines()
        .skip(1)
        .filter(|r| !r.contains("signal of "))
        .count();
    assert!(
        rows_named == 0 || declared.iter().any(|(n, _)| module.contains(n)),
        "{name}: the module names none of the signals declared:\n{eio}"
    );
}

/// A language's outputs, the main one (the write-back's) first.
fn extensions(name: &str, language: Option<&str>) -> &'static [&'static str] {
    match language.map(str::to_ascii_lowercase).as_deref() {
        // The program's files, then its I/O list (and for RAPID its EIO.cfg fragment).
        None | Some("krl") => &["src", "dat", "io.csv"],
        Some("rapid") => &["mod", "io.csv", "eio.cfg"],
        Some("urscript") => &["script", "io.csv"],
        Some(other) => panic!("{name}: case.toml: unknown language `{other}`"),
    }
}

macro_rules! cases {
    ($($test:ident => $dir:literal,)*) => {
        /// The case folders, sorted; [`every_case_folder_has_a_test`] keeps this list complete.
        const CASES: &[&str] = &[$($dir),*];
        $(
            #[test]
            fn $test() {
                run_case($dir);
            }
        )*
    };
}

cases! {
    abb_irb1200 => "abb-irb1200",
    caex3_english => "caex3-english",
    cell_eight_wires => "cell-eight-wires",
    cell_flow_states => "cell-flow-states",
    cell_gripper_controller_attribute => "cell-gripper-controller-attribute",
    cell_kuka_abb_ur => "cell-kuka-abb-ur",
    cell_robot_gripper => "cell-robot-gripper",
    cell_sequences_mixed => "cell-sequences-mixed",
    cell_tell_at_once => "cell-tell-at-once",
    cell_tool_base_load => "cell-tool-base-load",
    cell_two_robots_weld => "cell-two-robots-weld",
    cell_two_robots_wired => "cell-two-robots-wired",
    cell_two_sequences => "cell-two-sequences",
    codesys_addata_pou => "codesys-addata-pou",
    flow_codesys_nested_selection => "flow-codesys-nested-selection",
    flow_cyclic => "flow-cyclic",
    flow_guarded_sequence => "flow-guarded-sequence",
    flow_jump_forward => "flow-jump-forward",
    flow_loop_continued => "flow-loop-continued",
    flow_loop_early_exit => "flow-loop-early-exit",
    flow_loop_exit => "flow-loop-exit",
    flow_loop_joined_exits => "flow-loop-joined-exits",
    flow_macro_step => "flow-macro-step",
    flow_nested_loops => "flow-nested-loops",
    flow_parallel_in_selection => "flow-parallel-in-selection",
    flow_reference_condition => "flow-reference-condition",
    flow_selection_in_parallel => "flow-selection-in-parallel",
    flow_selection_three_way => "flow-selection-three-way",
    flow_selection_two_way => "flow-selection-two-way",
    flow_step_time => "flow-step-time",
    irl_helper_definitions => "irl-helper-definitions",
    lf_output => "lf-output",
    mappings_overloads => "mappings-overloads",
    no_writeback_target => "no-writeback-target",
    reference_sample => "reference-sample",
    split_cell => "split-cell",
    split_krl => "split-krl",
    split_rapid => "split-rapid",
    split_urscript => "split-urscript",
    step_name_line_break => "step-name-line-break",
    subfolders => "subfolders",
    typed_values => "typed-values",
    umlauts => "umlauts",
    ur10e => "ur10e",
    writeback_insert_value => "writeback-insert-value",
}

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn ok_dir() -> PathBuf {
    repo().join("fixtures/ok")
}

#[test]
fn every_case_folder_has_a_test() {
    let mut dirs: Vec<String> = fs::read_dir(ok_dir())
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_type().unwrap().is_dir())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    dirs.sort();
    let mut sorted = CASES.to_vec();
    sorted.sort();
    assert_eq!(CASES, sorted.as_slice(), "keep the case list sorted");
    assert_eq!(
        dirs, sorted,
        "fixtures/ok/ and the case list in tests/ok_fixtures.rs differ"
    );
}

// ---------------------------------------------------------------------------------------------
// Running one case
// ---------------------------------------------------------------------------------------------

fn run_case(name: &str) {
    let case_dir = ok_dir().join(name);
    let toml_text = fs::read_to_string(case_dir.join("case.toml"))
        .unwrap_or_else(|e| panic!("{name}: case.toml: {e}"));
    let case: CaseToml =
        toml::from_str(&toml_text).unwrap_or_else(|e| panic!("{name}: case.toml: {e}"));

    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    for base in case.base.iter().flat_map(common::Bases::list) {
        copy_dir(&repo().join("fixtures/base").join(base), dir);
    }
    copy_dir(&case_dir, dir);

    let bb_name = match &case.blackboard {
        Some(b) => b.clone(),
        None => single_aml(dir),
    };
    let bb = dir.join(&bb_name);
    let original = fs::read(&bb).unwrap();
    let lf = case.args.iter().any(|a| a == "--lf");
    // Each program and its outputs, the main one (the write-back's) first.
    let mut programs: Vec<(String, &[&str])> = if case.cell.is_empty() {
        vec![(
            case.program.clone(),
            extensions(name, case.language.as_deref()),
        )]
    } else {
        case.cell
            .iter()
            .map(|c| (c.program.clone(), extensions(name, c.language.as_deref())))
            .collect()
    };
    // The parts of split programs: a part's files are those of its program's language, without
    // the commissioning files.
    for part in &case.parts {
        let (_, exts) = programs
            .iter()
            .filter(|(p, _)| part.starts_with(&format!("{p}_")))
            .max_by_key(|(p, _)| p.len())
            .unwrap_or_else(|| panic!("{name}: part `{part}` extends no program's name"));
        let exts: &[&str] = match exts[0] {
            "src" => &["src", "dat"],
            "mod" => &["mod"],
            other => panic!("{name}: a .{other} program has no part files"),
        };
        programs.push((part.clone(), exts));
    }
    let outputs: Vec<(String, &str)> = programs
        .iter()
        .flat_map(|(p, exts)| exts.iter().map(move |e| (p.clone(), *e)))
        .collect();
    let out_paths: Vec<PathBuf> = outputs
        .iter()
        .map(|(p, e)| dir.join(format!("{p}.{e}")))
        .collect();

    let schemas = schema_dir();
    if let Some(s) = &schemas {
        let xsd = caex_schema(s, &original);
        xmllint(&xsd, &bb).unwrap_or_else(|e| panic!("{name}: input blackboard: {e}"));
        for f in &case.tc6_valid {
            xmllint(&s.join("tc6_xml_v201.xsd"), &dir.join(f))
                .unwrap_or_else(|e| panic!("{name}: {f}: {e}"));
        }
    }

    // Run 1.
    let before = listing(dir);
    let out = run(dir, &case, &bb_name);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{name}: run 1 failed:\n{stderr}"
    );
    for s in &case.stderr_contains {
        assert!(stderr.contains(s), "{name}: stderr lacks `{s}`:\n{stderr}");
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    for s in &case.stdout_contains {
        assert!(stdout.contains(s), "{name}: stdout lacks `{s}`:\n{stdout}");
    }
    let after = listing(dir);
    let added: Vec<&String> = after.keys().filter(|k| !before.contains_key(*k)).collect();
    // In the BTreeMap's order (`.dat` before `.src`).
    let mut expected_added: Vec<String> = outputs.iter().map(|(p, e)| format!("{p}.{e}")).collect();
    expected_added.sort();
    assert_eq!(
        added,
        expected_added.iter().collect::<Vec<_>>(),
        "{name}: run 1 should add exactly the program's outputs"
    );

    // The outputs.
    let bytes: Vec<Vec<u8>> = out_paths.iter().map(|p| fs::read(p).unwrap()).collect();
    let texts: Vec<String> = bytes
        .iter()
        .zip(&outputs)
        .map(|(b, (_, e))| {
            String::from_utf8(b.clone())
                .unwrap_or_else(|_| panic!("{name}: the .{e} is not UTF-8 (let alone ASCII)"))
        })
        .collect();
    let mut at = 0;
    for (program, exts) in &programs {
        match exts[0] {
            "src" => {
                if let Err(e) = check_krl(&texts[at], &texts[at + 1], program, lf) {
                    panic!(
                        "{name}: KRL structure check: {e}\n--- .src ---\n{}",
                        texts[at]
                    );
                }
            }
            "mod" => {
                check_rapid(name, &out_paths[at], &texts[at]);
                if exts.len() > 1 {
                    // A split module's signals are read in its parts.
                    let mut module = texts[at].clone();
                    let mut k = 0;
                    for (p, e) in &programs {
                        if case.parts.contains(p) && p.starts_with(&format!("{program}_")) {
                            module.push_str(&texts[k]);
                        }
                        k += e.len();
                    }
                    check_eio(name, &module, &texts[at + 1], &texts[at + 2]);
                }
            }
            _ => check_script(name, &texts[at]),
        }
        at += exts.len();
    }

    // The write-back.
    let written = fs::read(&bb).unwrap();
    let main_output = format!("{}.{}", programs[0].0, programs[0].1[0]);
    let region = if case.cell.is_empty() {
        check_write_back(name, &bb_name, &original, &written, &main_output)
    } else {
        let expected: Vec<(String, String)> = case
            .cell
            .iter()
            .zip(&programs)
            .filter_map(|(c, (p, exts))| Some((c.code.clone()?, format!("{p}.{}", exts[0]))))
            .collect();
        check_cell_write_back(name, &original, &written, &expected)
    };
    if let Some(s) = &schemas {
        let xsd = caex_schema(s, &written);
        xmllint(&xsd, &bb).unwrap_or_else(|e| panic!("{name}: written-back blackboard: {e}"));
    }

    // Snapshots.
    for ((program, ext), text) in outputs.iter().zip(&texts) {
        // A cell's snapshots are named by program too.
        let snapshot = if case.cell.is_empty() && *program == case.program {
            format!("{name}__{ext}")
        } else {
            format!("{name}__{program}.{ext}")
        };
        insta::with_settings!({
            description => format!("fixtures/ok/{name}: {program}.{ext}"),
            omit_expression => true,
        }, {
            insta::assert_snapshot!(snapshot, visible(text));
        });
    }
    insta::with_settings!({
        description => format!("fixtures/ok/{name}: the write-back into {bb_name}"),
        omit_expression => true,
    }, {
        insta::assert_snapshot!(format!("{name}__blackboard"), region);
    });

    // Run 2 over unchanged inputs: nothing is rewritten.
    let fixed = SystemTime::UNIX_EPOCH + Duration::new(1_000_000_000, 123_456_789);
    let mut watched: Vec<&PathBuf> = out_paths.iter().collect();
    watched.push(&bb);
    for p in &watched {
        fs::File::options()
            .write(true)
            .open(p)
            .unwrap()
            .set_modified(fixed)
            .unwrap();
    }
    let mtimes: Vec<SystemTime> = watched.iter().map(|p| mtime(p)).collect();
    // Run 2 without `--warn`: the warnings are counted, not shown, and their number is the
    // number run 1 showed (also those a run without `--warn` does not build).
    let out2 = run_with(dir, &case, &bb_name, false);
    let stderr2 = String::from_utf8_lossy(&out2.stderr).into_owned();
    assert_eq!(
        out2.status.code(),
        Some(0),
        "{name}: run 2 failed:\n{stderr2}"
    );
    let shown = String::from_utf8_lossy(&out.stderr)
        .matches("warning[")
        .count();
    let counted = match shown {
        0 => String::new(),
        1 => "1 warning; --warn shows it\n".to_owned(),
        n => format!("{n} warnings; --warn shows them\n"),
    };
    assert_eq!(stderr2, counted, "{name}: run 2 (without --warn) said");
    for (p, m) in watched.iter().zip(&mtimes) {
        assert_eq!(
            mtime(p),
            *m,
            "{name}: run 2 rewrote {} although nothing changed:\n{stderr2}",
            p.display()
        );
    }
    for (p, b) in out_paths.iter().zip(&bytes) {
        assert_eq!(&fs::read(p).unwrap(), b, "{name}: {} changed", p.display());
    }
    assert_eq!(
        fs::read(&bb).unwrap(),
        written,
        "{name}: blackboard changed"
    );
    assert_eq!(listing(dir), after, "{name}: run 2 left files behind");
}

fn run(dir: &Path, case: &CaseToml, bb: &str) -> Output {
    run_with(dir, case, bb, true)
}

fn run_with(dir: &Path, case: &CaseToml, bb: &str, warn: bool) -> Output {
    Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(warn.then_some("--warn"))
        .args(&case.args)
        .arg(bb)
        .arg(&case.program)
        .current_dir(dir)
        .output()
        .unwrap()
}

fn mtime(p: &Path) -> SystemTime {
    fs::metadata(p).unwrap().modified().unwrap()
}

fn copy_dir(from: &Path, to: &Path) {
    for e in fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            fs::create_dir_all(&target).unwrap();
            copy_dir(&e.path(), &target);
        } else {
            fs::copy(e.path(), &target).unwrap();
        }
    }
}

/// Every file below `dir` (relative path with `/`) and its size.
fn listing(dir: &Path) -> BTreeMap<String, u64> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, u64>) {
        for e in fs::read_dir(dir).unwrap() {
            let e = e.unwrap();
            let p = e.path();
            if e.file_type().unwrap().is_dir() {
                walk(root, &p, out);
            } else {
                let rel = p.strip_prefix(root).unwrap().to_string_lossy();
                out.insert(rel.replace('\\', "/"), e.metadata().unwrap().len());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn single_aml(dir: &Path) -> String {
    let amls: Vec<String> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.to_ascii_lowercase().ends_with(".aml"))
        .collect();
    assert_eq!(amls.len(), 1, "expected one *.aml in {}", dir.display());
    amls[0].clone()
}

/// Line ends made visible: `⏎` marks a CRLF; a lone CR shows as `␍`.
fn visible(text: &str) -> String {
    text.replace("\r\n", "⏎\n").replace('\r', "␍")
}

// ---------------------------------------------------------------------------------------------
// The write-back
// ---------------------------------------------------------------------------------------------

/// The write-back target's `Value` element, found independently of the compiler (docs/INPUTS.md:
/// hierarchy `Blackboard` (or the only one) → `Code` → `KRL code` (else the first
/// ExternalDataConnector) → `refURI` → `Value`). `None`: no target at all; `Some(None)`: the
/// `refURI` attribute has no `Value`; `Some(Some((element, content)))`: the byte ranges of the
/// `Value` element and of its content.
type ValueRanges = Option<(Range<usize>, Range<usize>)>;

/// A cell's write-back (docs/CELLS.md): the blackboard is the original with the `Value` of each
/// named `Code` interface's `refURI` replaced by its program's path, and nothing else changed.
fn check_cell_write_back(
    case: &str,
    original: &[u8],
    written: &[u8],
    expected: &[(String, String)],
) -> String {
    let text = std::str::from_utf8(original).unwrap();
    let doc = roxmltree::Document::parse(text).unwrap();
    let code = doc
        .descendants()
        .find(|n| n.has_tag_name("InternalElement") && n.attribute("Name") == Some("Code"))
        .unwrap_or_else(|| panic!("{case}: no Code element"));
    let mut sites: Vec<(std::ops::Range<usize>, &str, &str)> = Vec::new();
    for (iface, value) in expected {
        let i = code
            .children()
            .find(|n| {
                n.has_tag_name("ExternalInterface")
                    && n.attribute("Name")
                        .is_some_and(|v| v.eq_ignore_ascii_case(iface))
            })
            .unwrap_or_else(|| panic!("{case}: no Code interface `{iface}`"));
        let v = i
            .descendants()
            .find(|n| n.has_tag_name("Value"))
            .and_then(|v| v.first_child())
            .unwrap_or_else(|| panic!("{case}: `{iface}` has no value"));
        sites.push((v.range(), iface, value));
    }
    sites.sort_by_key(|s| std::cmp::Reverse(s.0.start));
    let mut want = original.to_vec();
    let mut report = String::new();
    for (r, iface, value) in &sites {
        want.splice(r.clone(), value.bytes());
        report.push_str(&format!("{iface}: `{}` -> `{value}`\n", &text[r.clone()]));
    }
    assert!(
        want == written,
        "{case}: the blackboard is not the original with the programs' paths in their Code interfaces"
    );
    report
}

fn target_value(bytes: &[u8]) -> Option<ValueRanges> {
    let (offset, text) = match bytes.strip_prefix(b"\xEF\xBB\xBF") {
        Some(rest) => (3, std::str::from_utf8(rest).unwrap()),
        None => (0, std::str::from_utf8(bytes).unwrap()),
    };
    let doc = roxmltree::Document::parse(text).unwrap();
    let named = |n: &roxmltree::Node, want: &str| {
        n.attribute("Name")
            .is_some_and(|v| v.trim().to_lowercase() == want.to_lowercase())
    };
    let hierarchies = elems(doc.root_element(), "InstanceHierarchy");
    let h = match hierarchies.iter().find(|h| named(h, "Blackboard")) {
        Some(h) => *h,
        None if hierarchies.len() == 1 => hierarchies[0],
        None => return None,
    };
    let code = elems(h, "InternalElement")
        .into_iter()
        .find(|e| named(e, "Code"))?;
    let ifaces = elems(code, "ExternalInterface");
    let iface = ifaces.iter().find(|i| named(i, "KRL code")).or_else(|| {
        ifaces.iter().find(|i| {
            i.attribute("RefBaseClassPath")
                .is_some_and(|p| p.contains("ExternalDataConnector"))
        })
    })?;
    let attr = elems(*iface, "Attribute")
        .into_iter()
        .find(|a| named(a, "refURI"))?;
    let Some(value) = elems(attr, "Value").into_iter().next() else {
        return Some(None);
    };
    let r = value.range();
    let whole = &text[r.clone()];
    assert!(
        !whole.ends_with("/>"),
        "a self-closing <Value/> target is not supported by this test"
    );
    let start = r.start + whole.find('>').unwrap() + 1;
    let end = r.start + whole.rfind("</").unwrap();
    Some(Some((
        r.start + offset..r.end + offset,
        start + offset..end + offset,
    )))
}

/// The element children of `n` with local name `tag`.
fn elems<'a, 'i>(n: roxmltree::Node<'a, 'i>, tag: &str) -> Vec<roxmltree::Node<'a, 'i>> {
    n.children()
        .filter(|c| c.is_element() && c.tag_name().name() == tag)
        .collect()
}

/// The line (with its line break) holding `bytes[at..end]`, line ends made visible.
fn line_around(bytes: &[u8], at: usize, end: usize) -> String {
    let s = bytes[..at]
        .iter()
        .rposition(|&b| b == b'\n')
        .map_or(0, |p| p + 1);
    let e = bytes[end..]
        .iter()
        .position(|&b| b == b'\n')
        .map_or(bytes.len(), |p| end + p + 1);
    visible(&String::from_utf8_lossy(&bytes[s..e]))
}

fn line_number(bytes: &[u8], at: usize) -> usize {
    bytes[..at].iter().filter(|&&b| b == b'\n').count() + 1
}

/// Asserts the write-back changed only the target value (to `new_value`, the main output's
/// name, e.g. `<program>.src`; or inserted the
/// missing `<Value>` element and nothing else), and describes the change for the snapshot.
fn check_write_back(
    case: &str,
    bb_name: &str,
    original: &[u8],
    written: &[u8],
    new_value: &str,
) -> String {
    let mut report = format!(
        "{bb_name}: {} bytes, BOM: {}, line ends: {}\n",
        written.len(),
        if written.starts_with(b"\xEF\xBB\xBF") {
            "yes"
        } else {
            "no"
        },
        line_ends(written)
    );
    let Some(target) = target_value(original) else {
        assert_eq!(
            written, original,
            "{case}: a blackboard without write-back target must stay untouched"
        );
        report.push_str("no write-back target: unchanged\n");
        return report;
    };
    let Some((_, target)) = target else {
        // No `Value`: the written file must hold exactly the original plus the `Value` element.
        let Some(Some((element, content))) = target_value(written) else {
            panic!("{case}: the write-back did not insert a <Value> into the target");
        };
        assert_eq!(
            &written[content.clone()],
            new_value.as_bytes(),
            "{case}: the inserted value is not `{new_value}`"
        );
        let mut rest = written[..element.start].to_vec();
        rest.extend_from_slice(&written[element.end..]);
        assert!(
            rest == original,
            "{case}: the write-back changed more than inserting the <Value> element"
        );
        report.push_str(&format!(
            "no <Value> in the target: inserted `{}` at byte {} (line {})\n",
            String::from_utf8_lossy(&written[element.clone()]),
            element.start,
            line_number(written, element.start)
        ));
        report.push_str(&format!(
            "- {}",
            line_around(original, element.start, element.start).trim_start()
        ));
        report.push_str(&format!(
            "+ {}",
            line_around(written, element.start, element.end).trim_start()
        ));
        return report;
    };

    // Everything before the old value's start and after its end is identical; the new value is
    // `<program>.src`.
    assert_eq!(
        written.len(),
        original.len() - target.len() + new_value.len(),
        "{case}: the blackboard's length changed by more than the value"
    );
    let prefix = common_prefix(original, written);
    let suffix = common_prefix(
        &original.iter().rev().copied().collect::<Vec<_>>(),
        &written.iter().rev().copied().collect::<Vec<_>>(),
    );
    assert!(
        prefix >= target.start,
        "{case}: the blackboard changed at byte {prefix}, before the target value at {}",
        target.start
    );
    assert!(
        suffix >= original.len() - target.end,
        "{case}: the blackboard changed at byte {} from the end, after the target value",
        suffix
    );
    assert_eq!(
        &written[target.start..target.start + new_value.len()],
        new_value.as_bytes(),
        "{case}: the target value is not `{new_value}`"
    );
    report.push_str(&format!(
        "value at bytes {}..{} (line {}): `{}` -> `{}`\n",
        target.start,
        target.end,
        line_number(original, target.start),
        String::from_utf8_lossy(&original[target.clone()]),
        new_value
    ));
    report.push_str(&format!(
        "- {}",
        line_around(original, target.start, target.end).trim_start()
    ));
    report.push_str(&format!(
        "+ {}",
        line_around(written, target.start, target.start + new_value.len()).trim_start()
    ));
    report
}

fn common_prefix(a: &[u8], b: &[u8]) -> usize {
    a.iter().zip(b).take_while(|(x, y)| x == y).count()
}

fn line_ends(bytes: &[u8]) -> &'static str {
    let lf = bytes.iter().filter(|&&b| b == b'\n').count();
    let crlf = bytes.windows(2).filter(|w| w == b"\r\n").count();
    match (crlf, lf) {
        (0, 0) => "none",
        (0, _) => "LF",
        (c, l) if c == l => "CRLF",
        _ => "mixed",
    }
}

// ---------------------------------------------------------------------------------------------
// Schemas
// ---------------------------------------------------------------------------------------------

/// The schema folder, when it and `xmllint` are there; otherwise says why the check is skipped.
fn schema_dir() -> Option<PathBuf> {
    let dir = repo().join("../shared/schemas");
    if !dir.is_dir() {
        common::skip(&format!("schema check: {} does not exist", dir.display()));
        return None;
    }
    match Command::new("xmllint").arg("--version").output() {
        Ok(o) if o.status.success() => Some(dir),
        Ok(o) => {
            common::skip(&format!(
                "schema check: `xmllint --version` failed with {}",
                o.status
            ));
            None
        }
        Err(e) => {
            common::skip(&format!("schema check: xmllint is not installed ({e})"));
            None
        }
    }
}

/// The CAEX XSD for the blackboard's `SchemaVersion`.
fn caex_schema(dir: &Path, bytes: &[u8]) -> PathBuf {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let text = std::str::from_utf8(bytes).unwrap();
    let doc = roxmltree::Document::parse(text).unwrap();
    match doc.root_element().attribute("SchemaVersion") {
        Some("2.15") => dir.join("CAEX_ClassModel_V2.15.xsd"),
        Some("3.0") => dir.join("CAEX_ClassModel_V.3.0.xsd"),
        v => panic!("unexpected CAEX SchemaVersion {v:?}"),
    }
}

fn xmllint(xsd: &Path, file: &Path) -> Result<(), String> {
    let o = Command::new("xmllint")
        .arg("--noout")
        .arg("--schema")
        .arg(xsd)
        .arg(file)
        .output()
        .map_err(|e| format!("cannot run xmllint: {e}"))?;
    if o.status.success() {
        Ok(())
    } else {
        Err(format!(
            "does not validate against {}:\n{}",
            xsd.display(),
            String::from_utf8_lossy(&o.stderr)
        ))
    }
}

// ---------------------------------------------------------------------------------------------
// KRL structure check
// ---------------------------------------------------------------------------------------------

#[path = "common/krl_check.rs"]
mod krl_syntax;
use krl_syntax::check_krl;

#[cfg(test)]
mod write_back_check {
    use super::check_write_back;

    const BB: &str = "<?xml version=\"1.0\"?>\r\n<CAEXFile SchemaVersion=\"2.15\">\r\n  \
        <InstanceHierarchy Name=\"Blackboard\">\r\n    <InternalElement Name=\"Code\">\r\n      \
        <ExternalInterface Name=\"KRL code\">\r\n        <Attribute Name=\"refURI\">\
        <Value>old.src</Value></Attribute>\r\n      </ExternalInterface>\r\n    \
        </InternalElement>\r\n  </InstanceHierarchy>\r\n</CAEXFile>\r\n";

    fn check(written: &str) -> String {
        check_write_back("t", "bb.aml", BB.as_bytes(), written.as_bytes(), "prog.src")
    }

    #[test]
    fn accepts_a_value_change() {
        let r = check(&BB.replace("old.src", "prog.src"));
        assert!(r.contains("`old.src` -> `prog.src`"), "{r}");
    }

    #[test]
    #[should_panic(expected = "changed at byte")]
    fn rejects_a_change_before_the_value() {
        check(&BB.replace("old.src", "prog.src").replace("1.0", "1.1"));
    }

    #[test]
    #[should_panic(expected = "from the end")]
    fn rejects_a_change_after_the_value() {
        check(
            &BB.replace("old.src", "prog.src")
                .replace("</CAEXFile>\r\n", "</CAEXFile>\n\r"),
        );
    }

    #[test]
    #[should_panic(expected = "length changed")]
    fn rejects_lost_line_endings() {
        check(&BB.replace("old.src", "prog.src").replace("\r\n", "\n"));
    }

    #[test]
    #[should_panic(expected = "is not `prog.src`")]
    fn rejects_a_wrong_value() {
        check(&BB.replace("old.src", "PROG.src"));
    }

    #[test]
    #[should_panic(expected = "more than inserting")]
    fn rejects_an_insertion_with_other_changes() {
        let no_value = BB.replace("<Value>old.src</Value>", "");
        let written = BB
            .replace("old.src", "prog.src")
            .replace("Blackboard", "blackboard");
        check_write_back(
            "t",
            "bb.aml",
            no_value.as_bytes(),
            written.as_bytes(),
            "prog.src",
        );
    }

    #[test]
    #[should_panic(expected = "must stay untouched")]
    fn rejects_a_change_without_target() {
        let no_target = BB.replace("\"Code\"", "\"Geometry\"");
        let written = no_target.replace("old.src", "prog.src");
        check_write_back(
            "t",
            "bb.aml",
            no_target.as_bytes(),
            written.as_bytes(),
            "prog.src",
        );
    }
}

#[cfg(test)]
mod krl_check {
    use super::check_krl;

    const DAT: &str = "&ACCESS RVP\r\nDEFDAT prog\r\nENDDAT\r\n";

    fn src(body: &str) -> String {
        format!("&ACCESS RVP\r\n&REL 1\r\nDEF prog( )\r\n{body}END\r\n")
    }

    fn crlf(s: &str) -> String {
        s.replace('\n', "\r\n")
    }

    fn ok(src: &str) {
        if let Err(e) = check_krl(src, DAT, "prog", false) {
            panic!("rejected a valid program: {e}\n{src}");
        }
    }

    fn rejects(src: &str, why: &str) {
        match check_krl(src, DAT, "prog", false) {
            Ok(()) => panic!("accepted an invalid program ({why}):\n{src}"),
            Err(e) => assert!(e.contains(why), "expected `{why}`, got `{e}`"),
        }
    }

    #[test]
    fn accepts_a_valid_program() {
        ok(&src(&crlf(
            ";FOLD INI\n  BAS (#INITMOV,0)\n;ENDFOLD (INI)\nIF $IN[1] THEN\n  \
             FOR I = 1 TO 3\n    WAIT SEC 0.1\n  ENDFOR\nELSE\n  LOOP\n    EXIT\n  ENDLOOP\n\
             ENDIF\nWHILE FALSE\nENDWHILE\nSWITCH N\nCASE 1\n  HALT\nDEFAULT\nENDSWITCH\n\
             REPEAT\nUNTIL TRUE\nWAIT FOR $IN[2] ; FOR in a WAIT does not open a block\n",
        )));
        let with_def = format!(
            "{}\r\nDEF Helper(X:IN)\r\n  DECL REAL X\r\nEND\r\n",
            src("")
        );
        ok(&with_def);
        let lf = src("  PTP HOME\r\n").replace("\r\n", "\n");
        check_krl(&lf, &DAT.replace("\r\n", "\n"), "prog", true).unwrap();
    }

    #[test]
    fn keywords_in_comments_and_strings_do_not_count() {
        ok(&src(&crlf(
            "  ; IF this were code THEN\n  MSG = \"IF x THEN ; ENDFOR\"\n  X = 1 ; ENDIF\n",
        )));
    }

    #[test]
    fn rejects_unbalanced_blocks() {
        rejects(&src(&crlf("IF A THEN\n")), "IF of line 4 is open");
        rejects(&src(&crlf("ENDIF\n")), "ENDIF without IF");
        rejects(&src(&crlf("FOR I = 1 TO 2\nENDLOOP\n")), "expected LOOP");
        rejects(&src(&crlf("WHILE TRUE\n")), "WHILE of line 4 is open");
        rejects(&src(&crlf("SWITCH N\nENDIF\n")), "expected IF");
        rejects(&src(&crlf("ELSE\n")), "ELSE outside IF");
        rejects(&src(&crlf("IF A\nENDIF\n")), "IF without THEN");
        rejects(&src(&crlf("LOOP\n")), "LOOP of line 4 is open");
    }

    #[test]
    fn rejects_unbalanced_defs() {
        rejects(
            &crlf("DEF prog( )\nDEF inner( )\nEND\nEND\n"),
            "DEF inside DEF",
        );
        rejects(&crlf("DEF prog( )\n  PTP HOME\n"), "has no END");
        rejects(&crlf("DEF prog( )\nEND\nEND\n"), "END without DEF");
        rejects(&crlf("DEF prog( )\nEND\nPTP HOME\n"), "outside a DEF");
        rejects(&crlf("DEF other( )\nEND\n"), "not the program");
        rejects(&crlf("&ACCESS RVP\n"), "no DEF");
        rejects(&crlf("DEF prog( )\nEND\n&REL 1\n"), "header line after");
    }

    #[test]
    fn rejects_unbalanced_folds() {
        rejects(&src(&crlf(";FOLD A\n")), "END inside the ;FOLD");
        rejects(&src(&crlf(";ENDFOLD\n")), "without `;FOLD`");
        rejects(&format!("{};FOLD B\r\n", src("")), "has no ;ENDFOLD");
    }

    #[test]
    fn rejects_bad_names() {
        rejects(&crlf("DEF 1prog( )\nEND\n"), "not a valid KRL name");
        rejects(
            &format!("{}DEF abcdefghijklmnopqrstuvwxy( )\r\nEND\r\n", src("")),
            "not a valid KRL name",
        );
        assert!(check_krl(&src(""), DAT, "abcdefghijklmnopqrstuvwxy", false).is_err());
        assert!(check_krl(&src(""), DAT, "prog-1", false).is_err());
        let e = check_krl(&src(""), &DAT.replace("prog", "other"), "prog", false).unwrap_err();
        assert!(e.contains("DEFDAT `other`"), "{e}");
    }

    #[test]
    fn rejects_bad_dat() {
        let e = check_krl(&src(""), "DEFDAT prog\r\n", "prog", false).unwrap_err();
        assert!(e.contains("without ENDDAT"), "{e}");
        let e = check_krl(&src(""), "ENDDAT\r\n", "prog", false).unwrap_err();
        assert!(e.contains("before DEFDAT"), "{e}");
        let e = check_krl(&src(""), "DEFDAT prog\r\nENDDAT\r\nX\r\n", "prog", false).unwrap_err();
        assert!(e.contains("after ENDDAT"), "{e}");
    }

    #[test]
    fn points_must_be_declared_and_inline_forms_whole() {
        let dat = |decls: &str| format!("DEFDAT prog\r\n{decls}ENDDAT\r\n");
        let named = src("  PTP XPick\r\n");
        let pick = "DECL E6POS XPick={X 1,Y 2,Z 3,A 0,B 0,C 0}\r\n";
        assert_eq!(check_krl(&named, &dat(pick), "prog", false), Ok(()));
        let e = check_krl(&named, &dat(""), "prog", false).unwrap_err();
        assert!(e.contains("`XPick` is not declared"), "{e}");
        let e = check_krl(
            &named,
            &dat("DECL FDAT XPick={TOOL_NO 0}\r\n"),
            "prog",
            false,
        )
        .unwrap_err();
        assert!(e.contains("is a FDAT"), "{e}");
        let e = check_krl(&named, &dat("DECL E6POS XPick={X V}\r\n"), "prog", false).unwrap_err();
        assert!(e.contains("not a number"), "{e}");
        let e = check_krl(&named, &dat(&format!("{pick}{pick}")), "prog", false).unwrap_err();
        assert!(e.contains("declared twice"), "{e}");
        // KUKA's own home points are declared in $config.dat.
        assert_eq!(
            check_krl(&src("  PTP XHOME1\r\n"), &dat(""), "prog", false),
            Ok(())
        );
        let form = ";FOLD PTP Pick Vel=100 % PDAT1 Tool[0] Base[0];%{PE}%R 8.3.40,%MKUKATPBASIS,%CMOVE,%VPTP,%P 1:PTP, 2:Pick, 3:, 5:100, 7:PDAT1\r\n$BWDSTART=FALSE\r\nPDAT_ACT=PPDAT1\r\nFDAT_ACT=FPick\r\nBAS(#PTP_PARAMS,100)\r\nPTP XPick\r\n;ENDFOLD\r\n";
        let data =
            format!("{pick}DECL PDAT PPDAT1={{VEL 100}}\r\nDECL FDAT FPick={{TOOL_NO 0}}\r\n");
        assert_eq!(check_krl(&src(form), &dat(&data), "prog", false), Ok(()));
        let e = check_krl(&src(form), &dat(pick), "prog", false).unwrap_err();
        assert!(e.contains("`PPDAT1` is not declared"), "{e}");
        let moved = form.replace("PTP XPick", "PTP XPlace");
        let e = check_krl(&src(&moved), &dat(&data), "prog", false).unwrap_err();
        assert!(e.contains("not KUKA's"), "{e}");
    }

    #[test]
    fn rejects_bad_bytes_and_line_endings() {
        rejects(&src("  PTP HOME\n"), "mixed line endings");
        rejects(
            &src("  PTP HOME\r\n").replace("END\r\n", "END"),
            "no line break",
        );
        rejects(&src("  ; Größe\r\n"), "non-ASCII");
        rejects(&src("  X = 1\x0c\r\n"), "control character");
        rejects(&src("  MSG = \"open\r\n"), "unterminated string");
        let crlf_in_lf = check_krl(&src(""), DAT, "prog", true).unwrap_err();
        assert!(crlf_in_lf.contains("expected LF"), "{crlf_in_lf}");
    }
}

// ---------------------------------------------------------------------------------------------
// RAPID and URScript outputs
// ---------------------------------------------------------------------------------------------

/// A `.mod` must pass `rapidchecker` (installed by `.ci/run`).
fn check_rapid(name: &str, path: &Path, text: &str) {
    if !common::rapid::rapidchecker_available() {
        common::skip(&format!("{name}: rapidchecker is not installed"));
        return;
    }
    if let Err(e) = common::rapid::rapidcheck(path) {
        panic!("{name}: rapidchecker: {e}\n--- .mod ---\n{text}");
    }
}

/// A `.script` must pass the URScript block-structure check.
fn check_script(name: &str, text: &str) {
    if let Err(e) = common::urscript::check_urscript(text) {
        panic!("{name}: URScript structure check: {e}\n--- .script ---\n{text}");
    }
}
