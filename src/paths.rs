//! Path handling in one place: `refURI` values → paths (docs/INPUTS.md), lexical normalisation, and
//! absolute paths. No function here touches the file system (except [`absolute`], which asks for
//! the current directory); symbolic links are not resolved.

use std::path::{Component, Path, PathBuf};

/// Turns a `refURI` value into a path (docs/INPUTS.md): surrounding quotes stripped, a `#fragment`
/// dropped, `file:` URLs accepted, percent-escapes decoded, `\` read as `/`, and a relative path
/// resolved against `base` (the blackboard's folder, relative or absolute). The result is
/// [`normalize`]d, so it can be compared with a project folder; a relative `base` gives a relative
/// result whose leading `..` are kept (`../../p` + `sfc.xml` → `../../p/sfc.xml`).
pub fn resolve_ref(base: &Path, raw: &str) -> Result<PathBuf, String> {
    let mut s = raw.trim();
    for q in ['"', '\''] {
        if s.len() >= 2 && s.starts_with(q) && s.ends_with(q) {
            s = s[1..s.len() - 1].trim();
        }
    }
    if let Some(i) = s.find('#') {
        s = &s[..i];
    }
    let lower = s.get(..5).map(str::to_ascii_lowercase);
    if lower.as_deref() == Some("file:") {
        s = &s[5..];
        if let Some(rest) = s.strip_prefix("//") {
            // file://host/path: only an empty host or localhost is a local file.
            let slash = rest.find('/').unwrap_or(rest.len());
            let host = &rest[..slash];
            if !(host.is_empty() || host.eq_ignore_ascii_case("localhost")) {
                return Err(format!("`{raw}` names a file on another host (`{host}`)"));
            }
            s = &rest[slash..];
        }
    }
    let decoded = percent_decode(s).ok_or_else(|| {
        format!("`{raw}` has a malformed percent-escape or does not decode to UTF-8")
    })?;
    let decoded = decoded.replace('\\', "/");
    if decoded.is_empty() {
        return Err("the reference is empty".to_owned());
    }
    if decoded.contains('\0') {
        return Err(format!("`{raw}` contains a NUL character"));
    }
    let p = Path::new(&decoded);
    let joined = if p.is_absolute() {
        p.to_path_buf()
    } else {
        base.join(p)
    };
    Ok(normalize(&joined))
}

/// Decodes percent-escapes (`%20` → space). `None` when a `%` is not followed by two hex digits
/// (`%2`, `%+4`, `%zz`) or the bytes are not UTF-8.
pub fn percent_decode(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let well_formed = b.iter().enumerate().all(|(i, &c)| {
        c != b'%'
            || (b.get(i + 1).is_some_and(u8::is_ascii_hexdigit)
                && b.get(i + 2).is_some_and(u8::is_ascii_hexdigit))
    });
    if !well_formed {
        return None;
    }
    percent_encoding::percent_decode_str(s)
        .decode_utf8()
        .ok()
        .map(|c| c.into_owned())
}

/// A path for a message, exactly: bytes that are not UTF-8 as `\xFF`, control characters
/// escaped (`\u{1b}`), so two names never read alike and nothing reaches a terminal raw.
pub fn escaped(p: &Path) -> String {
    use std::os::unix::ffi::OsStrExt as _;
    let mut out = String::new();
    for chunk in p.as_os_str().as_bytes().utf8_chunks() {
        for c in chunk.valid().chars() {
            if c.is_control() {
                out.extend(c.escape_default());
            } else {
                out.push(c);
            }
        }
        for b in chunk.invalid() {
            out.push_str(&format!("\\x{b:02X}"));
        }
    }
    out
}

/// Folds `.` and `..` lexically (no file-system access): `.` is dropped, `..` removes the name
/// before it; a `..` with no name before it is kept in a relative path (`../../p` stays) and
/// dropped at the root (`/..` is `/`). The empty path stands for the starting folder: `a/..` → ``.
pub fn normalize(p: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if matches!(out.components().next_back(), Some(Component::Normal(_))) {
                    out.pop();
                } else if !out.has_root() {
                    out.push("..");
                }
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

/// `p` made absolute against the current directory ([`std::path::absolute`]; the empty path is
/// the current directory), then [`normalize`]d. When the current directory cannot be found, `p`
/// normalised.
pub fn absolute(p: &Path) -> PathBuf {
    let p = if p.as_os_str().is_empty() {
        Path::new(".")
    } else {
        p
    };
    match std::path::absolute(p) {
        Ok(a) => normalize(&a),
        Err(_) => normalize(p),
    }
}

/// Whether `path` stays inside `root`: by its text, and, where `real` (the file system's
/// resolution, `canonicalize`) can tell, with symbolic links resolved: a link inside the folder
/// that points out of it leaves it. A path `real` cannot resolve (not there yet) is judged by
/// its text.
pub fn stays_inside(path: &Path, root: &Path, real: impl Fn(&Path) -> Option<PathBuf>) -> bool {
    if !absolute(path).starts_with(root) {
        return false;
    }
    match (real(path), real(root)) {
        (Some(real), Some(real_root)) => real.starts_with(real_root),
        _ => true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn refs() {
        let base = Path::new("/p/proj");
        let r = |s| resolve_ref(base, s).unwrap();
        assert_eq!(r("sfc.xml"), PathBuf::from("/p/proj/sfc.xml"));
        assert_eq!(
            r("\"sub dir\\my%20file.irl\""),
            PathBuf::from("/p/proj/sub dir/my file.irl")
        );
        assert_eq!(r("file:///abs/x.xml#frag"), PathBuf::from("/abs/x.xml"));
        assert_eq!(r("file://localhost/abs/x.xml"), PathBuf::from("/abs/x.xml"));
        assert_eq!(r("file:rel/x.xml"), PathBuf::from("/p/proj/rel/x.xml"));
        assert_eq!(r("./a/../b.xml"), PathBuf::from("/p/proj/b.xml"));
        assert_eq!(r("../lib/k.irl"), PathBuf::from("/p/lib/k.irl"));
        assert_eq!(r("../../../../x"), PathBuf::from("/x"));
        assert_eq!(
            r("%C3%9Cbergabe.xml"),
            PathBuf::from("/p/proj/Übergabe.xml")
        );
        assert!(resolve_ref(base, "file://server/x").is_err());
        assert!(resolve_ref(base, "a%2").is_err());
        assert!(resolve_ref(base, "%FF").is_err());
        assert!(resolve_ref(base, "\"\"").is_err());
        assert!(resolve_ref(base, "%00").is_err());
    }

    #[test]
    fn relative_bases_keep_their_leading_parents() {
        let r = |base: &str, s| resolve_ref(Path::new(base), s).unwrap();
        assert_eq!(r("../../p", "sfc.xml"), PathBuf::from("../../p/sfc.xml"));
        assert_eq!(r("../../p", "../q/k.irl"), PathBuf::from("../../q/k.irl"));
        assert_eq!(r("", "sfc.xml"), PathBuf::from("sfc.xml"));
        assert_eq!(r("", "../sfc.xml"), PathBuf::from("../sfc.xml"));
        assert_eq!(r("a", "../../sfc.xml"), PathBuf::from("../sfc.xml"));
    }

    #[test]
    fn malformed_percent_escapes_are_refused() {
        // `u8::from_str_radix` accepts a sign: `%+4` used to decode as U+0004.
        for s in ["%+4", "%-1", "%+F", "% 4", "%4", "%", "%zz", "a%4g"] {
            assert_eq!(percent_decode(s), None, "{s}");
        }
        assert_eq!(percent_decode("a%20b%25").as_deref(), Some("a b%"));
        assert_eq!(percent_decode("%c3%a4").as_deref(), Some("ä"));
        assert_eq!(percent_decode("plain").as_deref(), Some("plain"));
    }

    #[test]
    fn normalize_examples() {
        let n = |s: &str| normalize(Path::new(s));
        assert_eq!(
            n("../../p/Blackboard.aml"),
            PathBuf::from("../../p/Blackboard.aml")
        );
        assert_eq!(n("./a/./b/../c"), PathBuf::from("a/c"));
        assert_eq!(n("/.."), PathBuf::from("/"));
        assert_eq!(n("/a/../../b"), PathBuf::from("/b"));
        assert_eq!(n("a/.."), PathBuf::from(""));
        assert_eq!(n("a/../.."), PathBuf::from(".."));
    }

    /// Paths from a small alphabet of components, so `.` and `..` are frequent.
    fn path_strategy() -> impl Strategy<Value = String> {
        let comp = prop_oneof![
            Just(".".to_owned()),
            Just("..".to_owned()),
            Just("".to_owned()),
            "[a-c]{1,2}",
        ];
        (any::<bool>(), prop::collection::vec(comp, 0..10)).prop_map(|(abs, parts)| {
            let body = parts.join("/");
            if abs { format!("/{body}") } else { body }
        })
    }

    fn parts(p: &Path) -> Vec<Component<'_>> {
        p.components().collect()
    }

    proptest! {
        #[test]
        fn normalize_is_idempotent(s in path_strategy()) {
            let once = normalize(Path::new(&s));
            prop_assert_eq!(normalize(&once), once.clone());
        }

        #[test]
        fn absolute_results_hold_no_dots(s in path_strategy()) {
            let n = normalize(Path::new(&s));
            if n.has_root() {
                prop_assert!(parts(&n).iter().all(|c| matches!(c, Component::RootDir | Component::Normal(_))), "{:?}", n);
            }
            let a = absolute(Path::new(&s));
            prop_assert!(a.is_absolute());
            prop_assert!(parts(&a).iter().all(|c| matches!(c, Component::RootDir | Component::Normal(_))), "{:?}", a);
        }

        #[test]
        fn relative_results_keep_leading_parents_only(s in path_strategy()) {
            let n = normalize(Path::new(&s));
            if !n.has_root() {
                // Only `..`s first, then names: no `.`, and no `..` after a name.
                let cs = parts(&n);
                let first_name = cs.iter().position(|c| matches!(c, Component::Normal(_))).unwrap_or(cs.len());
                prop_assert!(cs[..first_name].iter().all(|c| *c == Component::ParentDir), "{:?}", n);
                prop_assert!(cs[first_name..].iter().all(|c| matches!(c, Component::Normal(_))), "{:?}", n);
                // As many leading `..` as the input climbs above its start.
                let mut depth: i64 = 0;
                let mut climb: i64 = 0;
                for c in Path::new(&s).components() {
                    match c {
                        Component::ParentDir => { depth -= 1; climb = climb.max(-depth); }
                        Component::Normal(_) => depth += 1,
                        _ => {}
                    }
                }
                prop_assert_eq!(first_name as i64, climb, "{:?}", n);
            }
        }

        #[test]
        fn joining_then_normalizing_agrees_with_normalizing_first(a in path_strategy(), b in path_strategy()) {
            let whole = normalize(&Path::new(&a).join(&b));
            let parts = normalize(&normalize(Path::new(&a)).join(normalize(Path::new(&b))));
            prop_assert_eq!(whole, parts);
        }
    }

    /// On a real tree without symbolic links, lexical normalisation of an existing path agrees
    /// with the file system's `canonicalize`.
    #[test]
    fn normalize_agrees_with_the_file_system() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().canonicalize().unwrap();
        for d in ["a/b/c", "a/c", "b/a", "c"] {
            std::fs::create_dir_all(root.join(d)).unwrap();
        }
        let dirs = ["a", "a/b", "a/b/c", "a/c", "b", "b/a", "c"];
        let comp = prop_oneof![Just("."), Just(".."), Just("a"), Just("b"), Just("c"),];
        let mut runner = proptest::test_runner::TestRunner::default();
        runner
            .run(
                &(0..dirs.len(), prop::collection::vec(comp, 0..8)),
                |(start, steps)| {
                    // Start in a folder of the tree, never climb out of `root`.
                    let mut rel = PathBuf::from(dirs[start]);
                    let mut depth = rel.components().count() as i64;
                    for s in steps {
                        depth += match s {
                            "." => 0,
                            ".." => -1,
                            _ => 1,
                        };
                        if depth < 0 {
                            return Ok(());
                        }
                        rel.push(s);
                    }
                    let p = root.join(&rel);
                    if let Ok(real) = p.canonicalize() {
                        prop_assert_eq!(normalize(&p), real.clone(), "{:?}", rel);
                        prop_assert_eq!(absolute(&p), real, "{:?}", rel);
                    }
                    Ok(())
                },
            )
            .unwrap();
    }

    #[test]
    fn absolute_uses_the_current_directory() {
        let cwd = std::env::current_dir().unwrap();
        assert_eq!(absolute(Path::new("x/../y")), normalize(&cwd.join("y")));
        assert_eq!(absolute(Path::new("/a/./b/..")), PathBuf::from("/a"));
        assert_eq!(absolute(Path::new("")), cwd);
    }
}
