//! Program splitting (docs/LANGUAGES.md, "Long programs"): a program whose steps take more
//! lines than its language's limit is cut between blocks of the program tree's top level into
//! parts that the main program calls one after another: KRL sub-programs in files of their own
//! (`P_1.src`/`P_1.dat`), RAPID modules of their own (`P_1.mod`, routine `P_1_run`), URScript
//! functions in the same script (`P_1()`). A loop, a selection, a state machine or a handshake
//! of a cell is one block of the top level, so structured flow never spans two parts; a block
//! longer than the limit makes a part of its own (`W310`).
//!
//! The writers record where each top-level block begins in their text ([`Generated::cuts`]);
//! this module only cuts that text and writes what each language needs around a part:
//!
//! - the variables a part shares with the main program are the same variables, passed by
//!   reference (KRL `:OUT`, RAPID `VAR` parameters) or global (URScript), so a part runs exactly as its
//!   blocks ran in the unsplit program;
//! - the writer's own variables that live within one block (the selection's `skp_branch`, a
//!   machine's `skp_state`, RAPID's loop flags) are declared in the part itself;
//! - KRL: a part's `.dat` declares the `SIGNAL`s it reads and the variables of the routines it
//!   holds (a copy of the program's routines: KRL calls a routine of another file only when it
//!   is global);
//! - every part names its program in a marker comment (`skillpost part 2 of P`), by which a
//!   later compile that needs fewer parts finds the files it may remove (`write::stale`).

use std::collections::HashSet;
use std::ops::Range;

use super::{EmitInput, Generated, Language, OutputFile};
use crate::diag::{Code, Diagnostic, Diagnostics};

/// The default limit of KRL programs: lines of the steps block. KUKA publishes no hard limit
/// for a `.src`; programs of more than 5,000 lines are reported to load and run, the pendant's
/// editor being what slows down (docs/LANGUAGES.md).
pub const DEFAULT_KRL: usize = 5000;
/// The default limit of RAPID modules (RoboDK's ABB post-processors cut at 5,000 lines).
pub const DEFAULT_RAPID: usize = 5000;
/// URScript: not split unless asked (parts would stay in the same script, which the
/// controller receives whole; RoboDK does not split UR programs either).
pub const DEFAULT_URSCRIPT: usize = 0;

/// The limit per language (`None`: the default); 0 never splits.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Limits {
    pub krl: Option<usize>,
    pub rapid: Option<usize>,
    pub urscript: Option<usize>,
}

impl Limits {
    /// The same limit for every language.
    pub fn all(n: usize) -> Self {
        Limits {
            krl: Some(n),
            rapid: Some(n),
            urscript: Some(n),
        }
    }

    /// The limit of `language`'s programs (0: never split).
    pub fn of(&self, language: Language) -> usize {
        match language {
            Language::Krl => self.krl.unwrap_or(DEFAULT_KRL),
            Language::Rapid => self.rapid.unwrap_or(DEFAULT_RAPID),
            Language::UrScript => self.urscript.unwrap_or(DEFAULT_URSCRIPT),
        }
    }

    /// Parses `N` (every language) or `LANG=N`, over `self`.
    pub fn set(&mut self, arg: &str) -> Result<(), String> {
        let (lang, n) = match arg.split_once('=') {
            Some((l, n)) => (
                Some(
                    Language::parse(l)
                        .ok_or_else(|| format!("`{l}` is no language: krl, rapid or urscript"))?,
                ),
                n,
            ),
            None => (None, arg),
        };
        let n: usize = n
            .trim()
            .parse()
            .map_err(|_| format!("`{}` is not a number of lines (0 never splits)", n.trim()))?;
        match lang {
            None => *self = Limits::all(n),
            Some(Language::Krl) => self.krl = Some(n),
            Some(Language::Rapid) => self.rapid = Some(n),
            Some(Language::UrScript) => self.urscript = Some(n),
        }
        Ok(())
    }
}

/// One part of a split program.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Part {
    /// The routine the main program calls (`P_1`, RAPID `P_1_run`).
    pub routine: String,
    /// Its file (`P_1.src`), or the program's own for URScript.
    pub file: String,
    /// The blocks of the program tree's top level it holds.
    pub blocks: Range<usize>,
}

/// The marker comment of part `n` of `program` (without the comment character): what
/// `write::stale` looks for before it removes a part a later compile no longer writes.
pub fn marker(n: usize, program: &str) -> String {
    format!("skillpost part {n} of {program}")
}

/// A split program: its parts and the texts of the files they need.
pub struct Split {
    pub parts: Vec<Part>,
    /// KRL: the program's own routines (a cell's handshakes), which each part's file holds too.
    routines: Vec<String>,
    /// Per part: its steps text and the declarations it takes from the program.
    texts: Vec<PartText>,
}

struct PartText {
    steps: String,
    /// Variables passed to it (declaration lines of the program).
    params: Vec<String>,
    /// Declarations it holds itself (KRL: its `.dat`; RAPID: its routine's `VAR`s).
    own: Vec<String>,
}

/// The name a declaration line declares (`DECL BOOL skp_tx1=FALSE`, `SIGNAL G $IN[1] TO
/// $IN[4]`, `VAR num skp_branch := 0;`), and whether it is a `SIGNAL`.
fn declared(line: &str) -> Option<(&str, bool)> {
    let mut w = line.split_whitespace();
    let first = w.next()?;
    let signal = first.eq_ignore_ascii_case("SIGNAL");
    let name = if signal { w.next()? } else { w.nth(1)? };
    let end = name
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .unwrap_or(name.len());
    (end > 0).then(|| (&name[..end], signal))
}

/// Which of `names` (lower-cased when `fold`: KRL and RAPID names are case-insensitive) stand
/// in `text` as identifiers (outside strings). Only identifiers as long as one of `names` are
/// looked up, through one reused buffer: a part's text is megabytes of step code.
fn used_names(text: &str, names: &HashSet<String>, fold: bool) -> HashSet<String> {
    if names.is_empty() {
        // (A program of only points and steps: nothing to look for in megabytes of text.)
        return HashSet::new();
    }
    let mut lengths = 0u128;
    for n in names {
        lengths |= 1u128 << n.len().min(127);
    }
    // Each byte's class: what may start a name, what may go on with one, a quote.
    const START: u8 = 1;
    const GOES_ON: u8 = 2;
    const QUOTE: u8 = 4;
    const CLASS: [u8; 256] = {
        let mut t = [0u8; 256];
        let mut c = 0;
        while c < 256 {
            let b = c as u8;
            t[c] = if b.is_ascii_alphabetic() || b == b'_' {
                START | GOES_ON
            } else if b.is_ascii_digit() {
                GOES_ON
            } else if b == b'"' {
                QUOTE
            } else {
                0
            };
            c += 1;
        }
        t
    };
    let mut out = HashSet::new();
    let mut buf = String::new();
    let b = text.as_bytes();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        let class = CLASS[usize::from(c)];
        if class & START != 0 {
            let start = i;
            i += 1;
            while i < b.len() && CLASS[usize::from(b[i])] & GOES_ON != 0 {
                i += 1;
            }
            let w = &text[start..i];
            if lengths & (1u128 << w.len().min(127)) == 0 {
                continue;
            }
            buf.clear();
            buf.push_str(w);
            if fold {
                buf.make_ascii_lowercase();
            }
            if names.contains(&buf) && !out.contains(&buf) {
                out.insert(buf.clone());
            }
        } else if class == QUOTE {
            // Strings hold no names.
            i += 1;
            while i < b.len() && b[i] != b'"' && b[i] != b'\n' {
                i += 1;
            }
            i += 1;
        } else {
            i += 1;
        }
    }
    out
}

/// Whether a KRL declaration is a named point or an inline form's data
/// ([`super::points`]): a part holds its own in its `.dat`.
fn is_point_data(line: &str) -> bool {
    line.strip_prefix("DECL ").is_some_and(|rest| {
        ["E6POS ", "E6AXIS ", "FDAT ", "PDAT ", "LDAT "]
            .iter()
            .any(|p| rest.starts_with(p))
    })
}

/// Whether `name` is one of the writer's variables that live within one block: set before the
/// block uses it, so a part may hold its own.
fn block_local(name: &str) -> bool {
    let n = name.to_ascii_lowercase();
    n == crate::lang::BRANCH_VAR.to_ascii_lowercase()
        || n == super::structured::STATE_VAR
        || n.strip_prefix("skp_loop")
            .is_some_and(|d| !d.is_empty() && d.bytes().all(|c| c.is_ascii_digit()))
}

/// The name of part `n` of `program` within `max` characters (the program's name shortened
/// where it would be longer), with `suffix` after it.
fn part_name(program: &str, n: usize, suffix: &str, max: usize) -> String {
    let tail = format!("_{n}{suffix}");
    let keep = max.saturating_sub(tail.len()).min(program.len());
    format!("{}{tail}", &program[..keep])
}

/// The file stem of part `n` of `program` in `language` (`P_2`).
pub fn part_stem(program: &str, n: usize, language: Language) -> String {
    let (max, suffix) = name_rule(language);
    part_name(program, n, "", max - suffix.len())
}

/// The longest routine name of `language`, and what a part's routine adds to its file stem.
fn name_rule(language: Language) -> (usize, &'static str) {
    match language {
        Language::Krl => (24, ""),
        Language::Rapid => (32, "_run"),
        Language::UrScript => (63, ""),
    }
}

/// Which top-level blocks go into which part: greedy, a part takes blocks while its lines stay
/// within `limit`; `None` when the program fits.
fn plan_parts(lines: &[usize], limit: usize) -> Option<Vec<Range<usize>>> {
    let total: usize = lines.iter().sum();
    if limit == 0 || total <= limit || lines.is_empty() {
        return None;
    }
    let mut parts = Vec::new();
    let (mut start, mut cur) = (0, 0);
    for (k, &n) in lines.iter().enumerate() {
        if cur > 0 && cur + n > limit {
            parts.push(start..k);
            start = k;
            cur = 0;
        }
        cur += n;
    }
    parts.push(start..lines.len());
    (parts.len() > 1).then_some(parts)
}

/// Splits the program when its steps are longer than `input.max_lines`: `generated.steps`
/// becomes the main program's (what comes before the first block, the calls of the parts, what
/// comes after the last), and for URScript the parts' functions join `generated.routines`.
/// `None`: not split.
pub fn split(
    input: &EmitInput,
    generated: &mut Generated,
    diags: &mut Diagnostics,
) -> Option<Split> {
    let cuts = &generated.cuts;
    if input.max_lines == 0 || cuts.len() < 2 {
        return None;
    }
    let steps = &generated.steps;
    let lines: Vec<usize> = cuts
        .windows(2)
        .map(|w| memchr::memchr_iter(b'\n', &steps.as_bytes()[w[0]..w[1]]).count())
        .collect();
    let ranges = plan_parts(&lines, input.max_lines)?;
    let lang = input.profile.language();
    let program = input.program;
    let (max_name, suffix) = name_rule(lang);
    let fold = lang != Language::UrScript;
    let ext = input.profile.files()[0];
    let nl = input.newline;
    let base = input.steps_indent;
    let key = |name: &str| {
        if fold {
            name.to_ascii_lowercase()
        } else {
            name.to_owned()
        }
    };
    // KRL's points are found by their blocks ([`Generated::point_cuts`]), not by name.
    let points = &generated.point_cuts;
    let point_range = |r: &Range<usize>| -> Range<usize> {
        if points.len() == cuts.len() {
            points[r.start]..points[r.end]
        } else {
            0..0
        }
    };
    // The names the declarations other than points declare, and each declaration's index by
    // its name (one pass: a program of 100,000 points has as many declarations).
    let mut declared_names: HashSet<String> = HashSet::new();
    let mut by_name: std::collections::HashMap<String, Vec<usize>> =
        std::collections::HashMap::new();
    for (i, d) in generated.declarations.iter().enumerate() {
        if is_point_data(d) {
            continue;
        }
        if let Some((n, _)) = declared(d) {
            let k = key(n);
            by_name.entry(k.clone()).or_default().push(i);
            declared_names.insert(k);
        }
    }
    // The declared names the program's own routines use (KRL: held by every part's file).
    let routine_words = used_names(&generated.routines.join("\n"), &declared_names, fold);
    let mut parts = Vec::new();
    let mut texts = Vec::new();
    let mut calls = String::new();
    for (k, r) in ranges.iter().enumerate() {
        let n = k + 1;
        let text = &steps[cuts[r.start]..cuts[r.end]];
        let part_lines: usize = lines[r.clone()].iter().sum();
        if part_lines > input.max_lines {
            let first = first_step(input, &input.body[r.clone()]);
            diags.push(Diagnostic::warning(
                Code::LongPart,
                format!(
                    "part {n} of {program} holds {part_lines} lines, more than the limit of {}: it is one block of the program's top level (a loop, a selection, a state machine or a handshake){first}, and structured flow is never cut",
                    input.max_lines
                ),
            ));
        }
        let used = used_names(text, &declared_names, fold);
        let mut params = Vec::new();
        let mut own = Vec::new();
        // The declarations the part uses, in the program's order (looked up by name: a
        // program of 100,000 points has as many declarations).
        let mut wanted: Vec<usize> = used
            .iter()
            .chain(routine_words.iter().filter(|_| lang == Language::Krl))
            .filter_map(|k| by_name.get(k))
            .flatten()
            .copied()
            .collect();
        wanted.sort_unstable();
        wanted.dedup();
        for i in wanted {
            let d = &generated.declarations[i];
            let Some((name, signal)) = declared(d) else {
                continue;
            };
            let by_routines = lang == Language::Krl && routine_words.contains(&key(name));
            if signal || by_routines || block_local(name) {
                own.push(d.clone());
            } else {
                params.push(d.clone());
            }
        }
        // A KRL part's points and their inline forms' data are its `.dat`'s: the technician
        // touches them up there.
        // (Moved, not copied: the main `.dat` loses them below.)
        own.extend(
            generated.declarations[point_range(r)]
                .iter_mut()
                .map(std::mem::take),
        );
        let routine = part_name(program, n, suffix, max_name);
        let stem = part_name(program, n, "", max_name - suffix.len());
        let file = match lang {
            Language::UrScript => format!("{program}.{ext}"),
            _ => format!("{stem}.{ext}"),
        };
        // The call in the main program.
        let names: Vec<&str> = params
            .iter()
            .filter_map(|d| declared(d))
            .map(|d| d.0)
            .collect();
        let (comment, call) = match lang {
            Language::Krl => (
                format!(";part {n} of {}: {file}", ranges.len()),
                format!("{routine}({})", names.join(", ")),
            ),
            Language::Rapid if names.is_empty() => (
                format!("! part {n} of {}: {file}", ranges.len()),
                format!("{routine};"),
            ),
            Language::Rapid => (
                format!("! part {n} of {}: {file}", ranges.len()),
                format!("{routine} {};", names.join(", ")),
            ),
            Language::UrScript => (
                format!("# part {n} of {}", ranges.len()),
                format!("{routine}()"),
            ),
        };
        for l in [comment, call] {
            calls.push_str(base);
            calls.push_str(&l);
            calls.push_str(nl);
        }
        parts.push(Part {
            routine,
            file,
            blocks: r.clone(),
        });
        texts.push(PartText {
            // Taken out of the program's text below.
            steps: String::new(),
            params,
            own,
        });
    }
    let last = cuts[ranges[ranges.len() - 1].end];
    // The parts' texts are taken from the end of the program's text, which shrinks as they
    // are: the program is not held twice (100,000 steps).
    let suffix = steps[last..].to_owned();
    let mut main = std::mem::take(&mut generated.steps);
    main.truncate(last);
    for (t, r) in texts.iter_mut().zip(&ranges).rev() {
        let start = cuts[r.start];
        t.steps = main[start..].to_owned();
        main.truncate(start);
        main.shrink_to_fit();
    }
    main.reserve(calls.len() + suffix.len());
    main.push_str(&calls);
    main.push_str(&suffix);
    // The main `.dat` keeps the points of the blocks it still holds, not the parts'.
    let moved = point_range(&(ranges[0].start..ranges[ranges.len() - 1].end));
    if lang == Language::UrScript {
        urscript_functions(input, generated, &main, &parts, &texts);
    }
    if !moved.is_empty() {
        generated.declarations.drain(moved);
    }
    generated.steps = main;
    let routines = match lang {
        Language::Krl => generated.routines.clone(),
        _ => Vec::new(),
    };
    Some(Split {
        parts,
        routines,
        texts,
    })
}

/// `, from step X (localId n)`: the first step of `blocks`, for a message.
fn first_step(input: &EmitInput, blocks: &[crate::plan::Block]) -> String {
    let mut first = None;
    crate::plan::visit(blocks, &mut |b| {
        if first.is_none()
            && let crate::plan::Block::Step(i) = b
        {
            first = Some(*i);
        }
    });
    match first {
        Some(i) => {
            let e = &input.sfc.elements[i];
            let name = match &e.kind {
                crate::model::ElementKind::Step(s) => crate::names::transliterate(&s.name),
                _ => String::new(),
            };
            format!(", whose first step is {name} (localId {})", e.local_id)
        }
        None => String::new(),
    }
}

/// URScript: the parts become functions of the script, defined before the steps (with the
/// IRL definitions). The variables the main program sets at its top level and a part uses are
/// declared `global` before them with their first value, so the part's assignments reach them
/// (a variable a function assigns is otherwise its own).
fn urscript_functions(
    input: &EmitInput,
    generated: &mut Generated,
    main: &str,
    parts: &[Part],
    texts: &[PartText],
) {
    // `name = value` (or `global name = value`) at the main program's top level.
    let base = input.steps_indent;
    let mut firsts: Vec<(String, String)> = Vec::new();
    for l in main.lines() {
        let Some(rest) = l.strip_prefix(base) else {
            continue;
        };
        if rest.starts_with(' ') {
            continue;
        }
        let rest = rest.strip_prefix("global ").unwrap_or(rest);
        if let Some((name, value)) = rest.split_once(" = ")
            && !name.is_empty()
            && name.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'_')
            && !firsts.iter().any(|(n, _)| n == name)
        {
            firsts.push((name.to_owned(), value.trim_end().to_owned()));
        }
    }
    let names: HashSet<String> = firsts.iter().map(|(n, _)| n.clone()).collect();
    let used: HashSet<String> = texts
        .iter()
        .flat_map(|t| used_names(&t.steps, &names, false))
        .collect();
    let mut lines: Vec<String> = firsts
        .iter()
        .filter(|(n, _)| used.contains(n))
        .map(|(n, v)| format!("global {n} = {v}"))
        .collect();
    for (p, t) in parts.iter().zip(texts) {
        if !lines.is_empty() {
            lines.push(String::new());
        }
        let n = lines.len();
        lines.push(format!("def {}():", p.routine));
        for l in t.steps.lines() {
            let l = l.strip_prefix(base).unwrap_or(l);
            if l.is_empty() {
                lines.push(String::new());
            } else {
                lines.push(format!("  {l}"));
            }
        }
        if lines.len() == n + 1 {
            lines.push("  sync()".to_owned());
        }
        lines.push("end".to_owned());
    }
    if !generated.routines.is_empty() {
        generated.routines.push(String::new());
    }
    generated.routines.extend(lines);
}

impl Split {
    /// The parts' own files (KRL: `.src` and `.dat` each; RAPID: a module each; URScript:
    /// none, its parts are functions of the script). `comment`: the header comment.
    /// Each part's text is dropped once its files are made (100,000 steps: the program's text
    /// is not held twice).
    pub fn files(&mut self, input: &EmitInput, comment: &str) -> Vec<OutputFile> {
        let lang = input.profile.language();
        let nl = input.newline;
        let program = input.program;
        let mut out = Vec::new();
        let texts = std::mem::take(&mut self.texts);
        for (k, (p, t)) in self.parts.iter().zip(texts).enumerate() {
            let n = k + 1;
            let stem = p.file.rsplit_once('.').map_or(p.file.as_str(), |s| s.0);
            let mark = marker(n, program);
            let main_file = format!("{program}.{}", input.profile.files()[0]);
            match lang {
                Language::Krl => {
                    let mut src = String::with_capacity(t.steps.len() + 512);
                    for l in [
                        "&ACCESS RVP".to_owned(),
                        "&REL 1".to_owned(),
                        format!("&COMMENT {comment}"),
                    ] {
                        src.push_str(&l);
                        src.push_str(nl);
                    }
                    // (name, type, array): an array is passed whole, `name[]:OUT`.
                    let params: Vec<(&str, &str, bool)> = t
                        .params
                        .iter()
                        .filter_map(|d| {
                            let mut w = d.split_whitespace();
                            let ty = w.nth(1)?;
                            let array = w.next()?.split('=').next()?.contains('[');
                            Some((declared(d)?.0, ty, array))
                        })
                        .collect();
                    let brackets = |array: bool| if array { "[]" } else { "" };
                    let list: Vec<String> = params
                        .iter()
                        .map(|(n, _, a)| format!("{n}{}:OUT", brackets(*a)))
                        .collect();
                    src.push_str(&format!("DEF {}({})", p.routine, list.join(", ")));
                    src.push_str(nl);
                    for (name, ty, array) in &params {
                        src.push_str(&format!("DECL {ty} {name}{}", brackets(*array)));
                        src.push_str(nl);
                    }
                    src.push_str(&format!(";{mark}: {main_file} calls it"));
                    src.push_str(nl);
                    src.push_str(&t.steps);
                    src.push_str("END");
                    src.push_str(nl);
                    // The IRL definitions and the program's own routines: KRL calls a
                    // routine of another file only when it is global.
                    super::definitions(input, &[], &self.routines, "", &mut src);
                    out.push(OutputFile {
                        extension: "src",
                        text: src,
                        stem: Some(stem.to_owned()),
                        ..Default::default()
                    });
                    let own: usize = t.own.iter().map(|d| d.len() + nl.len()).sum();
                    let mut dat = String::with_capacity(own + 512);
                    for l in [
                        "&ACCESS RVP".to_owned(),
                        "&REL 1".to_owned(),
                        format!("&COMMENT {comment}"),
                        format!("DEFDAT {stem}"),
                        format!(";{mark}"),
                    ] {
                        dat.push_str(&l);
                        dat.push_str(nl);
                    }
                    for d in &t.own {
                        dat.push_str(d);
                        dat.push_str(nl);
                    }
                    dat.push_str("ENDDAT");
                    dat.push_str(nl);
                    out.push(OutputFile {
                        extension: "dat",
                        text: dat,
                        stem: Some(stem.to_owned()),
                        ..Default::default()
                    });
                }
                Language::Rapid => {
                    let mut m = String::with_capacity(t.steps.len() + 512);
                    let params: Vec<String> = t
                        .params
                        .iter()
                        .filter_map(|d| {
                            let ty = d.split_whitespace().nth(1)?;
                            Some(format!("VAR {ty} {}", declared(d)?.0))
                        })
                        .collect();
                    for l in [
                        format!("MODULE {stem}"),
                        format!("  ! {mark}: {main_file} calls {}", p.routine),
                        format!("  ! {comment}"),
                        String::new(),
                        format!("  PROC {}({})", p.routine, params.join(", ")),
                    ] {
                        m.push_str(l.trim_end());
                        m.push_str(nl);
                    }
                    for d in &t.own {
                        m.push_str(input.steps_indent);
                        m.push_str(d);
                        m.push_str(nl);
                    }
                    m.push_str(&t.steps);
                    for l in ["  ENDPROC", "ENDMODULE"] {
                        m.push_str(l);
                        m.push_str(nl);
                    }
                    out.push(OutputFile {
                        extension: "mod",
                        text: m,
                        stem: Some(stem.to_owned()),
                        ..Default::default()
                    });
                }
                Language::UrScript => {}
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_take_blocks_while_they_fit() {
        assert_eq!(plan_parts(&[3, 3, 3], 10), None);
        assert_eq!(plan_parts(&[3, 3, 3], 0), None);
        assert_eq!(plan_parts(&[4, 4, 4], 8), Some(vec![0..2, 2..3]));
        // A block longer than the limit is a part of its own.
        assert_eq!(plan_parts(&[2, 20, 2], 8), Some(vec![0..1, 1..2, 2..3]));
        assert_eq!(plan_parts(&[20], 8), None);
    }

    #[test]
    fn declarations_name_what_they_declare() {
        assert_eq!(
            declared("DECL BOOL skp_tx1=FALSE"),
            Some(("skp_tx1", false))
        );
        assert_eq!(
            declared("DECL KrlMsgPar_T skp_par[3]"),
            Some(("skp_par", false))
        );
        assert_eq!(declared("SIGNAL G $IN[1] TO $IN[4]"), Some(("G", true)));
        assert_eq!(
            declared("VAR num skp_branch := 0;"),
            Some(("skp_branch", false))
        );
        assert!(block_local("SKP_BRANCH") && block_local("skp_loop12") && block_local("skp_state"));
        assert!(!block_local("skp_loop") && !block_local("skp_tx1"));
    }

    #[test]
    fn only_declared_names_outside_strings_are_found() {
        let names: HashSet<String> = ["skp_tx1", "skp_branch"].map(String::from).into();
        let text = "SKP_TX1 = NOT skp_tx1\nMsg = \"skp_branch\"\nskp_tx12 = 1\n";
        let found = used_names(text, &names, true);
        assert_eq!(found, ["skp_tx1".to_owned()].into());
        // URScript: case counts.
        assert!(used_names("SKP_TX1 = 1", &names, false).is_empty());
    }

    #[test]
    fn part_names_fit_the_language() {
        assert_eq!(part_name("Weld", 3, "", 24), "Weld_3");
        assert_eq!(
            part_name(&"A".repeat(24), 12, "", 24),
            format!("{}_12", "A".repeat(21))
        );
        assert_eq!(part_name("M", 1, "_run", 32), "M_1_run");
    }

    #[test]
    fn limits_parse_per_language() {
        let mut l = Limits::default();
        assert_eq!(l.of(Language::Krl), DEFAULT_KRL);
        l.set("rapid=200").unwrap();
        assert_eq!(l.of(Language::Rapid), 200);
        l.set("0").unwrap();
        assert_eq!(l, Limits::all(0));
        assert!(l.set("cobol=3").is_err() && l.set("x").is_err());
    }
}
