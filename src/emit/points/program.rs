//! Which points a program has: whether its literal targets are named (the resource's
//! `Points` attribute), in which form KRL writes them (inline forms unless the program's code
//! sets motion parameters itself), and the words of its code no point may be named.

use super::motion::krl_motion;
use super::{KrlForm, Mode, Points};
use crate::lang::Language;
use crate::names::transliterate;
use std::collections::HashSet;

/// The points of the program `input` writes: how (the program resource's `Points` attribute,
/// `E216` when it is neither `named` nor `inline`), for KRL in which form (`W210` when its code
/// sets motion parameters), and the names its code already uses.
pub fn for_program(
    input: &crate::emit::EmitInput,
    tools: &crate::emit::tool::Tools,
    diags: &mut crate::diag::Diagnostics,
) -> Option<Points> {
    use crate::diag::{Code, Diagnostic};
    let lang = input.profile.language();
    let res = input.bound.resource.map(|r| &input.blackboard.resources[r]);
    let mut mode = Mode::Named;
    let mut forms = false;
    if let Some(r) = res
        && let Some((v, span)) = &r.points_attr
    {
        mode = match v.trim().to_ascii_lowercase().as_str() {
            "named" => Mode::Named,
            "forms" => {
                forms = true;
                Mode::Named
            }
            "inline" => Mode::Literal,
            _ => {
                diags.push(
                    Diagnostic::error(
                        Code::BadPoints,
                        format!(
                            "`Points` is `{}`: it says how motions to literal positions are written, `named` (teachable points, the default), `forms` (named points, in KRL always as inline forms) or `inline` (as the IRL code wrote them){}",
                            v.trim(),
                            crate::names::did_you_mean(v.trim(), ["named", "forms", "inline"])
                        ),
                    )
                    .at(span.clone())
                    .element(r.element.clone()),
                );
                return None;
            }
        };
    }
    // The words the program's code uses that a point's declared name could be.
    let starts: [(u8, u8); 2] = match lang {
        Language::Krl => [(b'x', b'X'), (b'f', b'F')],
        Language::Rapid => [(b'p', b'P'), (b'j', b'J')],
        Language::UrScript => [(b'p', b'P'), (b'q', b'Q')],
    };
    let mut taken = HashSet::new();
    for l in input
        .bound
        .definitions
        .iter()
        .flat_map(|&(i, d)| input.irls[i].definitions[d].lines.iter())
    {
        words(l, &starts, &mut taken);
    }
    // KRL's named points are inline forms unless the program sets motion parameters itself:
    // the first statement that does, in a step or an IRL definition.
    let find_setting = lang == Language::Krl && mode == Mode::Named && !forms;
    // One pass over the steps' code for the words, the steps that may move to a literal
    // position (about as many points) and the first statement that sets motion parameters
    // (100,000 steps: each step's code is read while it is in the cache); a long program's
    // steps in pieces on two threads, each taking the next piece when done with one (its first
    // touch of the code is mostly waiting for memory).
    let steps = &input.bound.steps;
    let scan_of = |from: usize, piece: &[u32]| {
        scan(
            steps.of_table(from, piece),
            &starts,
            mode == Mode::Named,
            find_setting,
        )
    };
    let scans = if steps.len() >= input.read_ahead_from {
        crate::threads::pieces("skillpost-points", steps.table(), SCAN_PIECES, scan_of)
    } else {
        vec![scan_of(0, steps.table())]
    };
    let mut literal = 0;
    let mut found = None;
    for s in scans {
        taken.extend(s.taken);
        literal += s.literal;
        // The first in the program's order.
        found = found.or(s.found);
    }
    let mut found = found.map(|(i, l)| (Ok(i), l));
    if lang == Language::UrScript {
        for w in crate::emit::urscript::KEYWORDS {
            words(w, &starts, &mut taken);
        }
    }
    let mut krl = KrlForm::Inline { tool: 0, base: 0 };
    if let Ok(Some((tool, base))) = tools.krl_numbers() {
        krl = KrlForm::Inline { tool, base };
    }
    if find_setting {
        if found.is_none() {
            found = input.bound.definitions.iter().find_map(|&(i, d)| {
                let def = &input.irls[i].definitions[d];
                def.lines
                    .iter()
                    .find_map(|l| first_setting_motion(l))
                    .map(|l| (Err(def), l.trim().to_owned()))
            });
        }
        // The blackboard's tool, base and load, set by statements before the steps: an inline
        // form's FDAT must say the same tool and base, and set no other load.
        let found = found.map(|(step, statement)| (step.map_err(Some), statement));
        let found = match tools.krl_numbers() {
            Ok(None) => found,
            Ok(Some((tool, base))) => {
                krl = KrlForm::Inline { tool, base };
                found
            }
            Err(statement) => found.or(Some((Err(None), statement))),
        };
        if let Some((step, statement)) = found {
            krl = KrlForm::Named;
            let has_literal = input
                .bound
                .steps
                .unordered()
                .any(|b| b.code.split('\n').any(|l| krl_motion(l).is_some()));
            if has_literal {
                let (whence, at) = match step {
                    Ok(i) => {
                        let e = &input.sfc.elements[i];
                        let name = match &e.kind {
                            crate::model::ElementKind::Step(st) => transliterate(&st.name),
                            _ => String::new(),
                        };
                        (
                            format!("step {name}, localId {}", e.local_id),
                            Some(e.span.clone()),
                        )
                    }
                    Err(Some(def)) => (
                        format!("IRL definition `{}`", def.name.text),
                        Some(def.span.clone()),
                    ),
                    Err(None) => ("the tool, base or load of the blackboard".to_owned(), None),
                };
                let mut d = Diagnostic::warning(
                    Code::PointsNotInline,
                    format!(
                        "program `{}`: points are declared in the .dat and moved to as `PTP XName`, not as KUKA inline forms: `{statement}` ({whence}) sets motion parameters, which an inline form would replace with its own velocity, tool and base; Touch-Up needs an inline form, the points' values in the .dat can still be changed",
                        input.program
                    ),
                );
                if let Some(at) = at {
                    d = d.at(at);
                }
                diags.push(d);
            }
        }
    }
    let mut points = Points::new(lang, mode, krl, taken);
    points.names.reserve(literal);
    points.declarations.reserve(literal);
    Some(points)
}

/// The pieces a long program's steps are scanned in ([`for_program`]).
const SCAN_PIECES: usize = 16;

/// What one pass over steps' code finds (see [`for_program`]).
#[derive(Default)]
struct Scan {
    /// The words a point's declared name may not be, lower-case.
    taken: HashSet<String>,
    /// Steps that may move to a literal position.
    literal: usize,
    /// The first step (its element index) with a statement that sets motion parameters, and
    /// that statement.
    found: Option<(usize, String)>,
}

/// [`Scan`] of `steps`, the first of which is element `from`. `named`: literal targets become
/// points (their steps' words are collected); `find_setting`: look for a statement that sets
/// motion parameters.
fn scan<'s>(
    steps: impl Iterator<Item = (usize, &'s crate::bind::BoundStep)>,
    starts: &[(u8, u8); 2],
    named: bool,
    find_setting: bool,
) -> Scan {
    let mut scan = Scan::default();
    for (i, b) in steps {
        if named && memchr::memchr2(b'{', b'[', b.code.as_bytes()).is_some() {
            scan.literal += 1;
            words(&b.code, starts, &mut scan.taken);
        }
        if find_setting
            && scan.found.is_none()
            && let Some(l) = first_setting_motion(&b.code)
        {
            scan.found = Some((i, l.trim().to_owned()));
        }
    }
    scan
}

/// The words (letters, digits, `_`) of `text` of more than one character that begin with one
/// of `starts` (upper or lower case), lower-case, into `taken`: each such letter found
/// (memchr), then its word.
fn words(text: &str, starts: &[(u8, u8); 2], taken: &mut HashSet<String>) {
    let b = text.as_bytes();
    let word = |c: &u8| c.is_ascii_alphanumeric() || *c == b'_';
    for &(lower, upper) in starts {
        for start in memchr::memchr2_iter(lower, upper, b) {
            if start > 0 && word(&b[start - 1]) {
                continue;
            }
            let len = b[start..].iter().take_while(|c| word(c)).count();
            if len > 1 {
                taken.insert(text[start..start + len].to_ascii_lowercase());
            }
        }
    }
}

/// The first of `code`'s lines (separated by `\n`) that [`sets_motion`]: only the lines that
/// hold a `$`, `_` or `(` are read (every step's code, 100,000 steps).
fn first_setting_motion(code: &str) -> Option<&str> {
    let b = code.as_bytes();
    let mut from = 0;
    while let Some(k) = memchr::memchr3(b'$', b'_', b'(', &b[from..]) {
        let at = from + k;
        let start = memchr::memrchr(b'\n', &b[..at]).map_or(0, |i| i + 1);
        let end = memchr::memchr(b'\n', &b[at..]).map_or(b.len(), |i| at + i);
        let line = &code[start..end];
        if sets_motion(line) {
            return Some(line);
        }
        from = end;
    }
    None
}

/// Whether a KRL line sets a motion parameter an inline form sets too: velocity, acceleration,
/// approximation, tool, base, load, the interpolation frame, or the motion data (`BAS(…)`,
/// `PDAT_ACT`, …). Comments are not read.
fn sets_motion(line: &str) -> bool {
    let line = line.as_bytes();
    let code = &line[..memchr::memchr(b';', line).unwrap_or(line.len())];
    // Every statement sets its parameters with `$`, `_` or `BAS(`: most lines have none of
    // them (one pass over every line of every step).
    if memchr::memchr3(b'$', b'_', b'(', code).is_none() {
        return false;
    }
    let has = |needle: &[u8]| {
        code.windows(needle.len())
            .any(|w| w.eq_ignore_ascii_case(needle))
    };
    if memchr::memchr(b'$', code).is_some()
        && [
            &b"$VEL"[..],
            b"$ACC",
            b"$APO",
            b"$TOOL",
            b"$BASE",
            b"$LOAD",
            b"$IPO_MODE",
            b"$ORI_TYPE",
            b"$CIRC_TYPE",
        ]
        .iter()
        .any(|w| has(w))
    {
        return true;
    }
    if memchr::memchr(b'_', code).is_some()
        && [&b"PDAT_ACT"[..], b"LDAT_ACT", b"FDAT_ACT"]
            .iter()
            .any(|w| has(w))
    {
        return true;
    }
    // `BAS(` or `BAS (` as a word of its own: before each `(`, white space, then `BAS` not
    // part of a longer name.
    memchr::memchr_iter(b'(', code).any(|i| {
        let before = code[..i].trim_ascii_end();
        before.len() >= 3
            && before[before.len() - 3..].eq_ignore_ascii_case(b"BAS")
            && before[..before.len() - 3]
                .last()
                .is_none_or(|c| !(c.is_ascii_alphanumeric() || b"_$".contains(c)))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statements_that_set_motion_parameters_are_found() {
        for l in [
            "$VEL.CP = 0.5",
            "  $apo.cdis=10",
            "BAS(#TOOL, 3)",
            "bas (#CP_PARAMS,2)",
            "x=1 BAS  (#INITMOV,0)",
            "PDAT_ACT=PPDAT1",
            "lin_ldat_act=1 LDAT_ACT=L1",
            "BAS\t(#PTP_PARAMS,100)",
            "IF F(1) THEN BAS (#TOOL,1)",
            "A(1) BAS(2)",
        ] {
            assert!(sets_motion(l), "{l}");
        }
        for l in [
            "PTP XPick",
            "SetVelCP (0.5) ; $VEL.CP",
            "BASE_NO = 2",
            "MY_BAS(#TOOL)",
            "$BAS(1)",
            "BAS",
            "BASIS(1)",
            "WAIT FOR $IN[1]",
            "x=F(1) ; BAS(#TOOL)",
            "_BAS(1)",
            "XBAS (1)",
            "BAS X(1)",
            "(",
        ] {
            assert!(!sets_motion(l), "{l}");
        }
        // In a step's code: the first line that does, whichever line it is.
        assert_eq!(
            first_setting_motion("SetVelCP (0.5)\nPTP {X 1}\n  BAS (#TOOL,1)\n$VEL.CP=1"),
            Some("  BAS (#TOOL,1)")
        );
        assert_eq!(first_setting_motion("$VEL.CP=1"), Some("$VEL.CP=1"));
        assert_eq!(first_setting_motion("A(1)\nB\n$IN[1]=X ; $VEL"), None);
        assert_eq!(first_setting_motion("BAS\n(#TOOL)"), None);
        assert_eq!(first_setting_motion(""), None);
    }
}
