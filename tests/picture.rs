//! The plan as a picture (`skillpost --svg FILE`, issue 28): for fixtures with one controller,
//! two controllers, selections and loops, through the binary: a snapshot of the SVG, the SVG
//! parsed as XML, the same bytes from a second run, and the picture rendered by resvg with every
//! lane (controller) and every step's name and localId found among its texts.

mod common;

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

#[derive(serde::Deserialize)]
struct Case {
    base: Option<common::Bases>,
    program: String,
    blackboard: Option<String>,
    /// A cell's programs, one per controller (lane).
    #[serde(default)]
    cell: Vec<CellProgram>,
}

#[derive(serde::Deserialize)]
struct CellProgram {
    program: String,
}

/// The fixture `fixtures/ok/<name>` with its bases, in a temporary folder; its blackboard and
/// program name.
fn materialize(name: &str) -> (tempfile::TempDir, PathBuf, String) {
    let (tmp, bb, program, _) = materialize_cell(name);
    (tmp, bb, program)
}

/// [`materialize`], with the names of a cell's programs (one per lane).
fn materialize_cell(name: &str) -> (tempfile::TempDir, PathBuf, String, Vec<String>) {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let case_dir = repo.join("fixtures/ok").join(name);
    let case: Case =
        toml::from_str(&fs::read_to_string(case_dir.join("case.toml")).unwrap()).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let copy = |from: &Path| {
        for e in fs::read_dir(from).unwrap() {
            let e = e.unwrap();
            if e.file_type().unwrap().is_file() {
                fs::copy(e.path(), tmp.path().join(e.file_name())).unwrap();
            }
        }
    };
    for b in case.base.iter().flat_map(common::Bases::list) {
        copy(&repo.join("fixtures/base").join(b));
    }
    copy(&case_dir);
    let bb = match case.blackboard {
        Some(b) => tmp.path().join(b),
        None => fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.extension().is_some_and(|x| x == "aml"))
            .unwrap(),
    };
    let programs = case.cell.into_iter().map(|c| c.program).collect();
    (tmp, bb, case.program, programs)
}

/// `skillpost --validate --svg OUT BLACKBOARD PROGRAM`, run.
fn svg(bb: &Path, program: &str, out: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["--validate", "--svg"])
        .arg(out)
        .arg(bb)
        .arg(program)
        .output()
        .unwrap()
}

/// [`svg`], which must succeed: the SVG's text.
fn draw(bb: &Path, program: &str, out: &Path) -> String {
    let o = svg(bb, program, out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    fs::read_to_string(out).unwrap()
}

/// Every text of the rendered tree (usvg keeps each `text` element's characters).
fn texts(svg: &str) -> Vec<String> {
    let mut opt = resvg::usvg::Options::default();
    opt.fontdb_mut().load_system_fonts();
    let tree = resvg::usvg::Tree::from_str(svg, &opt).expect("usvg reads the SVG");
    // Rendered: a picture of the whole size, not blank.
    let size = tree.size().to_int_size();
    let mut pixmap = resvg::tiny_skia::Pixmap::new(size.width(), size.height()).unwrap();
    resvg::render(
        &tree,
        resvg::tiny_skia::Transform::default(),
        &mut pixmap.as_mut(),
    );
    assert!(
        pixmap.pixels().iter().any(|p| p.red() < 128),
        "the rendered picture is blank"
    );
    let mut out = Vec::new();
    fn walk(g: &resvg::usvg::Group, out: &mut Vec<String>) {
        for n in g.children() {
            match n {
                resvg::usvg::Node::Group(g) => walk(g, out),
                resvg::usvg::Node::Text(t) => out.push(
                    t.chunks()
                        .iter()
                        .map(|c| c.text().to_owned())
                        .collect::<Vec<_>>()
                        .join(""),
                ),
                _ => {}
            }
        }
    }
    walk(tree.root(), &mut out);
    out
}

/// What the picture must show: each step (name, `id=N`), read from the SFC.
fn expected_steps(dir: &Path) -> Vec<(String, String)> {
    let sfc_path = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "xml"))
        .unwrap();
    let sfc = fs::read_to_string(&sfc_path).unwrap();
    let doc = roxmltree::Document::parse(&sfc).unwrap();
    let steps: Vec<(String, String)> = doc
        .descendants()
        .filter(|n| n.has_tag_name("step"))
        .map(|n| {
            (
                n.attribute("name")
                    .unwrap_or("")
                    .split_whitespace()
                    .collect::<Vec<_>>()
                    .join(" "),
                format!("id={}", n.attribute("localId").unwrap()),
            )
        })
        .collect();
    steps
}

fn check(name: &str, lanes: usize) {
    let (tmp, bb, program, programs) = materialize_cell(name);
    let out = tmp.path().join("plan.svg");
    let svg = draw(&bb, &program, &out);
    // XML, deterministic.
    roxmltree::Document::parse(&svg).unwrap_or_else(|e| panic!("{name}: not XML: {e}"));
    let again = tmp.path().join("again.svg");
    assert_eq!(
        draw(&bb, &program, &again),
        svg,
        "{name}: same inputs, same bytes"
    );
    assert_eq!(svg.matches(r#"<g class="lane">"#).count(), lanes, "{name}");
    // Rendered, and every label there: each step's name and localId, each lane's program.
    let texts = texts(&svg);
    for (step, id) in expected_steps(tmp.path()) {
        assert!(
            texts
                .iter()
                .any(|t| t == &step || t.starts_with(&format!("{step} "))),
            "{name}: step {step} not in the picture's texts: {texts:?}"
        );
        assert!(
            texts.iter().any(|t| t.split(' ').any(|w| w == id)),
            "{name}: {id} ({step}) not in the picture's texts: {texts:?}"
        );
    }
    assert_eq!(programs.len(), if lanes > 1 { lanes } else { 0 }, "{name}");
    for p in &programs {
        assert!(texts.contains(p), "{name}: lane of {p} not in {texts:?}");
    }
    assert!(texts.iter().any(|t| t.starts_with("cycle time ")), "{name}");
    insta::assert_snapshot!(name, svg);
}

#[test]
fn one_controller() {
    check("reference-sample", 1);
}

#[test]
fn two_controllers_with_handshakes() {
    check("cell-two-robots-weld", 2);
}

#[test]
fn three_controllers_of_three_languages() {
    check("cell-kuka-abb-ur", 3);
}

/// Two initial steps: two sequences side by side from time 0, one per robot, no handshake.
#[test]
fn two_sequences() {
    check("cell-two-sequences", 2);
}

#[test]
fn selections() {
    check("flow-selection-three-way", 1);
}

#[test]
fn loops() {
    check("flow-loop-exit", 1);
}

#[test]
fn untimed_steps_and_states() {
    check("flow-jump-forward", 1);
}

#[test]
fn a_picture_of_inputs_with_errors_is_not_written() {
    let (tmp, bb, program) = materialize("reference-sample");
    let sfc = tmp.path().join("sfc.xml");
    let text = fs::read_to_string(&sfc).unwrap();
    fs::write(&sfc, text.replacen("</pou>", "</pous>", 1)).unwrap();
    let out = tmp.path().join("plan.svg");
    let o = svg(&bb, &program, &out);
    assert_eq!(o.status.code(), Some(1));
    assert!(!out.exists());
    assert!(String::from_utf8_lossy(&o.stderr).contains("not drawn"));
}

mod inproc;

/// The daemon with `picture = true`: `<program>.svg` beside the outputs, listed in
/// `compile-succeeded`, written only when it changes, and its own write starts no compile.
#[test]
fn the_daemon_draws_the_plan_beside_the_outputs() {
    use inproc::*;
    let w = Workspace::new();
    let a = w.project("A");
    let c = w.config(&format!(
        "picture = true\n[[project]]\npath = \"{}\"\n",
        a.display()
    ));
    let d = InProc::with_config(&c);
    d.startup(&[&a]);
    let svg = a.join("Blackboard.svg");
    let listed = |evs: &[serde_json::Value], mark: u64| {
        evs.iter()
            .filter(|e| is_after(e, "compile-succeeded", &a, mark))
            .flat_map(|e| e["outputs"].as_array().unwrap().clone())
            .find(|o| o["path"] == svg.display().to_string())
    };
    let first = listed(&d.events(), 0).expect("the picture is an output");
    assert_eq!(first["written"], true);
    let text = fs::read_to_string(&svg).unwrap();
    roxmltree::Document::parse(&text).unwrap();
    assert!(text.contains(">cycle time 4.5 s<"), "{text}");
    // A step's time changes: a new picture, the programs stay.
    let mark = d.mark();
    let sfc = fs::read_to_string(a.join("sfc.xml")).unwrap();
    fs::write(
        a.join("sfc.xml"),
        sfc.replacen(r#"<time duration="2"/>"#, r#"<time duration="3"/>"#, 1),
    )
    .unwrap();
    let evs = d.wait_for("the compile", WAIT, |e| {
        is_after(e, "compile-succeeded", &a, mark)
    });
    let e = evs
        .iter()
        .find(|e| is_after(e, "compile-succeeded", &a, mark))
        .unwrap();
    let outs = e["outputs"].as_array().unwrap();
    assert!(
        outs.iter()
            .any(|o| o["path"] == svg.display().to_string() && o["written"] == true)
    );
    assert!(
        outs.iter()
            .filter(|o| o["path"] != svg.display().to_string())
            .all(|o| o["written"] == false),
        "{e}"
    );
    assert!(read_string(&svg).contains(">cycle time 5.5 s<"));
    // Its own write starts nothing.
    std::thread::sleep(std::time::Duration::from_millis(SETTLE_MS * 8));
    assert_eq!(count_after(&d.events(), "compile-started", &a, mark), 1);
    d.stop(WAIT);
}

#[test]
fn a_picture_named_like_an_input_is_refused_and_the_input_kept() {
    let (tmp, bb, program) = materialize("reference-sample");
    let sfc = tmp.path().join("sfc.xml");
    let before = fs::read(&sfc).unwrap();
    let o = svg(&bb, &program, &sfc);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("E605"));
    assert_eq!(fs::read(&sfc).unwrap(), before, "the SFC is untouched");
}
