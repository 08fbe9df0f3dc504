//! Frame sequences. The patterns and the manifest are shared with `qbricks-view`, so they
//! live in [`format::sequence`]; this module re-exports them for the baker.

pub use format::sequence::*;
