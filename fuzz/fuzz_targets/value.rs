//! The SFC value syntax (`value.rs`): `check_value`, `parse_value` and `lookup` agree.
//!
//! - `check_value` accepts exactly what `parse_value` accepts, and both report the same error
//!   offset (inside the text, on a character boundary);
//! - a parsed value printed back as `(a, b, (c))` parses to the same value;
//! - `lookup` with small index paths finds what walking the parsed tree finds, and so does
//!   `lookup_in` with one item cache over all the paths.
#![no_main]

use libfuzzer_sys::fuzz_target;
use skillpost::model::Value;
use skillpost::value::{ItemCache, Lookup, check_value, lookup, lookup_in, parse_value};

fuzz_target!(|data: &[u8]| {
    // The first byte picks the index path checked besides the fixed ones.
    let Some((&sel, rest)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(rest) else {
        return;
    };
    let checked = check_value(text);
    let parsed = parse_value(text);
    match (&checked, &parsed) {
        (Ok(()), Ok(v)) => {
            if let Value::Scalar(s) = v {
                assert_eq!(s, text.trim());
            }
            let printed = print(v);
            assert_eq!(
                parse_value(&printed).as_ref(),
                Ok(v),
                "printed back as {printed:?}"
            );
            let own = [
                (sel & 3) as usize,
                ((sel >> 2) & 3) as usize,
                ((sel >> 4) & 3) as usize,
            ];
            let depth = (sel >> 6) as usize;
            let mut paths: Vec<&[usize]> = vec![&[], &[0], &[1], &[0, 0], &[1, 1], &[0, 1, 0]];
            paths.push(&own[..depth.min(3)]);
            let mut cache = ItemCache::default();
            for p in paths {
                let walked = walk(v, p);
                assert_eq!(lookup(text, p), walked, "lookup {p:?} in {text:?}");
                assert_eq!(
                    lookup_in(text, p, &mut cache),
                    walked,
                    "lookup_in {p:?} in {text:?}"
                );
            }
        }
        (Err((a, _)), Err((b, _))) => {
            assert_eq!(a, b, "check_value and parse_value report different offsets");
            assert!(*a <= text.len() && text.is_char_boundary(*a), "offset {a}");
        }
        _ => panic!("check_value {checked:?} but parse_value {parsed:?}"),
    }
});

fn walk<'a>(v: &'a Value, path: &[usize]) -> Lookup<'a> {
    let mut cur = v;
    for (depth, &ix) in path.iter().enumerate() {
        match cur {
            Value::Scalar(_) => return Lookup::NotAList { depth },
            Value::List(items) => match items.get(ix) {
                Some(item) => cur = item,
                None => {
                    return Lookup::OutOfRange {
                        depth,
                        len: items.len(),
                    };
                }
            },
        }
    }
    match cur {
        Value::Scalar(s) => Lookup::Scalar(s),
        Value::List(_) => Lookup::List,
    }
}

fn print(v: &Value) -> String {
    match v {
        Value::Scalar(s) => s.clone(),
        Value::List(items) => {
            let inner: Vec<String> = items.iter().map(print).collect();
            format!("({})", inner.join(", "))
        }
    }
}
