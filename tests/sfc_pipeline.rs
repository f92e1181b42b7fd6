//! The SFC reader gets its XML events from a producer: on a second thread for a large file, in
//! its own thread for a small one (`skillpost::read::tape`), in batches. The model and the
//! diagnostics must not depend on which, nor on where the batches are cut: every way is compared
//! with the plain one (in the reader's thread, one batch for the whole file) over every XML
//! fixture, a generated 2,000-step project with branches, selections and a loop, and files that
//! go wrong in the middle (syntax, UTF-8, a DTD, the end of the file).

use skillpost::diag::Diagnostics;
use skillpost::read::sfc::read_sfc_stream_with;
use skillpost::read::tape::Pipeline;

mod common;
use common::with_after_step;
#[path = "../benches/common/generator.rs"]
mod generator;

/// The model or the reason it stopped, and the diagnostics, as text.
fn read(text: &[u8], pipeline: Pipeline, batch: usize, pou: Option<&str>) -> String {
    let mut diags = Diagnostics::default();
    let sfc = read_sfc_stream_with(text, 0, text.len() as u64, pou, &mut diags, pipeline, batch);
    format!("{sfc:#?}\n{:#?}", diags.into_vec())
}

/// Every way gives what the plain way gives.
fn same_every_way(name: &str, text: &[u8], pou: Option<&str>) {
    let plain = read(text, Pipeline::Inline, usize::MAX, pou);
    for (pipeline, batch) in [
        (Pipeline::Inline, 1),
        (Pipeline::Inline, 100),
        (Pipeline::Threaded, 1),
        (Pipeline::Threaded, 64),
        (Pipeline::Threaded, 4096),
        (Pipeline::Threaded, usize::MAX),
    ] {
        let other = read(text, pipeline, batch, pou);
        assert!(
            other == plain,
            "{name}: {pipeline:?} in batches of {batch} bytes differs from one batch in the reader's thread"
        );
    }
}

#[test]
fn every_fixture_reads_the_same_every_way() {
    for (name, text) in common::fixture_xml() {
        same_every_way(&name, &text, None);
    }
}

/// A generated SFC of 2,000 skill steps with parallel branches, selections and a loop (about
/// 1.6 MB: the compile would read it on a second thread).
fn generated() -> Vec<u8> {
    let spec = generator::Spec {
        steps: 2000,
        branch_every: 40,
        branch_width: 3,
        select_every: 15,
        looped: true,
    };
    generator::sfc_text(&spec).into_bytes()
}

#[test]
fn a_large_sfc_reads_the_same_every_way() {
    let text = generated();
    assert!(text.len() as u64 >= skillpost::read::tape::THREAD_FROM);
    same_every_way("generated", &text, None);
    // And the compile's own choice for its size is the second thread.
    assert_eq!(
        Pipeline::choose(text.len() as u64),
        Pipeline::Threaded,
        "a file this large is read on two threads"
    );
    let threaded = read(
        &text,
        Pipeline::Threaded,
        skillpost::read::tape::BATCH_BYTES,
        None,
    );
    let ids = threaded.matches("local_id:").count();
    assert!(ids > 4000, "the model has every element: {ids} local ids");
}

#[test]
fn a_large_sfc_that_goes_wrong_in_the_middle_stops_the_same_every_way() {
    let text = generated();
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("a mismatched end tag", with_after_step(&text, 900, b"<a></b>")),
        ("an unclosed comment", with_after_step(&text, 900, b"<!-- ")),
        ("a bad attribute", with_after_step(&text, 900, b"<step localId=1/>")),
        (
            "a duplicated attribute",
            with_after_step(&text, 900, b"<step localId=\"9\" localId=\"9\"/>"),
        ),
        ("an unknown entity", with_after_step(&text, 900, b"&bogus;")),
        ("not UTF-8", with_after_step(&text, 900, b"\xFF\xFE")),
        ("a late DTD", with_after_step(&text, 900, b"<!DOCTYPE x>")),
        ("cut in half", text[..text.len() / 2].to_vec()),
        ("cut inside a tag", {
            let mut t = with_after_step(&text, 900, b"<step localId=\"");
            let end = String::from_utf8_lossy(&t).rfind("<step localId=\"").unwrap() + 15;
            t.truncate(end);
            t
        }),
        (
            "conditions with entities and CDATA",
            with_after_step(
                &text,
                900,
                b"<transition localId=\"99999\"><condition><inline name=\"c\"><ST><xhtml>a &amp;&#32;b<![CDATA[ AND <c> ]]>&lt;d&gt;</xhtml></ST></inline></condition></transition>",
            ),
        ),
    ];
    for (name, t) in cases {
        same_every_way(name, &t, None);
    }
}

#[test]
fn a_pou_asked_for_by_name_reads_the_same_every_way() {
    let text = generated();
    same_every_way("a missing POU", &text, Some("NoSuchPou"));
}
