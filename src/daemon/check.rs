//! `skillpost watch --check-config` (as `nginx -t`): reads the configuration, resolves every
//! project and root, and checks that this process could do what the daemon does there — read
//! the inputs, create the outputs in the project folder, keep the blackboard's owner at the
//! write-back, append to the events file — then prints a table and exits 0 when all is well, 1
//! otherwise. It writes nothing anywhere: no event, no state file, no lock, no output.
//!
//! Permissions are checked with `faccessat(2)` (`AT_EACCESS`: the effective ids, as an `open`
//! uses them); the blackboard's owner can be kept when the process is root or has `CAP_CHOWN`,
//! or the blackboard is its own (and in one of its groups). Run it as the service would run:
//! the same user, groups and capabilities (docs/DAEMON-INSTALL.md, step 4).

use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

use rustix::fs::{Access, AtFlags, CWD, accessat};

use super::Sources;
use super::config::{self, Config, ProjectSpec};
use crate::compile::{self, Options};
use crate::load::{DEFAULT_MAX_FILE_SIZE, FsSource};

/// One line of the table.
struct Row {
    /// The program (`Zelle_A`), `(root)`, `(events)` or `-`.
    what: String,
    folder: String,
    verdict: Verdict,
}

enum Verdict {
    Ok(String),
    Problem(String),
}

/// Runs the check; returns the exit status (0 all well, 1 otherwise).
pub fn main(
    config_file: Option<&Path>,
    dirs: &[PathBuf],
    events: Option<PathBuf>,
    settle_ms: Option<u64>,
    state: Option<&Path>,
) -> u8 {
    let (dirs, blackboards) = match config::command_line_targets(dirs) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            println!("configuration check failed: 1 problem");
            return 1;
        }
    };
    let sources = Sources {
        config_file: config_file.map(Path::to_owned),
        dirs,
        blackboards,
        events,
        settle_ms,
        runtime_dir: None,
        own_process: false,
    };
    let config = match sources.read() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            println!("configuration check failed: 1 problem");
            return 1;
        }
    };
    let me = Process::current();
    println!(
        "skillpost watch --check-config: {} (checked as {})",
        config
            .file
            .as_ref()
            .map_or("the command line".into(), |f| f.display().to_string()),
        me.describe()
    );
    let mut rows = Vec::new();
    let state = state
        .map(Path::to_owned)
        .unwrap_or_else(super::state::default_path);
    let own: Vec<PathBuf> = config.events.iter().cloned().chain([state]).collect();
    if let Some(why) = config::own_files_problem(&config, &own) {
        rows.push(Row {
            what: "-".into(),
            folder: "-".into(),
            verdict: Verdict::Problem(why),
        });
    }
    rows.push(events_row(config.events.as_deref()));
    // Each deploy hook's program, once.
    rows.extend(
        config::hook_programs(&config)
            .into_iter()
            .map(|p| hook_row(p, config::hook_program_problem(&config, p))),
    );
    for root in &config.roots {
        rows.push(root_row(&root.path));
        for dir in config::discover(&root.path) {
            rows.push(project_row(&root.project(dir), &config, &me));
        }
    }
    for p in &config.projects {
        rows.push(project_row(p, &config, &me));
    }
    print!("{}", table(&rows));
    let problems = rows
        .iter()
        .filter(|r| matches!(r.verdict, Verdict::Problem(_)))
        .count();
    if problems == 0 {
        println!("configuration OK");
        0
    } else {
        println!(
            "configuration check failed: {problems} problem{}",
            if problems == 1 { "" } else { "s" }
        );
        1
    }
}

/// The aligned table: PROJECT, FOLDER, RESULT.
fn table(rows: &[Row]) -> String {
    let w0 = rows.iter().map(|r| r.what.len()).max().unwrap_or(0).max(7);
    let w1 = rows
        .iter()
        .map(|r| r.folder.len())
        .max()
        .unwrap_or(0)
        .max(6);
    let mut out = format!("\n{:w0$}  {:w1$}  RESULT\n", "PROJECT", "FOLDER");
    for r in rows {
        let result = match &r.verdict {
            Verdict::Ok(s) => format!("ok: {s}"),
            Verdict::Problem(s) => format!("PROBLEM: {s}"),
        };
        out.push_str(&format!("{:w0$}  {:w1$}  {result}\n", r.what, r.folder));
    }
    out.push('\n');
    out
}

/// Who runs the check: what decides the daemon's permissions.
struct Process {
    uid: u32,
    gid: u32,
    groups: Vec<u32>,
    cap_chown: bool,
}

impl Process {
    fn current() -> Self {
        let gid = rustix::process::getegid().as_raw();
        Process {
            uid: rustix::process::geteuid().as_raw(),
            gid,
            groups: rustix::process::getgroups()
                .map(|g| g.into_iter().map(|g| g.as_raw()).collect())
                .unwrap_or_default(),
            cap_chown: effective_capability(0),
        }
    }

    fn may_chown(&self) -> bool {
        self.uid == 0 || self.cap_chown
    }

    fn in_group(&self, gid: u32) -> bool {
        self.gid == gid || self.groups.contains(&gid)
    }

    fn describe(&self) -> String {
        format!(
            "{} (uid {}), CAP_CHOWN {}",
            user_name(self.uid).unwrap_or_else(|| "?".into()),
            self.uid,
            if self.may_chown() { "yes" } else { "no" }
        )
    }
}

/// Whether the capability number `cap` is in this process's effective set (`/proc/self/status`).
fn effective_capability(cap: u32) -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("CapEff:"))
                .and_then(|v| u64::from_str_radix(v.trim(), 16).ok())
        })
        .is_some_and(|bits| bits & (1 << cap) != 0)
}

/// The user name of `uid` from `/etc/passwd`.
fn user_name(uid: u32) -> Option<String> {
    let passwd = std::fs::read_to_string("/etc/passwd").ok()?;
    passwd.lines().find_map(|l| {
        let mut f = l.split(':');
        let name = f.next()?;
        let id: u32 = f.nth(1)?.parse().ok()?;
        (id == uid).then(|| name.to_owned())
    })
}

fn access(path: &Path, how: Access) -> Result<(), String> {
    accessat(CWD, path, how, AtFlags::EACCESS).map_err(|e| {
        let text = std::io::Error::from(e).to_string();
        // "Permission denied (os error 13)" -> "Permission denied".
        match text.find(" (os error") {
            Some(i) => text[..i].to_owned(),
            None => text,
        }
    })
}

/// The events file: appended to, or created in its folder.
/// A deploy hook's program: found (a bare name in `PATH`) and executable by this process.
/// A deploy hook's program: absolute (as the configuration resolved it), or a bare name that was
/// not found in the absolute folders of `PATH`. `misplaced`: it lies where planners write.
fn hook_row(program: &str, misplaced: Option<String>) -> Row {
    let runs = |p: &Path| {
        std::fs::metadata(p).is_ok_and(|m| m.is_file()) && access(p, Access::EXEC_OK).is_ok()
    };
    let verdict = if let Some(why) = misplaced {
        Verdict::Problem(why)
    } else if !program.contains('/') {
        Verdict::Problem(format!(
            "the deploy hook's program `{program}` is not in PATH's absolute folders ({}) or \
             cannot be run; an empty or relative PATH entry is never searched (it would be the \
             project folder), and a service's PATH is short: give the absolute path",
            std::env::var("PATH").unwrap_or_default()
        ))
    } else if runs(Path::new(program)) {
        Verdict::Ok(format!("the deploy hook runs {program}"))
    } else {
        Verdict::Problem(format!(
            "the deploy hook's program {program} does not exist or cannot be run by this user"
        ))
    };
    Row {
        what: "(deploy)".into(),
        folder: program.to_owned(),
        verdict,
    }
}

fn events_row(events: Option<&Path>) -> Row {
    let Some(file) = events else {
        return Row {
            what: "(events)".into(),
            folder: "-".into(),
            verdict: Verdict::Ok("the events go to stdout".into()),
        };
    };
    let verdict = match std::fs::metadata(file) {
        Ok(m) if m.is_dir() => Verdict::Problem("the events file is a folder".into()),
        Ok(_) => match access(file, Access::WRITE_OK) {
            Ok(()) => Verdict::Ok("appends to the events file".into()),
            Err(e) => Verdict::Problem(format!("cannot append to the events file: {e}")),
        },
        Err(_) => {
            let dir = file.parent().unwrap_or(Path::new("/"));
            match access(dir, Access::WRITE_OK | Access::EXEC_OK) {
                Ok(()) => Verdict::Ok("creates the events file (it does not exist yet)".into()),
                Err(e) => Verdict::Problem(format!(
                    "cannot create the events file in {}: {e}",
                    dir.display()
                )),
            }
        }
    };
    Row {
        what: "(events)".into(),
        folder: file.display().to_string(),
        verdict,
    }
}

/// `; did you mean `…`?` with the folder beside `path` whose name is near its own, or nothing.
fn near_folder(path: &Path) -> String {
    let (Some(parent), Some(name)) = (path.parent(), path.file_name()) else {
        return String::new();
    };
    let siblings: Vec<String> = std::fs::read_dir(parent)
        .map(|d| {
            d.filter_map(Result::ok)
                .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    match crate::names::closest(&name.to_string_lossy(), siblings.iter().map(String::as_str)) {
        Some(n) => format!("; did you mean {}?", parent.join(n).display()),
        None => String::new(),
    }
}

/// A root: listed (its subfolders are its projects).
fn root_row(root: &Path) -> Row {
    let verdict = match std::fs::metadata(root) {
        Err(_) => Verdict::Problem(format!(
            "the root does not exist{} (the daemon would wait for it and find its projects then): create it, or correct the path",
            near_folder(root)
        )),
        Ok(m) if !m.is_dir() => Verdict::Problem("the root is not a folder".into()),
        Ok(_) => match access(root, Access::READ_OK | Access::EXEC_OK) {
            Err(e) => Verdict::Problem(format!("cannot list the root: {e}")),
            Ok(()) => {
                let n = config::discover(root).len();
                Verdict::Ok(format!(
                    "lists the root: {n} project{} now, new subfolders are found while it runs",
                    if n == 1 { "" } else { "s" }
                ))
            }
        },
    };
    Row {
        what: "(root)".into(),
        folder: root.display().to_string(),
        verdict,
    }
}

/// A project: its folder, blackboard and program resolved, its inputs read (compiled in memory,
/// nothing written), the folder writable, the blackboard's owner kept.
fn project_row(spec: &ProjectSpec, config: &Config, me: &Process) -> Row {
    let folder = spec.path.display().to_string();
    let row = |what: String, verdict| Row {
        what,
        folder: folder.clone(),
        verdict,
    };
    match std::fs::metadata(&spec.path) {
        Err(_) => {
            // Most often a typo (`cel-project`): a problem, with the near folder.
            return row(
                "-".into(),
                Verdict::Problem(format!(
                    "the project folder does not exist{} (the daemon would wait for it): create it, or correct the path",
                    near_folder(&spec.path)
                )),
            );
        }
        Ok(m) if !m.is_dir() => {
            return row("-".into(), Verdict::Problem("not a folder".into()));
        }
        Ok(_) => {}
    }
    let mut problems = Vec::new();
    if let Err(e) = access(&spec.path, Access::WRITE_OK | Access::EXEC_OK) {
        problems.push(format!(
            "cannot create files in the folder (the outputs, the write-back): {e}"
        ));
    }
    if let Err(e) = access(&spec.path, Access::READ_OK) {
        problems.push(format!("cannot list the folder: {e}"));
    }
    let (blackboard, program) = match config::resolve_project(spec) {
        Ok(x) => x,
        // A folder made for a project whose planners have not saved a blackboard yet: the
        // project's matter, not the configuration's (as a compile with errors is).
        Err(_)
            if problems.is_empty()
                && config::blackboards(&spec.path).is_ok_and(|b| b.is_empty()) =>
        {
            return row(
                "-".into(),
                Verdict::Ok(
                    "no blackboard (*.aml) in the folder yet: the daemon reports E101 until a planner saves one, then compiles it"
                        .into(),
                ),
            );
        }
        Err(why) => {
            problems.push(why);
            return row("-".into(), Verdict::Problem(problems.join("; ")));
        }
    };
    // A blackboard the configuration names that is not there.
    if spec.blackboard.is_some() && std::fs::metadata(&blackboard).is_err() {
        let have: Vec<String> = config::blackboards(&spec.path)
            .unwrap_or_default()
            .iter()
            .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .collect();
        let named = blackboard
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
        problems.push(format!(
            "the blackboard {named} does not exist in the folder{}",
            match crate::names::closest(&named, have.iter().map(String::as_str)) {
                Some(n) => format!("; did you mean `{n}`?"),
                None if have.is_empty() => " (it has no *.aml)".to_owned(),
                None => format!(" (it has {})", have.join(", ")),
            }
        ));
        return row(program.name.clone(), Verdict::Problem(problems.join("; ")));
    }
    let what = program.name.clone();
    let fs = FsSource {
        max_file_size: config
            .max_file_size_mb
            .map_or(DEFAULT_MAX_FILE_SIZE, |m| m * 1024 * 1024),
    };
    let opts = Options {
        program: Some(program.name.clone()),
        lf: spec.lf,
        template: spec.template.clone(),
        confine_to: (!config.allow_outside).then(|| spec.path.clone()),
        pou: spec.pou.clone(),
        keep_model: false,
        drop_warnings: true,
        bind_split_from: None,
        picture: None,
        max_lines: spec.max_lines,
    };
    let c = compile::compile(&fs, &blackboard, &opts);
    let mut read = 0;
    for f in &c.files_read {
        match access(f, Access::READ_OK) {
            Ok(()) => read += 1,
            // A file the blackboard names that does not exist is the project's error, which
            // the compile reports; not the configuration's.
            Err(_)
                if std::fs::metadata(f)
                    .is_err_and(|e| e.kind() == std::io::ErrorKind::NotFound) => {}
            Err(e) => problems.push(format!("cannot read {}: {e}", f.display())),
        }
    }
    let mut notes = vec![format!(
        "reads {read} input{}",
        if read == 1 { "" } else { "s" }
    )];
    if problems.is_empty() {
        notes.push("creates the outputs in the folder".into());
    }
    if let Ok(m) = std::fs::metadata(&blackboard) {
        if m.mode() & 0o222 == 0 {
            notes.push("the blackboard is read-only: it is not written back".into());
        } else if me.may_chown() {
            notes.push("keeps the blackboard's owner (root or CAP_CHOWN)".into());
        } else if m.uid() == me.uid && me.in_group(m.gid()) {
            notes.push("keeps the blackboard's owner (its own file)".into());
        } else {
            let owner = user_name(m.uid()).unwrap_or_else(|| m.uid().to_string());
            problems.push(format!(
                "the blackboard belongs to {owner}{}: without CAP_CHOWN its owner cannot be kept, \
                 so the write-back is skipped (the outputs are written); the shipped unit grants \
                 CAP_CHOWN, else run the service as {owner}",
                if m.uid() == me.uid {
                    " and a group this user is not in"
                } else {
                    ""
                }
            ));
        }
    }
    if c.has_errors()
        && let Some(d) = c.diagnostics.first()
    {
        let l = d.locate(&c.sources);
        notes.push(format!(
            "compiles with errors now ({} {}{}: {})",
            l.code,
            l.file.unwrap_or_default(),
            l.line.map_or(String::new(), |n| format!(":{n}")),
            l.message
        ));
    }
    let verdict = if problems.is_empty() {
        Verdict::Ok(notes.join(", "))
    } else {
        Verdict::Problem(problems.join("; "))
    };
    row(what, verdict)
}
