//! The whole pipeline for one project: read → plan → bind → emit, with every file read through a
//! [`FileSource`]. [`compile`] does no writing; [`apply`] writes the outputs and the write-back.

use std::collections::{HashMap, HashSet};
use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::bind;
use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::emit::{EmitInput, LanguageProfile as _, OutputFile, OutputTemplate};
use crate::lang::Language;
use crate::load::FileSource;
use crate::model::{Blackboard, Sfc};
use crate::paths;
use crate::plan::{self, Plan};
use crate::read::irl::Irl;
use crate::read::{blackboard::read_blackboard, irl, sfc::read_sfc_pou, xml};

mod binding;
mod checks;
mod ctx;
mod definitions;
mod parts;
mod programs;
use checks::*;
use ctx::*;
use programs::*;

/// The `DEF` name the code is generated under when no program name is given (a valid KRL name;
/// the code is checked, then discarded).
const PLACEHOLDER_PROGRAM: &str = "VALIDATE";

/// What to compile and how.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// The program name (`<PROGRAM>`): the output files' stem and the `DEF` name. `None`
    /// checks everything without one (`--validate BLACKBOARD`): the code is still generated, under
    /// a placeholder name, so its checks run, but no outputs and no write-back are produced.
    pub program: Option<String>,
    /// LF line endings instead of CRLF.
    pub lf: bool,
    /// A user output template instead of the built-in one.
    pub template: Option<PathBuf>,
    /// Refuse references that leave this folder (the daemon's project folder).
    pub confine_to: Option<PathBuf>,
    /// The SFC POU to use (`--pou`); else the SFC reference's `#fragment`, else the first
    /// program with an SFC body.
    pub pou: Option<String>,
    /// Return the SFC model and the plan in the [`Compilation`] (for the listings); else they
    /// are freed before the compile ends.
    pub keep_model: bool,
    /// Keep no warnings (the command line without `--warn` shows none): none is built, and the
    /// SFC is not read again to locate them. The daemon keeps them (its events count them).
    pub drop_warnings: bool,
    /// Steps from which the binder renders on two threads, a cell's programs are written two at
    /// a time, and a program's steps are read ahead of its writer on a second thread (`None`:
    /// [`bind::PARALLEL_FROM`]). For the tests, which compare the ways.
    #[doc(hidden)]
    pub bind_split_from: Option<usize>,
    /// A picture of the plan (`--svg FILE`) written besides the outputs: like an output, it may
    /// not be a file the compile reads (`E605`).
    pub picture: Option<PathBuf>,
    /// The longest program per language before it is split into parts (`--max-lines`).
    pub max_lines: crate::emit::split::Limits,
}

/// The write-back to do after a successful compile.
#[derive(Debug, Clone)]
pub struct WriteBack {
    pub blackboard: PathBuf,
    /// The blackboard's bytes as read (BOM included).
    pub expected: Vec<u8>,
    pub bom: bool,
    /// The refURI `Attribute` element's range in the text after the BOM.
    pub attribute: Range<usize>,
    /// Where the value goes in the text after the BOM, as the reader found it.
    pub site: crate::write::SpliceSite,
    /// The value to write: the `.src` path relative to the blackboard, with `/`.
    pub value: String,
    /// The other programs of a cell, each into its controller's `Code` interface (docs/CELLS.md).
    pub more: Vec<(crate::write::SpliceSite, String)>,
}

impl WriteBack {
    /// Every value to write and where.
    pub fn splices(&self) -> Vec<(&crate::write::SpliceSite, &str)> {
        std::iter::once((&self.site, self.value.as_str()))
            .chain(self.more.iter().map(|(s, v)| (s, v.as_str())))
            .collect()
    }

    /// The blackboard's bytes after this write-back (BOM included): what [`apply`] writes when
    /// it writes. `None` when the value is already right or cannot be spliced.
    pub fn new_bytes(&self) -> Option<Vec<u8>> {
        let body = if self.bom {
            self.expected.get(3..)?
        } else {
            &self.expected
        };
        let text = std::str::from_utf8(body).ok()?;
        let new = crate::write::splice_all(text, &self.splices()).ok()??;
        let mut out = Vec::with_capacity(new.len() + 3);
        if self.bom {
            out.extend_from_slice(b"\xEF\xBB\xBF");
        }
        out.extend_from_slice(new.as_bytes());
        Some(out)
    }
}

/// Everything a compile produced.
#[derive(Debug, Default)]
pub struct Compilation {
    pub sources: Sources,
    /// Sorted by file and position.
    pub diagnostics: Vec<Diagnostic>,
    /// Warnings found but not kept ([`Options::drop_warnings`]): the run says how many.
    pub dropped_warnings: usize,
    /// Every file the compile asked for, read or not (the daemon watches these).
    pub files_read: Vec<PathBuf>,
    /// Set when the blackboard itself (or the SFC with `--sfc`, or the `--template`) could not be
    /// read (an I/O failure, exit status 2).
    pub io_failure: bool,
    /// The outputs to write, with their paths; empty when there are errors.
    pub outputs: Vec<(PathBuf, OutputFile)>,
    pub write_back: Option<WriteBack>,
    pub blackboard: Option<Blackboard>,
    /// The SFC model and the plan: with [`Options::keep_model`] (and always from
    /// [`check_sfc`]).
    pub sfc: Option<Sfc>,
    pub plan: Option<Plan>,
    pub irls: Vec<Irl>,
    /// Skill steps that produce code.
    pub skill_steps: usize,
    /// The language of each resource the program uses (by resource index), as decided.
    pub languages: HashMap<usize, Language>,
    /// The program's language (`None` when no SFC could be read).
    pub language: Option<Language>,
    /// Wall time per stage, in order (`read-blackboard`, `read-sfc`, `plan`, `bind`, `emit`).
    pub timings: Vec<(&'static str, std::time::Duration, Option<u64>)>,
    /// The resource whose controller runs the program (docs/CELLS.md).
    pub controller: Option<String>,
    /// Per output (same order): its program's name and its controller's (docs/CELLS.md).
    pub output_programs: Vec<(String, String)>,
    /// The programs' names, the written-back one first (empty without a program name).
    pub program_names: Vec<String>,
    /// The cell's programs and handshakes when its steps run on several controllers.
    pub cell: Option<plan::cell::Cell>,
    /// The blackboard's folder, held open since before the blackboard was read: [`apply`]
    /// writes through it (`None` where it could not be opened, e.g. a compile from memory).
    pub folder: Option<crate::write::Folder>,
    /// Per program: the parts it was split into, for [`apply`] to remove those of an earlier,
    /// longer compile (docs/LANGUAGES.md, "Long programs").
    pub part_files: Vec<parts::PartFiles>,
}

/// The plan as an SVG timeline ([`crate::picture`]): one lane per controller of a cell (with
/// its program's handshakes), else one. Its title names every program, by its main file and
/// its controller, and the chart: `Cell: A.src (KUKA KR15-2), B.mod (ABB IRB 1200): the chart
/// of Demo`; `name` stands for the program when the compile has no program name. `None`
/// without a plan (errors, or a compile that did not keep the model).
pub fn picture(c: &Compilation, name: &str) -> Option<String> {
    let (sfc, plan) = (c.sfc.as_ref()?, c.plan.as_ref()?);
    let lanes = match (&c.cell, &c.blackboard) {
        (Some(cell), Some(bb)) => {
            let mut of = HashMap::new();
            for (k, p) in cell.programs.iter().enumerate() {
                plan::visit(&p.body, &mut |b| {
                    if let plan::Block::Step(i) = b {
                        of.insert(*i, k);
                    }
                });
            }
            crate::picture::Lanes {
                names: cell
                    .controllers
                    .iter()
                    .enumerate()
                    .map(|(k, &r)| {
                        (
                            bb.resources[r].name.text.to_string(),
                            c.program_names.get(k).cloned().unwrap_or_default(),
                        )
                    })
                    .collect(),
                of,
                programs: cell.programs.iter().map(|p| p.body.as_slice()).collect(),
            }
        }
        _ => crate::picture::Lanes {
            names: vec![(
                c.controller.clone().unwrap_or_else(|| "the robot".into()),
                c.program_names.first().cloned().unwrap_or_default(),
            )],
            of: HashMap::new(),
            programs: Vec::new(),
        },
    };
    // Each program by its main file (its first output), else its name.
    let programs: Vec<String> = lanes
        .names
        .iter()
        .map(|(controller, program)| {
            let file = c
                .outputs
                .iter()
                .zip(&c.output_programs)
                .find(|(_, (p, _))| p == program && !program.is_empty())
                .and_then(|((path, _), _)| path.file_name())
                .map(|f| f.to_string_lossy().into_owned());
            let program = match (file, program.is_empty()) {
                (Some(f), _) => f,
                (None, false) => program.clone(),
                (None, true) => name.to_owned(),
            };
            if c.controller.is_none() && c.cell.is_none() {
                program
            } else {
                format!("{program} ({controller})")
            }
        })
        .collect();
    let chart = sfc
        .pou_name
        .as_ref()
        .map_or_else(|| "the chart".to_owned(), |p| format!("the chart of {p}"));
    let title = if programs.len() > 1 {
        format!("Cell: {}: {chart}", programs.join(", "))
    } else {
        format!("{}: {chart}", programs.join(", "))
    };
    Some(crate::picture::svg(sfc, plan, &lanes, &title))
}

impl Compilation {
    pub fn has_errors(&self) -> bool {
        self.diagnostics
            .iter()
            .any(|d| d.severity == crate::diag::Severity::Error)
    }
}

/// Compiles one project. Never writes; see [`apply`].
pub fn compile(fs: &dyn FileSource, blackboard: &Path, opts: &Options) -> Compilation {
    let base = blackboard.parent().map(Path::to_owned).unwrap_or_default();
    let mut cx = Ctx::new(
        fs,
        base,
        opts.confine_to.as_ref().map(|p| paths::absolute(p)),
    );
    let mut out = Compilation::default();
    if opts.drop_warnings {
        cx.diags.drop_warnings();
    }
    // Before the blackboard is read: the outputs go to the folder it was read from.
    out.folder = crate::write::Folder::pin(match blackboard.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    });
    let mut clock = std::time::Instant::now();
    // The process's peak memory after each stage, only when the timings are printed.
    let peak = std::env::var_os("SKILLPOST_TIMINGS").is_some();
    let mut lap = |out: &mut Compilation, stage: &'static str| {
        let now = std::time::Instant::now();
        out.timings
            .push((stage, now - clock, peak.then(peak_kib).flatten()));
        clock = now;
    };

    let Some(bb_file) = cx.load_top(blackboard, &mut out) else {
        return finish(cx, out);
    };
    let Some(bb) = read_blackboard(&cx.sources, bb_file, &mut cx.diags) else {
        return finish(cx, out);
    };
    lap(&mut out, "read-blackboard");

    // The SFC and its plan.
    let pou = opts
        .pou
        .clone()
        .or_else(|| bb.sfc_ref.as_ref().and_then(|r| fragment(&r.value)));
    // The model holds all the rest needs: the SFC's text (the largest input: 78 MB for 100,000
    // steps) is read as a stream, and read again only if a diagnostic points into it.
    let (_, mut sfc) = match bb
        .sfc_ref
        .clone()
        .and_then(|r| Some((cx.ref_path(&r.value, &r.span)?, r.span)))
    {
        Some((path, at)) => cx.read_sfc(&path, Some(&at), pou.as_deref(), &mut out),
        None => (None, None),
    };
    lap(&mut out, "read-sfc");
    if let Some(s) = &mut sfc {
        plan::close_circles(s);
    }
    let mut plan = sfc.as_ref().and_then(|s| plan::plan(s, &mut cx.diags));
    lap(&mut out, "plan");

    // Bind, loading the IRL files the used skills need.
    let mut irls: Vec<Irl> = Vec::new();
    let mut language = None;
    let mut other_write_backs: Vec<(crate::write::SpliceSite, String)> = Vec::new();
    if let Some(sfc) = &mut sfc {
        // Bind even when the flow has errors (in document order), so one run reports every
        // problem; emit only a planned flow.
        let order = match &plan {
            Some(p) => bind::StepOrder::planned(p),
            None => bind::StepOrder::document(sfc),
        };
        let res = bind::resolve(&bb, sfc, &order, &mut cx.diags);
        // Several initial steps: each sequence on controllers of its own (docs/INPUTS.md, docs/CELLS.md).
        if let Some(p) = &mut plan {
            plan::place_sequences(
                p,
                sfc,
                &|i| res.step_skill[i].map(|(r, _)| bb.controller_of(r)),
                &|c| bb.resources[c].name.text.to_string(),
                &mut cx.diags,
            );
        }
        let needed = bind::needed_functions(&bb, &res, &mut cx.diags);
        let mut files: Vec<((usize, usize), crate::diag::FileId)> = Vec::new();
        for (r, f) in needed {
            let func = &bb.resources[r].functions[f];
            if let Some(file) = cx.load_ref(&func.irl.value, &func.irl.span) {
                files.push(((r, f), file));
            }
        }
        // A cell past the budget is refused before it is split, bound or written.
        let Some(controllers) =
            bind::budget::controllers_within_budget(&res, &bb, &order, sfc, &mut cx.diags)
        else {
            return finish(cx, out);
        };
        let langs = languages(&mut cx, &bb, &res, &files);
        language = Some(langs.program);
        out.languages = langs.resources.clone();
        out.controller = res.resource.map(|r| bb.resources[r].name.text.to_string());
        let mut fn_irl: HashMap<(usize, usize), usize> = HashMap::new();
        let mut by_file: HashMap<(crate::diag::FileId, Language), Option<usize>> = HashMap::new();
        for ((r, f), file) in files {
            let lang = langs.of(r);
            let idx = *by_file.entry((file, lang)).or_insert_with(|| {
                irl::read_irl_in(&cx.sources, file, lang, &mut cx.diags).map(|irl| {
                    irls.push(irl);
                    irls.len() - 1
                })
            });
            if let Some(i) = idx {
                fn_irl.insert((r, f), i);
            }
        }
        // The programs: one, or one per controller of a cell (docs/CELLS.md).
        let programs = programs(&mut cx, &bb, opts, &controllers, &langs);
        let cell = match (&plan, controllers.len() > 1) {
            (Some(plan), true) => {
                // By resource: its place among the controllers (a step's controller is one).
                let mut index = vec![usize::MAX; bb.resources.len()];
                for (k, &c) in controllers.iter().enumerate() {
                    index[c] = k;
                }
                let of = |i: usize| res.step_skill[i].map(|(r, _)| index[bb.controller_of(r)]);
                let mut cell = plan::cell::split(&plan.body, controllers.clone(), &of);
                plan::cell::assign_wires(&mut cell, &bb, sfc, &mut cx.diags);
                Some(cell)
            }
            _ => None,
        };
        lap(&mut out, "resolve+split");
        // A language named wrongly (E210) makes the language a guess: its signal rules are
        // not applied then.
        let sure = !cx.diags.iter().any(|d| d.code == Code::BadLanguage);
        let mut bound_programs = binding::bind_programs(
            &binding::Inputs {
                bb: &bb,
                sfc,
                order: &order,
                res: &res,
                irls: &irls,
                fn_irl: &fn_irl,
                controllers: &controllers,
                cell: cell.as_ref(),
                sure,
                split_from: opts.bind_split_from.unwrap_or(bind::PARALLEL_FROM),
            },
            &programs,
            &mut cx.diags,
        );
        definitions::unused_definitions(&mut cx.diags, &irls, &bound_programs);
        out.skill_steps = bound_programs.iter().map(|b| b.steps.len()).sum();
        if !opts.keep_model {
            let variables = sfc.take_variables();
            if sfc.elements.len() >= FREE_ASIDE_FROM {
                free_aside(variables);
            }
        }
        let sfc = &*sfc;
        lap(&mut out, "bind");
        // The output template: like the blackboard, one the command names, so a template
        // that cannot be read at all is an I/O failure. It is the first program's language's;
        // programs of other languages use their built-in one.
        let user_template = opts
            .template
            .as_ref()
            .and_then(|p| cx.load_top(p, &mut out));
        let mut outputs = Vec::new();
        let mut output_programs = Vec::new();
        // Per output: what the built-in check found when it ran as the file was written.
        let mut checked = Vec::new();
        let templates: Vec<Option<OutputTemplate>> = programs
            .iter()
            .map(|prog| match user_template {
                Some(f) if prog.language == langs.program => {
                    OutputTemplate::parse(&cx.sources, f, prog.language, &mut cx.diags)
                }
                _ if opts.template.is_some() && prog.language == langs.program => None,
                _ => Some(OutputTemplate::builtin(prog.language)),
            })
            .collect();
        if !cx.diags.has_errors()
            && let Some(plan) = &plan
            && templates.iter().all(Option::is_some)
        {
            let inputs: Vec<(EmitInput, &OutputTemplate)> = programs
                .iter()
                .zip(&templates)
                .enumerate()
                .filter_map(|(k, (prog, template))| {
                    let template = template.as_ref()?;
                    let input = EmitInput {
                        program: prog.name.as_deref().unwrap_or(PLACEHOLDER_PROGRAM),
                        blackboard: &bb,
                        sfc,
                        body: match &cell {
                            Some(c) => &c.programs[k].body,
                            None => &plan.body,
                        },
                        bound: &bound_programs[k],
                        irls: &irls,
                        newline: if opts.lf { "\n" } else { "\r\n" },
                        step_indent: &template.step_indent,
                        steps_indent: template.steps_indent(),
                        profile: prog.language.profile(),
                        cell: cell
                            .as_ref()
                            .map(|c| crate::emit::handshake::CellView { cell: c, me: k }),
                        max_lines: opts.max_lines.of(prog.language),
                        // A cell's programs are written two at a time: both cores are busy.
                        read_ahead_from: if programs.len() == 1 {
                            opts.bind_split_from.unwrap_or(bind::PARALLEL_FROM)
                        } else {
                            usize::MAX
                        },
                    };
                    Some((input, template))
                })
                .collect();
            let split_from = opts.bind_split_from.unwrap_or(bind::PARALLEL_FROM);
            let emitted = emit_programs(&inputs, &mut cx.diags, out.skill_steps, split_from);
            for ((files, prog), _) in emitted.into_iter().zip(&programs).zip(&inputs) {
                let (Some(files), Some(name)) = (files, &prog.name) else {
                    continue;
                };
                out.part_files.push(parts::PartFiles::of(
                    &cx.base,
                    name,
                    prog.language,
                    files.first().map(|(f, _)| f),
                ));
                for (f, problems) in files {
                    checked.push(problems);
                    let stem = f.stem.as_deref().unwrap_or(name);
                    let path = cx.base.join(format!("{stem}.{}", f.extension));
                    outputs.push((path, f));
                    output_programs.push((
                        name.clone(),
                        prog.controller
                            .map(|c| bb.resources[c].name.text.to_string())
                            .unwrap_or_default(),
                    ));
                }
            }
        }
        if plan.is_some() && !cx.diags.has_errors() {
            lap(&mut out, "emit");
        }
        // The other programs of a cell go into their controllers' `Code` interfaces.
        for prog in programs.iter().skip(1) {
            let (Some(c), Some(name)) = (prog.controller, &prog.name) else {
                continue;
            };
            let controller = &bb.resources[c].name.text;
            let main = bb.write_back.as_ref().map(|w| w.attribute.range.clone());
            match bb.code_targets.iter().find(|(n, t)| {
                crate::names::eq(n, controller) && Some(&t.attribute.range) != main.as_ref()
            }) {
                Some((_, t)) => other_write_backs.push((
                    t.site.clone(),
                    format!("{name}.{}", prog.language.profile().files()[0]),
                )),
                None => cx.diags.push(
                    Diagnostic::warning(
                        Code::NoProgramTarget,
                        format!(
                            "no `Code` interface named `{controller}`: the path of its program `{name}` is not written into the blackboard (add an ExternalInterface `{controller}` with a `refURI` attribute under `Code`)"
                        ),
                    )
                    .at(bb.resources[c].name.span.clone())
                    .element(bb.resources[c].element.clone()),
                ),
            }
        }
        // The built-in check (issue 28): the IRL snippets first, so that a broken one is named
        // in its file; then every generated file, which must load on its controller.
        for (k, irl) in irls.iter().enumerate() {
            // The definitions a program uses (an unused one is never written), every call.
            let used: HashSet<&str> = bound_programs
                .iter()
                .flat_map(|b| &b.definitions)
                .filter(|(i, _)| *i == k)
                .map(|&(_, d)| irl.definitions[d].name.key.as_ref())
                .collect();
            check_snippets(&cx.sources, irl, &used, &mut cx.diags);
        }
        if !cx.diags.has_errors() {
            check_generated(
                &outputs,
                std::mem::take(&mut checked),
                &cx.sources,
                user_template,
                &mut cx.diags,
            );
            definitions::check_definitions_held(
                &outputs,
                &cx.sources,
                &irls,
                &programs,
                &bound_programs,
                &mut cx.diags,
            );
        }
        lap(&mut out, "check");
        // The steps' code (100,000 steps: as many strings, ~7 ms to free) is freed on another
        // thread while the files are written.
        if sfc.elements.len() >= FREE_ASIDE_FROM {
            free_aside(std::mem::take(&mut bound_programs));
        }
        out.outputs = outputs;
        out.output_programs = output_programs;
        out.program_names = programs.iter().filter_map(|p| p.name.clone()).collect();
        out.cell = cell;
    } else {
        check_program_name(&mut cx, opts, None);
        if let Some(p) = &opts.template {
            // Read (an unreadable template is an I/O failure); its language is not known.
            cx.load_top(p, &mut out);
        }
    }
    let picture = opts.picture.iter().map(|p| p.as_path());
    let written: Vec<&Path> = out
        .outputs
        .iter()
        .map(|(p, _)| p.as_path())
        .chain(picture)
        .collect();
    check_outputs(&mut cx, &written, blackboard, opts.template.as_deref());
    if let Some(pic) = &opts.picture {
        check_picture(&mut cx, pic, &out.outputs);
    }

    if !cx.diags.has_errors()
        && let Some(wb) = &bb.write_back
        && let Some(program) = out.program_names.first()
    {
        let src = cx.sources.get(bb_file);
        let mut expected = Vec::with_capacity(src.text.len() + 3);
        if src.bom {
            expected.extend_from_slice(b"\xEF\xBB\xBF");
        }
        expected.extend_from_slice(src.text.as_bytes());
        out.write_back = Some(WriteBack {
            blackboard: blackboard.to_owned(),
            expected,
            bom: src.bom,
            attribute: wb.attribute.range.clone(),
            site: wb.site.clone(),
            value: format!(
                "{program}.{}",
                language.unwrap_or(Language::Krl).profile().files()[0]
            ),
            more: std::mem::take(&mut other_write_backs),
        });
    }
    out.language = language;
    out.blackboard = Some(bb);
    if opts.keep_model {
        out.sfc = sfc;
        out.plan = plan;
    } else {
        // Freed before the SFC's text may be read again for the diagnostics (`finish`): the
        // two together were the compile's peak. A large model is freed on another thread
        // meanwhile (100,000 steps: ~40 ms the caller need not wait for).
        let large = sfc
            .as_ref()
            .is_some_and(|s| s.elements.len() >= FREE_ASIDE_FROM);
        if large {
            free_aside((plan, sfc));
        } else {
            drop(plan);
            drop(sfc);
        }
    }
    out.irls = irls;
    finish(cx, out)
}

/// SFC elements from which the model is freed on another thread.
const FREE_ASIDE_FROM: usize = 20_000;

/// Drops `big` on a thread of its own; where none can be started, here.
fn free_aside<T: Send + 'static>(big: T) {
    // A thread that cannot be started drops the closure, and with it `big`, right here.
    let _ = std::thread::Builder::new()
        .name("skillpost-free".into())
        .spawn(move || drop(big));
}

/// The `#fragment` of a `refURI` (the SFC POU it names), percent-decoded.
fn fragment(value: &str) -> Option<String> {
    let v = value.trim().trim_matches('"');
    let (_, f) = v.split_once('#')?;
    let f = paths::percent_decode(f).unwrap_or_else(|| f.to_owned());
    let f = f.trim();
    (!f.is_empty()).then(|| f.to_owned())
}

/// Checks an SFC file on its own (`--sfc`): read and plan, no blackboard.
pub fn check_sfc(fs: &dyn FileSource, path: &Path) -> Compilation {
    check_sfc_pou(fs, path, None)
}

/// [`check_sfc`] of the POU named `pou`.
pub fn check_sfc_pou(fs: &dyn FileSource, path: &Path, pou: Option<&str>) -> Compilation {
    let mut cx = Ctx::new(fs, PathBuf::new(), None);
    let mut out = Compilation::default();
    let (Some(_), sfc) = cx.read_sfc(path, None, pou, &mut out) else {
        return finish(cx, out);
    };
    out.sfc = sfc;
    if let Some(sfc) = &out.sfc {
        // Without a blackboard the names stay unresolved: only what the literals tell.
        bind::check_conditions_unresolved(sfc, &mut cx.diags);
    }
    if let Some(s) = &mut out.sfc {
        plan::close_circles(s);
    }
    out.plan = out.sfc.as_ref().and_then(|s| plan::plan(s, &mut cx.diags));
    finish(cx, out)
}

fn finish(mut cx: Ctx, mut out: Compilation) -> Compilation {
    cx.restore_for_diagnostics();
    cx.diags.snap(&cx.sources);
    let mut diags = cx.diags;
    diags.sort();
    out.dropped_warnings = diags.dropped_warnings();
    out.diagnostics = diags.into_vec();
    out.sources = cx.sources;
    out.files_read = cx.fs.read.into_inner();
    if out.has_errors() {
        out.outputs.clear();
        out.write_back = None;
    }
    out
}

/// Why nothing may be written: the blackboard's folder was moved away or replaced (by another
/// folder or a link to one) since the compile opened it; `None` when it is still there.
pub fn folder_replaced(c: &Compilation) -> Option<String> {
    let f = c.folder.as_ref()?;
    (!f.still_at_its_name()).then(|| {
        format!(
            "the project folder {} was moved or replaced during the compile; nothing was \
             written (compile again)",
            f.path().display()
        )
    })
}

/// Writes one more file of the compile (the daemon's picture of the plan) atomically and only
/// when its bytes change, through the folder the blackboard was read from, like [`apply`]'s
/// outputs: a project folder swapped for a link after the programs landed never gets the file
/// written into the link's target.
pub fn write_beside(
    c: &Compilation,
    path: &Path,
    bytes: &[u8],
) -> std::io::Result<crate::write::WriteOutcome> {
    match &c.folder {
        Some(f) => crate::write::write_if_changed(&f.route(path), bytes)
            .map_err(|e| std::io::Error::new(e.kind(), f.unroute(&e.to_string()))),
        None => crate::write::write_if_changed(path, bytes),
    }
}

/// What [`apply`] did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Applied {
    /// Each output path and whether it was (re)written.
    pub outputs: Vec<(PathBuf, bool)>,
    pub write_back: Option<crate::write::WriteBackOutcome>,
    /// Parts of a split program an earlier compile wrote and this one does not need, removed.
    pub removed: Vec<PathBuf>,
}

/// How often, and how long apart at first (doubling), the write-back is tried again while
/// another program has the blackboard open: about 1.3 s in all.
const IN_USE_TRIES: u32 = 6;
const IN_USE_FIRST_WAIT: std::time::Duration = std::time::Duration::from_millis(40);

/// The write-back into the blackboard at `path` (`wb.blackboard`, or the same file reached
/// through the held-open folder), tried again a few times while another program has the
/// blackboard open (an editor saving it holds it open for milliseconds); after that it is
/// reported as skipped.
fn write_back_retrying(
    wb: &WriteBack,
    path: &Path,
) -> std::io::Result<crate::write::WriteBackOutcome> {
    let mut wait = IN_USE_FIRST_WAIT;
    let mut tries = 1;
    loop {
        let outcome = crate::write::write_back_all(path, &wb.expected, wb.bom, &wb.splices())?;
        if outcome != crate::write::WriteBackOutcome::SkippedInUse || tries >= IN_USE_TRIES {
            return Ok(outcome);
        }
        std::thread::sleep(wait);
        wait *= 2;
        tries += 1;
    }
}

/// Writes the outputs (atomically, only when their bytes change), then the write-back, into
/// the folder the blackboard was read from ([`Compilation::folder`]); nothing when that folder
/// is no longer at its name ([`folder_replaced`]).
/// The process's peak resident memory so far in KiB (Linux: `VmHWM` of `/proc/self/status`;
/// `None` elsewhere).
pub fn peak_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line["VmHWM:".len()..]
        .trim()
        .strip_suffix("kB")?
        .trim()
        .parse()
        .ok()
}

pub fn apply(c: &Compilation) -> std::io::Result<Applied> {
    if let Some(why) = folder_replaced(c) {
        return Err(std::io::Error::other(why));
    }
    let route = |p: &Path| match &c.folder {
        Some(f) => f.route(p),
        None => p.to_path_buf(),
    };
    let unroute = |e: std::io::Error| match &c.folder {
        Some(f) => std::io::Error::new(e.kind(), f.unroute(&e.to_string())),
        None => e,
    };
    // The `.src` and `.dat` only work as a pair: both are replaced or neither is.
    let routed: Vec<PathBuf> = c.outputs.iter().map(|(p, _)| route(p)).collect();
    let files: Vec<(&Path, &[u8])> = routed
        .iter()
        .zip(&c.outputs)
        .map(|(p, (_, f))| (p.as_path(), f.text.as_bytes()))
        .collect();
    let outputs = crate::write::write_all_if_changed(&files)
        .map_err(unroute)?
        .into_iter()
        .zip(&c.outputs)
        .map(|(o, (p, _))| (p.clone(), o == crate::write::WriteOutcome::Written))
        .collect();
    let write_back = match &c.write_back {
        Some(wb) => Some(
            write_back_retrying(wb, &route(&wb.blackboard)).map_err(|e| {
                let e = unroute(e);
                std::io::Error::new(e.kind(), format!("{}: {e}", wb.blackboard.display()))
            })?,
        ),
        None => None,
    };
    // Parts an earlier compile wrote that this one does not: after the new files, so a
    // failed write leaves the program as it was.
    let removed = parts::remove_stale(&c.part_files, &route);
    Ok(Applied {
        outputs,
        write_back,
        removed,
    })
}
