//! Writing VDB files, one test binary: `synth` scenes and `vdb::write` read back by our
//! reader and by real OpenVDB, and the bundled samples they made.

// As in `#[test]` functions (clippy.toml), `unwrap` is fine in their helpers too.
#![allow(clippy::unwrap_used)]

extern crate preprocess as qbricks_preprocess;

#[path = "../common/mod.rs"]
mod common;

mod boxes;
mod cache;
mod openvdb;
mod roundtrip;
mod sample;
