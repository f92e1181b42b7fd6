//! Reads a KRL program (`.src` with its `.dat`) into [`Program`]: the main program between
//! its `DEF` and `END`, each call of a routine the `.src` defines after it put in its place
//! (its `IN` parameters set first), `IF`/`ELSE`, `LOOP`/`EXIT`, `WHILE`, `REPEAT`/`UNTIL`,
//! `FOR`, `SWITCH`/`CASE`, `GOTO` and labels, `WAIT FOR`, `WAIT SEC`, `HALT`, `$IN`/`$OUT`
//! and the `.dat`'s `SIGNAL`s, `$TIMER`/`$TIMER_STOP`, and the `.dat`'s `BOOL`, `INT` and
//! `REAL` variables (KUKA System Software 8.x, Programming Manual for System Integrators).
//! A step is its `;FOLD n Name: … (localId N)`; motions (`PTP`, `LIN`, `CIRC` and their
//! spline and relative forms) are its motion; settings (`$VEL`, `BAS`, `PDAT_ACT`, …) and
//! messages take no time; any other statement is listed as not simulated.

use std::collections::HashMap;

use super::ir::{
    Grammar, Ins, Line, Op, Program, Raw, Settle, Val, X, parse_expr, point_name, step_title,
    writer_comment,
};

pub const GRAMMAR: Grammar = Grammar {
    levels: &[
        &[
            ("==", Op::Eq),
            ("<>", Op::Ne),
            ("<=", Op::Le),
            (">=", Op::Ge),
            ("<", Op::Lt),
            (">", Op::Gt),
        ],
        &[("OR", Op::Or)],
        &[("EXOR", Op::Xor)],
        &[("AND", Op::And)],
        &[("+", Op::Add), ("-", Op::Sub)],
        &[("*", Op::Mul), ("/", Op::Div)],
    ],
    not_level: 6,
    not: "NOT",
    fold_case: true,
    trues: &["TRUE"],
    falses: &["FALSE"],
};

const MOTIONS: &[&str] = &[
    "PTP", "LIN", "CIRC", "SPTP", "SLIN", "SCIRC", "PTP_REL", "LIN_REL", "CIRC_REL", "SPTP_REL",
    "SLIN_REL", "SPL", "SLIN_REL",
];

/// `XHOME`, `XHOME1` …: the home positions the KSS declares in `$config.dat`.
fn is_home(name: &str) -> bool {
    name.strip_prefix("XHOME")
        .is_some_and(|n| n.bytes().all(|b| b.is_ascii_digit()))
}

/// A `.dat`'s `SIGNAL` (bits, least significant first) by upper-cased name.
type Signals = HashMap<String, Vec<String>>;

/// The code of a line, without its `;` comment (outside strings).
fn code(line: &str) -> &str {
    let mut in_str = false;
    for (i, c) in line.char_indices() {
        match c {
            '"' => in_str = !in_str,
            ';' if !in_str => return line[..i].trim(),
            _ => {}
        }
    }
    line.trim()
}

/// `$IN[3]` → (`$IN`, 3).
fn io(text: &str) -> Option<(String, u32)> {
    let (head, rest) = text.split_once('[')?;
    let n = rest.strip_suffix(']')?.trim().parse().ok()?;
    Some((head.trim().to_ascii_uppercase(), n))
}

fn read_dat(dat: &str, p: &mut Program) -> Signals {
    let mut signals = Signals::new();
    for l in dat.lines() {
        let c = code(l);
        let words: Vec<&str> = c.split_whitespace().collect();
        let words: Vec<&str> = if words
            .first()
            .is_some_and(|w| w.eq_ignore_ascii_case("GLOBAL"))
        {
            words[1..].to_vec()
        } else {
            words
        };
        match words.as_slice() {
            [s, name, first, rest @ ..] if s.eq_ignore_ascii_case("SIGNAL") => {
                let Some((kind, a)) = io(first) else { continue };
                let b = match rest {
                    [to, last] if to.eq_ignore_ascii_case("TO") => io(last).map_or(a, |x| x.1),
                    _ => a,
                };
                if b < a || b - a > 63 {
                    continue;
                }
                signals.insert(
                    name.to_ascii_uppercase(),
                    (a..=b).map(|k| format!("{kind}[{k}]")).collect(),
                );
            }
            [d, ty, ..] if d.eq_ignore_ascii_case("DECL") => {
                let ty = ty.to_ascii_uppercase();
                let rest = c[c.to_ascii_uppercase().find(&ty).unwrap_or(0) + ty.len()..].trim();
                let (name, value) = match rest.split_once('=') {
                    Some((n, v)) => (n.trim(), Some(v.trim())),
                    None => (rest, None),
                };
                if name.contains(['[', '{', ' ', ',']) {
                    continue;
                }
                let v = match (ty.as_str(), value) {
                    ("BOOL", v) => Val::Bool(v.is_some_and(|v| v.eq_ignore_ascii_case("TRUE"))),
                    ("INT" | "REAL", v) => Val::Num(v.and_then(|v| v.parse().ok()).unwrap_or(0.0)),
                    _ => continue,
                };
                p.init.push((name.to_ascii_uppercase(), v));
            }
            _ => {}
        }
    }
    signals
}

/// The names a text declares with a type other than `BOOL`, `INT` and `REAL`.
fn opaque_decls(text: &str) -> impl Iterator<Item = String> + '_ {
    text.lines().filter_map(|l| {
        let c = code(l);
        let mut w = c.split_whitespace();
        let mut first = w.next()?.to_ascii_uppercase();
        if first == "GLOBAL" {
            first = w.next()?.to_ascii_uppercase();
        }
        if first != "DECL" {
            return None;
        }
        let ty = w.next()?.to_ascii_uppercase();
        if ["BOOL", "INT", "REAL"].contains(&ty.as_str()) {
            return None;
        }
        let name = w
            .next()?
            .split(['=', '[', ','].as_ref())
            .next()?
            .trim()
            .to_ascii_uppercase();
        Some(name)
    })
}

struct Routine<'a> {
    params: Vec<String>,
    body: Vec<(Line, &'a str)>,
}

/// The routines a `.src` defines after its main program, by upper-cased name.
fn routines<'a>(lines: &[(Line, &'a str)]) -> HashMap<String, Routine<'a>> {
    let mut out = HashMap::new();
    let mut i = 0;
    while i < lines.len() {
        let c = code(lines[i].1);
        let up = c.to_ascii_uppercase();
        let head = up
            .strip_prefix("GLOBAL ")
            .unwrap_or(&up)
            .trim_start()
            .to_owned();
        if let Some(sig) = head
            .strip_prefix("DEF ")
            .or_else(|| head.strip_prefix("DEFFCT "))
        {
            let name = sig.split('(').next().unwrap_or("").trim().to_owned();
            let params = c
                .split_once('(')
                .and_then(|(_, r)| r.rsplit_once(')'))
                .map(|(ps, _)| {
                    ps.split(',')
                        .filter_map(|p| {
                            let n = p.split(':').next()?.trim();
                            (!n.is_empty()).then(|| n.to_ascii_uppercase())
                        })
                        .collect()
                })
                .unwrap_or_default();
            let start = i + 1;
            let mut j = start;
            while j < lines.len() {
                let u = code(lines[j].1).to_ascii_uppercase();
                if u == "END" || u == "ENDFCT" {
                    break;
                }
                j += 1;
            }
            out.insert(
                name,
                Routine {
                    params,
                    body: lines[start..j.min(lines.len())].to_vec(),
                },
            );
            i = j;
        }
        i += 1;
    }
    out
}

enum Open {
    If {
        test: usize,
        to_end: Vec<usize>,
    },
    Loop {
        start: usize,
        exits: Vec<usize>,
    },
    While {
        start: usize,
        test: usize,
        exits: Vec<usize>,
    },
    Repeat {
        start: usize,
        exits: Vec<usize>,
    },
    For {
        start: usize,
        test: usize,
        var: String,
        step: X,
        exits: Vec<usize>,
    },
    Switch {
        sel: X,
        test: Option<usize>,
        to_end: Vec<usize>,
    },
    /// An inlined routine: its `RETURN`s.
    Call {
        returns: Vec<usize>,
    },
}

struct Reader<'a> {
    p: Program,
    io: &'a super::ir::IoKeys,
    signals: Signals,
    routines: HashMap<String, Routine<'a>>,
    open: Vec<Open>,
    labels: HashMap<String, usize>,
    gotos: Vec<(usize, String)>,
    depth: usize,
    /// The lines calls may still put in their places.
    inlined: super::ir::InlineBudget,
    /// The message text last set (`skp_msg.Msg_Txt[] = "…"`).
    msg: Option<String>,
    /// FOLDs open, and the depth of the step's FOLD while in one.
    folds: usize,
    step_fold: Option<usize>,
    /// Variables of other types (`FRAME`, `E6POS`, structures): what sets them is a setting.
    opaque: std::collections::HashSet<String>,
}

/// Reads a KRL program: `src` the main file, `dat` its data list.
pub fn read(src: &str, dat: &str, io: &super::ir::IoKeys) -> Program {
    let mut p = Program {
        fold_case: true,
        ..Program::default()
    };
    let signals = read_dat(dat, &mut p);
    let lines: Vec<(Line, &str)> = src
        .lines()
        .enumerate()
        .map(|(k, l)| (k as Line + 1, l))
        .collect();
    let is_def = |l: &str| {
        let u = code(l).to_ascii_uppercase();
        u.starts_with("DEF ") || u.starts_with("GLOBAL DEF ")
    };
    let Some(main) = lines.iter().position(|(_, l)| is_def(l)) else {
        p.push(Ins::Unknown("no DEF: not a KRL program".into()), 1);
        p.push(Ins::End, 1);
        return p;
    };
    let end = main
        + lines[main..]
            .iter()
            .position(|(_, l)| code(l).eq_ignore_ascii_case("END"))
            .unwrap_or(lines.len() - main);
    let mut r = Reader {
        p,
        io,
        signals,
        routines: routines(&lines[end.min(lines.len())..]),
        open: Vec::new(),
        labels: HashMap::new(),
        gotos: Vec::new(),
        depth: 0,
        inlined: super::ir::InlineBudget::new(lines.len()),
        msg: None,
        folds: 0,
        step_fold: None,
        opaque: opaque_decls(src).chain(opaque_decls(dat)).collect(),
    };
    let body: Vec<(Line, &str)> = lines[main + 1..end.min(lines.len())].to_vec();
    r.block(&body);
    r.p.declared = r.opaque.clone();
    r.p.declared.extend(r.p.init.iter().map(|(n, _)| n.clone()));
    r.p.undeclared_points();
    let end_line = lines.get(end).map_or(1, |l| l.0);
    // Blocks left open: the program's END closes them as far as jumps go.
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

impl Reader<'_> {
    fn x(&self, raw: &Raw) -> Result<X, String> {
        Ok(match raw {
            Raw::Num(n) => X::Const(Val::Num(*n)),
            Raw::Bool(b) => X::Const(Val::Bool(*b)),
            Raw::Str(s) => X::Const(Val::Str(s.clone())),
            Raw::Name(n) => {
                let u = n.to_ascii_uppercase();
                if u.starts_with('$') && !self.io.ins.contains(&u) && !self.io.outs.contains(&u) {
                    return Err(format!("the system variable `{n}`"));
                }
                match self.signals.get(&u) {
                    Some(bits) if bits.len() == 1 => {
                        if bits[0].starts_with("$OUT[") {
                            X::Out(bits[0].clone(), false)
                        } else {
                            X::In(bits[0].clone(), false)
                        }
                    }
                    Some(bits) => X::Group(bits.clone()),
                    None if self.io.outs.contains(&u) => X::Out(u, false),
                    None if self.io.ins.contains(&u) => X::In(u, false),
                    None => X::Var(u),
                }
            }
            Raw::Index(a, i) => {
                let Raw::Num(n) = **i else {
                    return Err(format!("{a}[…] with a computed index"));
                };
                let k = format!("{}[{}]", a.to_ascii_uppercase(), n as u32);
                match a.to_ascii_uppercase().as_str() {
                    "$OUT" => X::Out(k, false),
                    _ if self.io.outs.contains(&k) => X::Out(k, false),
                    "$TIMER" => X::Timer(n as u32),
                    _ if a.starts_with('$') => X::In(k, false),
                    _ => return Err(format!("the array `{a}`")),
                }
            }
            Raw::Call(f, _) => return Err(format!("the function `{f}`")),
            Raw::Not(a) => X::Not(Box::new(self.x(a)?)),
            Raw::Neg(a) => X::Neg(Box::new(self.x(a)?)),
            Raw::Bin(op, a, b) => X::Bin(*op, Box::new(self.x(a)?), Box::new(self.x(b)?)),
        })
    }

    fn expr(&self, s: &str) -> Result<X, String> {
        let raw = parse_expr(s, &GRAMMAR).map_err(|e| e.0)?;
        self.x(&raw)
    }

    fn unknown(&mut self, text: &str, line: Line) {
        self.p.push(Ins::Unknown(text.trim().to_owned()), line);
    }

    fn close(&mut self, o: Open, line: Line) {
        let here = self.p.ins.len();
        match o {
            Open::If { test, to_end } => {
                if test != usize::MAX {
                    self.p.patch(test, here);
                }
                for j in to_end {
                    self.p.patch(j, here);
                }
            }
            Open::Loop { start, exits } => {
                self.p.push(Ins::Jump(start), line);
                let end = self.p.ins.len();
                for j in exits {
                    self.p.patch(j, end);
                }
            }
            Open::While { start, test, exits } => {
                self.p.push(Ins::Jump(start), line);
                let end = self.p.ins.len();
                self.p.patch(test, end);
                for j in exits {
                    self.p.patch(j, end);
                }
            }
            Open::For {
                start,
                test,
                var,
                step,
                exits,
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
                for j in exits {
                    self.p.patch(j, end);
                }
            }
            Open::Repeat { exits, .. } => {
                let end = self.p.ins.len();
                for j in exits {
                    self.p.patch(j, end);
                }
            }
            Open::Switch { test, to_end, .. } => {
                if let Some(t) = test {
                    self.p.patch(t, here);
                }
                for j in to_end {
                    self.p.patch(j, here);
                }
            }
            Open::Call { returns } => {
                for j in returns {
                    self.p.patch(j, here);
                }
            }
        }
    }

    fn block(&mut self, lines: &[(Line, &str)]) {
        let mut i = 0;
        while i < lines.len() {
            let (line, raw) = lines[i];
            i += 1;
            let t = raw.trim();
            if let Some(title) = t.strip_prefix(";FOLD ") {
                self.folds += 1;
                if let Some((id, name)) = step_title(title.trim()) {
                    if self.step_fold.is_some() {
                        self.p.push(Ins::StepEnd, line);
                    }
                    self.step_fold = Some(self.folds);
                    self.p.push(Ins::Step { local_id: id, name }, line);
                }
                continue;
            }
            if t.to_ascii_uppercase().starts_with(";ENDFOLD") {
                if self.step_fold == Some(self.folds) {
                    self.step_fold = None;
                    self.p.push(Ins::StepEnd, line);
                }
                self.folds = self.folds.saturating_sub(1);
                continue;
            }
            if let Some(comment) = t.strip_prefix(';') {
                let comment = comment.trim();
                if let Some(ins) = writer_comment(comment)
                    && (matches!(ins, Ins::Branch { .. }) || self.depth == 0)
                {
                    self.p.push(ins, line);
                }
                continue;
            }
            let c = code(t);
            if c.is_empty() || c.starts_with('&') {
                continue;
            }
            self.statement(c, line);
        }
    }

    fn statement(&mut self, c: &str, line: Line) {
        let up = c.to_ascii_uppercase();
        let first = up
            .split(|ch: char| ch.is_whitespace() || ch == '(' || ch == '=')
            .next()
            .unwrap_or("");
        match first {
            "IF" => {
                let cond = up
                    .strip_suffix("THEN")
                    .map(|_| c[2..c.len() - 4].trim())
                    .unwrap_or(c[2..].trim());
                match self.expr(cond) {
                    Ok(x) => {
                        let test = self.p.push(Ins::JumpIfNot(x, 0), line);
                        self.open.push(Open::If {
                            test,
                            to_end: Vec::new(),
                        });
                    }
                    Err(_) => {
                        self.unknown(c, line);
                        // Both ways cannot be told apart: the THEN part runs.
                        self.open.push(Open::If {
                            test: usize::MAX,
                            to_end: Vec::new(),
                        });
                    }
                }
            }
            "ELSE" => {
                if let Some(Open::If { test, to_end }) = self.open.last_mut() {
                    let t = *test;
                    let j = self.p.ins.len();
                    to_end.push(j);
                    self.p.push(Ins::Jump(0), line);
                    let here = self.p.ins.len();
                    if t != usize::MAX {
                        self.p.patch(t, here);
                    }
                    if let Some(Open::If { test, .. }) = self.open.last_mut() {
                        *test = usize::MAX;
                    }
                } else {
                    self.unknown(c, line);
                }
            }
            "ENDIF" | "ENDLOOP" | "ENDWHILE" | "ENDFOR" | "ENDSWITCH" => {
                let want = |o: &Open| {
                    matches!(
                        (first, o),
                        ("ENDIF", Open::If { .. })
                            | ("ENDLOOP", Open::Loop { .. })
                            | ("ENDWHILE", Open::While { .. })
                            | ("ENDFOR", Open::For { .. })
                            | ("ENDSWITCH", Open::Switch { .. })
                    )
                };
                if self.open.last().is_some_and(want) {
                    let o = self.open.pop().unwrap_or(Open::Call { returns: vec![] });
                    self.close(o, line);
                } else {
                    self.unknown(c, line);
                }
            }
            "LOOP" => {
                let start = self.p.ins.len();
                self.open.push(Open::Loop {
                    start,
                    exits: Vec::new(),
                });
            }
            "WHILE" => match self.expr(c[5..].trim()) {
                Ok(x) => {
                    let start = self.p.ins.len();
                    let test = self.p.push(Ins::JumpIfNot(x, 0), line);
                    self.open.push(Open::While {
                        start,
                        test,
                        exits: Vec::new(),
                    });
                }
                Err(_) => {
                    // Not read: listed, and the loop not run (never a loop without end).
                    self.unknown(c, line);
                    let start = self.p.ins.len();
                    let test = self
                        .p
                        .push(Ins::JumpIfNot(X::Const(Val::Bool(false)), 0), line);
                    self.open.push(Open::While {
                        start,
                        test,
                        exits: Vec::new(),
                    });
                }
            },
            "REPEAT" => {
                let start = self.p.ins.len();
                self.open.push(Open::Repeat {
                    start,
                    exits: Vec::new(),
                });
            }
            "UNTIL" => {
                if let Some(Open::Repeat { start, .. }) = self.open.last() {
                    let start = *start;
                    let x = self
                        .expr(c[5..].trim())
                        .unwrap_or(X::Const(Val::Bool(true)));
                    self.p.push(Ins::JumpIfNot(x, start), line);
                    let o = self.open.pop().unwrap_or(Open::Call { returns: vec![] });
                    self.close(o, line);
                } else {
                    self.unknown(c, line);
                }
            }
            "FOR" => {
                // FOR i = a TO b [STEP s]
                let rest = c[3..].trim();
                let parsed = (|| {
                    let (var, rest) = rest.split_once('=')?;
                    let up = rest.to_ascii_uppercase();
                    let to = up.find(" TO ")?;
                    let (from, rest) = (rest[..to].trim(), rest[to + 4..].trim());
                    let up = rest.to_ascii_uppercase();
                    let (till, step) = match up.find(" STEP ") {
                        Some(s) => (rest[..s].trim(), rest[s + 6..].trim()),
                        None => (rest, "1"),
                    };
                    Some((
                        var.trim().to_ascii_uppercase(),
                        self.expr(from).ok()?,
                        self.expr(till).ok()?,
                        self.expr(step).ok()?,
                        step.trim().starts_with('-'),
                    ))
                })();
                match parsed {
                    Some((var, from, till, step, down)) => {
                        self.p.push(Ins::Assign(var.clone(), from), line);
                        let start = self.p.ins.len();
                        let op = if down { Op::Ge } else { Op::Le };
                        let test = self.p.push(
                            Ins::JumpIfNot(
                                X::Bin(op, Box::new(X::Var(var.clone())), Box::new(till)),
                                0,
                            ),
                            line,
                        );
                        self.open.push(Open::For {
                            start,
                            test,
                            var,
                            step,
                            exits: Vec::new(),
                        });
                    }
                    None => {
                        self.unknown(c, line);
                        let start = self.p.ins.len();
                        let test = self
                            .p
                            .push(Ins::JumpIfNot(X::Const(Val::Bool(false)), 0), line);
                        self.open.push(Open::For {
                            start,
                            test,
                            var: "SKP_UNREAD".into(),
                            step: X::Const(Val::Num(0.0)),
                            exits: Vec::new(),
                        });
                    }
                }
            }
            "EXIT" => {
                let j = self.p.push(Ins::Jump(0), line);
                let found = self.open.iter_mut().rev().find_map(|o| match o {
                    Open::Loop { exits, .. }
                    | Open::While { exits, .. }
                    | Open::Repeat { exits, .. }
                    | Open::For { exits, .. } => Some(exits),
                    _ => None,
                });
                match found {
                    Some(exits) => exits.push(j),
                    None => self.p.ins[j].0 = Ins::Unknown(c.to_owned()),
                }
            }
            "SWITCH" => {
                let sel = self
                    .expr(c[6..].trim())
                    .unwrap_or(X::Const(Val::Num(f64::NAN)));
                self.open.push(Open::Switch {
                    sel,
                    test: None,
                    to_end: Vec::new(),
                });
            }
            "CASE" | "DEFAULT" => {
                let values: Vec<X> = if first == "CASE" {
                    c[4..]
                        .split(',')
                        .filter_map(|v| self.expr(v.trim()).ok())
                        .collect()
                } else {
                    Vec::new()
                };
                let Some(Open::Switch { sel, test, to_end }) = self.open.last_mut() else {
                    self.unknown(c, line);
                    return;
                };
                let sel = sel.clone();
                let prev = test.take();
                // The previous case's body (if any) ends here: on to the ENDSWITCH.
                let first_case = prev.is_none() && to_end.is_empty();
                if !first_case {
                    let j = self.p.ins.len();
                    to_end.push(j);
                    self.p.push(Ins::Jump(0), line);
                }
                let start = self.p.ins.len();
                if let Some(t) = prev {
                    self.p.patch(t, start);
                }
                if first == "CASE" {
                    let cond = values
                        .into_iter()
                        .map(|v| X::Bin(Op::Eq, Box::new(sel.clone()), Box::new(v)))
                        .reduce(|a, b| X::Bin(Op::Or, Box::new(a), Box::new(b)))
                        .unwrap_or(X::Const(Val::Bool(false)));
                    let t = self.p.push(Ins::JumpIfNot(cond, 0), line);
                    if let Some(Open::Switch { test, .. }) = self.open.last_mut() {
                        *test = Some(t);
                    }
                }
            }
            "GOTO" => {
                let j = self.p.push(Ins::Jump(0), line);
                self.gotos.push((j, up[4..].trim().to_owned()));
            }
            "HALT" => {
                self.p.push(Ins::Halt, line);
            }
            "RETURN" => {
                let j = self.p.push(Ins::Jump(0), line);
                match self.open.iter_mut().rev().find_map(|o| match o {
                    Open::Call { returns } => Some(returns),
                    _ => None,
                }) {
                    Some(r) => r.push(j),
                    // RETURN in the main program ends it.
                    None => self.p.ins[j].0 = Ins::End,
                }
            }
            "WAIT" => {
                let rest = c[4..].trim();
                let up = rest.to_ascii_uppercase();
                if let Some(e) = up.strip_prefix("FOR").map(|_| rest[3..].trim()) {
                    match self.expr(e) {
                        Ok(cond) => {
                            self.p.push(
                                Ins::Wait {
                                    cond,
                                    settle: Settle::Yes,
                                    max: None,
                                    poll: None,
                                },
                                line,
                            );
                        }
                        Err(_) => self.unknown(c, line),
                    }
                } else if let Some(e) = up.strip_prefix("SEC").map(|_| rest[3..].trim()) {
                    match self.expr(e) {
                        Ok(x) => {
                            self.p.push(Ins::Sleep(x, Settle::Yes), line);
                        }
                        Err(_) => self.unknown(c, line),
                    }
                } else {
                    self.unknown(c, line);
                }
            }
            "DECL" | "BAS" | "INTERRUPT" | "GLOBAL" | "PDAT_ACT" | "FDAT_ACT" | "LDAT_ACT"
            | "TRIGGER" | "BRAKE" | "CONTINUE" => {}
            _ if MOTIONS.contains(&first) => {
                // `LIN XGrip`, `CIRC XAux, XEnd C_DIS`, `PTP {A1 0}`, `PTP $POS_ACT`.
                let n = if first.contains("CIRC") { 2 } else { 1 };
                let points = c[first.len()..]
                    .split(|ch: char| ch == ',' || ch.is_whitespace())
                    .filter(|w| !w.is_empty())
                    .take(n)
                    .filter_map(point_name)
                    // KSS's own home positions, declared in `$config.dat`.
                    .filter(|w| !is_home(&w.to_ascii_uppercase()))
                    .collect();
                self.p.push(Ins::Motion(points), line);
            }
            _ if c.ends_with(':') && !c.contains(' ') => {
                self.labels
                    .insert(up.trim_end_matches(':').to_owned(), self.p.ins.len());
            }
            _ => self.simple(c, line),
        }
    }

    /// An assignment or a call.
    fn simple(&mut self, c: &str, line: Line) {
        let up = c.to_ascii_uppercase();
        if up.contains("SET_KRLMSG(") || up.contains("CLR_KRLMSG(") {
            if up.contains("#QUIT")
                && let Some(m) = self.msg.clone()
            {
                self.p.push(Ins::Message(m), line);
            } else if up.contains("#WAITING") {
                // A wait's message (KSS: `Set_KrlMsg(#WAITING, …)` shows a wait message until
                // `Clr_KrlMsg` takes it away).
                self.p
                    .push(Ins::Show(self.msg.clone().unwrap_or_default()), line);
            } else if up.contains("CLR_KRLMSG(") {
                self.p.push(Ins::Clear, line);
            }
            return;
        }
        // An assignment `a = e` (not `==`).
        let eq = c
            .char_indices()
            .find(|&(i, ch)| {
                ch == '='
                    && c.as_bytes().get(i + 1) != Some(&b'=')
                    && !matches!(
                        c.as_bytes().get(i.wrapping_sub(1)),
                        Some(b'=' | b'<' | b'>')
                    )
            })
            .map(|(i, _)| i);
        if let Some(i) = eq {
            let (lhs, rhs) = (c[..i].trim(), c[i + 1..].trim());
            let lu = lhs.to_ascii_uppercase();
            if lu.ends_with("MSG_TXT[]") {
                self.msg = Some(rhs.trim_matches('"').to_owned());
                return;
            }
            if self.io.outs.contains(&lu) {
                match self.expr(rhs) {
                    Ok(x) => {
                        self.p.push(Ins::SetOut(lu, x), line);
                    }
                    Err(_) => self.unknown(c, line),
                }
                return;
            }
            if let Some((kind, n)) = io(lhs) {
                match (kind.as_str(), self.expr(rhs)) {
                    ("$OUT", Ok(x)) => {
                        self.p.push(Ins::SetOut(format!("$OUT[{n}]"), x), line);
                    }
                    ("$TIMER", Ok(x)) => {
                        self.p.push(Ins::TimerSet(n, x), line);
                    }
                    ("$TIMER_STOP", Ok(x)) => {
                        self.p.push(Ins::TimerStop(n, x), line);
                    }
                    (k, _) if k.starts_with('$') && k != "$OUT" && k != "$TIMER" => {}
                    _ => self.unknown(c, line),
                }
                return;
            }
            // System variables and their fields ($VEL.CP, $BWDSTART, $TOOL): settings.
            if lhs.starts_with('$') || lu.contains('.') && !lu.starts_with("SKP_") {
                return;
            }
            if let Some(bits) = self.signals.get(&lu).cloned() {
                if bits.len() == 1 && bits[0].starts_with("$OUT[") {
                    match self.expr(rhs) {
                        Ok(x) => {
                            self.p.push(Ins::SetOut(bits[0].clone(), x), line);
                        }
                        Err(_) => self.unknown(c, line),
                    }
                } else {
                    self.unknown(c, line);
                }
                return;
            }
            if lu.contains(['[', '.']) || self.opaque.contains(&lu) {
                return;
            }
            match self.expr(rhs) {
                Ok(x) => {
                    self.p.push(Ins::Assign(lu, x), line);
                }
                Err(_) => self.unknown(c, line),
            }
            return;
        }
        // A call: a routine of this file is put in its place.
        let name = up.split('(').next().unwrap_or("").trim().to_owned();
        if self.routines.contains_key(&name) && self.depth < 8 {
            let args: Vec<String> = c
                .split_once('(')
                .and_then(|(_, r)| r.rsplit_once(')'))
                .map(|(a, _)| {
                    a.split(',')
                        .map(|s| s.trim().to_owned())
                        .filter(|s| !s.is_empty())
                        .collect()
                })
                .unwrap_or_default();
            // Refused before the body is copied.
            if let Err(ins) = self.inlined.take(self.routines[&name].body.len(), c) {
                self.p.push(ins, line);
                return;
            }
            let (params, body) = {
                let r = &self.routines[&name];
                (r.params.clone(), r.body.clone())
            };
            for (p, a) in params.iter().zip(&args) {
                if let Ok(x) = self.expr(a) {
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
                let o = self.open.pop().unwrap_or(Open::Call { returns: vec![] });
                self.close(o, line);
            }
            self.depth -= 1;
            return;
        }
        self.unknown(c, line);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Routines that call each other many times over (a fuzzer found one: 46 s to read) are put
    /// in the places of their calls only up to a limit; the rest is a statement not understood.
    #[test]
    fn routines_calling_each_other_many_times_over_are_read_in_bounded_time() {
        let calls = "  A()\n".repeat(12);
        let src = format!("DEF P( )\n{calls}END\nDEF A( )\n{calls}END\n");
        let p = read(&src, "DEFDAT P\nENDDAT\n", &Default::default());
        // 12 calls eight deep would be 12^8 = 430 million bodies.
        assert!(p.ins.len() < 200_000, "{} instructions", p.ins.len());
        assert!(
            p.ins
                .iter()
                .any(|(i, _)| matches!(i, Ins::Unknown(t) if t.contains("not read"))),
            "the calls past the limit are not understood"
        );
    }

    #[test]
    fn a_main_program_with_a_routine_and_signals() {
        let src = "DEF P( )\n;FOLD 1 Pick: Move @ R (localId 3)\n  PTP XPick\n  Grip(40)\n;ENDFOLD\n;handshake: tell\nWAIT FOR From_A AND NOT $IN[2]\nTo_A = TRUE\nLOOP\n  IF x THEN\n    EXIT\n  ENDIF\nENDLOOP\nFoo(3)\nEND\nDEF Grip(F:IN)\n  DECL REAL F\n  $OUT[7] = TRUE\nEND\n";
        let dat =
            "DEFDAT P\nSIGNAL From_A $IN[41]\nSIGNAL To_A $OUT[41]\nDECL BOOL x = TRUE\nENDDAT\n";
        let p = read(src, dat, &Default::default());
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
                "Assign",
                "SetOut",
                "StepEnd",
                "Note",
                "Wait",
                "SetOut",
                "JumpIfNot",
                "Jump",
                "Jump",
                "Unknown",
                "End"
            ],
            "{:#?}",
            p.ins
        );
        assert_eq!(p.unknown, [("Foo(3)".to_owned(), 14)]);
        assert_eq!(p.init, [("X".to_owned(), Val::Bool(true))]);
    }
}
