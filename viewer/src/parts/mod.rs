//! One frame over the ranks of an MPI run, sort-last: the file's KD-tree is cut into
//! subtrees ([`pieces`]), each rank searches its rays only through the regions of its
//! subtrees, and rank 0 composites what the ranks found ([`frame`]). The ranks talk only
//! through [`Exchange`] (of the `ranks` crate): MPI's ranks (`ranks::Ranks`), or threads
//! of one process ([`local_ranks`]) for the tests.
//!
//! What is shared out is the iso-surface search: a ray's first crossing is the nearest of
//! the first crossings each rank finds in its own regions, because `exact` solves every
//! region segment on its own (no state passes from one segment to the next). The shading
//! of the nearest crossing is done by the rank that found it, with the same code as one
//! process, so the composite is the same image bit for bit. Shadow rays are a second pass:
//! rank 0 sends every shadow ray that reaches the volume to all ranks, each says whether
//! the surface crosses it in its own regions, and a ray is blocked where any rank says so.
//! Meshes are traced by every rank (they bound the search and are small).

pub mod frame;
pub mod pieces;

pub use frame::{check, render_part, PartError, RankReport, RanksReport, Unsupported};
pub use pieces::{owned_regions, Pieces};
pub use ranks::{local_ranks, Exchange, LocalRank};
