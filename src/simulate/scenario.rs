//! The scenario file (docs/SIMULATE.md): TOML with the inputs at the start, their changes, the
//! restarts of controllers and the timing; names as in the blackboard, matched without regard
//! to case. Every error names the file, line and column and, for a name, the nearest one.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;

use serde::Deserialize;
use toml::Spanned;

use super::ir::Val;
use super::{Cell, Change, Input, Restart, Scenario, When};

/// The largest scenario file read (a FIFO or `/dev/zero` must not hang or fill memory).
pub const MAX_SIZE: u64 = 1 << 20;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    runs: Option<Spanned<i64>>,
    seed: Option<u64>,
    jitter: Option<Spanned<f64>>,
    default_step_s: Option<Spanned<f64>>,
    max_time_s: Option<Spanned<f64>>,
    max_steps: Option<Spanned<i64>>,
    cycles: Option<Spanned<i64>>,
    cycle_pause_s: Option<Spanned<f64>>,
    #[serde(default)]
    timing: BTreeMap<Spanned<String>, RawTiming>,
    #[serde(default)]
    inputs: BTreeMap<Spanned<String>, BTreeMap<Spanned<String>, Spanned<toml::Value>>>,
    #[serde(default)]
    change: Vec<RawChange>,
    #[serde(default)]
    restart: Vec<RawRestart>,
    #[serde(default)]
    swap: Vec<RawSwap>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTiming {
    start_s: Option<Spanned<f64>>,
    motion_factor: Option<Spanned<f64>>,
    statement_s: Option<Spanned<f64>>,
    poll: Option<Spanned<toml::Value>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSwap {
    wires: Spanned<Vec<Spanned<String>>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawChange {
    after: Option<Spanned<String>>,
    after_steps: Option<Spanned<i64>>,
    at: Option<Spanned<f64>>,
    resource: Spanned<String>,
    signal: Spanned<toml::Value>,
    value: Spanned<toml::Value>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRestart {
    controller: Spanned<String>,
    after: Option<Spanned<String>>,
    after_steps: Option<Spanned<i64>>,
    at: Option<Spanned<f64>>,
}

/// A scenario that cannot be used: where and why.
#[derive(Debug, Clone)]
pub struct ScenarioError {
    pub file: String,
    pub line: Option<usize>,
    pub column: Option<usize>,
    pub message: String,
}

impl std::fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.line, self.column) {
            (Some(l), Some(c)) => write!(f, "{}:{l}:{c}: {}", self.file, self.message),
            _ => write!(f, "{}: {}", self.file, self.message),
        }
    }
}

fn line_column(text: &str, at: usize) -> (usize, usize) {
    let before = &text[..at.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before[before.rfind('\n').map_or(0, |i| i + 1)..]
        .chars()
        .count()
        + 1;
    (line, col)
}

/// Reads scenario file `path` (at most [`MAX_SIZE`] bytes, never blocking on a FIFO).
pub fn load(path: &Path, cell: &Cell) -> Result<Scenario, ScenarioError> {
    load_from(path, cell, crate::load::read_limited(path, MAX_SIZE))
}

/// [`load`] of bytes read already (the daemon reads them confined to the project folder and
/// hashes what it read): `read` is the read's result.
pub fn load_from(
    path: &Path,
    cell: &Cell,
    read: std::io::Result<Vec<u8>>,
) -> Result<Scenario, ScenarioError> {
    let file = path.display().to_string();
    let bytes = read.map_err(|e| ScenarioError {
        file: file.clone(),
        line: None,
        column: None,
        message: format!("cannot read the scenario: {e}"),
    })?;
    let text = String::from_utf8(bytes).map_err(|e| ScenarioError {
        file: file.clone(),
        line: None,
        column: None,
        message: format!("the scenario is not UTF-8: {e}"),
    })?;
    parse(&text, &file, cell)
}

/// Parses scenario text as if read from `file`.
pub fn parse(text: &str, file: &str, cell: &Cell) -> Result<Scenario, ScenarioError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let at = |span: Option<Range<usize>>, message: String| {
        let (line, column) = match span {
            Some(s) => {
                let (l, c) = line_column(text, s.start);
                (Some(l), Some(c))
            }
            None => (None, None),
        };
        ScenarioError {
            file: file.to_owned(),
            line,
            column,
            message,
        }
    };
    let raw: Raw = toml::from_str(text).map_err(|e| at(e.span(), e.message().trim().to_owned()))?;
    let mut s = Scenario::with_file();
    if let Some(r) = &raw.runs {
        if !(1..=1_000_000).contains(r.get_ref()) {
            return Err(at(Some(r.span()), "`runs` is 1 to 1,000,000".into()));
        }
        s.runs = *r.get_ref() as usize;
    }
    s.seed = raw.seed;
    let fraction = |v: &Spanned<f64>, key: &str, max: f64| {
        let x = *v.get_ref();
        if x.is_finite() && (0.0..=max).contains(&x) {
            Ok(x)
        } else {
            Err(at(
                Some(v.span()),
                format!("`{key}` is a number from 0 to {max}"),
            ))
        }
    };
    if let Some(j) = &raw.jitter {
        s.jitter = fraction(j, "jitter", 1.0)?;
    }
    if let Some(d) = &raw.default_step_s {
        s.default_step_s = fraction(d, "default_step_s", 86_400.0)?;
    }
    if let Some(d) = &raw.max_time_s {
        s.max_time_s = fraction(d, "max_time_s", 1.0e7)?;
    }
    if let Some(m) = &raw.max_steps {
        if !(1..=100_000_000).contains(m.get_ref()) {
            return Err(at(Some(m.span()), "`max_steps` is 1 to 100,000,000".into()));
        }
        s.max_steps = *m.get_ref() as usize;
    }
    if let Some(n) = &raw.cycles {
        if !(1..=1_000_000).contains(n.get_ref()) {
            return Err(at(Some(n.span()), "`cycles` is 1 to 1,000,000".into()));
        }
        s.cycles = *n.get_ref() as usize;
    }
    if let Some(p) = &raw.cycle_pause_s {
        s.cycle_pause_s = fraction(p, "cycle_pause_s", 86_400.0)?;
    }
    // A name of `names` (a controller's, a wire's), or the error with the nearest one.
    let one_of = |what: &str, names: &[&str], n: &Spanned<String>| {
        names
            .iter()
            .position(|x| crate::names::eq(x, n.get_ref()))
            .ok_or_else(|| {
                at(
                    Some(n.span()),
                    format!(
                        "no {what} `{}` in this cell{}",
                        n.get_ref(),
                        crate::names::did_you_mean(n.get_ref(), names.iter().copied())
                    ),
                )
            })
    };
    let controller_names: Vec<&str> = cell.controllers.iter().map(|x| x.name.as_str()).collect();
    let controller = |n: &Spanned<String>| one_of("controller", &controller_names, n);
    for (name, t) in &raw.timing {
        let c = controller(name)?;
        let mut timing = super::Timing::default();
        if let Some(v) = &t.start_s {
            timing.start_s = Some(fraction(v, "start_s", 86_400.0)?);
        }
        if let Some(v) = &t.motion_factor {
            let f = fraction(v, "motion_factor", 1000.0)?;
            if f == 0.0 {
                return Err(at(
                    Some(v.span()),
                    "`motion_factor` is more than 0 (1: the chart's times)".into(),
                ));
            }
            timing.motion_factor = f;
        }
        if let Some(v) = &t.statement_s {
            timing.statement_s = fraction(v, "statement_s", 10.0)?;
        }
        if let Some(v) = &t.poll {
            let rate = match v.get_ref() {
                toml::Value::String(s) if s == "controller" => Some(super::Poll::Controller),
                toml::Value::Float(p) if p.is_finite() && (0.001..=10.0).contains(p) => {
                    Some(super::Poll::Every(*p))
                }
                toml::Value::Integer(p) if (1..=10).contains(p) => {
                    Some(super::Poll::Every(*p as f64))
                }
                _ => None,
            };
            timing.poll = rate.ok_or_else(|| {
                at(
                    Some(v.span()),
                    "`poll` is seconds from 0.001 to 10 (how often a wait reads its condition), or \"controller\" (each controller's own rate)".into(),
                )
            })?;
        }
        s.timing.insert(c, timing);
    }
    let resource = |name: &Spanned<String>| {
        cell.resource(name.get_ref()).ok_or_else(|| {
            at(
                Some(name.span()),
                format!(
                    "no resource `{}` in the blackboard{}",
                    name.get_ref(),
                    crate::names::did_you_mean(
                        name.get_ref(),
                        cell.resources.iter().map(|r| r.name.as_str())
                    )
                ),
            )
        })
    };
    let signal = |r: usize, sig: &Spanned<toml::Value>| -> Result<Input, ScenarioError> {
        let res = &cell.resources[r];
        // An input the blackboard does not declare, by its number: KRL `$IN[n]`, URScript's
        // standard digital input n.
        if let toml::Value::Integer(k) = sig.get_ref()
            && !res.inputs.iter().any(|i| i.number == Some(*k))
            && let Some(c) = res.controller
            && (1..=4096).contains(k)
        {
            let key = match cell.controllers[c].language {
                crate::lang::Language::Krl => Some(format!("$IN[{k}]")),
                crate::lang::Language::UrScript => Some(format!("get_standard_digital_in({k})")),
                crate::lang::Language::Rapid => None,
            };
            if let Some(key) = key {
                return Ok(Input {
                    name: format!("input {k}"),
                    number: Some(*k),
                    controller: c,
                    key: vec![key],
                    integer: false,
                });
            }
        }
        let found = match sig.get_ref() {
            toml::Value::String(n) => res.inputs.iter().position(|i| crate::names::eq(&i.name, n)),
            toml::Value::Integer(k) => res.inputs.iter().position(|i| i.number == Some(*k)),
            _ => None,
        };
        // The output of the resource's controller it names, and whether that drives a wire. One
        // that drives none is forced, as a technician forces one from the pendant's I/O display
        // (a gripper's feedback the blackboard declares as an output).
        let output = match (sig.get_ref(), res.controller) {
            (toml::Value::String(n), Some(c)) => cell
                .outputs
                .iter()
                .find(|o| o.controller == c && crate::names::eq(&o.name, n))
                .map(|o| {
                    let drives = cell
                        .wires
                        .iter()
                        .any(|w| w.from.0 == c && o.key.first() == Some(&w.from.1));
                    (o, drives)
                }),
            _ => None,
        };
        let drives = output.is_some_and(|(_, d)| d);
        found
            .map(|k| res.inputs[k].clone())
            .or_else(|| output.filter(|(_, d)| !d).map(|(o, _)| o.clone()))
            .ok_or_else(|| {
            let shown = match sig.get_ref() {
                toml::Value::String(n) => format!("`{n}`"),
                v => format!("number {v}"),
            };
            let near = match sig.get_ref() {
                toml::Value::String(n) => crate::names::did_you_mean(
                    n,
                    res.inputs.iter().map(|i| i.name.as_str()),
                ),
                _ => String::new(),
            };
            let wired = match sig.get_ref() {
                toml::Value::String(n) => res.wired.iter().any(|w| crate::names::eq(w, n)),
                _ => false,
            };
            let elsewhere = match sig.get_ref() {
                toml::Value::String(n) => cell
                    .resources
                    .iter()
                    .find(|o| o.inputs.iter().any(|i| crate::names::eq(&i.name, n)))
                    .map(|o| format!("; `{}` has an input of that name", o.name)),
                _ => None,
            };
            at(
                Some(sig.span()),
                if drives {
                    format!(
                        "{shown} of `{}` is an output that drives a wire to another controller: its program sets it, a scenario cannot force it",
                        res.name
                    )
                } else if let (Some(e), false) = (&elsewhere, wired) {
                    format!("`{}` has no input {shown}{e}", res.name)
                } else if wired {
                    format!(
                        "{shown} of `{}` is a wire: another controller's program drives it, a scenario does not",
                        res.name
                    )
                } else {
                    format!("`{}` has no input {shown}{near}", res.name)
                },
            )
        })
    };
    let value = |inp: &Input, v: &Spanned<toml::Value>| match (v.get_ref(), inp.integer) {
        (toml::Value::Boolean(b), false) => Ok(Val::Bool(*b)),
        (toml::Value::Integer(i), true) => Ok(Val::Num(*i as f64)),
        (toml::Value::Integer(i @ (0 | 1)), false) => Ok(Val::Bool(*i == 1)),
        (_, integer) => Err(at(
            Some(v.span()),
            format!(
                "input `{}` takes {}",
                inp.name,
                if integer {
                    "an integer"
                } else {
                    "true or false"
                }
            ),
        )),
    };
    for (res, sigs) in &raw.inputs {
        let r = resource(res)?;
        for (name, v) in sigs {
            // A key of digits is an input's number.
            let raw = match name.get_ref().parse::<i64>() {
                Ok(n) => toml::Value::Integer(n),
                Err(_) => toml::Value::String(name.get_ref().clone()),
            };
            let inp = signal(r, &Spanned::new(name.span(), raw))?;
            s.start
                .push((inp.controller, inp.key.clone(), value(&inp, v)?));
        }
    }
    let when = |after: &Option<Spanned<String>>,
                after_steps: &Option<Spanned<i64>>,
                at_: &Option<Spanned<f64>>,
                span: Range<usize>| match (after, at_) {
        (None, None) if after_steps.is_some() => {
            let n = after_steps.as_ref().unwrap();
            if (1..=100_000_000).contains(n.get_ref()) {
                Ok(When::AfterSteps(*n.get_ref() as usize))
            } else {
                Err(at(
                    Some(n.span()),
                    "`after_steps` is 1 to 100,000,000 (the controller's steps run)".into(),
                ))
            }
        }
        _ if after_steps.is_some() => Err(at(
            Some(span),
            "give one of `after = \"STEP\"`, `after_steps = N` or `at = SECONDS`".into(),
        )),
        (Some(a), None) => {
            let known = cell
                .step_names
                .iter()
                .any(|n| crate::names::eq(n, a.get_ref()))
                || cell.steps.keys().any(|id| id.to_string() == *a.get_ref());
            if known {
                Ok(When::After(a.get_ref().clone()))
            } else {
                Err(at(
                    Some(a.span()),
                    format!(
                        "no step `{}` runs in this cell's programs{}",
                        a.get_ref(),
                        crate::names::did_you_mean(
                            a.get_ref(),
                            cell.step_names.iter().map(String::as_str)
                        )
                    ),
                ))
            }
        }
        (None, Some(t)) if t.get_ref().is_finite() && *t.get_ref() >= 0.0 => {
            Ok(When::At(*t.get_ref()))
        }
        (None, Some(t)) => Err(at(Some(t.span()), "`at` is seconds from 0 on".into())),
        _ => Err(at(
            Some(span),
            "give one of `after = \"STEP\"`, `after_steps = N` or `at = SECONDS`".into(),
        )),
    };
    for c in &raw.change {
        let r = resource(&c.resource)?;
        let inp = signal(r, &c.signal)?;
        let w = when(&c.after, &c.after_steps, &c.at, c.resource.span())?;
        s.changes.push(Change {
            when: w,
            controller: inp.controller,
            key: inp.key.clone(),
            value: value(&inp, &c.value)?,
        });
    }
    for rs in &raw.restart {
        let c = controller(&rs.controller)?;
        s.restarts.push(Restart {
            when: when(&rs.after, &rs.after_steps, &rs.at, rs.controller.span())?,
            controller: c,
        });
    }
    let wire_names: Vec<&str> = cell.wires.iter().map(|w| w.name.as_str()).collect();
    for sw in &raw.swap {
        let names = sw.wires.get_ref();
        let [a, b] = names.as_slice() else {
            return Err(at(
                Some(sw.wires.span()),
                "`wires` names two wires (the blackboard's link names)".into(),
            ));
        };
        let find = |n: &Spanned<String>| one_of("wire", &wire_names, n);
        let (x, y) = (find(a)?, find(b)?);
        if x == y {
            return Err(at(Some(b.span()), "a wire swapped with itself".into()));
        }
        s.swaps.push((x, y));
    }
    Ok(s)
}
