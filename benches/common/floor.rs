//! The floor the compile is measured against: one pass of quick-xml over a text in memory,
//! every event and attribute visited, nothing built. Shared by `benches/compile.rs` (timed
//! in-process) and `examples/floor.rs` (its instructions counted by `bench/guard.sh`), so both
//! measure the same pass: `#[path = "../benches/common/floor.rs"] mod floor;`.
#![allow(dead_code)]

use std::hint::black_box;

use quick_xml::events::Event;

/// Reads `text` with quick-xml: the number of elements and attributes, or the first error.
pub fn quick_xml_pass(text: &str) -> Result<(usize, usize), quick_xml::Error> {
    let mut reader = quick_xml::Reader::from_str(text);
    let (mut elements, mut attributes) = (0usize, 0usize);
    loop {
        match reader.read_event() {
            Ok(Event::Start(e) | Event::Empty(e)) => {
                elements += 1;
                for a in e.attributes() {
                    black_box(a?);
                    attributes += 1;
                }
            }
            Ok(Event::Eof) => return Ok((elements, attributes)),
            Ok(ev) => {
                black_box(ev);
            }
            Err(e) => return Err(e),
        }
    }
}
