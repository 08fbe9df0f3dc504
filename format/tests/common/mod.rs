//! Random `.qbk` contents for the tests: valid files built from a seed, and random KD
//! split trees whose leaves are the regions (so brute force is the reference).
#![allow(dead_code)]

use qbricks_format::kd;
use qbricks_format::{
    Aabb, Brick, BrickFile, Field, KdNode, Level, Provenance, Region, SourceGrid, ValueRange,
};

/// splitmix64: small, deterministic, good enough for test data.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    pub fn below(&mut self, n: u64) -> u64 {
        if n == 0 {
            0
        } else {
            self.next_u64() % n
        }
    }
    pub fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }
}

/// A random KD split tree over `root`: inner nodes split at a random plane inside their
/// cell; leaves hold a region (their cell, which is how format 3 defines a region's box)
/// or nothing. Inner nodes get shuffled indices (root stays 0, every node after its
/// parent, the order a file must have).
pub struct KdConfig {
    /// Each region's box (its leaf's cell).
    pub regions: Vec<Aabb>,
    pub root: u32,
    pub nodes: Vec<KdNode>,
    pub axes: Vec<u8>,
}

enum Tmp {
    Inner(u8, f64, Box<Tmp>, Box<Tmp>),
    Leaf(Option<u32>),
}

pub fn random_kd(rng: &mut Rng, root: Aabb, max_depth: u32) -> KdConfig {
    let mut regions = Vec::new();
    let tree = grow(rng, root, max_depth, &mut regions);
    // Each next index goes to a random inner node among those whose parent is placed,
    // so siblings, subtrees and levels interleave.
    let mut nodes: Vec<KdNode> = Vec::new();
    let mut axes: Vec<u8> = Vec::new();
    let mut root_ref = kd::EMPTY;
    // (node, the parent slot to fill: (parent index, is left)).
    let mut frontier: Vec<(&Tmp, Option<(usize, bool)>)> = vec![(&tree, None)];
    while !frontier.is_empty() {
        let k = rng.below(frontier.len() as u64) as usize;
        let (t, parent) = frontier.swap_remove(k);
        let r = match t {
            Tmp::Leaf(r) => kd::leaf_ref(*r),
            Tmp::Inner(axis, split, l, r) => {
                let id = nodes.len();
                nodes.push(KdNode {
                    split: *split,
                    left: kd::EMPTY,
                    right: kd::EMPTY,
                });
                axes.push(*axis);
                frontier.push((l, Some((id, true))));
                frontier.push((r, Some((id, false))));
                id as u32
            }
        };
        match parent {
            None => root_ref = r,
            Some((p, true)) => nodes[p].left = r,
            Some((p, false)) => nodes[p].right = r,
        }
    }
    KdConfig {
        regions,
        root: root_ref,
        nodes,
        axes,
    }
}

fn grow(rng: &mut Rng, cell: Aabb, depth: u32, regions: &mut Vec<Aabb>) -> Tmp {
    if depth == 0 || rng.chance(0.2) {
        if rng.chance(0.25) {
            return Tmp::Leaf(None);
        }
        regions.push(cell);
        return Tmp::Leaf(Some(regions.len() as u32 - 1));
    }
    let axis = rng.below(3) as u8;
    let a = axis as usize;
    let split = cell.min[a] + (cell.max[a] - cell.min[a]) * rng.range(0.1, 0.9);
    let (mut lo, mut hi) = (cell, cell);
    lo.max[a] = split;
    hi.min[a] = split;
    let l = grow(rng, lo, depth - 1, regions);
    let r = grow(rng, hi, depth - 1, regions);
    Tmp::Inner(axis, split, Box::new(l), Box::new(r))
}

fn random_string(rng: &mut Rng) -> String {
    const PARTS: [&str; 8] = ["q", "speed", "wake", "✓", "velocity_x", " ", "\"", "level"];
    (0..rng.below(4))
        .map(|_| PARTS[rng.below(PARTS.len() as u64) as usize])
        .collect()
}

/// A random file that satisfies every schema invariant (so it must open).
pub fn random_file(seed: u64) -> BrickFile {
    random_file_with_boxes(seed).0
}

/// [`random_file`] and its regions' boxes as generated (the reference for the queries,
/// which derive them from the tree).
pub fn random_file_with_boxes(seed: u64) -> (BrickFile, Vec<Aabb>) {
    let mut rng = Rng::new(seed);
    let n_levels = 1 + rng.below(3) as usize;
    let n_fields = 1 + rng.below(3) as usize;
    let n_bricks = rng.below(7) as usize;
    let offset = rng.range(-1e6, 1e6);

    let mut levels: Vec<Level> = (0..n_levels)
        .map(|l| Level {
            cell_width: 0.25 * f64::from(1u32 << l),
            cells: 0,
            bricks: 0,
        })
        .collect();
    let mut bricks = Vec::new();
    let mut first_value = 0u64;
    for _ in 0..n_bricks {
        let level = rng.below(n_levels as u64) as usize;
        let dims = [0; 3].map(|_: u32| 1 + rng.below(4) as u32);
        let cells: u64 = dims.iter().map(|&d| u64::from(d)).product();
        bricks.push(Brick {
            level: level as u32,
            origin: [0; 3].map(|_: i32| offset + rng.range(-4.0, 4.0)),
            cell_width: levels[level].cell_width,
            inv_cell_width: 1.0 / levels[level].cell_width,
            dims,
            first_value,
        });
        levels[level].cells += cells;
        levels[level].bricks += 1;
        first_value += cells;
    }
    let fields = (0..n_fields)
        .map(|f| Field {
            name: format!("f{f}{}", random_string(&mut rng)),
            min: -1.0,
            max: 1.0,
            histogram: (0..rng.below(5)).map(|_| rng.below(100)).collect(),
            values: (0..first_value)
                .map(|_| rng.range(-1.0, 1.0) as f32)
                .collect(),
        })
        .collect();

    let root = Aabb {
        min: [offset - 5.0; 3],
        max: [offset + 5.0; 3],
    };
    let depth = rng.below(4) as u32;
    let kd = random_kd(&mut rng, root, depth);
    let mut region_bricks = Vec::new();
    let regions: Vec<Region> = kd
        .regions
        .iter()
        .map(|_| {
            let start = region_bricks.len() as u32;
            for i in 0..bricks.len() {
                if rng.chance(0.4) {
                    region_bricks.push(i as u32);
                }
            }
            Region {
                bricks_start: start,
                bricks_len: region_bricks.len() as u32 - start,
            }
        })
        .collect();
    let region_ranges = (0..regions.len() * n_fields)
        .map(|_| {
            let a = rng.range(-1.0, 1.0) as f32;
            ValueRange {
                min: a,
                max: a + 0.5,
            }
        })
        .collect();

    let file = BrickFile {
        provenance: Provenance {
            source: format!("{}.vdb", random_string(&mut rng)),
            grids: (0..n_levels)
                .map(|l| SourceGrid {
                    name: random_string(&mut rng),
                    voxel_size: [levels[l].cell_width; 3],
                    level: l as u32,
                })
                .collect(),
            bake_options: "{\"step\":0.5}".to_owned(),
            tool_version: "0.1.0".to_owned(),
        },
        bounds: root,
        levels,
        fields,
        bricks,
        regions,
        region_bricks,
        region_ranges,
        kd_root: kd.root,
        kd_nodes: kd.nodes,
        kd_axes: kd.axes,
    };
    (file, kd.regions)
}
