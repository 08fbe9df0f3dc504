//! The two collective steps the work shared over ranks needs (one frame over ranks, one
//! file baked over ranks): bring every rank's bytes to rank 0, and send rank 0's bytes to
//! every rank. MPI's ranks do them with messages; threads of one process
//! ([`local_ranks`]) with channels, so that what is shared is tested without MPI; one
//! process alone ([`Alone`]) needs neither.

use std::sync::mpsc::{channel, Receiver, Sender};

/// The ranks a piece of work is shared between. Every rank must call the steps in the
/// same order.
pub trait Exchange {
    fn rank(&self) -> usize;
    fn size(&self) -> usize;
    /// Every rank's `bytes` at rank 0, in rank order; `None` at the other ranks.
    fn gather(&self, bytes: &[u8]) -> Option<Vec<Vec<u8>>>;
    /// Rank 0's `bytes` at every rank.
    fn broadcast(&self, bytes: Vec<u8>) -> Vec<u8>;
}

impl Exchange for crate::Ranks {
    fn rank(&self) -> usize {
        crate::Ranks::rank(self)
    }
    fn size(&self) -> usize {
        crate::Ranks::size(self)
    }
    fn gather(&self, bytes: &[u8]) -> Option<Vec<Vec<u8>>> {
        self.gather_bytes(bytes)
    }
    fn broadcast(&self, bytes: Vec<u8>) -> Vec<u8> {
        self.broadcast_bytes(bytes)
    }
}

/// One process on its own: rank 0 of 1 (shareable between threads, unlike [`crate::Ranks`]).
pub struct Alone;

impl Exchange for Alone {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        1
    }
    fn gather(&self, bytes: &[u8]) -> Option<Vec<Vec<u8>>> {
        Some(vec![bytes.to_vec()])
    }
    fn broadcast(&self, bytes: Vec<u8>) -> Vec<u8> {
        bytes
    }
}

/// One of the ranks [`local_ranks`] makes: threads of this process, joined by channels.
/// A rank whose peer has gone (its thread ended) receives nothing: empty bytes, which the
/// frame's decoding and the bake's checks refuse.
pub struct LocalRank {
    rank: usize,
    size: usize,
    /// To rank 0 (gather).
    up: Sender<Vec<u8>>,
    /// From rank 0 (broadcast).
    down: Receiver<Vec<u8>>,
    /// At rank 0: from every rank (index = rank), and to every rank.
    from: Vec<Receiver<Vec<u8>>>,
    to: Vec<Sender<Vec<u8>>>,
}

/// `n` ranks of one process: move each to its own thread.
pub fn local_ranks(n: usize) -> Vec<LocalRank> {
    let n = n.max(1);
    let (ups, from): (Vec<_>, Vec<_>) = (0..n).map(|_| channel()).unzip();
    let (to, downs): (Vec<_>, Vec<_>) = (0..n).map(|_| channel()).unzip();
    let mut from = Some(from);
    let mut to = Some(to);
    ups.into_iter()
        .zip(downs)
        .enumerate()
        .map(|(rank, (up, down))| LocalRank {
            rank,
            size: n,
            up,
            down,
            from: if rank == 0 {
                from.take().unwrap_or_default()
            } else {
                Vec::new()
            },
            to: if rank == 0 {
                to.take().unwrap_or_default()
            } else {
                Vec::new()
            },
        })
        .collect()
}

impl Exchange for LocalRank {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.size
    }
    fn gather(&self, bytes: &[u8]) -> Option<Vec<Vec<u8>>> {
        if self.rank != 0 {
            let _ = self.up.send(bytes.to_vec());
            return None;
        }
        let mut all = vec![bytes.to_vec()];
        for r in self.from.iter().skip(1) {
            all.push(r.recv().unwrap_or_default());
        }
        Some(all)
    }
    fn broadcast(&self, bytes: Vec<u8>) -> Vec<u8> {
        if self.rank != 0 {
            return self.down.recv().unwrap_or_default();
        }
        for t in self.to.iter().skip(1) {
            let _ = t.send(bytes.clone());
        }
        bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gather_and_broadcast_between_threads() {
        let ranks = local_ranks(3);
        type Got = (Option<Vec<Vec<u8>>>, Vec<u8>);
        let got: Vec<Got> = std::thread::scope(|s| {
            let handles: Vec<_> = ranks
                .into_iter()
                .map(|r| {
                    s.spawn(move || {
                        let g = r.gather(&[r.rank() as u8; 2]);
                        let b = r.broadcast(vec![9, r.rank() as u8]);
                        (g, b)
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().expect("rank"))
                .collect()
        });
        assert_eq!(got[0].0, Some(vec![vec![0, 0], vec![1, 1], vec![2, 2]]));
        assert!(got[1].0.is_none() && got[2].0.is_none());
        for (_, b) in &got {
            assert_eq!(b, &vec![9, 0]);
        }
    }
}
