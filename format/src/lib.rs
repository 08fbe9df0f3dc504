//! The `.qbk` brick file: the contract between `qbricks-bake` and `qbricks-view`.
//!
//! A file is a 48-byte [`header`] followed by the rkyv archive of a [`BrickFile`]
//! ([`schema`]). [`writer`] writes it atomically; [`BrickFileView`] ([`reader`])
//! memory-maps it and validates everything ([`header`] checks, rkyv bytecheck,
//! [`validate`]) before handing out `&ArchivedBrickFile`; [`query`] answers the
//! read-only questions both programs ask (point → region, ray → regions, bricks, cells).
//! [`sequence`] holds what both programs know about frame sequences (file-name patterns,
//! the manifest).

pub mod error;
pub mod header;
pub mod kd;
pub mod query;
pub mod reader;
pub mod schema;
pub mod sequence;
pub mod streamed;
pub mod validate;
pub mod writer;

pub use error::{FormatError, FormatErrorKind};
pub use header::FORMAT_VERSION;
pub use reader::{BrickFileView, OpenOptions, Structure};
pub use schema::*;
