//! Writes a small two-level `.qbk` test scene (a vortex ring of positive Q around the
//! origin, speed varying along the ring) for trying `qbricks-view` without a VDB file.
//! The ring (radius 1.5) surrounds the bundled `data/sphere.obj` (radius 0.5) when both
//! are at the origin.
//!
//! `cargo run --release -p qbricks-viewer --example ring_scene -- OUT.qbk [N]`

use std::path::PathBuf;

use qbricks_viewer::testvol;

/// World units per coarse cell: the scene spans [-4, 4]^3.
fn scale(n: u32) -> f64 {
    8.0 / (2.0 * f64::from(n))
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(args.next().unwrap_or_else(|| "ring.qbk".into()));
    let n: u32 = match args.next() {
        Some(s) => s.parse().map_err(|e| anyhow::anyhow!("N `{s}`: {e}"))?,
        None => 32,
    };
    anyhow::ensure!((4..=256).contains(&n), "N: expected 4..=256, found {n}");
    // testvol::nested works in cell units over [0, 2n]^3; map to [-4, 4]^3 afterwards by
    // evaluating the fields at world positions.
    let s = scale(n);
    let to_world = move |p: [f64; 3]| p.map(|x| x * s - 4.0);
    let q = move |p: [f64; 3]| {
        let [x, y, z] = to_world(p);
        let r = (x * x + y * y).sqrt() - 1.5;
        let wobble = 1.0 + 0.25 * (3.0 * y.atan2(x)).sin();
        wobble * (-(r * r + z * z) / 0.16).exp() - 0.1
    };
    let speed = move |p: [f64; 3]| {
        let [x, y, z] = to_world(p);
        0.04 + 0.03 * y.atan2(x).cos() + 0.002 * z
    };
    let mut file = testvol::nested(n, [0.0; 3], &[("q", &q), ("speed", &speed)], 8);
    // Move the cell-unit geometry to world units.
    scale_file(&mut file, s, -4.0);
    let bytes = format::writer::write(&out, &file).map_err(|e| anyhow::anyhow!("{e}"))?;
    println!(
        "{}: {bytes} bytes, {} bricks",
        out.display(),
        file.bricks.len()
    );
    Ok(())
}

/// Maps every coordinate `x` of the file to `x * s + shift`.
fn scale_file(file: &mut format::BrickFile, s: f64, shift: f64) {
    let m = |x: &mut f64| *x = *x * s + shift;
    file.bounds.min.iter_mut().for_each(m);
    file.bounds.max.iter_mut().for_each(m);
    for b in &mut file.bricks {
        b.origin.iter_mut().for_each(m);
        b.cell_width *= s;
        b.inv_cell_width = 1.0 / b.cell_width;
    }
    // Region boxes are the tree's leaf cells: scaling the splits scales them.
    for node in &mut file.kd_nodes {
        m(&mut node.split);
    }
    for l in &mut file.levels {
        l.cell_width *= s;
    }
}
