//! Which ranks search which regions: the file's KD-tree cut into subtrees ("pieces"),
//! balanced by their bricks and shared out with the same rule as the frames of a
//! sequence ([`ranks::share_of`]). Every rank computes the same cut from the same file,
//! so no message is needed to agree on it.
//!
//! A piece is a KD subtree, so its space is a box and a ray crosses it in one stretch.
//! Its cost is what its rays' search costs: the bricks of its regions whose value range
//! holds the view's iso value (the only regions whose values are read; a brick that
//! several regions read counts for each), plus one per region (stepping over it). A cut
//! by all bricks alike gave one rank of two the whole visible wake of the bundled sample
//! and the other nothing to search.

use format::kd::{KdTree, Node};

use crate::active::range_holds;
use crate::scene::Scene;
use crate::volume::Volume;

/// Cost of a region searched, per brick, against 1 for a region stepped over.
const SEARCHED_BRICK_COST: u64 = 64;

/// Most pieces per rank the cut makes while it looks for a balance.
const MAX_PIECES_PER_RANK: usize = 16;
/// The cut stops once the heaviest rank's share is within this factor of the mean.
const BALANCE: f64 = 1.1;

/// The file's KD-tree cut into subtrees.
#[derive(Debug, Clone, PartialEq)]
pub struct Pieces {
    /// Each piece's regions, ascending.
    pub regions: Vec<Vec<u32>>,
    /// Each piece's cost: the bricks its regions read.
    pub cost: Vec<u64>,
}

impl Pieces {
    /// Cuts the tree of `vol` for `ranks` ranks: the heaviest piece is split into its
    /// children until there are at least as many pieces as ranks and the heaviest rank's
    /// share (pieces given out heaviest first to the lightest rank) is within
    /// [`BALANCE`] of the mean, or no piece can be split, or there are
    /// [`MAX_PIECES_PER_RANK`] per rank.
    pub fn cut(vol: &Volume, ranks: usize, region_cost: impl Fn(u32) -> u64) -> Pieces {
        let ranks = ranks.max(1);
        let subtree_cost = |tree: &format::kd::Stored<'_, _>, node| -> u64 {
            subtree_regions(tree, node)
                .iter()
                .map(|&r| region_cost(r))
                .sum()
        };
        let tree = format::kd::file_tree(vol.file);
        let mut pieces = vec![tree.root()];
        let mut costs = vec![subtree_cost(&tree, tree.root())];
        loop {
            let total: u64 = costs.iter().sum();
            let heaviest = heaviest_share(&costs, ranks);
            let balanced = heaviest as f64 <= BALANCE * total as f64 / ranks as f64;
            if (pieces.len() >= ranks && balanced) || pieces.len() >= MAX_PIECES_PER_RANK * ranks {
                break;
            }
            // The heaviest piece that is an inner node.
            let split = (0..pieces.len())
                .filter(|&i| matches!(tree.node(pieces[i]), Some(Node::Inner { .. })))
                .max_by_key(|&i| (costs[i], std::cmp::Reverse(i)));
            let Some(i) = split else { break };
            let Some(Node::Inner { left, right, .. }) = tree.node(pieces[i]) else {
                break;
            };
            pieces.remove(i);
            costs.remove(i);
            for child in [left, right] {
                if child != format::kd::EMPTY {
                    pieces.insert(i, child);
                    costs.insert(i, subtree_cost(&tree, child));
                }
            }
        }
        let regions = pieces
            .iter()
            .map(|&p| {
                let mut r = subtree_regions(&tree, p);
                r.sort_unstable();
                r.dedup();
                r
            })
            .collect();
        Pieces {
            regions,
            cost: costs,
        }
    }

    /// The pieces (indices) rank `rank` of `ranks` takes.
    pub fn of_rank(&self, rank: usize, ranks: usize) -> Vec<usize> {
        ranks::share_of(&self.cost, rank, ranks)
    }
}

/// The regions (by index) rank `rank` of `ranks` searches in a frame of `scene` over
/// ranks: those of its pieces of [`Pieces::cut`], costed for the scene's iso value.
pub fn owned_regions(scene: &Scene, rank: usize, ranks: usize) -> Vec<bool> {
    let vol = scene.vol;
    let (field, iso) = (scene.params.field, scene.params.tf.iso);
    let cost = |r: u32| {
        let r = r as usize;
        if r >= vol.region_count() {
            return 0;
        }
        let [mn, mx] = vol.range(r, field);
        let searched = if range_holds(mn, mx, iso) {
            SEARCHED_BRICK_COST * vol.region_brick_ids(r).len() as u64
        } else {
            0
        };
        1 + searched
    };
    let pieces = Pieces::cut(vol, ranks, cost);
    let mut owned = vec![false; vol.region_count()];
    for p in pieces.of_rank(rank, ranks) {
        for &r in &pieces.regions[p] {
            if let Some(o) = owned.get_mut(r as usize) {
                *o = true;
            }
        }
    }
    owned
}

/// The heaviest rank's total when `costs` are shared out over `ranks`.
fn heaviest_share(costs: &[u64], ranks: usize) -> u64 {
    (0..ranks)
        .map(|r| {
            ranks::share_of(costs, r, ranks)
                .iter()
                .map(|&i| costs[i])
                .sum::<u64>()
        })
        .max()
        .unwrap_or(0)
}

/// The regions of the leaves under reference `node`. The walk visits at most as many
/// references as the tree has (twice its inner nodes plus one), so a malformed tree
/// cannot keep it going.
fn subtree_regions<T: KdTree>(tree: &T, node: u32) -> Vec<u32> {
    let mut out = Vec::new();
    let mut stack = vec![node];
    let mut budget = 2 * tree.node_count() + 1;
    while let Some(n) = stack.pop() {
        if budget == 0 {
            break;
        }
        budget -= 1;
        match tree.node(n) {
            Some(Node::Leaf(Some(r))) => out.push(r),
            Some(Node::Inner { left, right, .. }) => {
                stack.push(right);
                stack.push(left);
            }
            _ => {}
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_region_goes_to_exactly_one_rank_and_the_shares_balance() {
        let f = |p: [f64; 3]| p[0] + p[1] * p[2];
        let file = crate::testvol::nested(12, [0.0; 3], &[("f", &f)], 4);
        let view = crate::testvol::open(&file).expect("opens");
        let vol = Volume::new(&view).expect("volume");
        assert!(vol.region_count() > 8);
        let state = crate::view_state::ViewState::default_for_volume(&vol);
        let meshes = crate::mesh::Meshes::empty();
        let scene = Scene::new(&vol, &state, &meshes).expect("scene");
        for ranks in 1..=5 {
            let owned: Vec<Vec<bool>> = (0..ranks)
                .map(|r| owned_regions(&scene, r, ranks))
                .collect();
            for region in 0..vol.region_count() {
                let n = owned.iter().filter(|o| o[region]).count();
                assert_eq!(n, 1, "region {region} over {ranks} ranks");
            }
            let pieces = Pieces::cut(&vol, ranks, |r| {
                vol.region_brick_ids(r as usize).len() as u64
            });
            assert!(pieces.regions.len() >= ranks.min(vol.region_count()));
            let total: u64 = pieces.cost.iter().sum();
            assert!(total > 0);
            // Balanced: the heaviest rank carries at most its share and the heaviest piece.
            let heaviest = heaviest_share(&pieces.cost, ranks);
            let biggest = pieces.cost.iter().copied().max().unwrap_or(0);
            assert!(
                heaviest as f64
                    <= (BALANCE * total as f64 / ranks as f64)
                        .max(biggest as f64 + total as f64 / ranks as f64),
                "{ranks} ranks: {heaviest} of {total}"
            );
        }
    }
}
