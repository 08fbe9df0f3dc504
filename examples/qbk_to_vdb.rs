//! Resamples a baked file's iso field onto one uniform grid at the file's finest cell width
//! and writes it as OpenVDB float grids, so OpenVDB's own renderer (`vdb_render`) can be run
//! on the very field qbricks ray-casts (see `docs/bench/vdb_render_compare.sh`).
//!
//! ```sh
//! cargo run --release --example qbk_to_vdb -- wake128.qbk q.vdb fog.vdb [--iso 0.05]
//! ```
//!
//! Writes two files:
//! * `q.vdb`, grid `negq`: **−Q** at every voxel centre inside the data (inactive outside).
//!   Negated so that the vortex interior (Q above the iso value) is negative, OpenVDB's
//!   level-set convention: `vdb_tool -iso2ls iso=-ISO` then turns it into a narrow-band
//!   signed distance field with the right inside.
//! * `fog.vdb`, grid `density` (class `fog volume`): the vortex cores as OpenVDB's fog
//!   volumes are made, 0 outside and 1 inside, here a linear ramp of Q over the seed
//!   report's band (0 at `iso − 2σ`, 1 at `iso + 2σ`, σ = 8 % of the iso value), active
//!   only where it is non-zero. Not qbricks' dvr band itself: that band is thinner than a
//!   cell where Q is steep, so classified before interpolation (all `vdb_render` can do)
//!   it would fall between the voxel centres almost everywhere.
//!
//! A resampling tool for benchmarks, not part of the programs: it lives in the root
//! package, which may link both the viewer (reconstruction) and the preprocessor (VDB
//! writer).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use preprocess::grid::{AnyGrid, Grid, Leaf, Transform, LEAF_DIM, LEAF_VOXELS};
use preprocess::vdb::write::{write_vdb_with, Compression, MetaMap, WriteOptions};
use preprocess::vdb::MetaValue;
use rayon::prelude::*;
use viewer::dataset::Dataset;
use viewer::transfer::Band;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut pos = Vec::new();
    let mut iso: f64 = 0.05;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--iso" {
            let v = it.next().context("--iso needs a value")?;
            iso = v.parse().with_context(|| format!("--iso {v}"))?;
        } else {
            pos.push(PathBuf::from(a));
        }
    }
    let [input, q_out, fog_out] = pos.as_slice() else {
        bail!("usage: qbk_to_vdb IN.qbk Q.vdb FOG.vdb [--iso V]");
    };
    let t0 = Instant::now();
    let ds = Dataset::open(input).with_context(|| format!("{}", input.display()))?;
    let vol = ds.volume();
    let f = vol.field_index("q")?;
    let h = vol.finest_w;
    let half = Band::SEED_REPORT.k * 0.08 * iso.abs();
    let (band_lo, band_hi) = (iso - half, iso + half);

    // Voxel (i, j, k) is centred at world = h·ijk + translation; ijk = 0 is the first
    // centre inside the bounds.
    let lo = vol.to_world(vol.bounds_min);
    let hi = vol.to_world(vol.bounds_max);
    let translation: [f64; 3] = std::array::from_fn(|a| lo[a] + 0.5 * h);
    let dims: [i32; 3] = std::array::from_fn(|a| ((hi[a] - lo[a]) / h).floor() as i32);
    let transform = Transform {
        voxel_size: [h; 3],
        translation,
    };
    let leaf_dims: [i32; 3] = std::array::from_fn(|a| (dims[a] + LEAF_DIM - 1) / LEAF_DIM);
    let origins: Vec<[i32; 3]> = (0..leaf_dims[0])
        .flat_map(|x| {
            (0..leaf_dims[1])
                .flat_map(move |y| (0..leaf_dims[2]).map(move |z| [x, y, z].map(|c| c * LEAF_DIM)))
        })
        .collect();

    // One pass over every voxel centre: −Q where the data has a value, the fog ramp
    // where it is non-zero.
    type Pair = (Option<Leaf<f32>>, Option<Leaf<f32>>);
    let leaves: Vec<Pair> = origins
        .par_iter()
        .map(|&origin| {
            let mut q = Leaf {
                origin,
                active: [0; 8],
                values: Box::new([0.0; LEAF_VOXELS]),
            };
            let mut fog = q.clone();
            for n in 0..LEAF_VOXELS {
                let ijk = [
                    origin[0] + (n >> 6) as i32,
                    origin[1] + ((n >> 3) & 7) as i32,
                    origin[2] + (n & 7) as i32,
                ];
                if (0..3).any(|a| ijk[a] >= dims[a]) {
                    continue;
                }
                let p = transform.index_to_world(ijk.map(f64::from));
                let Some(v) = vol.value_at(vol.to_local(p), f) else {
                    continue;
                };
                q.values[n] = -v as f32;
                q.active[n >> 6] |= 1 << (n & 63);
                let density = ((v - band_lo) / (band_hi - band_lo)).clamp(0.0, 1.0);
                if density > 0.0 {
                    fog.values[n] = density as f32;
                    fog.active[n >> 6] |= 1 << (n & 63);
                }
            }
            let keep = |l: Leaf<f32>| l.active.iter().any(|w| *w != 0).then_some(l);
            (keep(q), keep(fog))
        })
        .collect();
    let (q_leaves, fog_leaves): (Vec<_>, Vec<_>) = leaves.into_iter().unzip();
    let grid = |name: &str, leaves: Vec<Option<Leaf<f32>>>| Grid {
        name: name.to_string(),
        transform,
        background: 0.0,
        leaves: leaves.into_iter().flatten().collect(),
        tiles: Vec::new(),
    };
    let q = grid("negq", q_leaves);
    let fog = grid("density", fog_leaves);
    let (nq, nf) = (q.active_voxel_count(), fog.active_voxel_count());

    let plain = WriteOptions::new(Compression::Zip);
    write_vdb_with(q_out, &[AnyGrid::Float(q)], &plain)?;
    let mut fog_meta = MetaMap::new();
    fog_meta.insert("class".into(), MetaValue::String("fog volume".into()));
    let fog_options = WriteOptions {
        grid_metadata: vec![fog_meta],
        ..plain
    };
    write_vdb_with(fog_out, &[AnyGrid::Float(fog)], &fog_options)?;
    println!(
        "{}: {}x{}x{} voxels of width {h}; {} ({nq} active), {} ({nf} active) in {:.1} s",
        input.display(),
        dims[0],
        dims[1],
        dims[2],
        q_out.display(),
        fog_out.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
