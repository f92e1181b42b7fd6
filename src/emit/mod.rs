//! Language profiles: the bound program → output files (docs/LANGUAGES.md).
//!
//! A [`Profile`] holds everything one robot language decides: its output files and their
//! built-in template (`templates/<lang>.toml`), how IRL templates are read ([`Syntax`]), how a
//! neutral [`Literal`] is written and which ones are refused (a value must never become code),
//! names and their limits, how a signal is read in a condition, and how the program tree's control
//! flow is written. The binder asks the program's profile about values; [`emit_files`] runs the
//! profile's writer and fills its template.
//!
//! Adding a language: a module beside [`krl`], [`rapid`] and [`urscript`] implementing
//! [`Profile`] (a language of `if`/`while` blocks describes its words in a
//! [`structured::Dialect`]), a `templates/<lang>.toml` whose keys are `step_indent` and the
//! profile's files, and a [`Language`] variant.
//!
//! [`Literal`]: crate::value::Literal

pub mod ahead;
pub mod flow;
pub mod handshake;
pub mod io;
pub mod krl;
pub mod points;
pub mod rapid;
pub mod split;
pub mod structured;
pub mod tool;
pub mod urscript;

use crate::bind::Bound;
use crate::diag::{Code, Diagnostic, Diagnostics, FileId, Sources, Span};
use crate::model::{Blackboard, Sfc};
use crate::read::irl::Irl;
use crate::template::Syntax;

pub use crate::lang::Language;

/// A language's profile: `language.profile()` where this trait is in scope.
pub trait LanguageProfile {
    fn profile(self) -> &'static dyn Profile;
}

impl LanguageProfile for Language {
    fn profile(self) -> &'static dyn Profile {
        match self {
            Language::Krl => &krl::Krl,
            Language::Rapid => &rapid::Rapid,
            Language::UrScript => &urscript::UrScript,
        }
    }
}

/// What one robot language decides. Implementations are stateless unit structs.
pub trait Profile: crate::bind::Rules {
    /// The output files' extensions, the main one (the write-back's) first. Each is also the
    /// key of that file's text in the output template.
    fn files(&self) -> &'static [&'static str];
    /// The built-in output template (`templates/<lang>.toml`).
    fn builtin_template(&self) -> &'static str;
    /// How IRL templates of this language are read.
    fn syntax(&self) -> Syntax;
    /// `Ok` when `name` can be the program's name; else why not (for `E601`).
    fn check_program_name(&self, name: &str) -> Result<(), String>;
    /// Where an IRL definition goes among the others, by its first line: definitions are written
    /// in this order (stable, then first use). RAPID puts data declarations before routines.
    fn definition_rank(&self, _first_line: &str) -> u8 {
        0
    }
    /// Whether template lines lose trailing spaces after their placeholders are filled (RAPID:
    /// `rapidchecker` refuses trailing whitespace, as in `! ` with an empty header comment).
    fn trim_trailing_spaces(&self) -> bool {
        false
    }
    /// Whether the program's signals must be declared in the controller's I/O configuration
    /// before it loads (RAPID: an `EIO.cfg` fragment is written beside the module, [`io::eio`]).
    fn declares_signals(&self) -> bool {
        false
    }
    /// Writes the program tree and its declarations (see [`Generated`]).
    fn generate(&self, input: &EmitInput, diags: &mut Diagnostics) -> Option<Generated>;
}

/// Everything a profile reads.
pub struct EmitInput<'a> {
    pub program: &'a str,
    pub blackboard: &'a Blackboard,
    pub sfc: &'a Sfc,
    /// The program tree: the chart's plan, or a cell's program (`plan::cell`).
    pub body: &'a [crate::plan::Block],
    pub bound: &'a Bound,
    pub irls: &'a [Irl],
    /// `"\r\n"` or `"\n"`.
    pub newline: &'a str,
    /// The template's indentation of a step's code lines.
    pub step_indent: &'a str,
    /// The indentation of the template's `{{steps}}` line ([`OutputTemplate::steps_indent`]),
    /// which the writer puts before every line of the block.
    pub steps_indent: &'a str,
    pub profile: &'static dyn Profile,
    /// For a program of a cell of several controllers: the cell, for the handshakes.
    pub cell: Option<handshake::CellView<'a>>,
    /// The longest program, in lines of its steps, before it is split into parts
    /// ([`split`]); 0: never split.
    pub max_lines: usize,
    /// Steps from which the steps' code is read on a second thread, ahead of the writer
    /// ([`ahead`]); `usize::MAX`: never (a cell's programs, written two at a time).
    pub read_ahead_from: usize,
}

/// What a profile's writer made: the text of the template's blocks, lines separated by the
/// newline, each line without the indentation of its placeholder line.
#[derive(Debug, Default)]
pub struct Generated {
    /// `{{steps}}`: the program tree.
    pub steps: String,
    /// `{{declarations}}`: one line each.
    pub declarations: Vec<String>,
    /// `{{definitions}}`, after the IRL definitions: the program's own routines (a cell's
    /// handshakes), one line each.
    pub routines: Vec<String>,
    /// `{{definitions}}`, before the IRL definitions: the program's data (RAPID's `tooldata`
    /// and `wobjdata` of the blackboard's tools and bases, [`tool`]; RAPID's and URScript's
    /// named points, [`points`]), one line each.
    pub data: Vec<String>,
    /// Where each block of the program tree's top level begins in `steps` (byte offsets), and
    /// where the last one ends: the places a program may be split ([`split`]). Empty: the
    /// writer recorded none, the program is never split.
    pub cuts: Vec<usize>,
    /// KRL: beside each of [`Generated::cuts`], where that block's named points (and their
    /// inline forms' data) begin in `declarations`: a block declares its own points, so a part
    /// holds a slice of them. Empty: the points are not the declarations'.
    pub point_cuts: Vec<usize>,
}

/// One generated file: its extension (`src`, `dat`, `mod`, `script`) and its bytes.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct OutputFile {
    pub extension: &'static str,
    pub text: String,
    /// The file's name without the extension when it is not the program's: a part of a split
    /// program (`P_2` of `P`, [`split`]).
    pub stem: Option<String>,
    /// In the program's main file of a split program: its parts, in the order it calls them.
    pub parts: Vec<split::Part>,
}

/// An output template: the step indentation and one text per output file.
#[derive(Debug, Clone)]
pub struct OutputTemplate {
    pub language: Language,
    /// Indentation of the code lines inside each step.
    pub step_indent: String,
    /// `(extension, text)` in the profile's file order.
    pub files: Vec<(&'static str, String)>,
}

/// Placeholders replaced inside a line.
const INLINE: &[&str] = &["program", "comment"];
/// Placeholders that stand on a line of their own.
const BLOCKS: &[&str] = &["steps", "definitions", "declarations"];

impl OutputTemplate {
    /// The built-in template of `language`.
    pub fn builtin(language: Language) -> Self {
        let mut sources = Sources::default();
        let file = sources.add(
            format!("templates/{}.toml", language.name().to_ascii_lowercase()).into(),
            "<built-in template>".into(),
            language.profile().builtin_template().to_owned(),
            false,
        );
        let mut d = Diagnostics::default();
        Self::parse(&sources, file, language, &mut d).expect("the built-in templates are valid")
    }

    /// The indentation of the `{{steps}}` line.
    pub fn steps_indent(&self) -> &str {
        self.files
            .iter()
            .flat_map(|(_, t)| t.lines())
            .find(|l| block_name(l) == Some("steps"))
            .map_or("", |l| &l[..l.len() - l.trim_start().len()])
    }

    /// The text of the file with this extension.
    pub fn file(&self, ext: &str) -> &str {
        self.files
            .iter()
            .find(|(e, _)| *e == ext)
            .map_or("", |(_, t)| t)
    }

    /// Parses and checks a template file for `language`.
    pub fn parse(
        sources: &Sources,
        file: FileId,
        language: Language,
        diags: &mut Diagnostics,
    ) -> Option<Self> {
        let text = &sources.get(file).text;
        let table: toml::Table = match toml::from_str(text) {
            Ok(t) => t,
            Err(e) => {
                let range = e.span().unwrap_or(0..0);
                diags.push(
                    Diagnostic::error(
                        Code::BadTemplate,
                        format!("output template: {}", e.message()),
                    )
                    .at(Span::new(file, range)),
                );
                return None;
            }
        };
        let profile = language.profile();
        let mut ok = true;
        let mut bad = |msg: String, needle: &str| {
            let at = text.find(needle).unwrap_or(0);
            diags.push(
                Diagnostic::error(Code::BadTemplate, format!("output template: {msg}"))
                    .at(Span::new(file, at..at + needle.len().max(1))),
            );
            ok = false;
        };
        // The keys: `step_indent` and one per output file of the language.
        let mut step_indent = None;
        let mut files = Vec::new();
        for (key, value) in &table {
            let ext = profile.files().iter().find(|e| **e == key.as_str());
            let other = Language::ALL
                .iter()
                .any(|l| l.profile().files().contains(&key.as_str()));
            match (key.as_str(), value.as_str()) {
                ("step_indent", Some(v)) => step_indent = Some(v.to_owned()),
                (_, Some(body)) if ext.is_some() => {
                    files.push((*ext.expect("checked"), body.to_owned()));
                }
                (_, None) if key == "step_indent" || ext.is_some() => {
                    bad(format!("`{key}` must be a string"), key)
                }
                _ if other => bad(
                    format!(
                        "`{key}` is not a file of a {language} program, which has {}: is this a template for another language?",
                        list(profile.files())
                    ),
                    key,
                ),
                _ => bad(
                    format!(
                        "unknown field `{key}`; a {language} template has `step_indent` and {}",
                        list(profile.files())
                    ),
                    key,
                ),
            }
        }
        for ext in profile.files() {
            if !files.iter().any(|(e, _)| e == ext) {
                bad(
                    format!(
                        "a {language} template needs `{ext}` (it has {})",
                        list(profile.files())
                    ),
                    "step_indent",
                );
            }
        }
        let step_indent = step_indent.unwrap_or_else(|| {
            bad("missing field `step_indent`".to_owned(), "");
            String::new()
        });
        files.sort_by_key(|(e, _)| profile.files().iter().position(|x| x == e));
        let main = profile.files()[0];
        let mut steps = 0;
        for (key, body) in &files {
            if let Some(pos) = body.find(|c: char| !c.is_ascii()) {
                let c = body[pos..].chars().next().unwrap_or('?');
                bad(
                    format!("`{key}` contains the non-ASCII character `{c}`"),
                    &c.to_string(),
                );
            }
            for name in placeholders(body) {
                if INLINE.contains(&name) {
                    continue;
                }
                let marker = format!("{{{{{name}}}}}");
                if name == "steps" && *key != main {
                    // The program goes into the main file, the one written back.
                    bad(
                        format!("`{marker}` belongs in `{main}`, not in `{key}`"),
                        &marker,
                    );
                } else if BLOCKS.contains(&name) {
                    if !body.lines().any(|l| l.trim() == marker) {
                        bad(
                            format!("`{marker}` must stand on a line of its own in `{key}`"),
                            &marker,
                        );
                    }
                } else {
                    bad(
                        format!("unknown placeholder `{marker}` in `{key}`"),
                        &marker,
                    );
                }
            }
            if *key == main {
                steps = body.lines().filter(|l| l.trim() == "{{steps}}").count();
            }
        }
        if steps != 1 {
            bad(
                format!("`{main}` must hold `{{{{steps}}}}` exactly once (found {steps})"),
                main,
            );
        }
        if !step_indent.chars().all(|c| c == ' ' || c == '\t') {
            bad(
                "`step_indent` may only hold spaces and tabs".to_owned(),
                "step_indent",
            );
        }
        ok.then_some(OutputTemplate {
            language,
            step_indent,
            files,
        })
    }
}

fn list(exts: &[&str]) -> String {
    let v: Vec<String> = exts.iter().map(|e| format!("`{e}`")).collect();
    v.join(" and ")
}

/// The `name`s of `{{name}}` in `text`.
fn placeholders(text: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("{{") {
        let after = &rest[i + 2..];
        match after.find("}}") {
            Some(j) => {
                out.push(after[..j].trim());
                rest = &after[j + 2..];
            }
            None => break,
        }
    }
    out
}

/// The block placeholder a template line holds, if it is one.
fn block_name(line: &str) -> Option<&str> {
    let t = line.trim();
    t.strip_prefix("{{")
        .and_then(|r| r.strip_suffix("}}"))
        .filter(|n| BLOCKS.contains(n))
}

/// The comment line from the SFC's file header (company, product, version, time), ASCII.
pub fn header_comment(h: &crate::model::FileHeader) -> String {
    let parts = [
        ("Company name", &h.company_name),
        ("Product name", &h.product_name),
        ("Product version", &h.product_version),
        ("Creation time", &h.creation_date_time),
    ];
    let s: Vec<String> = parts
        .iter()
        .filter_map(|(k, v)| v.as_ref().map(|v| format!("{k}: {}", v.trim())))
        .collect();
    crate::names::transliterate(&s.join(" "))
}

/// Runs the profile's writer and fills the template: the program's files, or `None` with the
/// reasons in `diags`.
pub fn emit_files(
    input: &EmitInput,
    template: &OutputTemplate,
    diags: &mut Diagnostics,
) -> Option<Vec<OutputFile>> {
    let mut generated = input.profile.generate(input, diags)?;
    let split = split::split(input, &mut generated, diags);
    let nl = input.newline;
    let comment = header_comment(&input.sfc.header);
    let inline = |line: &str| {
        line.replace("{{program}}", input.program)
            .replace("{{comment}}", &comment)
    };
    let has_block = |name: &str| {
        template
            .files
            .iter()
            .any(|(_, t)| t.lines().any(|l| block_name(l) == Some(name)))
    };
    if !generated.declarations.is_empty() && !has_block("declarations") {
        // The program would use names nothing declares.
        diags.push(Diagnostic::error(
            Code::BadTemplate,
            format!(
                "output template: the program needs declarations ({}), but the template has no `{{{{declarations}}}}` line",
                generated.declarations.join("; ")
            ),
        ));
        return None;
    }
    if !generated.data.is_empty() && !has_block("definitions") {
        // The program would use data nothing declares.
        diags.push(Diagnostic::error(
            Code::BadTemplate,
            format!(
                "output template: the program needs its data (the blackboard's tools and bases, its named points: {}), but the template has no `{{{{definitions}}}}` line to write them",
                generated.data.iter().filter(|l| !l.starts_with(['!', '#'])).take(3).cloned().collect::<Vec<_>>().join("; ")
            ),
        ));
        return None;
    }
    if !generated.routines.is_empty() && !has_block("definitions") {
        // The program would call routines nothing defines.
        diags.push(Diagnostic::error(
            Code::BadTemplate,
            "output template: the program calls the routines of its handshakes between controllers, but the template has no `{{definitions}}` line to write them".to_owned(),
        ));
        return None;
    }
    let mut out = Vec::new();
    for (ext, body) in &template.files {
        let mut text = String::with_capacity(body.len() + 1024);
        for line in body.lines() {
            let indent = &line[..line.len() - line.trim_start().len()];
            match block_name(line) {
                Some("steps") => {
                    // The block (indented by the writer) becomes the file's text, what came
                    // before put in front: the largest text of a compile is not copied.
                    let mut steps = std::mem::take(&mut generated.steps);
                    steps.insert_str(0, &text);
                    text = steps;
                }
                Some("definitions") => definitions(
                    input,
                    &generated.data,
                    &generated.routines,
                    indent,
                    &mut text,
                ),
                Some(_) => {
                    for d in &generated.declarations {
                        text.push_str(indent);
                        text.push_str(d);
                        text.push_str(nl);
                    }
                }
                None => {
                    let line = inline(line);
                    if input.profile.trim_trailing_spaces() {
                        text.push_str(line.trim_end_matches([' ', '\t']));
                    } else {
                        text.push_str(&line);
                    }
                    text.push_str(nl);
                }
            }
        }
        if let Some(pos) = first_non_ascii(&text) {
            // Values and templates are checked before; this is the last line of defence.
            diags.push(Diagnostic::error(
                Code::NonAscii,
                format!(
                    "generated .{ext} would contain a non-ASCII character at byte {pos}; nothing was written"
                ),
            ));
            return None;
        }
        out.push(OutputFile {
            extension: ext,
            text,
            ..Default::default()
        });
    }
    if let Some(mut split) = split {
        for f in split.files(input, &comment) {
            if let Some(pos) = first_non_ascii(&f.text) {
                diags.push(Diagnostic::error(
                    Code::NonAscii,
                    format!(
                        "generated {}.{} would contain a non-ASCII character at byte {pos}; nothing was written",
                        f.stem.as_deref().unwrap_or_default(),
                        f.extension
                    ),
                ));
                return None;
            }
            out.push(f);
        }
        if let Some(main) = out.first_mut() {
            main.parts = split.parts;
        }
    }
    // For commissioning: the signals to wire, and for RAPID their declarations.
    let rows = io::rows(input);
    out.push(OutputFile {
        extension: IO_LIST,
        text: io::csv(&rows, nl),
        ..Default::default()
    });
    if input.profile.declares_signals() {
        out.push(OutputFile {
            extension: IO_CONFIG,
            text: io::eio(&rows, nl),
            ..Default::default()
        });
    }
    Some(out)
}

/// The `{{definitions}}` block: the program's `data` (tools, bases, named points), each IRL
/// definition the program holds, then its own `routines`, each after an empty line, every
/// non-empty line after `indent`; appended to `text`.
pub fn definitions(
    input: &EmitInput,
    data: &[String],
    routines: &[String],
    indent: &str,
    text: &mut String,
) {
    let nl = input.newline;
    let mut defs = input.bound.definitions.clone();
    defs.sort_by_key(|&(irl, d)| {
        let lines = &input.irls[irl].definitions[d].lines;
        input
            .profile
            .definition_rank(lines.first().map_or("", String::as_str))
    });
    // The data, each definition, then the program's own routines, after an empty line.
    let blocks = Some(data)
        .filter(|d| !d.is_empty())
        .into_iter()
        .chain(
            defs.iter()
                .map(|&(irl, d)| input.irls[irl].definitions[d].lines.as_slice()),
        )
        .chain(Some(routines).filter(|r| !r.is_empty()));
    for lines in blocks {
        text.push_str(nl);
        for l in lines {
            if !l.is_empty() {
                text.push_str(indent);
            }
            text.push_str(l);
            text.push_str(nl);
        }
    }
}

/// The I/O list's "extension": `<program>.io.csv` ([`io::csv`]).
pub const IO_LIST: &str = "io.csv";
/// A RAPID module's `EIO.cfg` fragment: `<program>.eio.cfg` ([`io::eio`]).
pub const IO_CONFIG: &str = "eio.cfg";

/// Which commissioning file `path` is ([`IO_LIST`] or [`IO_CONFIG`], by its name's end), or
/// `None` for a program file.
pub fn commissioning_file(path: &std::path::Path) -> Option<&'static str> {
    let name = path.file_name()?.to_string_lossy();
    [IO_LIST, IO_CONFIG].into_iter().find(|x| {
        name.len() > x.len() + 1
            && name.ends_with(x)
            && name.as_bytes()[name.len() - x.len() - 1] == b'.'
    })
}

/// The byte index of the first non-ASCII character. `is_ascii` reads words at a time; the place
/// is looked for only when there is one (13 MB of program text for 100,000 steps).
fn first_non_ascii(text: &str) -> Option<usize> {
    if text.is_ascii() {
        None
    } else {
        text.bytes().position(|b| !b.is_ascii())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_non_ascii_character_is_found_where_it_starts() {
        assert_eq!(first_non_ascii("PTP HOME\r\n"), None);
        assert_eq!(first_non_ascii(""), None);
        assert_eq!(first_non_ascii("ab\u{e4}c\u{20ac}"), Some(2));
        let long = format!("{}\u{20ac}", "x".repeat(1000));
        assert_eq!(first_non_ascii(&long), Some(1000));
        assert_eq!(
            first_non_ascii(&long),
            long.find(|c: char| !c.is_ascii()),
            "the place a char search gives"
        );
    }

    fn parse(lang: Language, text: &str) -> (Option<OutputTemplate>, Vec<String>) {
        let mut s = Sources::default();
        let f = s.add("t.toml".into(), "t.toml".into(), text.to_owned(), false);
        let mut d = Diagnostics::default();
        let t = OutputTemplate::parse(&s, f, lang, &mut d);
        (t, d.iter().map(|d| d.message.clone()).collect())
    }

    #[test]
    fn builtin_templates_parse() {
        for l in Language::ALL {
            let t = OutputTemplate::builtin(l);
            assert_eq!(t.files.len(), l.profile().files().len(), "{l}");
            assert!(t.file(l.profile().files()[0]).contains("{{steps}}"), "{l}");
        }
    }

    #[test]
    fn template_errors() {
        let k = Language::Krl;
        let (t, m) = parse(k, "step_indent = \" \"\nsrc = \"DEF x\"\ndat = \"\"\n");
        assert!(t.is_none());
        assert!(m[0].contains("exactly once"), "{m:?}");
        let (t, m) = parse(
            k,
            "step_indent = \" \"\nsrc = \"\"\"\n{{steps}}\n{{oops}}\n\"\"\"\ndat = \"\"\n",
        );
        assert!(t.is_none());
        assert!(m[0].contains("unknown placeholder `{{oops}}`"), "{m:?}");
        let (t, m) = parse(
            k,
            "step_indent = \" \"\nsrc = \"\"\"\n{{steps}}\n\"\"\"\ndat = \"\"\nextra = 1\n",
        );
        assert!(t.is_none());
        assert!(m[0].contains("unknown field"), "{m:?}");
        // The program belongs in the main file.
        let (t, m) = parse(
            k,
            "step_indent = \" \"\nsrc = \"\"\"\n{{steps}}\n\"\"\"\ndat = \"\"\"\n{{steps}}\n\"\"\"\n",
        );
        assert!(t.is_none());
        assert!(m.iter().any(|m| m.contains("belongs in `src`")), "{m:?}");
        // A KRL template given to a RAPID program.
        let (t, m) = parse(
            Language::Rapid,
            "step_indent = \" \"\nsrc = \"\"\"\n{{steps}}\n\"\"\"\ndat = \"\"\n",
        );
        assert!(t.is_none());
        assert!(m.iter().any(|m| m.contains("another language")), "{m:?}");
    }

    #[test]
    fn languages_parse_in_any_case() {
        assert_eq!(Language::parse(" urscript "), Some(Language::UrScript));
        assert_eq!(Language::parse("Rapid"), Some(Language::Rapid));
        assert_eq!(Language::parse("krl"), Some(Language::Krl));
        assert_eq!(Language::parse("C++"), None);
    }

    #[test]
    fn program_names_follow_each_languages_rules() {
        let ok = |l: Language, n: &str| l.profile().check_program_name(n).is_ok();
        use Language::*;
        assert!(ok(Krl, &"a".repeat(24)) && !ok(Krl, &"a".repeat(25)));
        assert!(ok(Krl, "_cell") && !ok(Krl, "LOOP") && !ok(Krl, "1a"));
        assert!(ok(Rapid, &"a".repeat(32)) && !ok(Rapid, &"a".repeat(33)));
        assert!(!ok(Rapid, "_cell") && !ok(Rapid, "EndProc") && !ok(Rapid, "a-b"));
        assert!(ok(UrScript, &"a".repeat(63)) && !ok(UrScript, &"a".repeat(64)));
        assert!(ok(UrScript, "_cell") && !ok(UrScript, "1a") && !ok(UrScript, "end"));
        // URScript is case-sensitive: `End` is a name.
        assert!(ok(UrScript, "End"));
    }
}
