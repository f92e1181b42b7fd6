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

use std::collections::{BTreeSet, HashMap, HashSet};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use tokio::io::AsyncReadExt;
use tokio::sync::{Semaphore, watch};

use super::events::{Event, EventSink};

/// The hook's timeout when the configuration does not set one.
pub const DEFAULT_DEPLOY_TIMEOUT_S: u64 = 60;
/// The allowed values of `deploy_timeout_s`.
pub const DEPLOY_TIMEOUT_S_RANGE: RangeInclusive<u64> = 1..=3600;
/// How much of the end of a hook's stderr the events carry.
pub const STDERR_TAIL: usize = 4096;
/// After a stop's `SIGTERM`, how long a hook may take before its group gets `SIGKILL`.
const TERM_GRACE: Duration = Duration::from_secs(2);
/// How many hooks run at once, of all projects, when the configuration does not say
/// (`max_deploys`).
pub const DEFAULT_MAX_DEPLOYS: usize = 4;
/// The allowed values of `max_deploys`.
pub const MAX_DEPLOYS_RANGE: RangeInclusive<u64> = 1..=64;
/// The descriptors one running hook may hold in the daemon: its stdout and stderr pipes and
/// the process descriptor its end is waited on, and for a moment while it starts the pipes'
/// other ends and the pipe that reports a failed `exec`. The folder locks leave this many per
/// hook (`Locks::reserving`), so hooks never take the compiles' descriptors.
pub const FDS_PER_HOOK: u64 = 8;
/// The variable each hook (and whatever it starts, which inherits it) carries: its token, by
/// which the daemon finds the hook's processes also after they left its process group
/// (`setsid`) or lost their parent.
pub const HOOK_ENV: &str = "SKILLPOST_DEPLOY";

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
                    let found = ctx
                        .io
                        .iter()
                        .find(|p| crate::emit::commissioning_file(p) == Some(suffix));
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
/// What the hooks of all projects share: the cap on how many run at once, the hooks running
/// (their main process, which tokio reaps), and whether the daemon is its hooks' subreaper.
pub struct Pool {
    slots: std::sync::Arc<Semaphore>,
    cap: Mutex<usize>,
    next: AtomicU64,
    /// When the pool was made (nanoseconds of the clock): part of every token.
    born: u128,
    /// Main pid of each running hook. Held while a hook starts and while orphans are reaped, so
    /// that the reaper never takes a running hook's exit status from tokio.
    running: Mutex<HashSet<u32>>,
    /// The daemon is its hooks' subreaper (`PR_SET_CHILD_SUBREAPER`): a hook's process whose
    /// parent ended becomes the daemon's child (not init's) and is reaped here.
    subreaper: bool,
}

impl Pool {
    /// `cap` hooks at once. `subreaper`: make this process the subreaper of its hooks' processes
    /// (the daemon's own process only: a test process running the daemon keeps its children).
    pub fn new(cap: usize, subreaper: bool) -> Pool {
        let subreaper = subreaper
            && rustix::process::set_child_subreaper(Some(rustix::process::getpid())).is_ok();
        Pool {
            slots: std::sync::Arc::new(Semaphore::new(cap)),
            cap: Mutex::new(cap),
            next: AtomicU64::new(1),
            born: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos()),
            running: Mutex::new(HashSet::new()),
            subreaper,
        }
    }

    /// Takes a new cap (a reload): more slots at once; fewer as running hooks end.
    pub fn set_cap(&self, cap: usize) {
        let mut old = self.cap.lock().unwrap_or_else(|p| p.into_inner());
        if cap > *old {
            self.slots.add_permits(cap - *old);
        } else if cap < *old {
            let fewer = (*old - cap) as u32;
            let slots = self.slots.clone();
            tokio::spawn(async move {
                if let Ok(p) = slots.acquire_many_owned(fewer).await {
                    p.forget();
                }
            });
        }
        *old = cap;
    }

    /// A token no other hook carries: this process, this pool (several daemons may run in one
    /// process: tests), this hook.
    fn token(&self) -> String {
        format!(
            "{}-{:x}-{:x}-{}",
            std::process::id(),
            self.born,
            std::sync::Arc::as_ptr(&self.slots) as usize,
            self.next.fetch_add(1, Ordering::Relaxed)
        )
    }
}

/// The hooks of one project: a task that runs them one at a time, the newest waiting one next.
pub struct Worker {
    /// Rings when a request waits in `slot`; closed when the worker is dropped.
    tx: watch::Sender<()>,
    slot: Slot,
    task: tokio::task::JoinHandle<()>,
}

impl Worker {
    /// Starts the project's worker. `stop` turns true when the daemon stops.
    pub fn start(sink: Arc<EventSink>, stop: watch::Receiver<bool>, pool: Arc<Pool>) -> Worker {
        let (tx, rx) = watch::channel(());
        let slot = Slot::default();
        let task = tokio::spawn(work(sink, rx, slot.clone(), stop, pool));
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
    pool: Arc<Pool>,
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
            // One of the pool's slots: at most `max_deploys` hooks run at once.
            let slot = tokio::select! {
                s = pool.slots.clone().acquire_owned() => match s {
                    Ok(s) => s,
                    Err(_) => return,
                },
                _ = stop.wait_for(|s| *s) => return,
            };
            run(&sink, &r, ctx, &mut stop, &pool).await;
            drop(slot);
        }
    }
}

/// How a hook ended.
enum End {
    Exited(std::process::ExitStatus),
    TimedOut,
    Stopped,
}

async fn run(
    sink: &EventSink,
    r: &Request,
    ctx: &Context,
    stop: &mut watch::Receiver<bool>,
    pool: &Pool,
) {
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
                Event::deploy_not_run(&program, controller.as_deref(), r.run_id, 0, why),
            );
            return;
        }
    };
    if !Path::new(&argv[0]).is_absolute() {
        sink.emit(
            project,
            Event::deploy_not_run(
                &program,
                controller.as_deref(),
                r.run_id,
                0,
                format!(
                    "`{}` was not found in the absolute folders of PATH when the configuration \
                     was read (an empty or relative PATH entry is never searched: it would be \
                     the project folder); give the program's absolute path, or install it and \
                     reload",
                    argv[0]
                ),
            ),
        );
        return;
    }
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
    let token = pool.token();
    cmd.env(HOOK_ENV, &token);
    let spawned = {
        let mut running = pool.running.lock().unwrap_or_else(|p| p.into_inner());
        let c = cmd.spawn();
        if let Ok(c) = &c
            && let Some(id) = c.id()
        {
            running.insert(id);
        }
        c
    };
    let mut child = match spawned {
        Ok(c) => c,
        Err(e) => {
            sink.emit(
                project,
                Event::deploy_not_run(
                    &program,
                    controller.as_deref(),
                    r.run_id,
                    ms(),
                    format!("cannot run {}: {e}", argv[0]),
                ),
            );
            return;
        }
    };
    let main = child.id();
    let pgid = main.map(|id| id as i32);
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
                    signal_tree(&token, rustix::process::Signal::TERM);
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
    if let Some(id) = main {
        pool.running
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&id);
    }
    // The hook's whole process tree ends with it: what it left running in its group, in a
    // session of its own (`setsid`), or without a parent.
    let left = end_tree(pool, &token).await;
    if left > 0 {
        tracing::warn!(
            "{}: {left} process(es) of the deploy hook {} could not be ended",
            r.project,
            argv[0]
        );
    }
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

/// The processes of the hook whose token is `token`: those whose environment carries it
/// (every process the hook started inherits it, whatever its group, session or parent), and
/// every descendant of those (one that cleared its environment while its parent lives). Zombies
/// are left out (they hold nothing and cannot be signalled). This process is never among them.
fn tree(token: &str) -> Vec<u32> {
    let needle = format!("{HOOK_ENV}={token}\0");
    let me = std::process::id();
    let mut children: HashMap<u32, Vec<u32>> = HashMap::new();
    let mut marked: BTreeSet<u32> = BTreeSet::new();
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    for e in dir.flatten() {
        let Some(pid) = e.file_name().to_str().and_then(|n| n.parse::<u32>().ok()) else {
            continue;
        };
        let Some((state, ppid)) = stat(pid) else {
            continue;
        };
        if state == 'Z' || pid == me {
            continue;
        }
        children.entry(ppid).or_default().push(pid);
        if environ_has(pid, needle.as_bytes()) {
            marked.insert(pid);
        }
    }
    let mut all = marked.clone();
    let mut todo: Vec<u32> = marked.into_iter().collect();
    while let Some(p) = todo.pop() {
        for c in children.get(&p).into_iter().flatten() {
            if all.insert(*c) {
                todo.push(*c);
            }
        }
    }
    all.remove(&me);
    all.into_iter().collect()
}

/// A process's state letter and parent, from `/proc/PID/stat` (the name in parentheses may
/// hold anything: read after its last `)`).
fn stat(pid: u32) -> Option<(char, u32)> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let mut f = s.get(s.rfind(')')? + 1..)?.split_whitespace();
    let state = f.next()?.chars().next()?;
    let ppid = f.next()?.parse().ok()?;
    Some((state, ppid))
}

/// Whether the process's environment (as it started) holds `needle` (`NAME=value\0`). Only a
/// process of this user can be read; at most 1 MiB of it.
fn environ_has(pid: u32, needle: &[u8]) -> bool {
    use std::io::Read as _;
    let Ok(f) = std::fs::File::open(format!("/proc/{pid}/environ")) else {
        return false;
    };
    let mut env = Vec::new();
    if f.take(1 << 20).read_to_end(&mut env).is_err() {
        return false;
    }
    env.windows(needle.len())
        .enumerate()
        .any(|(i, w)| w == needle && (i == 0 || env[i - 1] == 0))
}

/// Sends `sig` to every process of the hook's tree; how many there were.
fn signal_tree(token: &str, sig: rustix::process::Signal) -> usize {
    let pids = tree(token);
    for p in &pids {
        if let Some(pid) = rustix::process::Pid::from_raw(*p as i32) {
            let _ = rustix::process::kill_process(pid, sig);
        }
    }
    pids.len()
}

/// Ends every process left of the hook `token` (`SIGKILL`, again until none is found: one may
/// start another before it is killed), reaps those that became this process's children, and
/// returns how many could not be ended.
async fn end_tree(pool: &Pool, token: &str) -> usize {
    let mut ended: BTreeSet<u32> = BTreeSet::new();
    let mut left = 0;
    for _ in 0..50 {
        let pids = tree(token);
        left = pids.len();
        if pids.is_empty() {
            break;
        }
        for p in &pids {
            if let Some(pid) = rustix::process::Pid::from_raw(*p as i32) {
                let _ = rustix::process::kill_process(pid, rustix::process::Signal::KILL);
            }
            ended.insert(*p);
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    if pool.subreaper {
        // Those whose parent had ended are ours now: reap them (a killed process becomes a
        // zombie at once or after its last thread ends).
        for _ in 0..50 {
            if reap(pool, &ended) == 0 {
                break;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }
    left
}

/// Reaps this process's children that ended and are no running hook's main process (tokio
/// reaps those): `ended`, and any other zombie child (a hook's orphan that ended on its own).
/// Returns how many of `ended` are still this process's unreaped children.
fn reap(pool: &Pool, ended: &BTreeSet<u32>) -> usize {
    let running = pool.running.lock().unwrap_or_else(|p| p.into_inner());
    let me = std::process::id();
    let mut waiting = 0;
    let zombies = std::fs::read_dir("/proc")
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let pid = e.file_name().to_str()?.parse::<u32>().ok()?;
            let (state, ppid) = stat(pid)?;
            (ppid == me && (state == 'Z' || ended.contains(&pid))).then_some((pid, state))
        });
    for (pid, state) in zombies.collect::<Vec<_>>() {
        if running.contains(&pid) {
            continue;
        }
        let Some(p) = rustix::process::Pid::from_raw(pid as i32) else {
            continue;
        };
        match rustix::process::waitpid(Some(p), rustix::process::WaitOptions::NOHANG) {
            Ok(Some(_)) => {}
            Ok(None) if state != 'Z' => waiting += 1,
            _ => {}
        }
    }
    waiting
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

/// The hook's program as the configuration gives it: an absolute path as written, a path with a
/// `/` relative to the configuration file's folder, a bare name looked up when the
/// configuration is read in the absolute folders of `PATH` ([`find_in_path`]). A bare name not
/// found there stays bare: `run` refuses to run it (it never falls to the process's own
/// lookup, which would search an empty or relative `PATH` entry in the project folder).
pub fn program_path(program: &str, base: &Path) -> String {
    if program.starts_with('/') {
        program.to_owned()
    } else if program.contains('/') {
        crate::paths::normalize(&base.join(program))
            .display()
            .to_string()
    } else {
        find_in_path(program, std::env::var_os("PATH").as_deref())
            .map_or_else(|| program.to_owned(), |p| p.display().to_string())
    }
}

/// The first executable regular file `name` in the absolute folders of `path` (a `PATH` value):
/// an empty entry or a relative one (`.`, `bin`) means the current folder, which for a hook is
/// the project folder, where planners write; such entries are skipped.
pub fn find_in_path(name: &str, path: Option<&std::ffi::OsStr>) -> Option<PathBuf> {
    use std::os::unix::fs::PermissionsExt as _;
    std::env::split_paths(path?)
        .filter(|d| d.is_absolute())
        .map(|d| d.join(name))
        .find(|c| {
            std::fs::metadata(c).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
        })
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
