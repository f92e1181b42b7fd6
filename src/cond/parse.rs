//! The parser: tokens → `Expr` by precedence climbing (calls of the standard functions made
//! operators), the limits on depth and length, and `1`/`0` read as booleans where one belongs.

use std::ops::Range;

use super::lex::{Lexer, Tok, describe};
use super::{
    BinOp, Expr, ExprKind, Function, MAX_DEPTH, MAX_TOKENS, STANDARD_FUNCTIONS, SyntaxError,
};

struct Parser<'t> {
    text: &'t str,
    toks: Vec<(Tok, Range<usize>)>,
    pos: usize,
    /// Maps a byte offset of the text to the file.
    map: &'t dyn Fn(usize) -> usize,
}

/// Parses a condition. `map` turns a byte offset of `text` into a byte offset of the file (the
/// expression's spans are file ranges); errors are ranges of `text`.
pub fn parse(text: &str, map: &dyn Fn(usize) -> usize) -> Result<Expr, SyntaxError> {
    parse_operand(text, map).map(as_condition)
}

/// An expression that is a whole condition: `1` and `0` read as booleans where a boolean
/// belongs (IEC 61131-3). [`parse`] does this; a wired condition does it once its network is
/// put together, since an `inVariable`'s `1` may be a number compared with an integer signal.
pub fn as_condition(e: Expr) -> Expr {
    booleans(e, true)
}

/// Parses an expression that is a part of a condition (an `inVariable` of a wired one): as
/// [`parse`], but a lone `1` or `0` stays a number until the whole condition is known
/// ([`as_condition`]).
pub fn parse_operand(text: &str, map: &dyn Fn(usize) -> usize) -> Result<Expr, SyntaxError> {
    let toks = Lexer::run(text)?;
    if let Some((_, r)) = toks.get(MAX_TOKENS) {
        return Err(SyntaxError {
            at: r.clone(),
            message: format!("the condition is longer than {MAX_TOKENS} tokens"),
        });
    }
    if toks.is_empty() {
        let t = text.len();
        return Err(SyntaxError {
            at: 0..t,
            message: "empty condition (write `TRUE` for a transition that always fires)".to_owned(),
        });
    }
    let mut p = Parser {
        text,
        toks,
        pos: 0,
        map,
    };
    let e = p.expr(0, 0)?;
    if let Some((_, r)) = p.toks.get(p.pos) {
        let r = r.clone();
        return Err(SyntaxError {
            message: format!(
                "{} after a complete condition: an operator is missing",
                describe(text, &r)
            ),
            at: r,
        });
    }
    Ok(e)
}

/// IEC 61131-3 reads `1` and `0` as booleans where a boolean belongs: the whole condition, the
/// operands of `NOT`, `AND`, `OR`, `XOR`, and a side of `=`/`<>` whose other side is a boolean
/// expression.
fn booleans(e: Expr, want: bool) -> Expr {
    fn boolish(e: &Expr) -> bool {
        match &e.kind {
            ExprKind::Bin(op, ..) => !op.arithmetic(),
            ExprKind::Bool(_) | ExprKind::Not(_) => true,
            _ => false,
        }
    }
    let Expr { kind, span } = e;
    let kind = match kind {
        ExprKind::Int(v) if want && (&*v == "0" || &*v == "1") => ExprKind::Bool(&*v == "1"),
        ExprKind::Not(a) => ExprKind::Not(Box::new(booleans(*a, true))),
        ExprKind::Bin(op @ (BinOp::And | BinOp::Or | BinOp::Xor), a, b) => ExprKind::Bin(
            op,
            Box::new(booleans(*a, true)),
            Box::new(booleans(*b, true)),
        ),
        ExprKind::Bin(op @ (BinOp::Eq | BinOp::Ne), a, b) => {
            let (a, b) = (booleans(*a, false), booleans(*b, false));
            let (a, b) = if boolish(&a) {
                let b = booleans(b, true);
                (a, b)
            } else if boolish(&b) {
                (booleans(a, true), b)
            } else {
                (a, b)
            };
            ExprKind::Bin(op, Box::new(a), Box::new(b))
        }
        ExprKind::Bin(op, a, b) => ExprKind::Bin(
            op,
            Box::new(booleans(*a, false)),
            Box::new(booleans(*b, false)),
        ),
        ExprKind::Neg(a) => ExprKind::Neg(Box::new(booleans(*a, false))),
        k => k,
    };
    Expr { kind, span }
}

impl Parser<'_> {
    fn span(&self, r: Range<usize>) -> Range<usize> {
        let s = (self.map)(r.start);
        let e = (self.map)(r.end.saturating_sub(1)) + 1;
        s..e.max(s)
    }

    fn end_error(&self, what: &str) -> SyntaxError {
        let t = self.text.trim_end().len();
        SyntaxError {
            at: t.saturating_sub(1)..t,
            message: format!("the condition ends where {what} is expected"),
        }
    }

    fn binop(&self) -> Option<BinOp> {
        match self.toks.get(self.pos).map(|t| &t.0) {
            Some(Tok::Or) => Some(BinOp::Or),
            Some(Tok::Xor) => Some(BinOp::Xor),
            Some(Tok::And) => Some(BinOp::And),
            Some(Tok::Op(op)) => Some(*op),
            _ => None,
        }
    }

    /// Precedence climbing: operators binding tighter than `min`.
    fn expr(&mut self, min: u8, depth: usize) -> Result<Expr, SyntaxError> {
        let mut lhs = self.unary(depth)?;
        while let Some(op) = self.binop() {
            if op.strength() <= min {
                break;
            }
            self.pos += 1;
            let rhs = self.expr(op.strength(), depth + 1)?;
            let span = lhs.span.start..rhs.span.end;
            lhs = Expr {
                kind: ExprKind::Bin(op, Box::new(lhs), Box::new(rhs)),
                span,
            };
        }
        Ok(lhs)
    }

    /// A call of a standard function, `F(a, b, …)` (the `(` is next): `AND`, `OR`, `XOR` of two
    /// or more operands, `NOT` of one, the comparisons `EQ`, `NE`, `GT`, `GE`, `LT`, `LE` of two
    /// or more (IEC's chain: `GT(a, b, c)` is `a > b AND b > c`), `SEL(G, IN0, IN1)` and
    /// `MOVE(x)`, as the blocks of a wired condition.
    fn call(&mut self, name: &str, r: Range<usize>, depth: usize) -> Result<Expr, SyntaxError> {
        let Some(f) = Function::named(name) else {
            return Err(SyntaxError {
                at: r,
                message: format!(
                    "function `{name}` is not part of the condition language ({STANDARD_FUNCTIONS} are)"
                ),
            });
        };
        let open = self.toks[self.pos].1.clone();
        self.pos += 1;
        let mut args = Vec::new();
        loop {
            args.push(self.expr(0, depth + 1)?);
            match self.toks.get(self.pos) {
                Some((Tok::Comma, _)) => self.pos += 1,
                Some((Tok::Close, _)) => {
                    self.pos += 1;
                    break;
                }
                Some((_, r2)) => {
                    return Err(SyntaxError {
                        message: format!(
                            "{} where `,` or `)` is expected (in the call of `{name}`)",
                            describe(self.text, r2)
                        ),
                        at: r2.clone(),
                    });
                }
                None => {
                    return Err(SyntaxError {
                        at: open,
                        message: format!("`(` of the call of `{name}` without its `)`"),
                    });
                }
            }
        }
        let close = self.toks[self.pos - 1].1.clone();
        let (least, most) = f.arity();
        if args.len() < least || args.len() > most {
            let wanted = if least == most {
                format!("{least}")
            } else {
                format!("at least {least}")
            };
            return Err(SyntaxError {
                at: r.start..close.end,
                message: format!(
                    "`{name}` takes {wanted} operand(s), this call has {}",
                    args.len()
                ),
            });
        }
        Ok(f.apply(args, self.span(r.start..close.end)))
    }

    fn unary(&mut self, depth: usize) -> Result<Expr, SyntaxError> {
        let Some((tok, r)) = self.toks.get(self.pos).cloned() else {
            return Err(self.end_error("an operand"));
        };
        if depth >= MAX_DEPTH {
            return Err(SyntaxError {
                at: r,
                message: format!("the condition nests deeper than {MAX_DEPTH} levels"),
            });
        }
        self.pos += 1;
        let leaf = |k: ExprKind, p: &Self| Expr {
            kind: k,
            span: p.span(r.clone()),
        };
        let text = &self.text[r.clone()];
        let is_int = matches!(tok, Tok::Int(_));
        Ok(match tok {
            Tok::True => leaf(ExprKind::Bool(true), self),
            Tok::False => leaf(ExprKind::Bool(false), self),
            // A typed literal's sign (`INT#-5`) is a unary minus, as `-5` is.
            Tok::Int(v) | Tok::Real(v) if v.starts_with('-') => {
                let abs: Box<str> = v[1..].into();
                let kind = if is_int {
                    ExprKind::Int(abs)
                } else {
                    ExprKind::Real(abs)
                };
                Expr {
                    kind: ExprKind::Neg(Box::new(leaf(kind, self))),
                    span: self.span(r.clone()),
                }
            }
            Tok::Int(v) => leaf(ExprKind::Int(v.clone()), self),
            Tok::Real(v) => leaf(ExprKind::Real(v.clone()), self),
            Tok::Time(ns) => leaf(ExprKind::Time(ns), self),
            Tok::Name | Tok::And | Tok::Or | Tok::Xor
                if matches!(self.toks.get(self.pos), Some((Tok::Open, _))) =>
            {
                self.call(text, r.clone(), depth)?
            }
            Tok::Name => leaf(ExprKind::Name(text.into()), self),
            Tok::Not | Tok::Minus => {
                let inner = self.unary(depth + 1)?;
                let span = self.span(r.clone()).start..inner.span.end;
                let kind = if tok == Tok::Not {
                    ExprKind::Not(Box::new(inner))
                } else {
                    ExprKind::Neg(Box::new(inner))
                };
                Expr { kind, span }
            }
            Tok::Open => {
                let inner = self.expr(0, depth + 1)?;
                match self.toks.get(self.pos) {
                    Some((Tok::Close, _)) => {
                        self.pos += 1;
                        inner
                    }
                    Some((_, r2)) => {
                        return Err(SyntaxError {
                            message: format!(
                                "{} where `)` is expected (to close the `(` at offset {})",
                                describe(self.text, r2),
                                r.start
                            ),
                            at: r2.clone(),
                        });
                    }
                    None => {
                        return Err(SyntaxError {
                            at: r,
                            message: "`(` without its `)`".to_owned(),
                        });
                    }
                }
            }
            _ => {
                return Err(SyntaxError {
                    message: format!("{} where an operand is expected", describe(self.text, &r)),
                    at: r,
                });
            }
        })
    }
}
