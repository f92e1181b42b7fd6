//! The project table: which projects the daemon keeps, where each one's files are, which
//! directories are watched for it, and the index from directory to projects that routes file
//! events without scanning every project.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::time::Duration;

use tokio::time::Instant;

use super::config::{self, Config, ProjectSpec};
use super::events::Event;
use super::settle::Scheduler;
use super::watch::{Backend, WatchFailure};
use super::{Daemon, max_wait_of, settle_of};

/// Where a project came from.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Origin {
    Explicit,
    Root(PathBuf),
}

pub(super) struct Project {
    pub(super) spec: ProjectSpec,
    pub(super) origin: Origin,
    /// Every file the last compile read, with the hash of the bytes it read (`None`: unreadable).
    pub(super) inputs: HashMap<PathBuf, Option<u64>>,
    /// The outputs of the last compile (never inputs).
    pub(super) outputs: BTreeSet<PathBuf>,
    /// The directories watched for this project.
    pub(super) watched: BTreeSet<PathBuf>,
    /// The directories whose events can concern this project (its folder and its inputs'
    /// folders): its entries in [`Daemon::by_dir`].
    pub(super) indexed: BTreeSet<PathBuf>,
    pub(super) backend: Backend,
    pub(super) sched: Scheduler,
    /// Paths changed since the last compile started.
    pub(super) changed: BTreeSet<PathBuf>,
    /// Files being written (modified, not yet closed), with when that was first seen.
    pub(super) writing: HashMap<PathBuf, Instant>,
    /// Why the next compile runs: the first reason of the burst counts.
    pub(super) trigger: Option<&'static str>,
    pub(super) retries: u32,
    pub(super) missing: bool,
    /// Compile without the hash check (startup, rescan of a new project, retry).
    pub(super) force: bool,
}

impl Daemon {
    pub(super) fn key_str(key: &Path) -> String {
        key.display().to_string()
    }

    /// Takes a (new) configuration: adds the projects it names, drops those it no longer does.
    pub(super) fn apply_config(
        &mut self,
        config: Config,
        now: Instant,
    ) -> (Vec<PathBuf>, Vec<PathBuf>) {
        let settle = settle_of(&config);
        let mut wanted: BTreeMap<PathBuf, (ProjectSpec, Origin)> = BTreeMap::new();
        for p in &config.projects {
            wanted.insert(p.path.clone(), (p.clone(), Origin::Explicit));
        }
        for root in &config.roots {
            for dir in config::discover(root) {
                wanted.entry(dir.clone()).or_insert((
                    ProjectSpec {
                        path: dir,
                        blackboard: None,
                        program: None,
                    },
                    Origin::Root(root.clone()),
                ));
            }
        }
        let removed: Vec<PathBuf> = self
            .projects
            .keys()
            .filter(|k| !wanted.contains_key(*k))
            .cloned()
            .collect();
        for k in &removed {
            self.drop_project(k);
        }
        // Roots: watch each and its subfolders (a blackboard may appear in any of them).
        let old_roots: Vec<PathBuf> = self.roots.keys().cloned().collect();
        for r in old_roots {
            if !config.roots.contains(&r) {
                self.unwatch_root(&r);
            }
        }
        for r in &config.roots {
            if !self.roots.contains_key(r) {
                self.watch_root(r);
            }
        }
        let mut added = Vec::new();
        for (k, (spec, origin)) in wanted {
            match self.projects.get_mut(&k) {
                Some(p) => {
                    if p.spec != spec {
                        p.spec = spec;
                        p.force = true;
                        p.sched.immediately(now);
                    }
                    p.sched.set_timing(settle, max_wait_of(settle));
                }
                None => {
                    self.add_project(spec, origin, settle);
                    added.push(k);
                }
            }
        }
        self.config = config;
        (added, removed)
    }

    pub(super) fn watch_root(&mut self, root: &Path) {
        let mut subs = BTreeSet::new();
        match self.watchers.add(root, self.force_poll) {
            Ok(_) => {
                for e in std::fs::read_dir(root).into_iter().flatten().flatten() {
                    let p = e.path();
                    if p.is_dir() && self.watchers.add(&p, self.force_poll).is_ok() {
                        subs.insert(p);
                    }
                }
            }
            Err(e) => self.sink.emit(
                None,
                Event::WatchDegraded {
                    root: Some(root.display().to_string()),
                    reason: failure_text(&e),
                    backend: None,
                },
            ),
        }
        self.roots.insert(root.to_owned(), subs);
    }

    pub(super) fn unwatch_root(&mut self, root: &Path) {
        if let Some(subs) = self.roots.remove(root) {
            for s in subs {
                self.watchers.remove(&s);
            }
            self.watchers.remove(root);
        }
    }

    pub(super) fn add_project(&mut self, spec: ProjectSpec, origin: Origin, settle: Duration) {
        let key = spec.path.clone();
        remove_stale_temporaries(&key);
        let mut p = Project {
            spec,
            origin,
            inputs: HashMap::new(),
            outputs: BTreeSet::new(),
            watched: BTreeSet::new(),
            indexed: BTreeSet::new(),
            backend: Backend::Native,
            sched: Scheduler::new(settle, max_wait_of(settle)),
            changed: BTreeSet::new(),
            writing: HashMap::new(),
            trigger: Some("startup"),
            retries: 0,
            missing: false,
            force: true,
        };
        let mut dirs = BTreeSet::new();
        dirs.insert(key.clone());
        if let Some(parent) = key.parent() {
            dirs.insert(parent.to_owned());
        }
        self.set_watches(&mut p, dirs);
        let blackboard = config::resolve(&p.spec).ok().map(|(b, _)| b);
        self.sink.emit(
            Some(&Self::key_str(&key)),
            Event::Watching {
                root: match &p.origin {
                    Origin::Root(r) => Some(r.display().to_string()),
                    Origin::Explicit => None,
                },
                blackboard: blackboard.map(|b| b.display().to_string()),
                backend: p.backend.as_str(),
                reason: None,
            },
        );
        self.reindex(&mut p);
        self.projects.insert(key, p);
    }

    pub(super) fn drop_project(&mut self, key: &Path) {
        if let Some(p) = self.projects.remove(key) {
            for d in &p.watched {
                self.watchers.remove(d);
            }
            for d in &p.indexed {
                if let Some(set) = self.by_dir.get_mut(d) {
                    set.remove(key);
                    if set.is_empty() {
                        self.by_dir.remove(d);
                    }
                }
            }
            self.queue.retain(|k| k != key);
        }
    }

    /// Changes a project's watched directories to `dirs` (adding before removing, so a shared
    /// directory is never unwatched in between).
    pub(super) fn set_watches(&mut self, p: &mut Project, dirs: BTreeSet<PathBuf>) {
        let key = p.spec.path.clone();
        let poll = self.force_poll;
        for d in dirs.difference(&p.watched.clone()) {
            match self.watchers.add(d, poll) {
                Ok((backend, why)) => {
                    p.watched.insert(d.clone());
                    if d == &key {
                        p.missing = false;
                        if backend != p.backend || why.is_some() {
                            p.backend = backend;
                            if let Some(why) = why {
                                self.sink.emit(
                                    Some(&Self::key_str(&key)),
                                    Event::WatchDegraded {
                                        root: None,
                                        reason: why.to_string(),
                                        backend: Some(backend.as_str()),
                                    },
                                );
                            }
                        }
                    }
                }
                Err(WatchFailure::Missing) if d == &key => {
                    if !p.missing {
                        p.missing = true;
                        self.sink.emit(
                            Some(&Self::key_str(&key)),
                            Event::WatchDegraded {
                                root: None,
                                reason: "the project folder does not exist; waiting for it".into(),
                                backend: Some("none"),
                            },
                        );
                    }
                }
                Err(WatchFailure::Missing) => {}
                Err(WatchFailure::Other(e)) => {
                    tracing::warn!("cannot watch {}: {e}", d.display());
                }
            }
        }
        for d in p.watched.clone().difference(&dirs) {
            self.watchers.remove(d);
            p.watched.remove(d);
        }
    }

    /// Updates [`Daemon::by_dir`] for a project: its folder and the folders of its inputs.
    pub(super) fn reindex(&mut self, p: &mut Project) {
        let key = p.spec.path.clone();
        let mut dirs: BTreeSet<PathBuf> = p
            .inputs
            .keys()
            .filter_map(|f| f.parent().map(Path::to_owned))
            .collect();
        dirs.insert(key.clone());
        for d in p.indexed.difference(&dirs) {
            if let Some(set) = self.by_dir.get_mut(d) {
                set.remove(&key);
                if set.is_empty() {
                    self.by_dir.remove(d);
                }
            }
        }
        for d in dirs.difference(&p.indexed) {
            self.by_dir
                .entry(d.clone())
                .or_default()
                .insert(key.clone());
        }
        p.indexed = dirs;
    }
}

/// Removes the temporary files an interrupted run of ours left in a project folder (a crash or
/// `kill -9` between writing and renaming). Only `.skillpost-*.tmp` files are touched; they are
/// never anything but ours, and the daemon writes none while it sets a project up.
pub(super) fn remove_stale_temporaries(folder: &Path) {
    for e in std::fs::read_dir(folder).into_iter().flatten().flatten() {
        let name = e.file_name();
        let Some(name) = name.to_str() else { continue };
        if name.starts_with(".skillpost-")
            && name.ends_with(".tmp")
            && e.file_type().is_ok_and(|t| t.is_file())
        {
            match std::fs::remove_file(e.path()) {
                Ok(()) => tracing::info!("removed a stale temporary file {}", e.path().display()),
                Err(err) => tracing::warn!("cannot remove {}: {err}", e.path().display()),
            }
        }
    }
}

/// Whether a folder holds a blackboard (what makes a root's subfolder a project).
pub(super) fn holds_blackboard(folder: &Path) -> bool {
    std::fs::read_dir(folder)
        .into_iter()
        .flatten()
        .flatten()
        .any(|e| config::is_blackboard_name(&e.file_name()) && e.path().is_file())
}

pub(super) fn failure_text(e: &WatchFailure) -> String {
    match e {
        WatchFailure::Missing => "missing".to_owned(),
        WatchFailure::Other(s) => s.clone(),
    }
}
