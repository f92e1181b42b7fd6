//! Reads a URScript program into [`Program`] (Universal Robots, The URScript Programming
//! Language, e-Series): the first `def` at the top (the program's own) to its `end`, each call
//! of a `def` inside it put in its place, `global` and plain variables, `if`/`elif`/`else`,
//! `while`/`break`/`continue`, `sync()`, `sleep(t)`, `halt`, standard and tool digital I/O and
//! the boolean and integer registers, `popup`. A `while` whose body is only `sync()` is a wait
//! (`while not (c): sync() end`). A `thread` that advances a variable by `get_steptime()` makes
//! that variable a counter of seconds. A step is its `# step n Name: … (localId N)` comment;
//! `movej`/`movel`/`movep`/`movec` are its motion (they return when the motion has ended); any
//! other statement is listed as not simulated.

use std::collections::HashMap;

use super::ir::{
    Grammar, Ins, IoKeys, Line, Op, Program, Raw, Settle, Val, X, parse_expr, point_name,
    step_title, writer_comment,
};

pub const GRAMMAR: Grammar = Grammar {
    levels: &[
        &[("or", Op::Or), ("xor", Op::Xor)],
        &[("and", Op::And)],
        &[],
        &[
            ("==", Op::Eq),
            ("!=", Op::Ne),
            ("<=", Op::Le),
            (">=", Op::Ge),
            ("<", Op::Lt),
            (">", Op::Gt),
        ],
        &[("+", Op::Add), ("-", Op::Sub)],
        &[("*", Op::Mul), ("/", Op::Div)],
    ],
    not_level: 2,
    not: "not",
    fold_case: false,
    trues: &["True", "true"],
    falses: &["False", "false"],
};

const MOTIONS: &[&str] = &[
    "movej", "movel", "movep", "movec", "servoj", "stopj", "stopl",
];
const SETTINGS: &[&str] = &[
    "set_tcp",
    "set_payload",
    "textmsg",
    "set_tool_voltage",
    "set_gravity",
    "set_payload_cog",
    "set_payload_mass",
    "kill",
    "join",
];
/// Input reads by the function's name (each keyed `f(n)`), and output reads.
const READS: &[&str] = &[
    "get_standard_digital_in",
    "get_configurable_digital_in",
    "get_tool_digital_in",
    "read_input_boolean_register",
    "read_input_integer_register",
    "get_standard_analog_in",
];
/// Each output setter and the key its value is read back by.
const WRITES: &[&str] = &[
    "set_standard_digital_out",
    "set_configurable_digital_out",
    "set_tool_digital_out",
    "write_output_boolean_register",
    "write_output_integer_register",
];

enum Open {
    If {
        test: Option<usize>,
        to_end: Vec<usize>,
    },
    While {
        start: usize,
        test: usize,
        breaks: Vec<usize>,
    },
    Call {
        returns: Vec<usize>,
    },
}

/// A `def` of the program: its parameters and body lines.
type Def = (Vec<String>, Vec<(Line, String)>);

struct Reader<'a> {
    p: Program,
    _io: &'a IoKeys,
    defs: HashMap<String, Def>,
    open: Vec<Open>,
    depth: usize,
    /// The lines calls may still put in their places.
    inlined: super::ir::InlineBudget,
    /// In a step's own code (after its title comment).
    in_step: bool,
}

/// The code of a line without its `#` comment (outside strings).
fn code(t: &str) -> &str {
    let mut in_str = false;
    for (i, c) in t.char_indices() {
        match c {
            '"' => in_str = !in_str,
            '#' if !in_str => return t[..i].trim(),
            _ => {}
        }
    }
    t.trim()
}

/// Where the block that opens at `lines[i]` ends (its `end`), counting the blocks inside.
fn block_end(lines: &[(Line, String)], i: usize) -> usize {
    let mut depth = 0usize;
    for (j, (_, l)) in lines.iter().enumerate().skip(i) {
        let c = code(l);
        if opens(c) {
            depth += 1;
        } else if c == "end" {
            depth = depth.saturating_sub(1);
            if depth == 0 {
                return j;
            }
        }
    }
    lines.len()
}

fn opens(c: &str) -> bool {
    c.ends_with(':')
        && (c.starts_with("def ")
            || c.starts_with("thread ")
            || c.starts_with("if ")
            || c.starts_with("while ")
            || c.starts_with("for "))
}

/// Reads program text `text`.
/// The names a script assigns (`global p_pick = p[…]`, `x = 1`) or takes as a routine's
/// parameters: what a motion may name.
fn assigned(text: &str) -> std::collections::HashSet<String> {
    let mut out = std::collections::HashSet::new();
    for l in text.lines() {
        let c = code(l.trim());
        let c = ["global ", "local "]
            .iter()
            .find_map(|k| c.strip_prefix(k))
            .unwrap_or(c);
        if let Some(head) = c.strip_prefix("def ").or_else(|| c.strip_prefix("thread ")) {
            if let Some((_, ps)) = head.split_once('(') {
                for p in ps.trim_end_matches(':').trim_end_matches(')').split(',') {
                    if let Some(n) = point_name(p.split('=').next().unwrap_or("")) {
                        out.insert(n);
                    }
                }
            }
            continue;
        }
        if let Some((lhs, rhs)) = c.split_once('=')
            && !rhs.starts_with('=')
            && !lhs.ends_with(['!', '<', '>'])
            && let Some(n) = point_name(lhs)
        {
            out.insert(n);
        }
    }
    out
}

pub fn read(text: &str, io: &IoKeys) -> Program {
    let lines: Vec<(Line, String)> = text
        .lines()
        .enumerate()
        .map(|(k, l)| (k as Line + 1, l.trim().to_owned()))
        .filter(|(_, l)| !l.is_empty())
        .collect();
    let mut p = Program::default();
    let Some(main) = lines.iter().position(|(_, l)| l.starts_with("def ")) else {
        p.push(Ins::Unknown("no def: not a URScript program".into()), 1);
        p.push(Ins::End, 1);
        return p;
    };
    let end = block_end(&lines, main);
    let body = &lines[main + 1..end.min(lines.len())];
    // The defs and threads inside (at any place of the main body's top level).
    let mut defs = HashMap::new();
    let mut i = 0;
    while i < body.len() {
        let c = code(&body[i].1);
        if c.starts_with("def ") || c.starts_with("thread ") {
            let e = block_end(body, i);
            let head = c.split_once(' ').map_or("", |x| x.1);
            let name = head.split('(').next().unwrap_or("").trim().to_owned();
            let params = head
                .split_once('(')
                .and_then(|(_, r)| r.rsplit_once(')'))
                .map(|(ps, _)| {
                    ps.split(',')
                        .map(|p| p.split('=').next().unwrap_or("").trim().to_owned())
                        .filter(|p| !p.is_empty())
                        .collect()
                })
                .unwrap_or_default();
            let inner = body[i + 1..e.min(body.len())].to_vec();
            if c.starts_with("thread ") {
                // A counter: `v = v + get_steptime()`.
                for (_, l) in &inner {
                    if let Some((v, r)) = code(l).split_once('=')
                        && r.replace(' ', "") == format!("{}+get_steptime()", v.trim())
                    {
                        p.counters.push(v.trim().to_owned());
                    }
                }
            }
            defs.insert(name, (params, inner));
            i = e + 1;
            continue;
        }
        i += 1;
    }
    p.declared = assigned(text);
    let mut r = Reader {
        p,
        _io: io,
        defs,
        open: Vec::new(),
        depth: 0,
        inlined: super::ir::InlineBudget::new(text.lines().count()),
        in_step: false,
    };
    r.block(body);
    let end_line = lines.get(end).map_or(1, |l| l.0);
    while let Some(o) = r.open.pop() {
        r.close(o, end_line);
    }
    r.p.push(Ins::End, end_line);
    r.p.undeclared_points();
    r.p
}

impl Reader<'_> {
    fn x(&self, raw: &Raw) -> Result<X, String> {
        Ok(match raw {
            Raw::Num(n) => X::Const(Val::Num(*n)),
            Raw::Bool(b) => X::Const(Val::Bool(*b)),
            Raw::Str(s) => X::Const(Val::Str(s.clone())),
            Raw::Name(n) => X::Var(n.clone()),
            Raw::Call(f, args) if READS.contains(&f.as_str()) && args.len() == 1 => {
                match &args[0] {
                    Raw::Num(n) => X::In(format!("{f}({})", *n as i64), false),
                    a => X::InAt(f.clone(), Box::new(self.x(a)?)),
                }
            }
            Raw::Call(f, args)
                if args.len() == 1 && f.starts_with("get_") && f.ends_with("_digital_out") =>
            {
                let set = f.replacen("get_", "set_", 1);
                match &args[0] {
                    Raw::Num(n) => X::Out(format!("{set}({})", *n as i64), false),
                    _ => return Err(format!("`{f}` of a computed number")),
                }
            }
            Raw::Call(f, _) => return Err(format!("the function `{f}`")),
            Raw::Index(a, _) => return Err(format!("the list `{a}`")),
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
            Open::While {
                start,
                test,
                breaks,
            } => {
                self.p.push(Ins::Jump(start), line);
                let end = self.p.ins.len();
                self.p.patch(test, end);
                for j in breaks {
                    self.p.patch(j, end);
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

    fn block(&mut self, lines: &[(Line, String)]) {
        let mut i = 0;
        while i < lines.len() {
            let (line, ref raw) = lines[i];
            i += 1;
            let marker = raw
                .strip_prefix('#')
                .and_then(|c| writer_comment(c.trim()))
                .is_some();
            let c0 = code(raw);
            if marker
                || ["if ", "elif ", "else:", "while ", "for "]
                    .iter()
                    .any(|k| c0.starts_with(k))
                || c0 == "end"
            {
                self.end_step(line);
            }
            if let Some(comment) = raw.strip_prefix('#') {
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
                continue;
            }
            let c = code(raw);
            if c.is_empty() {
                continue;
            }
            // A def or thread inside: read already (called where it is called).
            if c.starts_with("def ") || c.starts_with("thread ") {
                let e = block_end(lines, i - 1);
                i = e + 1;
                continue;
            }
            // The wait form: `while c:` `sync()` `end`.
            if let Some(cond) = c.strip_prefix("while ").and_then(|r| r.strip_suffix(':'))
                && lines.get(i).is_some_and(|l| code(&l.1) == "sync()")
                && lines.get(i + 1).is_some_and(|l| code(&l.1) == "end")
            {
                match self.expr(cond) {
                    Ok(x) => {
                        self.p.push(
                            Ins::Wait {
                                cond: X::Not(Box::new(x)),
                                settle: Settle::No,
                                max: None,
                                poll: None,
                            },
                            line,
                        );
                        i += 2;
                        continue;
                    }
                    Err(_) => self.unknown(c, line),
                }
            }
            self.statement(c, line);
        }
    }

    fn statement(&mut self, c: &str, line: Line) {
        let first = c
            .split(|ch: char| ch.is_whitespace() || ch == '(' || ch == ':')
            .next()
            .unwrap_or("");
        match first {
            "if" => {
                let cond = c[2..].trim().trim_end_matches(':');
                let test = match self.expr(cond) {
                    Ok(x) => Some(self.p.push(Ins::JumpIfNot(x, 0), line)),
                    Err(_) => {
                        self.unknown(c, line);
                        None
                    }
                };
                self.open.push(Open::If {
                    test,
                    to_end: Vec::new(),
                });
            }
            "elif" | "else" => {
                let Some(Open::If { test, to_end }) = self.open.last_mut() else {
                    return self.unknown(c, line);
                };
                let prev = test.take();
                let j = self.p.ins.len();
                to_end.push(j);
                self.p.push(Ins::Jump(0), line);
                let here = self.p.ins.len();
                if let Some(t) = prev {
                    self.p.patch(t, here);
                }
                if first == "elif" {
                    match self.expr(c[4..].trim().trim_end_matches(':')) {
                        Ok(x) => {
                            let t = self.p.push(Ins::JumpIfNot(x, 0), line);
                            if let Some(Open::If { test, .. }) = self.open.last_mut() {
                                *test = Some(t);
                            }
                        }
                        Err(_) => self.unknown(c, line),
                    }
                }
            }
            "while" => {
                let cond = c[5..].trim().trim_end_matches(':');
                // A condition not read: listed, and the loop not run (never a loop without end).
                let x = match self.expr(cond) {
                    Ok(x) => x,
                    Err(_) => {
                        self.unknown(c, line);
                        X::Const(Val::Bool(false))
                    }
                };
                let start = self.p.ins.len();
                let test = self.p.push(Ins::JumpIfNot(x, 0), line);
                self.open.push(Open::While {
                    start,
                    test,
                    breaks: Vec::new(),
                });
            }
            "end" => match self.open.pop() {
                Some(o) => self.close(o, line),
                None => self.unknown(c, line),
            },
            "break" | "continue" => {
                let j = self.p.push(Ins::Jump(0), line);
                let found = self.open.iter_mut().rev().find_map(|o| match o {
                    Open::While { start, breaks, .. } => Some((*start, breaks)),
                    _ => None,
                });
                match found {
                    Some((start, breaks)) => {
                        if first == "break" {
                            breaks.push(j);
                        } else {
                            self.p.patch(j, start);
                        }
                    }
                    None => self.p.ins[j].0 = Ins::Unknown(c.to_owned()),
                }
            }
            "return" => {
                let j = self.p.push(Ins::Jump(0), line);
                match self.open.iter_mut().rev().find_map(|o| match o {
                    Open::Call { returns } => Some(returns),
                    _ => None,
                }) {
                    Some(r) => r.push(j),
                    None => self.p.ins[j].0 = Ins::End,
                }
            }
            "halt" => {
                self.p.push(Ins::Halt, line);
            }
            "sync" => {
                self.p.push(Ins::Sync, line);
            }
            "sleep" => match self.call_args(c).first().map(|a| self.expr(a)) {
                Some(Ok(x)) => {
                    self.p.push(Ins::Sleep(x, Settle::No), line);
                }
                _ => self.unknown(c, line),
            },
            // The writer's log lines of a wait that lasts: at its start and at its end.
            "textmsg" if c.contains("\"skillpost: ") => {
                let a = self.call_args(c);
                let text = a.first().map_or("", |s| s.trim_matches('"'));
                if text.ends_with(": the wait has ended") {
                    self.p.push(Ins::Clear, line);
                } else {
                    self.p.push(Ins::Show(text.to_owned()), line);
                }
            }
            "popup" => {
                let a = self.call_args(c);
                let text = a.first().map_or("", |s| s.trim_matches('"')).to_owned();
                self.p.push(Ins::Message(text), line);
            }
            "global" | "local" => self.statement(c[first.len()..].trim(), line),
            _ if MOTIONS.contains(&first) => {
                // `movel(p_pick, a=1.2, v=0.25)`, `movec(p_via, p_to, …)`, `movel(p[…])`.
                let n = match first {
                    "movec" => 2,
                    "movej" | "movel" | "movep" => 1,
                    _ => 0,
                };
                let points = self
                    .call_args(c)
                    .iter()
                    .take(n)
                    .filter_map(|a| point_name(a))
                    .collect();
                self.p.push(Ins::Motion(points), line);
            }
            _ if SETTINGS.contains(&first) => {}
            _ if WRITES.contains(&first) => {
                let a = self.call_args(c);
                match (
                    a.first().map(|n| self.expr(n)),
                    a.get(1).map(|v| self.expr(v)),
                ) {
                    (Some(Ok(n)), Some(Ok(v))) => {
                        self.p.push(Ins::SetOutAt(first.to_owned(), n, v), line);
                    }
                    _ => self.unknown(c, line),
                }
            }
            _ => {
                // `x = e` (not `==`), `x = run f()`.
                if let Some((lhs, rhs)) = c.split_once('=')
                    && !rhs.starts_with('=')
                    && !lhs.ends_with(['!', '<', '>'])
                {
                    let (lhs, rhs) = (lhs.trim(), rhs.trim());
                    if rhs.starts_with("run ") {
                        return;
                    }
                    if lhs.chars().all(|ch| ch.is_alphanumeric() || ch == '_') {
                        // A pose or list literal is no value here (points).
                        if rhs.starts_with("p[") || rhs.starts_with('[') {
                            return;
                        }
                        match self.expr(rhs) {
                            Ok(x) => {
                                self.p.push(Ins::Assign(lhs.to_owned(), x), line);
                            }
                            Err(_) => self.unknown(c, line),
                        }
                        return;
                    }
                }
                // A call of a def of the program.
                if self.defs.contains_key(first) && self.depth < 8 {
                    let args = self.call_args(c);
                    // Refused before the body is copied.
                    if let Err(ins) = self.inlined.take(self.defs[first].1.len(), c) {
                        self.p.push(ins, line);
                        return;
                    }
                    let (params, body) = self.defs[first].clone();
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
                        if let Some(o) = self.open.pop() {
                            self.close(o, line);
                        }
                    }
                    self.depth -= 1;
                    return;
                }
                self.unknown(c, line);
            }
        }
    }

    /// The arguments of a call `f(a, b, k=v)` (keyword arguments left out).
    fn call_args(&self, c: &str) -> Vec<String> {
        let Some((_, r)) = c.split_once('(') else {
            return Vec::new();
        };
        let Some((inner, _)) = r.rsplit_once(')') else {
            return Vec::new();
        };
        let mut out = Vec::new();
        let (mut depth, mut in_str, mut cur) = (0i32, false, String::new());
        for ch in inner.chars() {
            match ch {
                '"' => in_str = !in_str,
                '(' | '[' if !in_str => depth += 1,
                ')' | ']' if !in_str => depth -= 1,
                ',' if !in_str && depth == 0 => {
                    out.push(std::mem::take(&mut cur));
                    continue;
                }
                _ => {}
            }
            cur.push(ch);
        }
        out.push(cur);
        out.into_iter()
            .map(|a| a.trim().to_owned())
            .filter(|a| !a.is_empty() && !a.contains("=") || a.contains("=="))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_program_with_a_counter_a_wait_and_a_def() {
        let text = "def P():\n  global skp_waited = 0.0\n  thread skp_clock():\n    while True:\n      skp_waited = skp_waited + get_steptime()\n      sync()\n    end\n  end\n  def grip(f):\n    set_standard_digital_out(0, True)\n  end\n  t = run skp_clock()\n  A = 4\n  # step 1 Place: Move L @ UR (localId 11)\n  movel(pPlace, a=1.2, v=0.25)\n  grip(3)\n  while not ((get_standard_digital_in(A) == True) or (skp_waited >= 10.0)):\n    sync()\n  end\n  if x:\n    halt\n  else:\n    foo()\n  end\nend\nP()\n";
        let p = read(text, &IoKeys::default());
        assert_eq!(p.counters, ["skp_waited"]);
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
                "Assign",
                "Assign",
                "Step",
                "Motion",
                "Assign",
                "SetOutAt",
                "StepEnd",
                "Wait",
                "JumpIfNot",
                "Halt",
                "Jump",
                "Unknown",
                "End"
            ],
            "{:#?}",
            p.ins
        );
    }
}
