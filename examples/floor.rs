//! The floor the compile is measured against: one pass of quick-xml over a file's text in
//! memory, every event and attribute visited, nothing built (what `cargo bench --bench compile`
//! calls the quick-xml floor). `bench/guard.sh` counts its instructions beside the compile's:
//!
//! ```text
//! cargo run --release --example floor -- /tmp/p10k/sfc.xml
//! ```
//!
//! Prints the number of elements and attributes seen.

use std::hint::black_box;
use std::process::ExitCode;

use quick_xml::events::Event;

fn main() -> ExitCode {
    let Some(path) = std::env::args_os().nth(1) else {
        eprintln!("usage: floor FILE.xml");
        return ExitCode::from(2);
    };
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("{}: {e}", path.to_string_lossy());
            return ExitCode::from(2);
        }
    };
    let mut reader = quick_xml::Reader::from_str(&text);
    let (mut elements, mut attributes) = (0usize, 0usize);
    loop {
        match reader.read_event() {
            Ok(Event::Start(e) | Event::Empty(e)) => {
                elements += 1;
                for a in e.attributes() {
                    match a {
                        Ok(a) => {
                            black_box(a);
                            attributes += 1;
                        }
                        Err(e) => {
                            eprintln!("{}: {e}", path.to_string_lossy());
                            return ExitCode::FAILURE;
                        }
                    }
                }
            }
            Ok(Event::Eof) => break,
            Ok(ev) => {
                black_box(ev);
            }
            Err(e) => {
                eprintln!("{}: {e}", path.to_string_lossy());
                return ExitCode::FAILURE;
            }
        }
    }
    println!("{elements} elements, {attributes} attributes");
    ExitCode::SUCCESS
}
