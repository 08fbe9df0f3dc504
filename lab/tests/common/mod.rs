//! Helpers shared by the lab's integration tests (`cli/`, `flows/`, `synth/`), each of
//! which includes this module as `#[path = "../common/mod.rs"] mod common;` and names the
//! preprocessor `qbricks_preprocess` (`extern crate preprocess as qbricks_preprocess;`) so
//! that the preprocessor's own test helpers, shared below, read the same in both crates.
#![allow(dead_code)]

#[path = "../../../preprocess/tests/common/bake.rs"]
pub mod bake;
#[path = "../../../preprocess/tests/common/support.rs"]
mod support;
#[path = "../../../preprocess/tests/common/vdb.rs"]
pub mod vdb;

// Each test binary uses some of these.
#[allow(unused_imports)]
pub use support::{have_pyopenvdb, peak_memory, Rng};

use std::path::PathBuf;
use std::process::Command;

/// The `qbricks-lab` binary of this package (cargo builds it for the integration tests).
pub fn qbricks_lab() -> Command {
    Command::new(env!("CARGO_BIN_EXE_qbricks-lab"))
}

/// The `qbricks-view` binary, for `qbricks-view bench`'s moved message.
pub fn qbricks_view() -> Command {
    Command::new(workspace_bin("qbricks-view"))
}

/// The `qbricks-bake` binary: another package's, so it is looked up beside this test's
/// executable, where `cargo test --workspace` (which builds every binary) puts it.
pub fn qbricks_bake() -> Command {
    Command::new(workspace_bin("qbricks-bake"))
}

fn workspace_bin(name: &str) -> PathBuf {
    let mut dir = std::env::current_exe().expect("test exe path");
    dir.pop();
    if dir.ends_with("deps") {
        dir.pop();
    }
    let path = dir.join(name);
    assert!(
        path.exists(),
        "{} is not built: run the lab's tests with `cargo test --workspace` (or build \
         `{name}` first), which builds every binary",
        path.display()
    );
    path
}

/// Repository root (the bundled samples are in its `data/`).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the crate is in the workspace root")
        .to_path_buf()
}
