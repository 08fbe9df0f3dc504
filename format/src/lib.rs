//! The `.qbk` brick file: the contract between `qbricks-bake` and `qbricks-view`.

pub mod schema;

pub use schema::*;
