//! The plan as a picture (`skillpost --svg FILE`, issue 28, issue 36): for fixtures with one
//! controller, two controllers, selections and loops, through the binary: a snapshot of the
//! SVG, the SVG parsed as XML, the same bytes from a second run, and the picture rendered by
//! resvg with every lane (controller) and every step's name and localId found among its texts.
//! Every picture is checked readable (no two texts overlap, none is cut by a box or the
//! picture's edge, by the rendered text's own extents) and as wide as what it draws (the
//! rightmost thing drawn ends within a small margin of the width); in a cell, its arrows are
//! the programs' handshakes (one per tell `-pO --format json` lists, between the same
//! controllers: also each alternative's decision of a selection or a loop), and its title
//! names every program by its main file and controller. Every cell fixture, and the cell
//! charts with their robots' steps moved between the robots every way, are drawn so too.

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
    language: Option<String>,
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
    // Each program by its main file.
    let programs = case
        .cell
        .into_iter()
        .map(|c| {
            let ext = match c.language.as_deref() {
                Some("RAPID") => "mod",
                Some("URScript") => "script",
                _ => "src",
            };
            format!("{}.{ext}", c.program)
        })
        .collect();
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

/// The picture as resvg draws it: each text with its box (the advance widths and the font's
/// line height, in canvas coordinates), where the rightmost thing drawn ends (the background
/// and the lanes' frames, which span the width, left out), and the size.
struct Rendered {
    texts: Vec<(String, resvg::tiny_skia::Rect)>,
    right: f32,
    width: f32,
    height: f32,
}

impl Rendered {
    fn texts(&self) -> Vec<String> {
        self.texts.iter().map(|(t, _)| t.clone()).collect()
    }
}

/// Renders `svg` with resvg (a picture of the whole size, not blank) and reads its texts.
fn render(svg: &str) -> Rendered {
    let mut opt = resvg::usvg::Options::default();
    opt.fontdb_mut().load_system_fonts();
    let tree = resvg::usvg::Tree::from_str(svg, &opt).expect("usvg reads the SVG");
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
    let (width, height) = (tree.size().width(), tree.size().height());
    let mut out = Rendered {
        texts: Vec::new(),
        right: 0.0,
        width,
        height,
    };
    fn walk(g: &resvg::usvg::Group, out: &mut Rendered) {
        for n in g.children() {
            match n {
                resvg::usvg::Node::Group(g) => walk(g, out),
                resvg::usvg::Node::Text(t) => {
                    let b = t.abs_bounding_box();
                    out.right = out.right.max(b.right());
                    out.texts.push((
                        t.chunks()
                            .iter()
                            .map(|c| c.text().to_owned())
                            .collect::<Vec<_>>()
                            .join(""),
                        b,
                    ));
                }
                n => {
                    let b = n.abs_stroke_bounding_box();
                    if b.width() < out.width - 20.0 {
                        out.right = out.right.max(b.right());
                    }
                }
            }
        }
    }
    walk(tree.root(), &mut out);
    out
}

/// Every text of the rendered tree (usvg keeps each `text` element's characters).
fn texts(svg: &str) -> Vec<String> {
    render(svg).texts()
}

/// The boxes of steps and waits and the diamonds of steps without a time, from the SVG's
/// elements (no transforms: their coordinates are the canvas').
fn boxes(svg: &str) -> Vec<(f32, f32, f32, f32)> {
    let doc = roxmltree::Document::parse(svg).unwrap();
    let num = |n: roxmltree::Node, a: &str| n.attribute(a).unwrap().parse::<f32>().unwrap();
    let mut out = Vec::new();
    for g in doc.descendants().filter(|n| {
        n.has_tag_name("g")
            && n.attribute("class")
                .is_some_and(|c| c.starts_with("step") || c == "wait")
    }) {
        for e in g.children().filter(|e| e.is_element()) {
            if e.has_tag_name("rect") {
                let (x, y) = (num(e, "x"), num(e, "y"));
                out.push((x, y, x + num(e, "width"), y + num(e, "height")));
            } else if e.has_tag_name("path") {
                let v: Vec<f32> = e
                    .attribute("d")
                    .unwrap()
                    .split_whitespace()
                    .filter_map(|w| w.parse().ok())
                    .collect();
                let xs = v.iter().step_by(2);
                let ys = v.iter().skip(1).step_by(2);
                out.push((
                    xs.clone().copied().fold(f32::INFINITY, f32::min),
                    ys.clone().copied().fold(f32::INFINITY, f32::min),
                    xs.copied().fold(f32::NEG_INFINITY, f32::max),
                    ys.copied().fold(f32::NEG_INFINITY, f32::max),
                ));
            }
        }
    }
    out
}

/// Every text readable: no two texts overlap, none runs out of the picture, and each lies
/// wholly inside a step's or wait's box (or diamond) or clear of it.
fn assert_readable(name: &str, svg: &str, r: &Rendered) {
    const EPS: f32 = 0.5;
    let meet = |a: (f32, f32, f32, f32), b: (f32, f32, f32, f32)| {
        a.0 < b.2 - EPS && b.0 < a.2 - EPS && a.1 < b.3 - EPS && b.1 < a.3 - EPS
    };
    let within = |a: (f32, f32, f32, f32), b: (f32, f32, f32, f32)| {
        a.0 >= b.0 - EPS && a.2 <= b.2 + EPS && a.1 >= b.1 - EPS && a.3 <= b.3 + EPS
    };
    let rect = |b: &resvg::tiny_skia::Rect| (b.left(), b.top(), b.right(), b.bottom());
    for (k, (t, b)) in r.texts.iter().enumerate() {
        let a = rect(b);
        assert!(
            within(a, (0.0, 0.0, r.width, r.height)),
            "{name}: `{t}` {a:?} runs out of the picture ({} x {})",
            r.width,
            r.height
        );
        for (u, c) in &r.texts[k + 1..] {
            assert!(
                !meet(a, rect(c)),
                "{name}: `{t}` {a:?} overlaps `{u}` {:?}",
                rect(c)
            );
        }
        for bx in boxes(svg) {
            assert!(
                within(a, bx) || !meet(a, bx),
                "{name}: `{t}` {a:?} is cut by the box {bx:?}"
            );
        }
    }
}

/// As wide as what it draws: the rightmost thing ends within a small margin of the width.
fn assert_fits(name: &str, r: &Rendered) {
    assert!(
        r.right <= r.width && r.width - r.right <= 24.0,
        "{name}: the picture is {} wide, what it draws ends at {}",
        r.width,
        r.right
    );
}

/// The handshakes the programs do, as `-pO --format json` lists them: (teller, hearer) of
/// every tell, sorted.
fn tells(bb: &Path, program: &str) -> Vec<(String, String)> {
    let o = Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .args(["--validate", "-pO", "--format", "json"])
        .arg(bb)
        .arg(program)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8(o.stdout).unwrap();
    let listing: serde_json::Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
    fn walk(v: &serde_json::Value, teller: &str, out: &mut Vec<(String, String)>) {
        match v {
            serde_json::Value::Object(m) => {
                if m.get("kind").and_then(|k| k.as_str()) == Some("tell") {
                    out.push((
                        teller.to_owned(),
                        m["controller"].as_str().unwrap().to_owned(),
                    ));
                }
                for v in m.values() {
                    walk(v, teller, out);
                }
            }
            serde_json::Value::Array(a) => {
                for v in a {
                    walk(v, teller, out);
                }
            }
            _ => {}
        }
    }
    let mut out = Vec::new();
    for p in listing["programs"].as_array().into_iter().flatten() {
        walk(&p["blocks"], p["controller"].as_str().unwrap(), &mut out);
    }
    out.sort();
    out
}

/// The picture's handshake arrows: (teller, hearer) of each, from its title, sorted; and how
/// many `<line class="handshake">` there are.
fn arrows(svg: &str) -> (Vec<(String, String)>, usize) {
    let doc = roxmltree::Document::parse(svg).unwrap();
    let lines: Vec<_> = doc
        .descendants()
        .filter(|n| n.attribute("class") == Some("handshake"))
        .collect();
    let mut out: Vec<(String, String)> = lines
        .iter()
        .map(|l| {
            let title = l
                .children()
                .find(|c| c.has_tag_name("title"))
                .and_then(|t| t.text())
                .unwrap();
            let (who, _) = title.split_once(": ").unwrap();
            let (teller, hearer) = who.split_once(" tells ").unwrap();
            (teller.to_owned(), hearer.to_owned())
        })
        .collect();
    out.sort();
    (out, lines.len())
}

/// The picture's title (the SVG's `title`, also drawn on top).
fn title(svg: &str) -> String {
    let doc = roxmltree::Document::parse(svg).unwrap();
    doc.root_element()
        .children()
        .find(|c| c.has_tag_name("title"))
        .and_then(|t| t.text())
        .unwrap()
        .to_owned()
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
    let svg = check_drawn(name, lanes);
    insta::assert_snapshot!(name, svg);
}

/// [`check`] without the snapshot: the SVG.
fn check_drawn(name: &str, lanes: usize) -> String {
    let (tmp, bb, program, files) = materialize_cell(name);
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
    let rendered = render(&svg);
    let texts = rendered.texts();
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
    assert_eq!(files.len(), if lanes > 1 { lanes } else { 0 }, "{name}");
    for f in &files {
        let p = f.rsplit_once('.').unwrap().0;
        assert!(
            texts.iter().any(|t| t == p),
            "{name}: lane of {p} not in {texts:?}"
        );
    }
    assert!(texts.iter().any(|t| t.starts_with("cycle time ")), "{name}");
    // Readable, as wide as it needs.
    assert_readable(name, &svg, &rendered);
    assert_fits(name, &rendered);
    // Every handshake the programs do is an arrow, between the same controllers.
    let (drawn, count) = arrows(&svg);
    if lanes > 1 {
        assert_eq!(drawn, tells(&bb, &program), "{name}: arrows and tells");
    }
    assert_eq!(count, drawn.len(), "{name}");
    // The title names every program (by its main file and controller) and the chart.
    let title = title(&svg);
    assert!(texts.contains(&title), "{name}: {title} not drawn");
    assert_eq!(title.starts_with("Cell: "), lanes > 1, "{name}: {title}");
    for f in &files {
        assert!(
            title.contains(&format!("{f} (")),
            "{name}: {f} not in {title}"
        );
    }
    svg
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

/// Every cell fixture: readable, as wide as it needs, an arrow for each tell of its programs
/// (a loop's decision, a selection's, the states' barriers, sequences without any), its title.
#[test]
fn every_cell_fixture() {
    let ok = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ok");
    let mut drawn = 0;
    for e in fs::read_dir(&ok).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        let case: Case =
            toml::from_str(&fs::read_to_string(ok.join(&name).join("case.toml")).unwrap()).unwrap();
        if case.cell.len() > 1 {
            check_drawn(&name, case.cell.len());
            drawn += 1;
        }
    }
    assert!(drawn >= 7, "{drawn} cells");
}

/// A loop whose decision one controller takes and another follows (the second robot decides
/// whether the first picks again): each alternative's decision is an arrow to the follower,
/// dashed, on its alternative's row; so is every other handshake.
#[test]
fn a_loops_decision_is_an_arrow_on_each_alternatives_row() {
    let (tmp, bb, program, _) = materialize_cell("cell-two-robots-weld");
    let svg = draw(&bb, &program, &tmp.path().join("plan.svg"));
    let doc = roxmltree::Document::parse(&svg).unwrap();
    let decisions: Vec<_> = doc
        .descendants()
        .filter(|n| n.attribute("class") == Some("handshake"))
        .filter(|n| n.attribute("stroke-dasharray").is_some())
        .collect();
    let titles: Vec<&str> = decisions
        .iter()
        .filter_map(|n| n.children().find(|c| c.has_tag_name("title"))?.text())
        .collect();
    assert_eq!(
        titles,
        [
            "KUKA KR16-2 tells KUKA KR15-2: branch 1 taken at the selection id=13",
            "KUKA KR16-2 tells KUKA KR15-2: branch 2 taken at the selection id=13",
        ]
    );
    // Two rows, two ends.
    let y2: Vec<&str> = decisions
        .iter()
        .map(|n| n.attribute("y2").unwrap())
        .collect();
    assert_ne!(y2[0], y2[1]);
    // Before: the arrows went from step to step across lanes only (2 of the 5 handshakes).
    assert_eq!(arrows(&svg).1, 5);
    assert_eq!(tells(&bb, &program).len(), 5);
}

/// The title names every program of a cell, by its main file and controller, and the chart.
#[test]
fn the_title_names_every_program() {
    let (tmp, bb, program, _) = materialize_cell("cell-kuka-abb-ur");
    let svg = draw(&bb, &program, &tmp.path().join("plan.svg"));
    let want = "Cell: Mix_KUKA_KR15_2.src (KUKA KR15-2), Mix_ABB_IRB_1200.mod (ABB IRB 1200), Mix_UR10e.script (UR10e): the chart of Demo";
    assert_eq!(title(&svg), want);
    assert!(texts(&svg).iter().any(|t| t == want));
    // One program: its file and controller.
    let (tmp, bb, program) = materialize("reference-sample");
    let svg = draw(&bb, &program, &tmp.path().join("plan.svg"));
    assert_eq!(title(&svg), "output.src (KUKA KR15-2): the chart of Demo");
}

/// Steps far shorter than their names (a handling robot's quick moves beside a long weld): no
/// name is cut or runs over another text; those that do not fit their box stand below it, tied
/// by a leader; the picture is no wider than what it draws.
#[test]
fn short_steps_keep_their_names_readable() {
    let (tmp, bb, program, _) = materialize_cell("cell-two-robots-weld");
    let sfc = tmp.path().join("sfc.xml");
    let mut text = fs::read_to_string(&sfc).unwrap();
    for (from, to) in [
        ("\"Pick\"", "\"Pick the housing from the conveyor\""),
        ("\"Grip\"", "\"Close the gripper\""),
        ("\"Weld\"", "\"Weld the first seam\""),
        ("\"PlaceA\"", "\"Place into fixture A\""),
        ("\"RetreatB\"", "\"Retreat to home B\""),
    ] {
        text = text
            .replace(&format!("name={from}>"), &format!("name={to}>"))
            .replace(&format!("targetName={from}"), &format!("targetName={to}"));
    }
    for (from, to) in [("1.5", "0.3"), ("1", "0.2"), ("4", "6"), ("2", "0.25")] {
        text = text.replace(
            &format!("<time duration=\"{from}\"/>"),
            &format!("<time duration=\"{to}\"/>"),
        );
    }
    fs::write(&sfc, text).unwrap();
    let svg = draw(&bb, &program, &tmp.path().join("plan.svg"));
    let r = render(&svg);
    assert_readable("short steps", &svg, &r);
    assert_fits("short steps", &r);
    let texts = r.texts();
    for (name, rest) in [
        ("Pick the housing from the conveyor", " Move PTP · id=3"),
        ("Close the gripper", " Close · id=5"),
        ("Place into fixture A", " Move LIN · id=10"),
        ("Retreat to home B", " Move LIN · id=11"),
    ] {
        assert!(
            texts.contains(&format!("{name}{rest}")),
            "{name} below its box: {texts:?}"
        );
    }
    assert!(
        texts.iter().any(|t| t == "Weld the first seam"),
        "{texts:?}"
    );
    assert_eq!(svg.matches(r#"<line class="leader""#).count(), 7, "{svg}");
    assert_eq!(arrows(&svg).0, tells(&bb, &program));
}

/// The cell fixtures' charts with their robots' steps moved between the two robots in every
/// way (the eight wires each way of `cell-eight-wires`; a way the compiler refuses, such as a
/// selection decided where its signal is not, is left out): an arrow for every tell, between
/// the same controllers, and every text readable.
#[test]
fn steps_moved_between_the_robots_keep_an_arrow_per_tell() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let robots = [
        r#"<ressource name="KUKA KR15-2"/>"#,
        r#"<ressource name="KUKA KR16-2"/>"#,
    ];
    let (mut compiled, mut cells) = (0, 0);
    for chart in [
        "fixtures/base/cell2/sfc.xml",
        "fixtures/ok/cell-tell-at-once/sfc.xml",
        "fixtures/ok/cell-flow-states/sfc.xml",
    ] {
        let text = fs::read_to_string(repo.join(chart)).unwrap();
        let pieces: Vec<&str> = text
            .split(robots[0])
            .flat_map(|p| p.split(robots[1]))
            .collect();
        let moves = pieces.len() - 1;
        for mask in 0..1u32 << moves {
            let (tmp, bb, program, _) = materialize_cell("cell-eight-wires");
            let mut moved = pieces[0].to_owned();
            for (k, p) in pieces[1..].iter().enumerate() {
                moved.push_str(robots[(mask >> k & 1) as usize]);
                moved.push_str(p);
            }
            fs::write(tmp.path().join("sfc.xml"), moved).unwrap();
            let out = tmp.path().join("plan.svg");
            if !svg(&bb, &program, &out).status.success() {
                continue;
            }
            compiled += 1;
            let what = format!("{chart} moved {mask:b}");
            let svg = fs::read_to_string(&out).unwrap();
            let (drawn, _) = arrows(&svg);
            let told = tells(&bb, &program);
            cells += usize::from(!told.is_empty());
            assert_eq!(drawn, told, "{what}: arrows and tells");
            let r = render(&svg);
            assert_readable(&what, &svg, &r);
            assert_fits(&what, &r);
        }
    }
    println!("{compiled} charts compiled, {cells} of them cells");
    assert!(
        compiled >= 12 && cells >= 8,
        "{compiled} compiled, {cells} cells"
    );
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
