//! The programs of a compile: one, or one per controller of a cell (docs/CELLS.md), their names
//! and languages, and their files emitted (on two threads where there are several).

use super::*;

/// A generated file, and what the built-in check found in it when it was checked right after
/// it was written (`None`: not checked yet).
pub(super) type Written = (OutputFile, Option<Vec<crate::check::Problem>>);

/// The programs' files, in order (`None` where a program has errors, reported in `diags`).
/// A cell's programs are written two at a time when they hold `split_from` steps or more
/// ([`bind::PARALLEL_FROM`], as the binder splits): the calling thread and another each take
/// the next program when done with one, the programs with most steps first, and check its
/// files while their text is still in the cache; each is written on its own, so the result is
/// the same (`tests/bind_split.rs` compares them); the diagnostics kept in program order.
pub(super) fn emit_programs(
    inputs: &[(EmitInput, &OutputTemplate)],
    diags: &mut Diagnostics,
    steps: usize,
    split_from: usize,
) -> Vec<Option<Vec<Written>>> {
    type Emitted = (Option<Vec<Written>>, Diagnostics);
    let emit = |(input, template): &(EmitInput, &OutputTemplate),
                like: &Diagnostics,
                check: bool|
     -> Emitted {
        let mut d = like.empty_like();
        let files = crate::emit::emit_files(input, template, &mut d).map(|files| {
            files
                .into_iter()
                .map(|f| {
                    let problems = check.then(|| super::checks::check_output(&f));
                    (f, problems)
                })
                .collect()
        });
        (files, d)
    };
    let emitted: Vec<Emitted> = if inputs.len() < 2 || steps < split_from.max(2) {
        inputs.iter().map(|i| emit(i, diags, false)).collect()
    } else {
        let like = diags.empty_like();
        let steps: Vec<usize> = inputs.iter().map(|(i, _)| i.bound.steps.len()).collect();
        crate::threads::largest_first("skillpost-emit", &steps, |k| emit(&inputs[k], &like, true))
    };
    emitted
        .into_iter()
        .map(|(files, d)| {
            diags.append(d);
            files
        })
        .collect()
}

/// One program to write: a cell of several controllers has one per controller.
pub(super) struct ProgramSpec {
    /// The controller's resource (`None` when no step names one).
    pub(super) controller: Option<usize>,
    /// `None` without a program name (`--validate BLACKBOARD`: checked, not written).
    pub(super) name: Option<String>,
    pub(super) language: Language,
}

/// The programs of this compile and their names (docs/CELLS.md): one program `<PROGRAM>`; or, for
/// several controllers, each controller's `Program` attribute or `<PROGRAM>_<controller>`.
/// `E601` for a name that is not one of its language or is used twice.
pub(super) fn programs(
    cx: &mut Ctx,
    bb: &Blackboard,
    opts: &Options,
    controllers: &[usize],
    langs: &Languages,
) -> Vec<ProgramSpec> {
    if controllers.len() <= 1 {
        check_program_name(cx, opts, Some(langs.program));
        return vec![ProgramSpec {
            controller: controllers.first().copied(),
            name: opts.program.clone(),
            language: langs.program,
        }];
    }
    let mut out: Vec<ProgramSpec> = Vec::new();
    for &c in controllers {
        let res = &bb.resources[c];
        let language = langs.controller(bb, c);
        let (name, attr) = match &res.program_attr {
            Some((v, span)) => (Some(v.trim().to_owned()), Some(span.clone())),
            None => (
                opts.program
                    .as_ref()
                    .map(|p| format!("{p}_{}", name_part(&res.name.text))),
                None,
            ),
        };
        if let (Some(n), Some(_)) = (&name, &opts.program) {
            let why = language.profile().check_program_name(n).err().or_else(|| {
                out.iter()
                    .any(|o| o.name.as_deref().is_some_and(|m| m.eq_ignore_ascii_case(n)))
                    .then(|| "the name of another controller's program too".to_owned())
            });
            if let Some(why) = why {
                let mut d = Diagnostic::error(
                    Code::BadProgramName,
                    format!(
                        "the program of controller `{}` would be named `{n}`, which is {why}; set the controller's `Program` attribute to another name",
                        res.name.text
                    ),
                );
                if let Some(at) = attr {
                    d = d.at(at);
                } else {
                    d = d.at(res.name.span.clone()).element(res.element.clone());
                }
                cx.diags.push(d);
            }
        }
        out.push(ProgramSpec {
            controller: Some(c),
            name: if opts.program.is_some() { name } else { None },
            language,
        });
    }
    if opts.program.is_none() {
        check_program_name(cx, opts, Some(langs.program));
    }
    out
}

/// A controller's name as a part of a program name: letters, digits and `_` (others become
/// `_`; non-ASCII letters transliterated).
pub(super) fn name_part(name: &str) -> String {
    crate::names::transliterate(name)
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// The transitions a program of a cell waits for or decides, and the steps it runs (whose times
/// its conditions may read): element indexes, ascending, each once.
pub(super) fn evaluated(body: &[plan::Block]) -> Vec<usize> {
    let mut out = Vec::new();
    plan::visit(body, &mut |b| match b {
        plan::Block::Wait(t) | plan::Block::Step(t) => out.push(*t),
        plan::Block::Choice { branches, .. } => {
            out.extend(branches.iter().flat_map(|br| br.heads()));
        }
        _ => {}
    });
    out.sort_unstable();
    out.dedup();
    out
}

/// The language of each resource the program uses, and the program's.
pub(super) struct Languages {
    pub(super) program: Language,
    pub(super) resources: HashMap<usize, Language>,
    /// The resources with steps, in first-use order.
    pub(super) order: Vec<usize>,
}

impl Languages {
    /// A controller's program's language: its own, else that of its first device with steps.
    pub(super) fn controller(&self, bb: &Blackboard, c: usize) -> Language {
        self.resources
            .get(&c)
            .copied()
            .or_else(|| {
                self.order
                    .iter()
                    .find(|&&r| bb.controller_of(r) == c)
                    .map(|r| self.resources[r])
            })
            .or(bb.resources[c].language.as_ref().map(|l| l.0))
            .unwrap_or(Language::Krl)
    }

    pub(super) fn of(&self, resource: usize) -> Language {
        self.resources
            .get(&resource)
            .copied()
            .unwrap_or(Language::Krl)
    }
}

/// Decides the languages (docs/LANGUAGES.md): a resource's `Language` attribute, else the language its
/// IRL files declare, else KRL. An IRL file declaring another language than its resource's, and
/// steps of resources of different languages, are `E319`.
pub(super) fn languages(
    cx: &mut Ctx,
    bb: &Blackboard,
    res: &bind::Resolution,
    files: &[((usize, usize), crate::diag::FileId)],
) -> Languages {
    let mut declared: HashMap<crate::diag::FileId, Option<(Language, Span)>> = HashMap::new();
    for &(_, file) in files {
        if let std::collections::hash_map::Entry::Vacant(v) = declared.entry(file) {
            v.insert(irl::declared_language(&cx.sources, file, &mut cx.diags));
        }
    }
    // Each used resource once, in first-use order, with its IRL files: one pass over each
    // list (the number of resources is an input dimension).
    let mut by_resource: HashMap<usize, Vec<(usize, crate::diag::FileId)>> = HashMap::new();
    for &((r, f), file) in files {
        by_resource.entry(r).or_default().push((f, file));
    }
    let mut seen = std::collections::HashSet::new();
    let order: Vec<usize> = res
        .used
        .iter()
        .map(|&(r, _)| r)
        .filter(|&r| seen.insert(r))
        .collect();
    let mut resources: HashMap<usize, Language> = HashMap::new();
    let mut reported: std::collections::HashSet<crate::diag::FileId> = Default::default();
    for &r in &order {
        let resource = &bb.resources[r];
        let own = by_resource.get(&r).map_or(&[][..], Vec::as_slice);
        let from_irl = own.iter().find_map(|(_, file)| declared[file].clone());
        // A device without a language of its own is in its controller's (docs/CELLS.md).
        let controller = &bb.resources[bb.controller_of(r)];
        let decided = resource
            .language
            .as_ref()
            .map(|(l, at)| (*l, at.clone(), "the resource's Language"))
            .or(from_irl.map(|(l, at)| (l, at, "the first IRL file's language")))
            .or(controller
                .language
                .as_ref()
                .map(|(l, at)| (*l, at.clone(), "its controller's Language")));
        let lang = decided.as_ref().map_or(Language::Krl, |d| d.0);
        resources.insert(r, lang);
        for (f, file) in own {
            if let Some((l, span)) = &declared[file]
                && *l != lang
                && reported.insert(*file)
            {
                let mut d = Diagnostic::error(
                    Code::TwoLanguages,
                    format!(
                        "IRL file of function `{}` is {l}, but resource `{}` is {lang}: one program is in one language",
                        resource.functions[*f].name.text, resource.name.text
                    ),
                )
                .at(span.clone());
                // A declaration differs from the language only when something decided it.
                if let Some((_, at, what)) = &decided {
                    d = d.related(at.clone(), *what);
                }
                cx.diags.push(d);
            }
        }
    }
    // Each controller's program is in one language (docs/CELLS.md): its own, else its first
    // device's with steps.
    let program_of = |c: usize| {
        resources.get(&c).copied().or_else(|| {
            order
                .iter()
                .find(|&&r| bb.controller_of(r) == c)
                .map(|r| resources[r])
        })
    };
    let program = res.resource.and_then(program_of).unwrap_or(Language::Krl);
    let mut reported_controllers = std::collections::HashSet::new();
    for &other in &order {
        let c = bb.controller_of(other);
        let Some(lang) = program_of(c) else {
            continue;
        };
        if resources[&other] == lang
            // A device whose Language attribute differs from its controller's: reported at
            // the attribute by the reader.
            || (bb.resources[other].language.is_some() && bb.resources[c].language.is_some())
            || !reported_controllers.insert(c)
        {
            continue;
        }
        let first = order
            .iter()
            .copied()
            .find(|&r| bb.controller_of(r) == c)
            .unwrap_or(c);
        cx.diags.push(Diagnostic::error(
            Code::TwoLanguages,
            format!(
                "steps use resource `{}` ({lang}) and resource `{}` ({}), both on the controller of `{}`: one program is in one language",
                bb.resources[first].name.text,
                bb.resources[other].name.text,
                resources[&other],
                bb.resources[c].name.text
            ),
        ));
    }
    Languages {
        program,
        resources,
        order,
    }
}
