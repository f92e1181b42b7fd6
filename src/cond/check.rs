//! The name and type check: `Ty` (booleans, numbers, times), `CheckError`, and `check` over a
//! whole condition.

use std::ops::Range;

use super::{BinOp, Expr, ExprKind};

/// The type of a (sub)expression.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ty {
    Bool,
    Number,
    /// A duration: a `T#` literal or a step's time.
    Time,
}

impl Ty {
    fn name(self) -> &'static str {
        match self {
            Ty::Bool => "boolean",
            Ty::Number => "number",
            Ty::Time => "time",
        }
    }
}

/// A name or type error: where (a file range) and what; `unknown` marks an unknown name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CheckError {
    pub at: Range<usize>,
    pub message: String,
    pub unknown: bool,
}

/// Resolves the names with `lookup` (`None`: unknown) and checks the types; the whole condition
/// must be boolean. Every error is returned.
pub fn check(e: &Expr, lookup: &dyn Fn(&str) -> Option<Ty>) -> Vec<CheckError> {
    let mut errs = Vec::new();
    if let Some(t) = ty(e, lookup, &mut errs)
        && t != Ty::Bool
    {
        errs.push(CheckError {
            at: e.span.clone(),
            message: "the condition is a number, not a boolean: compare it (`= 3`)".to_owned(),
            unknown: false,
        });
    }
    errs
}

fn ty(e: &Expr, lookup: &dyn Fn(&str) -> Option<Ty>, errs: &mut Vec<CheckError>) -> Option<Ty> {
    let want = |e: &Expr, t: Option<Ty>, wanted: Ty, what: &str, errs: &mut Vec<_>| {
        if let Some(t) = t
            && t != wanted
        {
            let hint = if matches!(e.kind, ExprKind::Not(_)) && wanted != Ty::Bool {
                " (`NOT` binds tighter than a comparison in ST: `NOT (a >= b)` negates the comparison; `NOT` of a number, bitwise in ST, is not part of the condition language)"
            } else {
                ""
            };
            errs.push(CheckError {
                at: e.span.clone(),
                message: format!(
                    "{what} needs a {}, this is a {}{hint}",
                    wanted.name(),
                    t.name()
                ),
                unknown: false,
            });
        }
    };
    match &e.kind {
        ExprKind::Bool(_) => Some(Ty::Bool),
        ExprKind::Int(_) | ExprKind::Real(_) => Some(Ty::Number),
        ExprKind::Time(_) => Some(Ty::Time),
        ExprKind::Name(n) => {
            let t = lookup(n);
            if t.is_none() {
                errs.push(CheckError {
                    at: e.span.clone(),
                    message: n.to_string(),
                    unknown: true,
                });
            }
            t
        }
        ExprKind::Not(a) => {
            let t = ty(a, lookup, errs);
            if t == Some(Ty::Number) {
                // ST's bitwise NOT of a number (`NOT n >= 3` is `(NOT n) >= 3`): one error,
                // here; what it gives is a number, so the comparison around it adds none.
                errs.push(CheckError {
                    at: a.span.clone(),
                    message: "`NOT` needs a boolean, this is a number (`NOT` binds tighter than a comparison in ST, so `NOT n >= 3` is the bitwise NOT of `n`, compared: write `NOT (n >= 3)` to negate the comparison; the bitwise NOT of a number is not part of the condition language)".to_owned(),
                    unknown: false,
                });
                return Some(Ty::Number);
            }
            want(a, t, Ty::Bool, "`NOT`", errs);
            Some(Ty::Bool)
        }
        ExprKind::Neg(a) => {
            let t = ty(a, lookup, errs);
            want(a, t, Ty::Number, "unary `-`", errs);
            Some(Ty::Number)
        }
        ExprKind::Bin(op, a, b) => {
            let (ta, tb) = (ty(a, lookup, errs), ty(b, lookup, errs));
            let what = format!("`{}`", op.st());
            if op.logical() {
                want(a, ta, Ty::Bool, &what, errs);
                want(b, tb, Ty::Bool, &what, errs);
            } else if op.arithmetic() {
                want(a, ta, Ty::Number, &what, errs);
                want(b, tb, Ty::Number, &what, errs);
                return Some(Ty::Number);
            } else if matches!(op, BinOp::Eq | BinOp::Ne) {
                if let (Some(x), Some(y)) = (ta, tb)
                    && x != y
                {
                    errs.push(CheckError {
                        at: e.span.clone(),
                        message: format!(
                            "{what} compares a {} with a {}{}",
                            x.name(),
                            y.name(),
                            if [a, b].iter().any(|o| matches!(o.kind, ExprKind::Not(_))) {
                                " (`NOT` binds tighter than `=` in ST: `NOT (a = b)` negates the comparison; `NOT` of a number, bitwise in ST, is not part of the condition language)"
                            } else {
                                ""
                            }
                        ),
                        unknown: false,
                    });
                }
            } else {
                // Numbers with numbers, times with times.
                let other = |t: Option<Ty>| t.filter(|t| *t != Ty::Bool);
                let wanted = other(ta).or(other(tb)).unwrap_or(Ty::Number);
                want(a, ta, wanted, &what, errs);
                want(b, tb, wanted, &what, errs);
            }
            Some(Ty::Bool)
        }
    }
}
