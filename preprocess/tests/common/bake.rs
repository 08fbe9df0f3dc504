//! Reading cells back from a baked file and a reference reconstruction (basis method)
//! written independently of the baker and the viewer.

use format::BrickFile;

/// One stored leaf cell.
#[derive(Debug, Clone, Copy)]
pub struct Cell {
    pub centre: [f64; 3],
    pub width: f64,
    pub level: u32,
    pub value: f32,
}

/// Every stored leaf cell with the value of field `f`.
pub fn cells(file: &BrickFile, f: usize) -> Vec<Cell> {
    let mut out = vec![];
    for b in &file.bricks {
        let [nx, ny, nz] = b.dims.map(|d| d as usize);
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let c = [x, y, z];
                    out.push(Cell {
                        centre: [0, 1, 2].map(|a| b.origin[a] + c[a] as f64 * b.cell_width),
                        width: b.cell_width,
                        level: b.level,
                        value: file.fields[f].values
                            [b.first_value as usize + x + nx * (y + ny * z)],
                    });
                }
            }
        }
    }
    out
}

/// Index of the field called `name`.
pub fn field(file: &BrickFile, name: &str) -> usize {
    file.fields
        .iter()
        .position(|f| f.name == name)
        .unwrap_or_else(|| panic!("field {name} missing"))
}

/// Every region's box (its leaf's cell), by region.
pub fn region_boxes(file: &BrickFile) -> Vec<format::Aabb> {
    let mut out = vec![format::Aabb::EMPTY; file.regions.len()];
    format::kd::leaf_cells(
        &file.kd_tree(),
        file.bounds.min,
        file.bounds.max,
        [0.0; 3],
        |r, min, max| out[r as usize] = format::Aabb { min, max },
    );
    out
}

/// Reconstruction over the given bricks: `Σ H v / Σ H` with tents
/// `H = Π max(0, 1 − |p − c| / w)`; `None` where no tent reaches `p`.
pub fn reconstruct(file: &BrickFile, bricks: &[u32], f: usize, p: [f64; 3]) -> Option<f64> {
    qbricks_preprocess::reconstruct::reconstruct_over(file, bricks, f, p)
}

/// Reconstruction at `p` through the KD-tree (None outside the data).
pub fn sample(file: &BrickFile, f: usize, p: [f64; 3]) -> Option<f64> {
    let r = file.region_at(p)?;
    reconstruct(file, file.bricks_of(r), f, p)
}
