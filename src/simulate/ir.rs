//! What the simulator runs: a program as flat instructions ([`Ins`], blocks become jumps) over
//! resolved expressions ([`X`]), the same for every language; and the expression reader the
//! three language readers share ([`Grammar`], [`parse_expr`]).

use std::fmt;

/// A value while a program runs.
#[derive(Debug, Clone, PartialEq)]
pub enum Val {
    Num(f64),
    Bool(bool),
    Str(String),
}

impl Val {
    /// A boolean, or a number other than 0 (RAPID's digital values are 0 and 1).
    pub fn truth(&self) -> bool {
        match self {
            Val::Bool(b) => *b,
            Val::Num(n) => *n != 0.0,
            Val::Str(s) => !s.is_empty(),
        }
    }

    pub fn num(&self) -> Option<f64> {
        match self {
            Val::Num(n) => Some(*n),
            Val::Bool(b) => Some(f64::from(u8::from(*b))),
            Val::Str(_) => None,
        }
    }
}

impl fmt::Display for Val {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Val::Num(n) => write!(f, "{n}"),
            Val::Bool(b) => write!(f, "{}", if *b { "TRUE" } else { "FALSE" }),
            Val::Str(s) => write!(f, "\"{s}\""),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Op {
    Or,
    Xor,
    And,
    Eq,
    Ne,
    Lt,
    Gt,
    Le,
    Ge,
    Add,
    Sub,
    Mul,
    Div,
}

/// An expression as read, before the language reader resolves its names.
#[derive(Debug, Clone)]
pub enum Raw {
    Num(f64),
    Bool(bool),
    Str(String),
    Name(String),
    /// `a[i]` (KRL `$IN[3]`, `$TIMER[16]`).
    Index(String, Box<Raw>),
    /// `f(a, b)`; RAPID's `\Switch` arguments are left out.
    Call(String, Vec<Raw>),
    Not(Box<Raw>),
    Neg(Box<Raw>),
    Bin(Op, Box<Raw>, Box<Raw>),
}

/// An I/O point of one controller, as its program addresses it: KRL `$IN[3]`, a RAPID signal's
/// name, URScript `get_standard_digital_in(3)`. Upper-cased for KRL and RAPID (their names
/// are not case-sensitive).
pub type Key = String;

/// The I/O keys of one controller's signals and wires (from the blackboard), which the
/// readers tell from variables by.
#[derive(Debug, Clone, Default)]
pub struct IoKeys {
    pub ins: std::collections::HashSet<Key>,
    pub outs: std::collections::HashSet<Key>,
}

/// A resolved expression.
#[derive(Debug, Clone)]
pub enum X {
    Const(Val),
    /// A program variable (its key: upper-cased where the language ignores case).
    Var(String),
    /// An input (or an output read back); `numeric`: a digital value reads as 0 or 1 (RAPID).
    In(Key, bool),
    /// An output of this controller read back.
    Out(Key, bool),
    /// An input whose number is computed (URScript `get_standard_digital_in(From_A_1)`): the
    /// function and the argument; the key is `f(n)`.
    InAt(String, Box<X>),
    /// A KRL `SIGNAL` group: its bits, least significant first.
    Group(Vec<Key>),
    /// KRL `$TIMER[n]`: milliseconds.
    Timer(u32),
    /// RAPID `ClkRead(c)`: seconds.
    Clock(String),
    Not(Box<X>),
    Neg(Box<X>),
    Bin(Op, Box<X>, Box<X>),
}

impl X {
    /// Every input key the expression reads (computed ones as `f(?)`).
    pub fn inputs(&self, out: &mut Vec<Key>) {
        match self {
            X::In(k, _) => out.push(k.clone()),
            X::Group(ks) => out.extend(ks.iter().cloned()),
            X::InAt(f, _) => out.push(format!("{f}(?)")),
            X::Not(a) | X::Neg(a) => a.inputs(out),
            X::Bin(_, a, b) => {
                a.inputs(out);
                b.inputs(out);
            }
            _ => {}
        }
    }

    /// Every output of its own controller the expression reads back.
    pub fn outputs(&self, out: &mut Vec<Key>) {
        match self {
            X::Out(k, _) => out.push(k.clone()),
            X::Not(a) | X::Neg(a) => a.outputs(out),
            X::Bin(_, a, b) => {
                a.outputs(out);
                b.outputs(out);
            }
            _ => {}
        }
    }

    /// The times a timer comparison in it flips: (timer, threshold in ms) for KRL `$TIMER[n] >=
    /// k`, (clock variable, seconds) for a URScript counter.
    pub fn thresholds(&self, out: &mut Vec<(Clockish, f64)>) {
        match self {
            X::Bin(op, a, b) => {
                let pair = match (&**a, &**b) {
                    (X::Timer(n), X::Const(v)) | (X::Const(v), X::Timer(n)) => {
                        v.num().map(|k| (Clockish::Timer(*n), k / 1000.0))
                    }
                    (X::Var(n), X::Const(v)) | (X::Const(v), X::Var(n)) => {
                        v.num().map(|k| (Clockish::Var(n.clone()), k))
                    }
                    (X::Clock(n), X::Const(v)) | (X::Const(v), X::Clock(n)) => {
                        v.num().map(|k| (Clockish::Clock(n.clone()), k))
                    }
                    _ => None,
                };
                if let Some(p) = pair
                    && matches!(op, Op::Ge | Op::Gt | Op::Le | Op::Lt)
                {
                    out.push(p);
                }
                a.thresholds(out);
                b.thresholds(out);
            }
            X::Not(a) | X::Neg(a) => a.thresholds(out),
            _ => {}
        }
    }
}

/// Something that counts time: a KRL timer, a URScript counter variable, a RAPID clock.
#[derive(Debug, Clone, PartialEq)]
pub enum Clockish {
    Timer(u32),
    Var(String),
    Clock(String),
}

/// Which wait: how the machine treats the motions before it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Settle {
    /// The motions before it end first (KRL `WAIT FOR`, RAPID `\InPos`).
    Yes,
    No,
}

/// One instruction.
#[derive(Debug, Clone)]
pub enum Ins {
    /// A step of the chart begins (its title comment): its localId and name.
    Step {
        local_id: u64,
        name: String,
    },
    /// The end of a step's own code: what it did (a `WAIT SEC`, a `sleep`) took the step's
    /// time, not more.
    StepEnd,
    /// A motion statement: part of its step's motion (the step's time covers it). The
    /// points it names (not a literal position, not a system variable), as written, that the
    /// program does not declare ([`Program::undeclared_points`]): a fault when it runs.
    Motion(Vec<String>),
    /// A comment of the writer's (`handshake: …`, `selection localId 8: …`): what the program
    /// does next, for the report.
    Note(String),
    /// A branch of a selection is taken (`branch 1 (transition localId 9): …`).
    Branch {
        selection: Option<u64>,
        transition: u64,
    },
    /// Waits until the condition holds. `max`: RAPID's `\MaxTime` (seconds) and its
    /// `\TimeFlag` variable; `poll`: RAPID's `\PollRate` (seconds), how often the controller
    /// reads the condition when a scenario asks for the controller's own rates.
    Wait {
        cond: X,
        settle: Settle,
        max: Option<(f64, Option<String>)>,
        poll: Option<f64>,
    },
    /// Time passes (seconds); `settle`: the motions before end first (KRL `WAIT SEC`, RAPID
    /// `WaitTime \InPos`).
    Sleep(X, Settle),
    /// One control cycle (URScript `sync()`).
    Sync,
    SetOut(Key, X),
    /// URScript `set_standard_digital_out(n, v)`: the function, the number, the value.
    SetOutAt(String, X, X),
    Assign(String, X),
    /// KRL `$TIMER[n] = v` (ms), `$TIMER_STOP[n] = v`.
    TimerSet(u32, X),
    TimerStop(u32, X),
    ClockReset(String),
    ClockStart(String),
    ClockStop(String),
    /// The message a stop or wait shows (a `Msg_Txt` set, `ErrWrite`, `popup`).
    Message(String),
    /// The message of a wait that lasts appears on the pendant (KRL `Set_KrlMsg(#WAITING …)`,
    /// RAPID `TPWrite`, the writer's URScript `textmsg` at a long wait's start) and is taken
    /// away (`Clr_KrlMsg`, `TPErase`, the `textmsg` at its end).
    Show(String),
    Clear,
    JumpIfNot(X, usize),
    Jump(usize),
    /// The program stops until it is started again (KRL `HALT`, RAPID `EXIT`/`Stop`,
    /// URScript `halt`).
    Halt,
    /// A statement the simulator does not run: its text (takes no time of its own).
    Unknown(String),
    End,
}

/// A statement's place in the program text: its line (1-based).
pub type Line = u32;

/// How many lines a reader puts in the places of calls (a routine's body for each call, the
/// calls in it too, eight deep), all calls together: 64 for each line of the program, and
/// 10,000 more. A program whose routines call each other many times over (a fuzzer's: a
/// routine holding the calls of the main program) grew exponentially before; a call past the
/// limit is read as a statement not understood.
pub struct InlineBudget {
    used: usize,
    limit: usize,
}

impl InlineBudget {
    /// The budget of a program of `source_lines` lines.
    pub fn new(source_lines: usize) -> Self {
        InlineBudget {
            used: 0,
            limit: source_lines.saturating_mul(64).saturating_add(10_000),
        }
    }

    /// Takes `lines` for the body of `call`; past the limit, nothing is taken and the
    /// statement the call is read as instead.
    pub fn take(&mut self, lines: usize, call: &str) -> Result<(), Ins> {
        if self.used + lines > self.limit {
            return Err(Ins::Unknown(format!(
                "{}: not read, the calls of this program's routines would put more than {} lines in their places",
                call.trim(),
                self.limit
            )));
        }
        self.used += lines;
        Ok(())
    }
}

/// A program read: instructions, each with its line; variables and their first values.
#[derive(Debug, Clone, Default)]
pub struct Program {
    pub ins: Vec<(Ins, Line)>,
    /// Variables declared with a value (KRL `.dat` `DECL`, RAPID `VAR`, URScript globals set
    /// before the main routine): set again at each start.
    pub init: Vec<(String, Val)>,
    /// URScript counters a thread advances by `get_steptime()`.
    pub counters: Vec<String>,
    /// Statements not run, each once, with its first line.
    pub unknown: Vec<(String, Line)>,
    /// Language-specific: RAPID and KRL compare names without regard to case.
    pub fold_case: bool,
    /// Every name the program's files declare as data (KRL `DECL`, RAPID `VAR`/`PERS`/
    /// `CONST`, URScript variables it assigns and routine parameters): a motion to a point
    /// not among them stops the program.
    pub declared: std::collections::HashSet<String>,
}

/// The point a motion's argument names (`XGrip`, `pTake`, `p_pick`), as written; `None` for
/// a literal position, a computed one (`Offs(p, 0, 0, 10)`), a system variable (`$POS_ACT`)
/// or RAPID's `*`.
pub fn point_name(arg: &str) -> Option<String> {
    let a = arg.trim();
    let mut chars = a.chars();
    let first = chars.next()?;
    if !(first.is_ascii_alphabetic() || first == '_')
        || !chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
    {
        return None;
    }
    Some(a.to_owned())
}

impl Program {
    pub fn push(&mut self, i: Ins, line: Line) -> usize {
        if let Ins::Unknown(t) = &i
            && !self.unknown.iter().any(|(u, _)| u == t)
        {
            self.unknown.push((t.clone(), line));
        }
        self.ins.push((i, line));
        self.ins.len() - 1
    }

    /// Keeps in each motion only the points [`Program::declared`] does not hold (compared as
    /// the language compares names): what a reader does once it has read the whole program.
    pub fn undeclared_points(&mut self) {
        let (declared, fold) = (&self.declared, self.fold_case);
        for (i, _) in &mut self.ins {
            if let Ins::Motion(points) = i {
                points.retain(|n| {
                    !if fold {
                        declared.contains(&n.to_ascii_uppercase())
                    } else {
                        declared.contains(n)
                    }
                });
            }
        }
    }

    pub fn patch(&mut self, at: usize, to: usize) {
        match &mut self.ins[at].0 {
            Ins::JumpIfNot(_, t) | Ins::Jump(t) => *t = to,
            _ => {}
        }
    }
}

/// An expression grammar: binary operator levels from the loosest, where a prefix `NOT`
/// binds, and whether keywords ignore case.
pub struct Grammar {
    pub levels: &'static [&'static [(&'static str, Op)]],
    /// The level at which `NOT` is read as a prefix (`levels.len()`: as tight as unary `-`).
    pub not_level: usize,
    pub not: &'static str,
    pub fold_case: bool,
    pub trues: &'static [&'static str],
    pub falses: &'static [&'static str],
}

/// A reason an expression could not be read.
#[derive(Debug, Clone)]
pub struct ExprError(pub String);

fn tokens(s: &str) -> Result<Vec<String>, ExprError> {
    let b: Vec<char> = s.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c.is_whitespace() {
            i += 1;
        } else if c == '"' {
            let st = i;
            i += 1;
            while i < b.len() && b[i] != '"' {
                i += 1;
            }
            if i >= b.len() {
                return Err(ExprError("a string without its closing quote".into()));
            }
            i += 1;
            out.push(b[st..i].iter().collect());
        } else if c.is_ascii_digit() || (c == '.' && b.get(i + 1).is_some_and(char::is_ascii_digit))
        {
            let st = i;
            while i < b.len()
                && (b[i].is_ascii_digit()
                    || b[i] == '.'
                    || ((b[i] == 'e' || b[i] == 'E')
                        && b.get(i + 1)
                            .is_some_and(|n| n.is_ascii_digit() || *n == '-' || *n == '+')))
            {
                if b[i] == 'e' || b[i] == 'E' {
                    i += 1;
                }
                i += 1;
            }
            out.push(b[st..i].iter().collect());
        } else if c.is_alphanumeric() || c == '_' || c == '$' || c == '\\' {
            let st = i;
            i += 1;
            while i < b.len() && (b[i].is_alphanumeric() || b[i] == '_' || b[i] == '.') {
                i += 1;
            }
            out.push(b[st..i].iter().collect());
        } else {
            let two: String = b[i..(i + 2).min(b.len())].iter().collect();
            if ["==", "<>", "<=", ">=", "!=", ":="].contains(&two.as_str()) {
                out.push(two);
                i += 2;
            } else if "()[],=<>+-*/:".contains(c) {
                out.push(c.to_string());
                i += 1;
            } else {
                return Err(ExprError(format!("the character `{c}`")));
            }
        }
    }
    Ok(out)
}

struct P<'g> {
    t: Vec<String>,
    i: usize,
    g: &'g Grammar,
    depth: usize,
}

impl P<'_> {
    fn peek(&self) -> Option<&str> {
        self.t.get(self.i).map(String::as_str)
    }

    fn is(&self, word: &str) -> bool {
        self.peek().is_some_and(|p| {
            if self.g.fold_case {
                p.eq_ignore_ascii_case(word)
            } else {
                p == word
            }
        })
    }

    fn level(&mut self, k: usize) -> Result<Raw, ExprError> {
        self.depth += 1;
        if self.depth > 200 {
            return Err(ExprError("too deeply nested".into()));
        }
        let r = self.level_inner(k);
        self.depth -= 1;
        r
    }

    fn level_inner(&mut self, k: usize) -> Result<Raw, ExprError> {
        if k == self.g.not_level && self.is(self.g.not) {
            self.i += 1;
            return Ok(Raw::Not(Box::new(self.level(k)?)));
        }
        if k >= self.g.levels.len() {
            return self.unary();
        }
        let mut l = self.level(k + 1)?;
        loop {
            let Some(op) = self.g.levels[k]
                .iter()
                .find(|(w, _)| self.is(w))
                .map(|(_, op)| *op)
            else {
                return Ok(l);
            };
            self.i += 1;
            let r = self.level(k + 1)?;
            l = Raw::Bin(op, Box::new(l), Box::new(r));
        }
    }

    fn unary(&mut self) -> Result<Raw, ExprError> {
        if self.g.not_level >= self.g.levels.len() && self.is(self.g.not) {
            self.i += 1;
            return Ok(Raw::Not(Box::new(self.unary()?)));
        }
        if self.peek() == Some("-") {
            self.i += 1;
            return Ok(Raw::Neg(Box::new(self.unary()?)));
        }
        if self.peek() == Some("+") {
            self.i += 1;
            return self.unary();
        }
        self.primary()
    }

    fn expect(&mut self, what: &str) -> Result<(), ExprError> {
        if self.peek() == Some(what) {
            self.i += 1;
            Ok(())
        } else {
            Err(ExprError(format!(
                "`{what}` expected, found {}",
                self.peek()
                    .map_or("the end".to_owned(), |t| format!("`{t}`"))
            )))
        }
    }

    fn primary(&mut self) -> Result<Raw, ExprError> {
        let Some(t) = self.t.get(self.i).cloned() else {
            return Err(ExprError("an operand expected, found the end".into()));
        };
        self.i += 1;
        if t == "(" {
            let e = self.level(0)?;
            self.expect(")")?;
            return Ok(e);
        }
        if t.starts_with('"') {
            return Ok(Raw::Str(t.trim_matches('"').to_owned()));
        }
        if t.starts_with(|c: char| c.is_ascii_digit() || c == '.') {
            return t
                .parse::<f64>()
                .map(Raw::Num)
                .map_err(|_| ExprError(format!("the number `{t}`")));
        }
        let eq = |w: &&str| {
            if self.g.fold_case {
                w.eq_ignore_ascii_case(&t)
            } else {
                **w == t
            }
        };
        if self.g.trues.iter().any(eq) {
            return Ok(Raw::Bool(true));
        }
        if self.g.falses.iter().any(eq) {
            return Ok(Raw::Bool(false));
        }
        if !t.starts_with(|c: char| c.is_alphabetic() || c == '_' || c == '$') {
            return Err(ExprError(format!("`{t}` where an operand belongs")));
        }
        if self.peek() == Some("(") {
            self.i += 1;
            let mut args = Vec::new();
            if self.peek() == Some(")") {
                self.i += 1;
                return Ok(Raw::Call(t, args));
            }
            loop {
                // RAPID's optional arguments (`\MaxTime:=2`) are not values of the call.
                if self.peek().is_some_and(|p| p.starts_with('\\')) {
                    self.i += 1;
                    if self.peek() == Some(":=") {
                        self.i += 1;
                        self.level(0)?;
                    }
                } else {
                    args.push(self.level(0)?);
                }
                match self.peek() {
                    Some(",") => self.i += 1,
                    Some(")") => {
                        self.i += 1;
                        return Ok(Raw::Call(t, args));
                    }
                    _ => return Err(ExprError(format!("`)` expected after `{t}(`"))),
                }
            }
        }
        if self.peek() == Some("[") {
            self.i += 1;
            if self.peek() == Some("]") {
                self.i += 1;
                return Ok(Raw::Name(format!("{t}[]")));
            }
            let e = self.level(0)?;
            self.expect("]")?;
            return Ok(Raw::Index(t, Box::new(e)));
        }
        Ok(Raw::Name(t))
    }
}

/// Reads an expression of grammar `g`.
pub fn parse_expr(s: &str, g: &Grammar) -> Result<Raw, ExprError> {
    let mut p = P {
        t: tokens(s)?,
        i: 0,
        g,
        depth: 0,
    };
    let e = p.level(0)?;
    if p.i != p.t.len() {
        return Err(ExprError(format!("`{}` after the expression", p.t[p.i])));
    }
    Ok(e)
}

/// The text of a comment's localId (`… (localId 5) …`, `localId 8:`).
pub fn local_id_in(text: &str) -> Option<u64> {
    let at = text.find("localId ")?;
    let digits: String = text[at + 8..]
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.parse().ok()
}

/// A step's title (`2 Grip: Close @ Greifer G1 (localId 5)`): its localId and name.
pub fn step_title(title: &str) -> Option<(u64, String)> {
    let mut words = title.split_whitespace();
    words.next()?.parse::<usize>().ok()?;
    let (head, _) = title.split_once(':')?;
    let name = head.split_once(' ')?.1.trim().to_owned();
    let id = local_id_in(&title[title.rfind("(localId ")?..])?;
    Some((id, name))
}

/// A branch comment (`branch 1 (transition localId 9): …`): the transition's localId.
pub fn branch_title(text: &str) -> Option<u64> {
    let rest = text.strip_prefix("branch ")?;
    let (n, rest) = rest.split_once(' ')?;
    n.parse::<usize>().ok()?;
    rest.strip_prefix("(transition localId ")
        .and_then(|r| r.split(')').next())
        .and_then(|d| d.parse().ok())
}

/// What a comment of the writer's says after a step's title: a branch taken
/// ([`Ins::Branch`]), what the program does next (a handshake, a selection, a transition, a
/// loop: [`Ins::Note`]), or nothing. Such a comment also ends a step's own code.
pub fn writer_comment(comment: &str) -> Option<Ins> {
    if let Some(transition) = branch_title(comment) {
        return Some(Ins::Branch {
            selection: None,
            transition,
        });
    }
    ["handshake:", "selection ", "transition ", "loop "]
        .iter()
        .any(|p| comment.starts_with(p))
        .then(|| Ins::Note(comment.to_owned()))
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::simulate::krl::GRAMMAR as KRL;

    #[test]
    fn krl_comparisons_bind_loosest() {
        let e = parse_expr("NOT a OR $IN[3] == b", &KRL).unwrap();
        let Raw::Bin(Op::Eq, l, _) = e else {
            panic!("{e:?}")
        };
        assert!(matches!(*l, Raw::Bin(Op::Or, _, _)));
    }

    #[test]
    fn titles_give_localid_and_name() {
        assert_eq!(
            step_title("2 Grip: Close @ Greifer G1 (localId 5)"),
            Some((5, "Grip".into()))
        );
        assert_eq!(
            step_title("3 Pick part: Move (x) @ R (localId 14)"),
            Some((14, "Pick part".into()))
        );
        assert_eq!(step_title("PTP XPick Vel=100 %"), None);
        assert_eq!(
            branch_title("branch 2 (transition localId 17): NOT Part_Present"),
            Some(17)
        );
    }

    /// An expression tree written out: `(a OR (b AND FALSE))`.
    fn shape(e: &Raw) -> String {
        match e {
            Raw::Num(n) => n.to_string(),
            Raw::Bool(b) => b.to_string(),
            Raw::Str(s) => format!("{s:?}"),
            Raw::Name(n) => n.clone(),
            Raw::Index(a, i) => format!("{a}[{}]", shape(i)),
            Raw::Call(f, args) => {
                format!(
                    "{f}({})",
                    args.iter().map(shape).collect::<Vec<_>>().join(", ")
                )
            }
            Raw::Not(a) => format!("(not {})", shape(a)),
            Raw::Neg(a) => format!("(-{})", shape(a)),
            Raw::Bin(op, a, b) => format!("({} {op:?} {})", shape(a), shape(b)),
        }
    }

    /// RAPID's priorities, weakest first: `OR`/`XOR`, `AND`, `NOT` (on a comparison),
    /// comparisons, `+`/`-`, `*`/`/`.
    #[test]
    fn rapid_expressions_use_rapid_priorities() {
        use crate::simulate::rapid::GRAMMAR as RAPID;
        for (text, want) in [
            (
                "gi_Variant = 3 AND di_Part_OK = 1",
                "((gi_Variant Eq 3) And (di_Part_OK Eq 1))",
            ),
            ("NOT di_Release = 1", "(not (di_Release Eq 1))"),
            (
                "di_Part_OK = 1 OR di_Release = 1 AND FALSE",
                "((di_Part_OK Eq 1) Or ((di_Release Eq 1) And false))",
            ),
            (
                "(di_Part_OK = 1 OR di_Release = 1) AND FALSE",
                "(((di_Part_OK Eq 1) Or (di_Release Eq 1)) And false)",
            ),
            (
                "(di_Part_OK = 1) XOR (di_Release = 1)",
                "((di_Part_OK Eq 1) Xor (di_Release Eq 1))",
            ),
            ("-gi_Variant < -2", "((-gi_Variant) Lt (-2))"),
            (
                "ClkRead(skp_clock1) > 0.35",
                "(ClkRead(skp_clock1) Gt 0.35)",
            ),
        ] {
            let e = parse_expr(text, &RAPID).unwrap_or_else(|e| panic!("{text}: {e:?}"));
            assert_eq!(shape(&e), want, "{text}");
        }
        for bad in ["(di_Part_OK = 1", "di_Part_OK = 1 di_Release = 1", "NOT"] {
            assert!(parse_expr(bad, &RAPID).is_err(), "`{bad}` is read");
        }
    }

    /// URScript's (Python's) precedence: `not` binds weaker than comparisons, tighter than
    /// `and`.
    #[test]
    fn urscript_expressions_use_python_precedence() {
        use crate::simulate::urscript::GRAMMAR as UR;
        for (text, want) in [
            (
                "not read_input_integer_register(9) == 3",
                "(not (read_input_integer_register(9) Eq 3))",
            ),
            (
                "read_input_integer_register(9) == 3 and get_standard_digital_in(1)",
                "((read_input_integer_register(9) Eq 3) And get_standard_digital_in(1))",
            ),
            (
                "get_standard_digital_in(1) or get_standard_digital_in(3) and False",
                "(get_standard_digital_in(1) Or (get_standard_digital_in(3) And false))",
            ),
            (
                "not get_standard_digital_in(3) and get_standard_digital_in(1)",
                "((not get_standard_digital_in(3)) And get_standard_digital_in(1))",
            ),
            (
                "skp_time1 > 0.35 or get_standard_digital_in(3)",
                "((skp_time1 Gt 0.35) Or get_standard_digital_in(3))",
            ),
        ] {
            let e = parse_expr(text, &UR).unwrap_or_else(|e| panic!("{text}: {e:?}"));
            assert_eq!(shape(&e), want, "{text}");
        }
        for bad in [
            "get_standard_digital_in(1) and not",
            "(get_standard_digital_in(1)",
        ] {
            assert!(parse_expr(bad, &UR).is_err(), "`{bad}` is read");
        }
    }

    #[test]
    fn bad_expressions_are_errors_not_panics() {
        for s in ["(", "a AND", "\"x", "a b", "f(", "a[", "§", ""] {
            assert!(parse_expr(s, &KRL).is_err(), "{s}");
        }
        let deep = "(".repeat(5000) + "1" + &")".repeat(5000);
        assert!(parse_expr(&deep, &KRL).is_err());
    }
}
