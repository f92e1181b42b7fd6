//! The compiler core does no I/O of its own (ARCHITECTURE.md, "Invariants"): the modules that
//! read, plan, bind and emit get their files through `load::FileSource` and never name the file
//! system, processes, the network, the environment, the daemon's crates or the command line's.
//! A workspace crate would make the build enforce it; until then this test does, by reading the
//! sources.

use std::path::{Path, PathBuf};

/// The core: everything between the bytes of the inputs and the text of the outputs.
const CORE: &[&str] = &[
    "src/read",
    "src/plan",
    "src/emit",
    "src/bind",
    "src/template.rs",
    "src/value.rs",
    "src/convert.rs",
    "src/cond",
    "src/model.rs",
    "src/names.rs",
];

/// What the core must not name.
const FORBIDDEN: &[&str] = &[
    "std::fs",
    "fs::",
    "File::",
    "OpenOptions",
    "std::process",
    "Command::new",
    "std::net",
    "std::env",
    "env::var",
    "tokio",
    "notify::",
    "clap::",
    "tracing::",
    "rustix",
    "fdlease",
    "SystemTime",
    "Instant::now",
    "crate::load::FsSource",
    "crate::write",
    "crate::daemon",
    "crate::cli",
];

fn files(p: &Path, out: &mut Vec<PathBuf>) {
    if p.is_dir() {
        for e in std::fs::read_dir(p).unwrap() {
            files(&e.unwrap().path(), out);
        }
    } else if p.extension().is_some_and(|e| e == "rs") {
        out.push(p.to_owned());
    }
}

#[test]
fn the_compiler_core_names_no_io() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut all = Vec::new();
    for c in CORE {
        let p = root.join(c);
        assert!(p.exists(), "{c} is gone: update CORE");
        files(&p, &mut all);
    }
    assert!(all.len() >= 15, "{all:?}");
    let mut found = Vec::new();
    for f in &all {
        let text = std::fs::read_to_string(f).unwrap();
        // Unit tests may make files; the code above them may not.
        let code = text.split("#[cfg(test)]").next().unwrap_or("");
        for (n, line) in code.lines().enumerate() {
            // The splice site is data the blackboard reader records for the write-back (pure).
            let code_part = line.split("//").next().unwrap_or("");
            let code_part = code_part.replace("crate::write::SpliceSite", "SpliceSite");
            let code_part = code_part.as_str();
            for word in FORBIDDEN {
                if code_part.contains(word) {
                    found.push(format!(
                        "{}:{}: `{word}` in `{}`",
                        f.strip_prefix(root).unwrap().display(),
                        n + 1,
                        line.trim()
                    ));
                }
            }
        }
    }
    assert!(
        found.is_empty(),
        "the compiler core names I/O:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_check_would_see_a_file_read() {
    // The scan itself: a line of the core that opened a file would be found.
    let line = "    let text = std::fs::read_to_string(path)?;";
    assert!(FORBIDDEN.iter().any(|w| line.contains(w)));
}
