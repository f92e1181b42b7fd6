//! Motions to literal targets, read from a step's code in each language: where each target
//! stands in the line, whether it is a position or axes, and its text as a declaration writes
//! it. `super` names the targets and declares them.

/// Whether a target is a Cartesian position or one of the axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    Cartesian,
    Axis,
}

/// One literal target of a motion: where it stands in the line and its text as declared.
#[derive(Debug)]
pub(super) struct Target {
    pub(super) range: std::ops::Range<usize>,
    pub(super) kind: Kind,
    /// The value as the declaration writes it.
    pub(super) text: String,
}

/// A motion statement with literal targets.
#[derive(Debug)]
pub(super) struct Motion {
    /// KRL: `PTP`, `LIN` or `CIRC` (upper-case).
    pub(super) verb: &'static str,
    pub(super) targets: Vec<Target>,
    /// KRL: what follows the targets (the approximation).
    pub(super) rest: String,
}

impl Motion {
    /// `line` with each target replaced by `name(i)`.
    pub(super) fn rewrite(&self, line: &str, name: impl Fn(usize) -> String) -> String {
        let mut out = String::with_capacity(line.len());
        let mut at = 0;
        for (i, t) in self.targets.iter().enumerate() {
            out.push_str(&line[at..t.range.start]);
            out.push_str(&name(i));
            at = t.range.end;
        }
        out.push_str(&line[at..]);
        out
    }
}

/// The index after the bracket group that opens at `open` (`{`/`[`), nested groups included.
fn group_end(s: &str, open: usize) -> Option<usize> {
    let (o, c) = match s.as_bytes()[open] {
        b'{' => (b'{', b'}'),
        b'[' => (b'[', b']'),
        _ => return None,
    };
    let mut depth = 0usize;
    for (i, b) in s.bytes().enumerate().skip(open) {
        if b == b'"' {
            return None;
        }
        if b == o {
            depth += 1;
        } else if b == c {
            depth -= 1;
            if depth == 0 {
                return Some(i + 1);
            }
        }
    }
    None
}

/// A number as the languages write it: `-12`, `0.5`, `.5`, `1E-3`, `9E9`.
pub(super) fn is_number(s: &str) -> bool {
    let b = s.trim().as_bytes();
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
    let code = line.trim_start();
    let at = line.len() - code.len();
    let word_end = code.find(|c: char| !c.is_ascii_alphabetic())?;
    let word = &code[..word_end];
    let verb = ["PTP", "LIN", "CIRC"]
        .into_iter()
        .find(|v| word.eq_ignore_ascii_case(v))?;
    let mut i = at + word_end;
    let mut targets = Vec::new();
    let wanted = if verb == "CIRC" { 2 } else { 1 };
    while targets.len() < wanted {
        let skip = line[i..].len() - line[i..].trim_start().len();
        i += skip;
        if !targets.is_empty() {
            i += line[i..].strip_prefix(',').map(|_| 1)?;
            i += line[i..].len() - line[i..].trim_start().len();
        } else if skip == 0 {
            return None;
        }
        if !line[i..].starts_with('{') {
            return None;
        }
        let end = group_end(line, i)?;
        let kind = krl_aggregate(&line[i + 1..end - 1])?;
        if verb != "PTP" && kind == Kind::Axis {
            return None;
        }
        // The declaration's value: the aggregate as written, without a type before `:` (the
        // declaration gives the type).
        let inner = &line[i + 1..end - 1];
        let text = match inner.split_once(':') {
            Some((_, rest)) => format!("{{{}}}", rest.trim()),
            None => line[i..end].to_owned(),
        };
        targets.push(Target {
            range: i..end,
            kind,
            text,
        });
        i = end;
    }
    let rest = &line[i..];
    // A comment or anything else after the approximation: not a plain motion.
    if rest.contains(';') || rest.contains(',') || rest.contains('{') {
        return None;
    }
    if !rest.trim().is_empty() && !rest.starts_with(char::is_whitespace) {
        return None;
    }
    Some(Motion {
        verb,
        targets,
        rest: rest.trim().to_owned(),
    })
}

/// A KRL aggregate of numbers (its text between the braces): its kind. The `.dat` declares the
/// aggregate as written (`{X 1, Y 2, …}`).
fn krl_aggregate(inner: &str) -> Option<Kind> {
    let mut inner = inner.trim();
    let mut ty = None;
    if let Some((t, rest)) = inner.split_once(':') {
        let t = t.trim();
        let is = |w: &str| t.eq_ignore_ascii_case(w);
        ty = Some(if is("POS") || is("E6POS") || is("FRAME") {
            Kind::Cartesian
        } else if is("AXIS") || is("E6AXIS") {
            Kind::Axis
        } else {
            return None;
        });
        inner = rest.trim();
    }
    // Which keys were seen, one bit each: a key twice is no position.
    let mut seen = 0u32;
    for item in inner.split(',') {
        let mut w = item.split_ascii_whitespace();
        let (key, value) = (w.next()?, w.next()?);
        if w.next().is_some() || !is_number(value) {
            return None;
        }
        let k = key_index(key)?;
        if seen & (1 << k) != 0 {
            return None;
        }
        seen |= 1 << k;
    }
    let cartesian = seen & 0xff != 0;
    let axis = seen & (0x3f << 8) != 0;
    match (cartesian, axis, ty) {
        (true, false, None | Some(Kind::Cartesian)) => Some(Kind::Cartesian),
        (false, true, None | Some(Kind::Axis)) => Some(Kind::Axis),
        _ => None,
    }
}

/// A component's bit in [`krl_aggregate`]: `X Y Z A B C S T` are 0–7 (a position), `A1`–`A6`
/// 8–13 and `E1`–`E6` 14–19 (the axes).
fn key_index(key: &str) -> Option<usize> {
    match *key.as_bytes() {
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
    let mut targets = Vec::new();
    while targets.len() < n {
        if !targets.is_empty() {
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
        targets.push(Target {
            range: i..end,
            kind,
            text: line[i..end].to_owned(),
        });
        i = end;
    }
    if !line[i..].trim_start().starts_with(',') {
        return None;
    }
    Some(Motion {
        verb,
        targets,
        rest: String::new(),
    })
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
    let mut targets = Vec::new();
    while targets.len() < n {
        i += line[i..].len() - line[i..].trim_start().len();
        if !targets.is_empty() {
            i += line[i..].strip_prefix(',').map(|_| 1)?;
            i += line[i..].len() - line[i..].trim_start().len();
        }
        let (start, kind) = if line[i..].starts_with("p[") {
            (i + 1, Kind::Cartesian)
        } else if line[i..].starts_with('[') && verb == "movej" && targets.is_empty() {
            (i, Kind::Axis)
        } else {
            return None;
        };
        let end = group_end(line, start)?;
        let groups = number_groups(&line[start..end])?;
        if groups.len() != 1 || groups[0].len() != 6 {
            return None;
        }
        targets.push(Target {
            range: i..end,
            kind,
            text: line[i..end].to_owned(),
        });
        i = end;
    }
    let after = line[i..].trim_start();
    if !(after.starts_with(',') || after.starts_with(')')) {
        return None;
    }
    Some(Motion {
        verb,
        targets,
        rest: String::new(),
    })
}
