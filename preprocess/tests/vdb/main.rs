//! The VDB reader on real and hostile files, one test binary:
//! * `fixtures`: files written by real OpenVDB (`tests/fixtures`), value by value;
//! * `differential`: random sparse grids written by pyopenvdb, value by value;
//! * `bad_input`: truncations, bit flips, absurd sizes, unsupported types.
//!
//! `.ci/run` re-runs `fixtures` and `bad_input` with integer overflow checks on (selected
//! by module path: `-- fixtures:: bad_input::`).

// As in `#[test]` functions (clippy.toml), `unwrap` is fine in their helpers too.
#![allow(clippy::unwrap_used)]

#[path = "../common/mod.rs"]
mod common;

mod bad_input;
mod differential;
mod fixtures;
mod mapped;
