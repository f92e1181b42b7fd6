//! A large SFC is read in two halves at once (`read/sfc/split.rs`): the second half from a split
//! place on, through a second reader of the same open file, taken only where it read what a
//! reading from the start would have. The model and the diagnostics must be the same as a
//! plain reading's wherever the split place is: at every tag of every XML fixture (charts with
//! named transitions, wired conditions, macro steps, actions, several POUs, errors), inside
//! comments, CDATA and attribute values, and in a generated 2,000-step chart. A file that
//! changes between the two readings is an error, never a model mixed from two files. And the
//! compile takes the split for a large file on disk, with the same programs as without it.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use skillpost::diag::Diagnostics;
use skillpost::read::sfc::{SplitSource, StreamError, read_sfc_stream_split};
use skillpost::read::tape::{BATCH_BYTES, Pipeline};

mod common;
#[path = "../benches/common/generator.rs"]
mod generator;

fn text_of(sfc: Result<Option<skillpost::model::Sfc>, StreamError>, diags: Diagnostics) -> String {
    format!("{sfc:#?}\n{:#?}", diags.into_vec())
}

/// The plain reading: one batch, in the reader's thread.
fn plain(text: &[u8], pou: Option<&str>) -> String {
    let mut diags = Diagnostics::default();
    let sfc = read_sfc_stream_split(
        text,
        0,
        text.len() as u64,
        pou,
        &mut diags,
        Pipeline::Inline,
        usize::MAX,
        None,
    );
    text_of(sfc, diags)
}

/// The reading split at `at` (the second reader reads `second`): its result, and whether the
/// second half's was taken.
fn split(
    text: &[u8],
    second: &[u8],
    at: Option<usize>,
    pipeline: Pipeline,
    batch: usize,
    pou: Option<&str>,
) -> (String, bool) {
    let joined = AtomicBool::new(false);
    let mut diags = Diagnostics::default();
    let sfc = read_sfc_stream_split(
        text,
        0,
        text.len() as u64,
        pou,
        &mut diags,
        pipeline,
        batch,
        Some(SplitSource {
            source: &second,
            skipped: 0,
            at,
            joined: Some(&joined),
        }),
    );
    (text_of(sfc, diags), joined.load(Ordering::Relaxed))
}

/// Reads `text` split at each of `places`, in two ways, and compares with the plain reading;
/// how many splits were taken.
fn same_at(name: &str, text: &[u8], places: &[usize], pou: Option<&str>) -> usize {
    let expected = plain(text, pou);
    let mut joined = 0;
    for (i, &at) in places.iter().enumerate() {
        // In turn: the first half inline in small batches (the split place cuts many pieces'
        // worth of carried bytes), and on its own thread in the compile's batches.
        let (pipeline, batch) = if i % 2 == 0 {
            (Pipeline::Inline, 64)
        } else {
            (Pipeline::Threaded, BATCH_BYTES)
        };
        let (got, taken) = split(text, text, Some(at), pipeline, batch, pou);
        assert!(
            got == expected,
            "{name}: split at byte {at} ({:?}…) differs from the plain reading",
            String::from_utf8_lossy(&text[at..(at + 40).min(text.len())])
        );
        joined += usize::from(taken);
    }
    joined
}

/// Every `<` of `text`, at most about `max` of them (evenly spread), and some places that are
/// no tag's start.
fn places(text: &[u8], max: usize) -> Vec<usize> {
    let tags: Vec<usize> = (1..text.len()).filter(|&i| text[i] == b'<').collect();
    let step = tags.len().div_ceil(max).max(1);
    let mut out: Vec<usize> = tags.into_iter().step_by(step).collect();
    out.extend((1..text.len()).step_by((text.len() / 8).max(1)));
    out
}

#[test]
fn every_fixture_reads_the_same_split_at_any_place() {
    let (mut joined, mut tried) = (0, 0);
    for (name, text) in common::fixture_xml() {
        let at = places(&text, 150);
        tried += at.len();
        joined += same_at(&name, &text, &at, None);
    }
    // Both ways are exercised: the second half taken, and read on from the split place.
    assert!(joined > 500, "second halves taken: {joined} of {tried}");
    assert!(
        tried - joined > 500,
        "read on: {} of {tried}",
        tried - joined
    );
}

/// A generated SFC of 2,000 skill steps with parallel branches, selections and a loop.
fn generated() -> Vec<u8> {
    generator::sfc_text(&generator::Spec {
        steps: 2000,
        branch_every: 40,
        branch_width: 3,
        select_every: 15,
        looped: true,
    })
    .into_bytes()
}

#[test]
fn a_generated_chart_split_at_any_element_is_joined_and_reads_the_same() {
    let text = generated();
    let s = String::from_utf8_lossy(&text);
    let elements: Vec<usize> = s
        .match_indices("<step ")
        .chain(s.match_indices("<transition "))
        .map(|(i, _)| i)
        .step_by(37)
        .collect();
    assert!(elements.len() > 100);
    let joined = same_at("generated", &text, &elements, None);
    assert_eq!(
        joined,
        elements.len(),
        "every element of the chart's body is a place the second half is taken"
    );
    // And a POU asked for that is not there: the same errors.
    same_at("a missing POU", &text, &elements[..10], Some("NoSuchPou"));
}

/// Places where the second half cannot be taken: it reads on, with the same result.
#[test]
fn a_split_place_the_second_half_cannot_start_at_reads_on() {
    let text = generated();
    let cases = [
        ("in a comment", "<!-- <step localId=\"1\"> -->", "<step"),
        (
            "in CDATA",
            "<transition localId=\"99990\"><condition><inline><ST><xhtml><![CDATA[ <step a> ]]></xhtml></ST></inline></condition></transition>",
            "<step a>",
        ),
        (
            "inside a step",
            "<step localId=\"99991\" name=\"x\"><connectionPointIn><connection refLocalId=\"1\"/></connectionPointIn></step>",
            "<connectionPointIn>",
        ),
        (
            "in a macro step's body",
            "<macroStep localId=\"99992\"><body><SFC><step localId=\"99993\" initialStep=\"true\" name=\"m\"/></SFC></body></macroStep>",
            "<step localId=\"99993\"",
        ),
        (
            "at an element the reader ignores",
            "<comment localId=\"99994\"><content/></comment>",
            "<comment",
        ),
        (
            "at a wired condition's part",
            "<inVariable localId=\"99995\"><expression>go</expression></inVariable>",
            "<inVariable",
        ),
    ];
    for (name, insert, needle) in cases {
        let (t, at) = common::with_after_step_at(&text, 1000, insert.as_bytes());
        let place = at + insert.find(needle).expect("the place");
        assert_eq!(t[place], b'<', "{name}: the place is a `<`");
        let expected = plain(&t, None);
        for (pipeline, batch) in [(Pipeline::Inline, 64), (Pipeline::Threaded, BATCH_BYTES)] {
            let (got, joined) = split(&t, &t, Some(place), pipeline, batch, None);
            assert!(got == expected, "{name}: differs from the plain reading");
            assert!(!joined, "{name}: the second half is not taken");
        }
    }
}

/// A POU with named transitions: a second half would read a condition that names one as a
/// signal (it has not seen them), so it is not taken.
#[test]
fn a_chart_with_named_transitions_is_not_joined() {
    let text = generated();
    let s = String::from_utf8_lossy(&text).into_owned();
    let pou = s.find("<body>").expect("a body");
    let named = "<transitions><transition name=\"T1\"><body><ST><xhtml xmlns=\"http://www.w3.org/1999/xhtml\">go</xhtml></ST></body></transition></transitions>";
    let t = format!("{}{named}{}", &s[..pou], &s[pou..]);
    let at = t
        .match_indices("<transition localId")
        .nth(500)
        .expect("transitions")
        .0;
    // A transition after the split place takes its condition from the named one.
    let cond = at + t[at..].find("<condition>").expect("a condition");
    let cond_end = cond + t[cond..].find("</condition>").expect("its end");
    let t = format!(
        "{}<condition><reference name=\"T1\"/>{}",
        &t[..cond],
        &t[cond_end..]
    )
    .into_bytes();
    let expected = plain(&t, None);
    assert!(
        expected.contains("text: \"go\""),
        "the named transition's condition is read"
    );
    let (got, joined) = split(&t, &t, Some(at), Pipeline::Threaded, BATCH_BYTES, None);
    assert!(got == expected);
    assert!(!joined);
}

/// The second reader sees other bytes than the stream (the file was written in place between
/// the two readings): an error, not a model made of both.
#[test]
fn a_file_changed_between_the_two_readings_is_an_error() {
    let text = generated();
    let s = String::from_utf8_lossy(&text).into_owned();
    let at = s.match_indices("<step ").nth(1000).expect("steps").0;
    // The same length, one skill renamed after the split place.
    let later = s[at..].find("skill name=\"").expect("a skill") + at + 12;
    let mut changed = text.clone();
    changed[later] = if changed[later] == b'X' { b'Y' } else { b'X' };
    let (got, joined) = split(
        &text,
        &changed,
        Some(at),
        Pipeline::Threaded,
        BATCH_BYTES,
        None,
    );
    assert!(joined, "the second half read its part");
    assert!(
        got.starts_with("Err(") && got.contains("it changed while it was being read; run again"),
        "the reading fails: {}",
        got.lines().take(3).collect::<Vec<_>>().join("\n")
    );
}

/// The second reader finds the file shorter (cut meanwhile): the second half ends without the
/// SFC's end tag, is not taken, and the first half reads on.
#[test]
fn a_file_cut_short_for_the_second_reader_is_read_on() {
    let text = generated();
    let s = String::from_utf8_lossy(&text).into_owned();
    let at = s.match_indices("<step ").nth(1000).expect("steps").0;
    let (got, joined) = split(
        &text,
        &text[..at + 5000],
        Some(at),
        Pipeline::Threaded,
        BATCH_BYTES,
        None,
    );
    assert!(!joined, "the second half is not taken");
    assert!(got == plain(&text, None), "the first half read on");
}

/// A file of 8 MiB or more gets its split place chosen, and is joined.
#[test]
fn a_large_file_is_split_where_the_reader_chooses() {
    let text = generator::sfc_text(&generator::Spec::flat(12_000)).into_bytes();
    assert!(text.len() as u64 >= skillpost::read::sfc::SPLIT_FROM);
    let (got, joined) = split(&text, &text, None, Pipeline::Threaded, BATCH_BYTES, None);
    assert!(joined, "the second half is taken");
    assert!(got == plain(&text, None), "the same model and diagnostics");
}

/// Through the binary: a large project compiled from disk (read in two halves) writes the
/// programs a compile that reads its SFC as one stream writes.
#[test]
fn the_compile_of_a_large_project_writes_the_same_programs_split() {
    let dir = tempfile::tempdir().unwrap();
    let project = generator::write_project(dir.path(), &generator::Spec::flat(12_000)).unwrap();
    assert!(std::fs::metadata(&project.sfc).unwrap().len() >= skillpost::read::sfc::SPLIT_FROM);
    // The library's compile with a source that offers no second reader.
    let whole = tempfile::tempdir().unwrap();
    for f in [&project.blackboard, &project.sfc, &project.irl] {
        std::fs::copy(f, whole.path().join(f.file_name().unwrap())).unwrap();
    }
    struct OneStream(skillpost::load::FsSource);
    impl skillpost::load::FileSource for OneStream {
        fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
            self.0.read(path)
        }
        fn open(&self, path: &Path) -> std::io::Result<skillpost::load::Opened<'_>> {
            let mut o = self.0.open(path)?;
            o.at = None;
            Ok(o)
        }
    }
    let opts = skillpost::compile::Options {
        program: Some("out".into()),
        ..Default::default()
    };
    let c = skillpost::compile::compile(
        &OneStream(skillpost::load::FsSource::default()),
        &whole.path().join(generator::BLACKBOARD_FILE),
        &opts,
    );
    assert!(
        !c.diagnostics
            .iter()
            .any(|d| d.severity == skillpost::diag::Severity::Error),
        "the compile without a split"
    );
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
        .arg(&project.blackboard)
        .arg("out")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        c.outputs.len() >= 2,
        "programs compared: {}",
        c.outputs.len()
    );
    for (path, file) in &c.outputs {
        let name = path.file_name().unwrap();
        assert!(
            std::fs::read_to_string(dir.path().join(name)).unwrap() == file.text,
            "{}: the binary wrote what the compile without a split made",
            name.to_string_lossy()
        );
    }
}
