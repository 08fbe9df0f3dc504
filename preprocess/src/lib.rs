//! qbricks-bake: OpenVDB in, `.qbk` brick file out.
//!
//! Data flows one way: VDB → grids → cells → bricks → regions → kd-tree → file.

pub mod bake;
pub mod bricks;
pub mod cells;
pub mod derive;
pub mod error;
pub mod fields;
pub mod grid;
pub mod heap;
pub mod inputs;
pub mod kdtree;
pub mod levels;
pub mod measures;
pub mod nonfinite;
pub mod progress;
pub mod reconstruct;
pub mod regions;
pub mod request;
pub mod sequence;
pub mod spilled;
pub mod vdb;
