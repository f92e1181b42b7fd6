//! The floor the compile is measured against: one pass of quick-xml over a file's text in
//! memory, every event and attribute visited, nothing built (what `cargo bench --bench compile`
//! calls the quick-xml floor; the pass is `benches/common/floor.rs`, shared with it).
//! `bench/guard.sh` counts its instructions beside the compile's:
//!
//! ```text
//! cargo run --release --example floor -- /tmp/p10k/sfc.xml
//! ```
//!
//! Prints the number of elements and attributes seen.

use std::process::ExitCode;

#[path = "../benches/common/floor.rs"]
mod floor;

fn main() -> ExitCode {
    let Some(path) = std::env::args_os().nth(1) else {
        eprintln!("usage: floor FILE.xml");
        return ExitCode::from(2);
    };
    let shown = path.to_string_lossy().into_owned();
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("{shown}: {e}");
            return ExitCode::from(2);
        }
    };
    match floor::quick_xml_pass(&text) {
        Ok((elements, attributes)) => {
            println!("{elements} elements, {attributes} attributes");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{shown}: {e}");
            ExitCode::FAILURE
        }
    }
}
