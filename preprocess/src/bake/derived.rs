//! Field stage: the value of every baked field at every cell of every brick.
//!
//! Bricks are computed in parallel, each writing straight into its own slice of every
//! field array (bricks lie one after the other, x fastest), so there are no per-brick
//! buffers to interleave afterwards; the values do not depend on the thread count.
//!
//! The fields are derived while the input's values are held (12 or 24 bytes a cell), and
//! take 4 bytes a cell each: held beside them, they made the bake's peak. So fields larger
//! than [`Spill::above`] are derived a chunk of bricks at a time, each chunk written to a
//! scratch file (one per field, unnamed, gone when closed). They stay there: the later
//! stages read them through a mapping, a part at a time, and the writer streams them into
//! the archive ([`FieldValues`]), so they are never all resident, beside the input's values
//! or after them. The bytes are the same either way.

use std::fs::File;
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use files::limits;
use files::scratch::ScratchValues;
use rayon::prelude::*;

use crate::bricks::BrickBox;
use crate::derive::{gradient, speed, VelocityField};
use crate::error::BakeError;
use crate::fields::{BrickValues, FieldKind};
use crate::measures;

use super::extra::ExtraGrid;
use super::peers::{check_message, chunk_per_rank};
use super::{BakeOptions, Bricks, Cells, Input};
use ranks::Exchange;

/// Field values larger than this (all fields together) are kept in scratch files while
/// the input's values are held (see the module docs): 256 MiB, two fields of 32 M cells.
pub const SPILL_BYTES: u64 = 256 << 20;
/// Cells of the bricks derived at once when the fields go to scratch files: every field's
/// values of this many cells are held (16 MiB a field).
pub const CHUNK_CELLS: u64 = 1 << 22;

/// Where a bake keeps values too large to hold: the field values and, past the same size,
/// each grid's cell values (see [`crate::cells::Keep`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Spill {
    /// The scratch files' directory (`None`: the system's temporary directory). A bake to
    /// a file keeps them beside it, where the file itself will need the room.
    pub dir: Option<PathBuf>,
    /// Field values up to this many bytes (all fields together), and each grid's cell
    /// values up to this many, stay in memory.
    pub above: u64,
    /// Cells derived at once otherwise (at least one brick).
    pub chunk: u64,
    /// Bytes of values kept on disk a pass reads before it lets their pages go.
    pub window: u64,
    /// Bytes each array of the structure (regions, their brick lists and value ranges,
    /// the KD-tree) may take in memory before it moves to a scratch file
    /// ([`crate::spilled`]); `u64::MAX`: never.
    pub structure: u64,
}

impl Default for Spill {
    fn default() -> Self {
        Spill {
            dir: None,
            above: SPILL_BYTES,
            chunk: CHUNK_CELLS,
            window: WINDOW_BYTES,
            structure: u64::MAX,
        }
    }
}

impl Spill {
    /// Settings that keep a bake within `budget` bytes where its input allows (`--memory`):
    /// values past an eighth of the budget go to disk (so a large budget keeps more in
    /// memory than the default, which is faster: writing the cells to disk and reading
    /// them back cost a few percent), passes over them hold an eighth of it at most, and a
    /// chunk of fields being derived a sixty-fourth; windows and chunks never larger than
    /// the defaults.
    pub fn within(budget: u64) -> Spill {
        let d = Spill::default();
        Spill {
            dir: None,
            above: budget / 8,
            chunk: d.chunk.min(budget / 64 / 4).max(1),
            window: d.window.min(budget / 8).max(1 << 20),
            structure: u64::MAX,
        }
    }

    /// These settings with the structure's arrays moved to disk past
    /// [`STRUCTURE_HELD_BYTES`] each.
    pub fn with_structure_on_disk(self) -> Spill {
        Spill {
            structure: STRUCTURE_HELD_BYTES,
            ..self
        }
    }

    /// Whether the structure's arrays may go to disk (past [`Spill::structure`] bytes).
    pub fn structure_on_disk(&self) -> bool {
        self.structure != u64::MAX
    }

    /// Where the structure's arrays go past [`Spill::structure`] bytes, if they may.
    pub(crate) fn structure_to(&self) -> Option<std::sync::Arc<crate::spilled::SpillTo>> {
        self.structure_on_disk().then(|| {
            std::sync::Arc::new(crate::spilled::SpillTo {
                dir: self.dir.clone().unwrap_or_else(std::env::temp_dir),
                above: usize::try_from(self.structure).unwrap_or(usize::MAX),
                window: STRUCTURE_WINDOW_BYTES,
            })
        })
    }

    /// The settings that hold the least: every value on disk, passes of a megabyte.
    pub fn least() -> Spill {
        Spill {
            dir: None,
            above: 0,
            chunk: 1,
            window: 1 << 20,
            structure: 0,
        }
    }

    /// Values of `size` bytes a pass over values on disk reads before it lets them go.
    pub(crate) fn window_values(&self, size: usize) -> usize {
        crate::cells::window_values(self.window, size)
    }
}

/// Bytes a pass over values on disk reads before it lets their pages go, by default.
pub const WINDOW_BYTES: u64 = 64 << 20;
/// Bytes of each structure array a bake within a budget holds in memory before the array
/// moves to disk: the arrays of small parts of the region split never do.
pub const STRUCTURE_HELD_BYTES: u64 = 64 << 10;
/// Bytes written to a structure array on disk before the pages behind are let go: the
/// split writes several arrays at once on every thread.
pub const STRUCTURE_WINDOW_BYTES: usize = 256 << 10;

/// Baked fields: names, and the values of each (brick after brick, x fastest), in memory
/// or, when they were derived into scratch files, read through a mapping of those files
/// whose pages every pass lets go behind itself ([`FieldValues::release`]): the stages
/// after the derivation and the writer then hold only the part of the values they are
/// working on, not all of them.
pub(super) struct FieldValues {
    pub(super) names: Vec<String>,
    values: Values,
}

enum Values {
    Memory(Vec<Vec<f32>>),
    Mapped(Vec<ScratchValues>),
}

impl FieldValues {
    /// Values per field.
    pub(super) fn cells(&self) -> usize {
        match &self.values {
            Values::Memory(v) => v.first().map_or(0, Vec::len),
            Values::Mapped(m) => m.first().map_or(0, ScratchValues::len),
        }
    }

    /// Every field's values.
    pub(super) fn slices(&self) -> Vec<&[f32]> {
        match &self.values {
            Values::Memory(v) => v.iter().map(Vec::as_slice).collect(),
            Values::Mapped(m) => m.iter().map(ScratchValues::as_slice).collect(),
        }
    }

    /// Field `f`'s values, to change.
    pub(super) fn field_mut(&mut self, f: usize) -> &mut [f32] {
        match &mut self.values {
            Values::Memory(v) => &mut v[f],
            Values::Mapped(m) => m[f].as_mut_slice(),
        }
    }

    /// Says that field `f`'s values in `range` are not needed for a while (see
    /// [`ScratchValues::release`]; nothing for values in memory).
    pub(super) fn release(&self, f: usize, range: std::ops::Range<usize>) {
        if let Values::Mapped(m) = &self.values {
            m[f].release(range);
        }
    }

    /// The values as [`region_ranges`](crate::fields::region_ranges) reads them (`slices`
    /// are [`FieldValues::slices`], `release` lets mapped ones go).
    pub(super) fn brick_values<'a>(
        &self,
        slices: &'a [&'a [f32]],
        release: &'a (dyn Fn(usize, std::ops::Range<usize>) + Sync),
    ) -> BrickValues<'a> {
        match self.values {
            Values::Memory(_) => BrickValues::Resident(slices),
            Values::Mapped(_) => BrickValues::Mapped {
                values: slices,
                release,
            },
        }
    }

    /// Every field's values in memory (read from their scratch files when kept there).
    pub(super) fn into_vecs(self) -> Result<Vec<Vec<f32>>, BakeError> {
        match self.values {
            Values::Memory(v) => Ok(v),
            Values::Mapped(m) => m
                .iter()
                .map(|m| {
                    let mut v: Vec<f32> = limits::vec_of("the baked field values", m.len())?;
                    v.copy_from_slice(m.as_slice());
                    m.release(0..m.len());
                    Ok(v)
                })
                .collect(),
        }
    }
}

/// Baked fields as derived: their values in memory or in scratch files.
pub(super) struct DerivedFields {
    pub(super) names: Vec<String>,
    store: Store,
    /// Per field, for one resampled from an extra scalar grid: how many leaf cells have an
    /// active voxel of that grid around their centre (see [`super::extra_coverage`]).
    pub(super) covered: Vec<Option<u64>>,
}

enum Store {
    Memory(Vec<Vec<f32>>),
    /// One scratch file per field, `total` values each, brick after brick.
    Spilled {
        files: Vec<File>,
        total: usize,
        dir: PathBuf,
    },
    /// At a rank other than 0 of a shared bake: the values went to rank 0.
    Elsewhere,
}

impl DerivedFields {
    /// The values went to rank 0 of a shared bake (see [`super::peers`]): this rank is done.
    pub(super) fn elsewhere(&self) -> bool {
        matches!(self.store, Store::Elsewhere)
    }

    /// The fields' values for the stages after the derivation: in memory, or their
    /// scratch files mapped (the files stay open while mapped; unnamed, they are gone once
    /// the mappings and files are).
    pub(super) fn open(self) -> Result<FieldValues, BakeError> {
        let values = match self.store {
            Store::Memory(values) => Values::Memory(values),
            // No values here: they went to rank 0, which writes the file.
            Store::Elsewhere => Values::Memory(Vec::new()),
            Store::Spilled { files, total, dir } => Values::Mapped(
                files
                    .iter()
                    .map(|f| ScratchValues::map(f, total))
                    .collect::<Result<_, _>>()
                    .map_err(|source| BakeError::Scratch {
                        what: "the baked field values".to_string(),
                        dir,
                        source,
                    })?,
            ),
        };
        Ok(FieldValues {
            names: self.names,
            values,
        })
    }
}

/// The value of every field at every cell of every brick, derived from the velocity (Q,
/// vorticity, λ2 and helicity from one gradient per cell, speed, velocity components) or
/// resampled from an extra scalar grid; a scalar grid baked on its own is its only field.
/// Cells of a brick that are not leaf cells read as zero.
pub(super) fn derive_fields(
    cells: &Cells,
    bricks: &Bricks,
    opts: &BakeOptions,
    peers: &dyn Exchange,
) -> Result<DerivedFields, BakeError> {
    match &cells.input {
        Input::Vector(sets, vals, faces) => {
            let kinds = opts
                .fields
                .clone()
                .unwrap_or(vec![FieldKind::Q, FieldKind::Speed]);
            let names: Vec<String> = kinds.iter().flat_map(FieldKind::names).collect();
            let needs_gradient = kinds.iter().any(FieldKind::needs_gradient);
            let field = VelocityField::new(sets, vals, faces);
            // The grid of each extra scalar field, looked up once rather than per cell.
            let extras: Vec<Option<&ExtraGrid>> = kinds
                .iter()
                .map(|k| match k {
                    FieldKind::Scalar(n) => cells.extras.iter().find(|e| &e.name == n),
                    _ => None,
                })
                .collect();
            // Covered cells per extra field, summed brick by brick (the sum does not
            // depend on the order).
            let covered: Vec<AtomicU64> = kinds.iter().map(|_| AtomicU64::new(0)).collect();
            let release = || cells.release_values();
            let store = per_brick(
                &bricks.boxes,
                names.len(),
                &opts.spill,
                peers,
                &release,
                |b, out| {
                    let set = &sets[b.set];
                    let v = &field.values[b.set];
                    let mut hits = vec![0u64; kinds.len()];
                    b.for_each_cell(set, |i, ijk, slot| {
                        let u = slot.map(|s| v.get(s)).unwrap_or_default();
                        // One gradient for every measure made from it.
                        let g = match slot.filter(|&s| needs_gradient && set.is_active(s)) {
                            Some(s) => gradient(&field, b.set, ijk, s, opts.stencil),
                            None => [[0.0; 3]; 3],
                        };
                        let mut f = 0;
                        for (ki, (k, extra)) in kinds.iter().zip(&extras).enumerate() {
                            match k {
                                FieldKind::Q => {
                                    out[f][i] = measures::q(&g) as f32;
                                    f += 1;
                                }
                                FieldKind::Speed => {
                                    out[f][i] = speed(&u) as f32;
                                    f += 1;
                                }
                                FieldKind::Vorticity => {
                                    out[f][i] = measures::vorticity_magnitude(&g) as f32;
                                    f += 1;
                                }
                                FieldKind::Lambda2 => {
                                    out[f][i] = measures::lambda2(&g) as f32;
                                    f += 1;
                                }
                                FieldKind::Helicity => {
                                    out[f][i] = measures::helicity(&u, &g) as f32;
                                    f += 1;
                                }
                                FieldKind::Velocity => {
                                    for c in u {
                                        out[f][i] = c as f32;
                                        f += 1;
                                    }
                                }
                                FieldKind::Scalar(_) => {
                                    let p = set.centre(ijk);
                                    let value = extra.map_or(0.0, |e| match e.sample(p) {
                                        Some(x) => {
                                            hits[ki] += 1;
                                            x
                                        }
                                        None => e.background(),
                                    });
                                    out[f][i] = value as f32;
                                    f += 1;
                                }
                            }
                        }
                    });
                    for (c, h) in covered.iter().zip(hits) {
                        if h > 0 {
                            c.fetch_add(h, Ordering::Relaxed);
                        }
                    }
                },
            )?;
            let covered = summed(covered.into_iter().map(AtomicU64::into_inner), peers)?;
            let covered = kinds
                .iter()
                .zip(covered)
                .flat_map(|(k, c)| {
                    let c = matches!(k, FieldKind::Scalar(_)).then_some(c);
                    vec![c; k.names().len()]
                })
                .collect();
            Ok(DerivedFields {
                names,
                store,
                covered,
            })
        }
        Input::Scalar(sets, vals, name) => {
            let release = || cells.release_values();
            let store = per_brick(&bricks.boxes, 1, &opts.spill, peers, &release, |b, out| {
                let set = &sets[b.set];
                let v = vals[b.set].view();
                b.for_each_cell(set, |i, _, slot| {
                    out[0][i] = slot.map(|s| v.get(s)).unwrap_or_default() as f32;
                });
            })?;
            Ok(DerivedFields {
                names: vec![name.clone()],
                store,
                covered: vec![None],
            })
        }
    }
}

/// `counts` summed over `peers` (at rank 0; the others' own counts stay theirs, unused).
fn summed(counts: impl Iterator<Item = u64>, peers: &dyn Exchange) -> Result<Vec<u64>, BakeError> {
    let mine: Vec<u64> = counts.collect();
    if peers.size() <= 1 {
        return Ok(mine);
    }
    let bytes: Vec<u8> = mine.iter().flat_map(|c| c.to_le_bytes()).collect();
    let Some(parts) = peers.gather(&bytes) else {
        return Ok(mine);
    };
    let mut sum = vec![0u64; mine.len()];
    for (rank, part) in parts.iter().enumerate() {
        check_message(rank, part, mine.len() as u64, 8)?;
        for (s, b) in sum.iter_mut().zip(part.chunks_exact(8)) {
            *s += u64::from_le_bytes(b.try_into().unwrap_or_default());
        }
    }
    Ok(sum)
}

/// Runs `cell_values` on every brick in parallel with the brick's slice of each of the `nf`
/// field arrays (which it must fill), and returns the arrays: brick after brick, x fastest.
/// The arrays are allocated fallibly (they are the largest allocations after the cells);
/// past `spill.above` bytes they are made a chunk of bricks at a time and written to
/// scratch files (see the module docs), and `release` is called after every chunk, so that
/// the input's values kept on disk let go of the pages the chunk read. Shared between
/// `peers`, each rank derives its chunks and rank 0 gathers them (see [`super::peers`]);
/// the other ranks get [`Store::Elsewhere`].
fn per_brick(
    bricks: &[BrickBox],
    nf: usize,
    spill: &Spill,
    peers: &dyn Exchange,
    release: &dyn Fn(),
    cell_values: impl Fn(&BrickBox, &mut [&mut [f32]]) + Sync,
) -> Result<Store, BakeError> {
    let total: usize = bricks.iter().map(|b| b.cells() as usize).sum();
    let bytes = (total as u64).saturating_mul(4 * nf as u64);
    let in_memory = bytes <= spill.above;
    let shared = peers.size() > 1;
    if in_memory && !shared {
        let mut fields = arrays(nf, total)?;
        fill(bricks, &mut fields, &cell_values);
        return Ok(Store::Memory(fields));
    }
    let mut sink = match peers.rank() {
        0 => Some(Sink::new(nf, total, bytes, in_memory, spill)?),
        _ => None,
    };
    let chunk = match shared {
        true => chunk_per_rank(spill.chunk, peers.size(), total as u64),
        false => spill.chunk,
    };
    let chunks = chunks(bricks, chunk);
    // One chunk's values, every field's after the other's.
    let derive = |c: &std::ops::Range<usize>| -> Result<Vec<Vec<f32>>, BakeError> {
        let cells: u64 = bricks[c.clone()].iter().map(BrickBox::cells).sum();
        let mut values = arrays(nf, cells as usize)?;
        fill(&bricks[c.clone()], &mut values, &cell_values);
        release();
        Ok(values)
    };
    if !shared {
        let sink = sink.as_mut().expect("one process is rank 0");
        for c in &chunks {
            sink.take(&as_bytes(&derive(c)?))?;
        }
    } else {
        let n = peers.size();
        for round in chunks.chunks(n) {
            let mut mine = Vec::new();
            if let Some(c) = round.get(peers.rank()) {
                let values = derive(c)?;
                match sink.as_mut() {
                    // Rank 0's chunk is the round's first: straight into place.
                    Some(sink) => sink.take(&as_bytes(&values))?,
                    None => {
                        mine.reserve_exact(values.iter().map(|v| v.len() * 4).sum());
                        as_bytes(&values)
                            .iter()
                            .for_each(|b| mine.extend_from_slice(b));
                    }
                }
            }
            let Some(parts) = peers.gather(&mine) else {
                continue;
            };
            let sink = sink.as_mut().expect("rank 0 gathers");
            for (rank, (c, part)) in round.iter().zip(&parts).enumerate().skip(1) {
                let cells: u64 = bricks[c.clone()].iter().map(BrickBox::cells).sum();
                check_message(rank, part, cells, 4 * nf as u64)?;
                let fields: Vec<&[u8]> = match cells {
                    0 => vec![&[]; nf],
                    _ => part.chunks_exact(cells as usize * 4).collect(),
                };
                sink.take(&fields)?;
            }
        }
    }
    Ok(match sink {
        Some(s) => s.into_store(),
        None => Store::Elsewhere,
    })
}

/// Every field's values as bytes.
fn as_bytes(values: &[Vec<f32>]) -> Vec<&[u8]> {
    values.iter().map(|v| bytemuck::cast_slice(v)).collect()
}

/// `nf` arrays of `n` values, allocated fallibly.
fn arrays(nf: usize, n: usize) -> Result<Vec<Vec<f32>>, BakeError> {
    Ok((0..nf)
        .map(|_| limits::vec_of("the baked field values", n))
        .collect::<Result<_, _>>()?)
}

/// The bricks (index ranges) of each chunk: at least one brick, then as many as fit in
/// `chunk` cells.
fn chunks(bricks: &[BrickBox], chunk: u64) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    while start < bricks.len() {
        let (mut end, mut cells) = (start, 0u64);
        while end < bricks.len() && (end == start || cells + bricks[end].cells() <= chunk) {
            cells += bricks[end].cells();
            end += 1;
        }
        out.push(start..end);
        start = end;
    }
    out
}

/// Where rank 0 puts the chunks' values, in file order: arrays in memory, or scratch files.
enum Sink {
    Memory {
        fields: Vec<Vec<f32>>,
        filled: usize,
    },
    Files {
        files: Vec<File>,
        total: usize,
        dir: PathBuf,
    },
}

impl Sink {
    fn new(
        nf: usize,
        total: usize,
        bytes: u64,
        in_memory: bool,
        spill: &Spill,
    ) -> Result<Sink, BakeError> {
        if in_memory {
            return Ok(Sink::Memory {
                fields: arrays(nf, total)?,
                filled: 0,
            });
        }
        let dir = spill.dir.clone().unwrap_or_else(std::env::temp_dir);
        // They stay until the file is written, beside it (the archive holds them again).
        files::output::check_space_in(
            "the field values kept on disk until they are written, and the file holding them",
            &dir,
            bytes.saturating_mul(2),
        )?;
        let files = (0..nf)
            .map(|_| tempfile::tempfile_in(&dir))
            .collect::<Result<_, _>>()
            .map_err(|source| scratch_error(&dir, source))?;
        Ok(Sink::Files { files, total, dir })
    }

    /// Appends one chunk's values: per field, the bytes of its `f32`s (as a rank sent
    /// them: copied, not cast, since a message's bytes need not be aligned for `f32`).
    fn take(&mut self, chunk: &[&[u8]]) -> Result<(), BakeError> {
        match self {
            Sink::Memory { fields, filled } => {
                let n = chunk.first().map_or(0, |b| b.len() / 4);
                for (f, bytes) in fields.iter_mut().zip(chunk) {
                    bytemuck::cast_slice_mut::<f32, u8>(&mut f[*filled..*filled + n])
                        .copy_from_slice(bytes);
                }
                *filled += n;
            }
            Sink::Files { files, dir, .. } => {
                for (f, bytes) in files.iter_mut().zip(chunk) {
                    f.write_all(bytes)
                        .map_err(|source| scratch_error(dir, source))?;
                }
            }
        }
        Ok(())
    }

    fn into_store(self) -> Store {
        match self {
            Sink::Memory { fields, .. } => Store::Memory(fields),
            Sink::Files { files, total, dir } => Store::Spilled { files, total, dir },
        }
    }
}

fn scratch_error(dir: &std::path::Path, source: std::io::Error) -> BakeError {
    BakeError::Scratch {
        what: "the baked field values".to_string(),
        dir: dir.to_path_buf(),
        source,
    }
}

/// Fills `fields` (every field's values of `bricks`, brick after brick) with `cell_values`
/// on every brick in parallel.
fn fill(
    bricks: &[BrickBox],
    fields: &mut [Vec<f32>],
    cell_values: &(impl Fn(&BrickBox, &mut [&mut [f32]]) + Sync),
) {
    // Cut every field into the bricks' slices, then regroup them per brick.
    let mut rest: Vec<&mut [f32]> = fields.iter_mut().map(Vec::as_mut_slice).collect();
    let mut slices: Vec<Vec<&mut [f32]>> = Vec::with_capacity(bricks.len());
    for b in bricks {
        let n = b.cells() as usize;
        slices.push(
            rest.iter_mut()
                .map(|r| {
                    let (head, tail) = std::mem::take(r).split_at_mut(n);
                    *r = tail;
                    head
                })
                .collect(),
        );
    }
    slices
        .into_par_iter()
        .zip(bricks)
        .for_each(|(mut out, b)| cell_values(b, &mut out));
}
