//! OpenVDB files: the subset qbricks reads, and a small writer for synthetic scenes.

pub mod write;
