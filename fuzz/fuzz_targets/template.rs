//! Template substitution (`template.rs`). Input: `P1,P2,...\0TEXT`, or just `TEXT` (then the
//! parameters come from `params_from_brackets`, as for an IRL call that declares none).
//!
//! Every text is also compiled and rendered with the RAPID and URScript syntaxes and with
//! conversions (`quat(A, B, C)`) fed numbers and non-numbers: never a panic. The checks below
//! are for the KRL syntax and texts without a conversion call (a conversion replaces its whole
//! call by numbers).
//!
//! Checked, besides "never panics":
//! - without parameters a template renders its text byte for byte;
//! - `used()[i]` exactly when parameter `i`'s value appears in the output;
//! - the output is the text with only these changes (rendering each value as a unique marker
//!   and walking text and output side by side): a whole word `W` replaced by the value of the
//!   parameter named `W` (case-insensitively, the first such parameter), or, for `W` alone in an
//!   aggregate item, ` value` inserted after it; never a word starting with `$` or a digit, a
//!   word after `.`, `#` or `'`, or a word in a string literal or a comment.
#![no_main]

use std::collections::HashSet;

use libfuzzer_sys::fuzz_target;
use skillpost::names;
use skillpost::template::{Syntax, Template, dedent, params_from_brackets};

fuzz_target!(|data: &[u8]| {
    let Ok(s) = std::str::from_utf8(data) else {
        return;
    };
    let (params, text): (Vec<String>, &str) = match s.split_once('\0') {
        Some((p, t)) => (p.split(',').take(16).map(str::to_owned).collect(), t),
        None => (params_from_brackets(s), s),
    };
    let _ = dedent(text);

    for syntax in [
        Syntax::KRL,
        Syntax {
            comment: b'!',
            aggregates: false,
            case_sensitive: false,
        },
        Syntax {
            comment: b'#',
            aggregates: false,
            case_sensitive: true,
        },
    ] {
        let t = Template::compile_for(text, &params, syntax);
        let mut out = String::new();
        let _ = t.render_with(&params, &|i| Some(i as f64 * 37.5 - 90.0), &mut out);
        let _ = t.render_with(&params, &|_| None, &mut out);
        let _ = t.render_with(&params, &|_| Some(f64::MAX), &mut out);
    }
    if Template::compile(text, &params).conversions() > 0
        || Template::compile(text, &[]).conversions() > 0
    {
        return;
    }

    let bare = Template::compile(text, &[]);
    let mut out = String::new();
    bare.render::<&str>(&[], &mut out);
    assert_eq!(out, text, "a template without parameters changed its text");

    let t = Template::compile(text, &params);
    assert_eq!(t.param_count(), params.len());
    assert_eq!(t.used().len(), params.len());
    let mut plain = String::new();
    t.render(&params, &mut plain);

    if text.contains('\u{1}') {
        return;
    }
    let markers: Vec<String> = (0..params.len())
        .map(|i| format!("\u{1}{i}\u{2}"))
        .collect();
    let mut out = String::new();
    t.render(&markers, &mut out);
    for (i, m) in markers.iter().enumerate() {
        assert_eq!(
            t.used()[i],
            out.contains(m.as_str()),
            "used() disagrees with the output for parameter {i}"
        );
    }
    let keys: Vec<String> = params.iter().map(|p| names::key(p)).collect();
    let mut w = Walk {
        text: text.as_bytes(),
        out: out.as_bytes(),
        keys,
        failed: HashSet::new(),
    };
    assert!(
        w.walk(0, 0),
        "the output is not the text with parameter words replaced\ntext:   {text:?}\nparams: {params:?}\noutput: {out:?}"
    );
});

fn is_word(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_' || b == b'$' || b >= 0x80
}

struct Walk<'a> {
    text: &'a [u8],
    out: &'a [u8],
    keys: Vec<String>,
    /// (text, output) positions from which no explanation exists.
    failed: HashSet<(usize, usize)>,
}

impl Walk<'_> {
    /// Whether `out[o..]` is `text[t..]` with substitutions by the rules.
    fn walk(&mut self, mut t: usize, mut o: usize) -> bool {
        let (text, out) = (self.text, self.out);
        loop {
            if o == out.len() {
                return t == text.len();
            }
            if out[o] == 1 {
                let Some((i, next)) = self.marker(o) else {
                    return false;
                };
                return self.slot(t, next, i);
            }
            if out[o] == b' ' && out.get(o + 1) == Some(&1) {
                if self.failed.contains(&(t, o)) {
                    return false;
                }
                let ok = self.aggregate(t, o + 1)
                    || (text.get(t) == Some(&b' ') && self.walk(t + 1, o + 1));
                if !ok {
                    self.failed.insert((t, o));
                }
                return ok;
            }
            if text.get(t) != Some(&out[o]) {
                return false;
            }
            t += 1;
            o += 1;
        }
    }

    /// The parameter index of the marker at `out[o] == 1` and the position after it.
    fn marker(&self, o: usize) -> Option<(usize, usize)> {
        let len = self.out[o..].iter().position(|&b| b == 2)?;
        let digits = std::str::from_utf8(&self.out[o + 1..o + len]).ok()?;
        Some((digits.parse().ok()?, o + len + 1))
    }

    /// A marker replaced the word starting at `text[t]`.
    fn slot(&mut self, t: usize, next: usize, i: usize) -> bool {
        let text = self.text;
        if t >= text.len() || !is_word(text[t]) || (t > 0 && is_word(text[t - 1])) {
            return false;
        }
        let mut e = t;
        while e < text.len() && is_word(text[e]) {
            e += 1;
        }
        self.substitutable(t, e, i) && self.walk(e, next)
    }

    /// ` marker` was inserted after the word ending at `text[t]`, alone in an aggregate item.
    fn aggregate(&mut self, t: usize, at_marker: usize) -> bool {
        let text = self.text;
        let Some((i, next)) = self.marker(at_marker) else {
            return false;
        };
        if t == 0 || !is_word(text[t - 1]) || text.get(t).is_some_and(|&b| is_word(b)) {
            return false;
        }
        let mut s = t;
        while s > 0 && is_word(text[s - 1]) {
            s -= 1;
        }
        let mut j = t;
        while j < text.len() && matches!(text[j], b' ' | b'\t') {
            j += 1;
        }
        if !matches!(text.get(j), Some(b',' | b'}')) {
            return false;
        }
        self.substitutable(s, t, i) && self.walk(t, next)
    }

    /// Whether the word `text[s..e]` may stand for parameter `i`.
    fn substitutable(&self, s: usize, e: usize, i: usize) -> bool {
        let text = self.text;
        let Ok(word) = std::str::from_utf8(&text[s..e]) else {
            return false;
        };
        let first = text[s];
        if first == b'$' || first.is_ascii_digit() {
            return false;
        }
        if s > 0 && matches!(text[s - 1], b'.' | b'#' | b'\'') {
            return false;
        }
        let key = names::key(word);
        // The first parameter with this name wins.
        if self.keys.iter().position(|k| *k == key) != Some(i) {
            return false;
        }
        // Not inside a string literal or a comment of its line.
        let line = text[..s]
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(0, |p| p + 1);
        let mut in_str = false;
        for &b in &text[line..s] {
            match b {
                b'"' => in_str = !in_str,
                b';' if !in_str => return false,
                _ => {}
            }
        }
        !in_str
    }
}
