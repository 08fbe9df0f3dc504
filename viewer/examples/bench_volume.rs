//! Writes a synthetic benchmark volume for timing the viewer (≥ 3 M cells at the default
//! N = 128): `testvol::nested(N, ..)` with a vortex-like `q` with many thin iso-surfaces
//! and a smooth `speed`. Prints the cell, brick, region and kd-node counts.
//!
//! ```sh
//! cargo run --release -p qbricks-viewer --example bench_volume [-- OUT.qbk [N]]
//! qbricks-lab bench OUT.qbk
//! ```
//!
//! `OUT.qbk` defaults to `/tmp/qbricks_bench.qbk`, `N` to 128. (Formerly the ignored test
//! `tests/view_bench.rs`.)

use std::path::PathBuf;

use qbricks_viewer::testvol;

/// A vortex-like scalar field with many thin iso-surfaces, and a smooth "speed".
fn q_like(p: [f64; 3]) -> f64 {
    let (x, y, z) = (p[0] / 40.0, p[1] / 40.0, p[2] / 40.0);
    let r2 = (x - 3.2).powi(2) + (y - 3.2).powi(2) + (z - 3.2).powi(2);
    0.1 * (5.0 * x).sin() * (4.0 * y + 0.5).sin() * (3.0 * z + 1.0).sin() * (-0.3 * r2).exp()
}

fn speed_like(p: [f64; 3]) -> f64 {
    0.04 + 0.03 * ((p[0] + p[1]) / 60.0).sin() * (p[2] / 50.0).cos()
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let out = args
        .next()
        .map_or_else(|| PathBuf::from("/tmp/qbricks_bench.qbk"), PathBuf::from);
    let n: u32 = match args.next() {
        Some(s) => s.parse().map_err(|e| anyhow::anyhow!("N `{s}`: {e}"))?,
        None => 128,
    };
    let file = testvol::nested(n, [0.0; 3], &[("q", &q_like), ("speed", &speed_like)], 8);
    let cells: u64 = file.levels.iter().map(|l| l.cells).sum();
    let bytes = format::writer::write(&out, &file)
        .map_err(|e| anyhow::anyhow!("{}: {e}", out.display()))?;
    println!(
        "{}: {cells} cells, {} bricks, {} regions, {} kd nodes, {bytes} bytes",
        out.display(),
        file.bricks.len(),
        file.regions.len(),
        file.kd_nodes.len()
    );
    Ok(())
}
