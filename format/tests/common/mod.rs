//! Random `.qbk` contents for the tests: valid files built from a seed, and random KD
//! split trees whose leaves are the regions (so brute force is the reference).
#![allow(dead_code)]

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
/// cell; leaves hold a region (their cell, sometimes shrunk inside it) or nothing.
/// Sometimes both leaf children of a node hold the *same* region (the parent's cell), as
/// when a builder has to cut a region. Node indices are shuffled (root stays 0).
pub struct KdConfig {
    pub regions: Vec<Aabb>,
    pub nodes: Vec<KdNode>,
}

enum Tmp {
    Inner(u8, f64, Box<Tmp>, Box<Tmp>),
    Leaf(Option<u32>),
}

pub fn random_kd(rng: &mut Rng, root: Aabb, max_depth: u32) -> KdConfig {
    let mut regions = Vec::new();
    let tree = grow(rng, root, max_depth, &mut regions);
    // Give the nodes shuffled indices with the root at 0 and every node after its parent
    // (the order a file must have): each next index goes to a random node among those
    // whose parent is placed, so siblings, subtrees and levels interleave.
    let mut nodes: Vec<KdNode> = Vec::new();
    // (node, its index, the index of the parent slot to fill: (parent index, is left)).
    let mut frontier: Vec<(&Tmp, Option<(usize, bool)>)> = vec![(&tree, None)];
    while !frontier.is_empty() {
        let k = rng.below(frontier.len() as u64) as usize;
        let (t, parent) = frontier.swap_remove(k);
        let id = nodes.len() as u32;
        if let Some((p, is_left)) = parent {
            if let KdNode::Inner { left, right, .. } = &mut nodes[p] {
                *(if is_left { left } else { right }) = id;
            }
        }
        match t {
            Tmp::Leaf(r) => nodes.push(KdNode::Leaf { region: *r }),
            Tmp::Inner(axis, split, l, r) => {
                nodes.push(KdNode::Inner {
                    axis: *axis,
                    split: *split,
                    left: u32::MAX,
                    right: u32::MAX,
                });
                frontier.push((l, Some((id as usize, true))));
                frontier.push((r, Some((id as usize, false))));
            }
        }
    }
    KdConfig { regions, nodes }
}

fn grow(rng: &mut Rng, cell: Aabb, depth: u32, regions: &mut Vec<Aabb>) -> Tmp {
    if depth == 0 || rng.chance(0.2) {
        if rng.chance(0.25) {
            return Tmp::Leaf(None);
        }
        let mut b = cell;
        if rng.chance(0.3) {
            for a in 0..3 {
                let w = cell.max[a] - cell.min[a];
                b.min[a] = cell.min[a] + w * rng.range(0.0, 0.3);
                b.max[a] = cell.max[a] - w * rng.range(0.0, 0.3);
            }
        }
        regions.push(b);
        return Tmp::Leaf(Some(regions.len() as u32 - 1));
    }
    let axis = rng.below(3) as u8;
    let a = axis as usize;
    let split = cell.min[a] + (cell.max[a] - cell.min[a]) * rng.range(0.1, 0.9);
    if depth == 1 && rng.chance(0.15) {
        // One region cut in two by the split plane.
        regions.push(cell);
        let r = regions.len() as u32 - 1;
        return Tmp::Inner(
            axis,
            split,
            Box::new(Tmp::Leaf(Some(r))),
            Box::new(Tmp::Leaf(Some(r))),
        );
    }
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
        .map(|b| {
            let start = region_bricks.len() as u32;
            let mut finest = u32::MAX;
            for (i, brick) in bricks.iter().enumerate() {
                if rng.chance(0.4) {
                    region_bricks.push(i as u32);
                    finest = finest.min(brick.level);
                }
            }
            Region {
                bounds: *b,
                bricks_start: start,
                bricks_len: region_bricks.len() as u32 - start,
                finest_level: if finest == u32::MAX { 0 } else { finest },
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

    BrickFile {
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
        kd_nodes: kd.nodes,
        kd_ranges: Vec::new(),
        kd_full: Vec::new(),
    }
    .with_kd_tables()
}
