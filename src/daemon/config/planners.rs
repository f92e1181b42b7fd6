//! What the daemon keeps out of the folders planners write (every project folder and root):
//! its own files (the events and state files), the programs its deploy hooks run, and a hook set
//! by a configuration file that lies there. Each check gives the sentence to refuse with.

use std::path::{Path, PathBuf};

use super::Config;

/// A path as the file system names it: the folder canonical (when it exists), the name kept.
fn canonical_or_literal(p: &Path) -> PathBuf {
    if let Ok(c) = std::fs::canonicalize(p) {
        return c;
    }
    match (p.parent(), p.file_name()) {
        (Some(dir), Some(name)) => std::fs::canonicalize(dir)
            .map(|d| d.join(name))
            .unwrap_or_else(|_| p.to_path_buf()),
        _ => p.to_path_buf(),
    }
}

/// Whether one of the daemon's own files (`own`: the events file, the state file) lies in a
/// project folder or a root of `config`: the daemon would write into a planner's folder (with
/// `--state P/Blackboard.aml`, replace the blackboard), and its own writes would be changes in
/// a watched folder. The sentence says which file and which folder; `None` when all is well.
pub fn own_files_problem(config: &Config, own: &[PathBuf]) -> Option<String> {
    let folders = planners_folders(config);
    let own: Vec<(PathBuf, &PathBuf)> = own.iter().map(|o| (canonical_or_literal(o), o)).collect();
    for (what, folder) in folders {
        let real = canonical_or_literal(folder);
        for (o, given) in &own {
            if o.starts_with(&real) || given.starts_with(folder) {
                return Some(format!(
                    "{} (the daemon's own events or state file) lies in the {what} {}: the daemon \
                     never writes its files among a planner's; put it elsewhere (say, \
                     /var/log/skillpost/events.jsonl, or --state in the runtime folder)",
                    given.display(),
                    folder.display()
                ));
            }
        }
    }
    None
}

/// Whether `config` sets a deploy hook although its file lies in one of its project folders or
/// roots, where planners write: the hook would run whatever they write into the file. The
/// sentence to refuse it with.
pub fn hook_from_a_planners_folder(config: &Config) -> Option<String> {
    let file = config.file.as_ref()?;
    let any_hook = config.on_success.is_some()
        || config.projects.iter().any(|p| p.on_success.is_some())
        || config.roots.iter().any(|r| r.on_success.is_some());
    if !any_hook {
        return None;
    }
    let real = canonical_or_literal(file);
    for (what, folder) in planners_folders(config) {
        if real.starts_with(canonical_or_literal(folder)) || file.starts_with(folder) {
            return Some(format!(
                "`on_success` in {}, which lies in the {what} {}: a deploy hook runs programs, \
                 and only the daemon's own configuration may say which, never a file planners \
                 can write; move the configuration out of the folder (say, to \
                 /etc/skillpost/skillpost.toml)",
                file.display(),
                folder.display()
            ));
        }
    }
    None
}

/// The folders planners write: every project folder and root of `config`, with what it is.
fn planners_folders(config: &Config) -> impl Iterator<Item = (&'static str, &PathBuf)> {
    config
        .projects
        .iter()
        .map(|p| ("project folder", &p.path))
        .chain(config.roots.iter().map(|r| ("root", &r.path)))
}

/// Every deploy hook's program of `config`, each once, sorted.
pub fn hook_programs(config: &Config) -> Vec<&str> {
    let mut programs: Vec<&str> = config
        .on_success
        .iter()
        .chain(config.projects.iter().filter_map(|p| p.on_success.as_ref()))
        .chain(config.roots.iter().filter_map(|r| r.on_success.as_ref()))
        .map(|h| h.argv[0].as_str())
        .collect();
    programs.sort();
    programs.dedup();
    programs
}

/// Whether the hook's `program` (as the configuration resolved it: absolute, or a bare name not
/// found) lies in a project folder or root of `config`, by its name or through a link: planners
/// write there, so they would choose what the daemon runs. The sentence to refuse it with.
pub fn hook_program_problem(config: &Config, program: &str) -> Option<String> {
    let given = Path::new(program);
    if !given.is_absolute() {
        return None;
    }
    let real = canonical_or_literal(given);
    for (what, folder) in planners_folders(config) {
        if real.starts_with(canonical_or_literal(folder)) || given.starts_with(folder) {
            return Some(format!(
                "the deploy hook's program {program} lies in the {what} {}: planners write \
                 there, so they would choose what the daemon runs; install it outside every \
                 project folder and root (say, /usr/local/bin) and name that path",
                folder.display()
            ));
        }
    }
    None
}
