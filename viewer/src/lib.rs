//! qbricks-view: ray casting of `.qbk` brick files.
//!
//! Data flows one way: file → volume → traversal → samples → shading → pixels.

pub mod bvh;
pub mod camera;
pub mod colormap;
pub mod info;
pub mod mesh;
pub mod shading;
pub mod view_state;
