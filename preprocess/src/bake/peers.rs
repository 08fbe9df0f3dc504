//! One bake shared between processes: the ranks of an MPI run (`mpirun -np N qbricks-bake
//! bake in.vdb -o out.qbk`).
//!
//! Every rank reads the input and makes the same cells and bricks (their topology is small
//! beside the values, and every rank needs the cells around its bricks for the stencils,
//! across level boundaries). The bricks are then cut into chunks of about equal cell
//! counts, in file order, and dealt out round by round: in round k rank r derives the
//! fields of chunk k·N + r, and rank 0 gathers the round's chunks, in rank order, which is
//! file order. Rank 0 alone builds the regions and the KD-tree from the bricks' values and
//! writes the file, so the file is byte for byte the one a single process bakes, and the
//! viewer opens it like any other. The other ranks end after the last round.
//!
//! Why one file assembled by rank 0 rather than one part per rank tied by an index: the
//! viewer maps one file and its KD-tree already gives each rank of a render its subtrees
//! (one frame over ranks), so parts would only move the assembly into every reader.
//!
//! The ranks talk through `ranks::Exchange`: MPI's ranks, or threads of one process in
//! the tests (`ranks::local_ranks`).
//!
//! Only the fields scale with the ranks: reading and the cells are every rank's, the
//! regions and the writing rank 0's (docs/baking.md, *One file over MPI ranks*).

use crate::error::BakeError;

/// The cells of one chunk per rank and round, for `total` cells over `ranks`: a serial
/// bake's chunk shared out, so that rank 0 holds one round's chunks at a time, as much as
/// one process holds one chunk; and at most an eighth of a rank's share, so that the
/// ranks' work differs by one chunk at most, an eighth. At least one cell (a chunk is at
/// least one brick).
pub(super) fn chunk_per_rank(chunk: u64, ranks: usize, total: u64) -> u64 {
    let ranks = ranks.max(1) as u64;
    (chunk / ranks)
        .min(total.div_ceil(ranks.saturating_mul(ROUNDS)))
        .max(1)
}

/// The fewest rounds a shared bake's fields take (when its chunk size allows).
const ROUNDS: u64 = 8;

/// `bytes` from rank `rank` as `items` items of `item_bytes` bytes each (a chunk's cells of
/// every field, counts), or the error of a message that does not hold them.
pub(super) fn check_message(
    rank: usize,
    bytes: &[u8],
    items: u64,
    item_bytes: u64,
) -> Result<(), BakeError> {
    let want = items.saturating_mul(item_bytes);
    match bytes.len() as u64 == want {
        true => Ok(()),
        false => Err(BakeError::PeerMessage {
            rank,
            got: bytes.len() as u64,
            want,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_per_rank_share_a_serial_chunk_in_eight_rounds_at_least() {
        let big = 1 << 40;
        assert_eq!(chunk_per_rank(1 << 22, 1, big), 1 << 22);
        assert_eq!(chunk_per_rank(1 << 22, 3, big), (1 << 22) / 3);
        assert_eq!(chunk_per_rank(1, 4, big), 1);
        assert_eq!(chunk_per_rank(5, 0, big), 5);
        // A small bake: eight rounds of the ranks' chunks cover it.
        assert_eq!(chunk_per_rank(1 << 22, 2, 1_000_000), 62_500);
        assert_eq!(chunk_per_rank(1 << 22, 3, 1_000), 42);
        assert_eq!(chunk_per_rank(1 << 22, 2, 0), 1);
    }

    #[test]
    fn a_message_of_the_wrong_size_is_refused_naming_its_rank() {
        assert!(check_message(1, &[0; 24], 3, 8).is_ok());
        let e = check_message(2, &[0; 20], 3, 8).expect_err("short");
        let text = e.to_string();
        assert!(
            text.contains("rank 2") && text.contains("20") && text.contains("24"),
            "{text}"
        );
    }
}
