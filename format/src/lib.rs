//! The `.qbk` brick file: the contract between `qbricks-bake` and `qbricks-view`.

pub mod error;
pub mod query;
pub mod reader;
pub mod schema;
pub mod writer;

pub use error::{FormatError, FormatErrorKind};
pub use reader::{BrickFileView, OpenOptions};
pub use schema::*;
