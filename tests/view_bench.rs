//! Writes the benchmark volume (≥ 3 M cells) for the measurements in the README:
//! `QBK_BENCH_OUT=/tmp/bench.qbk cargo test --release --test view_bench -- --ignored`.

use viewer::testvol;

/// A vortex-like scalar field with many thin iso-surfaces, and a smooth "speed".
pub fn q_like(p: [f64; 3]) -> f64 {
    let (x, y, z) = (p[0] / 40.0, p[1] / 40.0, p[2] / 40.0);
    let r2 = (x - 3.2).powi(2) + (y - 3.2).powi(2) + (z - 3.2).powi(2);
    0.1 * (5.0 * x).sin() * (4.0 * y + 0.5).sin() * (3.0 * z + 1.0).sin() * (-0.3 * r2).exp()
}

pub fn speed_like(p: [f64; 3]) -> f64 {
    0.04 + 0.03 * ((p[0] + p[1]) / 60.0).sin() * (p[2] / 50.0).cos()
}

#[test]
#[ignore]
fn write_bench_volume() {
    let out = std::env::var("QBK_BENCH_OUT").unwrap_or_else(|_| "/tmp/qbricks_bench.qbk".into());
    let n: u32 = std::env::var("QBK_BENCH_N")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(128);
    let file = testvol::nested(n, [0.0; 3], &[("q", &q_like), ("speed", &speed_like)], 8);
    let cells: u64 = file.levels.iter().map(|l| l.cells).sum();
    let bytes = format::writer::write(std::path::Path::new(&out), &file).expect("write");
    println!(
        "{out}: {cells} cells, {} bricks, {} regions, {} kd nodes, {bytes} bytes",
        file.bricks.len(),
        file.regions.len(),
        file.kd_nodes.len()
    );
}
