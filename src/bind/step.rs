//! One step bound: its variables checked and looked up by key, each call's arguments made
//! from them (values converted, constraints checked), and its code rendered from the IRL
//! template; a step's extra variables (`W303`) counted. `bind` runs it for every step, from
//! [`PARALLEL_FROM`] steps piece by piece on two threads.

use super::*;

/// What [`bind`] renders steps with.
pub(super) struct StepCx<'a> {
    pub(super) bb: &'a Blackboard,
    pub(super) sfc: &'a Sfc,
    pub(super) r: &'a Resolution,
    pub(super) prepared: &'a PreparedSkills,
    pub(super) irls: &'a [Irl],
    pub(super) profile: &'a dyn Rules,
}

/// Some steps rendered, in their order: their code, the definitions they used first (with their
/// keys), and their unused variables.
pub(super) struct Part<'a> {
    pub(super) steps: Vec<(usize, BoundStep)>,
    /// `(irl, definition)` and the called name's key, in order of first use.
    pub(super) definitions: Vec<((usize, usize), &'a str)>,
    pub(super) def_keys: HashSet<&'a str>,
    pub(super) extras: Extras,
}

impl<'a> Part<'a> {
    /// `later` (the steps after these) added after these.
    /// Takes `later`'s definitions and extras; its steps are left to the caller (moved into
    /// their places, not copied here first).
    pub(super) fn append(&mut self, later: Part<'a>) -> Vec<(usize, BoundStep)> {
        for (d, key) in later.definitions {
            if self.def_keys.insert(key) {
                self.definitions.push((d, key));
            }
        }
        self.extras.merge(later.extras);
        later.steps
    }
}

impl<'a> StepCx<'a> {
    pub(super) fn run(&self, steps: &[usize], diags: &mut Diagnostics) -> Part<'a> {
        let StepCx {
            bb,
            sfc,
            r,
            prepared,
            irls,
            profile,
        } = *self;
        let mut part = Part {
            // (No doubling: 100,000 steps.)
            steps: Vec::with_capacity(steps.len()),
            definitions: Vec::new(),
            def_keys: HashSet::new(),
            extras: Extras::default(),
        };
        let mut values: Vec<Cow<str>> = Vec::new();
        let mut numbers: Vec<Option<crate::value::Literal>> = Vec::new();
        let mut lists = crate::value::ItemCache::default();
        for &i in steps {
            let Some((res, sk)) = r.step_skill[i] else {
                continue;
            };
            let Some(Some(p)) = prepared.get(res, sk) else {
                continue;
            };
            let e = &sfc.elements[i];
            let ElementKind::Step(st) = &e.kind else {
                continue;
            };
            let skill = &bb.resources[res].skills[sk];
            let vars = StepVars::new(sfc, st, &p.variables);
            let mut ok =
                check_variables(st, &vars, skill, &p.variables, e, &mut part.extras, diags);
            let mut code = String::new();
            for pc in &p.calls {
                let call = &irls[pc.irl].calls[pc.call];
                values.clear();
                numbers.clear();
                for &pi in &pc.args {
                    match value_of(&vars, skill, pi, e.local_id, profile, &mut lists) {
                        Ok((v, n)) => {
                            values.push(v);
                            numbers.push(n);
                        }
                        Err(Some(d)) => {
                            diags.push(*d);
                            ok = false;
                        }
                        Err(None) => ok = false, // missing variable: reported by check_variables
                    }
                }
                if ok {
                    if !code.is_empty() {
                        code.push('\n');
                    }
                    let at = code.len();
                    if let Err(why) = call.template.render_with(
                        &values,
                        &|k| numbers.get(k)?.as_ref()?.as_f64(),
                        &mut code,
                    ) {
                        code.truncate(at);
                        ok = false;
                        diags.push(conversion_error(&why, call, pc, skill, e, &vars));
                        continue;
                    }
                    if let Some(d) = pc.definition
                        && !part.def_keys.contains(&*call.name.key)
                    {
                        part.def_keys.insert(&call.name.key);
                        part.definitions.push(((pc.irl, d), &call.name.key));
                    }
                }
            }
            if ok {
                part.steps.push((
                    i,
                    BoundStep {
                        resource: res,
                        skill: sk,
                        code,
                    },
                ));
            }
        }
        part
    }
}

/// `E505`: a conversion in a template got a value that is not a number (or a result too large
/// to write): names the step, the variable and the template.
pub(super) fn conversion_error(
    why: &crate::template::ConvError,
    call: &crate::read::irl::IrlCall,
    pc: &PreparedCall,
    skill: &crate::model::Skill,
    e: &crate::model::Element,
    vars: &StepVars,
) -> Diagnostic {
    use crate::template::ConvError;
    match *why {
        ConvError::NotANumber { conversion, param } => {
            let p = &skill.params[pc.args[param]];
            let var = p.variable.as_ref().and_then(|v| vars.get(&v.key));
            let (name, value, at) = match var {
                Some(v) => (
                    {
                        let mut n = v.name.text.to_string();
                        for ix in &p.indices {
                            n.push_str(&format!("[{ix}]"));
                        }
                        n
                    },
                    match crate::value::lookup(vars.raw(v), &p.indices) {
                        crate::value::Lookup::Scalar(s) => s.to_owned(),
                        _ => vars.raw(v).to_owned(),
                    },
                    v.value_span(),
                ),
                None => (p.path.text.to_string(), String::new(), e.span.clone()),
            };
            Diagnostic::error(
                Code::BadConversion,
                format!(
                    "`{}` in the template of function-call `{}` needs a number for its argument `{}`, but `{name}` is `{value}`",
                    conversion.name(),
                    call.name.text,
                    call.params.get(param).map_or("?", |n| &n.text),
                ),
            )
            .at(at)
            .element(label(e))
            .related(call.span.clone(), "the template")
        }
        ConvError::OutOfRange { conversion } => Diagnostic::error(
            Code::BadConversion,
            format!(
                "`{}` in the template of function-call `{}` gives a number too large to write (1e15 or more)",
                conversion.name(),
                call.name.text
            ),
        )
        .at(e.span.clone())
        .element(label(e))
        .related(call.span.clone(), "the template"),
    }
}

pub(super) fn label(e: &crate::model::Element) -> String {
    // Without `format!`: one per step with a warning, 100,000 in a large chart.
    let digits = e.local_id.checked_ilog10().map_or(1, |l| l as usize + 1);
    let mut s = String::with_capacity(8 + digits);
    s.push_str("localId ");
    crate::convert::push_u64(&mut s, e.local_id);
    s
}

/// A step's variables by key: a scan for the few of a usual step, a hash map for many (a step
/// may carry any number of variables; one lookup per parameter must not cost their number).
pub(super) struct StepVars<'a> {
    /// The values' texts ([`Sfc::values`]), which [`crate::model::Variable::raw`] indexes.
    pub(super) values: &'a str,
    pub(super) by: ByKey<'a>,
}

pub(super) enum ByKey<'a> {
    Few(&'a [crate::model::Variable]),
    /// The variables the skill reads, by key, and the others in document order.
    Many {
        used: HashMap<&'a str, &'a crate::model::Variable>,
        unused: Vec<&'a crate::model::Variable>,
    },
}

impl<'a> StepVars<'a> {
    /// Up to this many variables are scanned.
    const SCAN: usize = 16;

    /// `read`: the keys of the variables the skill reads.
    pub(super) fn new(sfc: &'a Sfc, st: &Step, read: &HashSet<Arc<str>>) -> Self {
        let vars = sfc.variables_of(st);
        let values = sfc.values.as_str();
        if vars.len() <= Self::SCAN {
            return StepVars {
                values,
                by: ByKey::Few(vars),
            };
        }
        let mut used = HashMap::new();
        let mut unused = Vec::new();
        for v in vars {
            if read.contains(&v.name.key) {
                // The first of equal names wins, as a scan finds it.
                used.entry(&*v.name.key).or_insert(v);
            } else {
                unused.push(v);
            }
        }
        StepVars {
            values,
            by: ByKey::Many { used, unused },
        }
    }

    /// A variable's value as written, trimmed.
    pub(super) fn raw(&self, v: &crate::model::Variable) -> &'a str {
        self.values.get(v.raw.clone()).unwrap_or("")
    }

    /// The variable of this key, if the skill reads that key (or the step has few variables).
    pub(super) fn get(&self, key: &str) -> Option<&'a crate::model::Variable> {
        match &self.by {
            ByKey::Few(vars) => vars.iter().find(|v| &*v.name.key == key),
            ByKey::Many { used, .. } => used.get(key).copied(),
        }
    }
}

/// Reports missing variables (`E314`) and extra ones (`W303`). False when one is missing.
/// `used` holds the keys of the variables the skill's parameters read.
pub(super) fn check_variables(
    st: &Step,
    vars: &StepVars,
    skill: &crate::model::Skill,
    used: &HashSet<Arc<str>>,
    e: &crate::model::Element,
    extras: &mut Extras,
    diags: &mut Diagnostics,
) -> bool {
    let mut ok = true;
    for p in skill.params.iter().filter(|p| p.indices.is_empty()) {
        let Some(var) = &p.variable else { continue };
        if vars.get(&var.key).is_none() {
            ok = false;
            if st.invalid_variables.contains(&var.key) {
                continue; // present but malformed: reported by the reader
            }
            diags.push(
                Diagnostic::error(
                    Code::MissingVariable,
                    format!(
                        "step lacks variable `{}`, which skill `{}` needs for parameter `{}`{}",
                        var.text,
                        skill.name.text,
                        p.path.text,
                        // The step's variables no parameter reads: one of them may be meant.
                        crate::names::did_you_mean(
                            &var.text,
                            match &vars.by {
                                ByKey::Few(list) => list.iter().collect::<Vec<_>>(),
                                ByKey::Many { unused, .. } => unused.clone(),
                            }
                            .into_iter()
                            .map(|v| v.name.text.as_ref())
                        )
                    ),
                )
                .at(e.span.clone())
                .element(label(e)),
            );
        }
    }
    // Without `--warn` the `W303`s are counted, not built.
    let keep = diags.keeps_warnings();
    match &vars.by {
        ByKey::Few(list) => {
            for v in *list {
                // A usual skill has a handful of parameters: a scan beats hashing.
                let read = if skill.params.len() <= StepVars::SCAN {
                    skill
                        .params
                        .iter()
                        .any(|p| p.variable.as_ref().is_some_and(|n| n.key == v.name.key))
                } else {
                    used.contains(&v.name.key)
                };
                if !read {
                    if keep {
                        extras.add(skill, v, e);
                    } else {
                        extras.count(skill, v, 0);
                    }
                }
            }
        }
        ByKey::Many { unused, .. } => {
            for (k, v) in unused.iter().enumerate() {
                if keep {
                    extras.add(skill, v, e);
                } else {
                    extras.count(skill, v, unused.len() - k);
                }
            }
        }
    }
    ok
}

/// Variables no skill parameter reads, one warning per skill and variable (a work plan in the
/// original format repeats them at every step).
#[derive(Default)]
pub(super) struct Extras {
    pub(super) list: Vec<Extra>,
    /// `(skill key, variable key)` → index into `list`.
    pub(super) index: HashMap<(Arc<str>, Arc<str>), usize>,
    /// When the warnings are not kept, only counted: the groups by key, nothing built; the
    /// first [`Extras::SCAN`] in `few` (a usual plan repeats a handful at every step: a scan,
    /// mostly of shared strings, beats hashing), the others in `counted`.
    pub(super) few: Vec<(Arc<str>, Arc<str>)>,
    /// Per skill (a handful: scanned), its other variables' keys.
    pub(super) counted: Vec<(Arc<str>, HashSet<Arc<str>>)>,
}

/// One unused variable of one skill: its first place, and every step's id. The warning is
/// built only when it is kept ([`Extras::report`]).
pub(super) struct Extra {
    pub(super) skill: Arc<str>,
    pub(super) variable: Arc<str>,
    /// The names as written, and the variable's place at its first step.
    pub(super) skill_text: Arc<str>,
    pub(super) variable_text: Arc<str>,
    pub(super) span: crate::diag::Span,
    pub(super) steps: Vec<u64>,
}

impl Extras {
    /// Up to this many groups are scanned; then `index` holds them all.
    const SCAN: usize = 8;

    pub(super) fn find(&mut self, skill: &Arc<str>, variable: &Arc<str>) -> Option<usize> {
        if self.list.len() <= Self::SCAN {
            return self
                .list
                .iter()
                .position(|x| x.skill == *skill && x.variable == *variable);
        }
        if self.index.is_empty() {
            for (i, x) in self.list.iter().enumerate() {
                self.index
                    .entry((x.skill.clone(), x.variable.clone()))
                    .or_insert(i);
            }
        }
        self.index.get(&(skill.clone(), variable.clone())).copied()
    }

    /// The group of `(skill, variable)`: `Some` its place, or `None` when there is none yet; the
    /// group pushed next is then it (an index, once built, already points to that place).
    pub(super) fn group(&mut self, skill: &Arc<str>, variable: &Arc<str>) -> Option<usize> {
        if self.list.len() > Self::SCAN && !self.index.is_empty() {
            // One hash for the look-up and the insertion (a step may bring 100,000 of them).
            use std::collections::hash_map::Entry;
            return match self.index.entry((skill.clone(), variable.clone())) {
                Entry::Occupied(at) => Some(*at.get()),
                Entry::Vacant(slot) => {
                    slot.insert(self.list.len());
                    None
                }
            };
        }
        let found = self.find(skill, variable);
        if found.is_none() && !self.index.is_empty() {
            self.index
                .insert((skill.clone(), variable.clone()), self.list.len());
        }
        found
    }

    pub(super) fn add(
        &mut self,
        skill: &crate::model::Skill,
        v: &crate::model::Variable,
        e: &crate::model::Element,
    ) {
        if let Some(at) = self.group(&skill.name.key, &v.name.key) {
            self.list[at].steps.push(e.local_id);
            return;
        }
        self.list.push(Extra {
            skill: skill.name.key.clone(),
            variable: v.name.key.clone(),
            skill_text: skill.name.text.clone(),
            variable_text: v.name.text.clone(),
            span: v.name.span.clone(),
            steps: vec![e.local_id],
        });
    }

    /// Counts the group of `(skill, v)` when the warnings are not kept; `more`: how many
    /// variables are still to come (room for them at once).
    pub(super) fn count(
        &mut self,
        skill: &crate::model::Skill,
        v: &crate::model::Variable,
        more: usize,
    ) {
        let (sk, var) = (&skill.name.key, &v.name.key);
        let same = |a: &Arc<str>, b: &Arc<str>| Arc::ptr_eq(a, b) || a == b;
        if self.few.iter().any(|(s, x)| same(s, sk) && same(x, var)) {
            return;
        }
        self.count_key(sk, var, more);
    }

    /// [`Extras::count`] past the scan of `few`.
    pub(super) fn count_key(&mut self, sk: &Arc<str>, var: &Arc<str>, more: usize) {
        if self.few.len() < Self::SCAN {
            self.few.push((sk.clone(), var.clone()));
            return;
        }
        let at = match self.counted.iter().position(|(s, _)| s == sk) {
            Some(at) => at,
            None => {
                self.counted.push((sk.clone(), HashSet::new()));
                self.counted.len() - 1
            }
        };
        let set = &mut self.counted[at].1;
        set.reserve(more);
        set.insert(var.clone());
    }

    /// How many groups [`Extras::count`] found.
    pub(super) fn counted(&self) -> usize {
        self.few.len() + self.counted.iter().map(|(_, v)| v.len()).sum::<usize>()
    }

    /// `later` (the groups of the steps after these) added after these.
    pub(super) fn merge(&mut self, later: Extras) {
        let later_counted = later
            .counted
            .into_iter()
            .flat_map(|(sk, vars)| vars.into_iter().map(move |v| (sk.clone(), v)));
        for (sk, var) in later.few.into_iter().chain(later_counted) {
            if !self.few.iter().any(|(s, x)| *s == sk && *x == var) {
                self.count_key(&sk, &var, 0);
            }
        }
        for x in later.list {
            match self.group(&x.skill, &x.variable) {
                Some(at) => self.list[at].steps.extend(x.steps),
                None => self.list.push(x),
            }
        }
    }

    /// One `W303` per group; only counted when warnings are not kept.
    pub(super) fn report(self, diags: &mut Diagnostics) {
        if !diags.keeps_warnings() {
            diags.count_dropped(self.counted());
            return;
        }
        for x in self.list {
            // Without `format!`: 100,000 distinct variables make 100,000 of these.
            let (name, skill_name) = (&*x.variable_text, &*x.skill_text);
            let mut message = String::with_capacity(35 + name.len() + skill_name.len());
            message.push_str("variable `");
            message.push_str(name);
            message.push_str("` is not used by skill `");
            message.push_str(skill_name);
            message.push('`');
            let ids = &x.steps;
            if ids.len() > 1 {
                let shown: Vec<String> = ids.iter().take(5).map(u64::to_string).collect();
                message.push_str(&format!(
                    " (at {} steps: localId {}{})",
                    ids.len(),
                    shown.join(", "),
                    if ids.len() > 5 { ", ..." } else { "" }
                ));
            }
            let mut element = String::with_capacity(28);
            element.push_str("localId ");
            crate::convert::push_u64(&mut element, ids[0]);
            diags.push(
                Diagnostic::warning(Code::ExtraVariable, message)
                    .at(x.span)
                    .element(element),
            );
        }
    }
}

/// The emitted token for skill parameter `pi` at this step. `Err(None)`: the variable is
/// missing (reported elsewhere). Allocates only for an error or a value that changes (a boolean
/// or string literal, a number spelled differently).
pub(super) fn value_of<'a>(
    vars: &StepVars<'a>,
    skill: &crate::model::Skill,
    pi: usize,
    local_id: u64,
    profile: &dyn Rules,
    lists: &mut crate::value::ItemCache<'a>,
) -> Result<Valued<'a>, Option<Box<Diagnostic>>> {
    use crate::value::{Lookup, lookup_in};
    let p = &skill.params[pi];
    let Some(var_name) = &p.variable else {
        return Err(None);
    };
    let Some(var) = vars.get(&var_name.key) else {
        return Err(None);
    };
    let err = |code: Code, msg: String| {
        Some(Box::new(
            Diagnostic::error(code, msg)
                .at(var.value_span())
                .element(format!("localId {local_id}")),
        ))
    };
    // `Frame[1][0]` for messages, up to `depth` indexes.
    let path = |depth: usize| {
        let mut s = var.name.text.to_string();
        for ix in &p.indices[..depth] {
            s.push_str(&format!("[{ix}]"));
        }
        s
    };
    let s = match lookup_in(vars.raw(var), &p.indices, lists) {
        Lookup::Scalar(s) => s,
        Lookup::OutOfRange { depth, len } => {
            return Err(err(
                Code::BadIndex,
                format!(
                    "parameter `{}` reads `{}[{}]`, but `{}` has {len} item{}",
                    p.path.text,
                    path(depth),
                    p.indices[depth],
                    path(depth),
                    if len == 1 { "" } else { "s" }
                ),
            )
            .map(|d| Box::new(d.related(p.path.span.clone(), "the parameter's index"))));
        }
        Lookup::NotAList { depth } => {
            return Err(err(
                Code::BadIndex,
                format!(
                    "parameter `{}` reads `{}[{}]`, but `{}` is one value, not a list",
                    p.path.text,
                    path(depth),
                    p.indices[depth],
                    path(depth)
                ),
            ));
        }
        Lookup::List => {
            return Err(err(
                Code::BadIndex,
                format!(
                    "parameter `{}` needs one value, but `{}` is a list",
                    p.path.text,
                    path(p.indices.len())
                ),
            ));
        }
    };
    let typed = crate::value::literal(s, p.ty);
    let number = match &typed {
        Ok(n @ crate::value::Literal::Number(_)) => Some(n.clone()),
        _ => None,
    };
    let neutral = typed.is_ok();
    if let Ok(l) = &typed
        && let Some((k, why)) = outside_constraints(&p.constraints, l)
    {
        return Err(err(
            Code::OutOfRange,
            format!(
                "`{}` = `{s}` for parameter `{}`: the blackboard's constraint `{}` {why}",
                path(p.indices.len()),
                p.path.text,
                k.name
            ),
        )
        .map(|d| Box::new(d.related(k.span.clone(), "the constraint"))));
    }
    match typed.and_then(|l| profile.literal(&l)) {
        Ok(t) => Ok((t, number)),
        Err(why) => {
            let code = if neutral {
                Code::UnsafeValue
            } else if why.starts_with("non-ASCII") {
                Code::NonAscii
            } else if p.ty.is_some() {
                Code::TypeMismatch
            } else {
                Code::UnsafeValue
            };
            Err(err(
                code,
                format!(
                    "`{}` = `{s}` for parameter `{}`: {why}",
                    path(p.indices.len()),
                    p.path.text
                ),
            ))
        }
    }
}
/// The first constraint `value` is outside of, and how (`below the least value 0`, `not one of
/// A, B (did you mean …)`); `None` when every constraint allows it. Bounds compare numbers
/// (a value that is not one is outside them); required values compare as numbers when both are
/// numbers, else as text (`true`/`false` whatever their case).
pub(super) fn outside_constraints<'k>(
    constraints: &'k [crate::model::Constraint],
    value: &crate::value::Literal,
) -> Option<(&'k crate::model::Constraint, String)> {
    use crate::value::Literal;
    if constraints.is_empty() {
        return None;
    }
    let text: std::borrow::Cow<str> = match value {
        Literal::Number(n) => std::borrow::Cow::Borrowed(n.as_ref()),
        Literal::Bool(b) => std::borrow::Cow::Owned(b.to_string()),
        Literal::Str(t) | Literal::Word(t) => std::borrow::Cow::Borrowed(t),
    };
    let number = match value {
        Literal::Number(n) => n.parse::<f64>().ok(),
        _ => None,
    };
    for k in constraints {
        let range = match (&k.min, &k.max) {
            (Some((_, lo)), Some((_, hi))) => format!(" (from {lo} to {hi})"),
            _ => String::new(),
        };
        if let Some((lo, written)) = &k.min {
            match number {
                Some(x) if x < *lo => {
                    return Some((k, format!("allows no value below {written}{range}")));
                }
                None => {
                    return Some((k, format!("allows numbers only, at least {written}{range}")));
                }
                _ => {}
            }
        }
        if let Some((hi, written)) = &k.max {
            match number {
                Some(x) if x > *hi => {
                    return Some((k, format!("allows no value above {written}{range}")));
                }
                None => return Some((k, format!("allows numbers only, at most {written}{range}"))),
                _ => {}
            }
        }
        if !k.one_of.is_empty() {
            let allowed = k.one_of.iter().any(|a| match (number, a.parse::<f64>()) {
                (Some(x), Ok(y)) => x == y,
                _ => {
                    *a == *text
                        || (matches!(value, Literal::Bool(_)) && a.eq_ignore_ascii_case(&text))
                }
            });
            if !allowed {
                // A number: the nearest allowed number; else the nearest name.
                let nearest = number.and_then(|x| {
                    k.one_of
                        .iter()
                        .filter_map(|a| Some((a, (a.parse::<f64>().ok()? - x).abs())))
                        .min_by(|a, b| a.1.total_cmp(&b.1))
                });
                let near = match nearest {
                    Some((a, _)) => format!("; the nearest is `{a}`"),
                    None => crate::names::did_you_mean(&text, k.one_of.iter().map(String::as_str)),
                };
                return Some((k, format!("allows only {}{near}", k.one_of.join(", "))));
            }
        }
    }
    None
}
