//! Language profiles: the bound program → output files. KRL is the first (and so far only)
//! profile; another robot language adds a module beside [`krl`] with the same shape: it takes
//! the [`EmitInput`] and returns its files or diagnostics.

pub mod krl;

use crate::bind::Bound;
use crate::model::{Blackboard, Irl, Sfc};
use crate::plan::Plan;

/// Everything a profile reads.
pub struct EmitInput<'a> {
    pub program: &'a str,
    pub blackboard: &'a Blackboard,
    pub sfc: &'a Sfc,
    pub plan: &'a Plan,
    pub bound: &'a Bound,
    pub irls: &'a [Irl],
    /// `"\r\n"` or `"\n"`.
    pub newline: &'a str,
}

/// One generated file: its extension (`src`, `dat`) and its bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OutputFile {
    pub extension: &'static str,
    pub text: String,
}
