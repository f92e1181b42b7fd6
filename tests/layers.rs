//! The core is a one-way street (issue 25, item 7; ARCHITECTURE.md): each module imports only
//! modules before it in [`ORDER`] — small value types, then the model, then the stages in the
//! order the data flows (`read` → `plan` → `bind` → `emit` → `write`), then the drivers. Read
//! from the sources: every `crate::<module>` a module's code names (comments and its unit tests
//! after `#[cfg(test)]` left out) must come earlier in the list, or be the module itself.

use std::path::Path;

/// From the bottom up.
const ORDER: &[&str] = &[
    "names", "paths", "convert", "threads", "load", "excerpt", "diag", "cond", "value", "template",
    "lang", "check", "model", "read", "plan", "bind", "emit", "write", "picture", "compile",
    "simulate", "print", "daemon", "cli",
];

fn module_of(rel: &Path) -> String {
    let first = rel
        .components()
        .next()
        .unwrap()
        .as_os_str()
        .to_string_lossy();
    first.trim_end_matches(".rs").to_owned()
}

/// The modules `text` names as `crate::<name>`, outside comments and before its unit tests.
fn named(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in text.lines() {
        let t = line.trim_start();
        if t.starts_with("#[cfg(test)]") {
            break;
        }
        if t.starts_with("//") {
            continue;
        }
        let code = match line.find("//") {
            Some(i) => &line[..i],
            None => line,
        };
        let mut rest = code;
        while let Some(i) = rest.find("crate::") {
            let after = &rest[i + "crate::".len()..];
            let name: String = after
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            if after.starts_with('{') {
                // `use crate::{a, b}` is not parsed: one `use` per module keeps this honest.
                out.push("{grouped import: write one `use crate::…` per module}".to_owned());
            } else if !name.is_empty() && name.chars().next().unwrap().is_ascii_lowercase() {
                out.push(name);
            }
            rest = after;
        }
    }
    out
}

#[test]
fn each_module_imports_only_modules_before_it() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    let mut stack = vec![src.clone()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                files.push(p);
            }
        }
    }
    let rank = |m: &str| ORDER.iter().position(|o| *o == m);
    let mut wrong = Vec::new();
    for f in files {
        let rel = f.strip_prefix(&src).unwrap();
        let module = module_of(rel);
        if module == "lib" || module == "main" {
            continue;
        }
        let Some(own) = rank(&module) else {
            wrong.push(format!(
                "{}: module `{module}` is not in ORDER",
                rel.display()
            ));
            continue;
        };
        let text = std::fs::read_to_string(&f).unwrap();
        let mut seen = std::collections::BTreeSet::new();
        for m in named(&text) {
            if m == "VERSION" || !seen.insert(m.clone()) {
                continue;
            }
            match rank(&m) {
                Some(r) if r <= own => {}
                Some(_) => wrong.push(format!(
                    "{}: `{module}` imports `crate::{m}`, which comes after it",
                    rel.display()
                )),
                None => wrong.push(format!("{}: unknown module `crate::{m}`", rel.display())),
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}
