//! skillpost: AutomationML blackboard + PLCopen SFC + IRL snippets → KUKA KRL.
//!
//! # Layout
//!
//! The modules follow the data (see `ARCHITECTURE.md` for the invariants):
//!
//! - [`load`]: the only file-system reads of the compiler core, behind the [`load::FileSource`]
//!   trait; records every file a compile read.
//! - [`read`]: blackboard, SFC and IRL files → [`model`], every item with its byte span.
//! - [`lang`]: the robot languages as values (names, IRL syntax); their profiles are `emit`'s.
//! - [`value`]: SFC variable values: list syntax, in-place lookup, typed neutral literals.
//! - [`cond`]: transition conditions (an ST subset): parse, check, render as KRL.
//! - [`plan`]: SFC graph checks → an ordered program tree ([`plan::Block`]).
//! - [`bind`]: skill steps → function calls with checked, typed values ([`bind::BoundStep`]).
//! - [`template`]: IRL template parsing and parameter substitution.
//! - [`convert`]: the conversions templates may call (`m`, `mm`, `rad`, `deg`, `quat`, `rotvec`)
//!   and how their results are written.
//! - [`emit`]: language profiles (KRL, RAPID, URScript): value rules, names, control flow, files.
//! - [`write`](mod@write): atomic output files and the byte-preserving blackboard write-back.
//! - [`compile`]: the whole pipeline for one project: inputs in, outputs + diagnostics out.
//! - [`daemon`]: `skillpost watch`, the long-running service over the same pipeline.
//! - [`simulate`]: `skillpost simulate`: the cell's programs run together on a built-in
//!   interpreter of the forms skillpost writes (after `compile`, before the drivers).
//! - [`print`](mod@print): the `-pB`/`-pS`/`-pF`/`-pO` and `--info` listings.
//! - [`picture`]: the plan as an SVG timeline (`--svg`, the daemon's `picture`).
//! - [`diag`]: diagnostics, their codes and their rendering.
//! - [`excerpt`]: the lines of a streamed file (the SFC) that diagnostics point into, read
//!   again without holding the file.
//! - [`names`]: case-insensitive name keys, KRL names, transliteration.
//! - [`paths`]: `refURI` values → paths, lexical normalisation, absolute paths.
//! - [`threads`]: work split in two, one part on a thread of its own.
#![forbid(unsafe_code)]

pub mod bind;
pub mod check;
pub mod cli;
pub mod compile;
pub mod cond;
pub mod convert;
pub mod daemon;
pub mod diag;
pub mod emit;
pub mod excerpt;
pub mod lang;
pub mod load;
pub mod model;
pub mod names;
pub mod paths;
pub mod picture;
pub mod plan;
pub mod print;
pub mod read;
pub mod simulate;
pub mod template;
pub mod threads;
pub mod value;
pub mod write;

/// The version printed by `--info`.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
