//! qbricks-lab: what is neither baking nor viewing. Analytic flows and the synthetic scenes
//! sampled from them (`synth`), the baked fields measured against their exact values
//! (`accuracy`), the viewer's sampling strategies timed against a fine reference (`bench`)
//! and the log–log charts of both (`chart`).
//!
//! The lab links `qbricks-preprocess` and `qbricks-viewer`; neither of them links the lab,
//! so the baker carries no ray caster or plotting and the viewer no VDB code.

// Numeric kernels index several per-axis arrays in lockstep; iterators would obscure them.
#![allow(clippy::needless_range_loop)]

pub mod accuracy;
pub mod analytic;
pub mod bench;
pub mod chart;
pub mod synth;
