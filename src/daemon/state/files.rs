//! The state files on disk: where a daemon writes its own, how (atomically), which ones
//! `skillpost status` finds and trusts, how one is read, and whether its daemon still runs.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use super::{FILE_NAME, ProjectState, SERVICE_STATE, Snapshot};

/// Writes the snapshot to a temporary file beside `path` (mode 0644: `skillpost status` is for
/// anyone who may read the folder), then renames it over `path`.
pub fn write_atomically(path: &Path, snap: &Snapshot) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    if !dir.exists() {
        use std::os::unix::fs::DirBuilderExt as _;
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(&dir)?;
    }
    let mut tmp = tempfile::Builder::new()
        .prefix(".status-")
        .suffix(".tmp")
        .tempfile_in(&dir)?;
    let mut text = serde_json::to_vec_pretty(snap).map_err(std::io::Error::other)?;
    text.push(b'\n');
    tmp.as_file_mut().write_all(&text)?;
    {
        use std::os::unix::fs::PermissionsExt as _;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644))?;
    }
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// The state file the daemon writes by default: `$RUNTIME_DIRECTORY/status.json` (a service's own
/// runtime folder), else `status-<pid>.json` beside the lock files (a daemon started by hand: one
/// file per daemon).
pub fn default_path() -> PathBuf {
    if std::env::var_os("RUNTIME_DIRECTORY").is_some_and(|d| !d.is_empty()) {
        crate::daemon::lock::runtime_dir().join(FILE_NAME)
    } else {
        crate::daemon::lock::runtime_dir().join(own_name(std::process::id()))
    }
}

/// The state file name of the daemon with this pid, started by hand.
fn own_name(pid: u32) -> String {
    format!("status-{pid}.json")
}

/// Whether `name` is a daemon's state file: `status.json` or `status-<pid>.json`.
pub fn is_state_name(name: &str) -> bool {
    name == FILE_NAME
        || name
            .strip_prefix("status-")
            .and_then(|n| n.strip_suffix(".json"))
            .is_some_and(|pid| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
}

/// The folders `skillpost status` looks in without `--state`, in order: `$RUNTIME_DIRECTORY`
/// (when set), the service's `/run/skillpost`, then the folder of daemons started by hand
/// (`$XDG_RUNTIME_DIR/skillpost`, else `/tmp/skillpost-<uid>`).
pub fn candidate_dirs() -> Vec<PathBuf> {
    let mut v = Vec::new();
    if std::env::var_os("RUNTIME_DIRECTORY").is_some_and(|d| !d.is_empty()) {
        v.push(crate::daemon::lock::runtime_dir());
    }
    if let Some(service) = Path::new(SERVICE_STATE).parent() {
        v.push(service.to_owned());
    }
    let by_hand = match std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        Some(d) => PathBuf::from(d).join("skillpost"),
        None => {
            std::env::temp_dir().join(format!("skillpost-{}", rustix::process::getuid().as_raw()))
        }
    };
    if !v.contains(&by_hand) {
        v.push(by_hand);
    }
    v
}

/// Every state file in [`candidate_dirs`] that can be read, with its path; and the problems
/// (a folder not to be trusted, a file that is no state file) as sentences. A file removed
/// between the listing and the read is left out silently.
pub fn discover() -> (Vec<(PathBuf, Snapshot)>, Vec<String>) {
    let (mut found, mut problems) = (Vec::new(), Vec::new());
    for dir in candidate_dirs() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        let mut names: Vec<PathBuf> = entries
            .flatten()
            .filter(|e| e.file_name().to_str().is_some_and(is_state_name))
            .map(|e| e.path())
            .collect();
        if names.is_empty() {
            continue;
        }
        if let Some(why) = untrusted_folder(&dir) {
            problems.push(why);
            continue;
        }
        names.sort();
        for path in names {
            match read(&path) {
                Ok(s) => found.push((path, s)),
                Err(_) if !path.exists() => {}
                Err(e) => problems.push(e),
            }
        }
    }
    (found, problems)
}

/// The start time of process `pid` (field 22 of `/proc/<pid>/stat`: clock ticks after boot).
pub fn process_start(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2, in parentheses) may hold spaces and parentheses itself.
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(19)?.parse().ok()
}

/// Whether the process that wrote the state still runs: its pid is alive and, where the file
/// records it, started when the writer did (a pid used again is another process). True where
/// that cannot be told (no `/proc`).
pub fn writer_alive(s: &Snapshot) -> bool {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return true;
    }
    match s.pid_start {
        Some(t) => process_start(s.pid) == Some(t),
        None => proc.join(s.pid.to_string()).exists(),
    }
}

/// Whether the daemon of this state runs: not `stopped`, and its writer alive.
pub fn running(s: &Snapshot) -> bool {
    s.daemon != "stopped" && writer_alive(s)
}

/// The state restricted to the projects that concern `folder` (the project itself, a folder in
/// it, or a folder it is in, such as a root); `None` when none does.
pub fn watching(s: &Snapshot, folder: &Path) -> Option<Snapshot> {
    let canon = |p: &Path| {
        std::fs::canonicalize(p).unwrap_or_else(|_| {
            std::env::current_dir()
                .map(|d| d.join(p))
                .unwrap_or_else(|_| p.to_owned())
        })
    };
    let folder = canon(folder);
    let projects: Vec<ProjectState> = s
        .projects
        .iter()
        .filter(|p| {
            let p = canon(Path::new(&p.project));
            p.starts_with(&folder) || folder.starts_with(&p)
        })
        .cloned()
        .collect();
    (!projects.is_empty()).then(|| Snapshot {
        projects,
        ..s.clone()
    })
}

/// Before a daemon's first write to `path` (a `status-<pid>.json` of a daemon started by hand):
/// removes the state files beside it of daemons that no longer run, so stopped daemons' files
/// do not pile up (the last ones stay until the next start, for `skillpost status`).
pub(super) fn sweep_stopped(path: &Path) {
    let own = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    if own == FILE_NAME || !is_state_name(own) {
        return;
    }
    let Some(Ok(entries)) = path.parent().map(std::fs::read_dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        if name.to_str().is_none_or(|n| n == own || !is_state_name(n)) {
            continue;
        }
        if read(&e.path()).is_ok_and(|s| !running(&s)) {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// Reads a state file.
pub fn read(path: &Path) -> Result<Snapshot, String> {
    // Without blocking, a regular file only, at most MAX_STATE bytes: a FIFO, `/dev/zero` or a
    // huge file at the path is an error at once, not a hang or a read without end.
    let text = crate::load::read_limited(path, MAX_STATE)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    serde_json::from_slice(&text)
        .map_err(|e| format!("{} is not a skillpost state file: {e}", path.display()))
}

/// The largest state file `skillpost status` reads (64 MiB: 100,000 projects' lines fit).
const MAX_STATE: u64 = 64 << 20;

/// Whether a folder the state file is looked for in without `--state` is one only its owner
/// can write to, and that owner is this user, root, or a user whose folder only a privileged
/// one could have made (its parent is root's and not writable by others, like `/run`): a
/// folder another user made first in `/tmp` (`/tmp/skillpost-<uid>`) is not trusted. The
/// reason when not.
pub fn untrusted_folder(dir: &Path) -> Option<String> {
    use std::os::unix::fs::MetadataExt as _;
    let m = match std::fs::symlink_metadata(dir) {
        Ok(m) => m,
        Err(e) => return Some(format!("{}: {e}", dir.display())),
    };
    let me = rustix::process::getuid().as_raw();
    let parent_privileged = dir
        .parent()
        .and_then(|p| std::fs::symlink_metadata(p).ok())
        .is_some_and(|p| p.uid() == 0 && p.mode() & 0o022 == 0);
    if !m.is_dir() || m.mode() & 0o022 != 0 || !(m.uid() == me || m.uid() == 0 || parent_privileged)
    {
        return Some(format!(
            "{} is not a folder of this user (or of a service) that only its owner can write to; \
             not reading a state file from it (name the file with --state)",
            dir.display()
        ));
    }
    None
}
