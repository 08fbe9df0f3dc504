//! Reconstruction, sampling and rendering, one test binary:
//! * `reconstruct`: the reconstruction and the tracer against analytic truth;
//! * `hard_rays`, `hard_images`: the ray caster's hard cases, ray by ray and whole images;
//! * `images`: whole images on any thread count, iso values outside the data;
//! * `probe_plane`: `probe --plane` against `probe` at the same points, and its files;
//! * `golden`, `golden_sample`: pictures compared with `tests/golden/*.png` by PSNR
//!   (`QBRICKS_UPDATE_GOLDEN=1` rewrites them, see TESTING.md).

// As in `#[test]` functions (clippy.toml), `unwrap` is fine in their helpers too.
#![allow(clippy::unwrap_used)]

#[path = "../common/mod.rs"]
mod common;

mod cuts;
mod defaults;
mod golden;
mod golden_sample;
mod hard_images;
mod hard_rays;
mod images;
mod probe_plane;
mod reconstruct;
