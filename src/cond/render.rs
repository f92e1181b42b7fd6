//! Rendering in a language's operators: `Ops` (KRL's, ST's for listings), `render`,
//! `render_krl`, with every nested operation parenthesised.

use super::lex::decimal;
use super::{BinOp, Expr, ExprKind};

/// The expression in KRL: `signal` renders a (resolved) name. Every operator nested inside
/// another is parenthesised, so KRL's precedence (comparisons bind weaker than `AND`/`OR`,
/// `EXOR` between them) cannot change the meaning.
pub fn render_krl(e: &Expr, signal: &dyn Fn(&str) -> String) -> String {
    render(e, signal, &Ops::KRL)
}

/// How a robot language writes the condition language's operators and literals.
#[derive(Debug)]
pub struct Ops {
    pub op: fn(BinOp) -> &'static str,
    /// A duration (nanoseconds) in the unit the language's step times count in.
    pub time: fn(u64) -> String,
    /// The negation with its space (`NOT `, `not `).
    pub not: &'static str,
    /// Whether arithmetic is written as the standard functions' calls (`ADD(a, b)`: ST, whose
    /// condition language has no infix arithmetic), else infix.
    pub calls: bool,
    pub true_: &'static str,
    pub false_: &'static str,
}

impl Ops {
    /// A duration in milliseconds (KRL's `$TIMER`).
    pub fn milliseconds(ns: u64) -> String {
        decimal(ns, 1_000_000)
    }

    /// A duration in seconds (RAPID's `ClkRead`, URScript's counters).
    pub fn seconds(ns: u64) -> String {
        decimal(ns, 1_000_000_000)
    }

    pub const KRL: Ops = Ops {
        op: BinOp::krl,
        time: Ops::milliseconds,
        calls: false,
        not: "NOT ",
        true_: "TRUE",
        false_: "FALSE",
    };
    pub(super) const ST: Ops = Ops {
        op: BinOp::st,
        time: |ns| format!("T#{}ms", decimal(ns, 1_000_000)),
        calls: true,
        not: "NOT ",
        true_: "TRUE",
        false_: "FALSE",
    };
}

/// Renders `e` with `ops`, every nested operation in parentheses (no language's precedence is
/// relied on); `signal` gives a name's text, which is parenthesised as an operand when it holds
/// a space (RAPID's `di_Part = 1`).
pub fn render(e: &Expr, signal: &dyn Fn(&str) -> String, ops: &Ops) -> String {
    let mut s = String::new();
    write(e, &mut s, signal, ops);
    s
}

pub(super) fn write(e: &Expr, out: &mut String, name: &dyn Fn(&str) -> String, ops: &Ops) {
    let sub = |x: &Expr, out: &mut String| {
        let text;
        let paren = match &x.kind {
            // A call (`ADD(a, b)` in ST) needs no parentheses.
            ExprKind::Bin(o, ..) => !(ops.calls && o.arithmetic()),
            ExprKind::Neg(_) | ExprKind::Not(_) => true,
            ExprKind::Name(n) => {
                text = name(n);
                if text.contains(' ') {
                    out.push('(');
                    out.push_str(&text);
                    out.push(')');
                } else {
                    out.push_str(&text);
                }
                return;
            }
            _ => false,
        };
        if paren {
            out.push('(');
        }
        write(x, out, name, ops);
        if paren {
            out.push(')');
        }
    };
    match &e.kind {
        ExprKind::Bool(true) => out.push_str(ops.true_),
        ExprKind::Bool(false) => out.push_str(ops.false_),
        ExprKind::Int(s) | ExprKind::Real(s) => out.push_str(s),
        ExprKind::Time(ns) => out.push_str(&(ops.time)(*ns)),
        ExprKind::Name(n) => out.push_str(&name(n)),
        ExprKind::Not(a) => {
            out.push_str(ops.not);
            sub(a, out);
        }
        ExprKind::Neg(a) => {
            out.push('-');
            sub(a, out);
        }
        ExprKind::Bin(o, a, b) if ops.calls && o.arithmetic() => {
            out.push_str(o.function().unwrap_or_default());
            out.push('(');
            write(a, out, name, ops);
            out.push_str(", ");
            write(b, out, name, ops);
            out.push(')');
        }
        ExprKind::Bin(o, a, b) => {
            sub(a, out);
            out.push(' ');
            out.push_str((ops.op)(*o));
            out.push(' ');
            sub(b, out);
        }
    }
}
