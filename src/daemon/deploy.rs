//! The deploy hook (`on_success`, docs/DAEMON.md "Deploying"): after a compile that wrote new
//! outputs (and its write-back), the configuration's argument vector is run, never a shell line,
//! with placeholders replaced by the compile's files.
//!
//! - One hook at a time per project: a hook of a newer compile waits for the running one, and of
//!   several waiting only the newest runs (the outputs on disk are the newest anyway).
//! - A hook never delays a compile: each project's hooks run on a task of their own.
//! - A hook that runs longer than its timeout (`deploy_timeout_s`, default 60 s) is killed with
//!   its whole process group; a stop of the daemon kills running hooks the same way.
//! - Its exit status and the last lines of its stderr go into `deploy-succeeded` /
//!   `deploy-failed`; what it prints is read as it comes and only the last
//!   [`STDERR_TAIL`] bytes of stderr are kept, so a hook printing megabytes costs no memory.
//! - The hook comes from the daemon's configuration only; a configuration file that lies in a
//!   project folder or root may not set one ([`super::config`] refuses it).

use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use tokio::io::AsyncReadExt;
use tokio::sync::watch;

use super::events::{Event, EventSink};

/// The hook's timeout when the configuration does not set one.
pub const DEFAULT_DEPLOY_TIMEOUT_S: u64 = 60;
/// The allowed values of `deploy_timeout_s`.
pub const DEPLOY_TIMEOUT_S_RANGE: RangeInclusive<u64> = 1..=3600;
/// How much of the end of a hook's stderr the events carry.
pub const STDERR_TAIL: usize = 4096;
/// After a stop's `SIGTERM`, how long a hook may take before its group gets `SIGKILL`.
const TERM_GRACE: Duration = Duration::from_secs(2);

/// The placeholders an argument may hold; `{outputs}` only as a whole argument.
pub const PLACEHOLDERS: &[&str] = &[
    "src",
    "dat",
    "mod",
    "script",
    "output",
    "outputs",
    "blackboard",
    "project",
    "program",
    "controller",
    "io",
    "eio",
];

/// A configured hook: the argument vector as written (placeholders not yet replaced) and its
/// timeout.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Hook {
    pub argv: Vec<String>,
    pub timeout: Duration,
}

/// What the placeholders of one compile stand for.
#[derive(Debug, Clone)]
pub struct Context {
    /// Every output file, in the order of `compile-succeeded`.
    pub outputs: Vec<PathBuf>,
    /// The main output of the first program (the write-back value's file).
    pub main: PathBuf,
    pub blackboard: PathBuf,
    pub project: PathBuf,
    pub program: String,
    /// The resource whose controller runs the program (empty when the compile does not say).
    pub controller: String,
    /// The daemon's own copy of the program's files, which `outputs` and `main` name (see
    /// [`super::snapshot`]); removed when the last clone of this context is dropped.
    pub snapshot: Option<super::snapshot::Held>,
    /// The program's I/O list and, for RAPID, its `EIO.cfg` fragment (`{io}`, `{eio}`): for
    /// commissioning, not program files (`{outputs}` does not hold them).
    pub io: Vec<PathBuf>,
}

/// The pieces of an argument: text and placeholder names, `{{`/`}}` as braces.
fn pieces(arg: &str) -> Result<Vec<(bool, String)>, String> {
    let mut out: Vec<(bool, String)> = Vec::new();
    let mut text = String::new();
    let mut chars = arg.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '{' if chars.peek() == Some(&'{') => {
                chars.next();
                text.push('{');
            }
            '}' if chars.peek() == Some(&'}') => {
                chars.next();
                text.push('}');
            }
            '{' => {
                let mut name = String::new();
                loop {
                    match chars.next() {
                        Some('}') => break,
                        Some(c) => name.push(c),
                        None => {
                            return Err(format!(
                                "`{arg}`: a `{{` without its `}}` (write `{{{{` for a brace)"
                            ));
                        }
                    }
                }
                if !PLACEHOLDERS.contains(&name.as_str()) {
                    return Err(format!(
                        "`{arg}`: unknown placeholder `{{{name}}}`; known: {}",
                        PLACEHOLDERS
                            .iter()
                            .map(|p| format!("{{{p}}}"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ));
                }
                if !text.is_empty() {
                    out.push((false, std::mem::take(&mut text)));
                }
                out.push((true, name));
            }
            '}' => return Err(format!("`{arg}`: a `}}` without its `{{` (write `}}}}`)")),
            c => text.push(c),
        }
    }
    if !text.is_empty() {
        out.push((false, text));
    }
    Ok(out)
}

/// Checks a configured argument vector: not empty, a program, known placeholders, `{outputs}`
/// only as a whole argument, no NUL. The message names the argument.
pub fn check(argv: &[String]) -> Result<(), String> {
    let Some(program) = argv.first() else {
        return Err(
            "`on_success` is empty: give the program and its arguments, \
                    e.g. [\"/usr/local/bin/deploy\", \"{src}\"]"
                .into(),
        );
    };
    if program.trim().is_empty() {
        return Err("`on_success`: the program (the first element) is empty".into());
    }
    for arg in argv {
        if arg.contains('\0') {
            return Err("`on_success`: an argument holds a NUL character".into());
        }
        let p = pieces(arg)?;
        if p.iter().any(|(ph, n)| *ph && n == "outputs") && p.len() > 1 {
            return Err(format!(
                "`{arg}`: `{{outputs}}` stands for one argument per output file and must be \
                 a whole argument"
            ));
        }
    }
    Ok(())
}

/// Whether the hook's arguments tell one program from another (`{controller}` or `{program}`):
/// a hook that does not would send every program of a cell to one place, all but one of them
/// to the wrong controller.
pub fn tells_programs_apart(argv: &[String]) -> bool {
    argv.iter().any(|a| {
        pieces(a).is_ok_and(|p| {
            p.iter()
                .any(|(ph, n)| *ph && (n == "controller" || n == "program"))
        })
    })
}

/// The argument vector for one compile. `Err` when a placeholder names a file this compile did
/// not write (`{dat}` of a RAPID program).
pub fn expand(argv: &[String], ctx: &Context) -> Result<Vec<String>, String> {
    let by_ext = |ext: &str| {
        ctx.outputs
            .iter()
            .find(|p| {
                p.extension()
                    .is_some_and(|e| e.to_string_lossy().eq_ignore_ascii_case(ext))
            })
            .map(|p| p.display().to_string())
            .ok_or_else(|| {
                format!(
                    "`{{{ext}}}`: this compile wrote no `.{ext}` file (its outputs: {})",
                    ctx.outputs
                        .iter()
                        .map(|p| p.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })
    };
    let mut out = Vec::new();
    for arg in argv {
        let p = pieces(arg)?;
        if p.len() == 1 && p[0].0 && p[0].1 == "outputs" {
            out.extend(ctx.outputs.iter().map(|o| o.display().to_string()));
            continue;
        }
        let mut s = String::new();
        for (placeholder, text) in p {
            if !placeholder {
                s.push_str(&text);
                continue;
            }
            match text.as_str() {
                "src" | "dat" | "mod" | "script" => s.push_str(&by_ext(&text)?),
                "output" => s.push_str(&ctx.main.display().to_string()),
                "blackboard" => s.push_str(&ctx.blackboard.display().to_string()),
                "project" => s.push_str(&ctx.project.display().to_string()),
                "program" => s.push_str(&ctx.program),
                "io" | "eio" => {
                    let suffix = if text == "io" {
                        crate::emit::IO_LIST
                    } else {
                        crate::emit::IO_CONFIG
                    };
                    let found = ctx.io.iter().find(|p| {
                        p.file_name()
                            .is_some_and(|n| n.to_string_lossy().ends_with(&format!(".{suffix}")))
                    });
                    match found {
                        Some(p) => s.push_str(&p.display().to_string()),
                        None => {
                            return Err(format!(
                                "`{{{text}}}`: this compile wrote no `.{suffix}` file{}",
                                if text == "eio" {
                                    " (only a RAPID module has an EIO.cfg fragment)"
                                } else {
                                    ""
                                }
                            ));
                        }
                    }
                }
                "controller" => s.push_str(&ctx.controller),
                other => return Err(format!("`{{{other}}}` is not allowed here")),
            }
        }
        out.push(s);
    }
    Ok(out)
}

/// One hook run to do.
#[derive(Debug, Clone)]
pub struct Request {
    pub project: String,
    pub run_id: u64,
    pub hook: Hook,
    /// One per program the compile wrote new bytes for, in the compile's order: the hook runs
    /// once for each, one after the other.
    pub programs: Vec<Context>,
}

/// The request waiting to run: taken out by the worker, so that a request (and its snapshot)
/// lives only until its hooks have run.
type Slot = Arc<std::sync::Mutex<Option<Request>>>;

/// The hooks of one project: a task that runs them one at a time, the newest waiting one next.
pub struct Worker {
    /// Rings when a request waits in `slot`; closed when the worker is dropped.
    tx: watch::Sender<()>,
    slot: Slot,
    task: tokio::task::JoinHandle<()>,
}

impl Worker {
    /// Starts the project's worker. `stop` turns true when the daemon stops.
    pub fn start(sink: Arc<EventSink>, stop: watch::Receiver<bool>) -> Worker {
        let (tx, rx) = watch::channel(());
        let slot = Slot::default();
        let task = tokio::spawn(work(sink, rx, slot.clone(), stop));
        Worker { tx, slot, task }
    }

    /// Runs `r` after the running hook; replaces one that waits (it is not run).
    pub fn submit(&self, r: Request) {
        *self.slot.lock().unwrap_or_else(|p| p.into_inner()) = Some(r);
        self.tx.send_replace(());
    }

    /// Whether its task has ended.
    pub fn is_finished(&self) -> bool {
        self.task.is_finished()
    }

    /// The task, to wait for at a stop.
    pub fn into_task(self) -> tokio::task::JoinHandle<()> {
        drop(self.tx);
        self.task
    }
}

async fn work(
    sink: Arc<EventSink>,
    mut rx: watch::Receiver<()>,
    slot: Slot,
    mut stop: watch::Receiver<bool>,
) {
    loop {
        tokio::select! {
            changed = rx.changed() => {
                if changed.is_err() {
                    return;
                }
            }
            _ = stop.wait_for(|s| *s) => return,
        }
        rx.borrow_and_update();
        let Some(r) = slot.lock().unwrap_or_else(|p| p.into_inner()).take() else {
            continue;
        };
        // Taken: a newer one waits in the channel from now on.
        if *stop.borrow() {
            return;
        }
        for ctx in &r.programs {
            if *stop.borrow() {
                return;
            }
            run(&sink, &r, ctx, &mut stop).await;
        }
    }
}

/// How a hook ended.
enum End {
    Exited(std::process::ExitStatus),
    TimedOut,
    Stopped,
}

async fn run(sink: &EventSink, r: &Request, ctx: &Context, stop: &mut watch::Receiver<bool>) {
    let project = Some(r.project.as_str());
    let started = std::time::Instant::now();
    let ms = || started.elapsed().as_millis() as u64;
    let program = ctx.program.clone();
    let controller = (!ctx.controller.is_empty()).then(|| ctx.controller.clone());
    let argv = match expand(&r.hook.argv, ctx) {
        Ok(a) => a,
        Err(why) => {
            sink.emit(
                project,
                Event::DeployFailed {
                    program: program.clone(),
                    controller: controller.clone(),
                    run_id: r.run_id,
                    duration_ms: 0,
                    exit_code: None,
                    signal: None,
                    timed_out: false,
                    reason: why,
                    stderr: String::new(),
                },
            );
            return;
        }
    };
    sink.emit(
        project,
        Event::DeployStarted {
            program: program.clone(),
            controller: controller.clone(),
            run_id: r.run_id,
            argv: argv.clone(),
        },
    );
    let mut cmd = tokio::process::Command::new(&argv[0]);
    cmd.args(&argv[1..])
        .current_dir(&ctx.project)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        // Its own process group: a timeout or a stop ends the hook and whatever it started.
        .process_group(0)
        .kill_on_drop(true);
    let mut child = match cmd.spawn() {
        Ok(c) => c,
        Err(e) => {
            sink.emit(
                project,
                Event::DeployFailed {
                    program: program.clone(),
                    controller: controller.clone(),
                    run_id: r.run_id,
                    duration_ms: ms(),
                    exit_code: None,
                    signal: None,
                    timed_out: false,
                    reason: format!("cannot run {}: {e}", argv[0]),
                    stderr: String::new(),
                },
            );
            return;
        }
    };
    let pgid = child.id().map(|id| id as i32);
    // Both pipes read as they come: a hook that prints megabytes never blocks on a full pipe,
    // and only the end of stderr is kept.
    let out = child.stdout.take().map(|mut s| {
        tokio::spawn(async move {
            let mut buf = vec![0u8; 16 * 1024];
            while let Ok(n) = s.read(&mut buf).await {
                if n == 0 {
                    break;
                }
            }
        })
    });
    let err = child.stderr.take().map(|mut s| {
        tokio::spawn(async move {
            let mut tail: Vec<u8> = Vec::new();
            let mut cut = false;
            let mut buf = vec![0u8; 16 * 1024];
            while let Ok(n) = s.read(&mut buf).await {
                if n == 0 {
                    break;
                }
                tail.extend_from_slice(&buf[..n]);
                if tail.len() > 2 * STDERR_TAIL {
                    tail.drain(..tail.len() - STDERR_TAIL);
                    cut = true;
                }
            }
            (tail, cut)
        })
    });
    let end = tokio::select! {
        status = child.wait() => match status {
            Ok(s) => End::Exited(s),
            Err(_) => End::Stopped,
        },
        _ = tokio::time::sleep(r.hook.timeout) => End::TimedOut,
        _ = stop.wait_for(|s| *s) => End::Stopped,
    };
    let end = match end {
        End::Exited(s) => End::Exited(s),
        other => {
            if let Some(g) = pgid {
                if matches!(other, End::Stopped) {
                    // A stop asks first; the timeout has waited long enough.
                    kill_group(g, rustix::process::Signal::TERM);
                    if tokio::time::timeout(TERM_GRACE, child.wait())
                        .await
                        .is_err()
                    {
                        kill_group(g, rustix::process::Signal::KILL);
                    }
                } else {
                    kill_group(g, rustix::process::Signal::KILL);
                }
            }
            let _ = child.wait().await;
            other
        }
    };
    // A process that left the group may still hold the pipes: wait for them boundedly.
    if let Some(o) = out {
        let _ = tokio::time::timeout(Duration::from_millis(500), o).await;
    }
    let (tail, cut) = match err {
        Some(e) => match tokio::time::timeout(Duration::from_millis(500), e).await {
            Ok(Ok(t)) => t,
            _ => (Vec::new(), false),
        },
        None => (Vec::new(), false),
    };
    let stderr = tail_text(&tail, cut);
    let event = match end {
        End::Exited(s) if s.success() => Event::DeploySucceeded {
            program: program.clone(),
            controller: controller.clone(),
            run_id: r.run_id,
            duration_ms: ms(),
            stderr,
        },
        End::Exited(s) => {
            use std::os::unix::process::ExitStatusExt as _;
            Event::DeployFailed {
                program: program.clone(),
                controller: controller.clone(),
                run_id: r.run_id,
                duration_ms: ms(),
                exit_code: s.code(),
                signal: s.signal(),
                timed_out: false,
                reason: match (s.code(), s.signal()) {
                    (Some(c), _) => format!("{} exited with status {c}", argv[0]),
                    (None, Some(sig)) => format!("{} was killed by signal {sig}", argv[0]),
                    _ => format!("{} failed", argv[0]),
                },
                stderr,
            }
        }
        End::TimedOut => Event::DeployFailed {
            program: program.clone(),
            controller: controller.clone(),
            run_id: r.run_id,
            duration_ms: ms(),
            exit_code: None,
            signal: Some(9),
            timed_out: true,
            reason: format!(
                "{} ran longer than {} s: killed with its process group",
                argv[0],
                r.hook.timeout.as_secs()
            ),
            stderr,
        },
        End::Stopped => Event::DeployFailed {
            program: program.clone(),
            controller: controller.clone(),
            run_id: r.run_id,
            duration_ms: ms(),
            exit_code: None,
            signal: None,
            timed_out: false,
            reason: format!("the daemon stopped: {} was ended", argv[0]),
            stderr,
        },
    };
    sink.emit(project, event);
}

fn kill_group(pgid: i32, sig: rustix::process::Signal) {
    if let Some(pid) = rustix::process::Pid::from_raw(pgid) {
        let _ = rustix::process::kill_process_group(pid, sig);
    }
}

/// The last lines of `bytes` (at most [`STDERR_TAIL`] bytes, from a line start where there is
/// one), as text. `cut`: bytes before these were dropped already.
fn tail_text(bytes: &[u8], cut: bool) -> String {
    let mut b = &bytes[bytes.len().saturating_sub(STDERR_TAIL)..];
    if (cut || b.len() < bytes.len())
        && let Some(i) = b.iter().position(|c| *c == b'\n')
    {
        b = &b[i + 1..];
    }
    String::from_utf8_lossy(b).trim_end().to_owned()
}

/// The hook's program as the configuration gives it: a path with a `/` relative to the
/// configuration file's folder, a bare name looked up in `PATH` when it runs.
pub fn program_path(program: &str, base: &Path) -> String {
    if program.contains('/') && !program.starts_with('/') {
        crate::paths::normalize(&base.join(program))
            .display()
            .to_string()
    } else {
        program.to_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ctx() -> Context {
        Context {
            outputs: vec!["/p/P.src".into(), "/p/P.dat".into()],
            main: "/p/P.src".into(),
            blackboard: "/p/P.aml".into(),
            project: "/p".into(),
            program: "P".into(),
            controller: "KUKA KR15-2".into(),
            snapshot: None,
            io: vec!["/p/P.io.csv".into()],
        }
    }

    fn v(a: &[&str]) -> Vec<String> {
        a.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn placeholders_are_replaced_and_outputs_is_one_argument_each() {
        let argv = v(&[
            "install",
            "-m",
            "0644",
            "{outputs}",
            "/mnt/kuka/{program}/",
            "{{literal}}",
            "--src={src}",
        ]);
        check(&argv).unwrap();
        assert_eq!(
            expand(&argv, &ctx()).unwrap(),
            v(&[
                "install",
                "-m",
                "0644",
                "/p/P.src",
                "/p/P.dat",
                "/mnt/kuka/P/",
                "{literal}",
                "--src=/p/P.src"
            ])
        );
    }

    #[test]
    fn wrong_hooks_are_refused_with_what_is_wrong() {
        for (argv, says) in [
            (v(&[]), "empty"),
            (v(&[" "]), "program"),
            (v(&["cp", "{source}"]), "unknown placeholder `{source}`"),
            (v(&["cp", "{src"]), "without its"),
            (v(&["cp", "x}"]), "without its"),
            (v(&["cp", "--files={outputs}"]), "whole argument"),
        ] {
            let e = check(&argv).unwrap_err();
            assert!(e.contains(says), "{argv:?}: {e}");
        }
    }

    #[test]
    fn a_placeholder_for_a_file_the_compile_did_not_write_is_an_error() {
        let e = expand(&v(&["cp", "{mod}"]), &ctx()).unwrap_err();
        assert!(e.contains("no `.mod` file"), "{e}");
    }

    #[test]
    fn the_stderr_tail_starts_at_a_line() {
        let mut b = Vec::new();
        for i in 0..2000 {
            b.extend_from_slice(format!("line {i}\n").as_bytes());
        }
        let t = tail_text(&b, false);
        assert!(t.len() <= STDERR_TAIL);
        assert!(t.starts_with("line "), "{}", &t[..20]);
        assert!(t.ends_with("line 1999"));
    }
}
