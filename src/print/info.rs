//! `--info`: version and build; with a blackboard, each resource's language, signals and
//! skills with the SFC variables each needs.

use std::fmt::Write as _;

use super::{language_text, signal_text};
use crate::model::Blackboard;

/// `--info`: version and build; with a blackboard, per resource the skills and the SFC
/// variables each needs (the original printed a fixed list of step types here).
pub fn info(bb: Option<&Blackboard>) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "skillpost v{}, build: {} {}",
        crate::VERSION,
        std::env::consts::OS,
        std::env::consts::ARCH
    );
    let _ = writeln!(
        o,
        "  Output profiles: KUKA KRL (.src/.dat), ABB RAPID (.mod), Universal Robots URScript (.script)"
    );
    let _ = writeln!(
        o,
        "  Step types: any; a step's variables come from its skill's SFC mapping"
    );
    if let Some(bb) = bb {
        for (ri, r) in bb.resources.iter().enumerate() {
            let _ = writeln!(o, "{}", r.name.text);
            let _ = writeln!(
                o,
                "  language {}",
                language_text(bb, ri, &Default::default())
            );
            if r.skills.is_empty() {
                let _ = writeln!(o, "  (no skills)");
            }
            for s in &r.signals {
                let _ = writeln!(o, "  signal {:<21} {}", s.name.text, signal_text(s));
            }
            for s in &r.skills {
                let vars = s.variables();
                let _ = writeln!(
                    o,
                    "  {:<28} variables: {}",
                    s.name.text,
                    if vars.is_empty() {
                        "none".to_owned()
                    } else {
                        vars.join(", ")
                    }
                );
            }
        }
    }
    o
}
