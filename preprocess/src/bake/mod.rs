//! The bake pipeline: grids → cells → leaf cells → bricks → field values → regions →
//! KD-tree → [`BrickFile`]. [`bake`] runs the stages in that order, each a function of its
//! own (`select_input`, `read_cells`, `classify`, `brick`, `derive_fields`, `build_regions`,
//! `kd_tree`, `assemble`), so that what one stage hands the next is spelled out in their
//! signatures.
//!
//! Every parallel stage maps items to results collected in item order, so the output is
//! byte-identical whatever the thread count.

use rayon::prelude::*;
use serde::Serialize;

use format::{BrickFile, SourceGrid};

use crate::bricks::{make_bricks, BrickBox};
use crate::cells::{classify_leaves, CellSet, Keep, SlotValues, Widen};
use crate::derive::{centre_from_faces, Stencil};
use crate::error::{field_grid_not_found, grid_labels, GridCount, GridCounts};
use crate::fields::{region_ranges, FieldKind, RangeInput};
use crate::grid::{AnyGrid, Transform};
use crate::kdtree::{Regions, TooLarge, Tree};
use crate::levels::assign_levels;
use crate::nonfinite::{self, CellValue};
use crate::regions;
use crate::spilled::Store;
use crate::vdb::AnyLocated;

/// Re-exported from [`crate::error`], where it lives since [`crate::levels`] returns it too.
pub use crate::error::BakeError;
pub use select::{select_grids, GridKind};

mod assemble;
use assemble::{archive_bytes, assemble, check_archive};
mod derived;
mod extra;
mod grids;
pub use grids::BakeGrid;
use grids::{decoded_cells, located_cells};
/// Memory estimates of a bake (also used by `qbricks-lab`'s `synth` and `accuracy` limits).
pub mod memory;
mod overlap;
pub mod peers;
pub use ranks::{Alone, Exchange};
mod reach;
mod select;
mod supports;
use supports::snapped_supports;

use derived::{derive_fields, FieldValues};
pub use derived::{Spill, CHUNK_CELLS, SPILL_BYTES, WINDOW_BYTES};
use extra::{extra_coverage, extra_fields, ExtraGrid};
use memory::check_bake_memory;
use overlap::same_level_overlaps;
use reach::check_reach;
use select::select;

/// Default cap on brick edge length (cells).
pub const DEFAULT_MAX_BRICK: u32 = 8;

/// What to bake and how.
#[derive(Debug, Clone, Serialize)]
pub struct BakeOptions {
    /// Grid names to bake (every grid of that name); empty: all vec3 grids, or the scalar
    /// grid when there is no vec3 grid.
    pub grids: Vec<String>,
    /// Fields derived from velocity; `None` means the default (Q and speed). Scalar grids
    /// are baked as their own field and accept no field list.
    pub fields: Option<Vec<FieldKind>>,
    pub stencil: Stencil,
    /// Largest brick edge in cells.
    pub max_brick: u32,
    /// Refuse non-finite input values instead of replacing them.
    pub strict: bool,
    /// Names of vec3 grids whose values sit on cell faces (OpenVDB class `staggered`, see
    /// [`crate::derive`]); the CLI fills it from the grid class. Recorded only when not
    /// empty, so that the provenance of cell-centred bakes stays as it was.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub staggered: Vec<String>,
    /// Source file name recorded in the provenance (not part of the options JSON).
    #[serde(skip)]
    pub source: String,
    /// Run on a pool of this many threads (None: rayon's global pool). Not recorded: the
    /// output does not depend on it.
    #[serde(skip)]
    pub threads: Option<usize>,
    /// Where values too large to hold go (see [`Spill`]). Not recorded: the output does
    /// not depend on it.
    #[serde(skip)]
    pub spill: Spill,
    /// The memory budget (`--memory`): the bake keeps values on disk as it needs to stay
    /// within it (`spill` then gives only their directory, see
    /// [`memory::spill_within`]), and is refused, naming the least budget that would do,
    /// when its estimate is over it even so. Not recorded.
    #[serde(skip)]
    pub memory: Option<u64>,
    /// When `memory` is a share of a budget several bakes run at once share (a
    /// sequence's `--jobs`): the whole budget and how many share it, so that a refusal
    /// names what the user gave and what would do. Not recorded.
    #[serde(skip)]
    pub memory_shared: Option<(u64, usize)>,
}

impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions {
            grids: vec![],
            fields: None,
            stencil: Stencil::Central,
            max_brick: DEFAULT_MAX_BRICK,
            strict: false,
            staggered: Vec::new(),
            source: String::new(),
            threads: None,
            spill: Spill::default(),
            memory: None,
            memory_shared: None,
        }
    }
}

/// Range of one baked field.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FieldSummary {
    pub name: String,
    pub min: f32,
    pub max: f32,
}

/// What a bake did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BakeSummary {
    pub input_cells: u64,
    pub leaf_cells: u64,
    pub dropped_cells: u64,
    pub bricks: u64,
    pub regions: u64,
    pub kd_nodes: u64,
    pub nonfinite: u64,
    /// Baked values (derived or resampled) that were not finite as f32 (overflow of Q, λ2,
    /// vorticity or speed from huge velocities, huge doubles); stored clamped, see [`clamp_nonfinite`].
    pub nonfinite_derived: u64,
    pub fields: Vec<FieldSummary>,
    /// Non-fatal problems (non-finite values replaced, …), one line each.
    #[serde(skip)]
    pub warnings: Vec<String>,
}

/// Bakes `grids` into a brick file.
pub fn bake(
    grids: Vec<AnyGrid>,
    opts: &BakeOptions,
) -> Result<(BrickFile, BakeSummary), BakeError> {
    bake_with_progress(grids, opts, &|_| {})
}

/// As [`bake`], calling `stage` with the name of each stage as it starts.
pub fn bake_with_progress(
    grids: Vec<AnyGrid>,
    opts: &BakeOptions,
    stage: &(dyn Fn(&str) + Sync),
) -> Result<(BrickFile, BakeSummary), BakeError> {
    let grids = grids.into_iter().map(BakeGrid::Decoded).collect();
    let (baked, summary) = bake_kept(grids, opts, stage)?;
    Ok((baked.into_file()?, summary))
}

/// As [`bake_with_progress`], with the field values left where the bake keeps them (in
/// memory, or in scratch files when they are large, see [`Spill`]): what a bake that
/// writes a file runs, so that the values are streamed from there into it
/// ([`Baked::write`]) instead of being gathered in memory first.
pub fn bake_kept(
    grids: Vec<BakeGrid>,
    opts: &BakeOptions,
    stage: &(dyn Fn(&str) + Sync),
) -> Result<(Baked, BakeSummary), BakeError> {
    let alone = |grids| {
        run(grids, opts, stage, &Alone)
            .map(|baked| baked.expect("a bake in one process is rank 0's"))
    };
    match opts.threads {
        Some(n) => {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n.max(1))
                .build()
                .map_err(|e| BakeError::ThreadPool(e.to_string()))?;
            pool.install(|| alone(grids))
        }
        None => alone(grids),
    }
}

/// As [`bake_kept`], shared between `peers` (the ranks of an MPI run, see
/// [`peers`](self::peers)): rank 0 gets the bake, the other ranks `None` once their part
/// is gathered. Over more than one rank each runs on its own global pool (one rank a
/// core, as MPI launchers bind them): `opts.threads` is not used.
pub fn bake_kept_among(
    grids: Vec<BakeGrid>,
    opts: &BakeOptions,
    stage: &(dyn Fn(&str) + Sync),
    peers: &dyn Exchange,
) -> Result<Option<(Baked, BakeSummary)>, BakeError> {
    match peers.size() {
        0 | 1 => bake_kept(grids, opts, stage).map(Some),
        _ => run(grids, opts, stage, peers),
    }
}

/// A baked file whose fields' values are kept apart from it (see [`bake_kept`]).
pub struct Baked {
    /// Everything but the fields' values (their `values` are empty), and but the regions
    /// and KD-tree when `structure` holds them.
    file: BrickFile,
    values: FieldValues,
    /// The regions and KD-tree when they were kept in scratch files (see
    /// [`crate::spilled`]); `None`: they are in `file`.
    structure: Option<Kd>,
}

impl Baked {
    /// The file with its values in it.
    pub fn into_file(self) -> Result<BrickFile, BakeError> {
        let Baked {
            mut file,
            values,
            structure,
        } = self;
        for (f, v) in file.fields.iter_mut().zip(values.into_vecs()?) {
            f.values = v;
        }
        if let Some(kd) = structure {
            assemble::structure_into(&mut file, kd);
        }
        Ok(file)
    }

    /// Writes the file to `path` atomically ([`format::writer::write_streamed`]): the
    /// values are read where they are kept, a chunk at a time, and let go once written.
    pub fn write(&self, path: &std::path::Path) -> Result<u64, format::FormatError> {
        let release = |f: usize, r: std::ops::Range<usize>| self.values.release(f, r);
        let slices = self.values.slices();
        let Some(kd) = &self.structure else {
            return format::writer::write_streamed(path, &self.file, &slices, &release);
        };
        let let_go = |part: usize, r: std::ops::Range<usize>| match part {
            0 => kd.regions.runs.release(r),
            1 => kd.regions.bricks.release(r),
            2 => kd.ranges.release(r),
            3 => kd.tree.1.release(r),
            _ => kd.tree.2.release(r),
        };
        let structure = format::streamed::Structure {
            regions: &kd.regions.runs,
            region_bricks: &kd.regions.bricks,
            region_ranges: bytemuck::cast_slice(&kd.ranges),
            kd_nodes: &kd.tree.1,
            kd_axes: &kd.tree.2,
            release: &let_go,
        };
        format::writer::write_streamed_with(path, &self.file, &slices, &release, Some(structure))
    }
}

/// Cell sets and values of the selected grids.
enum Input {
    /// Cell sets, cell-centred velocities, and the face values of staggered grids.
    Vector(
        Vec<CellSet>,
        Vec<SlotValues<[f64; 3]>>,
        Vec<Option<SlotValues<[f64; 3]>>>,
    ),
    Scalar(Vec<CellSet>, Vec<SlotValues<f64>>, String),
}

impl Input {
    fn sets(&self) -> &[CellSet] {
        match self {
            Input::Vector(s, _, _) | Input::Scalar(s, _, _) => s,
        }
    }

    /// The cell sets, the values dropped.
    fn into_sets(self) -> Vec<CellSet> {
        match self {
            Input::Vector(s, _, _) | Input::Scalar(s, _, _) => s,
        }
    }

    fn sets_mut(&mut self) -> &mut [CellSet] {
        match self {
            Input::Vector(s, _, _) | Input::Scalar(s, _, _) => s,
        }
    }
}

/// Cell sets of the grids (consumed) that `one` converts, in file order (rayon keeps the
/// order, so the output does not depend on the thread count).
fn to_sets<T: Send>(
    grids: Vec<BakeGrid>,
    levels: &[u32],
    one: impl Fn(BakeGrid, u32) -> Option<Result<(CellSet, T), BakeError>> + Sync,
) -> Result<(Vec<CellSet>, Vec<T>), BakeError> {
    Ok(grids
        .into_par_iter()
        .zip(levels)
        .filter_map(|(g, &l)| one(g, l))
        .collect::<Result<Vec<_>, _>>()?
        .into_iter()
        .unzip())
}

/// Replaces the non-finite values of every set by the average of their finite neighbours,
/// with one warning naming every grid that had some (with its count), or refuses them with
/// `strict`. Returns how many there were. Values kept on disk (as `keep` says, also the
/// widened copies of repaired grids) are read a window at a time.
fn fix_nonfinite<T: CellValue + Widen>(
    sets: &[CellSet],
    values: &mut [SlotValues<T>],
    keep: Keep<'_>,
    strict: bool,
    warnings: &mut Vec<String>,
) -> Result<u64, BakeError> {
    let labels = grid_labels(sets.iter().map(|s| s.name.as_str()));
    let every = keep.window_values(std::mem::size_of::<T>());
    let mut found = Vec::new();
    let mut any = vec![false; sets.len()];
    for (((set, vals), label), any) in sets.iter().zip(values.iter()).zip(labels).zip(&mut any) {
        let view = vals.view();
        let rep = nonfinite::count(set, |s| view.get(s), every, || vals.release());
        *any = rep.count > 0;
        if rep.count > 0 {
            found.push(GridCount {
                grid: label,
                count: rep.count,
                first: rep.first.unwrap_or([0; 3]),
            });
        }
    }
    let total: u64 = found.iter().map(|g| g.count).sum();
    if total == 0 {
        return Ok(0);
    }
    let grids = GridCounts(found);
    if strict {
        return Err(BakeError::NonFinite {
            count: total,
            grids,
        });
    }
    // Repaired values are means, which no f32 holds: only those grids are widened.
    for ((set, vals), _) in sets
        .iter()
        .zip(values.iter_mut())
        .zip(&any)
        .filter(|(_, &a)| a)
    {
        let what = format!("the repaired values of grid \"{}\"", set.name);
        nonfinite::replace(set, vals.wide_mut(&what, keep)?);
    }
    warnings.push(format!(
        "replaced {total} non-finite values by the average of their finite neighbours: {grids}"
    ));
    Ok(total)
}

/// The bake, stage after stage; `stage` hears each stage's name as it starts. Every stage
/// is one function below, in pipeline order, taking what the ones before it made.
fn run(
    grids: Vec<BakeGrid>,
    opts: &BakeOptions,
    stage: &(dyn Fn(&str) + Sync),
    peers: &dyn Exchange,
) -> Result<Option<(Baked, BakeSummary)>, BakeError> {
    if opts.max_brick == 0 {
        return Err(BakeError::BadMaxBrick(opts.max_brick));
    }
    stage("selecting grids");
    let selection = select_input(grids, opts)?;
    let opts = &BakeOptions {
        spill: selection.spill.clone(),
        ..opts.clone()
    };

    stage("reading cells");
    let mut warnings = Vec::new();
    let mut cells = read_cells(
        selection.grids,
        &selection.levels,
        &selection.extra_names,
        selection.extra_grids,
        opts,
        &mut warnings,
    )?;

    // The decoded grids are cells now: their leaves go back to the system before the
    // fields are allocated.
    memory::return_freed();
    stage("classifying leaf cells");
    let leaf_cells = classify(&mut cells.input);
    // The values alone: a file the format cannot hold is refused before its fields are
    // derived (the whole archive is checked again once it is known, in `assemble`).
    let nfields = field_names(&cells.input, opts).len() as u64;
    let at_least = leaf_cells
        .saturating_mul(nfields * 4)
        .saturating_add(leaf_cells / u64::from(opts.max_brick).saturating_pow(3) * 64);
    check_archive(leaf_cells, nfields, at_least)?;
    warnings.extend(same_level_overlaps(&cells.input));
    let sets = cells.input.sets();

    stage("bricking");
    let bricks = brick(sets, opts.max_brick);
    let opts = &BakeOptions {
        spill: selection
            .footprints
            .check_bricks(bricks.boxes.len() as u64, &opts.spill, opts)?,
        ..opts.clone()
    };

    stage("deriving fields");
    let derived = derive_fields(&cells, &bricks, opts, peers)?;
    if derived.elsewhere() {
        // Another rank's bake: its fields are at rank 0, which makes the rest.
        return Ok(None);
    }
    extra_coverage(
        &cells,
        (&derived.names, &derived.covered),
        sets,
        leaf_cells,
        &mut warnings,
    )?;
    // The cells' values are in the fields now: from here on only the sets' cells are read,
    // so the input values (12 or 24 bytes a cell for a velocity) and the extra fields'
    // grids are dropped before the fields are read back (when they were kept on disk) and
    // the regions made.
    let Cells {
        input,
        extras,
        nonfinite,
    } = cells;
    drop(extras);
    let sets = input.into_sets();
    memory::return_freed();
    let mut fields = derived.open()?;
    let nonfinite_derived = clamp_fields(
        &mut fields,
        &bricks,
        &sets,
        &opts.spill,
        opts.strict,
        &mut warnings,
    )?;

    stage("building regions");
    let built = build_regions(&sets, &bricks, selection.widths[0], &opts.spill)?;
    let bounds = built.bounds;
    let kd = kd_tree(built, &bricks, &fields, &opts.spill)?;

    stage("assembling");
    check_archive(leaf_cells, nfields, archive_bytes(&bricks, &fields, &kd))?;
    let (regions, kd_nodes) = (kd.regions.len() as u64, kd.tree.1.len() as u64);
    let (file, field_summaries, structure) = assemble(
        opts,
        selection.source_grids,
        &selection.widths,
        &bricks,
        &fields,
        kd,
        bounds,
    );
    let summary = BakeSummary {
        input_cells: selection.input_cells,
        leaf_cells,
        dropped_cells: selection.input_cells - leaf_cells,
        bricks: bricks.boxes.len() as u64,
        regions,
        kd_nodes,
        nonfinite,
        nonfinite_derived,
        fields: field_summaries,
        warnings,
    };
    Ok(Some((
        Baked {
            file,
            values: fields,
            structure,
        },
        summary,
    )))
}

/// What [`select_input`] keeps for the later stages.
struct Selection {
    /// The grids to bake (all vec3 or all scalar).
    grids: Vec<BakeGrid>,
    /// Where the bake keeps its values (as asked, or to keep within its memory budget).
    spill: Spill,
    /// What its memory estimate was made from (checked again once the bricks are made).
    footprints: memory::Footprints,
    /// Level of each grid (0 = finest) and cell width of each level.
    levels: Vec<u32>,
    widths: Vec<f64>,
    /// Active voxels of `grids` (tiles counted as the voxels they cover).
    input_cells: u64,
    /// The grids as the provenance records them.
    source_grids: Vec<SourceGrid>,
    /// Names of the fields resampled from scalar grids, and those grids.
    extra_names: Vec<String>,
    extra_grids: Vec<BakeGrid>,
}

/// Read stage: checks the field list, takes the scalar grids baked as extra fields out of
/// `grids`, selects the grids to bake and assigns their levels, refusing empty or too large
/// input before any cell is made from it.
fn select_input(grids: Vec<BakeGrid>, opts: &BakeOptions) -> Result<Selection, BakeError> {
    // Fields: no name twice; scalar-grid fields take their grids out of the selection.
    let mut extra_names: Vec<String> = Vec::new();
    if let Some(kinds) = &opts.fields {
        let mut seen: Vec<String> = Vec::new();
        for n in kinds.iter().flat_map(FieldKind::names) {
            if seen.contains(&n) {
                return Err(BakeError::DuplicateField(n));
            }
            seen.push(n);
        }
        for k in kinds {
            if let FieldKind::Scalar(n) = k {
                extra_names.push(n.clone());
            }
        }
    }
    let (extra_grids, grids): (Vec<BakeGrid>, Vec<BakeGrid>) = grids
        .into_iter()
        .partition(|g| !g.is_vector() && extra_names.iter().any(|n| n == g.name()));
    if let Some(missing) = extra_names
        .iter()
        .find(|n| !extra_grids.iter().any(|g| g.name() == n.as_str()))
    {
        let kinds: Vec<(&str, GridKind)> = grids
            .iter()
            .chain(&extra_grids)
            .map(|g| (g.name(), g.kind()))
            .collect();
        return Err(field_grid_not_found(missing, &kinds));
    }
    let grids = select(grids, &opts.grids)?;
    if grids.is_empty() {
        return Err(BakeError::NoGrids);
    }
    let named: Vec<(&str, Transform)> = grids.iter().map(|g| (g.name(), g.transform())).collect();
    let (levels, widths) = assign_levels(&named)?;
    check_reach(&grids, widths[0])?;
    let input_cells: u64 = grids.iter().map(BakeGrid::active_voxel_count).sum();
    if input_cells == 0 {
        return Err(BakeError::Empty);
    }
    let (spill, footprints) = check_bake_memory(&grids, &extra_grids, opts, input_cells)?;
    let source_grids: Vec<SourceGrid> = grids
        .iter()
        .zip(&levels)
        .map(|(g, &level)| SourceGrid {
            name: g.name().to_string(),
            voxel_size: g.transform().voxel_size,
            level,
        })
        .collect();
    Ok(Selection {
        grids,
        spill,
        footprints,
        levels,
        widths,
        input_cells,
        source_grids,
        extra_names,
        extra_grids,
    })
}

/// What [`read_cells`] makes of the selected grids.
struct Cells {
    input: Input,
    /// The scalar grids resampled as extra fields.
    extras: Vec<ExtraGrid>,
    /// Non-finite input values replaced.
    nonfinite: u64,
}

impl Cells {
    /// Lets the pages of the values kept on disk go (see [`Slots::release`]): called by
    /// the passes over them, behind themselves.
    fn release_values(&self) {
        match &self.input {
            Input::Vector(_, vals, faces) => {
                vals.iter().for_each(SlotValues::release);
                faces.iter().flatten().for_each(SlotValues::release);
            }
            Input::Scalar(_, vals, _) => vals.iter().for_each(SlotValues::release),
        }
        self.extras.iter().for_each(ExtraGrid::release_values);
    }
}

/// Cells stage: the selected grids as cell sets with f64 values (the grids are dropped as
/// soon as they are converted, so both are never held at once), non-finite values repaired
/// (or refused with `strict`), the extra fields' grids likewise, and staggered velocities
/// moved to cell centres.
fn read_cells(
    grids: Vec<BakeGrid>,
    levels: &[u32],
    extra_names: &[String],
    extra_grids: Vec<BakeGrid>,
    opts: &BakeOptions,
    warnings: &mut Vec<String>,
) -> Result<Cells, BakeError> {
    let mut input = cell_sets(grids, levels, opts)?;
    let nonfinite = match &mut input {
        Input::Vector(sets, vals, _) => {
            fix_nonfinite(sets, vals, keep(opts), opts.strict, warnings)?
        }
        Input::Scalar(sets, vals, _) => {
            fix_nonfinite(sets, vals, keep(opts), opts.strict, warnings)?
        }
    };
    let extras = extra_fields(extra_names, extra_grids, keep(opts), opts.strict, warnings)?;
    // Staggered grids: keep the (repaired) face values, bake from cell-centred ones.
    if let Input::Vector(sets, vals, faces) = &mut input {
        *faces = sets
            .iter()
            .zip(vals.iter_mut())
            .map(|(set, v)| {
                if !opts.staggered.contains(&set.name) {
                    return Ok(None);
                }
                let centred = SlotValues::Wide(centre_from_faces(set, v, keep(opts))?);
                Ok(Some(std::mem::replace(v, centred)))
            })
            .collect::<Result<_, BakeError>>()?;
    }
    Ok(Cells {
        input,
        extras,
        nonfinite,
    })
}

/// Converts the grids (consumed) to cell sets; a field list is refused for scalar grids,
/// and an empty one for vec3 grids.
fn cell_sets(grids: Vec<BakeGrid>, levels: &[u32], opts: &BakeOptions) -> Result<Input, BakeError> {
    let keep = keep(opts);
    if grids[0].is_vector() {
        if let Some(f) = &opts.fields {
            if f.is_empty() {
                return Err(BakeError::NoFields);
            }
        }
        // Single-precision velocities stay single (see `SlotValues`).
        let narrow = |(s, v)| (s, SlotValues::Narrow(v));
        let wide = |(s, v)| (s, SlotValues::Wide(v));
        let (sets, vals) = to_sets(grids, levels, |g, l| match g {
            BakeGrid::Decoded(AnyGrid::Vec3s(g)) => {
                Some(decoded_cells(g, l, |v| v, keep).map(narrow))
            }
            BakeGrid::Decoded(AnyGrid::Vec3d(g)) => {
                Some(decoded_cells(g, l, |v| v, keep).map(wide))
            }
            BakeGrid::Located(AnyLocated::Vec3s(g)) => {
                Some(located_cells(g, l, |v| v, keep).map(narrow))
            }
            BakeGrid::Located(AnyLocated::Vec3d(g)) => {
                Some(located_cells(g, l, |v| v, keep).map(wide))
            }
            _ => None,
        })?;
        Ok(Input::Vector(sets, vals, Vec::new()))
    } else {
        let name = grids[0].name().to_string();
        if opts.fields.is_some() {
            return Err(BakeError::FieldsForScalar { grid: name });
        }
        let narrow = |(s, v)| (s, SlotValues::Narrow(v));
        let wide = |(s, v)| (s, SlotValues::Wide(v));
        let (sets, vals) = to_sets(grids, levels, |g, l| match g {
            BakeGrid::Decoded(AnyGrid::Float(g)) => {
                Some(decoded_cells(g, l, |v| v, keep).map(narrow))
            }
            BakeGrid::Decoded(AnyGrid::Double(g)) => {
                Some(decoded_cells(g, l, |v| v, keep).map(wide))
            }
            BakeGrid::Located(AnyLocated::Float(g)) => {
                Some(located_cells(g, l, |v| v, keep).map(narrow))
            }
            BakeGrid::Located(AnyLocated::Double(g)) => {
                Some(located_cells(g, l, |v| v, keep).map(wide))
            }
            _ => None,
        })?;
        Ok(Input::Scalar(sets, vals, name))
    }
}

/// Where the cells' values are kept: beside the field values past the same size (see
/// [`Spill`]), so that a bake too large for memory keeps both on disk.
fn keep(opts: &BakeOptions) -> Keep<'_> {
    Keep {
        dir: opts.spill.dir.as_deref(),
        above: opts.spill.above,
        window: opts.spill.window,
        bounded: opts.memory.is_some(),
    }
}

/// Leaf-cell stage: keeps, in every set, the cells no finer level covers (see
/// [`classify_leaves`]). Returns how many there are.
fn classify(input: &mut Input) -> u64 {
    classify_leaves(input.sets_mut());
    input.sets().iter().map(|s| s.leaf_count()).sum()
}

/// The bricks, and where each one's values and cells are.
struct Bricks {
    boxes: Vec<BrickBox>,
    /// Index of each brick's first value in the field arrays (bricks are stored one after
    /// the other, x fastest).
    first: Vec<u64>,
    /// World position of each brick's first cell centre.
    origins: Vec<[f64; 3]>,
    /// Cell width of each brick (its grid's).
    widths: Vec<f64>,
}

/// Brick stage: covers the leaf cells with boxes of at most `max_brick` cells a side (see
/// [`make_bricks`]) and lays their values out one brick after the other.
fn brick(sets: &[CellSet], max_brick: u32) -> Bricks {
    let boxes = make_bricks(sets, max_brick);
    let mut first = Vec::with_capacity(boxes.len());
    let mut acc = 0u64;
    for b in &boxes {
        first.push(acc);
        acc += b.cells();
    }
    let origins = boxes.iter().map(|b| sets[b.set].centre(b.lo)).collect();
    let widths = boxes.iter().map(|b| sets[b.set].width).collect();
    Bricks {
        boxes,
        first,
        origins,
        widths,
    }
}

/// Values that overflowed f32 (or were NaN): counted, refused with `strict`, otherwise
/// clamped (see [`clamp_nonfinite`]) with one warning per field naming every grid they were
/// found in, each with its count and first cell. Returns how many there were.
fn clamp_fields(
    fields: &mut FieldValues,
    bricks: &Bricks,
    sets: &[CellSet],
    spill: &Spill,
    strict: bool,
    warnings: &mut Vec<String>,
) -> Result<u64, BakeError> {
    let labels = grid_labels(sets.iter().map(|s| s.name.as_str()));
    let window = spill.window_values(4);
    let mut nonfinite_derived = 0;
    for (f, name) in fields.names.clone().iter().enumerate() {
        // Counted brick by brick, so each value's grid (and its first cell) is known; the
        // values already read are let go every window.
        let mut per_set: Vec<Option<GridCount>> = vec![None; sets.len()];
        let mut count = 0u64;
        let mut kept_from = 0;
        for (b, bx) in bricks.boxes.iter().enumerate() {
            let first = bricks.first[b] as usize;
            if first - kept_from >= window {
                fields.release(f, kept_from..first);
                kept_from = first;
            }
            let part = &mut fields.field_mut(f)[first..first + bx.cells() as usize];
            let Some((n, at)) = clamp_nonfinite(part) else {
                continue;
            };
            count += n;
            let entry = per_set[bx.set].get_or_insert_with(|| {
                let (nx, ny) = (at % bx.dims[0] as usize, at / bx.dims[0] as usize);
                let off = [nx, ny % bx.dims[1] as usize, ny / bx.dims[1] as usize];
                GridCount {
                    grid: labels[bx.set].clone(),
                    count: 0,
                    first: [0, 1, 2].map(|a| bx.lo[a] + off[a] as i32),
                }
            });
            entry.count += n;
        }
        fields.release(f, kept_from..fields.cells());
        if count == 0 {
            continue;
        }
        let grids = GridCounts(per_set.into_iter().flatten().collect());
        if strict {
            return Err(BakeError::NonFiniteDerived {
                field: name.clone(),
                count,
                grids,
            });
        }
        warnings.push(format!(
            "field \"{name}\": {count} values are not finite as 32-bit floats: {grids}; stored as ±{:e} (infinities) and 0 (NaN)",
            f32::MAX
        ));
        nonfinite_derived += count;
    }
    Ok(nonfinite_derived)
}

/// Region stage: the bricks' supports, snapped so that neighbouring lattices agree (see
/// [`snapped_supports`]), split into regions and merged where many small ones would cost
/// rays more, with the KD-tree over them (see [`regions::build`]); or how far past what
/// the file can store they are.
fn build_regions(
    sets: &[CellSet],
    bricks: &Bricks,
    finest: f64,
    spill: &Spill,
) -> Result<regions::Built, BakeError> {
    let supports = snapped_supports(sets, &bricks.boxes, finest);
    let to = spill.structure_to();
    let segment = regions::SEGMENT_COST_CELLS * finest;
    regions::build(&supports, segment, to.clone()).map_err(|e| match e {
        TooLarge::Regions(regions) => BakeError::TooManyRegions {
            regions,
            limit: u64::from(format::kd::MAX_REGION) + 1,
        },
        TooLarge::BrickRefs(refs) => BakeError::TooManyBrickRefs {
            refs,
            limit: u64::from(u32::MAX),
        },
        TooLarge::Scratch(kind) => structure_scratch_error(to.as_deref(), kind),
    })
}

/// The error of a scratch file of the structure that failed with `kind`.
fn structure_scratch_error(
    to: Option<&crate::spilled::SpillTo>,
    kind: std::io::ErrorKind,
) -> BakeError {
    BakeError::Scratch {
        what: "the regions and the KD-tree".to_string(),
        dir: to.map(|t| t.dir.clone()).unwrap_or_else(std::env::temp_dir),
        source: kind.into(),
    }
}

/// The region tree as the file stores it.
struct Kd {
    /// Root reference, inner nodes, their axes.
    tree: Tree,
    /// Bounds and brick ids of each region, in the order the nodes number them.
    regions: Regions,
    /// `(min, max)` of each field over each region (see [`region_ranges`]).
    ranges: Store<[f32; 2]>,
}

impl Kd {
    /// Whether an array of it is kept in a scratch file.
    fn on_disk(&self) -> bool {
        self.tree.1.on_disk()
            || self.tree.2.on_disk()
            || self.regions.runs.on_disk()
            || self.regions.bricks.on_disk()
            || self.ranges.on_disk()
    }
}

/// KD-tree stage: each region's value range per field, which lets the viewer skip regions
/// an iso-value cannot cross.
fn kd_tree(
    built: regions::Built,
    bricks: &Bricks,
    fields: &FieldValues,
    spill: &Spill,
) -> Result<Kd, BakeError> {
    let regions::Built {
        bounds,
        tree: packed,
        regions,
    } = built;
    let boxes = bounds
        .map(|b| crate::kdtree::leaf_boxes(&packed, b))
        .into_iter()
        .flatten();
    let slices = fields.slices();
    let release = |f: usize, r: std::ops::Range<usize>| fields.release(f, r);
    let to = spill.structure_to();
    // Behind every batch, the pages of the structure kept on disk go.
    let let_go = || {
        regions.release_all();
        packed.1.release_all();
        packed.2.release_all();
    };
    let ranges = region_ranges(
        &RangeInput {
            bricks: &bricks.boxes,
            origins: &bricks.origins,
            widths: &bricks.widths,
            first: &bricks.first,
        },
        &regions,
        boxes,
        &fields.brick_values(&slices, &release),
        spill.window_values(4),
        (to.clone(), &let_go),
    );
    if let Some(kind) = ranges.failed() {
        return Err(structure_scratch_error(to.as_deref(), kind));
    }
    Ok(Kd {
        tree: packed,
        regions,
        ranges,
    })
}

/// Names of the fields a bake of `input` makes.
fn field_names(input: &Input, opts: &BakeOptions) -> Vec<String> {
    match input {
        Input::Vector(..) => opts
            .fields
            .as_deref()
            .unwrap_or(&[FieldKind::Q, FieldKind::Speed])
            .iter()
            .flat_map(FieldKind::names)
            .collect(),
        Input::Scalar(_, _, name) => vec![name.clone()],
    }
}

/// Replaces the non-finite values of `vals` (±∞ → ±`f32::MAX`, NaN → 0), so that every
/// stored value lies inside the field's range. Returns their count and the index of the
/// first, or `None` when all are finite.
pub(crate) fn clamp_nonfinite(vals: &mut [f32]) -> Option<(u64, usize)> {
    let mut first = None;
    let mut count = 0;
    for (i, v) in vals.iter_mut().enumerate() {
        if v.is_finite() {
            continue;
        }
        first.get_or_insert(i);
        count += 1;
        *v = if v.is_nan() {
            0.0
        } else {
            f32::MAX.copysign(*v)
        };
    }
    first.map(|f| (count, f))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 640³ tile (262 M cells of two fields, 2.2 GB) once panicked in the writer, past
    /// format 3's 32-bit offsets; format 4's reach any size a machine can bake, and an
    /// archive beyond the format's bound (1 TiB) is refused instead.
    #[test]
    fn an_archive_past_the_formats_bound_is_refused() {
        assert!(check_archive(1000, 2, 8000).is_ok());
        assert!(check_archive(262_144_000, 2, 2_200_000_000).is_ok());
        assert!(check_archive(1 << 30, 2, 9_700_000_000).is_ok());
        let e = check_archive(1 << 40, 2, (1 << 40) + (1 << 20)).expect_err("too large");
        assert_eq!(
            e.to_string(),
            "1099511627776 leaf cells with 2 field(s) make a .qbk archive of about 1048577 MiB, \
             more than the 1048576 MiB a .qbk may hold; bake a part of the data, or fewer fields"
        );
    }
}
