//! The basis-method reconstruction of a baked field, evaluated on the in-memory file: what
//! the viewer computes, here so that a bake can be checked before it is written (the bake
//! tests compare a region's bricks with all bricks; `qbricks-lab accuracy` measures errors).

use format::BrickFile;

/// The basis-method reconstruction at `p` over the bricks `ids` (`Σ H v / Σ H`, tents of
/// the cell width around every leaf-cell centre), the formula the viewer evaluates, written
/// over the in-memory file so a bake can be checked before it is written; `None` where no
/// tent reaches `p`. The bake tests use it too, to compare a region's bricks with all bricks.
pub fn reconstruct_over(file: &BrickFile, ids: &[u32], f: usize, p: [f64; 3]) -> Option<f64> {
    let (mut s, mut ws) = (0.0, 0.0);
    for &bi in ids {
        let b = &file.bricks[bi as usize];
        let d = b.dims.map(i64::from);
        let mut lo = [0i64; 3];
        let mut hi = [0i64; 3];
        for a in 0..3 {
            let x = (p[a] - b.origin[a]) / b.cell_width;
            lo[a] = ((x.floor() - 1.0).max(0.0)) as i64;
            hi[a] = ((x.ceil() + 1.0) as i64).min(d[a] - 1);
        }
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    let c = [x, y, z];
                    let mut h = 1.0;
                    for a in 0..3 {
                        let ca = b.origin[a] + c[a] as f64 * b.cell_width;
                        h *= (1.0 - (p[a] - ca).abs() / b.cell_width).max(0.0);
                    }
                    if h > 0.0 {
                        let i = b.first_value as usize + (x + d[0] * (y + d[1] * z)) as usize;
                        s += h * f64::from(file.fields[f].values[i]);
                        ws += h;
                    }
                }
            }
        }
    }
    (ws > 1e-12).then(|| s / ws)
}
