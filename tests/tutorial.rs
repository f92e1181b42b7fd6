//! docs/TUTORIAL.md against the files and the binary it describes.
//!
//! The tutorial marks what this test checks with the info string of its fenced blocks:
//!
//! - ```` ```xml step2/Blackboard.aml ````: a file shown whole; it must be
//!   `examples/tutorial/step2/Blackboard.aml`, byte for byte. Every file of every step folder is
//!   shown, unless it is the same as the file of that name in the step before (a step folder is
//!   complete: `cp -r examples/tutorial/step3 cell` gives the cell of step 3).
//! - ```` ```console step2 ````: commands run in a copy of `examples/tutorial/step2` (one copy
//!   per step, shared by the step's blocks in their order), each line `$ COMMAND` followed by
//!   what it prints, stdout and stderr as a terminal shows them. The commands: `skillpost ARGS`
//!   (the binary built with this test), `cat FILE...`, `ls`, `grep TEXT FILE` (the lines holding
//!   TEXT) and `echo $?` (the last exit status). Arguments are split at spaces. Output is
//!   compared line by line without trailing spaces and carriage returns (the programs have CRLF
//!   line endings).
//!
//! When the outputs or the files differ, the test fails with a diff. With
//! `SKILLPOST_UPDATE_TUTORIAL=1` it writes the outputs of the commands and the files of
//! `examples/tutorial` into docs/TUTORIAL.md instead (read the diff before committing it).

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

const UPDATE: &str = "SKILLPOST_UPDATE_TUTORIAL";

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A fenced block of the tutorial: its info string's words and the line range of its content.
#[derive(Debug)]
struct Block {
    info: Vec<String>,
    /// Index of the first content line and one past the last (the closing fence).
    lines: std::ops::Range<usize>,
}

fn blocks(lines: &[&str]) -> Vec<Block> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let Some(info) = lines[i].strip_prefix("```") else {
            i += 1;
            continue;
        };
        let start = i + 1;
        let mut end = start;
        while end < lines.len() && lines[end].trim_end() != "```" {
            end += 1;
        }
        out.push(Block {
            info: info.split_whitespace().map(str::to_owned).collect(),
            lines: start..end,
        });
        i = end + 1;
    }
    out
}

/// The step a `console` block runs in, or the file a block shows.
enum Kind {
    Console(String),
    File(String),
    Other,
}

fn kind(b: &Block) -> Kind {
    match b.info.as_slice() {
        [lang, step] if lang == "console" && is_step(step) => Kind::Console(step.clone()),
        [_, path] if path.split('/').next().is_some_and(is_step) && path.contains('/') => {
            Kind::File(path.clone())
        }
        _ => Kind::Other,
    }
}

fn is_step(s: &str) -> bool {
    s.strip_prefix("step")
        .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
}

/// Lines without trailing spaces or carriage returns, and without empty lines at the end.
fn normalized(text: &str) -> Vec<String> {
    let mut v: Vec<String> = text
        .split('\n')
        .map(|l| l.trim_end_matches([' ', '\t', '\r']).to_owned())
        .collect();
    while v.last().is_some_and(|l| l.is_empty()) {
        v.pop();
    }
    v
}

/// A line diff of `want` and `got` (longest common subsequence): `-` only in the tutorial, `+`
/// only in what the run printed (or the file holds).
fn diff(want: &[String], got: &[String]) -> String {
    let (n, m) = (want.len(), got.len());
    let mut lcs = vec![vec![0usize; m + 1]; n + 1];
    for i in (0..n).rev() {
        for j in (0..m).rev() {
            lcs[i][j] = if want[i] == got[j] {
                lcs[i + 1][j + 1] + 1
            } else {
                lcs[i + 1][j].max(lcs[i][j + 1])
            };
        }
    }
    let (mut i, mut j, mut out) = (0, 0, String::new());
    while i < n || j < m {
        if i < n && j < m && want[i] == got[j] {
            let _ = writeln!(out, "  {}", want[i]);
            i += 1;
            j += 1;
        } else if i < n && (j == m || lcs[i + 1][j] >= lcs[i][j + 1]) {
            let _ = writeln!(out, "- {}", want[i]);
            i += 1;
        } else {
            let _ = writeln!(out, "+ {}", got[j]);
            j += 1;
        }
    }
    out
}

fn copy_dir(from: &Path, to: &Path) {
    fs::create_dir_all(to).unwrap();
    for e in fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &target);
        } else {
            fs::copy(e.path(), &target).unwrap();
        }
    }
}

/// The folders the console blocks run in: a copy of each step, made at its first block.
struct Shell {
    root: PathBuf,
    last_status: i32,
}

impl Shell {
    fn new() -> Self {
        let root = std::env::temp_dir().join(format!("skillpost-tutorial-{}", std::process::id()));
        let _ = fs::remove_dir_all(&root);
        fs::create_dir_all(&root).unwrap();
        Shell {
            root,
            last_status: 0,
        }
    }

    fn folder(&self, step: &str) -> PathBuf {
        let dir = self.root.join(step);
        if !dir.exists() {
            let from = repo().join("examples/tutorial").join(step);
            assert!(
                from.is_dir(),
                "docs/TUTORIAL.md runs `{step}`, but there is no {}",
                from.display()
            );
            copy_dir(&from, &dir);
        }
        dir
    }

    /// Runs one command line in `dir`; its output as a terminal shows it.
    fn run(&mut self, dir: &Path, line: &str) -> String {
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some((&cmd, args)) = words.split_first() else {
            return String::new();
        };
        match cmd {
            "skillpost" => {
                let capture = self.root.join("output");
                let file = fs::File::create(&capture).unwrap();
                let status = Command::new(env!("CARGO_BIN_EXE_skillpost"))
                    .args(args)
                    .current_dir(dir)
                    .env_remove("SKILLPOST_TIMINGS")
                    .stdin(Stdio::null())
                    // One file for both, as a terminal shows them: in the order they were written.
                    .stdout(Stdio::from(file.try_clone().unwrap()))
                    .stderr(Stdio::from(file))
                    .status()
                    .unwrap();
                self.last_status = status.code().unwrap_or(-1);
                let text = String::from_utf8_lossy(&fs::read(&capture).unwrap()).into_owned();
                text.replace(&dir.display().to_string(), "~/cell")
            }
            "cat" => {
                self.last_status = 0;
                let mut text = String::new();
                for f in args {
                    text.push_str(&String::from_utf8_lossy(
                        &fs::read(dir.join(f))
                            .unwrap_or_else(|e| panic!("docs/TUTORIAL.md: `cat {f}`: {e}")),
                    ));
                }
                text
            }
            "ls" => {
                self.last_status = 0;
                let mut names: Vec<String> = fs::read_dir(dir)
                    .unwrap()
                    .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                    .collect();
                names.sort();
                names.join("\n")
            }
            "grep" => {
                let [text, file] = args else {
                    panic!("docs/TUTORIAL.md: `{line}`: grep takes TEXT FILE");
                };
                let content = fs::read_to_string(dir.join(file)).unwrap();
                let found: Vec<&str> = content.lines().filter(|l| l.contains(text)).collect();
                self.last_status = if found.is_empty() { 1 } else { 0 };
                found.join("\n")
            }
            "echo" if args == ["$?"] => self.last_status.to_string(),
            _ => panic!(
                "docs/TUTORIAL.md: `{line}`: this test runs skillpost, cat, ls, grep and echo $? only"
            ),
        }
    }
}

/// The files of every step folder, each either shown in the tutorial or the same as in the
/// step before: `(step/file, shown or not)`.
fn files_to_show() -> Vec<(String, Option<String>)> {
    let base = repo().join("examples/tutorial");
    let mut steps: Vec<(u32, String)> = fs::read_dir(&base)
        .unwrap()
        .filter_map(|e| {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            let n = name.strip_prefix("step")?.parse().ok()?;
            Some((n, name))
        })
        .collect();
    steps.sort();
    let mut out = Vec::new();
    let mut before: Option<&String> = None;
    for (_, step) in &steps {
        let mut names: Vec<String> = fs::read_dir(base.join(step))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        for name in names {
            let same_as = before.filter(|b| {
                fs::read(base.join(b).join(&name)).ok()
                    == fs::read(base.join(step).join(&name)).ok()
            });
            out.push((
                format!("{step}/{name}"),
                same_as.map(|b| format!("{b}/{name}")),
            ));
        }
        before = Some(step);
    }
    out
}

#[test]
fn the_tutorial_shows_what_its_files_and_commands_give() {
    let path = repo().join("docs/TUTORIAL.md");
    let text = fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let update = std::env::var_os(UPDATE).is_some();
    let mut shell = Shell::new();
    let mut problems = String::new();
    // New contents of blocks (update mode): line range → lines.
    let mut replace: Vec<(std::ops::Range<usize>, Vec<String>)> = Vec::new();
    let mut shown: Vec<String> = Vec::new();
    let mut consoles = 0;
    for b in blocks(&lines) {
        let content: Vec<&str> = lines[b.lines.clone()].to_vec();
        match kind(&b) {
            Kind::File(file) => {
                shown.push(file.clone());
                let on_disk = repo().join("examples/tutorial").join(&file);
                let Ok(disk) = fs::read_to_string(&on_disk) else {
                    let _ = writeln!(
                        problems,
                        "docs/TUTORIAL.md:{} shows `{file}`, which examples/tutorial does not have",
                        b.lines.start
                    );
                    continue;
                };
                let want = normalized(&content.join("\n"));
                let got = normalized(&disk);
                if want != got || disk.contains('\r') {
                    if update {
                        replace.push((b.lines.clone(), got));
                    } else {
                        let _ = writeln!(
                            problems,
                            "docs/TUTORIAL.md:{} shows `{file}` otherwise than examples/tutorial/{file} (- the tutorial, + the file):\n{}",
                            b.lines.start + 1,
                            diff(&want, &got)
                        );
                    }
                }
            }
            Kind::Console(step) => {
                consoles += 1;
                let dir = shell.folder(&step);
                let mut want: Vec<String> = Vec::new();
                let mut got: Vec<String> = Vec::new();
                for line in &content {
                    match line.strip_prefix("$ ") {
                        Some(cmd) => {
                            got.push(line.trim_end().to_owned());
                            got.extend(normalized(&shell.run(&dir, cmd)));
                        }
                        None if got.is_empty() => {
                            let _ = writeln!(
                                problems,
                                "docs/TUTORIAL.md:{}: a console block begins with `$ COMMAND`",
                                b.lines.start + 1
                            );
                            break;
                        }
                        None => {}
                    }
                    want.push(line.trim_end().to_owned());
                }
                let want = normalized(&want.join("\n"));
                if want != got {
                    if update {
                        replace.push((b.lines.clone(), got));
                    } else {
                        let _ = writeln!(
                            problems,
                            "docs/TUTORIAL.md:{} ({step}): the commands print otherwise (- the tutorial, + the run):\n{}",
                            b.lines.start + 1,
                            diff(&want, &got)
                        );
                    }
                }
            }
            Kind::Other => {}
        }
    }
    assert!(
        consoles >= 5,
        "docs/TUTORIAL.md runs its steps ({consoles} console blocks)"
    );
    // A file not shown must be the same as one of the step before that is shown (or is the
    // same as one shown before it).
    let mut covered: Vec<String> = Vec::new();
    for (file, same_as) in files_to_show() {
        if shown.contains(&file) || same_as.as_ref().is_some_and(|b| covered.contains(b)) {
            covered.push(file);
            continue;
        }
        let _ = writeln!(
            problems,
            "examples/tutorial/{file} is not shown in docs/TUTORIAL.md (a block ```LANG {file}), and it is not the same as the file of the step before"
        );
    }
    let _ = fs::remove_dir_all(&shell.root);
    if update && !replace.is_empty() {
        let mut out: Vec<String> = Vec::new();
        let mut at = 0;
        for (range, new) in &replace {
            out.extend(lines[at..range.start].iter().map(|l| l.to_string()));
            out.extend(new.iter().cloned());
            at = range.end;
        }
        out.extend(lines[at..].iter().map(|l| l.to_string()));
        fs::write(&path, out.join("\n") + "\n").unwrap();
        println!("docs/TUTORIAL.md: {} blocks rewritten", replace.len());
    }
    assert!(
        problems.is_empty(),
        "{problems}\ndocs/TUTORIAL.md and what it shows disagree. If the outputs or the files changed on purpose, \
         `{UPDATE}=1 cargo test --test tutorial` writes them into the tutorial (then read its diff); \
         otherwise fix the files or the program."
    );
}
