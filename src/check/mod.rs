//! The project's own check of robot programs (issue 28): the block structure a controller
//! needs before it loads a program, per language, line by line. Used on every IRL snippet a
//! program uses (so a broken snippet is an error located in its IRL file), on every generated
//! program before it is written, and by `skillpost check FILE...` for programs edited by hand.
//!
//! What it holds a text to:
//! - **KRL** (`.src`, `.dat`; keywords in any case, `;` comments, `"strings"`): `DEF`/`DEFFCT`
//!   … `END`/`ENDFCT`, `DEFDAT` … `ENDDAT`, `IF … THEN` \[`ELSE`\] `ENDIF`, `LOOP`/`ENDLOOP`,
//!   `WHILE`/`ENDWHILE`, `FOR`/`ENDFOR`, `REPEAT`/`UNTIL`, `SWITCH`/`CASE`/`DEFAULT`/`ENDSWITCH`,
//!   `SPLINE`/`PTP_SPLINE` … `ENDSPLINE`; `EXIT` only in a loop; `;FOLD`/`;ENDFOLD` balanced; in a
//!   whole `.src`/`.dat` no statement outside its `DEF`/`DEFDAT` (`&` header lines allowed);
//!   declarations (`DECL`, or a data type) before a routine's first statement; the names of
//!   `DEF`, `DEFFCT` and `DEFDAT` KRL names.
//! - **RAPID** (`.mod`, `.modx`, `.sys`; any case, `!` comments): `MODULE` … `ENDMODULE`,
//!   `PROC`/`FUNC`/`TRAP` … `ENDPROC`/`ENDFUNC`/`ENDTRAP` (with `LOCAL`), `IF … THEN`
//!   [`ELSEIF … THEN`]* \[`ELSE`\] `ENDIF` (a compact `IF c stmt;` opens nothing), `WHILE … DO`,
//!   `FOR … DO`, `TEST` with `CASE`/`DEFAULT`, `ENDTEST`; `ERROR`/`BACKWARD`/`UNDO` only in a
//!   routine; in a whole module no routine outside `MODULE`.
//! - **URScript** (`.script`; `#` comments): `def`/`thread`/`if`/`elif`/`else`/`while` lines end
//!   in `:` and open (or continue) a block that a line `end` closes; `elif`/`else` only in an
//!   `if` (nothing after its `else`); `break`/`continue` only in a `while`; a block's lines
//!   indented deeper than its first line, its `end`/`elif`/`else` as deep as it.
//!
//! Not a full parser: expressions and statements are the tests' business (the KRL grammar and
//! rapidchecker agree with this check on every program the tests generate).

use crate::lang::Language;

/// One problem: 1-based line and column in the checked text, and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    pub line: usize,
    pub column: usize,
    pub message: String,
    /// Where the block the problem is about was opened (line, column).
    pub opened: Option<(usize, usize)>,
}

/// What is checked: a whole file of the language, or a snippet that goes into one (an IRL
/// definition or call: its blocks must close within it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unit {
    /// A KRL `.src`, a RAPID module, a URScript file.
    Program,
    /// A KRL `.dat`.
    Data,
    /// A snippet that goes into a program: its blocks close within it.
    Snippet,
    /// KRL routines that go after the main program's `END` (IRL definitions): a snippet whose
    /// statements all stand inside its `DEF`s or `DEFFCT`s.
    Routines,
}

/// The language of a file by its extension (`skillpost check`).
pub fn language_of(path: &std::path::Path) -> Option<(Language, Unit)> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    Some(match ext.as_str() {
        "src" | "sub" => (Language::Krl, Unit::Program),
        "dat" => (Language::Krl, Unit::Data),
        "mod" | "modx" | "sys" | "sysx" | "prg" => (Language::Rapid, Unit::Program),
        "script" | "urscript" => (Language::UrScript, Unit::Program),
        _ => return None,
    })
}

/// At most this many problems of one text are kept (the first ones found); the others are only
/// counted ([`Checked::more`]), so a hostile file's report and memory stay small.
pub const MAX_PROBLEMS: usize = 100;

/// Blocks (and KRL folds) open at once beyond which a text is not checked further: no program
/// skillpost writes comes near (branches and loops nest at most 128 levels, a few blocks each),
/// and the open blocks are what the check keeps per line.
pub const MAX_OPEN: usize = 4096;

/// What [`check_counted`] found: the first [`MAX_PROBLEMS`] problems, sorted by place, and how
/// many more there were.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Checked {
    pub problems: Vec<Problem>,
    pub more: usize,
}

/// Checks `text` as `unit` of `language`: its first [`MAX_PROBLEMS`] problems.
pub fn check(language: Language, unit: Unit, text: &str) -> Vec<Problem> {
    check_counted(language, unit, text).problems
}

/// Checks `text` as `unit` of `language`, counting the problems beyond [`MAX_PROBLEMS`].
pub fn check_counted(language: Language, unit: Unit, text: &str) -> Checked {
    match language {
        Language::Krl => krl::krl(unit, text),
        Language::Rapid => rapid::rapid(unit, text),
        Language::UrScript => urscript::urscript(text),
    }
}

/// An open block: its keyword, where it opened, and what it allows next.
struct Open {
    kind: &'static str,
    line: usize,
    column: usize,
    /// An `ELSE` was seen (IF): nothing but the end may follow.
    closed_else: bool,
}

/// The lines of `text` as [`str::lines`] gives them (split at `\n`, a `\r` before it cut, no
/// empty line after a final line break), the breaks found by `memchr` over the whole text: a
/// program of 100,000 steps has a million lines, and `str::lines` searches each anew.
fn lines(text: &str) -> impl Iterator<Item = &str> {
    let mut breaks = memchr::memchr_iter(b'\n', text.as_bytes());
    let mut start = 0;
    std::iter::from_fn(move || match breaks.next() {
        Some(i) => {
            let line = &text[start..i];
            start = i + 1;
            Some(line.strip_suffix('\r').unwrap_or(line))
        }
        None if start < text.len() => {
            let line = &text[start..];
            start = text.len();
            Some(line)
        }
        None => None,
    })
}

/// Whether an ASCII byte is white space as [`char::is_whitespace`] has it (the vertical tab
/// too, which [`u8::is_ascii_whitespace`] leaves out).
fn is_space(c: u8) -> bool {
    matches!(c, b'\t' | b'\n' | 0x0b | 0x0c | b'\r' | b' ')
}

/// `s` without its leading white space, as [`str::trim_start`]; ASCII white space is skipped
/// byte by byte, the rest (rare) left to `trim_start`.
fn trim_start(s: &str) -> &str {
    let n = s.bytes().position(|c| !is_space(c)).unwrap_or(s.len());
    let rest = &s[n..];
    if rest.as_bytes().first().is_some_and(|c| !c.is_ascii()) {
        rest.trim_start()
    } else {
        rest
    }
}

/// `s` without its trailing white space, as [`str::trim_end`] (ASCII byte by byte, as above).
fn trim_end(s: &str) -> &str {
    let n = s.bytes().rposition(|c| !is_space(c)).map_or(0, |i| i + 1);
    let rest = &s[..n];
    if rest.as_bytes().last().is_some_and(|c| !c.is_ascii()) {
        rest.trim_end()
    } else {
        rest
    }
}

/// The code of a line without its comment (`comment` outside `"strings"`), and where the code
/// starts (1-based column).
fn code_of(line: &str, comment: char) -> (&str, usize) {
    // Byte by byte (both characters are ASCII), from one quote or comment character to the
    // next: every line of every generated program passes here.
    let (b, c) = (line.as_bytes(), comment as u8);
    debug_assert!(comment.is_ascii());
    let mut in_string = false;
    let mut end = line.len();
    let mut at = 0;
    while let Some(k) = memchr::memchr2(b'"', c, &b[at..]) {
        let i = at + k;
        if b[i] == b'"' {
            in_string = !in_string;
        } else if !in_string {
            end = i;
            break;
        }
        at = i + 1;
    }
    let code = &line[..end];
    let trimmed = trim_start(code);
    let indent = &code[..code.len() - trimmed.len()];
    let column = if indent.is_ascii() {
        indent.len()
    } else {
        indent.chars().count()
    } + 1;
    (trim_end(trimmed), column)
}

/// The first word, upper case (letters, digits, `_`, `$`).
fn is_word_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_' || c == '$'
}

/// A word upper case: the text's own when it has no lower-case letter (as generated code
/// mostly is), else a copy on the stack. Every line's first word is looked at, and a program of
/// 100,000 steps has a million lines. Longer words than any keyword are kept as `""`.
enum Word<'t> {
    Upper(&'t str),
    Folded { buf: [u8; 16], len: usize },
}

impl Word<'_> {
    fn as_str(&self) -> &str {
        match self {
            Word::Upper(w) => w,
            Word::Folded { buf, len } => std::str::from_utf8(&buf[..*len]).unwrap_or(""),
        }
    }
}

/// Where the word `s` starts with ends (letters, digits, `_`, `$`; [`is_word_char`] on bytes: a
/// byte that is not ASCII is no word character, as its character is none).
fn word_end(s: &str) -> usize {
    s.bytes()
        .position(|c| !(c.is_ascii_alphanumeric() || c == b'_' || c == b'$'))
        .unwrap_or(s.len())
}

/// The first word of `code` (letters, digits, `_`, `$`), upper case, and the text after it.
fn first_word(code: &str) -> (Word<'_>, &str) {
    let b = code.as_bytes();
    // The word's end and whether it has a lower-case letter, in one pass.
    let mut end = 0;
    let mut lower = false;
    while let Some(&c) = b.get(end) {
        if c.is_ascii_lowercase() {
            lower = true;
        } else if !(c.is_ascii_uppercase() || c.is_ascii_digit() || c == b'_' || c == b'$') {
            break;
        }
        end += 1;
    }
    let w = if end > 16 {
        Word::Upper("")
    } else if !lower {
        // (ASCII: a character boundary.)
        Word::Upper(&code[..end])
    } else {
        let mut buf = [0; 16];
        buf[..end].copy_from_slice(&b[..end]);
        buf[..end].make_ascii_uppercase();
        Word::Folded { buf, len: end }
    };
    (w, trim_start(&code[end..]))
}

/// Whether the last word of `code` is `word` (any case).
fn ends_with_word(code: &str, word: &str) -> bool {
    code.rsplit(|c: char| !is_word_char(c))
        .find(|w| !w.is_empty())
        .is_some_and(|w| w.eq_ignore_ascii_case(word))
}

/// A problem (`problem!(blocks, line, column, message)`), its message made only when it is kept.
macro_rules! problem {
    ($b:expr, $line:expr, $column:expr, $message:expr $(,)?) => {
        if $b.keeps() {
            $b.problem($line, $column, $message)
        } else {
            $b.more += 1
        }
    };
}

/// A problem about a block opened at `$opened` (`problem_at!(blocks, line, column, message,
/// opened)`), its message made only when it is kept.
macro_rules! problem_at {
    ($b:expr, $line:expr, $column:expr, $message:expr, $opened:expr $(,)?) => {
        if $b.keeps() {
            $b.problem_at($line, $column, $message, $opened)
        } else {
            $b.more += 1
        }
    };
}

struct Blocks {
    stack: Vec<Open>,
    problems: Vec<Problem>,
    /// Problems found beyond [`MAX_PROBLEMS`].
    more: usize,
    /// More than [`MAX_OPEN`] blocks were open: the rest of the text is not checked.
    stopped: bool,
}

impl Blocks {
    fn new() -> Self {
        Blocks {
            stack: Vec::new(),
            problems: Vec::new(),
            more: 0,
            stopped: false,
        }
    }

    /// Keeps a problem while fewer than [`MAX_PROBLEMS`] are kept, else counts it; the message
    /// is made only when it is kept.
    fn push(
        &mut self,
        line: usize,
        column: usize,
        message: impl FnOnce() -> String,
        opened: Option<(usize, usize)>,
    ) {
        if self.problems.len() < MAX_PROBLEMS {
            self.problems.push(Problem {
                line,
                column,
                message: message(),
                opened,
            });
        } else {
            self.more += 1;
        }
    }

    /// Whether a problem found now is kept (else only counted).
    fn keeps(&self) -> bool {
        self.problems.len() < MAX_PROBLEMS
    }

    fn problem(&mut self, line: usize, column: usize, message: String) {
        self.push(line, column, || message, None);
    }

    fn problem_at(&mut self, line: usize, column: usize, message: String, o: (usize, usize)) {
        self.push(line, column, || message, Some(o));
    }

    /// Stops the check at `line` when `open` blocks (or folds) are more than [`MAX_OPEN`].
    fn too_deep(&mut self, open: usize, line: usize, column: usize) -> bool {
        if open >= MAX_OPEN && !self.stopped {
            self.stopped = true;
            self.push(
                line,
                column,
                || format!("blocks nested deeper than {MAX_OPEN} levels: the rest is not checked"),
                None,
            );
        }
        self.stopped
    }

    fn open(&mut self, kind: &'static str, line: usize, column: usize) {
        if self.too_deep(self.stack.len(), line, column) {
            return;
        }
        self.stack.push(Open {
            kind,
            line,
            column,
            closed_else: false,
        });
    }

    /// Closes the innermost block with `end` (its keyword), which must be one of `kinds`.
    fn close(&mut self, end: &str, kinds: &[&'static str], line: usize, column: usize) {
        match self.stack.last() {
            Some(o) if kinds.contains(&o.kind) => {
                self.stack.pop();
            }
            Some(o) => {
                let (k, at) = (o.kind, (o.line, o.column));
                problem_at!(
                    self,
                    line,
                    column,
                    format!("`{end}` where `{k}` is still open"),
                    at,
                );
                // Recover: close up to a matching block if there is one.
                if let Some(i) = self.stack.iter().rposition(|o| kinds.contains(&o.kind)) {
                    self.stack.truncate(i);
                }
            }
            None => problem!(
                self,
                line,
                column,
                format!("`{end}` without its `{}`", kinds[0])
            ),
        }
    }

    /// A keyword that continues the innermost block (`ELSE`, `CASE`), which must be `kind`.
    fn middle(&mut self, word: &str, kind: &'static str, line: usize, column: usize) {
        match self.stack.last_mut() {
            Some(o) if o.kind == kind => {
                if o.closed_else {
                    let at = (o.line, o.column);
                    problem_at!(
                        self,
                        line,
                        column,
                        format!("`{word}` after the `else` of its `{kind}`"),
                        at,
                    );
                }
            }
            _ => problem!(
                self,
                line,
                column,
                format!("`{word}` outside an `{kind}` block")
            ),
        }
    }

    /// The `else` of the innermost block, which must be `kind`: after it only the end.
    fn else_(&mut self, word: &str, kind: &'static str, line: usize, column: usize) {
        self.middle(word, kind, line, column);
        if let Some(o) = self.stack.last_mut()
            && o.kind == kind
        {
            o.closed_else = true;
        }
    }

    fn in_any(&self, kinds: &[&str]) -> bool {
        self.stack.iter().any(|o| kinds.contains(&o.kind))
    }

    fn finish(mut self) -> Checked {
        for o in std::mem::take(&mut self.stack).into_iter().rev() {
            let at = (o.line, o.column);
            problem_at!(
                self,
                o.line,
                o.column,
                format!("`{}` is never closed", o.kind),
                at,
            );
        }
        self.problems.sort_by_key(|p| (p.line, p.column));
        Checked {
            problems: self.problems,
            more: self.more,
        }
    }
}

// (After the macros above, which the languages' checks use.)
mod krl;
mod rapid;
mod urscript;

#[cfg(test)]
mod tests {
    use super::*;

    fn msgs(l: Language, u: Unit, t: &str) -> Vec<String> {
        check(l, u, t)
            .into_iter()
            .map(|p| format!("{}:{}: {}", p.line, p.column, p.message))
            .collect()
    }

    /// The byte-wise line splitting and trimming give what `str::lines` and `str::trim_*` give,
    /// for line breaks of every kind and white space beyond ASCII (a `.src` a user checks with
    /// `skillpost check` may hold any).
    #[test]
    fn the_fast_lines_and_trims_equal_the_standard_ones() {
        let texts = [
            "",
            "\n",
            "a",
            "a\n",
            "a\r\nb\rc\n\r\n",
            "x\r",
            "\r\n\r\n",
            "  \u{a0} x \u{3000}\n\u{2003}y\t\r\n \u{85}",
            "\u{b}z\u{c}\n\t\n",
        ];
        for t in texts {
            assert_eq!(
                lines(t).collect::<Vec<_>>(),
                t.lines().collect::<Vec<_>>(),
                "{t:?}"
            );
            for l in t.split('\n').chain(t.lines()) {
                assert_eq!(trim_start(l), l.trim_start(), "{l:?}");
                assert_eq!(trim_end(l), l.trim_end(), "{l:?}");
            }
        }
        // The column counts characters of the indentation.
        assert_eq!(code_of("\u{3000}\u{3000}PTP P1 ; x", ';'), ("PTP P1", 3));
        assert_eq!(code_of("\t  WAIT SEC 1", ';'), ("WAIT SEC 1", 4));
    }

    /// A line's first word is its upper-case form whether the text already is upper case (taken
    /// as it is) or not (folded on the stack); a word longer than any keyword is `""`.
    #[test]
    fn the_first_word_is_upper_case_either_way() {
        for (code, word, after) in [
            ("ENDIF", "ENDIF", ""),
            ("endIf ; x", "ENDIF", "; x"),
            ("$VEL.CP = 1", "$VEL", ".CP = 1"),
            ("e6pos_2 P", "E6POS_2", "P"),
            ("DECL E6POS X1={X 1}", "DECL", "E6POS X1={X 1}"),
            ("ABCDEFGHIJKLMNOP x", "ABCDEFGHIJKLMNOP", "x"),
            ("ABCDEFGHIJKLMNOPQ x", "", "x"),
            ("abcdefghijklmnopq x", "", "x"),
            ("Wait\u{e4} 1", "WAIT", "\u{e4} 1"),
            ("", "", ""),
        ] {
            let (w, rest) = first_word(code);
            assert_eq!((w.as_str(), rest), (word, after), "{code:?}");
        }
        // Keywords in any case: the same check.
        let lower = "def p( )\n  if a then\n    loop\n      exit\n    endloop\n  endif\nend\n";
        assert_eq!(
            msgs(Language::Krl, Unit::Program, lower),
            Vec::<String>::new()
        );
        assert_eq!(
            msgs(Language::Krl, Unit::Program, "Def p( )\n  If a Then\nEnd\n").len(),
            1
        );
    }

    #[test]
    fn problems_beyond_the_cap_are_counted_and_deep_nesting_stops_the_check() {
        let c = check_counted(Language::Krl, Unit::Snippet, &"ENDIF\n".repeat(1000));
        assert_eq!(
            (c.problems.len(), c.more),
            (MAX_PROBLEMS, 1000 - MAX_PROBLEMS)
        );
        assert_eq!(c.problems[MAX_PROBLEMS - 1].line, MAX_PROBLEMS);
        let deep = "if a:\n".repeat(2 * MAX_OPEN) + "end\n";
        let c = check_counted(Language::UrScript, Unit::Program, &deep);
        // Lines 2 to MAX_OPEN + 1 not indented, the stop at line MAX_OPEN + 1, the open
        // blocks never closed; nothing after the stop.
        assert_eq!(c.problems.len() + c.more, 2 * MAX_OPEN + 1);
        assert!(c.problems.iter().all(|p| p.line <= MAX_OPEN + 1), "{c:?}");
        let folds = ";FOLD\n".repeat(MAX_OPEN + 10);
        let c = check_counted(Language::Krl, Unit::Snippet, &folds);
        assert!(
            c.problems
                .iter()
                .any(|p| p.message.contains("nested deeper")),
            "{c:?}"
        );
    }

    #[test]
    fn krl_blocks() {
        let ok = "&ACCESS RVP\nDEF P( )\n  ;FOLD x\n  IF $IN[1] THEN\n    LOOP\n      EXIT\n    ENDLOOP\n  ELSE\n    WAIT SEC 0\n  ENDIF\n  ;ENDFOLD\nEND\n";
        assert_eq!(msgs(Language::Krl, Unit::Program, ok), Vec::<String>::new());
        assert_eq!(
            msgs(Language::Krl, Unit::Snippet, "IF a THEN\n  x = 1\n"),
            ["1:1: `IF` is never closed"]
        );
        assert_eq!(
            msgs(Language::Krl, Unit::Snippet, "  ENDLOOP\n"),
            ["1:3: `ENDLOOP` without its `LOOP`"]
        );
        assert_eq!(
            msgs(Language::Krl, Unit::Snippet, "IF a THEN\nENDLOOP\nENDIF\n"),
            ["2:1: `ENDLOOP` where `IF` is still open"]
        );
        assert_eq!(
            msgs(Language::Krl, Unit::Program, "x = 1\nDEF P()\nEXIT\nEND\n"),
            [
                "1:1: a statement outside any `DEF` … `END`: `x = 1`",
                "3:1: `EXIT` outside a loop"
            ]
        );
        assert_eq!(
            msgs(
                Language::Krl,
                Unit::Snippet,
                "if a then ; comment ENDIF\nendif\n"
            ),
            Vec::<String>::new()
        );
        assert_eq!(
            msgs(Language::Krl, Unit::Snippet, ";FOLD a\n"),
            ["1:1: `;FOLD` without its `;ENDFOLD`"]
        );
        assert_eq!(
            msgs(
                Language::Krl,
                Unit::Routines,
                "DEF F(V:IN)\n  DECL REAL V\n  INT i\n  $VEL.CP = V\n  DECL INT late\nEND\n"
            ),
            [
                "5:3: a declaration after the first statement of its routine (KRL wants the declarations first)"
            ]
        );
        assert_eq!(
            msgs(
                Language::Krl,
                Unit::Routines,
                "DEF Move-It()\nEND\nDEFFCT INT ThisNameIsFarTooLongForKrl_1()\nENDFCT\n"
            ),
            [
                "1:1: `Move-It` is no KRL name (a letter or `_`, then letters, digits or `_`, at most 24 characters)",
                "3:1: `ThisNameIsFarTooLongForKrl_1` is no KRL name (a letter or `_`, then letters, digits or `_`, at most 24 characters)"
            ]
        );
        // What a declaration declares is a KRL name too.
        let dat = "DEFDAT P\nDECL E6POS XPick={X 1, Y 2}\nDECL GLOBAL CONST INT n=1\nINT i, j\nDECL REAL v[10]\nSIGNAL skp_rx $IN[1] TO $IN[4]\nDECL E6POS XAVeryLongStepNameThatGoesOnAndOn={X 1}\nDECL INT 1st\nDECL FDAT FPick={TOOL_NO 1}\nENDDAT\n";
        assert_eq!(
            msgs(Language::Krl, Unit::Data, dat),
            [
                "7:1: `XAVeryLongStepNameThatGoesOnAndOn` is no KRL name (a letter or `_`, then letters, digits or `_`, at most 24 characters)",
                "8:1: `1st` is no KRL name (a letter or `_`, then letters, digits or `_`, at most 24 characters)"
            ]
        );
    }

    #[test]
    fn rapid_blocks() {
        let ok = "MODULE M\n  PROC main()\n    IF a THEN\n      b;\n    ELSEIF c THEN\n    ELSE\n    ENDIF\n    IF a b;\n    WHILE TRUE DO\n    ENDWHILE\n  ERROR\n    RETRY;\n  ENDPROC\nENDMODULE\n";
        assert_eq!(
            msgs(Language::Rapid, Unit::Program, ok),
            Vec::<String>::new()
        );
        assert_eq!(
            msgs(Language::Rapid, Unit::Snippet, "IF a THEN\n  b;\n"),
            ["1:1: `IF` is never closed"]
        );
        assert_eq!(
            msgs(
                Language::Rapid,
                Unit::Snippet,
                "PROC p()\nIF a THEN\nENDPROC\n"
            ),
            ["3:1: `ENDPROC` where `IF` is still open"]
        );
    }

    #[test]
    fn urscript_blocks() {
        let ok = "def P():\n  if a:\n    b()\n  elif c:\n    d()\n  else:\n    e()\n  end\n  while True:\n    break\n  end\nend\nP()\n";
        assert_eq!(
            msgs(Language::UrScript, Unit::Program, ok),
            Vec::<String>::new()
        );
        assert_eq!(
            msgs(Language::UrScript, Unit::Snippet, "if a:\n  b()\n"),
            ["1:1: `if` is never closed"]
        );
        assert_eq!(
            msgs(Language::UrScript, Unit::Snippet, "end\nbreak\n"),
            [
                "1:1: `end` without its `def`",
                "2:1: `break` outside a `while`"
            ]
        );
        assert_eq!(
            msgs(
                Language::UrScript,
                Unit::Snippet,
                "def f():\nmovej(p)\n  end\n"
            ),
            [
                "2:1: a line of a `def` block not indented deeper than the block's first line",
                "3:3: `end` indented to column 3, its `def` to column 1"
            ]
        );
        assert_eq!(
            msgs(
                Language::UrScript,
                Unit::Snippet,
                "if a:\nelse:\nelif b:\nend\n"
            ),
            ["3:1: `elif` after the `else` of its `if`"]
        );
    }
}
