//! Helpers shared by the preprocessor's integration tests. `cli.rs` includes this module as
//! `mod common;`, the grouped binaries (`bake/`, `synth/`, `vdb/`) as
//! `#[path = "../common/mod.rs"] mod common;`.
#![allow(dead_code)]

pub mod bake;
mod support;
pub mod vdb;

// Each test binary uses some of these.
#[allow(unused_imports)]
pub use support::{have_pyopenvdb, peak_memory, Rng};

use std::path::PathBuf;
use std::process::Command;

/// The `qbricks-bake` binary of this package (cargo builds it for the integration tests).
pub fn qbricks_bake() -> Command {
    Command::new(env!("CARGO_BIN_EXE_qbricks-bake"))
}

/// Repository root (the bundled samples are in its `data/`).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the crate is in the workspace root")
        .to_path_buf()
}

/// The VDB files written by real OpenVDB (`preprocess/tests/fixtures`, made by
/// `make_fixtures.py`).
pub fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}
