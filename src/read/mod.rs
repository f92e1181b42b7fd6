//! The readers: blackboard, SFC and IRL files → [`crate::model`], with spans.
//!
//! Readers never stop at the first problem: they push diagnostics and return what they could read.

pub mod blackboard;
pub mod irl;
pub mod sfc;
pub mod xml;

use std::path::{Component, Path, PathBuf};

/// Turns a `refURI` value into a path (SPEC.md 2.4): surrounding quotes stripped, a `#fragment`
/// dropped, `file:` URLs accepted, percent-escapes decoded, `\` read as `/`, and a relative path
/// resolved against `base` (the blackboard's folder). `.` and `..` components are folded
/// lexically, so the result can be compared with a project folder.
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

/// Folds `.` and `..` lexically (no file-system access).
pub fn normalize(p: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

pub fn percent_decode(s: &str) -> Option<String> {
    if !s.contains('%') {
        return Some(s.to_owned());
    }
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = s.get(i + 1..i + 3)?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

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
        assert!(resolve_ref(base, "file://server/x").is_err());
        assert!(resolve_ref(base, "a%2").is_err());
        assert!(resolve_ref(base, "%FF").is_err());
        assert!(resolve_ref(base, "\"\"").is_err());
    }
}
