//! The blackboard reader: bytes → `read::xml::load` (BOM, UTF-8) → `read_blackboard`, the
//! listings, the diagnostics in every format; and the write-back contract: the target the reader
//! finds is one the splice accepts, and after the splice the reader reads the new value.
#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;
use skillpost::diag::Diagnostics;
use skillpost::print;
use skillpost::read::blackboard::read_blackboard;
use skillpost::write::splice_value;

const VALUE: &str = "output.src";

fuzz_target!(|data: &[u8]| {
    let (sources, mut diags, file) = common::load("/p/Blackboard.aml", data);
    let bb = file.and_then(|f| read_blackboard(&sources, f, &mut diags));
    if let (Some(bb), Some(file)) = (&bb, file) {
        let _ = print::blackboard(bb, &Default::default(), None);
        let _ = print::info(Some(bb));
        if let Some(wb) = &bb.write_back {
            let text = &sources.get(file).text;
            let spliced = splice_value(text, wb.attribute.range.clone(), VALUE);
            match spliced {
                Err(e) => panic!("the splice refuses the reader's write-back target: {e}"),
                Ok(None) => assert_eq!(
                    wb.current.as_deref(),
                    Some(VALUE),
                    "splice says already right, the reader disagrees"
                ),
                Ok(Some(new)) => {
                    assert_ne!(
                        wb.current.as_deref(),
                        Some(VALUE),
                        "splice rewrites a value the reader reads as right"
                    );
                    // What the write-back writes: the BOM it read, then the new text
                    // (a text that starts with a second BOM keeps it: crash-c56cb80e).
                    let mut bytes = Vec::new();
                    if sources.get(file).bom {
                        bytes.extend_from_slice(b"\xEF\xBB\xBF");
                    }
                    bytes.extend_from_slice(new.as_bytes());
                    let (s2, mut d2, f2) = common::load("/p/Blackboard.aml", &bytes);
                    let bb2 = f2
                        .and_then(|f| read_blackboard(&s2, f, &mut d2))
                        .expect("the written-back blackboard reads");
                    let wb2 = bb2
                        .write_back
                        .as_ref()
                        .expect("the written-back blackboard has its target");
                    assert_eq!(wb2.current.as_deref(), Some(VALUE));
                    let text2 = &s2.get(f2.expect("read")).text;
                    assert_eq!(text2, &new, "the text read back is the text written");
                    assert_eq!(
                        splice_value(text2, wb2.attribute.range.clone(), VALUE),
                        Ok(None),
                        "a second write-back changes nothing"
                    );
                    // The write-back changes one value: no new error appears.
                    assert!(
                        d2.error_count() <= diags.error_count(),
                        "the write-back adds errors: {:?}",
                        d2.into_vec()
                    );
                }
            }
        }
    }
    let diags = finish(diags);
    common::render_all(&diags, &sources);
});

fn finish(mut d: Diagnostics) -> Vec<skillpost::diag::Diagnostic> {
    d.sort();
    d.into_vec()
}
