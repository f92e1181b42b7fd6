//! The readers: blackboard, SFC and IRL files → [`crate::model`], with spans.
//!
//! Readers never stop at the first problem: they push diagnostics and return what they could read.

pub mod blackboard;
pub mod irl;
pub mod sfc;
pub mod site;
pub mod tape;
pub mod tooling;
pub mod xml;

// Paths (`refURI` values, normalisation) are handled in [`crate::paths`].
