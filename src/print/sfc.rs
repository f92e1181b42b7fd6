//! `-pS`: the file header, the POU and every SFC object with its connections.

use std::fmt::Write as _;

use super::{one_line, seconds};
use crate::model::{ElementKind, Sfc, Value};

fn value_text(v: &Value) -> String {
    match v {
        Value::Scalar(s) => s.clone(),
        Value::List(items) => {
            let inner: Vec<String> = items.iter().map(value_text).collect();
            format!("[ {} ]", inner.join(", "))
        }
    }
}

/// `-pS`: the file header, then every SFC object with its connections.
pub fn sfc(sfc: &Sfc) -> String {
    let mut o = String::new();
    let h = &sfc.header;
    let parts: Vec<&str> = [
        &h.company_name,
        &h.product_name,
        &h.product_version,
        &h.creation_date_time,
    ]
    .iter()
    .map(|v| v.as_deref().unwrap_or("?"))
    .collect();
    let _ = writeln!(o, "{}", parts.join(", "));
    let _ = writeln!(o, "POU: {}", sfc.pou_name.as_deref().unwrap_or("?"));
    let mut succs: std::collections::HashMap<u64, Vec<u64>> = Default::default();
    for e in &sfc.elements {
        for (r, _) in &e.inputs {
            succs.entry(*r).or_default().push(e.local_id);
        }
    }
    let ids = |v: Option<&Vec<u64>>| match v {
        Some(v) if !v.is_empty() => v.iter().map(u64::to_string).collect::<Vec<_>>().join(", "),
        _ => "(?)".to_owned(),
    };
    for e in &sfc.elements {
        let ins: Vec<u64> = e.inputs.iter().map(|(r, _)| *r).collect();
        let conn = format!(
            "{} -> [ {} ] -> {}",
            ids(Some(&ins)),
            e.local_id,
            ids(succs.get(&e.local_id))
        );
        match &e.kind {
            ElementKind::Step(st) => {
                let _ = writeln!(
                    o,
                    "Step: {}     {}",
                    if st.initial { "*" } else { " " },
                    st.name
                );
                let _ = writeln!(o, "            {conn}");
                let _ = writeln!(
                    o,
                    "            Duration:   {}",
                    seconds(st.duration.unwrap_or(0.0))
                );
                if let Some(r) = &st.resource {
                    let _ = writeln!(o, "            Resource:   {}", r.text);
                }
                if let Some(s) = &st.skill {
                    let _ = writeln!(o, "            Skill:      {}", s.text);
                }
                for v in sfc.variables_of(st) {
                    let value = sfc.value_of(v);
                    let kind = match value {
                        Value::Scalar(_) => "(Value)",
                        Value::List(_) => "(List) ",
                    };
                    let _ = writeln!(
                        o,
                        "            {:<19} {kind}    = {}",
                        format!("{}:", v.name.text.to_uppercase()),
                        value_text(&value)
                    );
                }
            }
            k => {
                let _ = writeln!(o, "Transition  ({})", k.tag());
                let _ = writeln!(o, "            {conn}");
                match k {
                    ElementKind::Transition(Some(c)) => {
                        let _ = writeln!(
                            o,
                            "            Condition:  {}{}",
                            one_line(&c.text),
                            if c.reference { "   (reference)" } else { "" }
                        );
                    }
                    ElementKind::Transition(None) => {
                        let _ = writeln!(o, "            Condition:  TRUE");
                    }
                    ElementKind::JumpStep(Some(t)) => {
                        let _ = writeln!(o, "            Target:     {}", t.text);
                    }
                    _ => {}
                }
            }
        }
    }
    o
}
