//! The command line (docs/COMMAND-LINE.md): parses arguments, runs the compiler, prints diagnostics
//! and listings, writes outputs, and maps the result to an exit status (0 success, 1 the inputs
//! have errors, 2 usage or I/O failure).

use std::ffi::OsString;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

mod check;
mod simulate;

use crate::compile::{self, Compilation, Options};
use crate::diag::{self, Format};
use crate::load::FsSource;

/// skillpost: AutomationML blackboard + PLCopen SFC + IRL snippets -> a robot program: KUKA KRL
/// (.src/.dat), ABB RAPID (.mod) or Universal Robots URScript (.script), by the resource's language
#[derive(Debug, Parser)]
#[command(
    name = "skillpost",
    version,
    disable_version_flag = true,
    override_usage = "skillpost [OPTIONS] <BLACKBOARD> <PROGRAM>\n       skillpost --validate [OPTIONS] <BLACKBOARD> [<PROGRAM>]\n       skillpost --sfc [OPTIONS] <SFC>\n       skillpost --info [<BLACKBOARD>]",
    after_help = "Exit status: 0 success (warnings allowed), 1 the inputs have errors, 2 usage or I/O failure."
)]
#[command(args_conflicts_with_subcommands = true)]
struct Args {
    #[command(subcommand)]
    command: Option<Command>,
    /// The blackboard (.aml); with --sfc, the SFC file instead; optional with --info
    #[arg(value_name = "BLACKBOARD")]
    blackboard: Option<PathBuf>,
    /// The program name, a name in the program's language: writes `<PROGRAM>.src` and .dat (KRL),
    /// `<PROGRAM>.mod` (RAPID) or `<PROGRAM>.script` (URScript) beside the blackboard (not needed
    /// with --validate)
    #[arg(value_name = "PROGRAM")]
    program: Option<PathBuf>,
    /// More arguments than a mode takes: a usage error that names the mode's arguments.
    #[arg(hide = true)]
    extra: Vec<PathBuf>,
    /// Print the version and build; with a blackboard, the skills of each resource and the SFC
    /// variables each needs
    #[arg(long)]
    info: bool,
    /// Show warnings
    #[arg(long)]
    warn: bool,
    /// Read and check everything, write nothing (implies --warn)
    #[arg(long)]
    validate: bool,
    /// Check an SFC file on its own (implies --validate)
    #[arg(long)]
    sfc: bool,
    /// Print: B the blackboard, S the SFC objects, F the flow with times, O (or 0) the execution
    /// order; repeatable (-pB -pS -pF -pO). Printing does not stop the compile: it still writes
    /// the outputs and the write-back; `--validate -pB` (any -p with --validate) only prints
    #[arg(short = 'p', value_name = "B|S|F|O", action = clap::ArgAction::Append,
          value_parser = ["B", "S", "F", "O", "0", "b", "s", "f", "o"])]
    print: Vec<String>,
    /// Draw the plan as an SVG timeline into FILE (one lane per controller, the steps' times,
    /// the handshakes, selections and loops, the cycle time); also with --validate. Not written
    /// when the inputs have errors
    #[arg(long, value_name = "FILE")]
    svg: Option<PathBuf>,
    /// How diagnostics are printed: human (stderr), short (stderr), json (one object per line,
    /// stdout)
    #[arg(long, value_enum, default_value_t = Format::Human)]
    format: Format,
    /// Write LF line endings instead of CRLF
    #[arg(long)]
    lf: bool,
    /// Split a program whose steps take more than N lines into parts the main program calls
    /// (0: never); `LANG=N` for one language (krl, rapid, urscript); repeatable. Default: KRL
    /// 5000, RAPID 5000, URScript 0
    #[arg(long, value_name = "N|LANG=N", action = clap::ArgAction::Append)]
    max_lines: Vec<String>,
    /// Use this output template instead of the built-in one of the program's language (see
    /// templates/krl.toml, rapid.toml, urscript.toml)
    #[arg(long, value_name = "FILE")]
    template: Option<PathBuf>,
    /// The SFC POU to use (default: the SFC reference's #fragment, else the first program with
    /// an SFC body)
    #[arg(long, value_name = "NAME")]
    pou: Option<String>,
    /// Refuse input files larger than MB MiB (default 256)
    #[arg(long, value_name = "MB", value_parser = clap::value_parser!(u64).range(1..=4096))]
    max_file_size: Option<u64>,
    /// Print version
    #[arg(long, action = clap::ArgAction::Version)]
    version: Option<bool>,
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// The daemon: keep project folders compiled, emit JSON events (see DAEMON.md, installed in
    /// /usr/local/share/doc/skillpost)
    Watch(WatchArgs),
    /// Each project's last result, as the running daemons' state files tell it (exit status 0
    /// a daemon runs, 3 only a stopped daemon's state, 1 no state, 2 a state that cannot be read)
    Status(StatusArgs),
    /// Check robot programs as the compiler checks what it writes: block structure and
    /// DEF/MODULE layout (KRL .src/.dat, RAPID .mod/.modx/.sys, URScript .script). Exit status
    /// 0 all pass, 1 a problem, 2 a file that cannot be read or whose language is not known
    Check(CheckArgs),
    /// Run the cell's programs on the built-in interpreter before a robot does: compiles in
    /// memory (writes no program), reports each run's timeline, cycle time and problems
    /// (deadlocks, waits for inputs nothing sets, steps out of the chart's order), and the
    /// steps and branches no run reached (see SIMULATE.md). Exit status 0 no problem, 1 a
    /// problem, 2 inputs with errors
    Simulate(simulate::SimulateArgs),
}

#[derive(Debug, clap::Args)]
struct CheckArgs {
    /// The programs to check
    #[arg(value_name = "FILE", required = true)]
    files: Vec<PathBuf>,
    /// The language, for files whose extension does not say it
    #[arg(long, value_enum)]
    language: Option<CheckLanguage>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum CheckLanguage {
    Krl,
    Rapid,
    Urscript,
}

#[derive(Debug, clap::Args)]
struct StatusArgs {
    /// The daemon's state file (default: every state file in $RUNTIME_DIRECTORY,
    /// /run/skillpost, and $XDG_RUNTIME_DIR/skillpost or `/tmp/skillpost-<uid>`: the daemons
    /// that run, else the one that stopped last)
    #[arg(long, value_name = "FILE")]
    state: Option<PathBuf>,
    /// Only the daemon(s) watching this folder (a project, a folder in one, or a root), and
    /// only its projects
    #[arg(value_name = "FOLDER")]
    folder: Option<PathBuf>,
    /// Output: an aligned table, or the state file's JSON
    #[arg(long, value_enum, default_value_t = StatusFormat::Table)]
    format: StatusFormat,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum StatusFormat {
    Table,
    Json,
}

#[derive(Debug, clap::Args)]
struct WatchArgs {
    /// Configuration file (TOML; every key is described in skillpost.toml, installed in
    /// /usr/local/share/doc/skillpost); SIGHUP reads it again
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Append the event stream to FILE instead of writing it to stdout
    #[arg(long, value_name = "FILE")]
    events: Option<PathBuf>,
    /// Quiet period after the last change before compiling, in milliseconds (default 100)
    #[arg(long, value_name = "MS", value_parser = clap::value_parser!(u64).range(1..=60000))]
    settle: Option<u64>,
    /// Format of the log on stderr: one line per compile and per problem (`human`), or JSON
    /// lines (`json`); the event stream stays on stdout (or in --events FILE)
    #[arg(long, value_enum, default_value_t = LogFormat::Human)]
    log_format: LogFormat,
    /// Keep each project's last result in FILE for `skillpost status` (default:
    /// $RUNTIME_DIRECTORY/status.json, else beside the lock files)
    #[arg(long, value_name = "FILE")]
    state: Option<PathBuf>,
    /// Check the configuration and exit (as `nginx -t`): resolve every project and root, check
    /// that this user could read the inputs, write the outputs and keep the blackboard's owner;
    /// print a table; exit status 0 when all is well, 1 otherwise. Writes nothing
    #[arg(long)]
    check_config: bool,
    /// Project folders (each holding one blackboard), or blackboards (their folder, with that
    /// blackboard); each must exist. Without any, --config is needed (`.` for this folder)
    #[arg(value_name = "DIR|BLACKBOARD")]
    dirs: Vec<PathBuf>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum LogFormat {
    /// One line per event for people: time, level, message (docs/DAEMON.md, "Where output goes")
    #[value(alias = "text")]
    Human,
    /// One JSON object per line, with the fields (`project`, `run_id`, `code`, `duration_ms`)
    Json,
}

/// Runs the command line; returns the exit status.
pub fn main(args: impl IntoIterator<Item = OsString>) -> ExitCode {
    let args = match Args::try_parse_from(args) {
        Ok(a) => a,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { 2 } else { 0 });
        }
    };
    ExitCode::from(run(args))
}

/// A line of `SKILLPOST_TIMINGS=1`: the stage, its time, the process's peak memory by then.
fn timing_line(stage: &str, d: std::time::Duration, peak_kib: Option<u64>) -> String {
    let peak = peak_kib.map_or(String::new(), |k| {
        format!("   peak {:>6.1} MiB", k as f64 / 1024.0)
    });
    format!(
        "timing: {stage:<16} {:>8.1} ms{peak}",
        d.as_secs_f64() * 1000.0
    )
}

fn usage(msg: &str) -> u8 {
    eprintln!(
        "error: {msg}\n\nUsage: skillpost [OPTIONS] <BLACKBOARD> <PROGRAM>\n       skillpost --validate [OPTIONS] <BLACKBOARD> [<PROGRAM>]\n       skillpost --sfc [OPTIONS] <SFC>\n       skillpost --info [<BLACKBOARD>]\n\nFor more information, try '--help'."
    );
    2
}

fn run(a: Args) -> u8 {
    match a.command {
        Some(Command::Watch(w)) => return watch(w),
        Some(Command::Status(s)) => return status_command(s),
        Some(Command::Check(c)) => return check::check_command(&c),
        Some(Command::Simulate(s)) => return simulate::simulate_command(&s),
        None => {}
    }
    let fs = FsSource {
        max_file_size: a
            .max_file_size
            .map_or(crate::load::DEFAULT_MAX_FILE_SIZE, |mb| mb * 1024 * 1024),
    };
    let print = |c: char| {
        a.print
            .iter()
            .any(|p| p.eq_ignore_ascii_case(&c.to_string()) || (c == 'O' && p == "0"))
    };
    let warnings = a.warn || a.validate || a.sfc;
    let mut stdout = std::io::stdout().lock();
    let inputs: Vec<&PathBuf> = a
        .blackboard
        .iter()
        .chain(&a.program)
        .chain(&a.extra)
        .collect();

    if a.info {
        if inputs.len() > 1 {
            return usage("--info takes at most one argument, the blackboard");
        }
        let Some(bb) = inputs.first() else {
            let _ = write!(stdout, "{}", crate::print::info(None));
            return 0;
        };
        // Read only the blackboard: no SFC or IRL files are needed to list skills.
        let mut sources = diag::Sources::default();
        let mut diags = diag::Diagnostics::default();
        let file = crate::read::xml::load(
            &fs,
            bb,
            bb.display().to_string(),
            None,
            &mut sources,
            &mut diags,
        );
        let model =
            file.and_then(|f| crate::read::blackboard::read_blackboard(&sources, f, &mut diags));
        let _ = write!(stdout, "{}", crate::print::info(model.as_ref()));
        diags.snap(&sources);
        let mut list = diags.into_vec();
        if file.is_none() {
            hint_for_a_folder(&mut list, bb, Input::Blackboard);
        }
        report(&list, &sources, a.format, warnings);
        // `--info` reports what it can: only a blackboard it cannot read at all fails it.
        return if file.is_none() && sources.find(bb).is_none() {
            2
        } else if model.is_none() {
            1
        } else {
            0
        };
    }

    if a.sfc {
        let [path] = inputs.as_slice() else {
            return usage("--sfc takes one argument, the SFC file");
        };
        let mut c = compile::check_sfc_pou(&fs, path, a.pou.as_deref());
        if c.io_failure {
            hint_for_a_folder(&mut c.diagnostics, path, Input::Sfc);
        }
        print_listings(&c, &print, a.format, &mut stdout);
        report(&c.diagnostics, &c.sources, a.format, warnings);
        return status(&c, "SFC validation successful!", a.format);
    }

    // `--validate` needs no program name: nothing is written.
    let (blackboard, program) = match inputs.as_slice() {
        [blackboard, program] => (blackboard, Some(program.to_string_lossy().into_owned())),
        [blackboard] if a.validate => (blackboard, None),
        _ if a.validate => {
            return usage("--validate takes a blackboard and, optionally, a program name");
        }
        _ => return usage("expected a blackboard and a program name"),
    };
    let mut max_lines = crate::emit::split::Limits::default();
    for m in &a.max_lines {
        if let Err(why) = max_lines.set(m) {
            return usage(&format!("--max-lines {m}: {why}"));
        }
    }
    let opts = Options {
        program,
        lf: a.lf,
        max_lines,
        template: a.template.clone(),
        confine_to: None,
        pou: a.pou.clone(),
        // The SFC model only for the listings and the picture.
        keep_model: !a.print.is_empty() || a.svg.is_some(),
        // Warnings not shown are not built (100,000 unused variables in one step).
        drop_warnings: !warnings,
        bind_split_from: None,
        picture: a.svg.clone(),
    };
    // The process ends after this run: the (possibly very large) compilation is left to the
    // OS instead of being freed piece by piece (100,000 warnings: ~5 % of the run).
    let mut c = std::mem::ManuallyDrop::new(compile::compile(&fs, blackboard, &opts));
    if c.io_failure {
        hint_for_a_folder(&mut c.diagnostics, blackboard, Input::Blackboard);
    }
    if std::env::var_os("SKILLPOST_TIMINGS").is_some() {
        for (stage, d, peak) in &c.timings {
            eprintln!("{}", timing_line(stage, *d, *peak));
        }
    }
    print_listings(&c, &print, a.format, &mut stdout);
    report(&c.diagnostics, &c.sources, a.format, warnings);
    if !warnings && c.dropped_warnings > 0 && a.format != Format::Json {
        // Counted, not shown: the user learns there is something to look at (JSON: stdout
        // holds the objects, stderr stays for what the run wrote).
        let n = c.dropped_warnings;
        eprintln!(
            "{n} warning{}; --warn shows {}",
            if n == 1 { "" } else { "s" },
            if n == 1 { "it" } else { "them" }
        );
    }
    if c.io_failure {
        summary(&c.diagnostics, a.format, "nothing was written");
        return 2;
    }
    if c.has_errors() {
        if let Some(svg) = &a.svg {
            eprintln!("note: {} not drawn: the inputs have errors", svg.display());
        }
        return status(&c, "", a.format);
    }
    // The picture: drawn now, written after the programs (a failed write of the programs leaves
    // it unwritten too: "nothing was written" holds), through the folder they went to.
    let picture = match &a.svg {
        Some(svg) => match compile::picture(&c, &blackboard.display().to_string()) {
            Some(p) => Some((svg, p)),
            None => {
                eprintln!("note: {} not drawn: the chart has no plan", svg.display());
                return status(&c, "", a.format);
            }
        },
        None => None,
    };
    let draw = |written: &str| -> Option<u8> {
        let (svg, picture) = picture.as_ref()?;
        match compile::write_beside(&c, svg, picture.as_bytes()) {
            Ok(o) => {
                say(
                    a.format == Format::Json,
                    &format!(
                        "{} {}",
                        if o == crate::write::WriteOutcome::Written {
                            "wrote"
                        } else {
                            "unchanged"
                        },
                        svg.display()
                    ),
                );
                None
            }
            Err(e) => {
                let list = [diag::Diagnostic::error(
                    diag::Code::CannotWrite,
                    format!("cannot write {}: {e}", svg.display()),
                )];
                report(&list, &c.sources, a.format, warnings);
                summary(&list, a.format, written);
                Some(2)
            }
        }
    };
    if a.validate {
        if let Some(code) = draw("the picture was not written") {
            return code;
        }
        return status(&c, "Input validation successful!", a.format);
    }
    let written_in = std::time::Instant::now();
    let result = compile::apply(&c);
    if std::env::var_os("SKILLPOST_TIMINGS").is_some() {
        let line = timing_line("write", written_in.elapsed(), compile::peak_kib());
        eprintln!("{line}");
    }
    match result {
        Ok(applied) => {
            let json = a.format == Format::Json;
            for (path, written) in &applied.outputs {
                say(
                    json,
                    &format!(
                        "{} {}",
                        if *written { "wrote" } else { "unchanged" },
                        path.display()
                    ),
                );
            }
            for path in &applied.removed {
                say(
                    json,
                    &format!(
                        "removed {} (a part of the program an earlier compile wrote)",
                        path.display()
                    ),
                );
            }
            use crate::write::WriteBackOutcome as W;
            // Whenever the blackboard does not get the value, say so on stdout (a JSON object
            // with --format json): (cause, reason).
            let not_updated = match &applied.write_back {
                Some(W::Written) => {
                    if let Some(wb) = &c.write_back {
                        let values: Vec<String> =
                            wb.splices().iter().map(|(_, v)| format!("`{v}`")).collect();
                        say(
                            json,
                            &format!(
                                "wrote back {} into {}",
                                values.join(", "),
                                wb.blackboard.display()
                            ),
                        );
                    }
                    None
                }
                Some(W::AlreadyRight) => None,
                Some(W::SkippedChangedOnDisk) => Some((
                    "changed-on-disk",
                    "it changed on disk while compiling; run again",
                )),
                Some(W::SkippedInUse) => Some((
                    "in-use",
                    "another program has it open; run again when it is closed",
                )),
                Some(W::SkippedHardLinked) => Some((
                    "hard-linked",
                    "it has several names (hard links); writing it would split them",
                )),
                Some(W::SkippedReadOnly) => Some((
                    "read-only",
                    "it is read-only (no write permission); make it writable to get the value",
                )),
                Some(W::SkippedOwner) => Some((
                    "owner",
                    "its owner could not be kept (replacing it would make it this user's file); run as its owner, or with CAP_CHOWN",
                )),
                None => Some((
                    "no-target",
                    "no write-back target (Code -> KRL code -> refURI; W204 with --warn shows where)",
                )),
            };
            if let Some((cause, reason)) = not_updated {
                let value = c.write_back.as_ref().map(|wb| wb.value.as_str());
                let _ = if json {
                    let mut line = serde_json::json!({
                        "outcome": "blackboard-not-updated",
                        "blackboard": blackboard.display().to_string(),
                        "cause": cause,
                        "reason": reason,
                    });
                    if let Some(v) = value {
                        line["value"] = v.into();
                    }
                    writeln!(stdout, "{line}")
                } else {
                    let value = value
                        .map(|v| format!(" (`{v}` not written)"))
                        .unwrap_or_default();
                    writeln!(
                        stdout,
                        "blackboard not updated: {}: {reason}{value}",
                        blackboard.display()
                    )
                };
            }
            draw("the programs were written, the picture was not").unwrap_or(0)
        }
        Err(e) => {
            // As the daemon reports it (`compile-failed` with E604), and with `--format json`
            // a diagnostic object on stdout like every other.
            let d = diag::Diagnostic::error(diag::Code::CannotWrite, format!("cannot write: {e}"));
            let list = [d];
            report(&list, &c.sources, a.format, warnings);
            // The `.src` and `.dat` are replaced together or not at all, before the write-back:
            // a failure with every output on disk as compiled is the write-back's.
            let outputs_written = !c.outputs.is_empty()
                && c.outputs
                    .iter()
                    .all(|(p, f)| std::fs::read(p).is_ok_and(|bytes| bytes == f.text.as_bytes()));
            summary(
                &list,
                a.format,
                if outputs_written {
                    "the outputs were written, the blackboard was not updated"
                } else {
                    "nothing was written"
                },
            );
            2
        }
    }
}

/// Which input a path on the command line is.
#[derive(Clone, Copy)]
enum Input {
    Blackboard,
    Sfc,
}

/// A folder given where a file is expected (`skillpost DIR prog`): the `E101` that says so gets
/// a note naming the file to give instead (the folder's only `.aml`, or `.xml` for `--sfc`), or
/// saying to name one, and for a blackboard's folder that `skillpost watch DIR` keeps a folder
/// compiled.
fn hint_for_a_folder(list: &mut [diag::Diagnostic], path: &std::path::Path, input: Input) {
    if !path.is_dir() {
        return;
    }
    let Some(d) = list.iter_mut().find(|d| {
        d.code == diag::Code::FileUnreadable && d.span.is_none() && d.path.as_deref() == Some(path)
    }) else {
        return;
    };
    let (ext, what) = match input {
        Input::Blackboard => ("aml", "the blackboard"),
        Input::Sfc => ("xml", "the SFC file"),
    };
    let mut found: Vec<PathBuf> = std::fs::read_dir(path)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| {
                    p.is_file()
                        && p.extension()
                            .is_some_and(|x| x.to_string_lossy().eq_ignore_ascii_case(ext))
                })
                .collect()
        })
        .unwrap_or_default();
    found.sort();
    let dir = path.display();
    // As the user would type it: `Blackboard.aml` for `.`, not `./Blackboard.aml`.
    let shown = |p: &PathBuf| {
        let p = if path == std::path::Path::new(".") {
            p.strip_prefix(".").unwrap_or(p)
        } else {
            p
        };
        format!("`{}`", p.display())
    };
    const LISTED: usize = 5;
    d.notes.push(match found.as_slice() {
        [one] => format!("a folder, not {what}: did you mean {}?", shown(one)),
        [] => format!("a folder, not {what}: it holds no `.{ext}` file; name {what} (`.{ext}`)"),
        several => {
            let mut names: Vec<String> = several.iter().take(LISTED).map(shown).collect();
            if several.len() > LISTED {
                names.push(format!("and {} more", several.len() - LISTED));
            }
            format!(
                "a folder, not {what}: name {what} (`.{ext}`); it holds {}",
                names.join(", ")
            )
        }
    });
    if let Input::Blackboard = input {
        d.notes.push(format!(
            "to keep a folder compiled whenever its files change: `skillpost watch {dir}`"
        ));
    }
}

/// The last line of a failing run in the text formats, after its diagnostics: how many errors,
/// and what was written (`--format json` prints none: count the objects).
fn summary(list: &[diag::Diagnostic], format: Format, written: &str) {
    if format == Format::Json {
        return;
    }
    let errors = list
        .iter()
        .filter(|d| d.severity == diag::Severity::Error)
        .count();
    if errors > 0 {
        eprintln!(
            "error: {errors} error{} found; {written}",
            if errors == 1 { "" } else { "s" }
        );
    }
}

/// A line of the run's outcome (what was written): on stdout, except with `--format json`,
/// whose stdout holds JSON objects only; there it goes to stderr.
fn say(json: bool, line: &str) {
    use std::io::Write as _;
    // A reader that went away (`skillpost … | head`) is no reason to panic: the line is lost,
    // the run goes on and its exit status says what happened.
    let _ = if json {
        writeln!(std::io::stderr(), "{line}")
    } else {
        writeln!(std::io::stdout(), "{line}")
    };
}

/// The `-p` listings on stdout: as text, or with `--format json` one JSON object per listing
/// (docs/JSON.md), so stdout stays JSON Lines.
fn print_listings(
    c: &Compilation,
    print: &dyn Fn(char) -> bool,
    format: Format,
    out: &mut impl Write,
) {
    use crate::print::json;
    let json = format == Format::Json;
    let mut emit = |text: &dyn Fn() -> String, object: &dyn Fn() -> serde_json::Value| {
        let _ = if json {
            writeln!(out, "{}", object())
        } else {
            writeln!(out, "{}", text())
        };
    };
    if print('B')
        && let Some(bb) = &c.blackboard
    {
        // The wires a cell's handshakes use, and what for (docs/CELLS.md).
        let uses = c
            .cell
            .as_ref()
            .map(|cell| crate::print::wire_uses(cell, bb));
        emit(
            &|| crate::print::blackboard(bb, &c.languages, uses.as_ref()),
            &|| json::blackboard(bb, &c.languages, uses.as_ref()),
        );
    }
    if print('S')
        && let Some(sfc) = &c.sfc
    {
        emit(&|| crate::print::sfc(sfc), &|| json::sfc(sfc));
    }
    if let (Some(sfc), Some(plan)) = (&c.sfc, &c.plan) {
        // A cell of several controllers: one lane and one order per program (docs/CELLS.md).
        let cell = match (&c.cell, &c.blackboard) {
            (Some(cell), Some(bb)) => Some(crate::print::CellView {
                cell,
                bb,
                names: &c.program_names,
            }),
            _ => None,
        };
        if print('F') {
            match &cell {
                Some(v) => emit(&|| crate::print::cell_flow(sfc, plan, v), &|| {
                    json::cell_flow(sfc, plan, v)
                }),
                None => emit(&|| crate::print::flow(sfc, plan), &|| json::flow(sfc, plan)),
            }
        }
        if print('O') {
            // Which part of a split program holds which steps.
            let parts = crate::print::parts::of(c);
            let with = |mut o: serde_json::Value| {
                crate::print::parts::add_json(&mut o, &parts);
                o
            };
            let text = |t: String| t + &crate::print::parts::text(&parts);
            match &cell {
                Some(v) => emit(&|| text(crate::print::cell_order(sfc, v)), &|| {
                    with(json::cell_order(sfc, v))
                }),
                None => emit(&|| text(crate::print::order(sfc, plan)), &|| {
                    with(json::order(sfc, plan))
                }),
            }
        }
    } else {
        for (p, what, listing) in [('F', "-pF", "flow"), ('O', "-pO", "order")] {
            if print(p) {
                let why = if c.sfc.is_some() {
                    "the SFC's flow has errors"
                } else {
                    "the SFC could not be read"
                };
                emit(
                    &|| format!("{what}: nothing to print: {why} (see the diagnostics)"),
                    &|| json::unavailable(listing, why),
                );
            }
        }
    }
}

fn report(list: &[diag::Diagnostic], sources: &diag::Sources, format: Format, warnings: bool) {
    let color = format == Format::Human && std::io::stderr().is_terminal();
    let text = diag::render(list, sources, format, warnings, color);
    if text.is_empty() {
        return;
    }
    if format == Format::Json {
        let _ = std::io::stdout().lock().write_all(text.as_bytes());
    } else {
        let _ = std::io::stderr().lock().write_all(text.as_bytes());
    }
}

fn status(c: &Compilation, ok_message: &str, format: Format) -> u8 {
    if c.io_failure {
        summary(&c.diagnostics, format, "nothing was written");
        return 2;
    }
    if c.has_errors() {
        summary(&c.diagnostics, format, "nothing was written");
        1
    } else {
        if !ok_message.is_empty() {
            say(format == Format::Json, ok_message);
        }
        0
    }
}

/// `skillpost watch`: logs to stderr, events to stdout or a file, signals to the daemon.
fn watch(w: WatchArgs) -> u8 {
    use crate::daemon::{self, Control, events::EventSink};
    if let Some(usage) = daemon::config::nothing_to_watch(w.config.as_deref(), &w.dirs) {
        eprintln!("{usage}");
        return 2;
    }
    if w.check_config {
        let (events, state) = (w.events.clone(), w.state.as_deref());
        return daemon::check::main(w.config.as_deref(), &w.dirs, events, w.settle, state);
    }
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal());
    match w.log_format {
        LogFormat::Human => builder
            .event_format(daemon::journal::Human::for_stderr())
            .init(),
        LogFormat::Json => builder.json().init(),
    }
    let (dirs, blackboards) = match daemon::config::command_line_targets(&w.dirs) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return 2;
        }
    };
    let sources = daemon::Sources {
        config_file: w.config.clone(),
        dirs,
        blackboards,
        events: w.events.clone(),
        settle_ms: w.settle,
        runtime_dir: None,
        own_process: true,
    };
    let config = match sources.load() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return 2;
        }
    };
    if config.projects.is_empty() && config.roots.is_empty() {
        tracing::warn!("no projects and no roots configured; waiting for a reload (SIGHUP)");
    }
    // The daemon's own files, refused in a planner's folder before either is created.
    let state_file = w.state.clone().unwrap_or_else(daemon::state::default_path);
    let own: Vec<_> = config
        .events
        .iter()
        .cloned()
        .chain([state_file.clone()])
        .collect();
    if let Some(why) = daemon::config::own_files_problem(&config, &own) {
        eprintln!("error: {why}");
        return 2;
    }
    let sink = match &config.events {
        Some(path) => match EventSink::append(path) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("error: cannot open the event file {}: {e}", path.display());
                return 2;
            }
        },
        None => EventSink::stdout(),
    };
    let sink = sink.with_state_file(state_file);
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: cannot start the runtime: {e}");
            return 2;
        }
    };
    let sink = std::sync::Arc::new(sink);
    let daemon_sink = sink.clone();
    let result = runtime.block_on(async move {
        let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
        use tokio::signal::unix::{SignalKind, signal};
        let (mut hup, mut term, mut int) = match (
            signal(SignalKind::hangup()),
            signal(SignalKind::terminate()),
            signal(SignalKind::interrupt()),
        ) {
            (Ok(h), Ok(t), Ok(i)) => (h, t, i),
            _ => return Err("cannot install signal handlers".to_owned()),
        };
        // Every signal is passed on: a second SIGTERM/SIGINT ends the wait for running compiles.
        tokio::spawn(async move {
            loop {
                let msg = tokio::select! {
                    _ = hup.recv() => Control::Reload,
                    _ = term.recv() => Control::Stop("SIGTERM".into()),
                    _ = int.recv() => Control::Stop("SIGINT".into()),
                };
                if tx.send(msg).is_err() {
                    break;
                }
            }
        });
        daemon::run(config, sources, daemon_sink, rx).await
    });
    // Compiles still running (a stop that timed out) are not waited for: the process ends.
    runtime.shutdown_background();
    // `run` flushed the events already (bounded): this only counts what is still waiting.
    let waiting = sink.flush(std::time::Duration::ZERO);
    match result {
        Ok(()) if waiting == 0 => 0,
        Ok(()) => {
            eprintln!("error: {waiting} event(s) not written: the event stream is stalled");
            2
        }
        Err(e) => {
            eprintln!("error: {e}");
            2
        }
    }
}

/// `skillpost status`: prints the state of the daemons that run (of those watching FOLDER, if
/// given), else of the one that stopped last. 0 a daemon runs, 3 only a stopped daemon's state
/// (as `systemctl status`), 1 no daemon state found, 2 a state file that cannot be read.
fn status_command(s: StatusArgs) -> u8 {
    use crate::daemon::state;
    let (found, problems) = match &s.state {
        Some(path) => {
            if !path.exists() {
                eprintln!(
                    "no daemon state: {} does not exist. Is `skillpost watch --state {}` running?",
                    path.display(),
                    path.display()
                );
                return 1;
            }
            match state::read(path) {
                Ok(snap) => (vec![(path.clone(), snap)], Vec::new()),
                Err(e) => {
                    eprintln!("error: {e}");
                    return 2;
                }
            }
        }
        None => state::discover(),
    };
    if found.is_empty() {
        if !problems.is_empty() {
            for p in &problems {
                eprintln!("error: {p}");
            }
            return 2;
        }
        let list: Vec<String> = state::candidate_dirs()
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        eprintln!(
            "no daemon state: no state file in {}. Is `skillpost watch` running? Under \
             systemd: `systemctl status skillpost`; a daemon started with --state FILE: \
             `skillpost status --state FILE`.",
            list.join(", ")
        );
        return 1;
    }
    for p in &problems {
        eprintln!("warning: {p}");
    }
    let found: Vec<state::Snapshot> = match &s.folder {
        Some(folder) => {
            let of: Vec<_> = found
                .iter()
                .filter_map(|(_, snap)| state::watching(snap, folder))
                .collect();
            if of.is_empty() {
                eprintln!(
                    "no daemon state for {}: no daemon watches it (the daemons' states: \
                     `skillpost status`)",
                    folder.display()
                );
                return 1;
            }
            of
        }
        None => found.into_iter().map(|(_, snap)| snap).collect(),
    };
    let (running, mut stopped): (Vec<_>, Vec<_>) = found.into_iter().partition(state::running);
    let (shown, code) = if running.is_empty() {
        // No daemon runs: the last one that stopped (RFC 3339 times sort as text).
        stopped.sort_by(|a, b| a.updated.cmp(&b.updated));
        (stopped.pop().into_iter().collect::<Vec<_>>(), 3)
    } else {
        (running, 0)
    };
    let mut text = String::new();
    for (i, snap) in shown.iter().enumerate() {
        match s.format {
            StatusFormat::Table => {
                if i > 0 {
                    text.push('\n');
                }
                text.push_str(&state::table(snap));
            }
            // One object per daemon (several in a row when several run: `jq -s` makes a list).
            StatusFormat::Json => match serde_json::to_string_pretty(snap) {
                Ok(t) => {
                    text.push_str(&t);
                    text.push('\n');
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    return 2;
                }
            },
        }
    }
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
    code
}
