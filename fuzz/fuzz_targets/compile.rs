//! The whole pipeline (`compile::compile`) on an in-memory project. Input: blackboard, SFC and
//! IRL bytes separated by NUL bytes. The blackboard is `/p/Blackboard.aml`; whatever other path
//! the compile asks for gets the IRL part when it ends in `.irl` and the SFC part otherwise, so
//! mutated `refURI`s still find their files (a plain `MemSource` keyed by fixed names would turn
//! most of them into "file not found").
//!
//! Checked: never panics; diagnostic spans are inside their files and render; with no errors
//! the outputs are ASCII and the write-back the compile asks for is one the splice accepts.
#![no_main]

mod common;

use std::path::{Path, PathBuf};

use libfuzzer_sys::fuzz_target;
use skillpost::compile::{Options, compile};
use skillpost::load::{FileSource, MemSource};

const BLACKBOARD: &str = "/p/Blackboard.aml";

/// A `MemSource` for the blackboard, and the SFC or IRL part for any other path.
struct Project {
    blackboard: MemSource,
    sfc: Vec<u8>,
    irl: Vec<u8>,
}

impl FileSource for Project {
    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        if path == Path::new(BLACKBOARD) {
            return self.blackboard.read(path);
        }
        let irl = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("irl"));
        Ok(if irl { &self.irl } else { &self.sfc }.clone())
    }
}

fuzz_target!(|data: &[u8]| {
    let mut parts = data.splitn(3, |&b| b == 0);
    let bb = parts.next().unwrap_or_default();
    let sfc = parts.next().unwrap_or_default().to_vec();
    let irl = parts.next().unwrap_or_default().to_vec();
    let mut blackboard = MemSource::default();
    blackboard.insert(BLACKBOARD, bb.to_vec());
    let fs = Project {
        blackboard,
        sfc,
        irl,
    };
    let opts = Options {
        program: Some("output".to_owned()),
        lf: data.len() % 2 == 0,
        template: None,
        confine_to: None,
        pou: None,
        keep_model: data.len() % 3 == 0,
        drop_warnings: data.len() % 5 == 0,
        bind_split_from: (data.len() % 7 == 0).then_some(1),
        picture: None,
        // Now and then a limit small enough that the programs are split into parts.
        max_lines: if data.len() % 11 == 0 {
            skillpost::emit::split::Limits::all(20)
        } else {
            Default::default()
        },
    };
    let c = compile(&fs, Path::new(BLACKBOARD), &opts);
    assert_eq!(c.files_read.first(), Some(&PathBuf::from(BLACKBOARD)));
    common::render_all(&c.diagnostics, &c.sources);
    if c.has_errors() {
        assert!(c.outputs.is_empty(), "outputs despite errors");
        assert!(c.write_back.is_none(), "a write-back despite errors");
        return;
    }
    for (path, out) in &c.outputs {
        assert!(
            out.text.is_ascii(),
            "{} is not ASCII:\n{}",
            path.display(),
            out.text
        );
    }
    if let Some(wb) = &c.write_back {
        let body = if wb.bom {
            &wb.expected[3..]
        } else {
            &wb.expected[..]
        };
        let text = std::str::from_utf8(body).expect("the blackboard read is UTF-8");
        if let Err(e) = skillpost::write::splice_value(text, wb.attribute.clone(), &wb.value) {
            panic!("the write-back the compile asks for is refused: {e}");
        }
    }
});
