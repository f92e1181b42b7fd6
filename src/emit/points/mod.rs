//! Teachable points (docs/LANGUAGES.md, "Points"): a motion whose target is a literal position
//! becomes a motion to a named point, declared where the language keeps its points, so the
//! technician can touch it up at the pendant.
//!
//! - KRL: `PTP {X 100, …}` → `DECL E6POS XPick={X 100,…}` in the `.dat` (`E6AXIS` for
//!   `{A1 …}`), the motion KUKA's inline form (the fold with its `FDAT` and `PDAT`/`LDAT`) when
//!   the program sets no motion parameters itself, else `PTP XPick`;
//! - RAPID: `MoveL [[…],[…],[…],[…]], …` → `CONST robtarget pPick := […];` in the module
//!   (`jointtarget jPick` for `MoveAbsJ`), the motion `MoveL pPick, …`;
//! - URScript: `movel(p[…], …)` → `global pPick = p[…]` at the program's start (`qPick` for a
//!   joint position `[…]`), the motion `movel(pPick, …)`.
//!
//! The IRL snippet stays as its author wrote it; only the emitted line changes. A point is named
//! after its step (`Pick Part` → `PickPart`, a number added when a step has several: `Pick1`,
//! `Pick2`), valid in the language and unique in the program (`_2` added).

use std::borrow::Cow;

use foldhash::{HashMap, HashSet};

use crate::lang::Language;
use crate::names::transliterate;

mod motion;
mod program;
mod taken;

use motion::{Kind, Motion, Target, krl_motion, rapid_motion, ur_motion};
pub use program::for_program;

/// How a KRL program's points are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KrlForm {
    /// KUKA's inline form: Touch-Up and Change work at the pendant. The tool and base numbers
    /// of its `FDAT`.
    Inline { tool: u32, base: u32 },
    /// `PTP XName` with the point in the `.dat`: the program's own velocity, acceleration,
    /// approximation, tool and base stay in effect (an inline form sets its own).
    Named,
}

/// Whether literal targets become named points at all (the resource's `Points` attribute).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Named,
    /// Literal targets stay in the motions (the output of earlier versions).
    Literal,
}

/// The points of one program: their names and declarations, made while its steps are written.
pub struct Points {
    lang: Language,
    krl: KrlForm,
    mode: Mode,
    /// The points' names so far, lower-case (KRL and RAPID ignore case; URScript's are kept
    /// apart without regard to case too).
    names: taken::Names,
    /// The words of the program's code a point's declared name (`XName`, `pName`) may not be,
    /// lower-case.
    words: HashSet<String>,
    /// The longest base name (the language's limit less the prefix).
    max: usize,
    /// Names tried and found taken (for the test that naming is not quadratic).
    tries: usize,
    /// Per stem (lower-case), the last number `_n` given to it.
    next: HashMap<String, usize>,
    /// The step being written, read here when it was not read ahead (kept between steps for
    /// its allocations).
    read: ReadAhead,
    /// Buffers kept from step to step: a name's stem and its lower-case form, a numbered
    /// name's lower-case form, the names of a motion's points, the step's code as written.
    stem: String,
    lower: String,
    numbered: String,
    /// A declared name being looked up ([`Points::free`]).
    full: String,
    names_buf: [String; 2],
    out: String,
    /// The declarations, in order: `.dat` lines (KRL), module data (RAPID), the program's first
    /// lines (URScript).
    pub declarations: Vec<String>,
    /// KRL inline forms: `PDAT`s and `CPDAT`s numbered so far.
    pdat: usize,
    cpdat: usize,
    /// Points named so far.
    pub count: usize,
}

/// How many digits `n` has in decimal.
fn decimal_len(n: usize) -> usize {
    n.checked_ilog10().map_or(1, |d| d as usize + 1)
}

impl Points {
    /// The points of a program in `lang`. `taken`: names the program already uses (its signals,
    /// routines, the words of its IRL code), which no point may get.
    pub fn new(
        lang: Language,
        mode: Mode,
        krl: KrlForm,
        taken: impl IntoIterator<Item = String>,
    ) -> Self {
        let max = match lang {
            // `X` + name and `F` + name are KRL names of at most 24 characters.
            Language::Krl => 23,
            Language::Rapid => 31,
            Language::UrScript => 62,
        };
        Points {
            lang,
            krl,
            mode,
            names: taken::Names::new(),
            words: taken.into_iter().map(|w| w.to_ascii_lowercase()).collect(),
            max,
            next: HashMap::default(),
            tries: 0,
            read: ReadAhead::default(),
            stem: String::new(),
            lower: String::new(),
            numbered: String::new(),
            full: String::new(),
            names_buf: [String::new(), String::new()],
            out: String::new(),
            declarations: Vec::new(),
            pdat: 0,
            cpdat: 0,
            count: 0,
        }
    }

    /// Step `step`'s code with every literal target named. Lines are separated by `\n`.
    pub fn step_code<'s>(&'s mut self, step: &str, code: &'s str) -> &'s str {
        if self.mode == Mode::Literal {
            return code;
        }
        // Read here as it would have been ahead: one way of reading a step.
        let mut read = std::mem::take(&mut self.read);
        read.clear();
        read.read(self.lang, 0, step, code);
        let named = !read.items[0].motions.is_empty();
        if named {
            self.rewrite(code, &read.motions, &read.bases);
        }
        self.read = read;
        if named { &self.out } else { code }
    }

    /// [`Points::step_code`] of item `k` of `read`, read ahead of the writer (on another
    /// thread): the same text.
    pub fn step_code_read<'s>(&'s mut self, code: &'s str, read: &ReadAhead, k: usize) -> &'s str {
        let item = &read.items[k];
        if self.mode == Mode::Literal || item.motions.is_empty() {
            return code;
        }
        self.rewrite(
            code,
            &read.motions[item.motions.clone()],
            &read.bases[item.base.clone()],
        );
        &self.out
    }

    /// `code` with the targets of `motions` (each with its line's start and length) named
    /// after `base`, into `self.out`.
    fn rewrite(&mut self, code: &str, motions: &[(usize, usize, Motion)], base: &str) {
        let targets: usize = motions.iter().map(|(_, _, m)| m.targets().len()).sum();
        let mut out = std::mem::take(&mut self.out);
        out.clear();
        let mut names = std::mem::take(&mut self.names_buf);
        let mut k = 0;
        let mut at = 0;
        for (start, len, m) in motions {
            // The lines before, as written.
            out.push_str(&code[at..*start]);
            let line = &code[*start..start + len];
            for name in names.iter_mut().take(m.targets().len()) {
                k += 1;
                self.name(base, (targets > 1).then_some(k), name);
            }
            self.write(line, m, &names[..m.targets().len()], &mut out);
            at = start + len;
        }
        out.push_str(&code[at..]);
        self.names_buf = names;
        self.out = out;
    }

    /// A unique name from `base` and the number of the point in its step, into `name`.
    fn name(&mut self, base: &str, k: Option<usize>, name: &mut String) {
        let mut stem = std::mem::take(&mut self.stem);
        stem.clear();
        // (`base` is ASCII.)
        stem.push_str(&base[..base.len().min(self.max)]);
        if let Some(k) = k {
            stem.truncate(self.max - decimal_len(k));
            super::flow::push_decimal(&mut stem, k as u64);
        }
        let mut lower = std::mem::take(&mut self.lower);
        lower.clear();
        lower.push_str(&stem);
        lower.make_ascii_lowercase();
        // A stem that was taken before goes on at its next number (many steps of one name:
        // not quadratic); only stems taken twice are recorded.
        let mut n = match self.next.get(lower.as_str()).copied() {
            Some(n) => n,
            None if self.free(&lower) => {
                self.names.insert(&lower);
                self.count += 1;
                name.clear();
                name.push_str(&stem);
                self.stem = stem;
                self.lower = lower;
                return;
            }
            None => 1,
        };
        loop {
            self.tries += 1;
            n += 1;
            let keep = stem.len().min(self.max - 1 - decimal_len(n));
            name.clear();
            name.push_str(&stem[..keep]);
            name.push('_');
            super::flow::push_decimal(name, n as u64);
            // (`stem` is ASCII: its lower-case form cut at the same place.)
            let mut numbered = std::mem::take(&mut self.numbered);
            numbered.clear();
            numbered.push_str(&lower[..keep]);
            numbered.push_str(&name[keep..]);
            let free = self.free(&numbered);
            if free {
                self.names.insert(&numbered);
            }
            self.numbered = numbered;
            if free {
                match self.next.get_mut(lower.as_str()) {
                    Some(last) => *last = n,
                    None => {
                        self.next.insert(lower.clone(), n);
                    }
                }
                self.count += 1;
                self.stem = stem;
                self.lower = lower;
                return;
            }
        }
    }

    /// The letters before a point's name in the names the language declares for it.
    fn prefixes(&self) -> &'static [u8; 2] {
        match self.lang {
            Language::Krl => b"xf",
            Language::Rapid => b"pj",
            Language::UrScript => b"pq",
        }
    }

    /// Whether the name whose lower-case form is `lower` may be a point's: not a point's
    /// already, none of its declared names a word of the program's code or a keyword, and not
    /// KUKA's own (`XHOME`, `XHOME1` … in `$config.dat`) or skillpost's (`skp_…`).
    fn free(&mut self, lower: &str) -> bool {
        let b = lower.as_bytes();
        if b.starts_with(b"skp_") {
            return false;
        }
        if self.lang == Language::Krl
            && b.starts_with(b"home")
            && b[4..].iter().all(u8::is_ascii_digit)
        {
            return false;
        }
        if self.names.contains(lower) {
            return false;
        }
        // The declared names, `x` + name …, in a kept buffer.
        let mut full = std::mem::take(&mut self.full);
        let mut free = true;
        for &p in self.prefixes() {
            full.clear();
            full.push(char::from(p));
            full.push_str(lower);
            let full = full.as_str();
            let keyword = match self.lang {
                // (No KRL keyword is longer than 16 characters.)
                Language::Krl => full.len() <= 16 && crate::names::is_krl_keyword(full),
                Language::Rapid => full == "pers" || full == "proc",
                Language::UrScript => false,
            };
            if keyword || (!self.words.is_empty() && self.words.contains(full)) {
                free = false;
                break;
            }
        }
        self.full = full;
        free
    }

    /// Writes the motion of `line` to the named points and declares them.
    fn write(&mut self, line: &str, m: &Motion, names: &[String], out: &mut String) {
        let indent = &line[..line.len() - line.trim_start().len()];
        match self.lang {
            Language::Krl => self.write_krl(line, indent, m, names, out),
            Language::Rapid | Language::UrScript => {
                // `pName` for a position, `jName` (RAPID) or `qName` (URScript) for the axes:
                // the prefixes `free` keeps apart.
                let [cartesian, axis] = *self.prefixes();
                let prefix = |t: &Target| {
                    char::from(if t.kind == Kind::Axis {
                        axis
                    } else {
                        cartesian
                    })
                };
                let mut at = 0;
                for (t, n) in m.targets().iter().zip(names) {
                    let head = match (self.lang, t.kind) {
                        (Language::Rapid, Kind::Cartesian) => "CONST robtarget ",
                        (Language::Rapid, Kind::Axis) => "CONST jointtarget ",
                        _ => "global ",
                    };
                    let mut d = String::with_capacity(head.len() + n.len() + 6 + t.value_len());
                    d.push_str(head);
                    d.push(prefix(t));
                    d.push_str(n);
                    d.push_str(if self.lang == Language::Rapid {
                        " := "
                    } else {
                        " = "
                    });
                    t.push_value(line, &mut d);
                    if self.lang == Language::Rapid {
                        d.push(';');
                    }
                    self.declarations.push(d);
                    out.push_str(&line[at..t.range.start]);
                    out.push(prefix(t));
                    out.push_str(n);
                    at = t.range.end;
                }
                out.push_str(&line[at..]);
            }
        }
    }

    fn write_krl(
        &mut self,
        line: &str,
        indent: &str,
        m: &Motion,
        names: &[String],
        out: &mut String,
    ) {
        for (t, n) in m.targets().iter().zip(names) {
            let ty = match t.kind {
                Kind::Cartesian => "DECL E6POS X",
                Kind::Axis => "DECL E6AXIS X",
            };
            let mut d = String::with_capacity(ty.len() + n.len() + 1 + t.value_len());
            d.push_str(ty);
            d.push_str(n);
            d.push('=');
            t.push_value(line, &mut d);
            self.declarations.push(d);
        }
        let verb = m.verb;
        let approx = &line[m.rest.clone()];
        // `PTP XName`, `CIRC XAux, XTarget C_DIS`.
        let push_motion = |out: &mut String| {
            out.push_str(verb);
            for (i, n) in names.iter().enumerate() {
                out.push_str(if i == 0 { " X" } else { ", X" });
                out.push_str(n);
            }
            if !approx.is_empty() {
                out.push(' ');
                out.push_str(approx);
            }
        };
        let KrlForm::Inline { tool, base } = self.krl else {
            out.push_str(indent);
            push_motion(out);
            return;
        };
        if !krl_approximation(approx) {
            // An inline form knows only its own approximation words.
            out.push_str(indent);
            push_motion(out);
            return;
        }
        let mut motion = String::new();
        push_motion(&mut motion);
        // The target is the last point; a CIRC's auxiliary point comes first.
        let target = names.last().expect("a motion has a target");
        let cont = if approx.is_empty() { "" } else { " CONT" };
        let (header, data_act, params) = if verb == "PTP" {
            self.pdat += 1;
            let d = format!("PDAT{}", self.pdat);
            self.declarations.push(format!(
                "DECL PDAT P{d}={{VEL 100,ACC 100,APO_DIST 100,APO_MODE #CDIS,GEAR_JERK 50,EXAX_IGN 0}}"
            ));
            (
                format!(
                    ";FOLD PTP {target}{cont} Vel=100 % {d} Tool[{tool}] Base[{base}];%{{PE}}%R 8.3.40,%MKUKATPBASIS,%CMOVE,%VPTP,%P 1:PTP, 2:{target}, 3:{approx}, 5:100, 7:{d}"
                ),
                format!("PDAT_ACT=P{d}"),
                "BAS(#PTP_PARAMS,100)",
            )
        } else {
            self.cpdat += 1;
            let d = format!("CPDAT{}", self.cpdat);
            self.declarations.push(format!(
                "DECL LDAT L{d}={{VEL 2,ACC 100,APO_DIST 100,APO_FAC 50,AXIS_VEL 100,AXIS_ACC 100,ORI_TYP #VAR,CIRC_TYP #BASE,JERK_FAC 50,GEAR_JERK 50,EXAX_IGN 0}}"
            ));
            let header = if verb == "CIRC" {
                let aux = &names[0];
                format!(
                    ";FOLD CIRC {aux} {target}{cont} Vel=2 m/s {d} Tool[{tool}] Base[{base}];%{{PE}}%R 8.3.40,%MKUKATPBASIS,%CMOVE,%VCIRC,%P 1:CIRC, 2:{aux}, 3:{target}, 4:{approx}, 6:2, 8:{d}"
                )
            } else {
                format!(
                    ";FOLD LIN {target}{cont} Vel=2 m/s {d} Tool[{tool}] Base[{base}];%{{PE}}%R 8.3.40,%MKUKATPBASIS,%CMOVE,%VLIN,%P 1:LIN, 2:{target}, 3:{approx}, 5:2, 7:{d}"
                )
            };
            (header, format!("LDAT_ACT=L{d}"), "BAS(#CP_PARAMS,2)")
        };
        for n in names {
            self.declarations.push(format!(
                "DECL FDAT F{n}={{TOOL_NO {tool},BASE_NO {base},IPO_FRAME #BASE,POINT2[] \" \",TQ_STATE FALSE}}"
            ));
        }
        for l in [
            header.as_str(),
            "$BWDSTART=FALSE",
            &data_act,
            &format!("FDAT_ACT=F{target}"),
            params,
            &motion,
            ";ENDFOLD",
        ] {
            if !out.is_empty() && !out.ends_with('\n') {
                out.push('\n');
            }
            out.push_str(indent);
            out.push_str(l);
        }
    }
}

/// The approximation words a KRL inline form writes after its point (`C_PTP`, `C_DIS`, …); an
/// empty text is exact positioning.
fn krl_approximation(rest: &str) -> bool {
    rest.split_whitespace()
        .all(|w| ["C_PTP", "C_DIS", "C_VEL", "C_ORI"].contains(&w.to_ascii_uppercase().as_str()))
        && rest.split_whitespace().count() <= 2
}

/// A point's name from its step's name: its words (transliterated, letters and digits) joined,
/// each after the first starting upper-case (`Pick part` → `PickPart`); `P` first when it would
/// not start with a letter; `P` for a step without a name.
pub fn base_name(step: &str) -> String {
    let mut name = String::new();
    push_base_name(step, &mut name);
    name
}

/// A cheap test before the lines are read (100,000 steps): whether `code` may hold a literal
/// target in `lang`.
fn may_hold_literal(lang: Language, code: &str) -> bool {
    match lang {
        Language::Krl => code.contains('{'),
        Language::Rapid => code.contains("[["),
        Language::UrScript => code.contains('['),
    }
}

/// The motions to literal targets among `code`'s lines (separated by `\n`), each with its
/// line's start and length, appended to `motions`.
fn read_motions(lang: Language, code: &str, motions: &mut Vec<(usize, usize, Motion)>) {
    let mut start = 0;
    for line in code.split('\n') {
        let m = match lang {
            Language::Krl => krl_motion(line),
            Language::Rapid => rapid_motion(line),
            Language::UrScript => ur_motion(line),
        };
        if let Some(m) = m {
            motions.push((start, line.len(), m));
        }
        start += line.len() + 1;
    }
}

/// What can be read of steps' code before their points are named, which needs no state of the
/// program: each step's motions to literal targets and the base of their names. A long
/// program's steps are read so on a second thread, ahead of the writer, which names the points
/// in order ([`Points::step_code_read`]).
#[derive(Default)]
pub struct ReadAhead {
    pub items: Vec<ReadItem>,
    motions: Vec<(usize, usize, Motion)>,
    bases: String,
}

/// One step of a [`ReadAhead`].
pub struct ReadItem {
    /// The step's element.
    pub step: usize,
    motions: std::ops::Range<usize>,
    base: std::ops::Range<usize>,
}

impl ReadAhead {
    /// Reads step `i` (named `name`, with `code`) into a new item, for a program in `lang`.
    pub fn read(&mut self, lang: Language, i: usize, name: &str, code: &str) {
        let m0 = self.motions.len();
        let b0 = self.bases.len();
        if may_hold_literal(lang, code) {
            read_motions(lang, code, &mut self.motions);
            if self.motions.len() > m0 {
                push_base_name(name, &mut self.bases);
            }
        }
        self.items.push(ReadItem {
            step: i,
            motions: m0..self.motions.len(),
            base: b0..self.bases.len(),
        });
    }

    /// Empties it, keeping its allocations.
    pub fn clear(&mut self) {
        self.items.clear();
        self.motions.clear();
        self.bases.clear();
    }
}

/// [`base_name`] appended to `out`.
fn push_base_name(step: &str, out: &mut String) {
    let start = out.len();
    let text = if step.is_ascii() {
        // (What `transliterate` changes in ASCII, control characters, separates words anyway.)
        Cow::Borrowed(step)
    } else {
        Cow::Owned(transliterate(step))
    };
    for word in text.split(|c: char| !c.is_ascii_alphanumeric()) {
        let mut chars = word.chars();
        let Some(first) = chars.next() else { continue };
        if out.len() == start {
            out.push(first);
        } else {
            out.push(first.to_ascii_uppercase());
        }
        out.push_str(chars.as_str());
    }
    if !out[start..].starts_with(|c: char| c.is_ascii_alphabetic()) {
        out.insert(start, 'P');
    }
}

#[cfg(test)]
mod tests {
    use super::motion::is_number;
    use super::*;

    fn points(lang: Language, krl: KrlForm) -> Points {
        Points::new(lang, Mode::Named, krl, Vec::new())
    }

    #[test]
    fn numbers_as_the_languages_write_them() {
        for n in ["-12", "0.5", ".5", "5.", "1E-3", "9E9", "+3", " 7 ", "1e+2"] {
            assert!(is_number(n), "{n}");
        }
        for n in [
            "", "-", ".", "1E", "1e+", "1.2.3", "12a", "E5", "--1", "0x1F", "1 2",
        ] {
            assert!(!is_number(n), "{n}");
        }
    }

    #[test]
    fn a_krl_motion_to_a_literal_becomes_a_named_point() {
        let mut p = points(Language::Krl, KrlForm::Named);
        let code = "SetVelCP (0.5)\nPTP {X 100, Y 200, Z 300, A 0, B 90, C 0}";
        assert_eq!(
            p.step_code("Pick part", code),
            "SetVelCP (0.5)\nPTP XPickPart"
        );
        assert_eq!(
            p.declarations,
            ["DECL E6POS XPickPart={X 100, Y 200, Z 300, A 0, B 90, C 0}"]
        );
        // The same step name again: a number keeps it unique.
        assert_eq!(
            p.step_code("Pick Part", "LIN {X 1, Y 2, Z 3, A 0, B 0, C 0} C_DIS"),
            "LIN XPickPart_2 C_DIS"
        );
        // Axis positions; several points in one step are numbered.
        assert_eq!(
            p.step_code(
                "Home",
                "PTP {A1 0, A2 -90, A3 90, A4 0, A5 0, A6 0}\nPTP {AXIS: A1 1}"
            ),
            "PTP XHome1_2\nPTP XHome2_2",
            "HOME1 and HOME2 are KUKA's own points"
        );
        assert_eq!(
            p.declarations[2],
            "DECL E6AXIS XHome1_2={A1 0, A2 -90, A3 90, A4 0, A5 0, A6 0}"
        );
        assert_eq!(p.step_code("Home", "PTP {A1 0}"), "PTP XHome_2");
        // `FOR` is a keyword: no point `Or`.
        assert_eq!(p.step_code("or", "PTP {X 1}"), "PTP Xor_2");
        // Status and Turn, when the skill maps them, are the point's.
        assert_eq!(
            p.step_code("Turn", "PTP {X 1, Y 2, Z 3, A 0, B 0, C 0, S 2, T 35}"),
            "PTP XTurn"
        );
        assert_eq!(
            p.declarations.last().unwrap(),
            "DECL E6POS XTurn={X 1, Y 2, Z 3, A 0, B 0, C 0, S 2, T 35}"
        );
        // What is not a literal position stays as written.
        for code in [
            "PTP HOME",
            "PTP {X 1, Y Y0}",
            "PTP_REL {X 10}",
            "LIN {A1 0}",
            "PTP {X 1} ; a comment",
            "PTP{X 1}",
        ] {
            assert_eq!(p.step_code("S", code), code);
        }
    }

    #[test]
    fn a_krl_inline_form_carries_its_data() {
        let mut p = points(Language::Krl, KrlForm::Inline { tool: 0, base: 0 });
        let out = p.step_code("Pick", "  LIN {X 1, Y 2, Z 3, A 0, B 0, C 0} C_DIS");
        let lines: Vec<&str> = out.lines().collect();
        assert!(
            lines[0].starts_with("  ;FOLD LIN Pick CONT Vel=2 m/s CPDAT1 Tool[0] Base[0];%{PE}"),
            "{out}"
        );
        assert!(
            lines[0].ends_with("%P 1:LIN, 2:Pick, 3:C_DIS, 5:2, 7:CPDAT1"),
            "{out}"
        );
        assert_eq!(
            &lines[1..],
            [
                "  $BWDSTART=FALSE",
                "  LDAT_ACT=LCPDAT1",
                "  FDAT_ACT=FPick",
                "  BAS(#CP_PARAMS,2)",
                "  LIN XPick C_DIS",
                "  ;ENDFOLD"
            ]
        );
        assert_eq!(p.declarations.len(), 3, "{:?}", p.declarations);
        assert!(p.declarations[1].starts_with("DECL LDAT LCPDAT1={VEL 2,"));
        assert!(p.declarations[2].starts_with("DECL FDAT FPick={TOOL_NO 0,BASE_NO 0,"));
        let circ = p.step_code("Arc", "CIRC {X 1, Y 2, Z 3}, {X 4, Y 5, Z 6}");
        assert!(
            circ.contains("%P 1:CIRC, 2:Arc1, 3:Arc2, 4:, 6:2, 8:CPDAT2"),
            "{circ}"
        );
        assert!(circ.contains("\nCIRC XArc1, XArc2\n"), "{circ}");
    }

    #[test]
    fn rapid_and_urscript_targets_are_declared_by_name() {
        let mut p = points(Language::Rapid, KrlForm::Named);
        let line = "MoveL [[400, 0, 300], [0, 0, 1, 0], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]], v200, fine, tGripper;";
        assert_eq!(
            p.step_code("Pick", line),
            "MoveL pPick, v200, fine, tGripper;"
        );
        assert_eq!(
            p.declarations,
            [
                "CONST robtarget pPick := [[400, 0, 300], [0, 0, 1, 0], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]];"
            ]
        );
        let j =
            "MoveAbsJ [[0, 0, 0, 0, 30, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]], v500, fine, tool0;";
        assert_eq!(p.step_code("Home", j), "MoveAbsJ jHome, v500, fine, tool0;");
        let named = "MoveL RelTool(pHome, 1, 2, 3), v100, fine, tool0;";
        assert_eq!(p.step_code("X", named), named);

        let mut u = points(Language::UrScript, KrlForm::Named);
        assert_eq!(
            u.step_code("Pick", "movel(p[0.4, 0, 0.3, 0, 3.14, 0], a=1.2, v=0.25)"),
            "movel(pPick, a=1.2, v=0.25)"
        );
        assert_eq!(
            u.step_code("Home", "movej([0, -1.57, 1.57, 0, 0, 0])"),
            "movej(qHome)"
        );
        assert_eq!(
            u.declarations,
            [
                "global pPick = p[0.4, 0, 0.3, 0, 3.14, 0]",
                "global qHome = [0, -1.57, 1.57, 0, 0, 0]"
            ]
        );
        assert_eq!(u.step_code("S", "movel(p[X, 1])"), "movel(p[X, 1])");
    }

    #[test]
    fn names_fit_the_language_and_avoid_taken_words() {
        let mut p = Points::new(
            Language::Krl,
            Mode::Named,
            KrlForm::Named,
            ["XGrip".to_owned()],
        );
        assert_eq!(p.step_code("Grip", "PTP {X 1}"), "PTP XGrip_2");
        let long = "a very long step name that goes on and on";
        let out = p.step_code(long, "PTP {X 1}\nPTP {X 2}");
        for l in out.lines() {
            let name = l.strip_prefix("PTP ").unwrap();
            assert!(crate::names::is_krl_name(name), "{name}");
        }
        // One point of a long step name is cut to the language's length too.
        let one = p.step_code(long, "PTP {X 1}");
        let name = one.strip_prefix("PTP ").unwrap();
        assert!(crate::names::is_krl_name(name), "{name}");
        assert_eq!(name, "XaVeryLongStepNameThatGo");
        assert_eq!(base_name("1. Übergabe"), "P1Uebergabe");
        // 20,000 steps of one name: unique names, found without trying every earlier one
        // (200 million tries before).
        let mut many = Points::new(Language::Rapid, Mode::Named, KrlForm::Named, Vec::new());
        let mut seen = std::collections::HashSet::new();
        for _ in 0..20_000 {
            let line = many.step_code(
                "Move",
                "MoveJ [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v1000, z50, tool0;",
            );
            assert!(seen.insert(line.to_ascii_lowercase()));
        }
        assert!(many.tries < 3 * 20_000, "{} names tried", many.tries);
        assert_eq!(base_name(""), "P");
        let mut lit = Points::new(Language::Krl, Mode::Literal, KrlForm::Named, Vec::new());
        assert_eq!(lit.step_code("S", "PTP {X 1}"), "PTP {X 1}");
    }
}
