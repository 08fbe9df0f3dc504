//! Baking analytic flows, one test binary: the preprocessor's `bake` (library and
//! `qbricks-bake bake`) on scenes sampled by `synth`, against their exact values.

// As in `#[test]` functions (clippy.toml), `unwrap` is fine in their helpers too.
#![allow(clippy::unwrap_used)]

extern crate preprocess as qbricks_preprocess;

#[path = "../common/mod.rs"]
mod common;

mod fields;
mod measures;
mod sequence;
mod split;
mod staggered;
mod wake;
