//! Transition conditions (docs/INPUTS.md): the ST subset `TRUE`, `FALSE`, integer and decimal
//! literals (IEC 61131-3's: `1`/`0` as booleans where a boolean belongs, `BOOL#1`, typed
//! `INT#5`/`REAL#1.5`, based `2#`/`8#`/`16#`, `_` between digits; kept in decimal), names (IEC
//! identifiers, any Unicode letter, and qualified names `A.B`), `NOT`, `AND` (`&`), `OR`, `XOR`, `=`, `<>`, `<`, `>`,
//! `<=`, `>=`, unary `-` and parentheses, with ST's precedence (loosest first: `OR`, `XOR`, `AND`,
//! `=`/`<>`, `<`/`>`/`<=`/`>=`, unary `-`/`NOT`). `(* comments *)` are skipped.
//!
//! [`parse`](fn@parse) turns a condition's text into an [`Expr`] whose spans are byte ranges of the file
//! the text came from (the caller maps text offsets to file offsets, since the text may have
//! been assembled from several XML text pieces). [`check`](fn@check) resolves names and types;
//! [`render_krl`] writes KRL with the parentheses KRL's different precedence needs (KRL binds
//! comparisons weaker than `AND`/`OR`).

use std::ops::Range;

mod check;
mod lex;
mod parse;
mod render;

pub use check::{CheckError, Ty, check};
pub use lex::decimal;
pub use parse::{as_condition, parse, parse_operand};
pub use render::{Ops, render, render_krl};

use render::write;

/// Parentheses and `NOT`s nest at most this deep.
pub const MAX_DEPTH: usize = 64;

/// A condition has at most this many tokens (so a chain of operators cannot build a tree deep
/// enough to exhaust the stack of the recursive passes over it).
pub const MAX_TOKENS: usize = 1024;

/// A condition expression. `span` is a byte range in the file the condition was read from.
#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    pub kind: ExprKind,
    pub span: Range<usize>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum ExprKind {
    Bool(bool),
    /// An integer literal, as written (digits only).
    Int(Box<str>),
    /// A decimal literal, as written (`1.5`).
    Real(Box<str>),
    /// A duration (a `T#` / `TIME#` literal), in nanoseconds.
    Time(u64),
    /// A name (a signal, or a step's time `S.t`), as written.
    Name(Box<str>),
    Not(Box<Expr>),
    Neg(Box<Expr>),
    Bin(BinOp, Box<Expr>, Box<Expr>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    Or,
    Xor,
    And,
    Eq,
    Ne,
    Lt,
    Gt,
    Le,
    Ge,
    /// Arithmetic, from the standard functions `ADD`, `SUB`, `MUL` (wired blocks or calls in
    /// ST; the condition language of docs/INPUTS.md has no infix arithmetic).
    Add,
    Sub,
    Mul,
}

impl BinOp {
    /// ST binding strength: higher binds tighter.
    fn strength(self) -> u8 {
        match self {
            BinOp::Or => 1,
            BinOp::Xor => 2,
            BinOp::And => 3,
            BinOp::Eq | BinOp::Ne => 4,
            BinOp::Lt | BinOp::Gt | BinOp::Le | BinOp::Ge => 5,
            BinOp::Add | BinOp::Sub => 6,
            BinOp::Mul => 7,
        }
    }

    /// Whether the operator is arithmetic (numbers to a number).
    pub fn arithmetic(self) -> bool {
        matches!(self, BinOp::Add | BinOp::Sub | BinOp::Mul)
    }

    /// The standard function of an arithmetic operator, as ST calls it.
    fn function(self) -> Option<&'static str> {
        match self {
            BinOp::Add => Some("ADD"),
            BinOp::Sub => Some("SUB"),
            BinOp::Mul => Some("MUL"),
            _ => None,
        }
    }

    /// The operator as ST writes it.
    pub fn st(self) -> &'static str {
        match self {
            BinOp::Or => "OR",
            BinOp::Xor => "XOR",
            BinOp::And => "AND",
            BinOp::Eq => "=",
            BinOp::Ne => "<>",
            BinOp::Lt => "<",
            BinOp::Gt => ">",
            BinOp::Le => "<=",
            BinOp::Ge => ">=",
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
        }
    }

    /// The operator as KRL writes it.
    pub fn krl(self) -> &'static str {
        match self {
            BinOp::Or => "OR",
            BinOp::Xor => "EXOR",
            BinOp::And => "AND",
            BinOp::Eq => "==",
            BinOp::Ne => "<>",
            BinOp::Lt => "<",
            BinOp::Gt => ">",
            BinOp::Le => "<=",
            BinOp::Ge => ">=",
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
        }
    }

    fn logical(self) -> bool {
        matches!(self, BinOp::Or | BinOp::Xor | BinOp::And)
    }
}

impl Expr {
    /// Whether the expression is the literal `TRUE`.
    pub fn is_true(&self) -> bool {
        matches!(self.kind, ExprKind::Bool(true))
    }

    /// Every name in the expression, left to right, with its span.
    pub fn names(&self) -> Vec<(&str, Range<usize>)> {
        let mut out = Vec::new();
        let mut stack = vec![self];
        while let Some(e) = stack.pop() {
            match &e.kind {
                ExprKind::Name(n) => out.push((&**n, e.span.clone())),
                ExprKind::Not(a) | ExprKind::Neg(a) => stack.push(a),
                ExprKind::Bin(_, a, b) => {
                    stack.push(b);
                    stack.push(a);
                }
                _ => {}
            }
        }
        out
    }

    /// The expression in ST, fully parenthesised where operators nest (for listings).
    pub fn to_st(&self) -> String {
        let mut s = String::new();
        write(self, &mut s, &|n| n.to_owned(), &Ops::ST);
        s
    }
}

/// A syntax error: where (a byte range of the condition's text) and what.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SyntaxError {
    pub at: Range<usize>,
    pub message: String,
}

/// The standard functions a condition may use, as a wired block or called in ST (docs/INPUTS.md),
/// as messages list them.
pub const STANDARD_FUNCTIONS: &str =
    "AND, OR, XOR, NOT, EQ, NE, GT, GE, LT, LE, ADD, SUB, MUL, SEL and MOVE";

/// What a standard function computes, made operators of the expression.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Function {
    /// `AND`, `OR`, `XOR`, `ADD`, `MUL`: over all its operands.
    Fold(BinOp),
    /// `SUB`: over exactly two.
    Two(BinOp),
    /// `EQ`, `NE`, `GT`, `GE`, `LT`, `LE`: IEC's chain, `GT(a, b, c)` is `a > b AND b > c`.
    Chain(BinOp),
    Not,
    Move,
    /// `SEL(G, IN0, IN1)`: `IN1` when `G`, else `IN0`.
    Sel,
}

impl Function {
    /// The standard function of this name (any case), if it is one of
    /// [`STANDARD_FUNCTIONS`].
    pub fn named(name: &str) -> Option<Function> {
        Some(match name.trim().to_ascii_uppercase().as_str() {
            "AND" => Function::Fold(BinOp::And),
            "OR" => Function::Fold(BinOp::Or),
            "XOR" => Function::Fold(BinOp::Xor),
            "ADD" => Function::Fold(BinOp::Add),
            "MUL" => Function::Fold(BinOp::Mul),
            "SUB" => Function::Two(BinOp::Sub),
            "EQ" => Function::Chain(BinOp::Eq),
            "NE" => Function::Chain(BinOp::Ne),
            "GT" => Function::Chain(BinOp::Gt),
            "GE" => Function::Chain(BinOp::Ge),
            "LT" => Function::Chain(BinOp::Lt),
            "LE" => Function::Chain(BinOp::Le),
            "NOT" => Function::Not,
            "MOVE" => Function::Move,
            "SEL" => Function::Sel,
            _ => return None,
        })
    }

    /// The formal parameters of its block, in operand order; `None`: all of the block's inputs,
    /// in order.
    pub fn formals(self) -> Option<&'static [&'static str]> {
        match self {
            Function::Fold(_) => None,
            Function::Two(_) | Function::Chain(_) => Some(&["IN1", "IN2"]),
            Function::Not | Function::Move => Some(&["IN"]),
            Function::Sel => Some(&["G", "IN0", "IN1"]),
        }
    }

    /// How many operands a call takes: at least, at most.
    fn arity(self) -> (usize, usize) {
        match self {
            Function::Fold(_) | Function::Chain(_) => (2, usize::MAX),
            Function::Two(_) => (2, 2),
            Function::Not | Function::Move => (1, 1),
            Function::Sel => (3, 3),
        }
    }

    /// The expression of the function over `args` (at least one; as many as
    /// [`Function::formals`] names where it names them), every new node spanning `span`.
    pub fn apply(self, args: Vec<Expr>, span: Range<usize>) -> Expr {
        let bin = |op, a: Expr, b: Expr| Expr {
            kind: ExprKind::Bin(op, Box::new(a), Box::new(b)),
            span: span.clone(),
        };
        let mut it = args.into_iter();
        let first = it.next().expect("an operand at least");
        match self {
            Function::Fold(op) | Function::Two(op) => it.fold(first, |acc, a| bin(op, acc, a)),
            Function::Chain(op) => {
                let mut prev = first;
                let mut out: Option<Expr> = None;
                for next in it {
                    let part = bin(op, prev, next.clone());
                    out = Some(match out {
                        None => part,
                        Some(acc) => bin(BinOp::And, acc, part),
                    });
                    prev = next;
                }
                out.unwrap_or(prev)
            }
            Function::Not => Expr {
                kind: ExprKind::Not(Box::new(first)),
                span: span.clone(),
            },
            Function::Move => first,
            Function::Sel => {
                let g = first;
                let (in0, in1) = (it.next().expect("IN0"), it.next().expect("IN1"));
                let not_g = Expr {
                    kind: ExprKind::Not(Box::new(g.clone())),
                    span: span.clone(),
                };
                bin(
                    BinOp::Or,
                    bin(BinOp::And, g, in1),
                    bin(BinOp::And, not_g, in0),
                )
            }
        }
    }
}

#[cfg(test)]
mod tests;
