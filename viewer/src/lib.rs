//! qbricks-view: ray casting of `.qbk` brick files.
//!
//! Data flows one way: file → volume → traversal → samples → shading → pixels.

// Numeric kernels index several per-axis arrays in lockstep; iterators would obscure them.
#![allow(clippy::needless_range_loop)]

pub mod accel;
mod active;
#[cfg(feature = "gui")]
pub mod app;
pub mod bvh;
pub mod camera;
pub mod colormap;
pub mod dataset;
mod dual_mask;
pub mod fields;
pub mod film;
pub mod framing;
pub mod info;
pub mod integrate;
mod lattice;
pub mod mesh;
pub mod overlay;
mod packed;
pub mod palette;
pub mod parts;
pub mod planes;
pub mod preview_scale;
pub mod probe;
pub mod progressive;
pub mod ray;
pub mod reconstruct;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod sequence;
pub mod sequence_defaults;
pub mod shading;
#[cfg(any(test, feature = "testkit"))]
pub mod testvol;
mod tiles;
pub mod transfer;
pub mod traverse;
pub mod view_state;
pub mod volume;
