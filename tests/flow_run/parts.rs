//! Following a split program's calls into its parts (docs/LANGUAGES.md, "Long programs"): the
//! interpreters run one routine, so a call of a part is replaced by the part's statements. A part
//! gets the main program's variables by reference (KRL `:OUT`, RAPID `VAR` parameters, URScript globals)
//! under their own names, so its statements mean in the main program what they mean in the part;
//! what a part declares itself joins the main program's declarations (KRL: the `.dat`; RAPID:
//! the `VAR`s of `PROC main()`).

use std::collections::HashSet;
use std::path::Path;

/// The statements of the routine that starts at `lines[start]` (its header), up to the line
/// `end` at the header's indentation; returns them and the index after `end`.
fn body<'a>(lines: &[&'a str], start: usize, end: &str) -> (Vec<&'a str>, usize) {
    let indent = lines[start].len() - lines[start].trim_start().len();
    let mut out = Vec::new();
    let mut i = start + 1;
    while i < lines.len() {
        let l = lines[i];
        if l.len() - l.trim_start().len() == indent && l.trim() == end {
            return (out, i + 1);
        }
        out.push(l);
        i += 1;
    }
    panic!("part: no `{end}` after `{}`", lines[start]);
}

/// The called routine of a call line (`P_1(a, b)`, `P_1_run a, b;`, `P_1()`), when `is_part`
/// says it is a part's.
fn callee<'a>(line: &'a str, is_part: &dyn Fn(&str) -> bool) -> Option<&'a str> {
    let t = line.split(';').next().unwrap_or("").trim();
    let t = if t.is_empty() { line.trim() } else { t };
    let name: &str = t.split(['(', ' ', ';']).next().unwrap_or("");
    (!name.is_empty() && is_part(name)).then_some(name)
}

/// KRL: `main` (a `.src`) and `dat` with every call of a part (`P_k(...)`, whose `P_k.src` in
/// `dir` names itself a part) replaced by the part's statements, and the part's `.dat`
/// declarations added to `dat` (each name once).
pub fn krl(dir: &Path, main: &str, dat: &str) -> (String, String) {
    let read = |stem: &str, ext: &str| std::fs::read_to_string(dir.join(format!("{stem}.{ext}")));
    let is_part = |name: &str| read(name, "src").is_ok_and(|t| t.contains(";skillpost part "));
    let mut src = String::new();
    let mut extra: Vec<String> = Vec::new();
    for l in main.lines() {
        let Some(part) = callee(l, &is_part) else {
            src.push_str(l);
            src.push('\n');
            continue;
        };
        let text = read(part, "src").unwrap();
        let lines: Vec<&str> = text.lines().collect();
        let def = lines
            .iter()
            .position(|l| l.trim_start().to_ascii_uppercase().starts_with("DEF "))
            .unwrap();
        let (stmts, _) = body(&lines, def, "END");
        for s in stmts {
            let upper = s.trim_start().to_ascii_uppercase();
            // The parameters' declarations: the main program's variables.
            if upper.starts_with("DECL ") {
                continue;
            }
            src.push_str(s);
            src.push('\n');
        }
        let pdat = read(part, "dat").unwrap();
        extra.extend(
            pdat.lines()
                .filter(|l| {
                    let u = l.trim_start().to_ascii_uppercase();
                    u.starts_with("DECL ") || u.starts_with("SIGNAL ")
                })
                .map(str::to_owned),
        );
    }
    // The part's own declarations, each name once (a name the main `.dat` has is the same).
    let name = |l: &str| -> String {
        let w: Vec<&str> = l.split_whitespace().collect();
        let n = if w[0].eq_ignore_ascii_case("SIGNAL") {
            w[1]
        } else {
            w[2]
        };
        n.split(['=', '[']).next().unwrap().to_ascii_uppercase()
    };
    let mut seen: HashSet<String> = dat
        .lines()
        .filter(|l| {
            let u = l.trim_start().to_ascii_uppercase();
            u.starts_with("DECL ") || u.starts_with("SIGNAL ")
        })
        .map(name)
        .collect();
    let mut out = String::new();
    for l in dat.lines() {
        if l.trim().eq_ignore_ascii_case("ENDDAT") {
            for e in &extra {
                if seen.insert(name(e)) {
                    out.push_str(e);
                    out.push('\n');
                }
            }
        }
        out.push_str(l);
        out.push('\n');
    }
    (src, out)
}

/// RAPID: `main` with every call of a part (`P_k_run args;`, whose module `P_k.mod` in `dir`
/// names itself a part) replaced by the routine's statements, its own `VAR`s added after
/// `PROC main()`'s (each once).
pub fn rapid(dir: &Path, main: &str) -> String {
    let module = |routine: &str| -> Option<String> {
        let stem = routine.strip_suffix("_run")?;
        std::fs::read_to_string(dir.join(format!("{stem}.mod")))
            .ok()
            .filter(|t| t.contains("! skillpost part "))
    };
    let is_part = |name: &str| module(name).is_some();
    let mut vars: Vec<String> = Vec::new();
    let mut steps = Vec::new();
    for l in main.lines() {
        let Some(part) = callee(l, &is_part) else {
            steps.push(l.to_owned());
            continue;
        };
        let text = module(part).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        let proc_ = lines
            .iter()
            .position(|l| l.trim_start().starts_with("PROC "))
            .unwrap();
        let (stmts, _) = body(&lines, proc_, "ENDPROC");
        for s in stmts {
            if s.trim_start().starts_with("VAR ") {
                if !vars.iter().any(|v| v.trim() == s.trim()) {
                    vars.push(s.to_owned());
                }
            } else {
                steps.push(s.to_owned());
            }
        }
    }
    // The parts' own variables among main's declarations (a name main declares is the same).
    let declared: HashSet<String> = steps
        .iter()
        .filter(|l| l.trim_start().starts_with("VAR "))
        .map(|l| l.trim().to_owned())
        .collect();
    let mut out = String::new();
    for l in &steps {
        out.push_str(l);
        out.push('\n');
        if l.trim() == "PROC main()" {
            for v in &vars {
                if !declared.contains(v.trim()) {
                    out.push_str(v);
                    out.push('\n');
                }
            }
        }
    }
    out
}

/// URScript: `script` with every call of a part's function (`P_k()`, defined in the script after
/// a `# skillpost`-free `def` whose name a `# part` comment before the call names) replaced by
/// its statements, and the parts' definitions taken out.
pub fn urscript(script: &str) -> String {
    let lines: Vec<&str> = script.lines().collect();
    // The called parts: a call right after a `# part k of n` comment.
    let mut parts: Vec<String> = Vec::new();
    for w in lines.windows(2) {
        if w[0].trim().starts_with("# part ") {
            parts.push(w[1].trim().trim_end_matches("()").to_owned());
        }
    }
    let mut bodies: Vec<(String, Vec<String>)> = Vec::new();
    let mut kept = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let t = lines[i].trim();
        if let Some(name) = t
            .strip_prefix("def ")
            .and_then(|r| r.strip_suffix("():"))
            .filter(|n| parts.iter().any(|p| p == n))
        {
            let (stmts, next) = body(&lines, i, "end");
            bodies.push((
                name.to_owned(),
                stmts
                    .iter()
                    .map(|s| s.strip_prefix("  ").unwrap_or(s).to_owned())
                    .collect(),
            ));
            i = next;
            continue;
        }
        kept.push(lines[i]);
        i += 1;
    }
    let mut out = String::new();
    for l in kept {
        let t = l.trim();
        if let Some((_, stmts)) = bodies
            .iter()
            .find(|(n, _)| t.strip_suffix("()") == Some(n.as_str()))
        {
            for s in stmts {
                out.push_str(s);
                out.push('\n');
            }
            continue;
        }
        out.push_str(l);
        out.push('\n');
    }
    out
}

/// A program's main file (and KRL `.dat`) with its parts' calls followed ([`krl`], [`rapid`],
/// [`urscript`]); unchanged for a program that is not split.
pub fn follow(lang: crate::Lang, dir: &Path, main: String, dat: String) -> (String, String) {
    match lang {
        crate::Lang::Krl => krl(dir, &main, &dat),
        crate::Lang::Rapid => (rapid(dir, &main), dat),
        crate::Lang::UrScript => (urscript(&main), dat),
    }
}

/// A generated chart of 20,000 skill steps (two-way selections and simultaneous branches on its
/// top level) in `lang`, compiled once unsplit (`--max-lines 0`) and once split at 5,000 lines:
/// the split program has parts, every file passes the language's check (the built-in one while
/// compiling; KRL's structure check, `rapidchecker`, the URScript block check), and it runs like
/// the unsplit program through all 20,000 steps, under steady inputs. (Not under the flickering
/// ones of `check_compiled`: they change at random instants, and the split program's calls of
/// its parts are statements of their own that take time there.)
fn a_20000_step_chart_split_runs_like_the_unsplit_program(lang: crate::Lang) {
    use crate::generator::{Spec, sfc_text};
    let spec = Spec {
        steps: 20_000,
        branch_every: 100,
        branch_width: 3,
        select_every: 50,
        looped: false,
    };
    // Every step a linear move: the flow base's `Move PTP` calls a KRL definition that only the
    // KRL program can hold.
    let sfc = sfc_text(&spec).replace("Move PTP", "Move LIN");
    let compile = |limit: &str| {
        let tmp = tempfile::tempdir().unwrap();
        lang.setup(tmp.path());
        std::fs::write(tmp.path().join("sfc.xml"), &sfc).unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_skillpost"))
            .args(["--lf", "--max-lines", limit, "Blackboard.aml", "R"])
            .current_dir(tmp.path())
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{lang:?} --max-lines {limit}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        tmp
    };
    let whole = compile("0");
    let split = compile("5000");
    let dir = split.path();
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap();
    // The parts' files (KRL, RAPID) or functions (URScript), each checked.
    let stems: Vec<String> = (1..)
        .map(|n| format!("R_{n}"))
        .take_while(|s| match lang {
            crate::Lang::UrScript => read("R.script").contains(&format!("def {s}():")),
            _ => dir.join(format!("{s}.{}", lang.ext())).exists(),
        })
        .collect();
    assert!(stems.len() >= 2, "{lang:?}: not split: {stems:?}");
    let main = read(&format!("R.{}", lang.ext()));
    match lang {
        crate::Lang::Krl => {
            crate::krl_syntax::check_krl(&main, &read("R.dat"), "R", true).unwrap();
            for s in &stems {
                let (src, dat) = (read(&format!("{s}.src")), read(&format!("{s}.dat")));
                assert!(src.lines().count() < 6000, "{s}.src is long");
                crate::krl_syntax::check_krl(&src, &dat, s, true)
                    .unwrap_or_else(|e| panic!("{s}: {e}"));
            }
        }
        crate::Lang::Rapid => {
            // rapidchecker (pyparsing) takes time that grows faster than a module's length: the
            // first and last part (5,000 and 2,800 lines) take about a minute together, the main
            // module (20,000 lines, the 20,000 points' declarations) took over 20 minutes, most
            // of CI's time. So the parts only; the main module and every part with
            // SKILLPOST_RAPIDCHECK_ALL=1. The main module of a split program and its parts pass
            // rapidchecker in the fixture split-rapid (tests/ok_fixtures.rs), every time.
            let mut rapid = crate::RapidChecker::new();
            let last = stems.len() - 1;
            for (k, (name, text)) in std::iter::once(("R".to_owned(), main.clone()))
                .chain(stems.iter().map(|s| (s.clone(), read(&format!("{s}.mod")))))
                .enumerate()
            {
                let output = crate::Output {
                    lang,
                    main: text,
                    dat: String::new(),
                    cell: None,
                };
                if k == 1 || k == last + 1 {
                    rapid.add(&name, &output);
                } else {
                    rapid.add_sampled(&name, &output, 1, 2);
                }
            }
            rapid.check();
        }
        crate::Lang::UrScript => crate::urscript_check::check_urscript(&main).unwrap(),
    }
    // Run like the unsplit program: the same actions, all 20,000 steps.
    let a = lang.read(whole.path(), "R").parse();
    let b = lang.read(dir, "R").parse();
    crate::ACTIONS_CAP.with(|c| c.set(100_000));
    for (k, seq) in crate::sequences(0x5b117, 3).iter().enumerate() {
        let (want, wend) = a.run(seq, false);
        let (got, gend) = b.run(seq, false);
        assert_eq!(wend, gend, "{lang:?}: sequence {k}");
        assert!(
            want == got,
            "{lang:?}: sequence {k}: the split program ran otherwise"
        );
        // A selection runs one of its two steps.
        assert!(
            want.len() > 19_000 && wend == crate::Outcome::Done,
            "{lang:?}: sequence {k}: the run ended after {} actions ({wend:?})",
            want.len()
        );
    }
    crate::ACTIONS_CAP.with(|c| c.set(crate::MAX_ACTIONS));
}

#[test]
fn a_20000_step_chart_split_runs_like_the_unsplit_program_krl() {
    a_20000_step_chart_split_runs_like_the_unsplit_program(crate::Lang::Krl);
}

#[test]
fn a_20000_step_chart_split_runs_like_the_unsplit_program_rapid() {
    a_20000_step_chart_split_runs_like_the_unsplit_program(crate::Lang::Rapid);
}

#[test]
fn a_20000_step_chart_split_runs_like_the_unsplit_program_urscript() {
    a_20000_step_chart_split_runs_like_the_unsplit_program(crate::Lang::UrScript);
}
