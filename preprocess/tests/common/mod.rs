//! Helpers shared by the preprocessor's integration tests. `cli.rs` includes this module as
//! `mod common;`, the grouped binaries (`bake/`, `synth/`, `vdb/`) as
//! `#[path = "../common/mod.rs"] mod common;`.
#![allow(dead_code)]

pub mod bake;
pub mod vdb;

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
