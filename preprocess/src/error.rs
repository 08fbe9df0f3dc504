//! Why a bake is refused: one error type for every stage, from grid selection
//! ([`crate::bake::select_grids`]) and level assignment ([`crate::levels`]) to the bake
//! itself. It lives apart from both so that neither module has to import the other for it;
//! `crate::bake::BakeError` re-exports it.

use files::limits::LimitError;

/// Why a bake was refused.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    #[error("no grids to bake: the input has no vec3 or scalar grid")]
    NoGrids,
    #[error("no grid named \"{name}\" (grids: {available})")]
    GridNotFound { name: String, available: String },
    #[error("grid \"{grid}\" has a value type that cannot be baked (expected vec3s, vec3d, float or double)")]
    UnsupportedGrid { grid: String },
    #[error("several scalar grids ({names}) and no vec3 grid: choose one with --grid")]
    AmbiguousScalar { names: String },
    #[error("cannot bake vec3 grids and scalar grids together: {vector} vs {scalar}")]
    MixedKinds { vector: String, scalar: String },
    #[error(
        "scalar grid \"{grid}\" is baked as its own field; --fields applies to velocity grids only"
    )]
    FieldsForScalar { grid: String },
    #[error("no fields requested")]
    NoFields,
    #[error("--fields: field \"{0}\" is requested twice")]
    DuplicateField(String),
    #[error("--fields: no scalar grid named \"{name}\" (scalar grids: {available})")]
    FieldGridNotFound { name: String, available: String },
    #[error("--grid names several scalar grids ({names}): a scalar grid is baked as its own field, one per bake (or bake the velocity with --fields q,speed,<grid>,…)")]
    SeveralScalarGrids { names: String },
    #[error("grid \"{grid}\": field \"{field}\": {count} values are not finite as 32-bit floats (first at voxel {first:?}); refused because of --strict")]
    NonFiniteDerived {
        grid: String,
        field: String,
        count: u64,
        first: [i32; 3],
    },
    #[error("grid \"{grid}\": transform is not usable: {found}")]
    BadTransform { grid: String, found: String },
    #[error("grid \"{grid}\": voxels must be cubes, found voxel size {voxel_size:?}")]
    NonCubicVoxels { grid: String, voxel_size: [f64; 3] },
    #[error("grid \"{grid}\": voxel size {voxel_size} is not the finest voxel size {finest} times a power of two")]
    NonPowerOfTwo {
        grid: String,
        voxel_size: f64,
        finest: f64,
    },
    /// The bake's memory estimate (or an allocation) is over the shared limit.
    #[error(transparent)]
    Memory(#[from] LimitError),
    /// The file would be larger than the format can address ([`format::MAX_ARCHIVE_BYTES`]).
    #[error("{leaf_cells} leaf cells with {fields} field(s) make a .qbk archive of about {} MiB, more than the {} MiB its 32-bit offsets reach; bake a part of the data, or fewer fields", bytes >> 20, format::MAX_ARCHIVE_BYTES >> 20)]
    TooLargeForFormat {
        leaf_cells: u64,
        fields: u64,
        bytes: u64,
    },
    #[error("grid \"{grid}\": {count} non-finite values (first at voxel {first:?}); refused because of --strict")]
    NonFinite {
        grid: String,
        count: u64,
        first: [i32; 3],
    },
    #[error("--max-brick must be at least 1, found {0}")]
    BadMaxBrick(u32),
    #[error("grids have no active cells")]
    Empty,
    /// A leaf of the file's KD-tree names its region in 31 bits.
    #[error("{regions} regions exceed the file format's limit of {limit}")]
    TooManyRegions { regions: u64, limit: u64 },
    #[error("thread pool: {0}")]
    ThreadPool(String),
}
