//! What a deploy hook gets from a compile: its outputs grouped by program, only the programs
//! with new bytes, a cell's programs only to a hook that tells them apart, each program's
//! files copied into a snapshot of the daemon's own.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::compile::Compilation;
use crate::daemon::events::Event;

use super::Job;

impl Job {
    /// The deploys of a successful compile that wrote `outputs` (`picture`, the plan's
    /// picture, among them: no program); `None` when no program is to be deployed.
    pub(super) fn deploys(
        &self,
        c: &Compilation,
        outputs: &[(PathBuf, bool)],
        picture: Option<&PathBuf>,
        program: &str,
        blackboard: &Path,
    ) -> Option<Vec<crate::daemon::deploy::Context>> {
        let deploy = self.deploy_contexts(c, outputs, picture, program, blackboard);
        // A cell's programs (several controllers) only to a hook that tells them apart.
        let mut controllers: Vec<&str> = c
            .output_programs
            .iter()
            .map(|(_, ctl)| ctl.as_str())
            .collect();
        controllers.sort_unstable();
        controllers.dedup();
        let deploy = match &self.spec.on_success {
            Some(hook)
                if controllers.len() > 1
                    && !crate::daemon::deploy::tells_programs_apart(&hook.argv) =>
            {
                for ctx in &deploy {
                    self.not_deployed(
                        ctx,
                        format!(
                            "not deployed: the project's programs run on {} controllers ({}), \
                             and the hook's arguments name neither `{{controller}}` nor \
                             `{{program}}`, so every program would go to the same place; choose \
                             the destination by `{{controller}}`",
                            controllers.len(),
                            controllers.join(", ")
                        ),
                    );
                }
                Vec::new()
            }
            _ => deploy,
        };
        let deploy = match &self.snapshots {
            Some(runtime) => self.snapshot(runtime, c, deploy),
            None => deploy,
        };
        (!deploy.is_empty()).then_some(deploy)
    }

    /// `deploy-failed` for a program whose hook is not run at all, and why.
    pub(super) fn not_deployed(&self, ctx: &crate::daemon::deploy::Context, reason: String) {
        let controller = (!ctx.controller.is_empty()).then_some(ctx.controller.as_str());
        self.sink.emit(
            Some(&self.project()),
            Event::deploy_not_run(&ctx.program, controller, self.run_id, 0, reason),
        );
    }

    /// Each program's files as this compile wrote them, copied into a snapshot of the daemon's
    /// own: what the hook gets instead of the files in the project folder, which anyone who
    /// can write there may replace. A program whose copy cannot be made is not deployed
    /// (`deploy-failed` with the reason): never the folder's files in its place.
    fn snapshot(
        &self,
        runtime: &Path,
        c: &Compilation,
        deploy: Vec<crate::daemon::deploy::Context>,
    ) -> Vec<crate::daemon::deploy::Context> {
        // By path: a cell of many controllers has many outputs.
        let by_path: HashMap<&PathBuf, &[u8]> = c
            .outputs
            .iter()
            .map(|(o, f)| (o, f.text.as_bytes()))
            .collect();
        let bytes = |p: &PathBuf| by_path.get(p).copied();
        let mut kept = Vec::with_capacity(deploy.len());
        for mut ctx in deploy {
            let files: Option<Vec<(&Path, &[u8])>> = ctx
                .outputs
                .iter()
                .chain(&ctx.io)
                .map(|p| bytes(p).map(|b| (p.as_path(), b)))
                .collect();
            let taken = match files {
                Some(files) => crate::daemon::snapshot::take(runtime, &files),
                None => Err(std::io::Error::other("an output's bytes are not at hand")),
            };
            match taken {
                Ok((held, copies)) => {
                    if let Some(k) = ctx.outputs.iter().position(|p| *p == ctx.main) {
                        ctx.main = copies[k].clone();
                    }
                    let mut copies = copies;
                    ctx.io = copies.split_off(ctx.outputs.len());
                    ctx.outputs = copies;
                    ctx.snapshot = Some(held);
                    kept.push(ctx);
                }
                Err(e) => self.not_deployed(
                    &ctx,
                    format!(
                        "cannot keep a copy of the program for the hook in {}: {e}",
                        runtime.display()
                    ),
                ),
            }
        }
        kept
    }

    /// New bytes in some program's files: what a deploy hook gets (the event loop runs it, if
    /// the project has one), once per such program with that program's files. The picture
    /// is no program: never deployed, and no reason to.
    fn deploy_contexts(
        &self,
        c: &Compilation,
        outputs: &[(PathBuf, bool)],
        picture: Option<&PathBuf>,
        program: &str,
        blackboard: &Path,
    ) -> Vec<crate::daemon::deploy::Context> {
        let mut deploy: Vec<(crate::daemon::deploy::Context, bool)> = Vec::new();
        for (k, (p, w)) in outputs.iter().enumerate() {
            if Some(p) == picture {
                continue;
            }
            let (prog, controller) = match c.output_programs.get(k) {
                Some((prog, ctl)) => (prog.clone(), ctl.clone()),
                None => (program.to_owned(), c.controller.clone().unwrap_or_default()),
            };
            let at = match deploy.iter().position(|(d, _)| d.program == prog) {
                Some(at) => at,
                None => {
                    let ctx = crate::daemon::deploy::Context {
                        outputs: Vec::new(),
                        main: PathBuf::new(),
                        blackboard: blackboard.to_path_buf(),
                        project: self.key.clone(),
                        program: prog,
                        controller,
                        snapshot: None,
                        io: Vec::new(),
                    };
                    deploy.push((ctx, false));
                    deploy.len() - 1
                }
            };
            // The I/O list and EIO fragment: `{io}`/`{eio}`, not program files.
            if crate::emit::commissioning_file(p).is_some() {
                deploy[at].0.io.push(p.clone());
            } else {
                deploy[at].0.outputs.push(p.clone());
            }
            deploy[at].1 |= *w;
        }
        // Only the programs with new bytes; each one's main file: its .src/.mod/.script.
        deploy
            .into_iter()
            .filter(|(_, written)| *written)
            .map(|(mut d, _)| {
                d.main = d
                    .outputs
                    .iter()
                    .find(|p| {
                        p.extension().is_some_and(|e| {
                            ["src", "mod", "script"]
                                .iter()
                                .any(|x| e.to_string_lossy().eq_ignore_ascii_case(x))
                        })
                    })
                    .or(d.outputs.first())
                    .cloned()
                    .unwrap_or_default();
                d
            })
            .collect()
    }
}
