//! Binding: each skill step's resource and skill, its function calls in order, and every value
//! taken from the SFC, type-checked (docs/INPUTS.md).
//!
//! Binding runs in two passes so the compiler can load exactly the IRL files it needs in between:
//! [`resolve`] finds each step's resource and skill; [`needed_functions`] lists the functions
//! those skills call; [`bind`] renders every call with the IRL templates.

use std::borrow::Cow;
use std::collections::{HashMap, HashSet};
use std::sync::Arc;

use crate::diag::{Code, Diagnostic, Diagnostics, Span};
use crate::model::{Blackboard, ElementKind, Sfc, Step};
use crate::read::irl::Irl;

pub mod budget;
mod conditions;
pub mod definitions;
mod step;
pub use conditions::{
    DEFAULT_HANDSHAKE_TIMEOUT_MS, DEFAULT_TIMERS, MAX_TIMER, Reads, StepNames, Watch,
    check_conditions_unresolved, conditions,
};
use step::*;

/// What binding needs to know of the program's robot language, handed in as data by the
/// caller: the language's profile implements it (`emit::Profile: Rules`), so this stage never
/// reaches up into `emit` (ARCHITECTURE.md, the layers; `tests/layers.rs`).
pub trait Rules: Sync {
    fn language(&self) -> crate::lang::Language;
    /// A value as this language writes it; `Err` says why the language cannot take it safely.
    fn literal<'v>(&self, v: &crate::value::Literal<'v>) -> Result<Cow<'v, str>, String>;
    /// A signal as a condition reads it: a boolean or an integer expression. `Err` says why the
    /// language cannot read this signal (for `E209`).
    fn signal(&self, s: &crate::model::Signal) -> Result<String, String>;
}

/// Which resource and skill each step uses.
#[derive(Debug, Default)]
pub struct Resolution {
    /// By element index: `(resource, skill)` for steps that produce code (shared by the
    /// programs of a cell: each binds only its own steps).
    pub step_skill: Arc<[Option<(usize, usize)>]>,
    /// The distinct `(resource, skill)` pairs used, in first-use order.
    pub used: Vec<(usize, usize)>,
    /// The program's resource: the controller of the first step (the first program's).
    pub resource: Option<usize>,
}

impl Resolution {
    /// This resolution for the program of one controller: the pairs its steps use. The steps'
    /// table is shared, not narrowed: [`bind`] binds the steps it is given, and a program of a
    /// cell is given its own ([`Resolution::runs_on`]).
    pub fn of_controller(&self, bb: &Blackboard, controller: usize) -> Resolution {
        Resolution {
            step_skill: Arc::clone(&self.step_skill),
            used: self
                .used
                .iter()
                .copied()
                .filter(|&(r, _)| bb.controller_of(r) == controller)
                .collect(),
            resource: Some(controller),
        }
    }

    /// Whether element `i` is a step with code on `controller` (a program of a cell's step).
    pub fn runs_on(&self, bb: &Blackboard, i: usize, controller: usize) -> bool {
        self.step_skill[i].is_some_and(|(r, _)| bb.controller_of(r) == controller)
    }
}

/// Which steps to bind, in which order.
#[derive(Debug, Clone)]
pub struct StepOrder {
    /// Element indexes of the steps, in execution order (or document order when the flow could
    /// not be planned: then the values are still checked, but nothing is emitted).
    pub steps: Vec<usize>,
    /// Each sequence's start and end step, which may name no skill; `None` when unknown (then
    /// any step may name no skill without an error, since the flow errors are reported
    /// already).
    pub start_end: Option<Vec<(usize, Option<usize>)>>,
}

impl StepOrder {
    /// The planned order.
    pub fn planned(plan: &crate::plan::Plan) -> Self {
        StepOrder {
            steps: plan.steps(),
            start_end: Some(plan.sequences.clone()),
        }
    }

    /// Every step in document order, for a flow that could not be planned.
    pub fn document(sfc: &Sfc) -> Self {
        StepOrder {
            steps: (0..sfc.elements.len())
                .filter(|&i| sfc.elements[i].kind.is_step())
                .collect(),
            start_end: None,
        }
    }
}

/// A resolved `(resource name, skill name)` pair, the names as the reader shares them.
type Recent<'a> = (&'a Arc<str>, &'a Arc<str>, (usize, usize));

/// Resolves every step's resource and skill.
pub fn resolve(
    bb: &Blackboard,
    sfc: &Sfc,
    order: &StepOrder,
    diags: &mut Diagnostics,
) -> Resolution {
    let mut r = Resolution::default();
    let mut step_skill = vec![None; sfc.elements.len()];
    let mut used: HashSet<(usize, usize)> = HashSet::new();
    // Resource key → index of its first resource.
    let mut by_key: HashMap<&str, usize> = HashMap::new();
    for (ri, res) in bb.resources.iter().enumerate() {
        by_key.entry(&res.name.key).or_insert(ri);
    }
    // The last few `(resource name, skill name)` pairs resolved without a diagnostic, by the
    // names' places in memory (the reader shares one `Arc` per distinct name): a plan repeats
    // a handful of skills, and each would otherwise hash its resource and its pair again.
    let mut recent: [Option<Recent>; 4] = [None; 4];
    // The resources whose `Skills` element is misnamed, said once each.
    let mut misnamed_said: HashSet<usize> = HashSet::new();
    let mut next_recent = 0;
    for &i in &order.steps {
        let e = &sfc.elements[i];
        let ElementKind::Step(st) = &e.kind else {
            continue;
        };
        if let (Some(rn), Some(sn)) = (&st.resource, &st.skill)
            && let Some(&(_, _, pair)) = recent
                .iter()
                .flatten()
                .find(|(r, s, _)| Arc::ptr_eq(r, &rn.key) && Arc::ptr_eq(s, &sn.key))
        {
            // Seen: the same resource (so no second-resource error) and a pair already used.
            step_skill[i] = Some(pair);
            continue;
        }
        // Only for a diagnostic: most steps make none.
        let label = || format!("localId {}", e.local_id);
        let Some(skill_name) = &st.skill else {
            if order
                .start_end
                .as_ref()
                .is_some_and(|se| !se.iter().any(|&(start, end)| i == start || Some(i) == end))
            {
                diags.push(
                    Diagnostic::error(
                        Code::UnknownSkill,
                        format!(
                            "step `{}` names no skill (addData/data/iwb/skill@name)",
                            st.name
                        ),
                    )
                    .at(e.span.clone())
                    .element(label()),
                );
            }
            continue;
        };
        let res = match &st.resource {
            Some(rn) => match by_key.get(&*rn.key).copied() {
                Some(ri) => ri,
                None => {
                    diags.push(
                        Diagnostic::error(
                            Code::UnknownResource,
                            format!(
                                "unknown resource `{}`; the blackboard has {}{}",
                                rn.text,
                                known(bb.resources.iter().map(|r| r.name.text.as_ref())),
                                crate::names::did_you_mean(
                                    &rn.text,
                                    bb.resources.iter().map(|r| r.name.text.as_ref())
                                )
                            ),
                        )
                        .at(rn.span.clone())
                        .element(label()),
                    );
                    continue;
                }
            },
            None => {
                let offering: Vec<usize> = (0..bb.resources.len())
                    .filter(|&ri| bb.resources[ri].skill(&skill_name.key).is_some())
                    .collect();
                match offering.as_slice() {
                    [ri] => {
                        diags.push(
                            Diagnostic::warning(
                                Code::ResourceInferred,
                                format!(
                                    "step names no resource; `{}` is the only one with skill `{}`",
                                    bb.resources[*ri].name.text, skill_name.text
                                ),
                            )
                            .at(e.span.clone())
                            .element(label()),
                        );
                        *ri
                    }
                    _ => {
                        diags.push(
                            Diagnostic::error(
                                Code::UnknownResource,
                                if offering.is_empty() {
                                    format!(
                                        "step names no resource, and no resource offers skill `{}`",
                                        skill_name.text
                                    )
                                } else {
                                    format!(
                                        "step names no resource, and {} resources offer skill `{}`",
                                        offering.len(),
                                        skill_name.text
                                    )
                                },
                            )
                            .at(e.span.clone())
                            .element(label()),
                        );
                        continue;
                    }
                }
            }
        };
        let resource = &bb.resources[res];
        let Some(sk) = resource.skill(&skill_name.key) else {
            let misnamed = resource.misnamed.iter().find(|m| m.2 == "Skills");
            if let Some((n, at, _)) = misnamed.filter(|_| resource.skills.is_empty()) {
                // The root cause, once per resource at the element: the skills are there, under
                // a name that is not read.
                if misnamed_said.insert(res) {
                    diags.push(
                        Diagnostic::error(
                            Code::UnknownSkill,
                            format!(
                                "resource `{}` has no `Skills` element, so it has no skill `{}` (nor any other); its InternalElement `{n}` is not read: did you mean `Skills`?",
                                resource.name.text, skill_name.text,
                            ),
                        )
                        .at(at.clone())
                        .element(resource.element.clone())
                        .related(skill_name.span.clone(), format!("the first step that uses it, {}", label())),
                    );
                }
                continue;
            }
            diags.push(
                Diagnostic::error(
                    Code::UnknownSkill,
                    format!(
                        "resource `{}` has no skill `{}`; it offers {}{}",
                        resource.name.text,
                        skill_name.text,
                        known(resource.skills.iter().map(|s| s.name.text.as_ref())),
                        crate::names::did_you_mean(
                            &skill_name.text,
                            resource.skills.iter().map(|s| s.name.text.as_ref())
                        )
                    ),
                )
                .at(skill_name.span.clone())
                .element(label()),
            );
            continue;
        };
        // The program is the controller's (docs/CELLS.md): a robot and the devices on it; the
        // first controller's program is the one written back (a cell of several controllers
        // gets one program per controller, `plan::cell`).
        if r.resource.is_none() {
            r.resource = Some(bb.controller_of(res));
        }
        if let Some(rn) = &st.resource {
            recent[next_recent] = Some((&rn.key, &skill_name.key, (res, sk)));
            next_recent = (next_recent + 1) % recent.len();
        }
        if used.insert((res, sk)) {
            r.used.push((res, sk));
            let skill = &resource.skills[sk];
            for d in &skill.defects {
                diags.push(d.clone().note(format!(
                    "skill `{}` is used by step {}",
                    skill.name.text,
                    label()
                )));
            }
        }
        step_skill[i] = Some((res, sk));
    }
    r.step_skill = step_skill.into();
    r
}

fn known<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let v: Vec<String> = names.take(12).map(|n| format!("`{n}`")).collect();
    if v.is_empty() {
        "none".to_owned()
    } else {
        v.join(", ")
    }
}

/// The `(resource, function)` pairs the used skills call, each once, in first-use order.
/// Mappings naming an unknown function are reported here (`E501`).
pub fn needed_functions(
    bb: &Blackboard,
    r: &Resolution,
    diags: &mut Diagnostics,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut seen = HashSet::new();
    for &(res, sk) in &r.used {
        let resource = &bb.resources[res];
        for m in &resource.skills[sk].mappings {
            match resource.function(&m.function.key) {
                Some(f) => {
                    if seen.insert((res, f)) {
                        out.push((res, f));
                    }
                }
                // Present but malformed: reported by the reader.
                None if resource.broken_functions.contains(&m.function.key) => {}
                None => diags.push(
                    Diagnostic::error(
                        Code::UnknownFunction,
                        format!(
                            "skill `{}` maps function `{}`, which resource `{}` does not have; it has {}{}",
                            resource.skills[sk].name.text,
                            m.function.text,
                            resource.name.text,
                            known(resource.functions.iter().map(|f| f.name.text.as_ref())),
                            crate::names::did_you_mean(
                                &m.function.text,
                                resource.functions.iter().map(|f| f.name.text.as_ref())
                            )
                        ),
                    )
                    .at(m.function.span.clone())
                    .element(m.element.clone()),
                ),
            }
        }
    }
    out
}

/// The bound program: each code-producing step's rendered calls, and the definitions to append.
#[derive(Debug, Default)]
pub struct Bound {
    /// The code lines of each step's calls (a call may span several lines), by element index.
    pub steps: BoundSteps,
    /// `(irl, definition)` indexes into the IRL list, in order of first use.
    pub definitions: Vec<(usize, usize)>,
    /// The program's resource, whose signals the conditions read.
    pub resource: Option<usize>,
    /// The signals the conditions use (indexes into the resource's), in first-use order.
    pub signals: Vec<usize>,
    /// The steps whose time a condition reads (`S.t`, docs/INPUTS.md), in first-use order, each
    /// with its KRL timer number (`$TIMER[n]`); the k-th is RAPID's `skp_clock<k+1>` and
    /// URScript's `skp_time<k+1>`.
    pub timers: Vec<(usize, u32)>,
    /// The step time names the conditions use (keys: `wait.t`) and their step.
    pub timer_names: HashMap<String, usize>,
    /// Step → its position in [`Bound::timers`] (built by [`Bound::set_timers`]).
    pub timer_index: HashMap<usize, usize>,
    /// A program of a cell: how its waits on partners show on the pendant when they last
    /// (`None`: not in a cell, or `HandshakeTimeout` 0).
    pub watch: Option<Watch>,
}

impl Bound {
    /// The resources the program uses, each once: its own (whose signals the conditions read),
    /// then those whose skills its steps run, in step order.
    pub fn resources(&self) -> Vec<usize> {
        let mut out: Vec<usize> = self.resource.into_iter().collect();
        for st in self.steps.iter() {
            if !out.contains(&st.resource) {
                out.push(st.resource);
            }
        }
        out
    }

    /// The timer of step `i` when a condition reads its time: its position `k` in
    /// [`Bound::timers`] and its KRL number.
    pub fn timer_of(&self, i: usize) -> Option<(usize, u32)> {
        let &k = self.timer_index.get(&i)?;
        Some((k, self.timers[k].1))
    }

    /// Sets [`Bound::timers`] and [`Bound::timer_names`] from what the conditions read, and
    /// indexes the timers by step.
    pub fn set_timers(&mut self, timers: Vec<(usize, u32)>, names: HashMap<String, usize>) {
        self.timer_index = timers
            .iter()
            .enumerate()
            .map(|(k, &(s, _))| (s, k))
            .collect();
        self.timers = timers;
        self.timer_names = names;
    }

    /// The timer a condition's name `S.t` reads.
    pub fn timer_named(&self, name: &str) -> Option<(usize, u32)> {
        if self.timer_names.is_empty() {
            return None;
        }
        self.timer_of(*self.timer_names.get(&crate::names::key(name))?)
    }
}

#[derive(Debug)]
pub struct BoundStep {
    pub resource: usize,
    pub skill: usize,
    /// The rendered calls, one after another, lines separated by `\n`.
    pub code: String,
}

/// A program's bound steps, found by their element index: a table of 4 bytes per element of the
/// chart (a program of a cell has one too), the steps themselves only for the program's own.
#[derive(Debug, Default)]
pub struct BoundSteps {
    /// By element index: where the element's step is in `steps` ([`NO_STEP`]: none).
    at: Vec<u32>,
    steps: Vec<BoundStep>,
}

/// In [`BoundSteps`]' table: no step of this program. (The input's size limit keeps the steps
/// of a chart far below it: 4 GiB of XML hold fewer than 100 million.)
const NO_STEP: u32 = u32::MAX;

impl BoundSteps {
    /// No steps yet, in a chart of `elements` elements; room for `count`.
    fn new(elements: usize, count: usize) -> Self {
        BoundSteps {
            at: vec![NO_STEP; elements],
            steps: Vec::with_capacity(count),
        }
    }

    /// The step of element `i` (again: the later one is kept).
    fn put(&mut self, i: usize, step: BoundStep) {
        match self.at[i] {
            NO_STEP => {
                self.at[i] = u32::try_from(self.steps.len()).unwrap_or(NO_STEP);
                self.steps.push(step);
            }
            k => self.steps[k as usize] = step,
        }
    }

    /// The step of element `i`, if it is one of the program's.
    pub fn get(&self, i: usize) -> Option<&BoundStep> {
        self.steps.get(*self.at.get(i)? as usize)
    }

    /// How many steps the program has.
    pub fn len(&self) -> usize {
        self.steps.len()
    }

    pub fn is_empty(&self) -> bool {
        self.steps.is_empty()
    }

    /// The steps in the chart's element order.
    pub fn iter(&self) -> impl Iterator<Item = &BoundStep> {
        self.at.iter().filter_map(|&k| self.steps.get(k as usize))
    }

    /// The steps in the order they were bound (for a sum or a search, where the order does not
    /// matter: no walk over the whole chart's table).
    pub fn unordered(&self) -> impl Iterator<Item = &BoundStep> {
        self.steps.iter()
    }

    /// The table by element index, to cut into pieces ([`BoundSteps::of_table`] reads one).
    pub fn table(&self) -> &[u32] {
        &self.at
    }

    /// The steps of `piece`, a part of [`BoundSteps::table`] that begins at element `from`, with
    /// their element indexes, in element order.
    pub fn of_table<'s>(
        &'s self,
        from: usize,
        piece: &'s [u32],
    ) -> impl Iterator<Item = (usize, &'s BoundStep)> {
        piece
            .iter()
            .enumerate()
            .filter_map(move |(k, &at)| Some((from + k, self.steps.get(at as usize)?)))
    }
}

/// A function mapping made ready to render: the IRL call, and for each template parameter the
/// skill parameter that fills it.
struct Prepared {
    calls: Vec<PreparedCall>,
    /// Keys of the SFC variables the skill's parameters read.
    variables: HashSet<Arc<str>>,
}

struct PreparedCall {
    irl: usize,
    call: usize,
    /// Skill parameter index per template parameter.
    args: Vec<usize>,
    /// The IRL file's definition of the call's routine, if it has one (written with the
    /// program when a step calls it).
    definition: Option<usize>,
}

/// The prepared skills by resource and skill index: looked up at every step without a hash.
/// `None` where a skill is not used; `Some(None)` where it cannot be rendered (reported).
struct PreparedSkills(Vec<Vec<Option<Option<Prepared>>>>);

impl PreparedSkills {
    fn get(&self, res: usize, sk: usize) -> Option<&Option<Prepared>> {
        self.0.get(res)?.get(sk)?.as_ref()
    }
}

/// Each IRL file's function-calls (all overloads, in order) and definitions (the first) by key.
struct CallIndex<'a> {
    calls: Vec<HashMap<&'a str, Vec<usize>>>,
    definitions: Vec<HashMap<&'a str, usize>>,
}

impl<'a> CallIndex<'a> {
    fn new(irls: &'a [Irl]) -> Self {
        let mut calls = Vec::with_capacity(irls.len());
        let mut definitions = Vec::with_capacity(irls.len());
        for irl in irls {
            let mut c: HashMap<&str, Vec<usize>> = HashMap::new();
            for (i, call) in irl.calls.iter().enumerate() {
                c.entry(&call.name.key).or_default().push(i);
            }
            let mut d: HashMap<&str, usize> = HashMap::new();
            for (i, def) in irl.definitions.iter().enumerate() {
                d.entry(&def.name.key).or_insert(i);
            }
            calls.push(c);
            definitions.push(d);
        }
        CallIndex { calls, definitions }
    }
}

/// The loaded IRL files and which one each `(resource, function)` uses (absent when it could
/// not be loaded; that was reported).
pub struct Calls<'a> {
    pub irls: &'a [Irl],
    pub fn_irl: &'a HashMap<(usize, usize), usize>,
}

/// A value as the language writes it, and as a number (for conversions) when it is one.
/// The number is the literal, read as one ([`crate::value::Literal::as_f64`]) only by a
/// conversion that needs it.
type Valued<'a> = (Cow<'a, str>, Option<crate::value::Literal<'a>>);

/// Steps from which [`bind`] renders them on two threads.
pub const PARALLEL_FROM: usize = 2_000;

/// The pieces [`bind`] cuts the steps into from [`PARALLEL_FROM`] on: at 100,000 steps a piece
/// is about 2 ms of work, the longest either thread can wait for the other at the end.
const PIECES: usize = 32;

/// Renders every step. `fn_irl` maps `(resource, function)` to the loaded IRL file (absent when
/// it could not be loaded; that was reported). From `split_from` steps ([`PARALLEL_FROM`] as the
/// compile calls it) the steps are cut into 32 pieces (`PIECES`), rendered on this thread and
/// another, each taking the next piece when done with one (a core that runs slower takes fewer).
/// The result is the same either way (the tests compare them): each piece keeps its
/// diagnostics, unused variables and definitions in step order, and each piece's are put after
/// those of the pieces before it.
#[allow(clippy::too_many_arguments)]
pub fn bind(
    bb: &Blackboard,
    sfc: &Sfc,
    order: &StepOrder,
    r: &Resolution,
    calls_in: &Calls,
    profile: &dyn Rules,
    diags: &mut Diagnostics,
    split_from: usize,
) -> Bound {
    let (irls, fn_irl) = (calls_in.irls, calls_in.fn_irl);
    let mut prepared = PreparedSkills((0..bb.resources.len()).map(|_| Vec::new()).collect());
    let calls = CallIndex::new(irls);
    for &(res, sk) in &r.used {
        let p = prepare(bb, res, sk, irls, &calls, fn_irl, diags);
        let of_resource = &mut prepared.0[res];
        if of_resource.len() <= sk {
            of_resource.resize_with(bb.resources[res].skills.len().max(sk + 1), || None);
        }
        of_resource[sk] = Some(p);
    }
    let cx = StepCx {
        bb,
        sfc,
        r,
        prepared: &prepared,
        irls,
        profile,
    };
    let steps = &order.steps[..];
    // The steps in pieces, rendered by this thread and another, each taking the next piece
    // when done with one; the pieces' results put together in step order.
    let mut later: Vec<Vec<(usize, BoundStep)>> = Vec::new();
    let mut first = if steps.len() >= split_from.max(2) {
        let like = diags.empty_like();
        let mut pieces = crate::threads::pieces("skillpost-bind", steps, PIECES, |_, some| {
            let mut d = like.empty_like();
            (cx.run(some, &mut d), d)
        })
        .into_iter();
        let (mut first, d) = pieces.next().expect("a piece of one step or more");
        diags.append(d);
        for (part, d) in pieces {
            diags.append(d);
            later.push(first.append(part));
        }
        first
    } else {
        cx.run(steps, diags)
    };
    let count = first.steps.len() + later.iter().map(Vec::len).sum::<usize>();
    let mut bound = Bound {
        steps: BoundSteps::new(sfc.elements.len(), count),
        definitions: first.definitions.into_iter().map(|(d, _)| d).collect(),
        resource: r.resource,
        signals: Vec::new(),
        timers: Vec::new(),
        timer_names: HashMap::new(),
        timer_index: HashMap::new(),
        watch: None,
    };
    for (i, step) in std::mem::take(&mut first.steps)
        .into_iter()
        .chain(later.into_iter().flatten())
    {
        bound.steps.put(i, step);
    }
    first.extras.report(diags);
    bound
}

/// Prepares a skill's calls: functions, IRL commands, overloads and parameter fit. Reports
/// problems once per skill; `None` when the skill cannot be rendered.
fn prepare(
    bb: &Blackboard,
    res: usize,
    sk: usize,
    irls: &[Irl],
    index: &CallIndex,
    fn_irl: &HashMap<(usize, usize), usize>,
    diags: &mut Diagnostics,
) -> Option<Prepared> {
    let resource = &bb.resources[res];
    let skill = &resource.skills[sk];
    if !skill.defects.is_empty() {
        return None; // reported by resolve
    }
    let mut ok = true;
    let mut calls = Vec::new();
    for m in &skill.mappings {
        let Some(fi) = resource.function(&m.function.key) else {
            ok = false; // reported by needed_functions
            continue;
        };
        let f = &resource.functions[fi];
        let Some(&irl_i) = fn_irl.get(&(res, fi)) else {
            ok = false; // the IRL file could not be read or parsed: reported
            continue;
        };
        let irl = &irls[irl_i];
        let irl_span = Span::new(irl.file, 0..0);
        let candidates: Vec<usize> = index.calls[irl_i]
            .get(&*f.command.key)
            .cloned()
            .unwrap_or_default();
        if candidates.is_empty() {
            diags.push(
                Diagnostic::error(
                    Code::UnknownCommand,
                    format!(
                        "function `{}`: its IRL file has no function-call `{}`{}",
                        f.name.text,
                        f.command.text,
                        crate::names::did_you_mean(
                            &f.command.text,
                            irl.calls.iter().map(|c| c.name.text.as_ref())
                        )
                    ),
                )
                .at(f.command.span.clone())
                .element(f.element.clone())
                .related(irl_span, "the IRL file"),
            );
            ok = false;
            continue;
        }
        let mut wanted: Vec<&str> = m
            .args
            .iter()
            .map(|a| a.function_param.key.as_ref())
            .collect();
        wanted.sort_unstable();
        wanted.dedup();
        let fits = |c: usize| {
            let mut have: Vec<&str> = irl.calls[c].params.iter().map(|p| p.key.as_ref()).collect();
            have.sort_unstable();
            have == wanted
        };
        let chosen = candidates
            .iter()
            .copied()
            .find(|&c| fits(c))
            .or(if candidates.len() == 1 {
                Some(candidates[0])
            } else {
                None
            });
        let Some(ci) = chosen else {
            let shapes: Vec<String> = candidates
                .iter()
                .map(|&c| {
                    let ps: Vec<&str> = irl.calls[c]
                        .params
                        .iter()
                        .map(|p| p.text.as_ref())
                        .collect();
                    format!("({})", ps.join(", "))
                })
                .collect();
            let mut d = Diagnostic::error(
                Code::ParameterMismatch,
                format!(
                    "no overload of `{}` takes the mapped parameters ({}); the IRL file has {}",
                    f.command.text,
                    m.args
                        .iter()
                        .map(|a| a.function_param.text.as_ref())
                        .collect::<Vec<_>>()
                        .join(", "),
                    shapes.join(", ")
                ),
            )
            .at(m.span.clone())
            .element(m.element.clone());
            for &c in &candidates {
                d = d.related(irl.calls[c].span.clone(), "an overload");
            }
            diags.push(d);
            ok = false;
            continue;
        };
        let call = &irl.calls[ci];
        let mut args = vec![usize::MAX; call.params.len()];
        for a in &m.args {
            let Some(pi) = skill.param(&a.skill_param.key) else {
                ok = false; // reported by the reader
                continue;
            };
            match call
                .params
                .iter()
                .position(|p| p.key == a.function_param.key)
            {
                Some(ti) => args[ti] = pi,
                None => {
                    diags.push(
                        Diagnostic::error(
                            Code::ParameterMismatch,
                            format!(
                                "mapping fills parameter `{}` of `{}`, which its IRL template does not have (it has {})",
                                a.function_param.text,
                                call.name.text,
                                known(call.params.iter().map(|p| p.text.as_ref()))
                            ),
                        )
                        .at(a.function_param.span.clone())
                        .element(m.element.clone())
                        .related(call.span.clone(), "the IRL template"),
                    );
                    ok = false;
                }
            }
            let p = &skill.params[pi];
            if !p.leaf {
                diags.push(
                    Diagnostic::error(
                        Code::BadIndex,
                        format!(
                            "mapping fills `{}` with skill parameter `{}`, which is a list (it has nested parameters); map its items",
                            a.function_param.text, p.path.text
                        ),
                    )
                    .at(a.skill_param.span.clone())
                    .element(m.element.clone()),
                );
                ok = false;
            }
        }
        for (ti, &pi) in args.iter().enumerate() {
            if pi == usize::MAX {
                diags.push(
                    Diagnostic::error(
                        Code::ParameterMismatch,
                        format!(
                            "parameter `{}` of IRL template `{}` is not filled by the mapping of skill `{}`",
                            call.params[ti].text, call.name.text, skill.name.text
                        ),
                    )
                    .at(m.span.clone())
                    .element(m.element.clone())
                    .related(call.params[ti].span.clone(), "the template parameter"),
                );
                ok = false;
            }
        }
        calls.push(PreparedCall {
            irl: irl_i,
            call: ci,
            args,
            definition: index.definitions[irl_i].get(&*call.name.key).copied(),
        });
    }
    let variables = skill
        .params
        .iter()
        .filter_map(|p| p.variable.as_ref().map(|n| n.key.clone()))
        .collect();
    ok.then_some(Prepared { calls, variables })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::emit::{Language, LanguageProfile as _};
    use crate::model::ValueType;

    /// A value for a parameter of type `ty`, as KRL writes it.
    fn typed(s: &str, ty: Option<ValueType>) -> Result<Cow<'_, str>, String> {
        typed_in(Language::Krl, s, ty)
    }

    fn typed_in(l: Language, s: &str, ty: Option<ValueType>) -> Result<Cow<'_, str>, String> {
        crate::value::literal(s, ty).and_then(|v| l.profile().literal(&v))
    }

    #[test]
    fn required_words_and_booleans_compare_as_written_and_suggest_the_near_one() {
        use crate::value::Literal;
        let k = [crate::model::Constraint {
            name: "modes".into(),
            span: Span::new(0, 0..0),
            min: None,
            max: None,
            one_of: vec!["fast".into(), "slow".into(), "TRUE".into()],
        }];
        assert!(outside_constraints(&k, &Literal::Word("fast")).is_none());
        assert!(outside_constraints(&k, &Literal::Bool(true)).is_none());
        let (_, why) = outside_constraints(&k, &Literal::Word("fasst")).unwrap();
        assert_eq!(why, "allows only fast, slow, TRUE; did you mean `fast`?");
        assert!(outside_constraints(&k, &Literal::Str("Fast")).is_some());
    }

    #[test]
    fn typed_values() {
        use ValueType::*;
        assert_eq!(typed("1.5e3", Some(Double)).unwrap(), "1.5E3");
        assert_eq!(typed("-.5", Some(Double)).unwrap(), "-0.5");
        assert_eq!(typed("+5.", Some(Double)).unwrap(), "5.0");
        assert_eq!(typed("2E+3", Some(Double)).unwrap(), "2E3");
        assert_eq!(typed("-12.50", Some(Decimal)).unwrap(), "-12.50");
        assert!(matches!(
            typed("12.5", Some(Double)).unwrap(),
            Cow::Borrowed(_)
        ));
        assert_eq!(typed("+.5", None).unwrap(), "0.5");
        assert!(typed("1.5e", Some(Double)).is_err());
        assert!(typed("1e3", Some(Decimal)).is_err());
        assert_eq!(typed("+12", Some(Integer)).unwrap(), "12");
        assert!(typed("1.0", Some(Integer)).is_err());
        assert_eq!(typed("True", Some(Boolean)).unwrap(), "TRUE");
        assert_eq!(typed("0", Some(Boolean)).unwrap(), "FALSE");
        assert!(typed("yes", Some(Boolean)).is_err());
        assert_eq!(typed("abc def", Some(String)).unwrap(), "\"abc def\"");
        assert!(typed("a\"b", Some(String)).is_err());
        assert!(typed("a\nb", Some(String)).is_err());
    }

    #[test]
    fn untyped_values_must_be_one_token() {
        for ok in [
            "12",
            "-1.5",
            "NAME_1",
            "TRUE",
            "#BASE",
            "$POS_ACT",
            "\"text ok\"",
        ] {
            assert!(typed(ok, None).is_ok(), "{ok}");
        }
        for bad in [
            "1; PTP HOME",
            "a b",
            "x\nEND",
            "\"a\"b\"",
            "}",
            "",
            "1)",
            "\"unterminated",
            "Grüße",
            "EXIT",
            "ENDLOOP",
        ] {
            assert!(typed(bad, None).is_err(), "{bad}");
        }
    }

    #[test]
    fn each_language_refuses_what_would_become_its_code() {
        use Language::*;
        // Words that are statements or block ends of the language.
        for (l, bad) in [
            (Rapid, "ENDPROC"),
            (Rapid, "RETURN"),
            (Rapid, "$POS_ACT"),
            (Rapid, "#BASE"),
            (Rapid, "_x"),
            (UrScript, "end"),
            (UrScript, "halt"),
            (UrScript, "$x"),
        ] {
            assert!(typed_in(l, bad, None).is_err(), "{l} {bad}");
        }
        assert!(typed_in(Rapid, "a\\b", Some(ValueType::String)).is_err());
        assert!(typed_in(UrScript, "a\\b", Some(ValueType::String)).is_err());
        assert!(typed_in(Rapid, &"x".repeat(81), Some(ValueType::String)).is_err());
        assert_eq!(typed_in(UrScript, "true", None).unwrap(), "True");
        assert_eq!(
            typed_in(UrScript, "0", Some(ValueType::Boolean)).unwrap(),
            "False"
        );
        assert_eq!(
            typed_in(Rapid, "1", Some(ValueType::Boolean)).unwrap(),
            "TRUE"
        );
        assert_eq!(typed_in(UrScript, "\"x y\"", None).unwrap(), "\"x y\"");
        assert_eq!(typed_in(UrScript, "1e3", None).unwrap(), "1000");
        assert_eq!(typed_in(Rapid, "tool0", None).unwrap(), "tool0");
        // KRL words RAPID and URScript take as names.
        assert_eq!(typed_in(UrScript, "LOOP", None).unwrap(), "LOOP");
    }
}
