//! Baking, one test binary: the library's `bake` and the `qbricks-bake bake` command on
//! the bundled sample, OpenVDB-written caches and hostile grids. (Bakes of the analytic
//! flows are `qbricks-lab`'s `flows` tests.)

// As in `#[test]` functions (clippy.toml), `unwrap` is fine in their helpers too.
#![allow(clippy::unwrap_used)]

#[path = "../common/mod.rs"]
mod common;

mod cache_fixtures;
mod hostile;
mod pipeline;
mod sample;
mod select_grids;
