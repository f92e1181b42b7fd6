//! `skillpost check FILE...` (docs/COMMAND-LINE.md): the built-in check of robot programs
//! ([`crate::check`]) on files a user names, bounded in what it reads and reports.

use super::{CheckArgs, CheckLanguage};

/// The largest program `skillpost check` reads: 64 MiB (a controller's program memory is a few
/// MiB).
const CHECK_MAX_BYTES: u64 = 64 * 1024 * 1024;

/// `skillpost check FILE...`: each file's first [`crate::check::MAX_PROBLEMS`] problems as
/// `file:line:column: error: message` and how many more, then a count.
pub(super) fn check_command(a: &CheckArgs) -> u8 {
    use crate::check::{self, Unit};
    use crate::lang::Language;
    let mut problems = 0usize;
    let mut failed = 0usize;
    let mut unreadable = false;
    for f in &a.files {
        let by_ext = check::language_of(f);
        let (language, unit) = match (a.language, by_ext) {
            (Some(l), ext) => {
                let language = match l {
                    CheckLanguage::Krl => Language::Krl,
                    CheckLanguage::Rapid => Language::Rapid,
                    CheckLanguage::Urscript => Language::UrScript,
                };
                let unit = match ext {
                    Some((Language::Krl, Unit::Data)) if language == Language::Krl => Unit::Data,
                    _ => Unit::Program,
                };
                (language, unit)
            }
            (None, Some(x)) => x,
            (None, None) => {
                eprintln!(
                    "error: {}: which robot language? The extension says none of .src, .dat \
                     (KRL), .mod, .modx, .sys (RAPID), .script (URScript); give --language",
                    f.display()
                );
                unreadable = true;
                continue;
            }
        };
        let text = match crate::load::read_limited(f, CHECK_MAX_BYTES) {
            Ok(b) => String::from_utf8(b)
                .unwrap_or_else(|e| String::from_utf8_lossy(e.as_bytes()).into_owned()),
            // `read_limited`'s only `InvalidData` is a file over the limit.
            Err(e) if e.kind() == std::io::ErrorKind::InvalidData => {
                eprintln!(
                    "error: cannot check {}: it is larger than the {} MiB `skillpost check` \
                     reads of a program",
                    f.display(),
                    CHECK_MAX_BYTES >> 20
                );
                unreadable = true;
                continue;
            }
            Err(e) => {
                eprintln!("error: cannot read {}: {e}", f.display());
                unreadable = true;
                continue;
            }
        };
        let found = check::check_counted(language, unit, &text);
        drop(text);
        if !found.problems.is_empty() {
            failed += 1;
        }
        problems += found.more;
        for p in &found.problems {
            problems += 1;
            let opened = match p.opened {
                Some((l, c)) if (l, c) != (p.line, p.column) => {
                    format!(" (opened at {l}:{c})")
                }
                _ => String::new(),
            };
            println!(
                "{}:{}:{}: error: {}{opened}",
                f.display(),
                p.line,
                p.column,
                p.message
            );
        }
        if found.more > 0 {
            println!(
                "{}: {} more problem{} not shown (the first {} are)",
                f.display(),
                found.more,
                if found.more == 1 { "" } else { "s" },
                check::MAX_PROBLEMS
            );
        }
    }
    let checked = a.files.len();
    if problems > 0 {
        println!(
            "{problems} problem{} in {failed} of {checked} file{}",
            if problems == 1 { "" } else { "s" },
            if checked == 1 { "" } else { "s" }
        );
    } else if !unreadable {
        println!(
            "{checked} file{} checked: no problems",
            if checked == 1 { "" } else { "s" }
        );
    }
    if unreadable {
        2
    } else if problems > 0 {
        1
    } else {
        0
    }
}
