//! Motions to literal targets, read from a step's code in each language: where each target
//! stands in the line, whether it is a position or axes, and its text as a declaration writes
//! it. `super` names the targets and declares them.

use std::ops::Range;

/// Whether a target is a Cartesian position or one of the axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    Cartesian,
    Axis,
}

/// One literal target of a motion: where it stands in the line and its value as declared.
#[derive(Clone, Debug)]
pub(super) struct Target {
    pub(super) range: Range<usize>,
    pub(super) kind: Kind,
    /// The value as the declaration writes it: `line[value]`, in braces when `braces` (a KRL
    /// aggregate written with its type, `{E6POS: X 1}`, is declared as `{X 1}`).
    pub(super) value: Range<usize>,
    pub(super) braces: bool,
}

impl Target {
    /// Appends the value as the declaration writes it.
    pub(super) fn push_value(&self, line: &str, out: &mut String) {
        if self.braces {
            out.push('{');
        }
        out.push_str(&line[self.value.clone()]);
        if self.braces {
            out.push('}');
        }
    }

    /// How long [`Target::push_value`] makes it.
    pub(super) fn value_len(&self) -> usize {
        self.value.len() + 2 * usize::from(self.braces)
    }
}

/// A motion statement with literal targets (at most two: `CIRC`, `MoveC`, `movec`).
#[derive(Debug)]
pub(super) struct Motion {
    /// KRL: `PTP`, `LIN` or `CIRC` (upper-case).
    pub(super) verb: &'static str,
    targets: [Target; 2],
    count: usize,
    /// KRL: what follows the targets (the approximation), trimmed: `line[rest]`.
    pub(super) rest: Range<usize>,
}

impl Motion {
    fn new(verb: &'static str) -> Self {
        let none = Target {
            range: 0..0,
            kind: Kind::Cartesian,
            value: 0..0,
            braces: false,
        };
        Motion {
            verb,
            targets: [none.clone(), none],
            count: 0,
            rest: 0..0,
        }
    }

    pub(super) fn targets(&self) -> &[Target] {
        &self.targets[..self.count]
    }

    fn push(&mut self, t: Target) {
        self.targets[self.count] = t;
        self.count += 1;
    }
}

/// The index after the bracket group that opens at `open` (`{`/`[`), nested groups included.
fn group_end(s: &str, open: usize) -> Option<usize> {
    let b = s.as_bytes();
    let (o, c) = match b[open] {
        b'{' => (b'{', b'}'),
        b'[' => (b'[', b']'),
        _ => return None,
    };
    let mut depth = 0usize;
    for i in memchr::memchr3_iter(o, c, b'"', &b[open..]) {
        let x = b[open + i];
        if x == b'"' {
            return None;
        }
        if x == o {
            depth += 1;
        } else {
            depth -= 1;
            if depth == 0 {
                return Some(open + i + 1);
            }
        }
    }
    None
}

/// A number as the languages write it: `-12`, `0.5`, `.5`, `1E-3`, `9E9`.
pub(super) fn is_number(s: &str) -> bool {
    number(s.trim().as_bytes())
}

/// [`is_number`] of bytes without white space around them.
fn number(b: &[u8]) -> bool {
    let mut i = usize::from(matches!(b.first(), Some(b'-' | b'+')));
    let digits = |i: &mut usize| {
        let start = *i;
        while *i < b.len() && b[*i].is_ascii_digit() {
            *i += 1;
        }
        *i - start
    };
    let mut n = digits(&mut i);
    if b.get(i) == Some(&b'.') {
        i += 1;
        n += digits(&mut i);
    }
    if n == 0 {
        return false;
    }
    if matches!(b.get(i), Some(b'e' | b'E')) {
        i += 1;
        i += usize::from(matches!(b.get(i), Some(b'-' | b'+')));
        if digits(&mut i) == 0 {
            return false;
        }
    }
    i == b.len()
}

/// A KRL motion to literal targets: `PTP {X 1, Y 2, …}`, `LIN {E6POS: X 1, …} C_DIS`,
/// `CIRC {X …}, {X …}`, `PTP {A1 0, …}`. Every component a number.
pub(super) fn krl_motion(line: &str) -> Option<Motion> {
    let b = line.as_bytes();
    let at = b.iter().position(|c| !c.is_ascii_whitespace())?;
    let word_end = at + b[at..].iter().position(|c| !c.is_ascii_alphabetic())?;
    let word = &b[at..word_end];
    let verb = ["PTP", "LIN", "CIRC"]
        .into_iter()
        .find(|v| word.eq_ignore_ascii_case(v.as_bytes()))?;
    let skip_space = |i: usize| {
        i + b[i..]
            .iter()
            .take_while(|c| c.is_ascii_whitespace())
            .count()
    };
    let mut i = word_end;
    let mut motion = Motion::new(verb);
    let wanted = if verb == "CIRC" { 2 } else { 1 };
    for n in 0..wanted {
        let skip = skip_space(i);
        if n > 0 {
            if b.get(skip) != Some(&b',') {
                return None;
            }
            i = skip_space(skip + 1);
        } else if skip == i {
            return None;
        } else {
            i = skip;
        }
        if b.get(i) != Some(&b'{') {
            return None;
        }
        let end = group_end(line, i)?;
        let inner = &line[i + 1..end - 1];
        let (kind, typed) = krl_aggregate(inner)?;
        if verb != "PTP" && kind == Kind::Axis {
            return None;
        }
        // The declaration's value: the aggregate as written, without a type before `:` (the
        // declaration gives the type).
        let (value, braces) = match typed {
            Some(values) => (
                trimmed(line, i + 1 + values.start..i + 1 + values.end),
                true,
            ),
            None => (i..end, false),
        };
        motion.push(Target {
            range: i..end,
            kind,
            value,
            braces,
        });
        i = end;
    }
    let rest = &b[i..];
    // A comment or anything else after the approximation: not a plain motion.
    if rest.iter().any(|c| matches!(c, b';' | b',' | b'{')) {
        return None;
    }
    let rest_range = trimmed(line, i..line.len());
    if !rest_range.is_empty() && !rest[0].is_ascii_whitespace() {
        return None;
    }
    motion.rest = rest_range;
    Some(motion)
}

/// `range` without the ASCII white space at its ends.
fn trimmed(line: &str, range: Range<usize>) -> Range<usize> {
    let b = &line.as_bytes()[range.clone()];
    let start = b.iter().take_while(|c| c.is_ascii_whitespace()).count();
    let end = b.len()
        - b[start..]
            .iter()
            .rev()
            .take_while(|c| c.is_ascii_whitespace())
            .count();
    range.start + start..range.start + end
}

/// A KRL aggregate of numbers (its text between the braces): its kind, and where its values
/// start when it names its type (`E6POS: X 1, …`: the declaration gives the type). The `.dat`
/// declares the aggregate as written (`{X 1, Y 2, …}`).
fn krl_aggregate(whole: &str) -> Option<(Kind, Option<Range<usize>>)> {
    let mut inner = whole;
    let mut ty = None;
    let mut values = None;
    if let Some((t, rest)) = inner.split_once(':') {
        values = Some(t.len() + 1..whole.len());
        let t = t.trim();
        let is = |w: &str| t.eq_ignore_ascii_case(w);
        ty = Some(if is("POS") || is("E6POS") || is("FRAME") {
            Kind::Cartesian
        } else if is("AXIS") || is("E6AXIS") {
            Kind::Axis
        } else {
            return None;
        });
        inner = rest;
    }
    // Which keys were seen, one bit each: a key twice is no position.
    let mut seen = 0u32;
    // Items `key value`, separated by commas, white space around them: one pass over the
    // bytes (every motion of every step).
    let b = inner.as_bytes();
    let n = b.len();
    let space = |c: u8| c.is_ascii_whitespace();
    let mut i = 0;
    loop {
        while i < n && space(b[i]) {
            i += 1;
        }
        let key_start = i;
        while i < n && !space(b[i]) && b[i] != b',' {
            i += 1;
        }
        let key = &b[key_start..i];
        while i < n && space(b[i]) {
            i += 1;
        }
        let value_start = i;
        while i < n && !space(b[i]) && b[i] != b',' {
            i += 1;
        }
        let value = &b[value_start..i];
        while i < n && space(b[i]) {
            i += 1;
        }
        if key.is_empty() || value.is_empty() || !number(value) {
            return None;
        }
        let k = key_index(key)?;
        if seen & (1 << k) != 0 {
            return None;
        }
        seen |= 1 << k;
        if i == n {
            break;
        }
        // A third word, or the next item.
        if b[i] != b',' {
            return None;
        }
        i += 1;
    }
    let cartesian = seen & 0xff != 0;
    let axis = seen & (0x3f << 8) != 0;
    let kind = match (cartesian, axis, ty) {
        (true, false, None | Some(Kind::Cartesian)) => Kind::Cartesian,
        (false, true, None | Some(Kind::Axis)) => Kind::Axis,
        _ => return None,
    };
    Some((kind, values))
}

/// A component's bit in [`krl_aggregate`]: `X Y Z A B C S T` are 0–7 (a position), `A1`–`A6`
/// 8–13 and `E1`–`E6` 14–19 (the axes).
fn key_index(key: &[u8]) -> Option<usize> {
    match *key {
        [c] => b"XYZABCST".iter().position(|k| k.eq_ignore_ascii_case(&c)),
        [c, d @ b'1'..=b'6'] => {
            let n = usize::from(d - b'1');
            match c.to_ascii_uppercase() {
                b'A' => Some(8 + n),
                b'E' => Some(14 + n),
                _ => None,
            }
        }
        _ => None,
    }
}

/// RAPID's motion instructions whose first arguments are targets.
const RAPID_MOVES: &[(&str, usize, Kind)] = &[
    ("MoveL", 1, Kind::Cartesian),
    ("MoveJ", 1, Kind::Cartesian),
    ("MoveC", 2, Kind::Cartesian),
    ("MoveAbsJ", 1, Kind::Axis),
];

/// A RAPID motion to literal targets: `MoveL [[x,y,z],[q1,…],[cf…],[e…]], v, z, tool;`,
/// `MoveAbsJ [[j1,…,j6],[e…]], …;`.
pub(super) fn rapid_motion(line: &str) -> Option<Motion> {
    let code = line.trim_start();
    let at = line.len() - code.len();
    let word_end = code.find(|c: char| !c.is_ascii_alphanumeric())?;
    let word = &code[..word_end];
    let &(verb, n, kind) = RAPID_MOVES
        .iter()
        .find(|(v, _, _)| v.eq_ignore_ascii_case(word))?;
    let mut i = at + word_end;
    let skip = line[i..].len() - line[i..].trim_start().len();
    if skip == 0 {
        return None;
    }
    i += skip;
    let mut motion = Motion::new(verb);
    for k in 0..n {
        if k > 0 {
            i += line[i..].strip_prefix(',').map(|_| 1)?;
            i += line[i..].len() - line[i..].trim_start().len();
        }
        if !line[i..].starts_with("[[") {
            return None;
        }
        let end = group_end(line, i)?;
        let groups = number_groups(&line[i + 1..end - 1])?;
        let sizes: Vec<usize> = groups.iter().map(Vec::len).collect();
        let fits = match kind {
            Kind::Cartesian => sizes == [3, 4, 4, 6],
            Kind::Axis => sizes == [6, 6],
        };
        if !fits {
            return None;
        }
        motion.push(Target {
            range: i..end,
            kind,
            value: i..end,
            braces: false,
        });
        i = end;
    }
    if !line[i..].trim_start().starts_with(',') {
        return None;
    }
    Some(motion)
}

/// `[a, b], [c]` → the numbers of each group; `None` unless every item is a number.
fn number_groups(s: &str) -> Option<Vec<Vec<&str>>> {
    let mut out = Vec::new();
    let mut rest = s.trim();
    while !rest.is_empty() {
        let inner = rest.strip_prefix('[')?;
        let close = inner.find(']')?;
        let items: Vec<&str> = inner[..close].split(',').map(str::trim).collect();
        if !items.iter().all(|x| is_number(x)) {
            return None;
        }
        out.push(items);
        rest = inner[close + 1..].trim_start();
        if let Some(r) = rest.strip_prefix(',') {
            rest = r.trim_start();
            if rest.is_empty() {
                return None;
            }
        } else if !rest.is_empty() {
            return None;
        }
    }
    Some(out)
}

/// URScript's motion functions and how many targets they take first.
const UR_MOVES: &[(&str, usize)] = &[("movel", 1), ("movej", 1), ("movep", 1), ("movec", 2)];

/// A URScript motion to literal targets: `movel(p[x, y, z, rx, ry, rz], a=…, v=…)`,
/// `movej([q1, …, q6], …)`.
pub(super) fn ur_motion(line: &str) -> Option<Motion> {
    let code = line.trim_start();
    let at = line.len() - code.len();
    let open = code.find('(')?;
    let word = &code[..open];
    let &(verb, n) = UR_MOVES.iter().find(|(v, _)| *v == word)?;
    let mut i = at + open + 1;
    let mut motion = Motion::new(verb);
    for k in 0..n {
        i += line[i..].len() - line[i..].trim_start().len();
        if k > 0 {
            i += line[i..].strip_prefix(',').map(|_| 1)?;
            i += line[i..].len() - line[i..].trim_start().len();
        }
        let (start, kind) = if line[i..].starts_with("p[") {
            (i + 1, Kind::Cartesian)
        } else if line[i..].starts_with('[') && verb == "movej" && k == 0 {
            (i, Kind::Axis)
        } else {
            return None;
        };
        let end = group_end(line, start)?;
        let groups = number_groups(&line[start..end])?;
        if groups.len() != 1 || groups[0].len() != 6 {
            return None;
        }
        motion.push(Target {
            range: i..end,
            kind,
            value: i..end,
            braces: false,
        });
        i = end;
    }
    let after = line[i..].trim_start();
    if !(after.starts_with(',') || after.starts_with(')')) {
        return None;
    }
    Some(motion)
}
