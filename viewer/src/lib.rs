//! qbricks-view: ray casting of `.qbk` brick files.
//!
//! Data flows one way: file → volume → traversal → samples → shading → pixels.

pub mod info;
