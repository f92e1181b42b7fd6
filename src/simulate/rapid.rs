//! Reads a RAPID module into [`Program`] (ABB RAPID Instructions, Functions and Data Types;
//! RAPID Kernel reference): `PROC main()` to `ENDPROC`, each call of a `PROC` of the module put
//! in its place (its parameters set first), `VAR`/`PERS`/`CONST` `num` and `bool` data,
//! `IF`/`ELSEIF`/`ELSE`, the one-line `IF`, `WHILE`, `FOR`, `TEST`/`CASE`, `GOTO` and labels,
//! `WaitUntil` (`\InPos`, `\MaxTime`, `\TimeFlag`), `WaitTime`, `WaitDI`, `SetDO`, `Set`,
//! `Reset`, `DInput`/`DOutput`, the clocks, `EXIT`/`Stop`, `ErrWrite`. A step is its `! step n
//! Name: … (localId N)` comment; `Move…` instructions are its motion; settings and pendant
//! texts take no time; any other statement is listed as not simulated.

use std::collections::HashMap;

use super::ir::{
    Grammar, Ins, IoKeys, Line, Op, Program, Raw, Settle, Val, X, parse_expr, point_name,
    step_title, writer_comment,
};

pub const GRAMMAR: Grammar = Grammar {
    levels: &[
        &[("OR", Op::Or), ("XOR", Op::Xor)],
        &[("AND", Op::And)],
        &[
            ("=", Op::Eq),
            ("<>", Op::Ne),
            ("<=", Op::Le),
            (">=", Op::Ge),
            ("<", Op::Lt),
            (">", Op::Gt),
        ],
        &[("+", Op::Add), ("-", Op::Sub)],
        &[("*", Op::Mul), ("/", Op::Div)],
    ],
    not_level: 2,
    not: "NOT",
    fold_case: true,
    trues: &["TRUE"],
    falses: &["FALSE"],
};

/// Instructions that only set up motion or show text: no time, nothing to simulate.
const SETTINGS: &[&str] = &[
    "CONFJ",
    "CONFL",
    "ACCSET",
    "VELSET",
    "SINGAREA",
    "TPWRITE",
    "TPERASE",
    "PATHACCLIM",
    "GRIPLOAD",
    "TOOLLOAD",
    "WOBJ",
];

struct Proc<'a> {
    params: Vec<String>,
    body: Vec<(Line, String)>,
    _m: std::marker::PhantomData<&'a ()>,
}

/// The statements of a text: a statement ends at its `;` (outside strings), a block keyword
/// line (`IF … THEN`, `ELSE`, `ENDIF`, `WHILE … DO`, …) stands alone; comments are their own.
fn statements(text: &str) -> Vec<(Line, String)> {
    let mut out = Vec::new();
    let mut acc = String::new();
    let mut first = 0;
    for (k, l) in text.lines().enumerate() {
        let line = k as Line + 1;
        let t = l.trim();
        if acc.is_empty() {
            if t.is_empty() {
                continue;
            }
            if t.starts_with('!') {
                out.push((line, t.to_owned()));
                continue;
            }
            first = line;
        } else {
            acc.push(' ');
        }
        // The code without its comment.
        let mut in_str = false;
        let mut code_end = t.len();
        for (i, c) in t.char_indices() {
            match c {
                '"' => in_str = !in_str,
                '!' if !in_str => {
                    code_end = i;
                    break;
                }
                _ => {}
            }
        }
        acc.push_str(t[..code_end].trim());
        let up = acc.to_ascii_uppercase();
        let block = up.ends_with(" THEN")
            || up.ends_with(" DO")
            || [
                "ELSE",
                "ENDIF",
                "ENDWHILE",
                "ENDFOR",
                "ENDTEST",
                "ENDPROC",
                "ENDMODULE",
                "ERROR",
                "BACKWARD",
                "UNDO",
            ]
            .contains(&up.as_str())
            || up.starts_with("MODULE ")
            || up.starts_with("PROC ")
            || up.starts_with("TEST ")
            || up.starts_with("CASE ")
            || up.starts_with("DEFAULT")
            || (up.ends_with(':') && !up.contains(' '));
        if acc.ends_with(';') || block {
            out.push((first, std::mem::take(&mut acc)));
        }
    }
    if !acc.is_empty() {
        out.push((first, acc));
    }
    out
}

enum Open {
    If {
        test: Option<usize>,
        to_end: Vec<usize>,
    },
    While {
        start: usize,
        test: usize,
    },
    For {
        start: usize,
        test: usize,
        var: String,
        step: X,
    },
    Test {
        sel: X,
        test: Option<usize>,
        to_end: Vec<usize>,
        cases: usize,
    },
    Call {
        returns: Vec<usize>,
    },
}

struct Reader<'a> {
    p: Program,
    io: &'a IoKeys,
    procs: HashMap<String, Proc<'a>>,
    vars: std::collections::HashSet<String>,
    /// Data of other types (`tooldata`, `robtarget`, …): what sets them is a setting.
    opaque: std::collections::HashSet<String>,
    open: Vec<Open>,
    labels: HashMap<String, usize>,
    gotos: Vec<(usize, String)>,
    depth: usize,
    /// The lines calls may still put in their places.
    inlined: super::ir::InlineBudget,
    /// In a step's own code (after its title comment).
    in_step: bool,
}

/// Reads module text `text`; the main routine is `main` (any case).
pub fn read(text: &str, io: &IoKeys) -> Program {
    let st = statements(text);
    let mut p = Program {
        fold_case: true,
        ..Program::default()
    };
    let mut procs = HashMap::new();
    let mut vars = std::collections::HashSet::new();
    let mut main: Option<(usize, usize)> = None;
    let mut i = 0;
    while i < st.len() {
        let up = st[i].1.to_ascii_uppercase();
        if let Some(head) = up.strip_prefix("PROC ") {
            let name = head.split('(').next().unwrap_or("").trim().to_owned();
            let params = st[i]
                .1
                .split_once('(')
                .and_then(|(_, r)| r.rsplit_once(')'))
                .map(|(ps, _)| {
                    ps.split(',')
                        .filter_map(|p| p.split_whitespace().last())
                        .map(|n| n.trim_start_matches('\\').to_ascii_uppercase())
                        .collect()
                })
                .unwrap_or_default();
            let start = i + 1;
            let mut j = start;
            while j < st.len() && !st[j].1.eq_ignore_ascii_case("ENDPROC") {
                j += 1;
            }
            if name == "MAIN" {
                main = Some((start, j));
            }
            procs.insert(
                name,
                Proc {
                    params,
                    body: st[start..j.min(st.len())].to_vec(),
                    _m: std::marker::PhantomData,
                },
            );
            i = j + 1;
            continue;
        }
        if let Some((name, v)) = data(&st[i].1) {
            vars.insert(name.clone());
            p.init.push((name, v));
        }
        i += 1;
    }
    let Some((a, b)) = main else {
        p.push(
            Ins::Unknown("no PROC main(): not a RAPID main module".into()),
            1,
        );
        p.push(Ins::End, 1);
        return p;
    };
    let mut r = Reader {
        p,
        io,
        procs,
        vars,
        opaque: opaque_data(text),
        open: Vec::new(),
        labels: HashMap::new(),
        gotos: Vec::new(),
        depth: 0,
        inlined: super::ir::InlineBudget::new(text.lines().count()),
        in_step: false,
    };
    let body = st[a..b.min(st.len())].to_vec();
    r.block(&body);
    r.p.declared = r.opaque.clone();
    r.p.declared.extend(r.vars.iter().cloned());
    r.p.undeclared_points();
    let end_line = st.get(b).map_or(1, |s| s.0);
    while let Some(o) = r.open.pop() {
        r.close(o, end_line);
    }
    let at = r.p.push(Ins::End, end_line);
    for (g, l) in std::mem::take(&mut r.gotos) {
        let to = r.labels.get(&l).copied().unwrap_or(at);
        r.p.patch(g, to);
    }
    r.p
}

/// The names a module declares with a type other than `num`, `dnum`, `bool` and `clock`.
fn opaque_data(text: &str) -> std::collections::HashSet<String> {
    statements(text)
        .into_iter()
        .filter_map(|(_, s)| {
            let mut w = s.split_whitespace();
            let mut kind = w.next()?.to_ascii_uppercase();
            if kind == "LOCAL" || kind == "TASK" {
                kind = w.next()?.to_ascii_uppercase();
            }
            if !["VAR", "PERS", "CONST"].contains(&kind.as_str()) {
                return None;
            }
            let ty = w.next()?.to_ascii_uppercase();
            if ["NUM", "DNUM", "BOOL", "CLOCK"].contains(&ty.as_str()) {
                return None;
            }
            let name = w
                .next()?
                .split([':', ';', '{'])
                .next()?
                .trim()
                .to_ascii_uppercase();
            Some(name)
        })
        .collect()
}

/// `VAR num x := 0;`, `PERS bool b := TRUE;`, `VAR num y;`: the name and its first value.
fn data(s: &str) -> Option<(String, Val)> {
    let words: Vec<&str> = s.split_whitespace().collect();
    let (kind, ty) = (
        words.first()?.to_ascii_uppercase(),
        words.get(1)?.to_ascii_uppercase(),
    );
    if !["VAR", "PERS", "CONST", "LOCAL"].contains(&kind.as_str()) {
        return None;
    }
    let (ty, rest_at) = if kind == "LOCAL" {
        (words.get(2)?.to_ascii_uppercase(), 3)
    } else {
        (ty, 2)
    };
    let rest = words.get(rest_at..)?.join(" ");
    let rest = rest.trim_end_matches(';');
    let (name, value) = match rest.split_once(":=") {
        Some((n, v)) => (n.trim(), Some(v.trim())),
        None => (rest.trim(), None),
    };
    if name.contains(['{', '[']) {
        return None;
    }
    let v = match ty.as_str() {
        "BOOL" => Val::Bool(value.is_some_and(|v| v.eq_ignore_ascii_case("TRUE"))),
        "NUM" | "DNUM" => Val::Num(value.and_then(|v| v.parse().ok()).unwrap_or(0.0)),
        "CLOCK" => Val::Num(0.0),
        _ => return None,
    };
    Some((name.to_ascii_uppercase(), v))
}

impl Reader<'_> {
    fn x(&self, raw: &Raw) -> Result<X, String> {
        Ok(match raw {
            Raw::Num(n) => X::Const(Val::Num(*n)),
            Raw::Bool(b) => X::Const(Val::Bool(*b)),
            Raw::Str(s) => X::Const(Val::Str(s.clone())),
            Raw::Name(n) => {
                let u = n.to_ascii_uppercase();
                if self.vars.contains(&u) {
                    X::Var(u)
                } else if self.io.ins.contains(&u) {
                    X::In(u, true)
                } else if self.io.outs.contains(&u) {
                    X::Out(u, true)
                } else {
                    X::Var(u)
                }
            }
            Raw::Call(f, args) => {
                let f = f.to_ascii_uppercase();
                match (f.as_str(), args.as_slice()) {
                    ("DINPUT" | "GINPUT", [Raw::Name(n)]) => X::In(n.to_ascii_uppercase(), true),
                    ("DOUTPUT" | "GOUTPUT", [Raw::Name(n)]) => X::Out(n.to_ascii_uppercase(), true),
                    ("CLKREAD", [Raw::Name(n)]) => X::Clock(n.to_ascii_uppercase()),
                    _ => return Err(format!("the function `{f}`")),
                }
            }
            Raw::Index(a, _) => return Err(format!("the array `{a}`")),
            Raw::Not(a) => X::Not(Box::new(self.x(a)?)),
            Raw::Neg(a) => X::Neg(Box::new(self.x(a)?)),
            Raw::Bin(op, a, b) => X::Bin(*op, Box::new(self.x(a)?), Box::new(self.x(b)?)),
        })
    }

    fn expr(&self, s: &str) -> Result<X, String> {
        self.x(&parse_expr(s, &GRAMMAR).map_err(|e| e.0)?)
    }

    /// A step's own code ends where the writer's structure goes on.
    fn end_step(&mut self, line: Line) {
        if self.in_step && self.depth == 0 {
            self.in_step = false;
            self.p.push(Ins::StepEnd, line);
        }
    }

    fn unknown(&mut self, text: &str, line: Line) {
        self.p.push(Ins::Unknown(text.trim().to_owned()), line);
    }

    fn close(&mut self, o: Open, line: Line) {
        match o {
            Open::If { test, to_end } => {
                let here = self.p.ins.len();
                if let Some(t) = test {
                    self.p.patch(t, here);
                }
                for j in to_end {
                    self.p.patch(j, here);
                }
            }
            Open::While { start, test } => {
                self.p.push(Ins::Jump(start), line);
                let end = self.p.ins.len();
                self.p.patch(test, end);
            }
            Open::For {
                start,
                test,
                var,
                step,
            } => {
                self.p.push(
                    Ins::Assign(
                        var.clone(),
                        X::Bin(Op::Add, Box::new(X::Var(var)), Box::new(step)),
                    ),
                    line,
                );
                self.p.push(Ins::Jump(start), line);
                let end = self.p.ins.len();
                self.p.patch(test, end);
            }
            Open::Test { test, to_end, .. } => {
                let here = self.p.ins.len();
                if let Some(t) = test {
                    self.p.patch(t, here);
                }
                for j in to_end {
                    self.p.patch(j, here);
                }
            }
            Open::Call { returns } => {
                let here = self.p.ins.len();
                for j in returns {
                    self.p.patch(j, here);
                }
            }
        }
    }

    fn block(&mut self, st: &[(Line, String)]) {
        for (line, s) in st {
            self.statement(s, *line);
        }
    }

    /// The arguments of an instruction (`SetDO do_x, 1;` → `do_x`, `1`), optional ones
    /// (`\InPos`, `\MaxTime:=2`) apart.
    fn args(rest: &str) -> (Vec<String>, HashMap<String, String>) {
        let mut plain = Vec::new();
        let mut opts = HashMap::new();
        let mut depth = 0i32;
        let mut in_str = false;
        let mut cur = String::new();
        let mut parts = Vec::new();
        for c in rest.chars() {
            match c {
                '"' => in_str = !in_str,
                '(' | '[' if !in_str => depth += 1,
                ')' | ']' if !in_str => depth -= 1,
                _ => {}
            }
            if !in_str && depth == 0 && (c == ',' || c == '\\') {
                parts.push(std::mem::take(&mut cur));
                if c == '\\' {
                    cur.push('\\');
                }
                continue;
            }
            cur.push(c);
        }
        parts.push(cur);
        for p in parts {
            let p = p.trim();
            if p.is_empty() {
                continue;
            }
            if let Some(o) = p.strip_prefix('\\') {
                let (k, v) = o.split_once(":=").unwrap_or((o, ""));
                opts.insert(k.trim().to_ascii_uppercase(), v.trim().to_owned());
            } else {
                plain.push(p.to_owned());
            }
        }
        (plain, opts)
    }

    fn statement(&mut self, s: &str, line: Line) {
        let up0 = s.to_ascii_uppercase();
        let marker = s
            .strip_prefix('!')
            .and_then(|c| writer_comment(c.trim()))
            .is_some();
        let block = up0.ends_with(" THEN")
            || up0.ends_with(" DO")
            || [
                "ELSE", "ENDIF", "ENDWHILE", "ENDFOR", "TEST ", "CASE ", "DEFAULT", "ENDTEST",
            ]
            .iter()
            .any(|k| up0.starts_with(k));
        if marker || block {
            self.end_step(line);
        }
        if let Some(comment) = s.strip_prefix('!') {
            let comment = comment.trim();
            if let Some(title) = comment.strip_prefix("step ")
                && let Some((id, name)) = step_title(title)
            {
                self.end_step(line);
                self.p.push(Ins::Step { local_id: id, name }, line);
                self.in_step = true;
            } else if let Some(ins) = writer_comment(comment)
                && (matches!(ins, Ins::Branch { .. }) || self.depth == 0)
            {
                self.p.push(ins, line);
            }
            return;
        }
        let body = s.trim_end_matches(';').trim();
        let up = body.to_ascii_uppercase();
        let first = up
            .split(|c: char| c.is_whitespace() || c == '(' || c == ';' || c == '\\')
            .next()
            .unwrap_or("")
            .to_owned();
        let rest = body[first.len().min(body.len())..].trim();
        match first.as_str() {
            "IF" if up.ends_with(" THEN") => {
                let cond = &rest[..rest.len() - 4];
                let test = match self.expr(cond.trim()) {
                    Ok(x) => Some(self.p.push(Ins::JumpIfNot(x, 0), line)),
                    Err(_) => {
                        self.unknown(s, line);
                        None
                    }
                };
                self.open.push(Open::If {
                    test,
                    to_end: Vec::new(),
                });
            }
            "IF" => {
                // The one-line IF: `IF c stmt;`. The condition ends where its parentheses
                // and words allow a statement to begin: tried from the longest.
                let words: Vec<&str> = rest.split(' ').collect();
                for k in (1..words.len()).rev() {
                    let (c, st) = (words[..k].join(" "), words[k..].join(" "));
                    if let Ok(x) = self.expr(&c) {
                        let t = self.p.push(Ins::JumpIfNot(x, 0), line);
                        self.statement(&format!("{st};"), line);
                        let here = self.p.ins.len();
                        self.p.patch(t, here);
                        return;
                    }
                }
                self.unknown(s, line);
            }
            "ELSEIF" | "ELSE" => {
                let Some(Open::If { test, to_end }) = self.open.last_mut() else {
                    return self.unknown(s, line);
                };
                let prev = test.take();
                let j = self.p.ins.len();
                to_end.push(j);
                self.p.push(Ins::Jump(0), line);
                let here = self.p.ins.len();
                if let Some(t) = prev {
                    self.p.patch(t, here);
                }
                if first == "ELSEIF" {
                    let cond = rest
                        .trim_end_matches("THEN")
                        .trim_end_matches("then")
                        .trim();
                    match self.expr(cond) {
                        Ok(x) => {
                            let t = self.p.push(Ins::JumpIfNot(x, 0), line);
                            if let Some(Open::If { test, .. }) = self.open.last_mut() {
                                *test = Some(t);
                            }
                        }
                        Err(_) => self.unknown(s, line),
                    }
                }
            }
            "ENDIF" | "ENDWHILE" | "ENDFOR" | "ENDTEST" => {
                let fits = matches!(
                    (first.as_str(), self.open.last()),
                    ("ENDIF", Some(Open::If { .. }))
                        | ("ENDWHILE", Some(Open::While { .. }))
                        | ("ENDFOR", Some(Open::For { .. }))
                        | ("ENDTEST", Some(Open::Test { .. }))
                );
                if fits && let Some(o) = self.open.pop() {
                    self.close(o, line);
                } else {
                    self.unknown(s, line);
                }
            }
            "WHILE" => {
                let cond = rest.strip_suffix("DO").or_else(|| rest.strip_suffix("do"));
                match cond.map(|c| self.expr(c.trim())) {
                    Some(Ok(x)) => {
                        let start = self.p.ins.len();
                        let test = self.p.push(Ins::JumpIfNot(x, 0), line);
                        self.open.push(Open::While { start, test });
                    }
                    _ => {
                        // Not read: listed, and the loop not run (never a loop without end).
                        self.unknown(s, line);
                        let start = self.p.ins.len();
                        let test = self
                            .p
                            .push(Ins::JumpIfNot(X::Const(Val::Bool(false)), 0), line);
                        self.open.push(Open::While { start, test });
                    }
                }
            }
            "FOR" => {
                // FOR i FROM a TO b [STEP s] DO
                let parsed = (|| {
                    let u = rest.to_ascii_uppercase();
                    let from = u.find(" FROM ")?;
                    let to = u.find(" TO ")?;
                    let do_ = u.rfind(" DO")?;
                    let (till_end, step) = match u.find(" STEP ") {
                        Some(k) => (k, &rest[k + 6..do_]),
                        None => (do_, "1"),
                    };
                    Some((
                        rest[..from].trim().to_ascii_uppercase(),
                        self.expr(&rest[from + 6..to]).ok()?,
                        self.expr(&rest[to + 4..till_end]).ok()?,
                        self.expr(step).ok()?,
                        step.trim().starts_with('-'),
                    ))
                })();
                let Some((var, from, till, step, down)) = parsed else {
                    self.unknown(s, line);
                    let start = self.p.ins.len();
                    let test = self
                        .p
                        .push(Ins::JumpIfNot(X::Const(Val::Bool(false)), 0), line);
                    self.open.push(Open::While { start, test });
                    return;
                };
                self.vars.insert(var.clone());
                self.p.push(Ins::Assign(var.clone(), from), line);
                let start = self.p.ins.len();
                let op = if down { Op::Ge } else { Op::Le };
                let test = self.p.push(
                    Ins::JumpIfNot(X::Bin(op, Box::new(X::Var(var.clone())), Box::new(till)), 0),
                    line,
                );
                self.open.push(Open::For {
                    start,
                    test,
                    var,
                    step,
                });
            }
            "TEST" => {
                let sel = self.expr(rest).unwrap_or(X::Const(Val::Num(f64::NAN)));
                self.open.push(Open::Test {
                    sel,
                    test: None,
                    to_end: Vec::new(),
                    cases: 0,
                });
            }
            "CASE" | "DEFAULT" => {
                let values: Vec<X> = rest
                    .trim_end_matches(':')
                    .split(',')
                    .filter_map(|v| self.expr(v.trim()).ok())
                    .collect();
                let Some(Open::Test {
                    sel,
                    test,
                    to_end,
                    cases,
                }) = self.open.last_mut()
                else {
                    return self.unknown(s, line);
                };
                let sel = sel.clone();
                let prev = test.take();
                if *cases > 0 {
                    let j = self.p.ins.len();
                    to_end.push(j);
                    self.p.push(Ins::Jump(0), line);
                }
                if let Some(Open::Test { cases, .. }) = self.open.last_mut() {
                    *cases += 1;
                }
                let here = self.p.ins.len();
                if let Some(t) = prev {
                    self.p.patch(t, here);
                }
                if first == "CASE" {
                    let cond = values
                        .into_iter()
                        .map(|v| X::Bin(Op::Eq, Box::new(sel.clone()), Box::new(v)))
                        .reduce(|a, b| X::Bin(Op::Or, Box::new(a), Box::new(b)))
                        .unwrap_or(X::Const(Val::Bool(false)));
                    let t = self.p.push(Ins::JumpIfNot(cond, 0), line);
                    if let Some(Open::Test { test, .. }) = self.open.last_mut() {
                        *test = Some(t);
                    }
                }
            }
            "GOTO" => {
                let j = self.p.push(Ins::Jump(0), line);
                self.gotos.push((j, rest.to_ascii_uppercase()));
            }
            "EXIT" | "STOP" | "EXITCYCLE" => {
                self.p.push(Ins::Halt, line);
            }
            "RETURN" => {
                let j = self.p.push(Ins::Jump(0), line);
                match self.open.iter_mut().rev().find_map(|o| match o {
                    Open::Call { returns } => Some(returns),
                    _ => None,
                }) {
                    Some(r) => r.push(j),
                    None => self.p.ins[j].0 = Ins::End,
                }
            }
            "WAITUNTIL" => {
                let (plain, opts) = Self::args(rest);
                let settle = if opts.contains_key("INPOS") {
                    Settle::Yes
                } else {
                    Settle::No
                };
                let max = opts
                    .get("MAXTIME")
                    .and_then(|v| v.parse::<f64>().ok())
                    .map(|t| (t, opts.get("TIMEFLAG").map(|f| f.to_ascii_uppercase())));
                let poll = opts
                    .get("POLLRATE")
                    .and_then(|v| v.parse::<f64>().ok())
                    .filter(|p| *p > 0.0);
                match plain.first().map(|c| self.expr(c)) {
                    Some(Ok(cond)) => {
                        self.p.push(
                            Ins::Wait {
                                cond,
                                settle,
                                max,
                                poll,
                            },
                            line,
                        );
                    }
                    _ => self.unknown(s, line),
                }
            }
            "WAITDI" | "WAITDO" => {
                let (plain, opts) = Self::args(rest);
                let max = opts
                    .get("MAXTIME")
                    .and_then(|v| v.parse::<f64>().ok())
                    .map(|t| (t, opts.get("TIMEFLAG").map(|f| f.to_ascii_uppercase())));
                match (plain.first(), plain.get(1).map(|v| self.expr(v))) {
                    (Some(sig), Some(Ok(v))) => {
                        let k = sig.to_ascii_uppercase();
                        let read = if first == "WAITDI" {
                            X::In(k, true)
                        } else {
                            X::Out(k, true)
                        };
                        self.p.push(
                            Ins::Wait {
                                cond: X::Bin(Op::Eq, Box::new(read), Box::new(v)),
                                settle: Settle::No,
                                max,
                                poll: None,
                            },
                            line,
                        );
                    }
                    _ => self.unknown(s, line),
                }
            }
            "WAITTIME" => {
                let (plain, opts) = Self::args(rest);
                let settle = if opts.contains_key("INPOS") {
                    Settle::Yes
                } else {
                    Settle::No
                };
                match plain.first().map(|t| self.expr(t)) {
                    Some(Ok(x)) => {
                        self.p.push(Ins::Sleep(x, settle), line);
                    }
                    _ => self.unknown(s, line),
                }
            }
            "SETDO" | "SETGO" => {
                let (plain, _) = Self::args(rest);
                match (plain.first(), plain.get(1).map(|v| self.expr(v))) {
                    (Some(sig), Some(Ok(v))) => {
                        self.p.push(Ins::SetOut(sig.to_ascii_uppercase(), v), line);
                    }
                    _ => self.unknown(s, line),
                }
            }
            "SET" | "RESET" => {
                let v = X::Const(Val::Num(if first == "SET" { 1.0 } else { 0.0 }));
                self.p.push(Ins::SetOut(rest.to_ascii_uppercase(), v), line);
            }
            "CLKRESET" => {
                self.p
                    .push(Ins::ClockReset(rest.to_ascii_uppercase()), line);
            }
            "CLKSTART" => {
                self.p
                    .push(Ins::ClockStart(rest.to_ascii_uppercase()), line);
            }
            "CLKSTOP" => {
                self.p.push(Ins::ClockStop(rest.to_ascii_uppercase()), line);
            }
            // The writer's message of a wait that lasts (`TPWrite "… waits for …"`), taken
            // away by `TPErase`; any other line on the FlexPendant is a setting.
            "TPWRITE" if rest.contains("waits for") => {
                let (plain, _) = Self::args(rest);
                let text = plain.first().map_or("", |p| p.trim_matches('"')).to_owned();
                self.p.push(Ins::Show(text), line);
            }
            "TPERASE" => {
                self.p.push(Ins::Clear, line);
            }
            "ERRWRITE" => {
                let (plain, _) = Self::args(rest);
                let text: Vec<&str> = plain.iter().map(|p| p.trim_matches('"')).collect();
                self.p.push(Ins::Message(text.join(": ")), line);
            }
            "VAR" | "PERS" | "CONST" | "LOCAL" => {
                if let Some((name, v)) = data(body) {
                    self.vars.insert(name.clone());
                    self.p.init.push((name, v));
                }
            }
            _ if first.starts_with("MOVE") || first.starts_with("SEARCH") => {
                // `MoveL pTake, v200, fine, tool0;`, `MoveC pVia, pTo, …`; a search's
                // arguments are others.
                let n = match first.as_str() {
                    f if f.starts_with("SEARCH") => 0,
                    f if f.starts_with("MOVEC") => 2,
                    _ => 1,
                };
                let (plain, _) = Self::args(rest);
                let points = plain.iter().take(n).filter_map(|a| point_name(a)).collect();
                self.p.push(Ins::Motion(points), line);
            }
            _ if SETTINGS.contains(&first.as_str()) => {}
            _ if up.ends_with(':') && !up.contains(' ') => {
                self.labels
                    .insert(up.trim_end_matches(':').to_owned(), self.p.ins.len());
            }
            _ => {
                if let Some((lhs, rhs)) = body.split_once(":=") {
                    let l = lhs.trim().to_ascii_uppercase();
                    if self.opaque.contains(&l) {
                        return;
                    }
                    if l.contains(['.', '{', '[']) {
                        return self.unknown(s, line);
                    }
                    match self.expr(rhs.trim()) {
                        Ok(x) => {
                            self.vars.insert(l.clone());
                            self.p.push(Ins::Assign(l, x), line);
                        }
                        Err(_) => self.unknown(s, line),
                    }
                    return;
                }
                // A call of a PROC of the module.
                if self.procs.contains_key(&first) && self.depth < 8 {
                    let (plain, _) = Self::args(rest);
                    // Refused before the body is copied.
                    if let Err(ins) = self.inlined.take(self.procs[&first].body.len(), s) {
                        self.p.push(ins, line);
                        return;
                    }
                    let (params, body) = {
                        let p = &self.procs[&first];
                        (p.params.clone(), p.body.clone())
                    };
                    for (p, a) in params.iter().zip(&plain) {
                        if let Ok(x) = self.expr(a) {
                            self.vars.insert(p.clone());
                            self.p.push(Ins::Assign(p.clone(), x), line);
                        }
                    }
                    self.depth += 1;
                    let mark = self.open.len();
                    self.open.push(Open::Call {
                        returns: Vec::new(),
                    });
                    self.block(&body);
                    while self.open.len() > mark {
                        if let Some(o) = self.open.pop() {
                            self.close(o, line);
                        }
                    }
                    self.depth -= 1;
                    return;
                }
                self.unknown(s, line);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_module_with_waits_outputs_and_a_proc() {
        let text = "MODULE M\n  VAR num n := 0;\n  PROC GoHome()\n    MoveAbsJ [[0,0,0,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v500, fine, tool0;\n  ENDPROC\n  PROC main()\n    VAR bool late := FALSE;\n    ! step 1 Take: Move L @ R (localId 7)\n    MoveL pTake, v200, fine, tool0;\n    WaitUntil \\InPos, DInput(di_A) = 1 \\MaxTime:=10 \\TimeFlag:=late \\PollRate:=0.04;\n    IF late THEN\n      TPWrite \"x\";\n    ELSEIF n = 2 THEN\n      GoHome;\n    ELSE\n      SetDO do_B, 1;\n    ENDIF\n    IF n = 1 n := 2;\n    Foo 3;\n  ENDPROC\nENDMODULE\n";
        let p = read(text, &IoKeys::default());
        let kinds: Vec<String> = p
            .ins
            .iter()
            .map(|(i, _)| {
                format!("{i:?}")
                    .split(['(', ' '])
                    .next()
                    .unwrap()
                    .to_owned()
            })
            .collect();
        assert_eq!(
            kinds,
            [
                "Step",
                "Motion",
                "Wait",
                "StepEnd",
                "JumpIfNot",
                "Jump",
                "JumpIfNot",
                "Motion",
                "Jump",
                "SetOut",
                "JumpIfNot",
                "Assign",
                "Unknown",
                "End"
            ],
            "{:#?}",
            p.ins
        );
        assert!(
            matches!(&p.ins[2].0, Ins::Wait { settle: Settle::Yes, max: Some((t, Some(f))), .. } if *t == 10.0 && f == "LATE")
        );
        assert_eq!(p.unknown[0].0, "Foo 3;");
    }
}
