//! The checks of a compile's outputs: that none is an input or the picture, that the program
//! name is one of its language, the IRL snippets the program uses, and every generated file
//! (`E606`), on two threads where there are several.

use super::*;

/// `E605` for every output that is also an input of this compile: a `refURI`'s file (located
/// at the reference), the blackboard or the template. Paths are compared as written (after
/// `.`/`..` are resolved) and, where the file system can tell, with symbolic links resolved, so
/// `./X.src` and a link to `X.src` count. (The blackboard is the write-back's target, which is
/// not an output; an *output* named like it is an error.)
pub(super) fn check_outputs(
    cx: &mut Ctx,
    outputs: &[&Path],
    blackboard: &Path,
    template: Option<&Path>,
) {
    if outputs.is_empty() {
        return;
    }
    let mut inputs: Vec<(PathBuf, Option<Span>)> = vec![(blackboard.to_owned(), None::<Span>)];
    inputs.extend(template.map(|t| (t.to_owned(), None)));
    inputs.extend(cx.refs.iter().map(|(p, s)| (p.clone(), Some(s.clone()))));
    // Each input's absolute and real path once, looked up by both: every output against every
    // input was outputs × inputs look-ups of real paths (4,000 IRL files and a program split
    // into parts: most of the compile).
    let mut by_absolute: HashMap<PathBuf, Vec<usize>> = HashMap::new();
    let mut by_real: HashMap<PathBuf, Vec<usize>> = HashMap::new();
    for (k, (input, _)) in inputs.iter().enumerate() {
        by_absolute
            .entry(paths::absolute(input))
            .or_default()
            .push(k);
        if let Some(real) = real_or_parent(&cx.fs, input) {
            by_real.entry(real).or_default().push(k);
        }
    }
    let mut reported: Vec<(PathBuf, PathBuf)> = Vec::new();
    for &out in outputs {
        // As [`same_file`]: the same absolute path, or the same real one.
        let mut same: Vec<usize> = by_absolute
            .get(&paths::absolute(out))
            .into_iter()
            .chain(real_or_parent(&cx.fs, out).and_then(|r| by_real.get(&r)))
            .flatten()
            .copied()
            .collect();
        same.sort_unstable();
        same.dedup();
        for (input, at) in same.into_iter().map(|k| &inputs[k]) {
            if reported.iter().any(|(o, i)| o == out && i == input) {
                continue;
            }
            reported.push((out.to_owned(), input.clone()));
            let name = out.file_name().unwrap_or_default().to_string_lossy();
            let d = Diagnostic::error(
                Code::OutputIsInput,
                format!(
                    "the output `{name}` is also an input of this compile (`{}`); writing it would overwrite that input: rename the input or choose another program name",
                    input.display()
                ),
            );
            cx.diags.push(match at {
                Some(span) => d.at(span.clone()),
                None => match cx.sources.find(input) {
                    Some(file) => d.at(Span::new(file, 0..0)),
                    None => d.path(input),
                },
            });
        }
    }
}

/// The picture (`--svg FILE`) may not be one of the programs' files: both would be written to
/// one name (and a failed write of the programs left the picture in the program's place).
pub(super) fn check_picture(cx: &mut Ctx, picture: &Path, outputs: &[(PathBuf, OutputFile)]) {
    let pic_real = real_or_parent(&cx.fs, picture);
    for (out, _) in outputs {
        if same_file(cx, picture, &pic_real, out) {
            cx.diags.push(Diagnostic::error(
                Code::CannotWrite,
                format!(
                    "the picture `{}` (--svg) is also a file of the program this compile writes: \
                     choose another name for the picture (e.g. `{}`)",
                    picture.display(),
                    out.with_extension("svg").display()
                ),
            ));
            return;
        }
    }
}

/// Whether `a` (whose [`real_or_parent`] is `a_real`) and `b` name one file: the same absolute
/// path, or the same real one.
pub(super) fn same_file(cx: &Ctx, a: &Path, a_real: &Option<PathBuf>, b: &Path) -> bool {
    paths::absolute(a) == paths::absolute(b)
        || (a_real.is_some() && *a_real == real_or_parent(&cx.fs, b))
}

/// The real path of a file, or of its folder joined with its name when the file does not exist
/// (an output about to be created); `None` where the file system cannot tell.
pub(super) fn real_or_parent(fs: &dyn FileSource, p: &Path) -> Option<PathBuf> {
    fs.real_path(p).or_else(|| {
        let name = p.file_name()?;
        let parent = match p.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        Some(fs.real_path(parent)?.join(name))
    })
}

/// `E601` when the program name is not a name of `language` (when the language is not known:
/// of no language).
pub(super) fn check_program_name(cx: &mut Ctx, opts: &Options, language: Option<Language>) {
    let Some(program) = &opts.program else {
        return;
    };
    let why = match language {
        Some(l) => l.profile().check_program_name(program).err(),
        None => Language::ALL
            .iter()
            .all(|l| l.profile().check_program_name(program).is_err())
            .then(|| "a name in no robot language".to_owned()),
    };
    if let Some(why) = why {
        cx.diags.push(Diagnostic::error(
            Code::BadProgramName,
            format!("program name `{program}` is {why}"),
        ));
    }
}

/// `E405` for each IRL snippet of `irl` (a `definition` named in `used`, every
/// `function-call`'s code) whose blocks do not close within it, located at the line of the IRL
/// file ([`crate::check`]).
pub(super) fn check_snippets(
    sources: &Sources,
    irl: &Irl,
    used: &HashSet<&str>,
    diags: &mut Diagnostics,
) {
    let text = &sources.get(irl.file).text;
    let Ok(doc) = roxmltree::Document::parse(text) else {
        return;
    };
    for el in doc
        .descendants()
        .filter(|n| n.has_tag_name("definition") || n.has_tag_name("function-call"))
    {
        // The snippet: the element's own text, line by line, with each line's place.
        let mut lines: Vec<(usize, &str)> = Vec::new();
        for t in el.children().filter(|c| c.is_text()) {
            let start = t.range().start;
            let body = &text[t.range()];
            let mut off = 0;
            for l in body.split('\n') {
                lines.push((start + off, l.trim_end_matches('\r')));
                off += l.len() + 1;
            }
        }
        let snippet: String = lines.iter().map(|(_, l)| format!("{l}\n")).collect();
        let name = el.attribute("name").unwrap_or("?");
        if el.has_tag_name("definition") && !used.contains(crate::names::key(name).as_str()) {
            continue;
        }
        let what = if el.has_tag_name("definition") {
            "definition"
        } else {
            "function call"
        };
        // A KRL definition goes after the program's `END`: routines only.
        let unit = if irl.language == crate::lang::Language::Krl && what == "definition" {
            crate::check::Unit::Routines
        } else {
            crate::check::Unit::Snippet
        };
        for p in crate::check::check(irl.language, unit, &snippet) {
            let Some(&(line_start, line)) = lines.get(p.line - 1) else {
                continue;
            };
            let col = line
                .char_indices()
                .nth(p.column - 1)
                .map_or(line.len(), |(i, _)| i);
            let word = line[col..]
                .find(|c: char| c.is_whitespace())
                .unwrap_or(line.len() - col);
            let mut d = Diagnostic::error(
                Code::BadSnippet,
                format!(
                    "{} {what} `{name}`: {}; the program would not load on the controller",
                    irl.language.name(),
                    p.message
                ),
            )
            .at(Span::new(
                irl.file,
                line_start + col..line_start + col + word.max(1),
            ));
            if let Some((ol, oc)) = p.opened.filter(|o| *o != (p.line, p.column))
                && let Some(&(os, oline)) = lines.get(ol - 1)
            {
                let c = oline.char_indices().nth(oc - 1).map_or(0, |(i, _)| i);
                d = d.related(
                    Span::new(irl.file, os + c..os + c + 1),
                    "the block opened here",
                );
            }
            diags.push(d);
        }
    }
}

/// The problems of each generated file (none for a file of no language): as `checked` has them
/// where a file was checked as it was written, else checked now, by this thread and another at
/// once when there are several large ones (a split program's parts): each takes the next file,
/// the largest first, when done with one, so a core that runs slower checks fewer.
pub(super) fn check_outputs_in_parallel(
    outputs: &[(PathBuf, OutputFile)],
    checked: Vec<Option<Vec<crate::check::Problem>>>,
) -> Vec<Vec<crate::check::Problem>> {
    let check = |(path, f): &(PathBuf, OutputFile)| match crate::check::language_of(path) {
        Some((language, unit)) => crate::check::check(language, unit, &f.text),
        None => Vec::new(),
    };
    // The files checked as they were written keep what was found; the others are checked now.
    let mut out: Vec<Vec<crate::check::Problem>> = Vec::with_capacity(outputs.len());
    let mut left: Vec<usize> = Vec::new();
    let mut checked = checked.into_iter();
    for k in 0..outputs.len() {
        match checked.next().flatten() {
            Some(problems) => out.push(problems),
            None => {
                left.push(k);
                out.push(Vec::new());
            }
        }
    }
    let sizes: Vec<usize> = left.iter().map(|&k| outputs[k].1.text.len()).collect();
    // Only worth a thread when the files other than the largest are large (as a split
    // program's parts or a cell's programs are, from about 2,000 steps).
    let rest = sizes.iter().sum::<usize>() - sizes.iter().max().unwrap_or(&0);
    let found: Vec<Vec<crate::check::Problem>> = if rest < PARALLEL_CHECK_FROM {
        left.iter().map(|&k| check(&outputs[k])).collect()
    } else {
        crate::threads::largest_first("skillpost-check", &sizes, |j| check(&outputs[left[j]]))
    };
    for (&k, problems) in left.iter().zip(found) {
        out[k] = problems;
    }
    out
}

/// What the built-in check finds in a generated file, by its extension (nothing in a file no
/// check reads, an I/O list): what [`check_outputs_in_parallel`] finds for it.
pub(super) fn check_output(f: &OutputFile) -> Vec<crate::check::Problem> {
    let path = PathBuf::from(format!("x.{}", f.extension));
    match crate::check::language_of(&path) {
        Some((language, unit)) => crate::check::check(language, unit, &f.text),
        None => Vec::new(),
    }
}

/// The bytes of the generated files other than the largest from which a second thread checks
/// some of them.
const PARALLEL_CHECK_FROM: usize = 256 * 1024;

/// `E606` for each problem the built-in check finds in a generated file ([`crate::check`]):
/// what the IRL snippets and the output template made together. Nothing is written then.
/// `checked`: per output, what the check found when it ran as the file was written.
pub(super) fn check_generated(
    outputs: &[(PathBuf, OutputFile)],
    checked: Vec<Option<Vec<crate::check::Problem>>>,
    sources: &Sources,
    template: Option<FileId>,
    diags: &mut Diagnostics,
) {
    // A generated line that stands once, as it is, in the `--template` file came from there:
    // the problem is located at it.
    let in_template = |line: &str| -> Option<Span> {
        let tf = template?;
        let text = &sources.get(tf).text;
        let mut found = None;
        let mut at = 0;
        for l in text.split_inclusive('\n') {
            let t = l.trim();
            if !line.is_empty() && t == line {
                if found.is_some() {
                    return None;
                }
                let start = at + (l.len() - l.trim_start().len());
                found = Some(Span::new(tf, start..start + t.len()));
            }
            at += l.len();
        }
        found
    };
    let problems = check_outputs_in_parallel(outputs, checked);
    for ((path, f), problems) in outputs.iter().zip(problems) {
        for p in problems.iter().take(20) {
            let line = f.text.lines().nth(p.line - 1).unwrap_or("").trim();
            let opened = match p.opened {
                Some((l, _)) if l != p.line => format!(" (opened at line {l})"),
                _ => String::new(),
            };
            let file = path
                .file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into_owned());
            let mut d = Diagnostic::error(
                Code::BadProgram,
                format!(
                    "the generated {file} would not load: line {}: {}{opened} (`{line}`); check \
                     the IRL snippets and the output template",
                    p.line, p.message
                ),
            );
            if let Some(span) = in_template(line) {
                d = d.at(span);
                if let Some((l, _)) = p.opened.filter(|(l, _)| *l != p.line)
                    && let Some(o) = in_template(f.text.lines().nth(l - 1).unwrap_or("").trim())
                {
                    d = d.related(o, "the block opened here");
                }
            }
            diags.push(d);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Many large files, some broken: each file's problems are its own, in any order of sizes,
    /// as one thread checking them one by one finds them.
    #[test]
    fn files_checked_on_two_threads_keep_their_own_problems() {
        let body = "  WAIT SEC 0\r\n".repeat(10_000);
        let outputs: Vec<(PathBuf, OutputFile)> = (0..12)
            .map(|k| {
                // Sizes out of order; every third file misses its ENDIF at a line of its own.
                let mut text = format!("DEF p{k}()\r\n{}", body.repeat(1 + k % 4));
                if k % 3 == 0 {
                    text.push_str(&"  WAIT SEC 0\r\n".repeat(k));
                    text.push_str("  IF TRUE THEN\r\n");
                }
                text.push_str("END\r\n");
                let file = OutputFile {
                    extension: "src",
                    text,
                    stem: None,
                    parts: Vec::new(),
                };
                (PathBuf::from(format!("p{k}.src")), file)
            })
            .collect();
        let one_by_one: Vec<Vec<crate::check::Problem>> = outputs
            .iter()
            .map(|(_, f)| crate::check::check(Language::Krl, crate::check::Unit::Program, &f.text))
            .collect();
        let together = check_outputs_in_parallel(&outputs, vec![None; outputs.len()]);
        assert_eq!(together, one_by_one);
        for (k, problems) in together.iter().enumerate() {
            assert_eq!(problems.is_empty(), k % 3 != 0, "file {k}: {problems:?}");
        }
    }
}
