//! Routing of file events: which project an event concerns, whether it can have changed an
//! input, new projects in roots, and project folders that come and go.

use std::path::{Path, PathBuf};

use tokio::time::Instant;

use super::config;
use super::events::Event;
use super::project::{Origin, Project, holds_blackboard};
use super::watch::{self, Backend, WatchMsg};
use super::{Daemon, settle_of};

impl Daemon {
    pub(super) fn on_watch(&mut self, msg: WatchMsg, now: Instant) {
        match msg {
            WatchMsg::Error(e) => {
                tracing::warn!("watcher error: {e}");
                self.rescan("watcher-error", Some(e.to_string()), now);
            }
            WatchMsg::Event(mut e) => {
                if e.need_rescan() {
                    self.rescan("overflow", None, now);
                    return;
                }
                // Watches are on canonical folders: give the paths under every name asked for.
                if e.paths.len() == 1 {
                    e.paths = self.watchers.expand(&e.paths[0]);
                } else {
                    e.paths = e
                        .paths
                        .iter()
                        .flat_map(|p| self.watchers.expand(p))
                        .collect();
                }
                self.route(&e, now);
            }
        }
    }

    /// Every project checks its inputs again (a compile only where bytes changed).
    pub(super) fn rescan(&mut self, reason: &str, error: Option<String>, now: Instant) {
        self.sink.emit(
            None,
            Event::Rescan {
                reason: reason.into(),
                projects: None,
                error,
            },
        );
        for p in self.projects.values_mut() {
            p.trigger.get_or_insert("rescan");
            p.sched.change(now);
        }
    }

    pub(super) fn route(&mut self, e: &notify::Event, now: Instant) {
        use notify::EventKind as K;
        use notify::event::{AccessKind, AccessMode, MetadataKind, ModifyKind, RenameMode};
        let kind = e.kind;
        // inotify's rename gives `From` (old name), `To` (new name), then `Both` with the two:
        // each name was routed already, and `Both` must not undo what `To` said (complete).
        if matches!(kind, K::Modify(ModifyKind::Name(RenameMode::Both))) {
            return;
        }
        // Reads and metadata-only changes (`touch`, chmod) never change bytes.
        let closed_write = matches!(kind, K::Access(AccessKind::Close(AccessMode::Write)));
        if matches!(kind, K::Access(_)) && !closed_write {
            return;
        }
        // Polling reports a new write time (the content hash then tells a `touch` from an edit);
        // other metadata (attributes, permissions; inotify's `touch`) never change bytes, but
        // may make a file the last compile could not read readable again.
        if matches!(kind, K::Modify(ModifyKind::Metadata(m)) if m != MetadataKind::WriteTime) {
            self.route_readable(&e.paths, now);
            return;
        }
        let data_write = matches!(
            kind,
            K::Modify(ModifyKind::Data(_)) | K::Modify(ModifyKind::Any)
        );
        // The writer is done with the file: it closed it after writing, or renamed it into
        // place (an atomic save). Only the native watch says so; polling never does.
        let complete = closed_write || matches!(kind, K::Modify(ModifyKind::Name(RenameMode::To)));
        // Only these say that a project folder itself came or went.
        let structural = matches!(
            kind,
            K::Create(_) | K::Remove(_) | K::Modify(ModifyKind::Name(_)) | K::Any | K::Other
        );
        for path in &e.paths {
            // Editor noise (`x.xml~`, `4913`, `*.swp`, `*.tmp`) starts nothing, unless it is an
            // input: a file is tracked by what the last compile read, whatever its name.
            let noise = watch::is_noise(path);
            if !noise {
                // A project folder known before this event came or went. One that
                // `route_roots` adds now was just watched: renewing its watch at once (as
                // `folder_event` does for a folder created again) would lose the events of the
                // files being written into it meanwhile.
                let known = structural && self.projects.contains_key(path);
                self.route_roots(path, now);
                if known {
                    self.folder_event(path, now);
                }
            }
            let Some(keys) = path.parent().and_then(|d| self.by_dir.get(d)) else {
                continue;
            };
            let keys: Vec<PathBuf> = keys.iter().cloned().collect();
            for k in keys {
                let Some(p) = self.projects.get_mut(&k) else {
                    continue;
                };
                if p.outputs.contains(path) {
                    continue;
                }
                let is_input = p.inputs.contains_key(path);
                let in_folder = !noise && path.parent() == Some(k.as_path());
                let new_blackboard =
                    in_folder && path.file_name().is_some_and(config::is_blackboard_name);
                if !(is_input || new_blackboard) {
                    // While a compile runs, its inputs are not known yet (a new project's first
                    // compile knows none): a file of the folder that it may be reading right
                    // now gets a follow-up, whose hash check costs nothing if that file was not
                    // one (nothing else is recorded: no trigger, no changed path, no open write).
                    // Dropping the event lost a file written during the compile for good.
                    if in_folder && p.sched.is_running() {
                        p.sched.change(now);
                    }
                    continue;
                }
                // Polling reports no closes: only native watches track open writes.
                if data_write && p.backend == Backend::Native {
                    p.writing.entry(path.clone()).or_insert(now);
                } else {
                    // Closed, created, removed or renamed: the write is complete.
                    p.writing.remove(path);
                }
                p.changed.insert(path.clone());
                p.trigger.get_or_insert("change");
                if complete && p.backend == Backend::Native && p.writing.is_empty() {
                    p.sched.completed(now);
                } else {
                    p.sched.change(now);
                }
            }
        }
    }

    /// A permission or owner change of `paths`: every project with an input the last compile
    /// could not read (hash `None`) at or below one of them, or whose folder it is, checks its
    /// inputs again (the hash check compiles only when a file's bytes differ now). Without this, a planner's edit
    /// whose compile failed with "permission denied" (a `chmod 000` of the file or the folder
    /// meanwhile) stayed uncompiled after the permission came back, until the next edit.
    fn route_readable(&mut self, paths: &[PathBuf], now: Instant) {
        // Only the projects a path can concern (never a scan of them all): a project folder
        // itself, a folder of inputs, or a file in one.
        let mut keys: std::collections::BTreeSet<PathBuf> = Default::default();
        for path in paths {
            if self.projects.contains_key(path) {
                keys.insert(path.clone());
            }
            for dir in [Some(path.as_path()), path.parent()].into_iter().flatten() {
                if let Some(ks) = self.by_dir.get(dir) {
                    keys.extend(ks.iter().cloned());
                }
            }
        }
        for k in keys {
            let Some(p) = self.projects.get_mut(&k) else {
                continue;
            };
            let unreadable = p.inputs.iter().find(|(input, hash)| {
                hash.is_none() && paths.iter().any(|changed| input.starts_with(changed))
            });
            // The folder itself: a compile that could not list it knows no inputs.
            let folder = paths.iter().any(|changed| p.spec.path.starts_with(changed));
            // The project folder's own permissions, group, ACL or times (`chmod -R g+rwX`,
            // `setfacl`, `touch` of the folder; never one of the daemon's writes): compiled
            // without the hash check. A compile whose outputs or write-back could not be
            // written (E604: a folder copied in with `cp -r` under umask 022) read every input
            // fine, so the hash check found nothing to do after the fix, until a content edit.
            if paths.contains(&p.spec.path) {
                p.force = true;
            }
            // A compile runs: what it could read is known only when it reports (its
            // `compile-failed` may be out already). A follow-up checks the inputs' hashes then;
            // it costs nothing when the compile read them all. Without it, a permission given
            // back in that window left the edit uncompiled until the next one.
            if p.sched.is_running() && paths.iter().any(|changed| !p.outputs.contains(changed)) {
                p.sched.change(now);
                continue;
            }
            if let Some((input, _)) = unreadable {
                let input = input.clone();
                p.changed.insert(input);
            } else if !folder {
                continue;
            }
            p.trigger.get_or_insert("change");
            p.sched.change(now);
        }
    }

    /// An event inside a root: a new subfolder, or a blackboard appearing in one.
    pub(super) fn route_roots(&mut self, path: &Path, now: Instant) {
        // A root itself, or a folder on the way to it, came or went.
        let concerned: Vec<PathBuf> = self
            .roots
            .keys()
            .filter(|r| r.starts_with(path))
            .cloned()
            .collect();
        for r in concerned {
            self.check_root(&r, now);
        }
        let Some(parent) = path.parent() else { return };
        let roots: Vec<PathBuf> = self
            .roots
            .iter()
            .filter(|(_, r)| r.id.is_some())
            .map(|(k, _)| k.clone())
            .collect();
        for root in roots {
            let folder = if parent == root {
                path.to_owned()
            } else if parent.parent() == Some(root.as_path()) {
                parent.to_owned()
            } else {
                continue;
            };
            if folder.is_dir() && !self.roots[&root].subs.contains(&folder) {
                if self.watchers.add(&folder, self.force_poll).is_ok() {
                    self.roots
                        .get_mut(&root)
                        .expect("root")
                        .subs
                        .insert(folder.clone());
                }
            } else if !folder.exists() {
                let r = self.roots.get_mut(&root).expect("root");
                r.locked_out.remove(&folder);
                if r.subs.remove(&folder) {
                    self.watchers.remove(&folder);
                }
            }
            if !self.projects.contains_key(&folder)
                && !self.roots[&root].locked_out.contains(&folder)
                && holds_blackboard(&folder)
            {
                let settle = settle_of(&self.config);
                let spec = self.root_project(&root, folder.clone());
                let added = self.add_project(spec, Origin::Root(root.clone()), settle);
                if added && let Some(p) = self.projects.get_mut(&folder) {
                    p.trigger = Some("new-project");
                    p.sched.change(now);
                }
            }
        }
    }

    /// The project folder itself was created, removed or renamed.
    pub(super) fn folder_event(&mut self, key: &Path, now: Instant) {
        let Some(mut p) = self.projects.remove(key) else {
            return;
        };
        if key.is_dir() && self.claim_folder(&mut p) {
            let was_missing = p.missing;
            match self.watchers.renew(key, self.force_poll) {
                Ok(b) => {
                    p.missing = false;
                    p.backend = b;
                    p.watched.insert(key.to_owned());
                }
                Err(_) => p.missing = true,
            }
            if was_missing && !p.missing {
                self.sink.emit(Some(&Self::key_str(key)), folder_back(&p));
            }
            p.trigger.get_or_insert("folder-created");
            p.force = true;
            p.sched.change(now);
        } else if !p.missing {
            p.missing = true;
            self.degraded(key, "the project folder was removed; waiting for it".into());
        }
        self.projects.insert(key.to_owned(), p);
    }

    /// The periodic check (every `MISSING_RETRY`): roots that went, came or were replaced
    /// without an event we saw, missing project folders that appeared, and projects of roots
    /// gone for longer than `forget_after_s`.
    pub(super) fn look_for_missing(&mut self, now: Instant) {
        let roots: Vec<PathBuf> = self.roots.keys().cloned().collect();
        for r in roots {
            self.check_root(&r, now);
        }
        self.look_for_missing_folders(now);
        self.forget_gone(now);
    }

    /// Missing project folders that appeared without an event we saw (their parent was missing
    /// too): watch and compile them.
    pub(super) fn look_for_missing_folders(&mut self, now: Instant) {
        let missing: Vec<PathBuf> = self
            .projects
            .iter()
            .filter(|(k, p)| p.missing && k.is_dir())
            .map(|(k, _)| k.clone())
            .collect();
        for k in missing {
            let Some(mut p) = self.projects.remove(&k) else {
                continue;
            };
            let mut dirs = p.watched.clone();
            dirs.insert(k.clone());
            if let Some(parent) = k.parent() {
                dirs.insert(parent.to_owned());
            }
            p.watched.remove(&k);
            self.set_watches(&mut p, dirs);
            if !p.missing {
                self.sink.emit(Some(&Self::key_str(&k)), folder_back(&p));
                p.trigger = Some("folder-created");
                p.force = true;
                p.sched.change(now);
            }
            self.projects.insert(k, p);
        }
    }
}

/// The `watching` event of a project folder that came back.
pub(super) fn folder_back(p: &Project) -> Event {
    let resolved = config::resolve(&p.spec).ok();
    Event::Watching {
        root: None,
        blackboard: resolved.as_ref().map(|(b, _)| b.display().to_string()),
        backend: p.backend.as_str(),
        reason: Some("the project folder is back".into()),
        program: resolved.map(|(_, program)| program),
    }
}
