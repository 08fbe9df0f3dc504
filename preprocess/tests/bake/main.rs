//! Baking, one test binary: the library's `bake` and the `qbricks-bake bake` command on
//! analytic flows, the bundled sample and OpenVDB-written caches.

// As in `#[test]` functions (clippy.toml), `unwrap` is fine in their helpers too.
#![allow(clippy::unwrap_used)]

#[path = "../common/mod.rs"]
mod common;

mod cache_fixtures;
mod fields;
mod hostile;
mod pipeline;
mod sample;
mod select_grids;
mod sequence;
mod split;
mod staggered;
mod wake;
