//! Why a bake is refused: one error type for every stage, from grid selection
//! ([`crate::bake::select_grids`]) and level assignment ([`crate::levels`]) to the bake
//! itself. It lives apart from both so that neither module has to import the other for it;
//! `crate::bake::BakeError` re-exports it.

use std::fmt;

use files::limits::LimitError;

/// How far from the origin, in voxels of the finest baked size, a baked voxel may lie.
/// The bake works in world coordinates and decides what it cuts and merges with a
/// tolerance of 1e-7 of a cell (leaf-cell classification, support snapping); at 2^26
/// voxels out a coordinate's double-precision spacing is 2^-26 (1.5e-8) of a voxel, well
/// inside it, and bakes of one layout placed anywhere up to there give the same bricks and
/// regions (tested; the first difference showed near 2^32). Far enough out (a grid
/// translated to 1e300 with voxels of 0.1) neighbouring centres are the same number and
/// the file would be nonsense. 2^26 voxels of 0.1 m are 6700 km, so data placed in a
/// geographic frame still fits at that resolution. The viewer's own bound
/// ([`format::MAX_REACH_LOG2`], 2^40) is wider, so everything baked opens.
pub const MAX_BAKE_REACH_LOG2: i32 = 26;
/// [`MAX_BAKE_REACH_LOG2`] as a number.
pub const MAX_REACH: f64 = (1u64 << MAX_BAKE_REACH_LOG2) as f64;

/// `1.2e13`-style for huge counts, plain below a million.
fn fmt_cells(x: f64) -> String {
    if x < 1e6 {
        format!("{x:.0}")
    } else {
        format!("{x:.1e}")
    }
}

/// One grid's share of a count of values (non-finite, overflowing), for messages.
#[derive(Debug, Clone, PartialEq)]
pub struct GridCount {
    /// The grid as [`grid_labels`] names it (`"vel"`, or `"vel" (2nd of 3 of that name)`).
    pub grid: String,
    pub count: u64,
    /// Index coordinate of the first value counted.
    pub first: [i32; 3],
}

/// Every grid a count of values came from, each with its share and first voxel: one
/// message names them all, never only the first.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GridCounts(pub Vec<GridCount>);

impl fmt::Display for GridCounts {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, g) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(
                f,
                "{} in grid {} (first at voxel {:?})",
                g.count, g.grid, g.first
            )?;
        }
        Ok(())
    }
}

/// Names of grids for messages, in the order given: the quoted name, and where several
/// grids share it, which of them (`"vel" (2nd of 3 of that name)`).
pub(crate) fn grid_labels<'a>(names: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    let names: Vec<&str> = names.into_iter().collect();
    names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let same = names.iter().filter(|m| *m == n).count();
            if same == 1 {
                format!("\"{n}\"")
            } else {
                let k = names[..=i].iter().filter(|m| *m == n).count();
                format!("\"{n}\" ({} of {same} of that name)", ordinal(k))
            }
        })
        .collect()
}

fn ordinal(k: usize) -> String {
    let suffix = match (k % 10, k % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{k}{suffix}")
}

/// The error for `--fields NAME` when `NAME` is no scalar grid of the file (`grids`: every
/// grid's name and kind): a vec3 grid is said to be one, with how to bake it; otherwise
/// the scalar grids are listed, or their absence said.
pub(crate) fn field_grid_not_found(
    name: &str,
    grids: &[(&str, crate::grid::GridKind)],
) -> BakeError {
    use crate::grid::GridKind;
    if grids
        .iter()
        .any(|(g, k)| *g == name && *k == GridKind::Vector)
    {
        return BakeError::FieldIsVector {
            name: name.to_string(),
        };
    }
    let mut scalars: Vec<&str> = grids
        .iter()
        .filter(|(_, k)| *k == GridKind::Scalar)
        .map(|(g, _)| *g)
        .collect();
    scalars.sort_unstable();
    scalars.dedup();
    let available = if scalars.is_empty() {
        "the file has no scalar grids".to_string()
    } else {
        format!(
            "scalar grids: {}",
            scalars
                .iter()
                .map(|n| format!("\"{n}\""))
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    BakeError::FieldGridNotFound {
        name: name.to_string(),
        available,
    }
}

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
    /// `available` is "scalar grids: …" or says that there is none.
    #[error("--fields: no scalar grid named \"{name}\" ({available})")]
    FieldGridNotFound { name: String, available: String },
    #[error("--fields: \"{name}\" is a vec3 grid, and a field list takes q, speed, vorticity, lambda2, helicity, velocity and scalar grids: to bake it as the velocity, give --velocity {name} (with --fields q,speed,velocity for its components)")]
    FieldIsVector { name: String },
    #[error("--grid names several scalar grids ({names}): a scalar grid is baked as its own field, one per bake (or bake the velocity with --fields q,speed,<grid>,…)")]
    SeveralScalarGrids { names: String },
    #[error("field \"{field}\": {count} values are not finite as 32-bit floats: {grids}; refused because of --strict")]
    NonFiniteDerived {
        field: String,
        count: u64,
        grids: GridCounts,
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
    /// The bake's estimate is over the `--memory` budget even with every value kept on
    /// disk; `least` is the least budget it fits in. `shared`: the whole budget and how
    /// many bakes share it, when `budget` is a share of it (a sequence's `--jobs`).
    #[error("{}", over_budget(what, *budget, *least, *shared))]
    OverBudget {
        what: String,
        budget: u64,
        least: u64,
        shared: Option<(u64, usize)>,
    },
    /// A leaf of a grid located in the file (decoded as it becomes cells) is malformed.
    #[error(transparent)]
    Vdb(#[from] Box<crate::vdb::VdbError>),
    #[error("rank {rank} sent {got} bytes of field values where {want} were due (ranks of one bake disagree: were they given the same input?)")]
    PeerMessage { rank: usize, got: u64, want: u64 },
    #[error("cannot keep {what} in a scratch file in {}: {source}", dir.display())]
    Scratch {
        /// What was to be kept there: the baked field values, a grid's cells.
        what: String,
        dir: std::path::PathBuf,
        source: std::io::Error,
    },
    #[error("grid \"{grid}\" (voxel size {voxel_size}): voxels reach {reach:e} from the origin, {} voxels of the finest size {finest} out: too far for double precision to place cells exactly (the bake takes 2^{MAX_BAKE_REACH_LOG2}, about {:.1e}, finest voxels); translate the grid towards the origin", fmt_cells(*reach / *finest), MAX_REACH)]
    FarFromOrigin {
        grid: String,
        reach: f64,
        voxel_size: f64,
        finest: f64,
    },
    /// The file would be larger than a `.qbk` may be ([`format::MAX_ARCHIVE_BYTES`]).
    #[error("{leaf_cells} leaf cells with {fields} field(s) make a .qbk archive of about {} MiB, more than the {} MiB a .qbk may hold; bake a part of the data, or fewer fields", bytes >> 20, format::MAX_ARCHIVE_BYTES >> 20)]
    TooLargeForFormat {
        leaf_cells: u64,
        fields: u64,
        bytes: u64,
    },
    #[error("{count} non-finite values: {grids}; refused because of --strict")]
    NonFinite { count: u64, grids: GridCounts },
    #[error("field \"{field}\": grid \"{field}\" has no active voxel at any of the velocity's {cells} leaf cells, so every value would be its background {background} (its voxels lie in {extra}, the velocity's cells in {velocity})")]
    FieldNotCovered {
        field: String,
        cells: u64,
        background: f64,
        extra: String,
        velocity: String,
    },
    #[error("--max-brick must be at least 1, found {0}")]
    BadMaxBrick(u32),
    #[error("grids have no active cells")]
    Empty,
    /// A leaf of the file's KD-tree names its region in 31 bits.
    #[error("{regions} regions exceed the file format's limit of {limit}")]
    TooManyRegions { regions: u64, limit: u64 },
    /// A region names its bricks by a 32-bit run into one list.
    #[error("{refs} brick references of the regions exceed the file format's limit of {limit}")]
    TooManyBrickRefs { refs: u64, limit: u64 },
    #[error("thread pool: {0}")]
    ThreadPool(String),
}

/// The message of [`BakeError::OverBudget`]: the least budget that would do, as the user
/// gives it (for a shared budget, the whole of it: every bake run at once gets that share).
fn over_budget(what: &str, budget: u64, least: u64, shared: Option<(u64, usize)>) -> String {
    let mib = |b: u64| b.div_ceil(1 << 20);
    let needs = format!(
        "{what} needs about {} MiB even with every value kept on disk (what is left: the cells' masks and the bricks)",
        mib(least)
    );
    match shared {
        Some((total, jobs)) if jobs > 1 => format!(
            "{needs}, more than its share of the --memory budget: {} MiB of {} MiB, shared by {jobs} frames baked at once: give --memory {}M or more, or fewer --jobs",
            budget >> 20,
            total >> 20,
            mib(least).saturating_mul(jobs as u64)
        ),
        _ => format!(
            "{needs}, more than the --memory budget of {} MiB: give --memory {}M or more",
            budget >> 20,
            mib(least)
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::GridKind;

    #[test]
    fn grids_sharing_a_name_are_told_apart() {
        assert_eq!(
            grid_labels(["vel", "a", "vel", "vel"]),
            [
                "\"vel\" (1st of 3 of that name)",
                "\"a\"",
                "\"vel\" (2nd of 3 of that name)",
                "\"vel\" (3rd of 3 of that name)"
            ]
        );
    }

    #[test]
    fn a_field_that_is_no_scalar_grid_says_what_it_is() {
        let grids = [("vel", GridKind::Vector), ("vel2", GridKind::Vector)];
        assert_eq!(
            field_grid_not_found("vel2", &grids).to_string(),
            "--fields: \"vel2\" is a vec3 grid, and a field list takes q, speed, vorticity, \
             lambda2, helicity, velocity and scalar grids: to bake it as the velocity, give --velocity vel2 (with --fields \
             q,speed,velocity for its components)"
        );
        assert_eq!(
            field_grid_not_found("nope", &grids).to_string(),
            "--fields: no scalar grid named \"nope\" (the file has no scalar grids)"
        );
        let grids = [
            ("b", GridKind::Scalar),
            ("a", GridKind::Scalar),
            ("b", GridKind::Scalar),
        ];
        assert_eq!(
            field_grid_not_found("nope", &grids).to_string(),
            "--fields: no scalar grid named \"nope\" (scalar grids: \"a\", \"b\")"
        );
    }

    #[test]
    fn a_count_names_every_grid_it_came_from() {
        let e = BakeError::NonFinite {
            count: 3,
            grids: GridCounts(vec![
                GridCount {
                    grid: "\"a\"".into(),
                    count: 2,
                    first: [1, 1, 1],
                },
                GridCount {
                    grid: "\"b\"".into(),
                    count: 1,
                    first: [0, 0, 0],
                },
            ]),
        };
        assert_eq!(
            e.to_string(),
            "3 non-finite values: 2 in grid \"a\" (first at voxel [1, 1, 1]), 1 in grid \"b\" \
             (first at voxel [0, 0, 0]); refused because of --strict"
        );
    }
}
