//! qbricks-bake: OpenVDB in, `.qbk` brick file out.

pub mod grid;
