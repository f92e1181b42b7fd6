//! The state as `skillpost status` prints it: the projects, their deploys and simulations as
//! aligned tables, names from disk made printable.

use std::path::Path;

use super::Snapshot;
use super::files::writer_alive;

/// The state as an aligned table (spaces, no tabs), with a heading line.
pub fn table(s: &Snapshot) -> String {
    let mut out = if s.daemon == "stopped" {
        format!(
            "skillpost {} (pid {}) stopped; last state written {}\n",
            s.version, s.pid, s.updated
        )
    } else {
        format!(
            "skillpost {} (pid {}) {} since {}: {}\n",
            s.version, s.pid, s.daemon, s.started, s.summary
        )
    };
    if s.daemon != "stopped" && !writer_alive(s) {
        out.push_str(&format!(
            "warning: pid {} is not running: the daemon ended without updating this state\n",
            s.pid
        ));
    }
    if s.projects.is_empty() {
        return out;
    }
    out.push('\n');
    let header = [
        "PROJECT", "RESULT", "LAST RUN", "ERRORS", "WARNINGS", "OUTPUTS",
    ];
    let rows: Vec<[String; 6]> = s
        .projects
        .iter()
        .map(|p| {
            // A project waiting for its folder: why (its outputs may be gone with the folder).
            let outputs = if let Some(w) = &p.waiting {
                w.clone()
            } else if p.result == "failed" {
                p.first_error.clone().unwrap_or_default()
            } else {
                let name = |o: &String| {
                    Path::new(o)
                        .file_name()
                        .map_or_else(|| o.clone(), |n| n.to_string_lossy().into_owned())
                };
                let mut s = p.outputs.iter().map(name).collect::<Vec<_>>().join(", ");
                if !p.stale.is_empty() {
                    s.push_str(&format!(
                        "; stale (not written, kept): {}",
                        p.stale.iter().map(name).collect::<Vec<_>>().join(", ")
                    ));
                }
                s
            };
            [
                p.project.clone(),
                p.result.clone(),
                p.time.clone().unwrap_or_else(|| "-".into()),
                p.errors.to_string(),
                p.warnings.to_string(),
                outputs,
            ]
        })
        .collect();
    out.push_str(&aligned(header, &rows));
    out.push_str(&deploy_table(s));
    out.push_str(&simulation_table(s));
    out
}

/// The last simulation of each project that simulates (nothing when none does).
fn simulation_table(s: &Snapshot) -> String {
    let header = ["PROJECT", "SIMULATION", "WHEN", "CYCLE", "FIRST PROBLEM"];
    let rows: Vec<[String; 5]> = s
        .projects
        .iter()
        .filter_map(|p| {
            let sim = p.simulation.as_ref()?;
            Some([
                p.project.clone(),
                format!(
                    "{} ({} run{})",
                    sim.result,
                    sim.runs,
                    if sim.runs == 1 { "" } else { "s" }
                ),
                sim.time.clone(),
                sim.cycle_s
                    .map_or_else(|| "-".into(), |c| format!("{c:.2} s")),
                sim.problem.clone().unwrap_or_default(),
            ])
        })
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    format!("\n{}", aligned(header, &rows))
}

/// The last deploy of each program, under the projects (nothing when no project deploys).
fn deploy_table(s: &Snapshot) -> String {
    let header = ["PROJECT", "PROGRAM", "DEPLOY", "WHEN", "WHY"];
    let rows: Vec<[String; 5]> = s
        .projects
        .iter()
        .flat_map(|p| {
            p.deploys.iter().map(|d| {
                [
                    p.project.clone(),
                    match &d.controller {
                        Some(c) => format!("{} ({c})", d.program),
                        None => d.program.clone(),
                    },
                    d.result.clone(),
                    d.time.clone(),
                    d.reason.clone().unwrap_or_default(),
                ]
            })
        })
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    format!("\n{}", aligned(header, &rows))
}

/// Rows under their header, each column as wide as its widest cell plus two spaces; line
/// breaks and tabs in a cell become spaces, no trailing blanks.
/// `s` with its control characters escaped (`\u{1b}`; a tab and line breaks become spaces
/// first where a caller wants that): what a table or a log line shows of a name from disk.
pub fn printable(s: &str) -> std::borrow::Cow<'_, str> {
    if !s.chars().any(char::is_control) {
        return std::borrow::Cow::Borrowed(s);
    }
    std::borrow::Cow::Owned(crate::paths::escaped(std::path::Path::new(s)))
}

fn aligned<const N: usize>(header: [&str; N], rows: &[[String; N]]) -> String {
    let rows: Vec<[String; N]> = rows
        .iter()
        .map(|r| {
            r.each_ref()
                .map(|c| printable(&c.replace(['\t', '\n', '\r'], " ")).into_owned())
        })
        .collect();
    let rows = &rows[..];
    let mut width = header.map(|h| h.chars().count());
    for r in rows {
        for (w, c) in width.iter_mut().zip(r) {
            *w = (*w).max(c.chars().count());
        }
    }
    let line = |cells: &[&str]| {
        let mut l = String::new();
        for (i, c) in cells.iter().enumerate() {
            let c = c.replace(['\t', '\n', '\r'], " ");
            l.push_str(&c);
            if i + 1 < cells.len() {
                l.push_str(&" ".repeat(width[i] - c.chars().count() + 2));
            }
        }
        l.truncate(l.trim_end().len());
        l.push('\n');
        l
    };
    let mut out = line(&header);
    for r in rows {
        out.push_str(&line(&r.each_ref().map(String::as_str)));
    }
    out
}
