//! A [`BrickFile`] whose field values are not in it: the archive is written with each
//! field's values taken from a slice the caller holds elsewhere (a scratch file mapped by
//! the baker), a chunk at a time, so that a billion cells' values never have to be one
//! `Vec` in memory to be written.
//!
//! [`Streamed`] mirrors [`BrickFile`] field for field and archives *as* its archived type
//! (`ArchivedBrickFile`), serialising its parts in the same order, so the bytes are the
//! ones [`crate::writer::write`] gives for the same file with the values inside it; the
//! tests check that byte for byte.

use rkyv::munge::munge;
use rkyv::rancor::{Fallible, Source};
use rkyv::ser::{Allocator, Writer, WriterExt};
use rkyv::vec::{ArchivedVec, VecResolver};
use rkyv::{Archive, Place, Serialize};

use crate::schema::{
    Aabb, ArchivedBrickFile, ArchivedField, BrickFile, KdNode, Provenance, Region, ValueRange,
};

/// Values written per chunk (16 MiB); `release` hears each chunk's range once written.
const CHUNK_VALUES: usize = 4 << 20;

/// What the writer calls with each field's index and range of values once they are
/// written (a caller holding them mapped lets those pages go).
pub type Release<'a> = &'a (dyn Fn(usize, std::ops::Range<usize>) + Sync);

/// The regions and KD-tree of a file, held apart from it (a bake of a billion cells keeps
/// their hundreds of megabytes in scratch files and hands them over mapped): they are
/// written in place of the file's own `regions`, `region_bricks`, `region_ranges`,
/// `kd_nodes` and `kd_axes`, a chunk at a time, and `release(part, range)` hears each
/// chunk once written (`part` counts the arrays in that order, 0 to 4).
#[derive(Clone, Copy)]
pub struct Structure<'a> {
    pub regions: &'a [Region],
    pub region_bricks: &'a [u32],
    pub region_ranges: &'a [ValueRange],
    pub kd_nodes: &'a [KdNode],
    pub kd_axes: &'a [u8],
    pub release: Release<'a>,
}

/// A [`BrickFile`] with the values of field `f` in `values[f]` (its own `values` are not
/// read, and are empty in practice), and its structure from a [`Structure`] when one is
/// given. Archived by hand as `ArchivedBrickFile`: each part is serialised as the derived
/// `BrickFile` serialises it, in the schema's field order.
pub(crate) struct Streamed<'a> {
    file: &'a BrickFile,
    fields: Vec<StreamedField<'a>>,
    structure: Option<Structure<'a>>,
}

/// One field, archived as `ArchivedField`.
struct StreamedField<'a> {
    field: &'a crate::schema::Field,
    values: Values<'a>,
}

type Resolver<T> = <T as Archive>::Resolver;

pub(crate) struct StreamedResolver {
    provenance: Resolver<Provenance>,
    bounds: Resolver<Aabb>,
    levels: VecResolver,
    fields: VecResolver,
    bricks: VecResolver,
    regions: VecResolver,
    region_bricks: VecResolver,
    region_ranges: VecResolver,
    kd_nodes: VecResolver,
    kd_axes: VecResolver,
}

impl Archive for Streamed<'_> {
    type Archived = ArchivedBrickFile;
    type Resolver = StreamedResolver;

    fn resolve(&self, r: Self::Resolver, out: Place<Self::Archived>) {
        let f = self.file;
        munge!(let ArchivedBrickFile {
            provenance, bounds, levels, fields, bricks, regions, region_bricks,
            region_ranges, kd_root, kd_nodes, kd_axes,
        } = out);
        f.provenance.resolve(r.provenance, provenance);
        f.bounds.resolve(r.bounds, bounds);
        f.levels.resolve(r.levels, levels);
        ArchivedVec::resolve_from_len(self.fields.len(), r.fields, fields);
        f.bricks.resolve(r.bricks, bricks);
        match &self.structure {
            Some(s) => {
                ArchivedVec::resolve_from_len(s.regions.len(), r.regions, regions);
                ArchivedVec::resolve_from_len(
                    s.region_bricks.len(),
                    r.region_bricks,
                    region_bricks,
                );
                ArchivedVec::resolve_from_len(
                    s.region_ranges.len(),
                    r.region_ranges,
                    region_ranges,
                );
            }
            None => {
                f.regions.resolve(r.regions, regions);
                f.region_bricks.resolve(r.region_bricks, region_bricks);
                f.region_ranges.resolve(r.region_ranges, region_ranges);
            }
        }
        f.kd_root.resolve((), kd_root);
        match &self.structure {
            Some(s) => {
                ArchivedVec::resolve_from_len(s.kd_nodes.len(), r.kd_nodes, kd_nodes);
                ArchivedVec::resolve_from_len(s.kd_axes.len(), r.kd_axes, kd_axes);
            }
            None => {
                f.kd_nodes.resolve(r.kd_nodes, kd_nodes);
                f.kd_axes.resolve(r.kd_axes, kd_axes);
            }
        }
    }
}

impl<S> Serialize<S> for Streamed<'_>
where
    S: Fallible + Allocator + Writer + ?Sized,
    S::Error: Source,
{
    fn serialize(&self, s: &mut S) -> Result<Self::Resolver, S::Error> {
        let f = self.file;
        let provenance = f.provenance.serialize(s)?;
        let bounds = f.bounds.serialize(s)?;
        let levels = f.levels.serialize(s)?;
        let fields = ArchivedVec::<ArchivedField>::serialize_from_slice(&self.fields, s)?;
        let bricks = f.bricks.serialize(s)?;
        let Some(st) = &self.structure else {
            return Ok(StreamedResolver {
                provenance,
                bounds,
                levels,
                fields,
                bricks,
                regions: f.regions.serialize(s)?,
                region_bricks: f.region_bricks.serialize(s)?,
                region_ranges: f.region_ranges.serialize(s)?,
                kd_nodes: f.kd_nodes.serialize(s)?,
                kd_axes: f.kd_axes.serialize(s)?,
            });
        };
        Ok(StreamedResolver {
            provenance,
            bounds,
            levels,
            fields,
            bricks,
            regions: plain_array(st.regions, 0, st.release, s)?,
            region_bricks: plain_array(st.region_bricks, 1, st.release, s)?,
            region_ranges: plain_array(st.region_ranges, 2, st.release, s)?,
            kd_nodes: plain_array(st.kd_nodes, 3, st.release, s)?,
            kd_axes: plain_array(st.kd_axes, 4, st.release, s)?,
        })
    }
}

pub(crate) struct FieldResolver {
    name: Resolver<String>,
    histogram: VecResolver,
    values: VecResolver,
}

impl Archive for StreamedField<'_> {
    type Archived = ArchivedField;
    type Resolver = FieldResolver;

    fn resolve(&self, r: Self::Resolver, out: Place<Self::Archived>) {
        let f = self.field;
        munge!(let ArchivedField { name, min, max, histogram, values } = out);
        f.name.resolve(r.name, name);
        f.min.resolve((), min);
        f.max.resolve((), max);
        f.histogram.resolve(r.histogram, histogram);
        self.values.resolve(r.values, values);
    }
}

impl<S> Serialize<S> for StreamedField<'_>
where
    S: Fallible + Allocator + Writer + ?Sized,
    S::Error: Source,
{
    fn serialize(&self, s: &mut S) -> Result<Self::Resolver, S::Error> {
        let f = self.field;
        Ok(FieldResolver {
            name: f.name.serialize(s)?,
            histogram: f.histogram.serialize(s)?,
            values: self.values.serialize(s)?,
        })
    }
}

/// Field `field`'s values archived as the `Vec<f32>` they stand for.
struct Values<'a> {
    values: &'a [f32],
    field: usize,
    release: Release<'a>,
}

impl Archive for Values<'_> {
    type Archived = ArchivedVec<rkyv::Archived<f32>>;
    type Resolver = VecResolver;

    fn resolve(&self, resolver: Self::Resolver, out: Place<Self::Archived>) {
        ArchivedVec::resolve_from_len(self.values.len(), resolver, out);
    }
}

impl<S> Serialize<S> for Values<'_>
where
    S: Fallible + Allocator + Writer + ?Sized,
    S::Error: Source,
{
    fn serialize(&self, serializer: &mut S) -> Result<Self::Resolver, S::Error> {
        // As rkyv lays out a `[f32]`: aligned for the archived value, then the values
        // little-endian, one after the other.
        let pos = serializer.align_for::<rkyv::Archived<f32>>()?;
        let mut start = 0;
        for chunk in self.values.chunks(CHUNK_VALUES) {
            if cfg!(target_endian = "little") {
                serializer.write(bytemuck::cast_slice(chunk))?;
            } else {
                let bytes: Vec<u8> = chunk.iter().flat_map(|v| v.to_le_bytes()).collect();
                serializer.write(&bytes)?;
            }
            (self.release)(self.field, start..start + chunk.len());
            start += chunk.len();
        }
        Ok(VecResolver::from_pos(pos))
    }
}

/// Plain values whose archived form is their little-endian bytes, field after field (the
/// schema's `repr(C)` structs of `u32`, `f32` and `f64` have no padding): what rkyv writes
/// for each element of a `Vec` of them. The tests compare the bytes with rkyv's own.
trait PlainLe: Archive + Copy {
    const SIZE: usize;
    fn put_le(&self, out: &mut Vec<u8>);
}

impl PlainLe for u8 {
    const SIZE: usize = 1;
    fn put_le(&self, out: &mut Vec<u8>) {
        out.push(*self);
    }
}

impl PlainLe for u32 {
    const SIZE: usize = 4;
    fn put_le(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl PlainLe for Region {
    const SIZE: usize = 8;
    fn put_le(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.bricks_start.to_le_bytes());
        out.extend_from_slice(&self.bricks_len.to_le_bytes());
    }
}

impl PlainLe for ValueRange {
    const SIZE: usize = 8;
    fn put_le(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.min.to_le_bytes());
        out.extend_from_slice(&self.max.to_le_bytes());
    }
}

impl PlainLe for KdNode {
    const SIZE: usize = 16;
    fn put_le(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.split.to_le_bytes());
        out.extend_from_slice(&self.left.to_le_bytes());
        out.extend_from_slice(&self.right.to_le_bytes());
    }
}

/// Bytes of plain values written per chunk.
const CHUNK_BYTES: usize = 4 << 20;

/// `values` archived as the `Vec` they stand for, a chunk at a time, `release(part, range)`
/// called on each chunk once written.
fn plain_array<T: PlainLe, S>(
    values: &[T],
    part: usize,
    release: Release<'_>,
    s: &mut S,
) -> Result<VecResolver, S::Error>
where
    S: Fallible + Writer + ?Sized,
    S::Error: Source,
{
    let pos = s.align_for::<T::Archived>()?;
    let per_chunk = (CHUNK_BYTES / T::SIZE).max(1);
    let mut bytes = Vec::with_capacity(per_chunk.min(values.len()) * T::SIZE);
    let mut start = 0;
    for chunk in values.chunks(per_chunk) {
        bytes.clear();
        for v in chunk {
            v.put_le(&mut bytes);
        }
        s.write(&bytes)?;
        release(part, start..start + chunk.len());
        start += chunk.len();
    }
    Ok(VecResolver::from_pos(pos))
}

impl<'a> Streamed<'a> {
    /// `file` with its structure taken from `structure` (see [`Streamed::new`]).
    pub(crate) fn with_structure(mut self, structure: Option<Structure<'a>>) -> Streamed<'a> {
        self.structure = structure;
        self
    }

    /// `file` with the values of field `f` taken from `values[f]`, `release` called on
    /// them as they are written; `None` when the counts differ.
    pub(crate) fn new(
        file: &'a BrickFile,
        values: &[&'a [f32]],
        release: Release<'a>,
    ) -> Option<Streamed<'a>> {
        if values.len() != file.fields.len() {
            return None;
        }
        Some(Streamed {
            file,
            fields: file
                .fields
                .iter()
                .zip(values)
                .enumerate()
                .map(|(f, (field, v))| StreamedField {
                    field,
                    values: Values {
                        values: v,
                        field: f,
                        release,
                    },
                })
                .collect(),
            structure: None,
        })
    }
}
