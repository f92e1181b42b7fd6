//! The IRL definitions the generated programs hold: `E606` for a call of one a program does
//! not hold, `W308` for one no program holds.

use std::collections::HashSet;
use std::path::PathBuf;

use super::ProgramSpec;
use crate::bind;
use crate::diag::{Code, Diagnostic, Diagnostics, Sources};
use crate::emit::OutputFile;
use crate::read::irl;

/// `E606` for a generated program that calls a routine one of the project's IRL files defines
/// but does not hold it (the definition belongs to a resource of another controller, or the
/// call comes from the output template): it would not load.
pub(super) fn check_definitions_held(
    outputs: &[(PathBuf, OutputFile)],
    sources: &Sources,
    irls: &[irl::Irl],
    programs: &[ProgramSpec],
    bound: &[bind::Bound],
    diags: &mut Diagnostics,
) {
    for (path, f) in outputs {
        let Some((lang, crate::check::Unit::Program)) = crate::check::language_of(path) else {
            continue;
        };
        let stem = path.file_stem().and_then(|s| s.to_str());
        let Some(k) = programs.iter().position(|p| p.name.as_deref() == stem) else {
            continue;
        };
        let held: HashSet<String> = bound[k]
            .definitions
            .iter()
            .flat_map(|&(i, d)| bind::definitions::routines(lang, &irls[i].definitions[d]))
            .map(|r: String| bind::definitions::key(lang, &r))
            .collect();
        for (routine, i, d) in bind::definitions::missing(lang, &f.text, irls, &held) {
            let def = &irls[i].definitions[d];
            let file = path
                .file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into_owned());
            diags.push(
                Diagnostic::error(
                    Code::BadProgram,
                    format!(
                        "the generated {file} calls `{routine}` but does not hold it: {} defines it (definition `{}`) for a resource whose steps this program does not run (a resource on another controller, or the call is in the output template); give the resource that calls it its own definition, or put the resource on this controller",
                        sources.get(irls[i].file).display,
                        def.name.text
                    ),
                )
                .at(def.span.clone()),
            );
        }
    }
}

/// `W308` at each definition of the loaded IRL files that no program holds (its routine is
/// called by no program's code and no call is named like it), once per place.
pub(super) fn unused_definitions(
    diags: &mut Diagnostics,
    irls: &[irl::Irl],
    bound: &[bind::Bound],
) {
    let held: HashSet<(usize, usize)> = bound
        .iter()
        .flat_map(|b| b.definitions.iter().copied())
        .collect();
    // Each routine a held definition defines, by language and name as the language compares
    // names: a definition left out for another of the same routine says which one was taken.
    let mut taken: std::collections::HashMap<(crate::lang::Language, String), (usize, usize)> =
        std::collections::HashMap::new();
    for &(i, d) in &held {
        let lang = irls[i].language;
        for r in bind::definitions::routines(lang, &irls[i].definitions[d]) {
            let k = (lang, bind::definitions::key(lang, &r));
            let at = taken.entry(k).or_insert((i, d));
            *at = (*at).min((i, d));
        }
    }
    let mut seen = HashSet::new();
    for (i, f) in irls.iter().enumerate() {
        for (d, def) in f.definitions.iter().enumerate() {
            if held.contains(&(i, d)) || !seen.insert((f.file, def.span.range.start)) {
                continue;
            }
            let routines = bind::definitions::routines(f.language, def);
            let other = routines.iter().find_map(|r| {
                let k = (f.language, bind::definitions::key(f.language, r));
                taken.get(&k).map(|&at| (r, at))
            });
            let w = match (routines.as_slice(), other) {
                ([], _) => Diagnostic::warning(
                    Code::UnusedDefinition,
                    format!(
                        "definition `{}` is not written into any program: it defines no routine that a program could call",
                        def.name.text
                    ),
                ),
                (_, Some((r, (oi, od)))) => {
                    let o = &irls[oi].definitions[od];
                    // The routine as the definition taken spells it.
                    let k = bind::definitions::key(f.language, r);
                    let spelt = bind::definitions::routines(f.language, o)
                        .into_iter()
                        .find(|n| bind::definitions::key(f.language, n) == k)
                        .unwrap_or_else(|| r.clone());
                    Diagnostic::warning(
                        Code::UnusedDefinition,
                        format!(
                            "definition `{}` is not written into any program: `{r}` is defined again here, and the programs hold the first definition of it (definition `{}`); rename one of the two routines if both are meant",
                            def.name.text, o.name.text
                        ),
                    )
                    .related(o.span.clone(), format!("`{spelt}` is taken from here"))
                }
                (names, None) => Diagnostic::warning(
                    Code::UnusedDefinition,
                    format!(
                        "definition `{}` is not written into any program: no program calls {}",
                        def.name.text,
                        names
                            .iter()
                            .map(|n| format!("`{n}`"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ),
            };
            diags.push(w.at(def.span.clone()));
        }
    }
}
