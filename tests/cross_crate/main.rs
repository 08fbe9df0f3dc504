//! Cross-crate tests, one test binary: whole chains through both programs and what holds
//! for both (they link the viewer and the preprocessor, and run both binaries):
//! * `cli_cases`: every hostile command-line case of issues 12 and 32 in one table;
//! * `hostile_inputs`: the small VDB and `.qbk` inputs of issue 32, written at test time;
//! * `interrupt`: SIGINT/SIGTERM in the middle of writing an output;
//! * `render_sequence`: bake the bundled cache, then render the frames;
//! * `framing_layouts`: the default camera on a baked cache frame, a single grid and the
//!   cache as a sequence;
//! * `docs_exist`: the documents and the README against the code and `--help`;
//! * `shading_wake` (ignored): a measurement of shading normals on a baked wake.
//!
//! The binaries are run from cargo's target directory: `cargo test --workspace` builds
//! them; a lone `cargo test --test cross_crate` needs `cargo build --workspace` first
//! (with the same `--release` or not).

// As in `#[test]` functions (clippy.toml), `unwrap` is fine in their helpers too.
#![allow(clippy::unwrap_used)]

#[path = "../common/mod.rs"]
mod common;

mod cli_cases;
mod docs_exist;
mod framing_layouts;
mod hostile_inputs;
mod interrupt;
mod render_sequence;
mod shading_wake;
