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

/// A `[[root]]`: its watched subfolders, or the ancestor watched while it does not exist.
#[derive(Debug, Default)]
pub(super) struct Root {
    pub(super) subs: BTreeSet<PathBuf>,
    /// While the root does not exist: its nearest existing ancestor, watched to see it come.
    pub(super) anchor: Option<PathBuf>,
    /// The root directory's (device, inode) while it is watched: a root deleted and created
    /// again (a new inode; the kernel ended the old watch) is watched anew.
    pub(super) id: Option<(u64, u64)>,
    /// Subfolders whose lock another daemon holds (reported once).
    pub(super) locked_out: BTreeSet<PathBuf>,
    /// The (device, inode) of a root that exists but could not be watched (reported once; tried
    /// again when it is another folder).
    pub(super) failed: Option<(u64, u64)>,
    /// Another program (not a skillpost daemon) holds a lock on the root: not watched until
    /// it lets go (said once; tried again with the missing folders' check).
    pub(super) held_elsewhere: bool,
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
    /// Retries in a row of compiles that ran short of descriptors or memory.
    pub(super) starved: u32,
    /// Consecutive compiles whose write-back found the blackboard open elsewhere.
    pub(super) in_use_rounds: u32,
    pub(super) missing: bool,
    /// Since when the folder is known to be missing (set by the periodic check).
    pub(super) missing_since: Option<Instant>,
    /// The canonical blackboard of the compile started last: no other project may compile it.
    pub(super) claim: Option<PathBuf>,
    /// Not compiled because another project compiles the same blackboard.
    pub(super) refused: bool,
    /// Compile without the hash check (startup, rescan of a new project, retry).
    pub(super) force: bool,
    /// Stale temporaries of ours are still to be removed from the folder (after the first
    /// compile, which tells which files the project reads).
    pub(super) sweep: bool,
    /// The folder appeared, but another daemon keeps it: waited for like a missing folder
    /// (said once, with `watch-degraded`).
    pub(super) foreign: bool,
    /// The programs to deploy, each from the last successful compile that wrote it new bytes:
    /// handed to the hook once the inputs have been quiet for the whole quiet period
    /// ([`Scheduler::quiet_at`]) and the last compile succeeded (docs/DAEMON.md, "Deploying").
    pub(super) held: Vec<super::deploy::Context>,
    /// The `run_id` of the newest compile among `held`.
    pub(super) held_run: u64,
    /// The last compile succeeded (or found nothing changed after one that did).
    pub(super) last_ok: bool,
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
            for dir in config::discover(&root.path) {
                wanted
                    .entry(dir.clone())
                    .or_insert((root.project(dir), Origin::Root(root.path.clone())));
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
            if !config.roots.iter().any(|c| c.path == r) {
                self.unwatch_root(&r);
            }
        }
        for r in self.roots.values_mut() {
            r.locked_out.clear();
        }
        for r in &config.roots {
            if !self.roots.contains_key(&r.path) {
                self.watch_root(&r.path);
            }
        }
        // Once more now that the roots and their subfolders are watched: a blackboard written
        // into a subfolder after the first look but before its watch existed gives no event
        // (seen at startup with folders created while the daemon started: never compiled).
        for root in &config.roots {
            for dir in config::discover(&root.path) {
                wanted
                    .entry(dir.clone())
                    .or_insert((root.project(dir), Origin::Root(root.path.clone())));
            }
        }
        let mut added = Vec::new();
        for (k, (spec, origin)) in wanted {
            match self.projects.get_mut(&k) {
                Some(p) => {
                    if p.spec != spec {
                        p.spec = spec;
                        p.force = true;
                        // The first reason of a burst counts: a pending retry stays a retry.
                        p.trigger.get_or_insert("reload");
                        p.sched.immediately(now);
                    }
                    p.sched.set_timing(settle, max_wait_of(settle));
                }
                None => {
                    if self.add_project(spec, origin, settle) {
                        added.push(k);
                    }
                }
            }
        }
        self.config = config;
        (added, removed)
    }

    /// Starts keeping a root: locked, watched (or its nearest existing ancestor while it does
    /// not exist).
    pub(super) fn watch_root(&mut self, root: &Path) {
        let refused = |why: String| Event::WatchDegraded {
            root: Some(root.display().to_string()),
            reason: why,
            backend: Some("none"),
        };
        if let Err(why) = self.locks.acquire(root) {
            self.sink.emit(None, refused(why));
            return;
        }
        self.roots.insert(root.to_owned(), Root::default());
        if let Err(why) = self.locks.ensure(root) {
            self.sink.emit(None, refused(why));
            self.roots.get_mut(root).expect("root").held_elsewhere = true;
            return;
        }
        // A root that exists is watched now: `watching` says so (docs/DAEMON.md, "Watching"); a
        // missing one got `watch-degraded` and says `watching` when it appears.
        if self.attach_root(root, None) {
            self.root_watching(root, None);
        }
    }

    /// `watching` for a root (with why it is watched again, when it is).
    fn root_watching(&mut self, root: &Path, reason: Option<&str>) {
        let backend = self.watchers.backend_of(root).unwrap_or(Backend::Native);
        self.sink.emit(
            None,
            Event::Watching {
                root: Some(root.display().to_string()),
                blackboard: None,
                backend: backend.as_str(),
                reason: reason.map(str::to_owned),
                program: None,
            },
        );
    }

    /// Watches a root and its subfolders; when it does not exist, its nearest existing ancestor
    /// instead, with a `watch-degraded` event (`why` says what happened to it). Returns whether
    /// the root itself is watched.
    fn attach_root(&mut self, root: &Path, why: Option<&str>) -> bool {
        let poll = self.force_poll;
        match self.watchers.add_renewed(root, poll) {
            Ok(_) => {
                let mut subs = BTreeSet::new();
                for e in std::fs::read_dir(root).into_iter().flatten().flatten() {
                    let p = e.path();
                    if p.is_dir() && self.watchers.add_renewed(&p, poll).is_ok() {
                        subs.insert(p);
                    }
                }
                let r = self.roots.get_mut(root).expect("root");
                r.subs = subs;
                r.anchor = None;
                r.id = dir_id(root);
                r.failed = None;
                true
            }
            Err(WatchFailure::Missing) => {
                let anchor = nearest_existing_ancestor(root);
                if let Some(a) = &anchor {
                    let _ = self.watchers.add(a, poll);
                }
                self.sink.emit(
                    None,
                    Event::WatchDegraded {
                        root: Some(root.display().to_string()),
                        reason: format!(
                            "{}; watching {} for it",
                            why.unwrap_or("the root does not exist"),
                            anchor
                                .as_deref()
                                .map_or("nothing".into(), |a| a.display().to_string())
                        ),
                        backend: Some("none"),
                    },
                );
                let r = self.roots.get_mut(root).expect("root");
                r.anchor = anchor;
                r.id = None;
                false
            }
            Err(e) => {
                self.sink.emit(
                    None,
                    Event::WatchDegraded {
                        root: Some(root.display().to_string()),
                        reason: failure_text(&e),
                        backend: Some("none"),
                    },
                );
                let r = self.roots.get_mut(root).expect("root");
                r.anchor = None;
                r.id = None;
                r.failed = dir_id(root);
                false
            }
        }
    }

    /// Ends a root's watches (its subfolders, itself or the ancestor watched for it).
    fn detach_root(&mut self, root: &Path) {
        let Some(r) = self.roots.get_mut(root) else {
            return;
        };
        let subs = std::mem::take(&mut r.subs);
        let anchor = r.anchor.take();
        let watched = r.id.take().is_some();
        for s in subs {
            self.watchers.remove(&s);
        }
        if watched {
            self.watchers.remove(root);
        }
        if let Some(a) = anchor {
            self.watchers.remove(&a);
        }
    }

    pub(super) fn unwatch_root(&mut self, root: &Path) {
        self.detach_root(root);
        self.roots.remove(root);
        self.locks.release(root);
    }

    /// Checks whether a root went, came, or was replaced, and follows it: a root that went is
    /// waited for from its nearest existing ancestor; one that came (or came back, or was
    /// replaced) is watched again and its projects found.
    pub(super) fn check_root(&mut self, root: &Path, now: Instant) {
        let Some(r) = self.roots.get(root) else {
            return;
        };
        if r.held_elsewhere {
            // Another program's lock: watched once it is let go (or the root is gone).
            if self.locks.ensure(root).is_err() {
                return;
            }
            self.roots.get_mut(root).expect("root").held_elsewhere = false;
            if self.attach_root(root, None) {
                self.root_back(root, false, now);
            }
            return;
        }
        let current = dir_id(root);
        match (r.id, current) {
            (Some(a), Some(b)) if a == b => {}
            (None, Some(b)) if r.failed == Some(b) => {}
            (None, None) => {
                // Still missing: follow the nearest existing ancestor deeper (or higher).
                let anchor = nearest_existing_ancestor(root);
                if anchor != r.anchor && r.anchor.is_some() {
                    let old = self.roots.get_mut(root).expect("root").anchor.take();
                    if let Some(old) = old {
                        self.watchers.remove(&old);
                    }
                    if let Some(a) = &anchor {
                        let _ = self.watchers.add(a, self.force_poll);
                    }
                    self.roots.get_mut(root).expect("root").anchor = anchor;
                } else if r.anchor.is_none() {
                    self.attach_root(root, None);
                }
            }
            (Some(_), None) => {
                self.detach_root(root);
                // Between its removal and here another folder may have taken its name (a root
                // replaced by two renames, looked at in between): then it is watched again.
                if self.attach_root(root, Some("the root was removed")) {
                    self.root_back(root, true, now);
                }
            }
            (_, Some(_)) => {
                let replaced = r.id.is_some();
                self.detach_root(root);
                if self.attach_root(root, None) {
                    self.root_back(root, replaced, now);
                }
            }
        }
    }

    /// A root watched again (it appeared, or another folder took its name): `watching`, and its
    /// projects.
    fn root_back(&mut self, root: &Path, replaced: bool, now: Instant) {
        let reason = if replaced {
            "the root was replaced"
        } else {
            "the root exists now"
        };
        self.root_watching(root, Some(reason));
        self.discover_in(root, now);
        self.look_for_missing_folders(now);
    }

    /// The spec of the project in the subfolder `dir` of `root`, with the root's settings.
    pub(super) fn root_project(&self, root: &Path, dir: PathBuf) -> ProjectSpec {
        match self.config.roots.iter().find(|r| r.path == root) {
            Some(r) => r.project(dir),
            None => ProjectSpec {
                path: dir,
                ..ProjectSpec::default()
            },
        }
    }

    /// Adds the projects of a root that the table does not have yet.
    fn discover_in(&mut self, root: &Path, now: Instant) {
        let settle = settle_of(&self.config);
        for dir in config::discover(root) {
            if self.projects.contains_key(&dir)
                || self
                    .roots
                    .get(root)
                    .is_some_and(|r| r.locked_out.contains(&dir))
            {
                continue;
            }
            let spec = self.root_project(root, dir.clone());
            if self.add_project(spec, Origin::Root(root.to_owned()), settle)
                && let Some(p) = self.projects.get_mut(&dir)
            {
                p.trigger = Some("new-project");
                p.sched.change(now);
            }
        }
    }

    /// Forgets the projects of roots whose folder has been gone for longer than
    /// `forget_after_s` (explicit projects are kept: the configuration names them), so folders
    /// that come and go do not pile up. Also notices project folders gone without an event.
    pub(super) fn forget_gone(&mut self, now: Instant) {
        let gone: Vec<PathBuf> = self
            .projects
            .iter()
            .filter(|(k, p)| !p.missing && !k.is_dir())
            .map(|(k, _)| k.clone())
            .collect();
        for k in gone {
            self.folder_event(&k, now);
        }
        let after = self.config.forget_after();
        let mut forget = Vec::new();
        for (k, p) in self.projects.iter_mut() {
            if !p.missing {
                p.missing_since = None;
                continue;
            }
            let since = *p.missing_since.get_or_insert(now);
            if matches!(p.origin, Origin::Root(_)) && now.duration_since(since) >= after {
                forget.push(k.clone());
            }
        }
        for k in forget {
            self.drop_project(&k);
            // A new project if it comes back: its run_ids start again at 1.
            self.run_ids.remove(&k);
            self.degraded(
                &k,
                format!(
                    "the project folder has been gone for {} s: the project is forgotten \
                         (found again if it comes back)",
                    after.as_secs()
                ),
            );
        }
    }

    /// Whether the project may compile its blackboard now: no other project compiles the same
    /// file (by canonical path; a link or an alias folder). Two projects writing their own
    /// outputs' paths into one blackboard would rewrite it back and forth for ever, so the one
    /// that claimed it first keeps it and the other is refused with `compile-failed` (`E701`)
    /// naming both, until the first is gone or the blackboards differ.
    pub(super) fn claim_blackboard(&mut self, key: &Path, now: Instant) -> bool {
        let Some(p) = self.projects.get(key) else {
            return false;
        };
        let real = config::resolve(&p.spec)
            .ok()
            .and_then(|(b, _)| std::fs::canonicalize(b).ok());
        let owner = real.as_ref().and_then(|r| {
            self.projects
                .iter()
                .find(|(k, q)| k.as_path() != key && !q.missing && q.claim.as_ref() == Some(r))
                .map(|(k, _)| k.clone())
        });
        let Some(owner) = owner else {
            let p = self.projects.get_mut(key).expect("project");
            p.claim = real;
            p.refused = false;
            return true;
        };
        let mut p = self.projects.remove(key).expect("project");
        let trigger = p.trigger.take().unwrap_or("change");
        let changed: Vec<String> = std::mem::take(&mut p.changed)
            .iter()
            .map(|c| c.display().to_string())
            .collect();
        p.claim = None;
        p.refused = true;
        p.sched.finished(now);
        p.force = true;
        // Nothing of the other project's files concerns this one until it may compile again.
        p.inputs.clear();
        p.outputs.clear();
        let mut dirs = BTreeSet::new();
        dirs.insert(key.to_owned());
        if let Some(parent) = key.parent() {
            dirs.insert(parent.to_owned());
        }
        self.set_watches(&mut p, dirs);
        self.reindex(&mut p);
        self.projects.insert(key.to_owned(), p);
        // A run like any other: `compile-started`, then its outcome.
        let run_id = super::next_run_id(&mut self.run_ids, key);
        self.sink.emit(
            Some(&Self::key_str(key)),
            Event::CompileStarted {
                run_id,
                trigger,
                changed,
            },
        );
        self.sink.emit(
            Some(&Self::key_str(key)),
            Event::failed_with(
                run_id,
                0,
                SHARED_BLACKBOARD,
                format!(
                    "the blackboard {} is also the blackboard of the project {}: two projects \
                     writing back into one blackboard would rewrite it back and forth, so this \
                     project is not compiled; give each project its own blackboard",
                    real.as_deref().unwrap_or(key).display(),
                    owner.display()
                ),
            ),
        );
        false
    }

    /// Adds a project to the table and watches it. `false`: another daemon keeps its folder
    /// (reported with `watch-degraded`); nothing of it is touched.
    pub(super) fn add_project(
        &mut self,
        spec: ProjectSpec,
        origin: Origin,
        settle: Duration,
    ) -> bool {
        let key = spec.path.clone();
        // A name that is not UTF-8 cannot be carried exactly by a hook's arguments, the events or
        // the state file (`A\xFF` and `A\u{FFFD}` would be one project there): refused, once
        // (until a reload), the event naming it with its bytes escaped.
        if key.to_str().is_none() {
            if let Origin::Root(r) = &origin
                && let Some(root) = self.roots.get_mut(r)
            {
                root.locked_out.insert(key.clone());
            }
            self.sink.emit(
                None,
                Event::WatchDegraded {
                    root: match &origin {
                        Origin::Root(r) => Some(r.display().to_string()),
                        Origin::Explicit => None,
                    },
                    reason: format!(
                        "the project folder {} is not watched: its name is not UTF-8, and a \
                         deploy hook's arguments, the events and the state file could not name \
                         it exactly; rename it",
                        crate::paths::escaped(&key)
                    ),
                    backend: Some("none"),
                },
            );
            return false;
        }
        if let Err(why) = self.locks.acquire(&key) {
            if let Origin::Root(r) = &origin
                && let Some(root) = self.roots.get_mut(r)
            {
                root.locked_out.insert(key.clone());
            }
            self.degraded(&key, why);
            return false;
        }
        // Stale temporaries are removed after the first compile (`sweep`), when the project's
        // inputs are known: a file the project reads is never removed, whatever its name.
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
            starved: 0,
            in_use_rounds: 0,
            held: Vec::new(),
            held_run: 0,
            last_ok: false,
            missing: false,
            missing_since: None,
            claim: None,
            refused: false,
            force: true,
            sweep: true,
            foreign: false,
        };
        let mut dirs = BTreeSet::new();
        dirs.insert(key.clone());
        if let Some(parent) = key.parent() {
            dirs.insert(parent.to_owned());
        }
        self.set_watches(&mut p, dirs);
        // Only a folder really watched is `watching`; a missing one was reported
        // (`watch-degraded`) and says `watching` when it is back.
        if p.watched.contains(&key) {
            let resolved = config::resolve_project(&p.spec).ok();
            if let Some((b, program)) = &resolved
                && let Some(from) = &program.derived_from
            {
                tracing::warn!(
                    "{}: `{from}` ({}) is not a KRL name: the program is called `{}`",
                    key.display(),
                    b.display(),
                    program.name
                );
            }
            self.sink.emit(
                Some(&Self::key_str(&key)),
                Event::Watching {
                    root: match &p.origin {
                        Origin::Root(r) => Some(r.display().to_string()),
                        Origin::Explicit => None,
                    },
                    blackboard: resolved.as_ref().map(|(b, _)| b.display().to_string()),
                    backend: p.backend.as_str(),
                    reason: None,
                    program: resolved.map(|(_, program)| program.name),
                },
            );
        }
        self.reindex(&mut p);
        self.projects.insert(key, p);
        true
    }

    /// Locks a project folder that has appeared (one that did not exist was kept without a
    /// lock); `false` when another daemon keeps it: the project then waits as for a missing
    /// folder, reported once, and tries again with the missing folders' check.
    pub(super) fn claim_folder(&mut self, p: &mut Project) -> bool {
        let key = p.spec.path.clone();
        match self.locks.ensure(&key) {
            Ok(true) => {
                p.foreign = false;
                true
            }
            // Not there at the lock: it is not ours yet, whatever appears a moment later (the
            // folder's event, or the missing folders' check, claims it then).
            Ok(false) => {
                if !p.missing {
                    p.missing = true;
                    self.degraded(&key, missing_reason(&key));
                }
                false
            }
            Err(why) => {
                p.missing = true;
                if !p.foreign {
                    p.foreign = true;
                    self.degraded(&key, why);
                }
                false
            }
        }
    }

    /// `watch-degraded` for a project that is not watched now (`backend` `none`), with why.
    pub(super) fn degraded(&self, key: &Path, reason: String) {
        self.sink.emit(
            Some(&Self::key_str(key)),
            Event::WatchDegraded {
                root: None,
                reason,
                backend: Some("none"),
            },
        );
    }

    pub(super) fn drop_project(&mut self, key: &Path) {
        if let Some(p) = self.projects.remove(key) {
            self.locks.release(key);
            if p.claim.is_some() {
                // Its blackboard is free: a project refused for it may compile now.
                let now = Instant::now();
                for q in self.projects.values_mut().filter(|q| q.refused) {
                    q.refused = false;
                    q.force = true;
                    q.trigger.get_or_insert("blackboard-released");
                    q.sched.change(now);
                }
            }
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
    pub(super) fn set_watches(&mut self, p: &mut Project, mut dirs: BTreeSet<PathBuf>) {
        let key = p.spec.path.clone();
        let poll = self.force_poll;
        if dirs.contains(&key) && !p.watched.contains(&key) && !self.claim_folder(p) {
            dirs.remove(&key);
        }
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
                        self.degraded(&key, missing_reason(&key));
                    }
                }
                Err(WatchFailure::Missing) => {}
                Err(WatchFailure::Other(e)) if d == &key => {
                    tracing::warn!("cannot watch {}: {e}", d.display());
                    self.degraded(&key, format!("the project folder cannot be watched: {e}"));
                }
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
/// `kill -9` between writing and renaming). Called after the project's first compile, with the
/// files it read (`inputs`): a file is removed only when it is a regular file with one name,
/// named exactly as our temporaries are (`.skillpost-` + six letters or digits + `.tmp`, see
/// [`crate::write::is_temporary`]), and not one of the project's inputs (a planner may name a
/// file anything: the command line compiles `.skillpost-plan.tmp` as it compiles any SFC).
pub(super) fn remove_stale_temporaries(folder: &Path, inputs: &HashMap<PathBuf, Option<u64>>) {
    use std::os::unix::fs::MetadataExt as _;
    for e in std::fs::read_dir(folder).into_iter().flatten().flatten() {
        let name = e.file_name();
        let Some(name) = name.to_str() else { continue };
        if !crate::write::is_temporary(name) {
            continue;
        }
        let path = e.path();
        let real = std::fs::canonicalize(&path).unwrap_or_else(|_| path.clone());
        let single = std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_file() && m.nlink() == 1);
        // The inputs hold every file as read and, for one read through a link, the file the
        // link resolves to (`job::add_link_targets`): the path or its real one names an input.
        if !single || inputs.contains_key(&real) || inputs.contains_key(&path) {
            continue;
        }
        match std::fs::remove_file(&path) {
            Ok(()) => tracing::info!("removed a stale temporary file {}", path.display()),
            Err(err) => tracing::warn!("cannot remove {}: {err}", path.display()),
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

/// The code of `compile-failed` for a project refused because another project compiles the same
/// blackboard (a daemon-only code: the command line compiles one project).
pub(super) const SHARED_BLACKBOARD: &str = "E701";

/// A directory's (device, inode), `None` if it is not a directory.
pub(super) fn dir_id(dir: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(dir)
        .ok()
        .filter(|m| m.is_dir())
        .map(|m| (m.dev(), m.ino()))
}

/// The nearest ancestor of `path` that is an existing directory.
pub(super) fn nearest_existing_ancestor(path: &Path) -> Option<PathBuf> {
    path.ancestors()
        .skip(1)
        .find(|a| a.is_dir())
        .map(Path::to_owned)
}

pub(super) fn failure_text(e: &WatchFailure) -> String {
    match e {
        WatchFailure::Missing => "missing".to_owned(),
        WatchFailure::Other(s) => s.clone(),
    }
}

/// Why a project folder is not watched: it does not exist (yet), or its path cannot be used.
fn missing_reason(key: &Path) -> String {
    match config::too_long(key) {
        Err(why) => format!("the project folder cannot be used: {why}"),
        Ok(()) => "the project folder does not exist; waiting for it".into(),
    }
}
