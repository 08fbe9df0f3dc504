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

use crate::schema::{Aabb, ArchivedBrickFile, ArchivedField, BrickFile, Provenance};

/// Values written per chunk (16 MiB); `release` hears each chunk's range once written.
const CHUNK_VALUES: usize = 4 << 20;

/// What the writer calls with each field's index and range of values once they are
/// written (a caller holding them mapped lets those pages go).
pub type Release<'a> = &'a (dyn Fn(usize, std::ops::Range<usize>) + Sync);

/// A [`BrickFile`] with the values of field `f` in `values[f]` (its own `values` are not
/// read, and are empty in practice). Archived by hand as `ArchivedBrickFile`: each part is
/// serialised as the derived `BrickFile` serialises it, in the schema's field order.
pub(crate) struct Streamed<'a> {
    file: &'a BrickFile,
    fields: Vec<StreamedField<'a>>,
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
        f.regions.resolve(r.regions, regions);
        f.region_bricks.resolve(r.region_bricks, region_bricks);
        f.region_ranges.resolve(r.region_ranges, region_ranges);
        f.kd_root.resolve((), kd_root);
        f.kd_nodes.resolve(r.kd_nodes, kd_nodes);
        f.kd_axes.resolve(r.kd_axes, kd_axes);
    }
}

impl<S> Serialize<S> for Streamed<'_>
where
    S: Fallible + Allocator + Writer + ?Sized,
    S::Error: Source,
{
    fn serialize(&self, s: &mut S) -> Result<Self::Resolver, S::Error> {
        let f = self.file;
        Ok(StreamedResolver {
            provenance: f.provenance.serialize(s)?,
            bounds: f.bounds.serialize(s)?,
            levels: f.levels.serialize(s)?,
            fields: ArchivedVec::<ArchivedField>::serialize_from_slice(&self.fields, s)?,
            bricks: f.bricks.serialize(s)?,
            regions: f.regions.serialize(s)?,
            region_bricks: f.region_bricks.serialize(s)?,
            region_ranges: f.region_ranges.serialize(s)?,
            kd_nodes: f.kd_nodes.serialize(s)?,
            kd_axes: f.kd_axes.serialize(s)?,
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

impl<'a> Streamed<'a> {
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
        })
    }
}
