//! The documentation stands on its own: README.md, ARCHITECTURE.md and docs/ cite no contract
//! a user who clones the repository does not have (the project's specification is not part of
//! it), nor do the program's sources, its tests or the fixtures' descriptions: a rule is
//! referenced by the page of `docs/` that states it (docs/INPUTS.md, docs/CELLS.md, ...). And the
//! links between the pages lead to pages that exist.

use std::fs;
use std::path::{Path, PathBuf};

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The files under `dir` (recursively) whose name ends in one of `exts`.
fn files(dir: &Path, exts: &[&str], out: &mut Vec<PathBuf>) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            files(&p, exts, out);
        } else if exts.iter().any(|x| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().ends_with(x))
        }) {
            out.push(p);
        }
    }
}

/// Where `text` cites the specification: its file name (`.md`), a `§`, a section number or
/// `section` after its name.
fn citations(text: &str) -> Vec<(usize, String)> {
    let spec = ["SP", "EC"].concat();
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        for (i, _) in line.match_indices(&spec) {
            let rest = &line[i + spec.len()..];
            let cites = rest.starts_with(".md")
                || rest.starts_with(" §")
                || rest.starts_with('§')
                || rest.starts_with(" section")
                || rest
                    .strip_prefix(' ')
                    .is_some_and(|r| r.starts_with(|c: char| c.is_ascii_digit()));
            let word_before = line[..i]
                .chars()
                .next_back()
                .is_some_and(|c| c.is_alphanumeric() || c == '_');
            if cites && !word_before {
                out.push((n + 1, line.trim().to_owned()));
            }
        }
    }
    out
}

#[test]
fn no_page_or_message_cites_the_specification() {
    let root = repo();
    let mut checked = vec![root.join("README.md"), root.join("ARCHITECTURE.md")];
    files(&root.join("docs"), &[".md"], &mut checked);
    files(&root.join("src"), &[".rs"], &mut checked);
    files(&root.join("tests"), &[".rs"], &mut checked);
    // The fixtures' descriptions (their blackboards' and charts' bytes are pinned by snapshots).
    files(
        &root.join("fixtures"),
        &["case.toml", "expect.toml", ".txt"],
        &mut checked,
    );
    assert!(checked.len() > 100, "{} files", checked.len());
    let mut found = String::new();
    for f in &checked {
        let Ok(text) = fs::read_to_string(f) else {
            continue;
        };
        for (line, what) in citations(&text) {
            found.push_str(&format!(
                "{}:{line}: {what}\n",
                f.strip_prefix(root).unwrap_or(f).display()
            ));
        }
    }
    assert!(
        found.is_empty(),
        "these cite the specification, which is not in the repository; name the page of docs/ \
         that states the rule instead (docs/INPUTS.md, docs/CELLS.md, docs/LANGUAGES.md, \
         docs/COMMAND-LINE.md, docs/DAEMON.md), or state the rule:\n{found}"
    );
}

#[test]
fn the_citation_check_finds_citations() {
    let spec = ["SP", "EC"].concat();
    for cited in [".md 9", " §3", " 3.1's list", " section 7"] {
        assert_eq!(
            citations(&format!("as {spec}{cited} says")).len(),
            1,
            "{cited}"
        );
    }
    assert!(citations(&format!("{spec}IAL_{spec}S 3 DE{spec} 9")).is_empty());
}

/// The targets of the markdown links in `text` outside code (`[a](b)`), without `#anchor`s,
/// that are no URLs.
fn links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut code = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            code = !code;
            continue;
        }
        if code {
            continue;
        }
        let prose: String = line.split('`').step_by(2).collect::<Vec<_>>().join(" ");
        for (i, _) in prose.match_indices("](") {
            let rest = &prose[i + 2..];
            let Some(end) = rest.find(')') else { continue };
            let target = rest[..end].split('#').next().unwrap_or("");
            if !target.is_empty() && !target.contains("://") && !target.starts_with("mailto:") {
                out.push(target.to_owned());
            }
        }
    }
    out
}

/// Every link of README.md, ARCHITECTURE.md and docs/ leads to a file: docs/ pages link to each
/// other by their bare names (they are installed side by side, docs/DAEMON-INSTALL.md).
#[test]
fn the_pages_link_to_pages_that_exist() {
    let root = repo();
    let mut pages = vec![root.join("README.md"), root.join("ARCHITECTURE.md")];
    files(&root.join("docs"), &[".md"], &mut pages);
    let mut broken = String::new();
    let mut count = 0;
    for page in &pages {
        let text = fs::read_to_string(page).unwrap();
        for target in links(&text) {
            count += 1;
            let to = page.parent().unwrap().join(&target);
            let in_docs = page.parent() == Some(&root.join("docs"));
            if !to.exists() || (in_docs && target.contains('/')) {
                broken.push_str(&format!(
                    "{} links to {target}{}\n",
                    page.strip_prefix(root).unwrap().display(),
                    if to.exists() {
                        ", outside docs/ (not installed beside the page)"
                    } else {
                        ", which does not exist"
                    }
                ));
            }
        }
    }
    assert!(count > 30, "{count} links");
    assert!(broken.is_empty(), "{broken}");
}
