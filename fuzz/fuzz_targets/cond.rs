//! The transition condition parser (`cond/`):
//!
//! - `parse` never panics; an error's range lies inside the text, on character boundaries;
//! - a parsed condition printed back as ST (`Expr::to_st`, fully parenthesised) parses to a tree
//!   that prints the same (the tree survives the round trip), unless the added parentheses pass
//!   the nesting or length limit;
//! - the KRL rendering has balanced parentheses and no `=` without its `==`/`<=`/`>=`/`<>`;
//! - `check` never panics, whatever the names resolve to.
#![no_main]

use libfuzzer_sys::fuzz_target;
use skillpost::cond::{Ty, check, parse, render_krl};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match parse(text, &|o| o) {
        Ok(e) => {
            assert!(
                e.span.start <= e.span.end && e.span.end <= text.len(),
                "{e:?}"
            );
            for (_, r) in e.names() {
                assert!(text.get(r.clone()).is_some(), "name span {r:?} in {text:?}");
            }
            let printed = e.to_st();
            match parse(&printed, &|o| o) {
                Ok(again) => assert_eq!(again.to_st(), printed, "round trip of {text:?}"),
                // The printed form has more parentheses: it may pass the limits the text kept.
                Err(err) if err.message.contains("deeper") || err.message.contains("longer") => {}
                Err(err) => panic!("{printed:?} (from {text:?}) does not parse: {err:?}"),
            }
            let krl = render_krl(&e, &|n| format!("$IN[{}]", n.len()));
            let mut depth = 0i32;
            for c in krl.chars() {
                match c {
                    '(' => depth += 1,
                    ')' => depth -= 1,
                    _ => {}
                }
                assert!(depth >= 0, "{krl}");
            }
            assert_eq!(depth, 0, "{krl}");
            let _ = check(&e, &|n| match n.len() % 3 {
                0 => Some(Ty::Bool),
                1 => Some(Ty::Number),
                _ => None,
            });
        }
        Err(err) => {
            assert!(
                err.at.start <= err.at.end
                    && err.at.end <= text.len()
                    && text.is_char_boundary(err.at.start)
                    && text.is_char_boundary(err.at.end),
                "error range {:?} in {text:?}",
                err.at
            );
        }
    }
});
