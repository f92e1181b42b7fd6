//! Reading a program's expressions: inputs through the wires and the world, timers, clocks
//! and counters, and when a timer reaches a limit.

use std::collections::HashMap;

use super::{Clockish, Op, Run, SYNC_S, Val, X};
use crate::simulate::ir::Key;

/// A clock's reading in steps of `res` (what the controller shows: whole milliseconds, whole
/// control cycles), the last step it has passed. The tolerance keeps a reading taken at the
/// very time of a step (a wake at a threshold) from falling a step short by rounding.
fn steps_of(x: f64, res: f64) -> f64 {
    (x / res + 1e-6).floor() * res
}

/// The smallest step a clock advances by, in the unit [`Run::reaches`] takes: KRL's `$TIMER`
/// counts whole milliseconds, a RAPID clock is read to the millisecond (`ClkRead` without
/// `\HighRes`), a URScript counter grows by `get_steptime()` once a control cycle.
pub(super) fn resolution(clock: &Clockish) -> f64 {
    match clock {
        Clockish::Timer(_) | Clockish::Clock(_) => 0.001,
        Clockish::Var(_) => SYNC_S,
    }
}

impl Run<'_> {
    /// When `clock` reads `k` (seconds), if it counts.
    pub(super) fn reaches(&self, c: usize, clock: &Clockish, k: f64) -> Option<f64> {
        let x = &self.ctls[c];
        match clock {
            Clockish::Timer(n) => {
                let (ms, t0, running) = *x.timers.get(n)?;
                running.then(|| t0 + (k * 1000.0 - ms) / 1000.0)
            }
            Clockish::Var(v) => {
                let (base, t0) = *x.counters.get(v)?;
                Some(t0 + (k - base))
            }
            Clockish::Clock(n) => {
                let (s, t0, running) = *x.clocks.get(n)?;
                running.then_some(t0 + (k - s))
            }
        }
    }

    pub(super) fn input(&self, c: usize, k: &Key) -> Val {
        if let Some((d, out)) = self.wired[c].get(k) {
            return self.ctls[*d]
                .outs
                .get(out)
                .cloned()
                .unwrap_or(Val::Bool(false));
        }
        self.world[c].get(k).cloned().unwrap_or(Val::Bool(false))
    }

    /// Whether `e` holds with every comparison of a timer or counter taken as false.
    pub(super) fn eval_untimed(&self, c: usize, e: &X) -> bool {
        fn strip(e: &X, counters: &HashMap<String, (f64, f64)>) -> X {
            match e {
                X::Bin(op, a, b) => {
                    let timed = |x: &X| {
                        matches!(x, X::Timer(_) | X::Clock(_))
                            || matches!(x, X::Var(n) if counters.contains_key(n))
                    };
                    if matches!(op, Op::Ge | Op::Gt | Op::Le | Op::Lt) && (timed(a) || timed(b)) {
                        X::Const(Val::Bool(false))
                    } else {
                        X::Bin(
                            *op,
                            Box::new(strip(a, counters)),
                            Box::new(strip(b, counters)),
                        )
                    }
                }
                X::Not(a) => X::Not(Box::new(strip(a, counters))),
                other => other.clone(),
            }
        }
        let s = strip(e, &self.ctls[c].counters);
        self.eval(c, &s).is_ok_and(|v| v.truth())
    }

    pub(super) fn eval(&self, c: usize, e: &X) -> Result<Val, EvalError> {
        let x = &self.ctls[c];
        Ok(match e {
            X::Const(v) => v.clone(),
            X::Var(n) => {
                if let Some((base, t0)) = x.counters.get(n) {
                    Val::Num(base + steps_of(x.t - t0, SYNC_S))
                } else {
                    x.vars
                        .get(n)
                        .cloned()
                        .ok_or_else(|| EvalError(format!("`{n}` is read before it has a value")))?
                }
            }
            X::In(k, numeric) => {
                let v = self.input(c, k);
                if *numeric {
                    Val::Num(v.num().unwrap_or(0.0))
                } else {
                    v
                }
            }
            X::Out(k, numeric) => {
                let v = x.outs.get(k).cloned().unwrap_or(Val::Bool(false));
                if *numeric {
                    Val::Num(v.num().unwrap_or(0.0))
                } else {
                    v
                }
            }
            X::InAt(f, n) => {
                let n = self.eval(c, n)?.num().unwrap_or(-1.0) as i64;
                self.input(c, &format!("{f}({n})"))
            }
            X::Group(bits) => {
                let mut v = 0u64;
                for (i, b) in bits.iter().enumerate() {
                    if self.input(c, b).truth() {
                        v |= 1 << i;
                    }
                }
                Val::Num(v as f64)
            }
            X::Timer(n) => {
                let (ms, t0, running) = x.timers.get(n).copied().unwrap_or((0.0, x.t, false));
                Val::Num(if running {
                    steps_of(ms + (x.t - t0) * 1000.0, 1.0)
                } else {
                    ms
                })
            }
            X::Clock(n) => {
                let (s, t0, running) = x.clocks.get(n).copied().unwrap_or((0.0, x.t, false));
                Val::Num(if running {
                    steps_of((s + (x.t - t0)) * 1000.0, 1.0) / 1000.0
                } else {
                    s
                })
            }
            X::Not(a) => match self.eval(c, a)? {
                Val::Bool(b) => Val::Bool(!b),
                v => return Err(EvalError(format!("NOT of the number {v}"))),
            },
            X::Neg(a) => match self.eval(c, a)?.num() {
                Some(n) => Val::Num(-n),
                None => return Err(EvalError("- of a text".into())),
            },
            X::Bin(op, a, b) => {
                let (l, r) = (self.eval(c, a)?, self.eval(c, b)?);
                bin(*op, &l, &r)?
            }
        })
    }
}

/// Why an expression could not be evaluated.
pub(super) struct EvalError(pub(super) String);

pub(super) fn bin(op: Op, l: &Val, r: &Val) -> Result<Val, EvalError> {
    let nums = || match (l.num(), r.num()) {
        (Some(a), Some(b)) => Ok((a, b)),
        _ => Err(EvalError(format!("{l} {op:?} {r}: not numbers"))),
    };
    Ok(match op {
        Op::Or | Op::And | Op::Xor => match (l, r) {
            (Val::Bool(a), Val::Bool(b)) => Val::Bool(match op {
                Op::Or => *a || *b,
                Op::And => *a && *b,
                _ => a != b,
            }),
            _ => return Err(EvalError(format!("{l} {op:?} {r}: not booleans"))),
        },
        Op::Eq | Op::Ne => {
            let same = match (l, r) {
                (Val::Str(a), Val::Str(b)) => a == b,
                (Val::Bool(a), Val::Bool(b)) => a == b,
                _ => {
                    let (a, b) = nums()?;
                    (a - b).abs() < 1e-9
                }
            };
            Val::Bool(if op == Op::Eq { same } else { !same })
        }
        Op::Lt | Op::Gt | Op::Le | Op::Ge => {
            let (a, b) = nums()?;
            Val::Bool(match op {
                Op::Lt => a < b,
                Op::Gt => a > b,
                Op::Le => a <= b,
                _ => a >= b,
            })
        }
        Op::Add | Op::Sub | Op::Mul | Op::Div => {
            let (a, b) = nums()?;
            Val::Num(match op {
                Op::Add => a + b,
                Op::Sub => a - b,
                Op::Mul => a * b,
                _ => a / b,
            })
        }
    })
}
