//! The parts of split programs (docs/LANGUAGES.md, "Long programs"): which files a compile
//! wrote, and after [`super::apply`] the removal of the parts an earlier, longer compile of the
//! same program left behind.

use std::path::{Path, PathBuf};

use crate::emit::LanguageProfile as _;
use crate::emit::OutputFile;
use crate::emit::split;
use crate::lang::Language;

/// One program's parts as written.
#[derive(Debug, Clone)]
pub struct PartFiles {
    /// The folder the outputs go to.
    pub folder: PathBuf,
    pub program: String,
    pub language: Language,
    /// How many parts it has now (0: not split).
    pub parts: usize,
}

impl PartFiles {
    /// The parts of the program `name` whose first (main) file is `main`.
    pub fn of(folder: &Path, name: &str, language: Language, main: Option<&OutputFile>) -> Self {
        PartFiles {
            folder: folder.to_owned(),
            program: name.to_owned(),
            language,
            parts: main.map_or(0, |f| f.parts.len()),
        }
    }
}

/// Removes, per program, the part files numbered after its last part that name themselves
/// parts of it (their marker), until a number has none; URScript's parts are in the script.
pub fn remove_stale(programs: &[PartFiles], route: &dyn Fn(&Path) -> PathBuf) -> Vec<PathBuf> {
    let mut removed = Vec::new();
    for p in programs {
        let exts: &[&str] = match p.language {
            Language::UrScript => continue,
            l => l.profile().files(),
        };
        for n in p.parts + 1.. {
            let stem = split::part_stem(&p.program, n, p.language);
            let files: Vec<PathBuf> = exts
                .iter()
                .map(|e| p.folder.join(format!("{stem}.{e}")))
                .collect();
            match crate::write::stale::remove_marked(&files, &split::marker(n, &p.program), route) {
                Some(r) => removed.extend(r),
                None => break,
            }
        }
    }
    removed
}
