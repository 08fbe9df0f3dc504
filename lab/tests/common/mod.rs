//! Helpers shared by the lab's integration tests (`cli/`, `flows/`, `synth/`), each of
//! which includes this module as `#[path = "../common/mod.rs"] mod common;` and names the
//! preprocessor `qbricks_preprocess` (`extern crate preprocess as qbricks_preprocess;`) so
//! that the preprocessor's own test helpers, shared below, read the same in both crates.
#![allow(dead_code)]

#[path = "../../../preprocess/tests/common/bake.rs"]
pub mod bake;
#[path = "../../../preprocess/tests/common/vdb.rs"]
pub mod vdb;

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

/// Is `/usr/bin/python3 -c 'import pyopenvdb'` available?
pub fn have_pyopenvdb() -> bool {
    Command::new("/usr/bin/python3")
        .args(["-c", "import pyopenvdb"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

/// Small deterministic random numbers (xorshift64*).
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// Uniform in [0, 1).
    pub fn next(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in `0..n`.
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n
    }
}
