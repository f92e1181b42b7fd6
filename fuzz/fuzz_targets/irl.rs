//! The IRL reader: bytes → `read::xml::load` → `read_irl`; every call's template renders (with
//! its parameters' names as values, and with empty values); the diagnostics in every format.
#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;
use skillpost::read::irl::read_irl;

fuzz_target!(|data: &[u8]| {
    let (sources, mut diags, file) = common::load("/p/robot.irl", data);
    let irl = file.and_then(|f| read_irl(&sources, f, &mut diags));
    if let Some(irl) = &irl {
        for call in &irl.calls {
            let t = &call.template;
            assert_eq!(t.param_count(), call.params.len());
            assert_eq!(t.used().len(), call.params.len());
            let names: Vec<&str> = call.params.iter().map(|p| &*p.text).collect();
            let mut out = String::new();
            t.render(&names, &mut out);
            let empty = vec![""; names.len()];
            let mut out2 = String::new();
            t.render(&empty, &mut out2);
            assert!(out2.len() <= out.len());
        }
        for d in &irl.definitions {
            assert!(d.lines.iter().all(|l| !l.contains('\n')));
        }
    }
    let mut diags = diags;
    diags.sort();
    common::render_all(&diags.into_vec(), &sources);
});
