//! Which IRL definitions a program holds: the ones its calls name (a `definition` named like a
//! `function-call`), and every one whose routine the program's code calls, by the routine's
//! own name as its `DEF`/`DEFFCT` (KRL), `PROC`/`FUNC`/`TRAP` (RAPID) or `def` (URScript) line
//! says, transitively through the definitions already in. RAPID module data a definition
//! declares (`PERS`, `VAR`, `CONST`) counts as a routine: code that names it needs it.
//!
//! A routine is called when its name stands as a word in the code (KRL and RAPID without regard
//! to case): a RAPID procedure call has no parentheses (`ArcSeam 10;`), and a word that only
//! names a variable of the same name brings in a routine that is not needed, which is harmless.

use std::collections::{BTreeSet, HashSet};

use crate::lang::Language;
use crate::read::irl::{Irl, IrlDefinition};

use super::Bound;

/// The routines a definition defines, by the names its own lines give them, in order.
pub fn routines(lang: Language, def: &IrlDefinition) -> Vec<String> {
    def.lines.iter().filter_map(|l| routine(lang, l)).collect()
}

/// The routine a line opens, if it opens one.
pub fn routine(lang: Language, line: &str) -> Option<String> {
    let mut words = line
        .split(|c: char| c.is_whitespace() || c == '(' || c == ':')
        .filter(|w| !w.is_empty());
    let mut first = words.next()?;
    let upper = |w: &str| w.to_ascii_uppercase();
    let name = match lang {
        Language::Krl => {
            if upper(first) == "GLOBAL" {
                first = words.next()?;
            }
            match upper(first).as_str() {
                "DEF" => words.next()?,
                "DEFFCT" => {
                    words.next()?;
                    words.next()?
                }
                _ => return None,
            }
        }
        Language::Rapid => {
            if matches!(upper(first).as_str(), "LOCAL" | "TASK") {
                first = words.next()?;
            }
            match upper(first).as_str() {
                "PROC" | "TRAP" => words.next()?,
                // A function, and module data (`PERS tooldata tGripper := …;`): the code
                // names them as it calls a routine.
                "FUNC" | "PERS" | "VAR" | "CONST" => {
                    words.next()?;
                    words.next()?
                }
                _ => return None,
            }
        }
        Language::UrScript => match first {
            "def" => words.next()?,
            _ => return None,
        },
    };
    let name: String = name
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
        .collect();
    (!name.is_empty()).then_some(name)
}

/// A name as the language compares names (KRL and RAPID without regard to case).
pub fn key(lang: Language, name: &str) -> String {
    match lang {
        Language::UrScript => name.to_owned(),
        _ => name.to_ascii_lowercase(),
    }
}

/// Whether `name` stands in `hay` as a word.
fn has_word(hay: &[u8], name: &str) -> bool {
    words_at(hay, name).next().is_some()
}

/// Where `name` stands in `hay` as a word (not part of a longer name).
fn words_at<'h>(hay: &'h [u8], name: &'h str) -> impl Iterator<Item = usize> + 'h {
    memchr::memmem::find_iter(hay, name.as_bytes()).filter(move |&at| {
        let end = at + name.len();
        (at == 0 || !is_word_byte(hay[at - 1])) && hay.get(end).is_none_or(|&b| !is_word_byte(b))
    })
}

/// A byte a name is made of: what bounds a name as a word.
fn is_word_byte(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_'
}

/// The words of `text` (runs of [`is_word_byte`]), each with where it starts.
fn words(text: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    let mut i = 0;
    std::iter::from_fn(move || {
        while i < text.len() && !is_word_byte(text[i]) {
            i += 1;
        }
        let start = i;
        while i < text.len() && is_word_byte(text[i]) {
            i += 1;
        }
        (i > start).then(|| (start, &text[start..i]))
    })
}

/// Up to this many names, each is searched for in the code (a `memmem` pass is cheaper than
/// taking the code apart into words); more, as a library of helpers has, are found by one pass
/// over the code's words, each looked up.
const FEW_NAMES: usize = 8;

/// Puts into `bound` every definition of the IRL files `files` (of the program's language) whose
/// routine the program's code calls, directly or through a definition already in, after the
/// ones its calls named. Of two definitions of one routine the first (in `files`' order) is
/// taken.
pub fn complete(bound: &mut Bound, irls: &[Irl], files: &[usize], lang: Language) {
    let mut defined: HashSet<String> = HashSet::new();
    for &(i, d) in &bound.definitions {
        for r in routines(lang, &irls[i].definitions[d]) {
            defined.insert(key(lang, &r));
        }
    }
    let mut candidates: Vec<((usize, usize), Vec<String>)> = Vec::new();
    // Looked up once per definition of the files (4,000 of them: a scan of the list each was
    // quadratic).
    let held: HashSet<(usize, usize)> = bound.definitions.iter().copied().collect();
    for &i in files {
        if irls[i].language != lang {
            continue;
        }
        for (d, def) in irls[i].definitions.iter().enumerate() {
            if held.contains(&(i, d)) {
                continue;
            }
            let names: Vec<String> = routines(lang, def).iter().map(|r| key(lang, r)).collect();
            if !names.is_empty() {
                candidates.push(((i, d), names));
            }
        }
    }
    if candidates.is_empty() {
        return;
    }
    // The code as the language compares names (KRL and RAPID folded to lower case), searched
    // once for each name a candidate defines.
    let fold = |text: &str, hay: &mut String| match lang {
        Language::UrScript => hay.push_str(text),
        _ => hay.extend(text.chars().map(|c| c.to_ascii_lowercase())),
    };
    let mut hay = String::new();
    for step in bound.steps.iter() {
        fold(&step.code, &mut hay);
        hay.push('\n');
    }
    for &(i, d) in &bound.definitions {
        for l in &irls[i].definitions[d].lines {
            fold(l, &mut hay);
            hay.push('\n');
        }
    }
    // Each name to the candidates that define it; the names the code calls so far.
    let mut by_name: foldhash::HashMap<&str, Vec<usize>> = foldhash::HashMap::default();
    for (k, (_, names)) in candidates.iter().enumerate() {
        for n in names {
            by_name.entry(n.as_str()).or_default().push(k);
        }
    }
    let mut called: foldhash::HashSet<&str> = foldhash::HashSet::default();
    // The candidates that may be taken: each one that defines a called name, until it is
    // looked at. A candidate is taken when it defines a called name no definition taken before
    // defines, the first such one in `files`' order; one that defines only names already
    // defined is dropped here, and comes back when another of its names is called.
    let mut maybe: BTreeSet<usize> = BTreeSet::new();
    let mut taken = vec![false; candidates.len()];
    // The names the code calls ([`FEW_NAMES`]; with many, a search each cost 30 instructions a
    // step for each name).
    if by_name.len() <= FEW_NAMES {
        for (&n, ks) in &by_name {
            if !defined.contains(n) && has_word(hay.as_bytes(), n) {
                called.insert(n);
                maybe.extend(ks.iter().copied());
            }
        }
    } else {
        mark_called(hay.as_bytes(), &by_name, &taken, &mut called, &mut maybe);
    }
    drop(hay);
    let mut line = String::new();
    while let Some(k) = maybe.pop_first() {
        let ((i, d), names) = &candidates[k];
        if taken[k]
            || !names
                .iter()
                .any(|n| called.contains(n.as_str()) && !defined.contains(n))
        {
            continue;
        }
        taken[k] = true;
        defined.extend(names.iter().cloned());
        bound.definitions.push((*i, *d));
        // Only the new definition's own lines can call a name not called before.
        for l in &irls[*i].definitions[*d].lines {
            line.clear();
            fold(l, &mut line);
            mark_called(line.as_bytes(), &by_name, &taken, &mut called, &mut maybe);
        }
    }
}

/// Marks each name of `by_name` that stands in `text` as a word (`text` folded as the language
/// compares names) as called, and the candidates not yet taken that define it as ones that may
/// be taken.
fn mark_called<'n>(
    text: &[u8],
    by_name: &foldhash::HashMap<&'n str, Vec<usize>>,
    taken: &[bool],
    called: &mut foldhash::HashSet<&'n str>,
    maybe: &mut BTreeSet<usize>,
) {
    for (_, w) in words(text) {
        // Only ASCII bytes are in a word, so it is UTF-8.
        let Ok(w) = std::str::from_utf8(w) else {
            continue;
        };
        if let Some((&n, ks)) = by_name.get_key_value(w)
            && called.insert(n)
        {
            maybe.extend(ks.iter().copied().filter(|&k| !taken[k]));
        }
    }
}

/// The routines a generated program calls that one of `irls` defines but the program does not
/// hold (`held`: the keys of the routines of its definitions): each with the IRL file and
/// definition that define it. Words in comments and strings do not count. Only routines not
/// held are looked for, so a program that holds every definition costs nothing here.
pub fn missing(
    lang: Language,
    text: &str,
    irls: &[Irl],
    held: &HashSet<String>,
) -> Vec<(String, usize, usize)> {
    // Each routine once, in the files' order (4,000 of them: a scan of the list each was
    // quadratic).
    let mut wanted: Vec<(String, String, usize, usize)> = Vec::new();
    let mut seen: foldhash::HashSet<String> = foldhash::HashSet::default();
    for (i, f) in irls.iter().enumerate() {
        if f.language != lang {
            continue;
        }
        for (d, def) in f.definitions.iter().enumerate() {
            for r in routines(lang, def) {
                let k = key(lang, &r);
                if !held.contains(&k) && !seen.contains(&k) {
                    seen.insert(k.clone());
                    wanted.push((k, r, i, d));
                }
            }
        }
    }
    if wanted.is_empty() {
        return Vec::new();
    }
    let comment = match lang {
        Language::Krl => b';',
        Language::Rapid => b'!',
        Language::UrScript => b'#',
    };
    let folded;
    let hay: &[u8] = match lang {
        Language::UrScript => text.as_bytes(),
        _ => {
            folded = text.to_ascii_lowercase();
            folded.as_bytes()
        }
    };
    let mut found = vec![false; wanted.len()];
    if wanted.len() <= FEW_NAMES {
        for (k, w) in wanted.iter().enumerate() {
            let mut code = Code::new(comment);
            found[k] = words_at(hay, &w.0).any(|at| code.at(hay, at));
        }
    } else {
        let index: foldhash::HashMap<&[u8], usize> = wanted
            .iter()
            .enumerate()
            .map(|(k, w)| (w.0.as_bytes(), k))
            .collect();
        let mut code = Code::new(comment);
        for (start, w) in words(hay) {
            if let Some(&k) = index.get(w)
                && !found[k]
                && code.at(hay, start)
            {
                found[k] = true;
            }
        }
    }
    wanted
        .into_iter()
        .zip(found)
        .filter(|(_, f)| *f)
        .map(|((_, name, i, d), _)| (name, i, d))
        .collect()
}

/// Whether places of a text, asked in increasing order, stand in code: not in a string or
/// after the line's comment. Each byte is read at most once over all the places asked (a
/// line of many matches in a string was read again from its start for each).
struct Code {
    comment: u8,
    /// The text up to here is read; the state is that of this place.
    pos: usize,
    in_string: bool,
    in_comment: bool,
}

impl Code {
    fn new(comment: u8) -> Self {
        Code {
            comment,
            pos: 0,
            in_string: false,
            in_comment: false,
        }
    }

    /// Whether `at` (not before the place asked last) stands in code.
    fn at(&mut self, hay: &[u8], at: usize) -> bool {
        if let Some(nl) = memchr::memrchr(b'\n', &hay[self.pos..at]) {
            self.pos += nl + 1;
            self.in_string = false;
            self.in_comment = false;
        }
        if !self.in_comment {
            for &b in &hay[self.pos..at] {
                if b == b'"' {
                    self.in_string = !self.in_string;
                } else if b == self.comment && !self.in_string {
                    self.in_comment = true;
                    break;
                }
            }
        }
        self.pos = at;
        !self.in_string && !self.in_comment
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn def(lines: &[&str]) -> IrlDefinition {
        IrlDefinition {
            name: crate::model::Name::new("x", crate::diag::Span::new(0, 0..0)),
            lines: lines.iter().map(|l| (*l).to_owned()).collect(),
            span: crate::diag::Span::new(0, 0..0),
        }
    }

    #[test]
    fn a_definitions_routines_are_named_by_its_own_lines() {
        let krl = def(&[
            "DEF G1_Set(CLOSE:IN, WAITTIME:IN)",
            "END",
            "global deffct REAL Half(X:IN)",
            "ENDFCT",
        ]);
        assert_eq!(routines(Language::Krl, &krl), ["G1_Set", "Half"]);
        let rapid = def(&[
            "PROC ArcSeam(num speed)",
            "ENDPROC",
            "LOCAL FUNC num Twice(num x)",
            "TRAP Stop",
            "PERS tooldata tGripper := [TRUE, [[0, 0, 120], [1, 0, 0, 0]]];",
            "  MoveL p, v200, fine, tGripper;",
        ]);
        assert_eq!(
            routines(Language::Rapid, &rapid),
            ["ArcSeam", "Twice", "Stop", "tGripper"]
        );
        let ur = def(&[
            "def grip(close):",
            "  set_standard_digital_out(0, close)",
            "end",
        ]);
        assert_eq!(routines(Language::UrScript, &ur), ["grip"]);
    }

    fn library(names: &[String]) -> Irl {
        Irl {
            file: 0,
            info: None,
            language: Language::Krl,
            calls: Vec::new(),
            definitions: names
                .iter()
                .map(|n| def(&[&format!("DEF {n}()"), "END"]))
                .collect(),
        }
    }

    /// The routines `missing` finds in `text` of a library of `names`.
    fn found(names: &[String], text: &str) -> Vec<String> {
        let irls = [library(names)];
        missing(Language::Krl, text, &irls, &HashSet::new())
            .into_iter()
            .map(|(r, _, _)| r)
            .collect()
    }

    #[test]
    fn a_routine_counts_as_called_only_in_code_with_few_names_or_many() {
        let text = "Grip()\n; Spare1() in a comment\nMSG = \"Spare2() in a string\"; Spare3()\nX = \"a;b\" + Spare4() ; Spare5()\nSPARE6()\nSpare7X()\n";
        let expect = ["Grip", "Spare4", "Spare6"];
        let few: Vec<String> = [
            "Grip", "Spare1", "Spare2", "Spare3", "Spare4", "Spare5", "Spare6", "Spare7",
        ]
        .map(String::from)
        .to_vec();
        assert_eq!(found(&few, text), expect, "eight names: one search each");
        let mut many = few.clone();
        many.extend((0..100).map(|k| format!("Other{k}")));
        assert_eq!(found(&many, text), expect, "more: one pass over the words");
        // A line of many matches inside a string is read once, not once per match.
        let long = format!("X = \"{}\"\nSpare1()\n", "Spare1 ".repeat(200_000));
        assert_eq!(found(&few, &long), ["Spare1"]);
        assert_eq!(found(&many, &long), ["Spare1"]);
    }
}
