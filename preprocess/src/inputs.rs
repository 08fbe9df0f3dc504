//! Which grids of a file make the velocity: vec3 grids, or three scalar component grids
//! (`X.x`/`X.y`/`X.z`, `X_x`/…, or `Xx`/… where unambiguous, as Houdini and other tools
//! export velocity) merged into one vec3 grid named `X`.
//!
//! Selection works on names and types alone ([`velocity_candidates`], [`choose_velocity`]),
//! so it is decided before any tree is decoded; [`merge_components`] then checks that the
//! three grids describe one field (same transform, same active voxels) and joins them.

use std::collections::{BTreeMap, HashMap};

use files::limits::{self, LimitError};

use crate::bake::memory::{leaf_bytes, GridFootprint};
use crate::bake::{select_grids, BakeError, BakeGrid, GridKind};
use crate::error::field_grid_not_found;
use crate::grid::{AnyGrid, Grid, Leaf, Transform, LEAF_DIM, LEAF_VOXELS};
use crate::vdb::{GridDescriptor, ValueType, VdbError, VdbFile};

/// Where the velocity components of vec3 grids sit (`--layout`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Layout {
    /// From each grid's class: `staggered` grids are MAC grids, others cell-centred.
    #[default]
    Auto,
    /// Every vec3 grid holds velocities at cell centres, whatever its class says.
    #[value(alias = "centered")]
    Centred,
    /// Every vec3 grid is a MAC grid (component c on the lower face along axis c).
    Staggered,
}

/// What to read from a file for a bake.
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    /// Grids by exact name (`--grid`), as [`select_grids`] takes them.
    pub grids: Vec<String>,
    /// Velocity candidates by name (`--velocity`), see [`choose_velocity`].
    pub velocity: Vec<String>,
    pub layout: Layout,
    /// Scalar grids baked as extra fields (every scalar grid of each name is read too).
    pub extra: Vec<String>,
}

/// Why reading the bake input failed.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error(transparent)]
    Vdb(#[from] VdbError),
    #[error(transparent)]
    Input(#[from] InputError),
    #[error(transparent)]
    Bake(#[from] BakeError),
    #[error("--grid and --velocity cannot be combined (--grid names grids, --velocity names a velocity)")]
    GridAndVelocity,
}

/// The grids of `file` to bake, and the names of those that are MAC grids under
/// `opts.layout`. They are located, not decoded (see [`crate::vdb::located`]): the bake
/// decodes them a batch of leaves at a time as they become cells. Component grids are
/// decoded here, to be checked and merged.
pub fn read_inputs(
    file: &VdbFile,
    opts: &ReadOptions,
) -> Result<(Vec<BakeGrid>, Vec<String>), ReadError> {
    let descs = file.grids();
    let kinds: Vec<(&str, GridKind)> = descs
        .iter()
        .map(|g| {
            let k = match g.value_type {
                ValueType::Vec3s | ValueType::Vec3d => GridKind::Vector,
                ValueType::Float | ValueType::Double => GridKind::Scalar,
                ValueType::Unsupported(_) => GridKind::Other,
            };
            (g.name.as_str(), k)
        })
        .collect();
    if !opts.grids.is_empty() && !opts.velocity.is_empty() {
        return Err(ReadError::GridAndVelocity);
    }
    let staggered = |g: &GridDescriptor| match opts.layout {
        Layout::Auto => g.is_staggered(),
        Layout::Centred => false,
        Layout::Staggered => true,
    };
    let velocity = if opts.grids.is_empty() {
        choose_velocity(&kinds, &opts.velocity)?
    } else {
        None
    };
    let Some(velocity) = velocity else {
        let chosen = select_grids(&kinds, &opts.grids)?;
        let mac = chosen
            .iter()
            .map(|&i| &descs[i])
            .filter(|g| g.value_type.is_vector() && staggered(g))
            .map(|g| g.name.clone())
            .collect();
        let mut grids = chosen
            .iter()
            .map(|&i| file.locate_grid(i).map(BakeGrid::Located))
            .collect::<Result<Vec<_>, _>>()?;
        read_extra(file, &kinds, &opts.extra, &chosen, &mut grids)?;
        return Ok((grids, mac));
    };
    let mut grids = Vec::new();
    let mut mac = Vec::new();
    let mut read = Vec::new();
    for v in velocity {
        match v {
            Velocity::Vector { name, grids: ids } => {
                if ids.iter().any(|&i| staggered(&descs[i])) {
                    mac.push(name);
                }
                for i in ids {
                    grids.push(BakeGrid::Located(file.locate_grid(i)?));
                    read.push(i);
                }
            }
            Velocity::Split { name, parts } => {
                if parts.iter().all(|&i| staggered(&descs[i])) {
                    mac.push(name.clone());
                }
                let [x, y, z] = parts.map(|i| file.read_grid(i));
                let merged = match (x?, y?, z?) {
                    (AnyGrid::Float(x), AnyGrid::Float(y), AnyGrid::Float(z)) => {
                        merge_components(&name, [&x, &y, &z])?
                    }
                    (x, y, z) => {
                        let [x, y, z] = [x, y, z].map(widen);
                        merge_components(&name, [&x, &y, &z])?
                    }
                };
                grids.push(BakeGrid::Decoded(AnyGrid::Vec3d(merged)));
            }
        }
    }
    read_extra(file, &kinds, &opts.extra, &read, &mut grids)?;
    Ok((grids, mac))
}

/// Appends every scalar grid named in `extra` that is not among `done` (file indices);
/// a name without a scalar grid is an error listing the file's scalar grids.
fn read_extra(
    file: &VdbFile,
    kinds: &[(&str, GridKind)],
    extra: &[String],
    done: &[usize],
    grids: &mut Vec<BakeGrid>,
) -> Result<(), ReadError> {
    let scalar = |n: &str| kinds.iter().any(|(g, k)| *k == GridKind::Scalar && *g == n);
    if let Some(missing) = extra.iter().find(|n| !scalar(n)) {
        return Err(field_grid_not_found(missing, kinds).into());
    }
    for (i, (name, kind)) in kinds.iter().enumerate() {
        if *kind == GridKind::Scalar && !done.contains(&i) && extra.iter().any(|e| e == name) {
            grids.push(BakeGrid::Located(file.locate_grid(i)?));
        }
    }
    Ok(())
}

/// A scalar grid as doubles (vector grids become empty: component sets hold scalars only).
fn widen(g: AnyGrid) -> Grid<f64> {
    match g {
        AnyGrid::Double(g) => g,
        AnyGrid::Float(g) => Grid {
            name: g.name,
            transform: g.transform,
            background: g.background.into(),
            leaves: g
                .leaves
                .into_iter()
                .map(|l| Leaf {
                    origin: l.origin,
                    active: l.active,
                    values: Box::new(l.values.map(f64::from)),
                })
                .collect(),
            tiles: g
                .tiles
                .into_iter()
                .map(|t| crate::grid::Tile {
                    origin: t.origin,
                    size: t.size,
                    value: t.value.into(),
                })
                .collect(),
        },
        AnyGrid::Vec3s(g) => Grid {
            name: g.name,
            transform: g.transform,
            background: 0.0,
            leaves: vec![],
            tiles: vec![],
        },
        AnyGrid::Vec3d(g) => Grid {
            name: g.name,
            transform: g.transform,
            background: 0.0,
            leaves: vec![],
            tiles: vec![],
        },
    }
}

/// One velocity candidate of a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Velocity {
    /// Every vec3 grid with this name (file indices).
    Vector { name: String, grids: Vec<usize> },
    /// Three scalar grids (x, y, z components, file indices) taken as one grid `name`.
    Split { name: String, parts: [usize; 3] },
}

impl Velocity {
    pub(crate) fn name(&self) -> &str {
        match self {
            Velocity::Vector { name, .. } | Velocity::Split { name, .. } => name,
        }
    }
}

/// Why the velocity could not be chosen or assembled.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    #[error("no velocity named \"{name}\" (candidates: {candidates})")]
    VelocityNotFound { name: String, candidates: String },
    #[error("several velocity candidates ({candidates}): choose one with --velocity")]
    AmbiguousVelocity { candidates: String },
    #[error("component grids {grids}: {what}")]
    ComponentMismatch { grids: String, what: String },
    #[error("component grids {grids}: {error}")]
    Memory { grids: String, error: LimitError },
    /// Three component names are there, but one is held by several grids.
    #[error("component grids {grids} cannot make the velocity \"{name}\": {duplicates} (each component must be exactly one grid; rename or remove the others)")]
    DuplicateComponent {
        name: String,
        grids: String,
        duplicates: String,
    },
}

fn quoted<'a>(names: impl IntoIterator<Item = &'a str>) -> String {
    names
        .into_iter()
        .map(|n| format!("\"{n}\""))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Component suffix styles, in order of precedence: `X.x`, `X_x`, then `Xx`.
const STYLES: [&str; 3] = [".", "_", ""];

/// Velocity candidates of a file (name, kind per grid, file order): every vec3 grid name
/// (all grids of that name), then every complete set of three scalar component grids.
///
/// A component set needs exactly one scalar grid of each of the three names. The bare style
/// (`velx`, `vely`, `velz`) is taken only where it is unambiguous: its base is not empty,
/// does not end in `.` or `_` (those are the other styles' grids), none of its grids belongs
/// to another set, and no other candidate has the same name.
pub(crate) fn velocity_candidates(grids: &[(&str, GridKind)]) -> Vec<Velocity> {
    let mut out: Vec<Velocity> = Vec::new();
    for (i, (name, kind)) in grids.iter().enumerate() {
        if *kind != GridKind::Vector || out.iter().any(|v| v.name() == *name) {
            continue;
        }
        let all = (i..grids.len())
            .filter(|&j| grids[j].0 == *name && grids[j].1 == GridKind::Vector)
            .collect();
        out.push(Velocity::Vector {
            name: name.to_string(),
            grids: all,
        });
    }
    // Scalar grids by name; a name held by several grids cannot be a component.
    let mut scalars: HashMap<&str, Vec<usize>> = HashMap::new();
    for (i, (name, kind)) in grids.iter().enumerate() {
        if *kind == GridKind::Scalar {
            scalars.entry(name).or_default().push(i);
        }
    }
    let unique = |n: &str| match scalars.get(n).map(Vec::as_slice) {
        Some([i]) => Some(*i),
        _ => None,
    };
    let mut used = vec![false; grids.len()];
    for style in STYLES {
        let mut found: BTreeMap<usize, Velocity> = BTreeMap::new();
        for (name, kind) in grids {
            if *kind != GridKind::Scalar {
                continue;
            }
            let Some(base) = name.strip_suffix(&format!("{style}x")) else {
                continue;
            };
            if style.is_empty() && (base.is_empty() || base.ends_with(['.', '_'])) {
                continue;
            }
            let parts = ["x", "y", "z"].map(|c| unique(&format!("{base}{style}{c}")));
            let [Some(x), Some(y), Some(z)] = parts else {
                continue;
            };
            if [x, y, z].iter().any(|&p| used[p]) {
                continue;
            }
            if style.is_empty() && out.iter().any(|v| v.name() == base) {
                continue;
            }
            found.insert(
                x,
                Velocity::Split {
                    name: base.to_string(),
                    parts: [x, y, z],
                },
            );
        }
        for v in found.into_values() {
            if let Velocity::Split { parts, .. } = &v {
                parts.iter().for_each(|&p| used[p] = true);
            }
            out.push(v);
        }
    }
    out
}

/// Component sets that are complete but for a name several grids hold (`vel.x` twice):
/// no velocity candidate (which grid would be the x component?), but worth naming, since
/// otherwise the file only seems to have no velocity. One error per set, keyed by its base
/// name, in file order.
fn duplicated_sets(grids: &[(&str, GridKind)]) -> Vec<(String, InputError)> {
    let mut count: HashMap<&str, usize> = HashMap::new();
    for (name, kind) in grids {
        if *kind == GridKind::Scalar {
            *count.entry(name).or_default() += 1;
        }
    }
    let mut out: Vec<(String, InputError)> = Vec::new();
    for style in STYLES {
        for (name, kind) in grids {
            let Some(base) = name.strip_suffix(&format!("{style}x")) else {
                continue;
            };
            if *kind != GridKind::Scalar
                || (style.is_empty() && (base.is_empty() || base.ends_with(['.', '_'])))
                || out.iter().any(|(b, _)| b == base)
            {
                continue;
            }
            let names = ["x", "y", "z"].map(|c| format!("{base}{style}{c}"));
            let counts = names
                .clone()
                .map(|n| count.get(n.as_str()).copied().unwrap_or(0));
            if counts.contains(&0) || counts.iter().all(|&c| c == 1) {
                continue;
            }
            let duplicates = names
                .iter()
                .zip(counts)
                .filter(|(_, c)| *c > 1)
                .map(|(n, c)| format!("{c} grids are named \"{n}\""))
                .collect::<Vec<_>>()
                .join(", ");
            out.push((
                base.to_string(),
                InputError::DuplicateComponent {
                    name: base.to_string(),
                    grids: quoted(names.iter().map(String::as_str)),
                    duplicates,
                },
            ));
        }
    }
    out
}

/// The velocity to bake: the candidates named in `names` (any number, e.g. the levels of a
/// nested set), or `None` when no name is given and the file has no component grids (the
/// caller then keeps its default: every vec3 grid). Without names, one component set and no
/// vec3 grid is taken as the velocity; any other mix is ambiguous.
pub(crate) fn choose_velocity(
    grids: &[(&str, GridKind)],
    names: &[String],
) -> Result<Option<Vec<Velocity>>, InputError> {
    let cands = velocity_candidates(grids);
    let list = || quoted(cands.iter().map(Velocity::name));
    if !names.is_empty() {
        let mut out = Vec::new();
        for n in names {
            let Some(v) = cands.iter().find(|v| v.name() == n) else {
                // A set of that name with a duplicated component says so.
                if let Some((_, e)) = duplicated_sets(grids).into_iter().find(|(b, _)| b == n) {
                    return Err(e);
                }
                return Err(InputError::VelocityNotFound {
                    name: n.clone(),
                    candidates: list(),
                });
            };
            if !out.contains(v) {
                out.push(v.clone());
            }
        }
        return Ok(Some(out));
    }
    let split = cands
        .iter()
        .filter(|v| matches!(v, Velocity::Split { .. }))
        .count();
    match (split, cands.len()) {
        // Without any velocity, a component set broken by a duplicate is what was meant.
        (0, 0) => match duplicated_sets(grids).into_iter().next() {
            Some((_, e)) => Err(e),
            None => Ok(None),
        },
        (0, _) => Ok(None),
        (1, 1) => Ok(Some(cands)),
        _ => Err(InputError::AmbiguousVelocity { candidates: list() }),
    }
}

/// Block origin → (active mask, values).
type Blocks<V> = BTreeMap<[i32; 3], ([u64; 8], Box<[V; LEAF_VOXELS]>)>;

/// Active voxels of `g` as 8³ blocks (origin → mask, values), tiles expanded; the caller
/// bounds the voxel count first.
fn blocks<V: Copy + Default>(g: &Grid<V>) -> Blocks<V> {
    let mut out: Blocks<V> = BTreeMap::new();
    let d = LEAF_DIM as i64;
    for t in &g.tiles {
        let lo = t.origin.map(i64::from);
        let n = (i64::from(t.size) / d).max(1);
        for bx in 0..n {
            for by in 0..n {
                for bz in 0..n {
                    let o = [lo[0] + bx * d, lo[1] + by * d, lo[2] + bz * d];
                    let Ok(o) = o
                        .map(i32::try_from)
                        .into_iter()
                        .collect::<Result<Vec<_>, _>>()
                    else {
                        continue;
                    };
                    let origin = [o[0], o[1], o[2]];
                    out.insert(origin, ([u64::MAX; 8], Box::new([t.value; LEAF_VOXELS])));
                }
            }
        }
    }
    for l in &g.leaves {
        let e = out
            .entry(l.origin)
            .or_insert_with(|| ([0; 8], Box::new([V::default(); LEAF_VOXELS])));
        for n in 0..LEAF_VOXELS {
            if l.is_active(n) {
                e.0[n >> 6] |= 1 << (n & 63);
                e.1[n] = l.values[n];
            }
        }
    }
    out.retain(|_, (m, _)| m.iter().any(|&w| w != 0));
    out
}

/// Joins three scalar component grids into one vec3 grid `name` (values widened to f64).
/// Refused when the transforms differ or the active voxels differ (leaf/tile structure may
/// differ: a tile and a full leaf holding the same voxels match), or when expanding them
/// would take more memory than the shared limit allows (estimated before tiles are
/// expanded: three grids of blocks and the merged one).
pub fn merge_components<V: Copy + Default + Into<f64>>(
    name: &str,
    parts: [&Grid<V>; 3],
) -> Result<Grid<[f64; 3]>, InputError> {
    let grids = quoted(parts.iter().map(|g| g.name.as_str()));
    let t0: Transform = parts[0].transform;
    for p in &parts[1..] {
        if p.transform != t0 {
            return Err(InputError::ComponentMismatch {
                grids,
                what: format!(
                    "different transforms: \"{}\" has voxel size {:?} and translation {:?}, \"{}\" has voxel size {:?} and translation {:?}",
                    parts[0].name, t0.voxel_size, t0.translation, p.name, p.transform.voxel_size,
                    p.transform.translation
                ),
            });
        }
    }
    let counts = parts.map(Grid::active_voxel_count);
    // Every block of every part as a map entry with its values, and the merged leaves.
    let part_blocks = parts
        .iter()
        .map(|p| GridFootprint::of_grid(p).blocks)
        .fold(0u64, u64::saturating_add);
    let need = part_blocks
        .saturating_mul(leaf_bytes::<V>() + 64)
        .saturating_add(
            GridFootprint::of_grid(parts[0])
                .blocks
                .saturating_mul(leaf_bytes::<[f64; 3]>()),
        );
    let memory = |error| InputError::Memory {
        grids: grids.clone(),
        error,
    };
    limits::check_memory(
        format!(
            "merging {} active voxels into the velocity \"{name}\"",
            counts[0]
        ),
        need,
    )
    .map_err(memory)?;
    if counts[0] != counts[1] || counts[0] != counts[2] {
        return Err(InputError::ComponentMismatch {
            grids,
            what: format!(
                "active sets differ ({}, {} and {} active voxels)",
                counts[0], counts[1], counts[2]
            ),
        });
    }
    let [bx, by, bz] = parts.map(blocks);
    let mut leaves =
        limits::with_capacity(format!("the velocity \"{name}\""), bx.len()).map_err(memory)?;
    for (origin, (mask, xv)) in &bx {
        let (yb, zb) = match (by.get(origin), bz.get(origin)) {
            (Some(y), Some(z)) if y.0 == *mask && z.0 == *mask => (y, z),
            _ => {
                return Err(InputError::ComponentMismatch {
                    grids,
                    what: format!("active sets differ in the 8³ block at voxel {origin:?}"),
                })
            }
        };
        leaves.push(Leaf {
            origin: *origin,
            active: *mask,
            values: Box::new(std::array::from_fn(|n| {
                [xv[n].into(), yb.1[n].into(), zb.1[n].into()]
            })),
        });
    }
    Ok(Grid {
        name: name.to_string(),
        transform: t0,
        background: [
            parts[0].background.into(),
            parts[1].background.into(),
            parts[2].background.into(),
        ],
        leaves,
        tiles: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kinds<'a>(v: &[(&'a str, GridKind)]) -> Vec<(&'a str, GridKind)> {
        v.to_vec()
    }

    #[test]
    fn candidates_by_style() {
        use GridKind::*;
        let g = kinds(&[
            ("vel.x", Scalar),
            ("vel.y", Scalar),
            ("vel.z", Scalar),
            ("v_x", Scalar),
            ("v_y", Scalar),
            ("v_z", Scalar),
            ("ux", Scalar),
            ("uy", Scalar),
            ("uz", Scalar),
            ("density", Scalar),
            ("flow", Vector),
        ]);
        let c = velocity_candidates(&g);
        let names: Vec<&str> = c.iter().map(Velocity::name).collect();
        assert_eq!(names, ["flow", "vel", "v", "u"]);
        assert_eq!(
            c[1],
            Velocity::Split {
                name: "vel".into(),
                parts: [0, 1, 2]
            }
        );
        // `v_x` is not also read as the bare style with base `v_`.
        assert!(!names.contains(&"v_"));
    }

    #[test]
    fn ambiguous_bare_style_and_duplicates_are_not_candidates() {
        use GridKind::*;
        // `velx` would be named like the vec3 grid `vel`.
        let g = kinds(&[
            ("vel", Vector),
            ("velx", Scalar),
            ("vely", Scalar),
            ("velz", Scalar),
        ]);
        assert_eq!(velocity_candidates(&g).len(), 1);
        // Two grids named `a.y`: not a component set.
        let g = kinds(&[
            ("a.x", Scalar),
            ("a.y", Scalar),
            ("a.y", Scalar),
            ("a.z", Scalar),
        ]);
        assert!(velocity_candidates(&g).is_empty());
        // Missing component.
        let g = kinds(&[("a.x", Scalar), ("a.y", Scalar)]);
        assert!(velocity_candidates(&g).is_empty());
    }

    #[test]
    fn choosing() {
        use GridKind::*;
        let g = kinds(&[("vel.x", Scalar), ("vel.y", Scalar), ("vel.z", Scalar)]);
        let one = choose_velocity(&g, &[]).unwrap().unwrap();
        assert_eq!(one[0].name(), "vel");
        let g = kinds(&[
            ("vel.x", Scalar),
            ("vel.y", Scalar),
            ("vel.z", Scalar),
            ("v", Vector),
        ]);
        let e = choose_velocity(&g, &[]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "several velocity candidates (\"v\", \"vel\"): choose one with --velocity"
        );
        assert_eq!(
            choose_velocity(&g, &["v".into()]).unwrap().unwrap().len(),
            1
        );
        assert!(matches!(
            choose_velocity(&g, &["w".into()]),
            Err(InputError::VelocityNotFound { .. })
        ));
        // No component grids: the caller's default applies.
        let g = kinds(&[("v", Vector), ("d", Scalar)]);
        assert_eq!(choose_velocity(&g, &[]).unwrap(), None);
    }

    /// Issue 32: `vel.x` twice made no candidate, and the file seemed to hold several
    /// unrelated scalar grids (or no velocity "vel" at all, with --velocity vel).
    #[test]
    fn a_duplicated_component_is_named() {
        use GridKind::*;
        let g = kinds(&[
            ("vel.x", Scalar),
            ("vel.x", Scalar),
            ("vel.y", Scalar),
            ("vel.z", Scalar),
        ]);
        let expected = "component grids \"vel.x\", \"vel.y\", \"vel.z\" cannot make the \
                        velocity \"vel\": 2 grids are named \"vel.x\" (each component must be \
                        exactly one grid; rename or remove the others)";
        let e = choose_velocity(&g, &[]).unwrap_err();
        assert_eq!(e.to_string(), expected);
        let e = choose_velocity(&g, &["vel".into()]).unwrap_err();
        assert_eq!(e.to_string(), expected);
        // With a vec3 grid the default stays every vec3 grid; naming the set still says
        // why it is no candidate.
        let mut g = g;
        g.push(("flow", Vector));
        assert_eq!(choose_velocity(&g, &[]).unwrap(), None);
        let e = choose_velocity(&g, &["vel".into()]).unwrap_err();
        assert_eq!(e.to_string(), expected);
    }
}
