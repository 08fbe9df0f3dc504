//! Synthetic scenes: analytic flows sampled onto grids, as `qbricks-bake synth` writes them.
//!
//! # Layout
//! All grids share one world-aligned lattice: a grid of voxel size `h` has voxel `(i, j, k)`
//! centred at `((i + ½) h, (j + ½) h, (k + ½) h)` (transform: scale `h`, translation `h/2`),
//! so its cells are `[i h, (i + 1) h)` and every cell of a level is exactly covered by 2³
//! cells of the next finer level. Index coordinates are negative left of the world origin.
//!
//! * `wake`: `levels` nested boxes. The coarsest covers the scene domain
//!   x ∈ [-2, 6], y, z ∈ [-2, 2] with voxel size `8 / n0` (so `n0` voxels along x, the longest
//!   axis; the box snaps outward to the world-aligned lattice, so when 4 does not divide
//!   `n0` each side grows by less than one voxel). Each finer level halves the voxel size and covers a box interpolated
//!   linearly between the domain and the core box x ∈ [-0.75, 5], y, z ∈ [-0.75, 0.75]
//!   (sphere and ring train), snapped outward to the next coarser level's cells so that
//!   boxes nest exactly. Grids are named `vel_l0` (finest) … `vel_l{levels-1}` (coarsest)
//!   and returned in that order.
//! * `wake-single`, `lamb-oseen`, `burgers`, `abc`: one grid named `vel` over the scene
//!   domain (`wake-single`: the `wake` domain; the others: [-1, 1]³) with `n0` voxels along
//!   the longest axis; `levels` is ignored.
//!
//! Every voxel whose centre lies in a grid's box is active and holds the exact velocity at
//! its centre (f32); leaves at box edges have partial active masks, inactive voxels hold the
//! background (0, 0, 0). No tiles are written. Results are deterministic.

use format::Aabb;
use rayon::prelude::*;
use thiserror::Error;

use files::limits::{self, LimitError};

use crate::analytic::{self, Flow};
use crate::bake::memory::leaf_bytes;
use crate::grid::{leaf_offset, AnyGrid, Grid, Leaf, Transform, Vec3, LEAF_DIM, LEAF_VOXELS};
use crate::vdb::write::{
    write_vdb_with, Compression, MetaMap, MetaValue, WriteError, WriteOptions,
};

/// Most bytes of leaves a scene may allocate (velocity grids, plus the speed grids when
/// asked for). Leaves are counted whole, as `sample_grid` allocates them, partial leaves at
/// box edges included: a voxel count alone underestimates memory (a leaf of 3-vectors takes
/// about 6.2 kB however few of its 512 voxels are active), and `synth` holds every grid in
/// memory until the file is written. 4 GiB of leaves is a peak of about 10 GB once the
/// writer's buffers are added, well past any scene the tests or the README use (the largest,
/// `wake --n0 160 --levels 3`, takes 140 MB) and below what the project's machines have.
pub(crate) const MAX_LEAF_BYTES: u64 = 4 << 30;

/// What `synth` holds at its peak per byte of leaves: the grids and, while the file is
/// written, every grid's encoded body (at most as large as its leaves); measured 2.0 (a
/// 256³ Lamb–Oseen grid, 204 MB of leaves, 413 MB resident at the peak), taken as 2.5.
const PEAK_PER_LEAF_BYTE: (u64, u64) = (5, 2);

#[derive(Debug, Error)]
pub enum SynthError {
    #[error(transparent)]
    Write(#[from] WriteError),
    #[error("unknown scene {name:?} (expected one of: {})", analytic::SCENE_NAMES.join(", "))]
    UnknownScene { name: String },
    #[error("{what} must be in {min}..={max}, found {found}")]
    OutOfRange {
        what: &'static str,
        min: u32,
        max: u32,
        found: u32,
    },
    /// Over [`MAX_LEAF_BYTES`], whatever the machine.
    #[error(
        "scene {name:?} with n0 {n0} in {grids} grid(s) needs {leaves} leaves ({} MiB of grid memory), more than the limit of {} MiB; use a smaller --n0 or fewer --levels",
        bytes >> 20,
        limit >> 20
    )]
    TooLarge {
        name: String,
        n0: u32,
        grids: usize,
        leaves: u64,
        bytes: u64,
        limit: u64,
    },
    /// Within [`MAX_LEAF_BYTES`] but over what this machine (or `ulimit -v`) leaves: the
    /// shared limit of every command.
    #[error("{0}; use a smaller --n0 or fewer --levels")]
    Memory(LimitError),
}

const WAKE_DOMAIN: Aabb = Aabb {
    min: [-2.0, -2.0, -2.0],
    max: [6.0, 2.0, 2.0],
};
const WAKE_CORE: Aabb = Aabb {
    min: [-0.75, -0.75, -0.75],
    max: [5.0, 0.75, 0.75],
};
const UNIT_DOMAIN: Aabb = Aabb {
    min: [-1.0, -1.0, -1.0],
    max: [1.0, 1.0, 1.0],
};

/// One grid of a scene layout: its name, voxel size and active index box (half-open).
#[derive(Debug, Clone, PartialEq)]
pub struct GridLayout {
    pub name: String,
    pub voxel_size: f64,
    /// First active voxel index per axis.
    pub lo: [i64; 3],
    /// One past the last active voxel index per axis.
    pub hi: [i64; 3],
}

impl GridLayout {
    /// Active voxels in the box, saturating at `u64::MAX` (an allowed `--n0` with ten levels
    /// has a finest box of 2^75 voxels, which a plain product would overflow).
    pub(crate) fn voxel_count(&self) -> u64 {
        saturating_product((0..3).map(|a| self.hi[a].saturating_sub(self.lo[a])))
    }

    /// Leaves [`sample_grid`] allocates for this box (every 8³ block the box touches),
    /// saturating at `u64::MAX`.
    pub(crate) fn leaf_count(&self) -> u64 {
        let d = i64::from(LEAF_DIM);
        saturating_product((0..3).map(|a| {
            if self.hi[a] <= self.lo[a] {
                0
            } else {
                (self.hi[a] - 1).div_euclid(d) - self.lo[a].div_euclid(d) + 1
            }
        }))
    }

    pub(crate) fn transform(&self) -> Transform {
        Transform {
            voxel_size: [self.voxel_size; 3],
            translation: [0.5 * self.voxel_size; 3],
        }
    }

    /// World-space centre of voxel `ijk`.
    pub(crate) fn centre(&self, ijk: [i64; 3]) -> [f64; 3] {
        ijk.map(|i| (i as f64 + 0.5) * self.voxel_size)
    }
}

/// The grids (finest first) that [`scene_grids`] fills, without sampling anything.
pub fn scene_layout(scene: &str, n0: u32, levels: u32) -> Result<Vec<GridLayout>, SynthError> {
    let (domain, multi) = match scene {
        "wake" => (WAKE_DOMAIN, true),
        "wake-single" => (WAKE_DOMAIN, false),
        "lamb-oseen" | "burgers" | "abc" | "ring-plume" => (UNIT_DOMAIN, false),
        _ => {
            return Err(SynthError::UnknownScene {
                name: scene.to_string(),
            })
        }
    };
    check_range("n0", n0, 2, 1 << 16)?;
    let levels = if multi {
        check_range("levels", levels, 1, 10)?;
        levels
    } else {
        1
    };
    let extent = (0..3)
        .map(|a| domain.max[a] - domain.min[a])
        .fold(0.0, f64::max);
    let coarse = extent / f64::from(n0);
    let eps = 1e-9;
    // Coarsest first; `c` counts levels from the coarsest.
    let mut out: Vec<GridLayout> = Vec::with_capacity(levels as usize);
    for c in 0..levels {
        let h = coarse / f64::from(1u32 << c);
        let (lo, hi) = if c == 0 {
            (
                domain.min.map(|v| (v / h + eps).floor() as i64),
                domain.max.map(|v| (v / h - eps).ceil() as i64),
            )
        } else {
            let t = f64::from(c) / f64::from(levels - 1);
            let parent = 2.0 * h;
            let mut lo = [0i64; 3];
            let mut hi = [0i64; 3];
            for a in 0..3 {
                let bmin = domain.min[a] + t * (WAKE_CORE.min[a] - domain.min[a]);
                let bmax = domain.max[a] + t * (WAKE_CORE.max[a] - domain.max[a]);
                lo[a] = 2 * (bmin / parent + eps).floor() as i64;
                hi[a] = 2 * (bmax / parent - eps).ceil() as i64;
            }
            (lo, hi)
        };
        let name = if multi {
            format!("vel_l{}", levels - 1 - c)
        } else if scene == "ring-plume" {
            // Named as Blender's Mantaflow names its cache grids.
            "velocity".to_string()
        } else {
            "vel".to_string()
        };
        out.push(GridLayout {
            name,
            voxel_size: h,
            lo,
            hi,
        });
    }
    out.reverse();
    check_memory(scene, n0, &out, false)?;
    Ok(out)
}

fn saturating_product(extents: impl Iterator<Item = i64>) -> u64 {
    extents.fold(1u64, |acc, e| acc.saturating_mul(e.max(0).unsigned_abs()))
}

/// Refuses a scene whose leaves (velocity, plus speed when `speed_grids`) would take more than
/// [`MAX_LEAF_BYTES`], whatever the machine, before anything is sampled. Returns the leaf
/// count and bytes.
pub(crate) fn check_memory(
    scene: &str,
    n0: u32,
    layouts: &[GridLayout],
    speed_grids: bool,
) -> Result<(u64, u64), SynthError> {
    let per_leaf = leaf_bytes::<Vec3>() + if speed_grids { leaf_bytes::<f32>() } else { 0 };
    let leaves = layouts
        .iter()
        .fold(0u64, |acc, l| acc.saturating_add(l.leaf_count()));
    let bytes = leaves.saturating_mul(per_leaf);
    if bytes > MAX_LEAF_BYTES {
        return Err(SynthError::TooLarge {
            name: scene.to_string(),
            n0,
            grids: layouts.len(),
            leaves,
            bytes,
            limit: MAX_LEAF_BYTES,
        });
    }
    Ok((leaves, bytes))
}

/// [`check_memory`], and then the peak of writing the scene (leaves and the file's encoded
/// grids) against the shared memory limit ([`files::limits::check_memory`]), which depends
/// on the machine and `ulimit -v`.
fn check_write_memory(
    scene: &str,
    n0: u32,
    layouts: &[GridLayout],
    speed_grids: bool,
) -> Result<(), SynthError> {
    let (leaves, bytes) = check_memory(scene, n0, layouts, speed_grids)?;
    let (num, den) = PEAK_PER_LEAF_BYTE;
    limits::check_memory(
        format!(
            "scene {scene:?} with n0 {n0} in {} grid(s) ({leaves} leaves, sampled and written)",
            layouts.len()
        ),
        bytes.saturating_mul(num) / den,
    )
    .map_err(SynthError::Memory)
}

fn check_range(what: &'static str, found: u32, min: u32, max: u32) -> Result<(), SynthError> {
    if (min..=max).contains(&found) {
        Ok(())
    } else {
        Err(SynthError::OutOfRange {
            what,
            min,
            max,
            found,
        })
    }
}

/// Samples scene `scene` onto its grids (see the module docs for the layout), finest first.
pub fn scene_grids(scene: &str, n0: u32, levels: u32) -> Result<Vec<Grid<Vec3>>, SynthError> {
    scene_grids_with(scene, n0, levels, false, 1)
}

/// As [`scene_grids`]; with `staggered`, as MAC grids (see [`sample_grid_with`]); `frame`
/// (1-based) picks the time of a time-dependent scene (`ring-plume`).
pub fn scene_grids_with(
    scene: &str,
    n0: u32,
    levels: u32,
    staggered: bool,
    frame: u64,
) -> Result<Vec<Grid<Vec3>>, SynthError> {
    let layouts = scene_layout(scene, n0, levels)?;
    let flow = analytic::scene_at(scene, frame).ok_or_else(|| SynthError::UnknownScene {
        name: scene.to_string(),
    })?;
    Ok(layouts
        .iter()
        .map(|layout| sample_grid_with(flow.as_ref(), layout, staggered))
        .collect())
}

/// Origins of the leaves that hold `layout`'s box.
fn leaf_origins(layout: &GridLayout) -> Vec<[i64; 3]> {
    let d = i64::from(LEAF_DIM);
    let first = layout.lo.map(|v| v.div_euclid(d) * d);
    let counts: Vec<i64> = (0..3)
        .map(|a| (layout.hi[a] - first[a] + d - 1).div_euclid(d).max(0))
        .collect();
    let mut origins = Vec::with_capacity((counts[0] * counts[1] * counts[2]) as usize);
    for x in 0..counts[0] {
        for y in 0..counts[1] {
            for z in 0..counts[2] {
                origins.push([first[0] + x * d, first[1] + y * d, first[2] + z * d]);
            }
        }
    }
    origins
}

/// Samples `flow` at the voxel centres of `layout`'s box.
pub fn sample_grid(flow: &dyn Flow, layout: &GridLayout) -> Grid<Vec3> {
    sample_grid_with(flow, layout, false)
}

/// Samples `flow` on `layout`'s box: at voxel centres, or with `staggered` as a MAC grid in
/// OpenVDB's convention (component `c` of voxel `i` at the lower face, centre − ½h·e_c).
/// The active voxels are the same either way, so the upper faces of the last cells along
/// each axis are not stored (as in a solver's MAC grid of the same size as its cell grid).
pub(crate) fn sample_grid_with(
    flow: &dyn Flow,
    layout: &GridLayout,
    staggered: bool,
) -> Grid<Vec3> {
    let origins = leaf_origins(layout);
    let leaves = origins
        .par_iter()
        .map(|&origin| sample_leaf(flow, layout, origin, staggered))
        .collect();
    Grid {
        name: layout.name.clone(),
        transform: layout.transform(),
        background: [0.0; 3],
        leaves,
        tiles: Vec::new(),
    }
}

fn sample_leaf(
    flow: &dyn Flow,
    layout: &GridLayout,
    origin: [i64; 3],
    staggered: bool,
) -> Leaf<Vec3> {
    let mut active = [0u64; 8];
    let mut values = Box::new([[0.0f32; 3]; LEAF_VOXELS]);
    let inside = |a: usize, v: i64| v >= layout.lo[a] && v < layout.hi[a];
    for x in 0..8usize {
        let i = origin[0] + x as i64;
        if !inside(0, i) {
            continue;
        }
        for y in 0..8usize {
            let j = origin[1] + y as i64;
            if !inside(1, j) {
                continue;
            }
            for z in 0..8usize {
                let k = origin[2] + z as i64;
                if !inside(2, k) {
                    continue;
                }
                let n = leaf_offset(x, y, z);
                let p = layout.centre([i, j, k]);
                values[n] = if staggered {
                    std::array::from_fn(|c| {
                        let mut f = p;
                        f[c] -= 0.5 * layout.voxel_size;
                        flow.velocity(f)[c] as f32
                    })
                } else {
                    let u = flow.velocity(p);
                    [u[0] as f32, u[1] as f32, u[2] as f32]
                };
                active[n >> 6] |= 1u64 << (n & 63);
            }
        }
    }
    Leaf {
        // Index boxes stay far inside i32 (checked by MAX_LEAF_BYTES and the n0 range).
        origin: origin.map(|v| v as i32),
        active,
        values,
    }
}

/// What `qbricks-bake synth` writes.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthOptions {
    pub scene: String,
    pub n0: u32,
    pub levels: u32,
    pub compression: Compression,
    /// Also write the speed `|u|` of each velocity grid as a float grid named
    /// `speed` / `speed_l<k>` with the same active voxels (a scalar-grid test input).
    pub speed_grids: bool,
    /// Write the velocity grids as MAC grids (class `staggered`, see
    /// [`sample_grid_with`]); speed grids stay cell-centred.
    pub staggered: bool,
    /// Frame (1-based) of a time-dependent scene (`ring-plume`); ignored by the others.
    pub frame: u64,
}

/// One written grid, for the command's summary.
#[derive(Debug, Clone, PartialEq)]
pub struct GridSummary {
    pub name: String,
    pub value_type: &'static str,
    pub voxel_size: f64,
    pub active_voxels: u64,
    pub leaves: usize,
}

/// Samples a scene and writes it as a VDB file. Returns per-grid counts and the file size.
///
/// Grid metadata besides what the writer always adds: `scene` (string), `level` (int32,
/// 0 = finest), `origin` (vec3d, world-space minimum corner of the grid's box) and
/// `dx` (double, voxel size). File metadata: `scene`, `n0`, `levels`.
pub fn write_scene(
    path: &std::path::Path,
    opts: &SynthOptions,
) -> Result<(Vec<GridSummary>, u64), SynthError> {
    let layouts = scene_layout(&opts.scene, opts.n0, opts.levels)?;
    check_write_memory(&opts.scene, opts.n0, &layouts, opts.speed_grids)?;
    let velocity = scene_grids_with(
        &opts.scene,
        opts.n0,
        opts.levels,
        opts.staggered,
        opts.frame,
    )?;
    let mut grids: Vec<AnyGrid> = Vec::new();
    let mut metadata: Vec<MetaMap> = Vec::new();
    let mut summary = Vec::new();
    let meta_for = |layout: &GridLayout, level: usize| {
        let mut m = MetaMap::new();
        m.insert("scene".into(), MetaValue::String(opts.scene.clone()));
        m.insert("level".into(), MetaValue::Int32(level as i32));
        m.insert(
            "origin".into(),
            MetaValue::Vec3d(layout.lo.map(|v| v as f64 * layout.voxel_size)),
        );
        m.insert("dx".into(), MetaValue::Double(layout.voxel_size));
        m
    };
    for (level, (grid, layout)) in velocity.iter().zip(&layouts).enumerate() {
        summary.push(GridSummary {
            name: grid.name.clone(),
            value_type: "vec3s",
            voxel_size: layout.voxel_size,
            active_voxels: grid.active_voxel_count(),
            leaves: grid.leaves.len(),
        });
        let mut m = meta_for(layout, level);
        if opts.staggered {
            m.insert("class".into(), MetaValue::String("staggered".into()));
        }
        metadata.push(m);
    }
    let speed: Vec<Grid<f32>> = if opts.speed_grids && opts.staggered {
        let mut centred = scene_grids(&opts.scene, opts.n0, opts.levels)?;
        for (c, v) in centred.iter_mut().zip(&velocity) {
            c.name.clone_from(&v.name);
        }
        centred.iter().map(speed_grid).collect()
    } else if opts.speed_grids {
        velocity.iter().map(speed_grid).collect()
    } else {
        Vec::new()
    };
    grids.extend(velocity.into_iter().map(AnyGrid::Vec3s));
    for (level, (grid, layout)) in speed.into_iter().zip(&layouts).enumerate() {
        summary.push(GridSummary {
            name: grid.name.clone(),
            value_type: "float",
            voxel_size: layout.voxel_size,
            active_voxels: grid.active_voxel_count(),
            leaves: grid.leaves.len(),
        });
        metadata.push(meta_for(layout, level));
        grids.push(AnyGrid::Float(grid));
    }
    if opts.scene == "ring-plume" {
        // The smoke the ring carries, at voxel centres (class "fog volume", as Mantaflow).
        let plume = analytic::RingPlume::frame(opts.frame);
        for (level, layout) in layouts.iter().enumerate() {
            let density = sample_scalar("density", layout, |p| plume.density(p));
            summary.push(GridSummary {
                name: density.name.clone(),
                value_type: "float",
                voxel_size: layout.voxel_size,
                active_voxels: density.active_voxel_count(),
                leaves: density.leaves.len(),
            });
            let mut m = meta_for(layout, level);
            m.insert("class".into(), MetaValue::String("fog volume".into()));
            metadata.push(m);
            grids.push(AnyGrid::Float(density));
        }
    }
    let mut options = WriteOptions::new(opts.compression);
    options.grid_metadata = metadata;
    options
        .file_metadata
        .insert("scene".into(), MetaValue::String(opts.scene.clone()));
    options
        .file_metadata
        .insert("n0".into(), MetaValue::Int32(opts.n0 as i32));
    options
        .file_metadata
        .insert("levels".into(), MetaValue::Int32(opts.levels as i32));
    if opts.scene == "ring-plume" {
        options.file_metadata.insert(
            "frame".into(),
            MetaValue::Int64(i64::try_from(opts.frame).unwrap_or(i64::MAX)),
        );
    }
    let bytes = write_vdb_with(path, &grids, &options)?;
    Ok((summary, bytes))
}

/// A float grid `name` over `layout`'s box with `f` at the voxel centres.
pub(crate) fn sample_scalar(
    name: &str,
    layout: &GridLayout,
    f: impl Fn([f64; 3]) -> f64 + Sync,
) -> Grid<f32> {
    let inside = |a: usize, v: i64| v >= layout.lo[a] && v < layout.hi[a];
    let leaves = leaf_origins(layout)
        .par_iter()
        .map(|&o| {
            let mut active = [0u64; 8];
            let values = Box::new(std::array::from_fn(|n| {
                let ijk = [
                    o[0] + (n >> 6) as i64,
                    o[1] + ((n >> 3) & 7) as i64,
                    o[2] + (n & 7) as i64,
                ];
                if !(0..3).all(|a| inside(a, ijk[a])) {
                    return 0.0;
                }
                active[n >> 6] |= 1u64 << (n & 63);
                f(layout.centre(ijk)) as f32
            }));
            Leaf {
                origin: o.map(|v| v as i32),
                active,
                values,
            }
        })
        .collect();
    Grid {
        name: name.to_string(),
        transform: layout.transform(),
        background: 0.0,
        leaves,
        tiles: Vec::new(),
    }
}

/// `|u|` of a velocity grid, same leaves and active masks, named `speed…` for `vel…`.
pub fn speed_grid(grid: &Grid<Vec3>) -> Grid<f32> {
    let name = match grid.name.strip_prefix("vel") {
        Some(rest) => format!("speed{rest}"),
        None => format!("{}_speed", grid.name),
    };
    Grid {
        name,
        transform: grid.transform,
        background: 0.0,
        leaves: grid
            .leaves
            .iter()
            .map(|l| Leaf {
                origin: l.origin,
                active: l.active,
                values: Box::new(std::array::from_fn(|n| {
                    let [x, y, z] = l.values[n];
                    (x * x + y * y + z * z).sqrt()
                })),
            })
            .collect(),
        tiles: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wake_layout_nests_and_refines_by_two() {
        let l = scene_layout("wake", 64, 3).expect("layout");
        assert_eq!(l.len(), 3);
        assert_eq!(
            l.iter().map(|g| g.name.as_str()).collect::<Vec<_>>(),
            ["vel_l0", "vel_l1", "vel_l2"]
        );
        let coarse = &l[2];
        assert!((coarse.voxel_size - 0.125).abs() < 1e-15);
        assert_eq!(coarse.hi[0] - coarse.lo[0], 64);
        assert_eq!(coarse.lo, [-16, -16, -16]);
        for w in l.windows(2) {
            let (fine, parent) = (&w[0], &w[1]);
            assert!((parent.voxel_size - 2.0 * fine.voxel_size).abs() < 1e-15);
            for a in 0..3 {
                // Fine box on the parent's cell boundaries, and inside the parent box.
                assert_eq!(fine.lo[a] % 2, 0);
                assert_eq!(fine.hi[a] % 2, 0);
                assert!(fine.lo[a] >= 2 * parent.lo[a] && fine.hi[a] <= 2 * parent.hi[a]);
                assert!(fine.hi[a] - fine.lo[a] < 2 * (parent.hi[a] - parent.lo[a]));
            }
        }
        // The finest box holds the sphere and the rings.
        let f = &l[0];
        for a in 0..3 {
            assert!(f.lo[a] as f64 * f.voxel_size <= WAKE_CORE.min[a]);
            assert!(f.hi[a] as f64 * f.voxel_size >= WAKE_CORE.max[a]);
        }
    }

    #[test]
    fn layouts_nest_for_any_n0_and_level_count() {
        for n0 in [2, 5, 15, 30, 48, 64, 161] {
            for levels in 1..=5 {
                let l = match scene_layout("wake", n0, levels) {
                    Ok(l) => l,
                    // 161 with 5 levels needs 8 GB of leaves: past the memory limit.
                    Err(SynthError::TooLarge { .. }) if (n0, levels) == (161, 5) => continue,
                    Err(e) => panic!("n0 {n0}, {levels} levels: {e}"),
                };
                assert_eq!(l.len(), levels as usize);
                let coarse = &l[l.len() - 1];
                let nx = coarse.hi[0] - coarse.lo[0];
                assert!(nx == i64::from(n0) || nx == i64::from(n0) + 1, "{n0}: {nx}");
                for a in 0..3 {
                    assert!(coarse.lo[a] as f64 * coarse.voxel_size <= WAKE_DOMAIN.min[a] + 1e-12);
                    assert!(coarse.hi[a] as f64 * coarse.voxel_size >= WAKE_DOMAIN.max[a] - 1e-12);
                }
                for w in l.windows(2) {
                    let (fine, parent) = (&w[0], &w[1]);
                    for a in 0..3 {
                        assert!(fine.lo[a] >= 2 * parent.lo[a] && fine.hi[a] <= 2 * parent.hi[a]);
                        assert!(fine.lo[a] % 2 == 0 && fine.hi[a] % 2 == 0);
                        assert!(fine.hi[a] > fine.lo[a]);
                    }
                }
                if levels > 1 {
                    let f = &l[0];
                    for a in 0..3 {
                        assert!(f.lo[a] as f64 * f.voxel_size <= WAKE_CORE.min[a] + 1e-12);
                        assert!(f.hi[a] as f64 * f.voxel_size >= WAKE_CORE.max[a] - 1e-12);
                    }
                }
            }
        }
    }

    #[test]
    fn grids_hold_exact_velocities_at_voxel_centres() {
        let grids = scene_grids("wake", 16, 2).expect("grids");
        let layouts = scene_layout("wake", 16, 2).expect("layout");
        let flow = analytic::scene("wake").expect("wake");
        for (g, l) in grids.iter().zip(&layouts) {
            assert_eq!(g.active_voxel_count(), l.voxel_count());
            assert_eq!(g.transform, l.transform());
            for leaf in &g.leaves {
                for (ijk, v) in leaf.active_voxels() {
                    let p = g.transform.index_to_world(ijk.map(f64::from));
                    let u = flow.velocity(p);
                    for a in 0..3 {
                        assert_eq!(v[a], u[a] as f32);
                    }
                }
            }
        }
    }

    #[test]
    fn single_grid_scenes_and_partial_leaves() {
        let grids = scene_grids("lamb-oseen", 20, 3).expect("grids");
        assert_eq!(grids.len(), 1);
        assert_eq!(grids[0].name, "vel");
        assert_eq!(grids[0].active_voxel_count(), 20 * 20 * 20);
        // -10..10 spans leaves -16..-8, -8..0, 0..8, 8..16: partial masks at both ends.
        assert_eq!(grids[0].leaves.len(), 4 * 4 * 4);
        let counts: Vec<u32> = grids[0].leaves.iter().map(Leaf::active_count).collect();
        assert!(counts.contains(&512) && counts.contains(&8));
    }

    #[test]
    fn bad_parameters_are_refused() {
        assert!(matches!(
            scene_grids("nope", 16, 2),
            Err(SynthError::UnknownScene { .. })
        ));
        assert!(matches!(
            scene_layout("wake", 1, 2),
            Err(SynthError::OutOfRange { what: "n0", .. })
        ));
        assert!(matches!(
            scene_layout("wake", 16, 0),
            Err(SynthError::OutOfRange { what: "levels", .. })
        ));
        assert!(matches!(
            scene_layout("wake", 4096, 10),
            Err(SynthError::TooLarge { .. })
        ));
    }

    /// The largest allowed parameters overflow a u64 voxel count (2^75 voxels in the finest
    /// box): the layout must still be refused with the leaf count saturated, not panic.
    #[test]
    fn largest_parameters_are_refused_without_overflow() {
        match scene_layout("wake", 1 << 16, 10) {
            Err(SynthError::TooLarge { leaves, bytes, .. }) => {
                assert!(leaves > 1 << 50, "{leaves}");
                assert_eq!(bytes, u64::MAX);
            }
            other => panic!("expected TooLarge, got {other:?}"),
        }
        let finest = GridLayout {
            name: "x".into(),
            voxel_size: 1.0,
            lo: [-(1 << 25); 3],
            hi: [1 << 25; 3],
        };
        assert_eq!(finest.voxel_count(), u64::MAX);
    }

    /// `abc --n0 1024` has exactly 2^30 voxels, which the old voxel limit let through while
    /// its leaves take 13 GB: the limit counts leaf bytes, so it is refused before sampling.
    #[test]
    fn limit_counts_leaf_memory_not_voxels() {
        match scene_layout("abc", 1024, 1) {
            Err(SynthError::TooLarge { leaves, bytes, .. }) => {
                assert_eq!(leaves, 128 * 128 * 128);
                assert!(bytes > 12 << 30, "{bytes}");
            }
            other => panic!("expected TooLarge, got {other:?}"),
        }
        // The speed grids count too: a scene that fits alone can be refused with them.
        let layouts = scene_layout("abc", 656, 1).expect("fits without speed grids");
        check_memory("abc", 656, &layouts, false).expect("fits");
        assert!(matches!(
            check_memory("abc", 656, &layouts, true),
            Err(SynthError::TooLarge { .. })
        ));
    }

    /// `leaf_count` counts exactly the leaves `sample_grid` allocates, partial ones included.
    #[test]
    fn leaf_count_matches_sampled_leaves() {
        for (scene, n0, levels) in [("wake", 16, 3), ("wake", 13, 2), ("abc", 20, 1)] {
            let layouts = scene_layout(scene, n0, levels).expect("layout");
            let grids = scene_grids(scene, n0, levels).expect("grids");
            for (l, g) in layouts.iter().zip(&grids) {
                assert_eq!(l.leaf_count(), g.leaves.len() as u64, "{scene} {}", l.name);
            }
        }
    }

    #[test]
    fn deterministic() {
        assert_eq!(
            scene_grids("wake", 16, 2).expect("a"),
            scene_grids("wake", 16, 2).expect("b")
        );
    }
}
