//! What the transition conditions read (docs/INPUTS.md): the signals of the program's resource and
//! the steps' times, with the KRL timers those use, type-checked.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;

use crate::diag::{Code, Diagnostic, Diagnostics, Span};
use crate::model::{Blackboard, ElementKind, Sfc};

use super::{Rules, known};

/// The KRL timers step times use when the resource has no `Timers` attribute: the upper half
/// of the 16 every KUKA controller has.
pub const DEFAULT_TIMERS: (u32, u32) = (9, 16);

/// The highest KRL timer number (KSS 8: `$TIMER[1]` … `$TIMER[64]`).
pub const MAX_TIMER: u32 = 64;

/// The steps of a chart by name (key), for step times: the first step of each name and how many
/// steps have it.
pub struct StepNames(HashMap<String, (usize, usize)>);

impl StepNames {
    pub fn new(sfc: &Sfc) -> Self {
        let mut m: HashMap<String, (usize, usize)> = HashMap::new();
        for (i, e) in sfc.elements.iter().enumerate() {
            if let ElementKind::Step(st) = &e.kind {
                m.entry(crate::names::key(&st.name))
                    .and_modify(|v| v.1 += 1)
                    .or_insert((i, 1));
            }
        }
        StepNames(m)
    }

    /// The step whose time `name` reads (`S.t` or `S.T`, IEC 61131-3's step time) and how many
    /// steps have that name; `None` when `name` is not a step's time.
    pub fn step_time(&self, name: &str) -> Option<(usize, usize)> {
        let (step, t) = name.rsplit_once('.')?;
        if !t.eq_ignore_ascii_case("t") {
            return None;
        }
        self.0.get(&crate::names::key(step)).copied()
    }
}

/// The steps a transition leaves: the steps before it, through selection divergences and
/// simultaneous convergences.
fn steps_before(sfc: &Sfc, by_id: &HashMap<u64, usize>, t: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let mut seen = HashSet::new();
    let mut stack: Vec<usize> = sfc.elements[t]
        .inputs
        .iter()
        .filter_map(|(id, _)| by_id.get(id).copied())
        .collect();
    while let Some(i) = stack.pop() {
        if !seen.insert(i) {
            continue;
        }
        let e = &sfc.elements[i];
        match e.kind {
            ElementKind::Step(_) | ElementKind::MacroStep => out.push(i),
            ElementKind::SelectionDivergence | ElementKind::SimultaneousConvergence => {
                stack.extend(e.inputs.iter().filter_map(|(id, _)| by_id.get(id).copied()))
            }
            _ => {}
        }
    }
    out
}

/// The step times of a chart's conditions, checked (docs/INPUTS.md): the steps by name and the
/// elements by `localId`, built at the first dotted name (most charts read no step time).
#[derive(Default)]
struct StepTimes {
    steps: Option<StepNames>,
    by_id: Option<HashMap<u64, usize>>,
}

impl StepTimes {
    /// The steps of the chart by name, once a condition has a dotted name (`None` before).
    fn names(&mut self, sfc: &Sfc, c: &crate::model::Condition) -> Option<&StepNames> {
        if self.steps.is_none() && c.expr.names().iter().any(|(n, _)| n.contains('.')) {
            self.steps = Some(StepNames::new(sfc));
        }
        self.steps.as_ref()
    }

    /// The step times transition `t` (condition `c`) reads, each `(name, step)`; a problem with
    /// one (`step_time_problem`) is an error at it, and the name is left out.
    fn read_by<'c>(
        &mut self,
        sfc: &Sfc,
        t: usize,
        c: &'c crate::model::Condition,
        here: Option<&[usize]>,
        diags: &mut Diagnostics,
    ) -> Vec<(&'c str, usize)> {
        let mut out = Vec::new();
        if self.names(sfc, c).is_none() {
            return out;
        }
        for (n, at) in c.expr.names() {
            let Some((step, count)) = self.steps.as_ref().and_then(|s| s.step_time(n)) else {
                continue;
            };
            let by_id = self.by_id.get_or_insert_with(|| {
                sfc.elements
                    .iter()
                    .enumerate()
                    .map(|(i, e)| (e.local_id, i))
                    .collect()
            });
            let elsewhere = here.is_some_and(|h| h.binary_search(&step).is_err());
            match step_time_problem(sfc, by_id, t, n, step, count, elsewhere) {
                Some(why) => diags.push(
                    Diagnostic::error(Code::BadCondition, format!("condition `{}`: {why}", c.text))
                        .at(Span::new(sfc.file, at))
                        .element(format!("localId {}", sfc.elements[t].local_id)),
                ),
                None => out.push((n, step)),
            }
        }
        out
    }
}

/// Why transition `t` cannot read `name`, the time of `step` (`count` steps have its name), if
/// it cannot: the name is not unique, the step runs on another controller of a cell than the
/// one that waits for or decides the transition (`elsewhere`), or the transition does not
/// follow the step.
fn step_time_problem(
    sfc: &Sfc,
    by_id: &HashMap<u64, usize>,
    t: usize,
    name: &str,
    step: usize,
    count: usize,
    elsewhere: bool,
) -> Option<String> {
    let step_name = &name[..name.len() - 2];
    if count > 1 {
        Some(format!(
            "`{name}` reads a step's time, but {count} steps are named `{step_name}`: give the step a name of its own"
        ))
    } else if elsewhere {
        Some(format!(
            "`{name}` reads the time of step `{step_name}` (localId {}), which runs on another controller than the one that waits for this transition (the controller of the step after it); step times are not shared between controllers: run the step after on the step's controller, or wait for a signal instead",
            sfc.elements[step].local_id
        ))
    } else if !steps_before(sfc, by_id, t).contains(&step) {
        Some(format!(
            "`{name}` reads the time of step `{step_name}` (localId {}), but this transition does not follow that step: the program knows a step's time while the step is active, so read it in a transition after the step",
            sfc.elements[step].local_id
        ))
    } else {
        None
    }
}

/// The KRL timers `(first, last)` of a resource's `Timers` attribute (`A-B` or `N`).
fn timer_range(attr: &str) -> Result<(u32, u32), String> {
    let t = attr.trim();
    let (a, b) = match t.split_once('-') {
        Some((a, b)) => (a.trim(), b.trim()),
        None => (t, t),
    };
    match (a.parse::<u32>(), b.parse::<u32>()) {
        (Ok(a), Ok(b)) if (1..=MAX_TIMER).contains(&a) && (a..=MAX_TIMER).contains(&b) => {
            Ok((a, b))
        }
        _ => Err(format!(
            "`Timers` is `{t}`: it names the KRL timers step times may use, `A-B` or `N`, between 1 and {MAX_TIMER} (`9-16`)"
        )),
    }
}

/// What the conditions read: signals of the program's resource (indexes into its signals) and
/// step times, each in first-use order.
#[derive(Debug, Default)]
pub struct Reads {
    pub signals: Vec<usize>,
    /// See [`Bound::timers`](crate::bind::Bound::timers).
    pub timers: Vec<(usize, u32)>,
    /// See [`Bound::timer_names`](crate::bind::Bound::timer_names).
    pub timer_names: HashMap<String, usize>,
    /// See [`Bound::watch`](crate::bind::Bound::watch).
    pub watch: Option<Watch>,
}

/// `E318` for `name`, which resource `r` (the program's) does not declare: the near name it
/// does declare, or the other resources that declare `name` and, in a cell (`cell`), why this
/// controller decides the condition: it runs the step before it.
fn unknown_signal(
    bb: &Blackboard,
    sfc: &Sfc,
    t: usize,
    r: &crate::model::Resource,
    name: &str,
    cell: bool,
) -> Diagnostic {
    let key = crate::names::key(name);
    let elsewhere: Vec<&str> = bb
        .resources
        .iter()
        .filter(|o| !std::ptr::eq(*o, r) && o.signal(&key).is_some())
        .map(|o| o.name.text.as_ref())
        .collect();
    let declare = format!(
        "an ExternalInterface named `{name}` with RefBaseClassPath ending in `SignalInterface`, directly under the resource or under its `Signals` element, with `Number` (or `Address`)"
    );
    if elsewhere.is_empty() {
        let misnamed = r
            .misnamed
            .iter()
            .find(|m| m.2 == "Signals" || m.2 == "Signale");
        let near = match crate::names::closest(name, r.signals.iter().map(|s| s.name.text.as_ref()))
        {
            Some(n) => format!("; did you mean `{n}`? Or declare it there: {declare}"),
            None => match misnamed {
                Some((n, _, meant)) => {
                    format!("; its InternalElement `{n}` is not read: did you mean `{meant}`?")
                }
                None => format!("; declare it there: {declare}"),
            },
        };
        return Diagnostic::error(
            Code::UnknownSignal,
            format!(
                "condition names `{name}`, which is not a signal of resource `{}` (it has {}){near}",
                r.name.text,
                known(r.signals.iter().map(|s| s.name.text.as_ref()))
            ),
        );
    }
    let on = elsewhere
        .iter()
        .map(|n| format!("`{n}`"))
        .collect::<Vec<_>>()
        .join(", ");
    let by_id: HashMap<u64, usize> = sfc
        .elements
        .iter()
        .enumerate()
        .map(|(i, e)| (e.local_id, i))
        .collect();
    let before: Vec<String> = steps_before(sfc, &by_id, t)
        .into_iter()
        .map(|i| {
            let e = &sfc.elements[i];
            match &e.kind {
                ElementKind::Step(st) => format!("`{}` (localId {})", st.name, e.local_id),
                _ => format!("localId {}", e.local_id),
            }
        })
        .collect();
    let who = if cell && !before.is_empty() {
        format!(
            "but controller `{}` decides it: it runs the step before the condition, {}. Declare `{name}` on `{}` too ({declare}, wired to the same input), or let a step of {on} come right before the condition",
            r.name.text,
            before.join(", "),
            r.name.text
        )
    } else {
        format!(
            "not of resource `{}`, whose program reads this condition: declare it on `{}` too ({declare})",
            r.name.text, r.name.text
        )
    };
    Diagnostic::error(
        Code::UnknownSignal,
        format!("condition names `{name}`, a signal of {on}, {who}"),
    )
}

/// Resolves the names in every transition condition (or, for a program of a cell, those of
/// `only`: the transitions it waits for or decides, and the steps it runs, as element indexes
/// in ascending order; only those are visited) against
/// the signals of the program's resource and the chart's steps (a step's time `S.t`, in a cell
/// only of a step it runs), and checks the types (docs/INPUTS.md).
#[allow(clippy::too_many_arguments)]
pub fn conditions(
    bb: &Blackboard,
    sfc: &Sfc,
    resource: Option<usize>,
    profile: Option<&dyn Rules>,
    only: Option<&[usize]>,
    partners: bool,
    undecided: bool,
    diags: &mut Diagnostics,
) -> Reads {
    use crate::cond::Ty;
    let mut used = Vec::new();
    let mut seen = HashSet::new();
    let mut timed: Vec<usize> = Vec::new();
    let mut timed_set: HashSet<usize> = HashSet::new();
    let mut timer_names = HashMap::new();
    // The first condition that reads a step's time, for a diagnostic about timers.
    let mut first_timed: Option<usize> = None;
    let res = resource.map(|r| &bb.resources[r]);
    let mut times = StepTimes::default();
    let visited: Box<dyn Iterator<Item = usize>> = match only {
        Some(o) => Box::new(o.iter().copied()),
        None => Box::new(0..sfc.elements.len()),
    };
    for ei in visited {
        let e = &sfc.elements[ei];
        let ElementKind::Transition(Some(c)) = &e.kind else {
            continue;
        };
        let step_names = times.names(sfc, c);
        let lookup = |n: &str| {
            if step_names.is_some_and(|s| s.step_time(n).is_some()) {
                return Some(Ty::Time);
            }
            let key = crate::names::key(n);
            let s = match res.and_then(|r| Some(&r.signals[r.signal(&key)?])) {
                Some(s) => s,
                // Which controller decides is not known (the chart's flow has errors): a
                // signal of any resource is no error of its own.
                None if undecided => bb
                    .resources
                    .iter()
                    .find_map(|r| Some(&r.signals[r.signal(&key)?]))?,
                None => return None,
            };
            Some(if s.is_integer() { Ty::Number } else { Ty::Bool })
        };
        for err in crate::cond::check(&c.expr, &lookup) {
            let at = Span::new(sfc.file, err.at.clone());
            let label = format!("localId {}", e.local_id);
            if !err.unknown {
                diags.push(
                    Diagnostic::error(
                        Code::BadCondition,
                        format!("condition `{}`: {}", c.text, err.message),
                    )
                    .at(at)
                    .element(label),
                );
                continue;
            }
            let name = &err.message;
            let d = match res {
                // Present but malformed: reported by the reader.
                Some(r)
                    if r.broken_signals
                        .contains(&Arc::from(crate::names::key(name))) =>
                {
                    continue;
                }
                Some(r) => unknown_signal(bb, sfc, ei, r, name, only.is_some()),
                None => Diagnostic::error(
                    Code::UnknownSignal,
                    format!(
                        "condition names `{name}`, but no step names the program's resource, whose signals conditions read"
                    ),
                ),
            };
            diags.push(d.at(at).element(label));
        }
        let read = times.read_by(sfc, ei, c, only, diags);
        for &(n, step) in &read {
            if timed_set.insert(step) {
                timed.push(step);
            }
            timer_names.insert(crate::names::key(n), step);
            first_timed.get_or_insert(ei);
        }
        let step_names = times.steps.as_ref();
        for (n, _) in c.expr.names() {
            // A step's time (read, or refused above) is no signal.
            if step_names.is_some_and(|s| s.step_time(n).is_some()) {
                continue;
            }
            if let Some(r) = res
                && let Some(si) = r.signal(&crate::names::key(n))
                && seen.insert(si)
            {
                used.push(si);
            }
        }
    }
    let watch = if partners { watch(res, diags) } else { None };
    let timers = number_timers(sfc, res, profile, &timed, first_timed, watch, diags);
    // Whether the program's language can read each signal the conditions use (not asked when
    // the language is not known for sure).
    if let (Some(r), Some(profile)) = (res, profile) {
        for &si in &used {
            let sig = &r.signals[si];
            if let Err(why) = profile.signal(sig) {
                diags.push(
                    Diagnostic::error(
                        Code::BadSignal,
                        format!(
                            "signal `{}`, read by a condition of this {} program: {why}",
                            sig.name.text,
                            profile.language()
                        ),
                    )
                    .at(sig.name.span.clone())
                    .element(sig.element.clone()),
                );
            }
        }
    }
    Reads {
        signals: used,
        timers,
        timer_names,
        watch,
    }
}

/// How long a wait on a partner may last before the pendant shows it, when the resource has no
/// `HandshakeTimeout` attribute: 10 s.
pub const DEFAULT_HANDSHAKE_TIMEOUT_MS: u64 = 10_000;

/// The longest `HandshakeTimeout`, in seconds (a day).
pub const MAX_HANDSHAKE_TIMEOUT_S: f64 = 86_400.0;

/// How a program of a cell shows a wait on a partner that lasts: after `after_ms`
/// milliseconds a message on the pendant says what it waits for, taken away when the wait ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Watch {
    pub after_ms: u64,
    /// The KRL timer that measures the wait (`$TIMER[n]`): the last of the resource's `Timers`
    /// (step times use the others).
    pub timer: u32,
}

/// The watch of the waits on partners of controller `res`'s program, from its
/// `HandshakeTimeout` attribute (seconds; `0`: no message); an attribute that is not such a
/// number is an error at it (and the default is used).
fn watch(res: Option<&crate::model::Resource>, diags: &mut Diagnostics) -> Option<Watch> {
    let (_, last) = timers_of(res, &mut Diagnostics::default());
    let after_ms = resource_attr(
        res,
        res.and_then(|r| r.handshake_timeout_attr.as_ref()),
        handshake_timeout,
        Code::BadHandshakeTimeout,
        DEFAULT_HANDSHAKE_TIMEOUT_MS,
        diags,
    );
    (after_ms > 0).then_some(Watch {
        after_ms,
        timer: last,
    })
}

/// The milliseconds of a `HandshakeTimeout` attribute's value (seconds, `0` to a day).
fn handshake_timeout(attr: &str) -> Result<u64, String> {
    let t = attr.trim();
    let why = || {
        format!(
            "`HandshakeTimeout` is `{t}`: it is how many seconds a wait on another controller may last before the pendant shows what the program waits for, a number from 0 (no message) to {MAX_HANDSHAKE_TIMEOUT_S} with a `.` for decimals (`10`, `2.5`)"
        )
    };
    let v: f64 = t.parse().map_err(|_| why())?;
    if !(0.0..=MAX_HANDSHAKE_TIMEOUT_S).contains(&v) || t.starts_with('+') {
        return Err(why());
    }
    let ms = (v * 1000.0).round() as u64;
    if v > 0.0 && ms == 0 {
        return Err(why());
    }
    Ok(ms)
}

/// The KRL timers `(first, last)` of a resource (its `Timers` attribute or [`DEFAULT_TIMERS`];
/// a bad attribute is an error in `diags` and the default is used).
fn timers_of(res: Option<&crate::model::Resource>, diags: &mut Diagnostics) -> (u32, u32) {
    resource_attr(
        res,
        res.and_then(|r| r.timers_attr.as_ref()),
        timer_range,
        Code::BadTimers,
        DEFAULT_TIMERS,
        diags,
    )
}

/// A resource attribute's value (`attr`: its text and span) read by `parse`: `default` without
/// the attribute, and also when `parse` refuses it, with an error `code` at the attribute.
fn resource_attr<T>(
    res: Option<&crate::model::Resource>,
    attr: Option<&(String, Span)>,
    parse: fn(&str) -> Result<T, String>,
    code: Code,
    default: T,
    diags: &mut Diagnostics,
) -> T {
    let Some((text, span)) = attr else {
        return default;
    };
    match parse(text) {
        Ok(v) => v,
        Err(why) => {
            diags.push(
                Diagnostic::error(code, why)
                    .at(span.clone())
                    .element(res.map(|r| r.element.clone()).unwrap_or_default()),
            );
            default
        }
    }
}

/// Numbers the timers of the steps in `timed` (KRL's `$TIMER[n]`, from the resource's `Timers`
/// attribute or [`DEFAULT_TIMERS`], without the last one when `watch` measures the waits on
/// partners with it); a KRL program needing more timers than the range holds is an error at
/// the attribute (or, without one, at the first condition that reads a step time).
fn number_timers(
    sfc: &Sfc,
    res: Option<&crate::model::Resource>,
    profile: Option<&dyn Rules>,
    timed: &[usize],
    first_timed: Option<usize>,
    watch: Option<Watch>,
    diags: &mut Diagnostics,
) -> Vec<(usize, u32)> {
    if timed.is_empty() {
        return Vec::new();
    }
    let attr = res.and_then(|r| r.timers_attr.as_ref());
    let (first, last) = timers_of(res, diags);
    let room = (last - first + 1) as usize - usize::from(watch.is_some());
    if timed.len() > room && profile.is_some_and(|p| p.language() == crate::lang::Language::Krl) {
        let msg = format!(
            "the conditions read the times of {} steps, and each needs a KRL timer; `Timers` {}holds {room} (`$TIMER[{first}]` to `$TIMER[{}]`{}): set the resource's attribute `Timers` to a larger range (`A-B`, up to {MAX_TIMER})",
            timed.len(),
            if attr.is_some() {
                ""
            } else {
                "(not set, so 9-16) "
            },
            last - u32::from(watch.is_some()),
            if watch.is_some() {
                format!(
                    "; `$TIMER[{last}]` measures the waits on the other controllers of the cell"
                )
            } else {
                String::new()
            },
        );
        let d = Diagnostic::error(Code::BadTimers, msg);
        let d = match (attr, first_timed) {
            (Some((_, span)), _) => d
                .at(span.clone())
                .element(res.map(|r| r.element.clone()).unwrap_or_default()),
            (None, Some(t)) => d
                .at(sfc.elements[t].span.clone())
                .element(format!("localId {}", sfc.elements[t].local_id)),
            (None, None) => d,
        };
        diags.push(d);
    }
    timed
        .iter()
        .enumerate()
        .map(|(k, &st)| (st, first.saturating_add(k as u32).min(MAX_TIMER)))
        .collect()
}

/// Checks the conditions' types as far as they do not depend on names (`--sfc`: no
/// blackboard, no signals): `3 AND TRUE` is an error, `a AND 3` too, `a AND b` is not.
pub fn check_conditions_unresolved(sfc: &Sfc, diags: &mut Diagnostics) {
    let mut times = StepTimes::default();
    for (ei, e) in sfc.elements.iter().enumerate() {
        let ElementKind::Transition(Some(c)) = &e.kind else {
            continue;
        };
        times.read_by(sfc, ei, c, None, diags);
        let step_names = times.steps.as_ref();
        let lookup = |n: &str| {
            step_names
                .and_then(|s| s.step_time(n))
                .map(|_| crate::cond::Ty::Time)
        };
        for err in crate::cond::check(&c.expr, &lookup) {
            if err.unknown {
                continue;
            }
            diags.push(
                Diagnostic::error(
                    Code::BadCondition,
                    format!("condition `{}`: {}", c.text, err.message),
                )
                .at(Span::new(sfc.file, err.at.clone()))
                .element(format!("localId {}", e.local_id)),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timer_ranges() {
        assert_eq!(timer_range("9-16"), Ok((9, 16)));
        assert_eq!(timer_range(" 3 "), Ok((3, 3)));
        assert_eq!(timer_range("1 - 64"), Ok((1, 64)));
        for bad in ["0-4", "5-4", "1-65", "x", "", "-3", "3-"] {
            assert!(timer_range(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn handshake_timeouts() {
        assert_eq!(handshake_timeout("10"), Ok(10_000));
        assert_eq!(handshake_timeout(" 2.5 "), Ok(2_500));
        assert_eq!(handshake_timeout("0"), Ok(0));
        assert_eq!(handshake_timeout("0.001"), Ok(1));
        assert_eq!(handshake_timeout("86400"), Ok(86_400_000));
        for bad in [
            "-1", "x", "", "2,5", "1e9", "NaN", "inf", "0.0001", "86401", "+3",
        ] {
            assert!(handshake_timeout(bad).is_err(), "{bad}");
        }
    }
}
