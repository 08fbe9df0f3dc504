//! How accurate is the data model? Bakes an analytic `synth` flow at several resolutions and
//! compares what the file stores, and what the basis-method reconstruction makes of it, with
//! the exact Q, speed, vorticity magnitude and λ2 of the flow ([`MEASURED`]; the three
//! made from the velocity gradient share the bake's one stencil).
//!
//! The stored values are checked at every leaf-cell centre (per level, since a coarse level
//! carries a coarse stencil's error); the reconstruction of Q, vorticity and λ2 at random
//! points in the data and at random points within two coarse cells of a level boundary
//! (nested scenes), where cracks and blending errors would show. Errors are given absolute
//! and relative to the 99th percentile of the exact |value| over the leaf-cell centres, so
//! flows of different strength compare; the observed order of convergence between two
//! resolutions is `log2(e_coarse / e_fine) / log2(h_coarse / h_fine)`.
//!
//! The iso-surface is checked where the viewer finds it: rays cast through each bake with
//! the viewer's own `exact` strategy and shading (this crate links the viewer, never the
//! reverse), and at every hit `p` the distance to the exact surface to first order,
//! `|Q_exact(p) − iso| / |∇Q_exact(p)|`, and the angle between the shading normal and the
//! exact `∇Q`.

use crate::chart::{Line, LogLogChart, PlotError};
use format::BrickFile;
use glam::DVec3;
use serde::Serialize;
use viewer::mesh::Meshes;
use viewer::ray::RayCaster;
use viewer::render::Scene;
use viewer::sampling::Strategy;
use viewer::transfer::Mode;
use viewer::view_state::ViewState;
use viewer::volume::Volume;

use files::limits::{check_memory, with_capacity, LimitError};

use crate::analytic::{self, Exact, Flow};
use crate::synth::{scene_grids, scene_layout, SynthError};
use preprocess::bake::memory::{bake_bytes, GridFootprint, CELL_BYTES, SINGLE_VELOCITY_SLOT_BYTES};
use preprocess::bake::{bake, BakeError, BakeOptions};
use preprocess::derive::Stencil;
use preprocess::fields::FieldKind;
use preprocess::grid::{AnyGrid, Vec3};
use preprocess::reconstruct::reconstruct_over;

mod plot;
mod surface;
#[cfg(test)]
mod tests;

pub use plot::save_plot;
use surface::{default_iso, surface_errors};

/// What to measure.
#[derive(Debug, Clone)]
pub struct AccuracyOptions {
    pub scene: String,
    /// Coarsest-grid resolutions to bake, in any order (reported as given).
    pub n0: Vec<u32>,
    /// Levels of the wake (single-grid scenes ignore it).
    pub levels: u32,
    pub stencil: Stencil,
    /// Random points for each reconstruction check.
    pub points: usize,
    pub seed: u64,
    /// Iso value of the surface checks; `None`: the seed report's 0.05 for the wakes,
    /// else a fifth of the largest exact Q over the scene's domain.
    pub iso: Option<f64>,
    /// The surface checks cast `rays`×`rays` camera rays (the viewer's default framing of
    /// the iso-surface).
    pub rays: u32,
    /// The fields baked and compared, of [`MEASURED`]; `q` is always among them (the
    /// reconstruction and surface checks use it). Fewer fields make a smaller archive: at
    /// n0 512 a single grid's four fields pass the format's 2 GiB.
    pub fields: Vec<String>,
}

impl Default for AccuracyOptions {
    fn default() -> Self {
        AccuracyOptions {
            scene: "wake".into(),
            n0: vec![32, 64],
            levels: 3,
            stencil: Stencil::Central,
            points: 20_000,
            seed: 1,
            iso: None,
            rays: 128,
            fields: MEASURED.map(String::from).to_vec(),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum AccuracyError {
    #[error("unknown scene `{0}`: expected one of {names}", names = analytic::SCENE_NAMES.join(", "))]
    UnknownScene(String),
    #[error(transparent)]
    Synth(#[from] SynthError),
    #[error("n0 {0}: {1}")]
    Bake(u32, BakeError),
    #[error("the file has no field `{0}`")]
    MissingField(&'static str),
    #[error("no resolutions given")]
    NoResolutions,
    /// The viewer refused the bake (a bug: a fresh bake always opens).
    #[error("n0 {0}: the viewer cannot open the bake: {1}")]
    View(u32, String),
    /// A resolution whose estimated peak ([`memory_needed`]) is over the shared limit.
    #[error("n0 {0}: {1}")]
    Memory(u32, LimitError),
    #[error(
        "--fields: {0} (the fields are q, which is always measured, speed, vorticity and lambda2)"
    )]
    Fields(String),
}

/// The baked fields compared with the flow, by file field name, in report order.
pub const MEASURED: [&str; 4] = ["q", "speed", "vorticity", "lambda2"];
/// Indices into [`MEASURED`] (and the per-quantity arrays below).
const Q: usize = 0;
const SPEED: usize = 1;
const VORTICITY: usize = 2;
const LAMBDA2: usize = 3;
/// The quantities reconstructed at random points (speed is not: it is no vortex measure).
const RECONSTRUCTED: [usize; 3] = [Q, VORTICITY, LAMBDA2];

/// The exact value of each of [`MEASURED`].
fn exact_values(e: &Exact) -> [f64; 4] {
    [e.q, e.speed, e.vorticity, e.lambda2]
}

/// Bytes per leaf cell a measurement of `fields` fields holds once its bake is done: the
/// file's fields (4 bytes each) and the exact |value| of each quantity kept for its
/// percentile (8 each), plus the bake's per-cell bookkeeping that is still held (bricks,
/// regions).
fn measure_cell_bytes(fields: u64) -> u64 {
    (4 + 8) * fields + CELL_BYTES
}

/// Which of [`MEASURED`] `fields` asks for; refuses unknown and repeated names and a list
/// without `q`.
fn measured(fields: &[String]) -> Result<[bool; 4], AccuracyError> {
    let mut on = [false; 4];
    for f in fields {
        let k = MEASURED
            .iter()
            .position(|m| m == f)
            .ok_or_else(|| AccuracyError::Fields(format!("unknown field \"{f}\"")))?;
        if on[k] {
            return Err(AccuracyError::Fields(format!("\"{f}\" is given twice")));
        }
        on[k] = true;
    }
    if !on[Q] {
        return Err(AccuracyError::Fields("q is missing".into()));
    }
    Ok(on)
}

/// The estimated peak of measuring `fields` fields of `scene` at `n0`: the larger of its
/// bake (the one estimate every bake is checked with, [`preprocess::bake::memory`]) and what
/// the comparison holds afterwards, both with the sampled grids' leaves. From the layout
/// alone, so it is known before anything is sampled.
pub fn memory_needed(scene: &str, n0: u32, levels: u32, fields: u64) -> Result<u64, SynthError> {
    let layouts = scene_layout(scene, n0, levels)?;
    let grids: Vec<(GridFootprint, u64)> = layouts
        .iter()
        .map(|l| {
            (
                GridFootprint::leaves::<Vec3>(l.leaf_count(), l.voxel_count()),
                SINGLE_VELOCITY_SLOT_BYTES,
            )
        })
        .collect();
    let bake = bake_bytes(&grids, &[], fields, &preprocess::bake::Spill::default());
    let (decoded, cells) = grids.iter().fold((0u64, 0u64), |(d, c), (f, _)| {
        (d.saturating_add(f.decoded), c.saturating_add(f.cells))
    });
    let after = decoded.saturating_add(cells.saturating_mul(measure_cell_bytes(fields)));
    Ok(bake.max(after))
}

/// Absolute and relative error statistics of one quantity over a set of points.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct ErrorStats {
    pub points: u64,
    pub max: f64,
    pub rms: f64,
    /// `max` over the scale (99th percentile of the exact |value| at leaf-cell centres).
    pub max_rel: f64,
    pub rms_rel: f64,
}

#[derive(Default)]
struct Acc {
    n: u64,
    max: f64,
    sum2: f64,
}

impl Acc {
    fn add(&mut self, e: f64) {
        if e.is_finite() {
            self.n += 1;
            self.max = self.max.max(e.abs());
            self.sum2 += e * e;
        }
    }
    fn stats(&self, scale: f64) -> ErrorStats {
        let rms = if self.n == 0 {
            0.0
        } else {
            (self.sum2 / self.n as f64).sqrt()
        };
        let s = if scale > 0.0 { scale } else { 1.0 };
        ErrorStats {
            points: self.n,
            max: self.max,
            rms,
            max_rel: self.max / s,
            rms_rel: rms / s,
        }
    }
}

/// Stored-value errors of one level.
#[derive(Debug, Clone, Serialize)]
pub struct LevelReport {
    /// 0 = finest.
    pub level: u32,
    pub cell_width: f64,
    pub q: ErrorStats,
    pub speed: ErrorStats,
    pub vorticity: ErrorStats,
    pub lambda2: ErrorStats,
}

/// Everything measured at one resolution.
#[derive(Debug, Clone, Serialize)]
pub struct ResolutionReport {
    pub n0: u32,
    /// Finest cell width, world units.
    pub finest_width: f64,
    pub leaf_cells: u64,
    /// 99th percentile of exact |Q|, speed, vorticity magnitude and |λ2| at the leaf-cell
    /// centres.
    pub q_scale: f64,
    pub speed_scale: f64,
    pub vorticity_scale: f64,
    pub lambda2_scale: f64,
    /// Stored values at leaf-cell centres, all levels together.
    pub stored_q: ErrorStats,
    pub stored_speed: ErrorStats,
    pub stored_vorticity: ErrorStats,
    pub stored_lambda2: ErrorStats,
    pub levels: Vec<LevelReport>,
    /// Reconstructed values at random points in the data.
    pub reconstructed_q: ErrorStats,
    pub reconstructed_vorticity: ErrorStats,
    pub reconstructed_lambda2: ErrorStats,
    /// Reconstructed values at random points within two coarse cells of a level boundary
    /// (no points for single-grid scenes).
    pub boundary_q: ErrorStats,
    pub boundary_vorticity: ErrorStats,
    pub boundary_lambda2: ErrorStats,
    pub surface: SurfaceReport,
}

/// The iso-surface as the viewer's `exact` strategy finds it, against the exact flow.
#[derive(Debug, Clone, Serialize)]
pub struct SurfaceReport {
    pub iso: f64,
    pub rays: u64,
    /// Rays that hit the surface where the flow is smooth (hits within two cells of a
    /// non-smooth surface of the flow, the wake's sphere, are left out and not counted).
    pub hits: u64,
    /// `|Q_exact(p) − iso| / |∇Q_exact(p)|` at the hits, world units; the `_rel` fields are
    /// in finest cell widths.
    pub position: ErrorStats,
    /// Angle between the shading normal and the exact `∇Q` at the hits, degrees (the
    /// `_rel` fields are the same numbers).
    pub normal_deg: ErrorStats,
}

/// Observed order of convergence between two consecutive resolutions (by finest width).
#[derive(Debug, Clone, Serialize)]
pub struct OrderReport {
    pub n0_coarse: u32,
    pub n0_fine: u32,
    pub stored_q_rms: f64,
    pub stored_q_max: f64,
    /// Orders of the fields besides Q: `None` when a field is not measured (`fields`).
    pub stored_speed_rms: Option<f64>,
    pub stored_vorticity_rms: Option<f64>,
    pub stored_vorticity_max: Option<f64>,
    pub stored_lambda2_rms: Option<f64>,
    pub stored_lambda2_max: Option<f64>,
    pub reconstructed_q_rms: f64,
    pub reconstructed_vorticity_rms: Option<f64>,
    pub reconstructed_lambda2_rms: Option<f64>,
    pub boundary_q_rms: Option<f64>,
    pub boundary_vorticity_rms: Option<f64>,
    pub boundary_lambda2_rms: Option<f64>,
    /// Of the world-unit surface position error and of the normal angle (RMS); `None`
    /// when a resolution had no hits.
    pub surface_position_rms: Option<f64>,
    pub normal_angle_rms: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct AccuracyReport {
    pub scene: String,
    pub stencil: &'static str,
    pub resolutions: Vec<ResolutionReport>,
    pub orders: Vec<OrderReport>,
}

/// Small deterministic random numbers (xorshift64*), uniform in [0, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn field_index(file: &BrickFile, name: &'static str) -> Result<usize, AccuracyError> {
    file.fields
        .iter()
        .position(|f| f.name == name)
        .ok_or(AccuracyError::MissingField(name))
}

/// The basis-method reconstruction at `p` over the bricks of the region holding it.
fn reconstruct(file: &BrickFile, f: usize, p: [f64; 3]) -> Option<f64> {
    let r = file.region_at(p)?;
    reconstruct_over(file, file.bricks_of(r), f, p)
}

fn percentile_99(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * 0.99).round() as usize]
}

/// Boxes (world units) of the finer grids whose faces are level boundaries, with the cell
/// width of the next coarser level (what "two coarse cells" means there).
fn level_boundaries(scene: &str, n0: u32, levels: u32) -> Result<Vec<([f64; 6], f64)>, SynthError> {
    let layout = scene_layout(scene, n0, levels)?;
    // Finest first; every grid but the coarsest has a boundary with the next coarser one.
    Ok(layout
        .windows(2)
        .map(|w| {
            let g = &w[0];
            let lo = g.lo.map(|i| i as f64 * g.voxel_size);
            let hi = g.hi.map(|i| i as f64 * g.voxel_size);
            ([lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]], w[1].voxel_size)
        })
        .collect())
}

fn measure(
    flow: &dyn Flow,
    opts: &AccuracyOptions,
    n0: u32,
    iso: f64,
) -> Result<ResolutionReport, AccuracyError> {
    let grids: Vec<AnyGrid> = scene_grids(&opts.scene, n0, opts.levels)?
        .into_iter()
        .map(AnyGrid::Vec3s)
        .collect();
    let on = measured(&opts.fields)?;
    let kinds = [
        FieldKind::Q,
        FieldKind::Speed,
        FieldKind::Vorticity,
        FieldKind::Lambda2,
    ];
    let bopts = BakeOptions {
        stencil: opts.stencil,
        fields: Some(
            kinds
                .into_iter()
                .zip(on)
                .filter_map(|(k, on)| on.then_some(k))
                .collect(),
        ),
        ..BakeOptions::default()
    };
    let (file, summary) = bake(grids, &bopts).map_err(|e| AccuracyError::Bake(n0, e))?;
    // The file's field of each measured quantity.
    let mut fields: [Option<usize>; 4] = [None; 4];
    for k in 0..MEASURED.len() {
        if on[k] {
            fields[k] = Some(field_index(&file, MEASURED[k])?);
        }
    }
    let fq = field_index(&file, MEASURED[Q])?;

    // Errors at every leaf-cell centre, per level, brick after brick; the exact |value|s
    // are kept for the percentiles that scale them (room for all of them at once: growing
    // the lists by doubling would need half as much again while they move).
    let cells = summary.leaf_cells as usize;
    let mut magnitudes: Vec<Vec<f64>> = Vec::with_capacity(MEASURED.len());
    for (name, on) in MEASURED.iter().zip(on) {
        let room = if on { cells } else { 0 };
        magnitudes.push(
            with_capacity(
                format!("the exact {name} at {} leaf cells", summary.leaf_cells),
                room,
            )
            .map_err(|e| AccuracyError::Memory(n0, e))?,
        );
    }
    let nlevels = file.levels.len();
    let mut all: [Acc; 4] = Default::default();
    let mut per_level: Vec<[Acc; 4]> = (0..nlevels).map(|_| Default::default()).collect();
    let mut widths = vec![0.0; nlevels];
    for b in &file.bricks {
        let [nx, ny, nz] = b.dims.map(|d| d as usize);
        let mut level = per_level.get_mut(b.level as usize);
        if let Some(w) = widths.get_mut(b.level as usize) {
            *w = b.cell_width;
        }
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let c = [x, y, z];
                    let p = [0, 1, 2].map(|a| b.origin[a] + c[a] as f64 * b.cell_width);
                    let i = b.first_value as usize + x + nx * (y + ny * z);
                    let exact = exact_values(&flow.exact(p));
                    for (k, f) in fields.iter().enumerate() {
                        let Some(f) = *f else { continue };
                        let e = f64::from(file.fields[f].values[i]) - exact[k];
                        all[k].add(e);
                        if let Some(l) = level.as_deref_mut() {
                            l[k].add(e);
                        }
                        magnitudes[k].push(exact[k].abs());
                    }
                }
            }
        }
    }
    let scales: Vec<f64> = magnitudes.into_iter().map(percentile_99).collect();
    let levels = (0..nlevels)
        .filter(|&l| per_level[l][Q].n > 0)
        .map(|l| {
            let s = |k: usize| per_level[l][k].stats(scales[k]);
            LevelReport {
                level: l as u32,
                cell_width: widths[l],
                q: s(Q),
                speed: s(SPEED),
                vorticity: s(VORTICITY),
                lambda2: s(LAMBDA2),
            }
        })
        .collect();

    // Reconstruction at random points of the data's bounds (points outside the data
    // are skipped and redrawn, up to a bounded number of tries).
    let mut rng = Rng(opts.seed.max(1).wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
    let (lo, hi) = (file.bounds.min, file.bounds.max);
    let mut rec: [Acc; 4] = Default::default();
    let reconstruct_at = |p: [f64; 3], acc: &mut [Acc; 4]| {
        if let Some(v) = reconstruct(&file, fq, p) {
            let exact = exact_values(&flow.exact(p));
            acc[Q].add(v - exact[Q]);
            for k in RECONSTRUCTED.into_iter().filter(|&k| k != Q) {
                if let Some(v) = fields[k].and_then(|f| reconstruct(&file, f, p)) {
                    acc[k].add(v - exact[k]);
                }
            }
        }
    };
    let mut tries = 0usize;
    while (rec[Q].n as usize) < opts.points && tries < 20 * opts.points.max(1) {
        tries += 1;
        let p = [0, 1, 2].map(|a| lo[a] + rng.next() * (hi[a] - lo[a]));
        reconstruct_at(p, &mut rec);
    }
    // Near level boundaries: a random point on a random face of a finer box, moved off
    // the face by up to two coarse cells either way.
    let bounds = level_boundaries(&opts.scene, n0, opts.levels)?;
    let mut near: [Acc; 4] = Default::default();
    if !bounds.is_empty() {
        let mut tries = 0usize;
        while (near[Q].n as usize) < opts.points && tries < 20 * opts.points.max(1) {
            tries += 1;
            let k = ((rng.next() * bounds.len() as f64) as usize).min(bounds.len() - 1);
            let (b, w) = bounds[k];
            let axis = ((rng.next() * 3.0) as usize).min(2);
            let upper = rng.next() < 0.5;
            let mut p = [0, 1, 2].map(|a| b[a] + rng.next() * (b[a + 3] - b[a]));
            let face = if upper { b[axis + 3] } else { b[axis] };
            p[axis] = face + (2.0 * rng.next() - 1.0) * 2.0 * w;
            reconstruct_at(p, &mut near);
        }
    }
    let surface = surface_errors(flow, &file, opts, iso, n0)?;
    let stats = |acc: &[Acc; 4], k: usize| acc[k].stats(scales[k]);
    Ok(ResolutionReport {
        n0,
        finest_width: file.levels.first().map_or(0.0, |l| l.cell_width),
        leaf_cells: summary.leaf_cells,
        q_scale: scales[Q],
        speed_scale: scales[SPEED],
        vorticity_scale: scales[VORTICITY],
        lambda2_scale: scales[LAMBDA2],
        stored_q: stats(&all, Q),
        stored_speed: stats(&all, SPEED),
        stored_vorticity: stats(&all, VORTICITY),
        stored_lambda2: stats(&all, LAMBDA2),
        levels,
        reconstructed_q: stats(&rec, Q),
        reconstructed_vorticity: stats(&rec, VORTICITY),
        reconstructed_lambda2: stats(&rec, LAMBDA2),
        boundary_q: stats(&near, Q),
        boundary_vorticity: stats(&near, VORTICITY),
        boundary_lambda2: stats(&near, LAMBDA2),
        surface,
    })
}

/// `log(e_a / e_b) / log(h_a / h_b)`.
fn order(ea: f64, eb: f64, ha: f64, hb: f64) -> f64 {
    (ea / eb).ln() / (ha / hb).ln()
}

/// Measures every resolution of `opts.n0` (each baked in memory), calling `progress` with
/// each n0 as it starts.
pub fn accuracy(
    opts: &AccuracyOptions,
    progress: &mut dyn FnMut(u32),
) -> Result<AccuracyReport, AccuracyError> {
    let flow = analytic::scene(&opts.scene)
        .ok_or_else(|| AccuracyError::UnknownScene(opts.scene.clone()))?;
    if opts.n0.is_empty() {
        return Err(AccuracyError::NoResolutions);
    }
    let nfields = measured(&opts.fields)?.iter().filter(|&&on| on).count() as u64;
    let iso = match opts.iso {
        Some(v) => v,
        None => default_iso(flow.as_ref(), opts)?,
    };
    // Every resolution is checked before the first is sampled: a run that cannot finish
    // does not start.
    for &n0 in &opts.n0 {
        let need = memory_needed(&opts.scene, n0, opts.levels, nfields)?;
        check_memory(
            format!(
                "measuring scene \"{}\" (sampled, baked and compared in memory)",
                opts.scene
            ),
            need,
        )
        .map_err(|e| AccuracyError::Memory(n0, e))?;
    }
    let mut resolutions = Vec::new();
    for &n0 in &opts.n0 {
        progress(n0);
        resolutions.push(measure(flow.as_ref(), opts, n0, iso)?);
    }
    let mut sorted: Vec<&ResolutionReport> = resolutions.iter().collect();
    sorted.sort_by(|a, b| b.finest_width.total_cmp(&a.finest_width));
    let orders = sorted
        .windows(2)
        .filter(|w| w[0].finest_width > w[1].finest_width)
        .map(|w| {
            let (a, b) = (w[0], w[1]);
            let o = |ea: f64, eb: f64| order(ea, eb, a.finest_width, b.finest_width);
            // The order of errors measured at both resolutions (RMS, or max).
            let both = |ea: &ErrorStats, eb: &ErrorStats| {
                (ea.points > 0 && eb.points > 0).then(|| o(ea.rms, eb.rms))
            };
            let both_max = |ea: &ErrorStats, eb: &ErrorStats| {
                (ea.points > 0 && eb.points > 0).then(|| o(ea.max, eb.max))
            };
            OrderReport {
                n0_coarse: a.n0,
                n0_fine: b.n0,
                stored_q_rms: o(a.stored_q.rms, b.stored_q.rms),
                stored_q_max: o(a.stored_q.max, b.stored_q.max),
                stored_speed_rms: both(&a.stored_speed, &b.stored_speed),
                stored_vorticity_rms: both(&a.stored_vorticity, &b.stored_vorticity),
                stored_vorticity_max: both_max(&a.stored_vorticity, &b.stored_vorticity),
                stored_lambda2_rms: both(&a.stored_lambda2, &b.stored_lambda2),
                stored_lambda2_max: both_max(&a.stored_lambda2, &b.stored_lambda2),
                reconstructed_q_rms: o(a.reconstructed_q.rms, b.reconstructed_q.rms),
                reconstructed_vorticity_rms: both(
                    &a.reconstructed_vorticity,
                    &b.reconstructed_vorticity,
                ),
                reconstructed_lambda2_rms: both(&a.reconstructed_lambda2, &b.reconstructed_lambda2),
                boundary_q_rms: both(&a.boundary_q, &b.boundary_q),
                boundary_vorticity_rms: both(&a.boundary_vorticity, &b.boundary_vorticity),
                boundary_lambda2_rms: both(&a.boundary_lambda2, &b.boundary_lambda2),
                surface_position_rms: (a.surface.hits > 0 && b.surface.hits > 0)
                    .then(|| o(a.surface.position.rms, b.surface.position.rms)),
                normal_angle_rms: (a.surface.hits > 0 && b.surface.hits > 0)
                    .then(|| o(a.surface.normal_deg.rms, b.surface.normal_deg.rms)),
            }
        })
        .collect();
    Ok(AccuracyReport {
        scene: opts.scene.clone(),
        stencil: match opts.stencil {
            Stencil::Central => "central",
            Stencil::CrossLevel => "cross-level",
        },
        resolutions,
        orders,
    })
}
