//! Helpers shared by the cross-crate tests (`tests/cross_crate/`, which includes this module as
//! `#[path = "../common/mod.rs"] mod common;`).
#![allow(dead_code)]

use std::path::PathBuf;

/// Path of a workspace binary built by cargo for this test run.
pub fn bin(name: &str) -> PathBuf {
    let mut dir = std::env::current_exe().expect("test exe path");
    dir.pop();
    if dir.ends_with("deps") {
        dir.pop();
    }
    let path = dir.join(name);
    assert!(
        path.exists(),
        "{} is not built: run the end-to-end tests with `cargo test --workspace`, which builds \
         every binary",
        path.display()
    );
    path
}

/// Repository root (the root package's manifest is there).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}
