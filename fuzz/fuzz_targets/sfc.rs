//! The SFC reader: bytes → `read::xml::load` → `read_sfc` (the streaming reader) → `plan::plan`
//! → the listings; every variable the reader accepted parses and looks up; the program tree's
//! invariants (each step once, waits and branches on transitions, loops start at their head);
//! the diagnostics in every format; the same model and diagnostics however the events were
//! produced (`read::tape`) or whether the file was read in two halves (`read/sfc/split.rs`),
//! and those events and the attributes the reader reads itself are quick-xml's.
#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;
use skillpost::model::ElementKind;
use skillpost::read::sfc::read_sfc;
use skillpost::value::{Lookup, lookup, parse_value};
use skillpost::{plan, print};

fuzz_target!(|data: &[u8]| {
    let (sources, mut diags, file) = common::load("/p/sfc.xml", data);
    let mut sfc = file.and_then(|f| read_sfc(&sources, f, &mut diags));
    // Connections back to earlier steps made jumps, as the compile does.
    if let Some(s) = &mut sfc {
        plan::close_circles(s);
    }
    if let Some(sfc) = &sfc {
        let _ = print::sfc(sfc);
        for e in &sfc.elements {
            if let ElementKind::Step(step) = &e.kind {
                for v in sfc.variables_of(step) {
                    let raw = sfc.raw(v);
                    // The reader keeps only values whose syntax it checked.
                    assert!(
                        parse_value(raw).is_ok(),
                        "the reader kept a malformed value: {raw:?}"
                    );
                    let _ = sfc.value_of(v);
                    for path in [&[][..], &[0], &[1, 0], &[0, 2, 1]] {
                        if let Lookup::Scalar(s) = lookup(raw, path) {
                            assert!(raw.contains(s));
                        }
                    }
                }
            }
        }
        if let Some(p) = plan::plan(sfc, &mut diags) {
            let steps = p.steps();
            for &i in &steps {
                assert!(
                    sfc.elements[i].kind.is_step(),
                    "plan step {i} is not a step"
                );
            }
            // Each step once; waits and branch conditions are transitions; loops start at
            // their head step.
            let mut seen = vec![false; sfc.elements.len()];
            for &i in &steps {
                assert!(!seen[i], "plan step {i} twice");
                seen[i] = true;
            }
            // Several initial steps: one sequence each, side by side at the top.
            match p.body.as_slice() {
                [plan::Block::Sequences(seqs)] => assert_eq!(seqs.len(), p.sequences.len()),
                _ => assert_eq!(p.sequences.len(), 1),
            }
            let (mut gotos, mut machines) = (Vec::new(), Vec::new());
            plan::visit(&p.body, &mut |b| match b {
                plan::Block::Wait(t) => assert!(matches!(
                    sfc.elements[*t].kind,
                    ElementKind::Transition(Some(_))
                )),
                plan::Block::Choice { branches, .. } => {
                    // A branch starts with its transition, or opens another selection.
                    for br in branches {
                        assert!(matches!(
                            sfc.elements[br.transition].kind,
                            ElementKind::Transition(_) | ElementKind::SelectionDivergence
                        ));
                        for h in br.heads() {
                            assert!(matches!(
                                sfc.elements[h].kind,
                                ElementKind::Transition(_)
                            ));
                        }
                    }
                }
                // Each state begins where a Goto of its machine goes, and every Goto goes to a
                // state.
                plan::Block::Machine(states) => {
                    let entries: Vec<usize> = states.iter().map(|s| s.entry).collect();
                    for st in states {
                        plan::visit(&st.body, &mut |x| {
                            if let plan::Block::Goto { target, .. } = x {
                                gotos.push(*target);
                            }
                        });
                    }
                    machines.extend(entries);
                }
                plan::Block::Loop { head, body, .. } => {
                    assert_eq!(body.first(), Some(&plan::Block::Step(*head)));
                }
                _ => {}
            });
            for g in &gotos {
                assert!(machines.contains(g), "a Goto to {g}, which begins no state");
            }
            let _ = print::flow(sfc, &p);
            let _ = print::order(sfc, &p);
        }
    }
    let mut diags = diags;
    diags.sort();
    common::render_all(&diags.into_vec(), &sources);
    same_every_way(data);
});

/// The reader's model and diagnostics do not depend on how its events were produced: in its own
/// thread in one batch, or in batches of a few bytes (on a second thread for every fourth input).
fn same_every_way(data: &[u8]) {
    use skillpost::read::sfc::read_sfc_stream_with;
    use skillpost::read::tape::Pipeline;
    let read = |pipeline, batch| {
        let mut d = skillpost::diag::Diagnostics::default();
        let r = read_sfc_stream_with(data, 0, data.len() as u64, None, &mut d, pipeline, batch);
        format!("{r:?}\n{:?}", d.into_vec())
    };
    // The events of pieces of a few bytes are quick-xml's over the whole input (with the one
    // difference `reference_text` names).
    let pieces = skillpost::read::tape::records_text(data, data.len() % 29 + 1);
    let whole = skillpost::read::tape::reference_text(data);
    assert!(pieces == whole, "pieces:\n{pieces}\nwhole:\n{whole}");
    // Attributes read by the reader itself are quick-xml's.
    if let Ok(text) = std::str::from_utf8(data) {
        let mut reader = quick_xml::Reader::from_str(text);
        while let Ok(ev) = reader.read_event() {
            match ev {
                quick_xml::events::Event::Start(e) | quick_xml::events::Event::Empty(e) => {
                    if let Err(e) = skillpost::read::tape::compare_attributes(&e) {
                        panic!("{e}");
                    }
                }
                quick_xml::events::Event::Eof => break,
                _ => {}
            }
        }
    }
    let plain = read(Pipeline::Inline, usize::MAX);
    let (pipeline, batch) = if data.len() % 4 == 0 {
        (Pipeline::Threaded, data.len() % 61 + 1)
    } else {
        (Pipeline::Inline, data.len() % 13 + 1)
    };
    assert!(
        read(pipeline, batch) == plain,
        "{pipeline:?} in batches of {batch} bytes reads differently"
    );
    // Read in two halves, split at a place that depends on the input (at a `<` half of the
    // time): the same as the plain reading, whether the second half was taken or not.
    if data.len() > 1 {
        let mut at = (data.len() * 7 + 3) % data.len();
        if data.len() % 2 == 0
            && let Some(i) = data[at..].iter().position(|&b| b == b'<')
        {
            at += i;
        }
        let mut d = skillpost::diag::Diagnostics::default();
        let r = skillpost::read::sfc::read_sfc_stream_split(
            data,
            0,
            data.len() as u64,
            None,
            &mut d,
            pipeline,
            batch,
            Some(skillpost::read::sfc::SplitSource {
                source: &data,
                skipped: 0,
                at: Some(at),
                joined: None,
            }),
        );
        let split = format!("{r:?}\n{:?}", d.into_vec());
        assert!(split == plain, "split at {at} reads differently");
    }
}
