//! The processes one run is made of: under an MPI launcher (`mpirun -np N`, with the `mpi`
//! feature) the N ranks it started, else this one process; which share of a run's items
//! each rank takes; and the few collective steps the frame-parallel commands need (does
//! every rank agree, bring every rank's results to rank 0).
//!
//! Without the feature, or started without a launcher, a run is one rank and every call is
//! trivial, so the commands behave exactly as without MPI. A rank that fails where the
//! others cannot know it must not let them wait for it forever: [`Ranks::abandon`] ends the
//! process without finalising MPI, which makes the launcher end the whole job.

use std::path::Path;

mod exchange;
pub use exchange::{local_ranks, Alone, Exchange, LocalRank};

use serde::de::DeserializeOwned;
use serde::Serialize;

/// The ranks of a run.
pub struct Ranks {
    rank: usize,
    size: usize,
    /// The run's last collective step ([`Ranks::gather`]) is done: from here on a rank
    /// may end on its own.
    collected: std::cell::Cell<bool>,
    #[cfg(feature = "mpi")]
    world: Option<World>,
}

#[cfg(feature = "mpi")]
struct World {
    // Dropping the universe finalises MPI; kept for the run's life.
    _universe: mpi::environment::Universe,
    comm: mpi::topology::SimpleCommunicator,
}

/// The environment variables by which MPI launchers (Open MPI, MPICH's Hydra, PMIx) tell
/// a process it is one of several.
#[cfg(feature = "mpi")]
const LAUNCHER_VARS: [&str; 3] = ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK"];

impl Ranks {
    /// One process, whatever the build.
    pub fn single() -> Ranks {
        Ranks {
            rank: 0,
            size: 1,
            collected: std::cell::Cell::new(false),
            #[cfg(feature = "mpi")]
            world: None,
        }
    }

    /// The ranks of this run: with the `mpi` feature and started by an MPI launcher, the
    /// processes it started (MPI is initialised here); otherwise one, and MPI is not
    /// touched, so a binary built with the feature runs on its own as without it.
    pub fn init() -> Ranks {
        #[cfg(feature = "mpi")]
        if LAUNCHER_VARS.iter().any(|v| std::env::var_os(v).is_some()) {
            use mpi::traits::Communicator;
            if let Some(universe) = mpi::initialize() {
                let comm = universe.world();
                let (rank, size) = (comm.rank(), comm.size());
                if size > 1 {
                    // A panic must not leave the other ranks waiting in a collective step.
                    let previous = std::panic::take_hook();
                    std::panic::set_hook(Box::new(move |info| {
                        previous(info);
                        std::process::exit(101);
                    }));
                }
                return Ranks {
                    rank: usize::try_from(rank).unwrap_or(0),
                    size: usize::try_from(size).unwrap_or(1),
                    collected: std::cell::Cell::new(false),
                    world: Some(World {
                        _universe: universe,
                        comm,
                    }),
                };
            }
        }
        Ranks::single()
    }

    /// This process's rank, from 0.
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// How many ranks the run has.
    pub fn size(&self) -> usize {
        self.size
    }

    /// Rank 0: the one that reports and writes what the run writes once.
    pub fn is_root(&self) -> bool {
        self.rank == 0
    }

    /// More than one rank.
    pub fn is_parallel(&self) -> bool {
        self.size > 1
    }

    /// The items (by index into `weights`, ascending) this rank takes: see [`share_of`].
    pub fn share(&self, weights: &[u64]) -> Vec<usize> {
        share_of(weights, self.rank, self.size)
    }

    /// The files (indices, ascending) this rank takes, weighed by their size (0 when it
    /// cannot be read): how the frames of a sequence are shared out.
    pub fn share_files<'a>(&self, files: impl IntoIterator<Item = &'a Path>) -> Vec<usize> {
        let sizes: Vec<u64> = files
            .into_iter()
            .map(|p| std::fs::metadata(p).map_or(0, |m| m.len()))
            .collect();
        self.share(&sizes)
    }

    /// Each rank's `ok`, at every rank, in rank order. Collective: every rank must call it
    /// at the same step.
    pub fn statuses(&self, ok: bool) -> Vec<bool> {
        #[cfg(feature = "mpi")]
        if let Some(w) = &self.world {
            use mpi::traits::CommunicatorCollectives;
            let mut all = vec![0u8; self.size];
            w.comm.all_gather_into(&u8::from(ok), &mut all[..]);
            return all.into_iter().map(|b| b != 0).collect();
        }
        vec![ok]
    }

    /// `result` where every rank's is `Ok`; otherwise an error at every rank, so that all
    /// of them stop at the same step. Collective. The error is this rank's own when it
    /// failed and should say so (rank 0, or another when rank 0 did not fail: one message
    /// for what every rank found alike), else [`FailedElsewhere`], which says nothing.
    pub fn agree<T>(&self, result: anyhow::Result<T>) -> anyhow::Result<T> {
        let all = self.statuses(result.is_ok());
        match result {
            Ok(v) if all.iter().all(|ok| *ok) => Ok(v),
            Ok(_) => Err(FailedElsewhere.into()),
            Err(e) if self.is_root() || all.first() == Some(&true) => Err(e),
            Err(_) => Err(FailedElsewhere.into()),
        }
    }

    /// An error in a parallel run, for a command that runs in one process only (`what`
    /// names it): every rank stops, rank 0 says why.
    pub fn one_process_only(&self, what: &str) -> anyhow::Result<()> {
        match (self.is_parallel(), self.is_root()) {
            (false, _) => Ok(()),
            (true, true) => Err(anyhow::anyhow!(
                "{what} runs in one process: over {} MPI ranks only frame sequences \
                 ('frame_####') are shared out; run it without mpirun",
                self.size
            )),
            (true, false) => Err(FailedElsewhere.into()),
        }
    }

    /// Every rank's `items` at rank 0, rank after rank (`None` at the other ranks).
    /// Collective: every rank must call it at the same step; the last one of a run.
    pub fn gather<T: Serialize + DeserializeOwned>(
        &self,
        items: &[T],
    ) -> anyhow::Result<Option<Vec<T>>> {
        let parts = self.gather_bytes(&serde_json::to_vec(items)?);
        self.collected.set(true);
        let Some(parts) = parts else {
            return Ok(None);
        };
        let mut all = Vec::new();
        for part in parts {
            all.extend(serde_json::from_slice::<Vec<T>>(&part)?);
        }
        Ok(Some(all))
    }

    /// Every rank's `bytes` at rank 0, in rank order (`None` at the other ranks): one step
    /// of a computation the ranks share (one frame over ranks), which may take many.
    /// Collective.
    pub fn gather_bytes(&self, bytes: &[u8]) -> Option<Vec<Vec<u8>>> {
        #[cfg(feature = "mpi")]
        if let Some(w) = &self.world {
            use mpi::point_to_point::{Destination, Source};
            use mpi::traits::Communicator;
            // MPI counts are `int`s: the length first, then pieces of at most `piece`.
            let piece = piece_bytes();
            if self.rank != 0 {
                let to = w.comm.process_at_rank(0);
                to.send(&(bytes.len() as u64));
                bytes.chunks(piece).for_each(|p| to.send(p));
                return None;
            }
            let mut all = vec![bytes.to_vec()];
            for r in 1..self.size {
                let from = w.comm.process_at_rank(i32::try_from(r).unwrap_or(i32::MAX));
                let (len, _) = from.receive::<u64>();
                // The length comes from a rank of the same run, not from a file.
                let len = usize::try_from(len).unwrap_or(0);
                let mut v = Vec::with_capacity(len);
                while v.len() < len {
                    let (p, _) = from.receive_vec::<u8>();
                    if p.is_empty() {
                        break;
                    }
                    v.extend_from_slice(&p);
                }
                all.push(v);
            }
            return Some(all);
        }
        Some(vec![bytes.to_vec()])
    }

    /// Rank 0's `bytes` at every rank (what the others pass is ignored). Collective.
    pub fn broadcast_bytes(&self, bytes: Vec<u8>) -> Vec<u8> {
        #[cfg(feature = "mpi")]
        if let Some(w) = &self.world {
            use mpi::traits::{Communicator, Root};
            let root = w.comm.process_at_rank(0);
            let mut len = bytes.len() as u64;
            root.broadcast_into(&mut len);
            let mut buf = if self.rank == 0 {
                bytes
            } else {
                // The length comes from rank 0 of the same run, not from a file.
                vec![0u8; usize::try_from(len).unwrap_or(0)]
            };
            for p in buf.chunks_mut(piece_bytes()) {
                root.broadcast_into(p);
            }
            return buf;
        }
        bytes
    }

    /// How a command's error `err` ends this rank (of `program`): said on stderr (by the
    /// rank that found it; [`FailedElsewhere`] says nothing), exit code 2. In a parallel
    /// run before the last collective step the process is [abandoned](Ranks::abandon), so
    /// that no other rank waits for this one.
    pub fn fail(&self, program: &str, err: &anyhow::Error) -> std::process::ExitCode {
        if err.is::<FailedElsewhere>() {
            return std::process::ExitCode::from(2);
        }
        match self.is_parallel() && !self.is_root() {
            true => eprintln!("{program}: rank {}: {err:#}", self.rank),
            false => eprintln!("{program}: {err:#}"),
        }
        if self.is_parallel() && !self.collected.get() {
            self.abandon(2);
        }
        std::process::ExitCode::from(2)
    }

    /// Ends this process with `code`. In a parallel run MPI is not finalised, so the
    /// launcher sees a rank end early and ends the job: no rank is left waiting for this
    /// one. Alone, the same as `std::process::exit`.
    pub fn abandon(&self, code: i32) -> ! {
        std::process::exit(code)
    }
}

/// The largest piece of one MPI message, bytes: MPI counts are C `int`s, so larger messages
/// go in pieces (1 GiB; `QBRICKS_MPI_PIECE=N` sets another size, which the tests use to
/// send every message in many pieces).
#[cfg(feature = "mpi")]
fn piece_bytes() -> usize {
    std::env::var("QBRICKS_MPI_PIECE")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or(1 << 30)
        .min(i32::MAX as usize)
}

/// The error of a rank that stops because another rank failed (and reports why): nothing
/// to print, but the run fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FailedElsewhere;

impl std::fmt::Display for FailedElsewhere {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("another rank failed")
    }
}

impl std::error::Error for FailedElsewhere {}

/// The items (indices into `weights`, ascending) rank `rank` of `size` takes: the heaviest
/// first, each to the rank with the least weight so far (the lowest rank on a tie), so the
/// ranks' totals differ by at most the heaviest item. Every rank computes the same split
/// from the same weights, so no message is needed to agree on it.
pub fn share_of(weights: &[u64], rank: usize, size: usize) -> Vec<usize> {
    let size = size.max(1);
    let mut order: Vec<usize> = (0..weights.len()).collect();
    order.sort_by(|&a, &b| weights[b].cmp(&weights[a]).then(a.cmp(&b)));
    let mut load = vec![0u64; size];
    let mut mine = Vec::new();
    for i in order {
        let (r, _) = load
            .iter()
            .enumerate()
            .min_by_key(|&(r, l)| (*l, r))
            .unwrap_or((0, &0));
        load[r] = load[r].saturating_add(weights[i]);
        if r == rank {
            mine.push(i);
        }
    }
    mine.sort_unstable();
    mine
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_item_goes_to_exactly_one_rank_and_loads_are_balanced() {
        let weights: Vec<u64> = (0..37).map(|i| (i * 7919 % 101) + 1).collect();
        for size in 1..=6 {
            let shares: Vec<Vec<usize>> = (0..size).map(|r| share_of(&weights, r, size)).collect();
            let mut all: Vec<usize> = shares.iter().flatten().copied().collect();
            all.sort_unstable();
            assert_eq!(all, (0..weights.len()).collect::<Vec<_>>(), "size {size}");
            let loads: Vec<u64> = shares
                .iter()
                .map(|s| s.iter().map(|&i| weights[i]).sum())
                .collect();
            let (lo, hi) = (
                loads.iter().min().unwrap_or(&0),
                loads.iter().max().unwrap_or(&0),
            );
            let heaviest = weights.iter().max().copied().unwrap_or(0);
            assert!(hi - lo <= heaviest, "size {size}: loads {loads:?}");
            for s in &shares {
                assert!(s.windows(2).all(|w| w[0] < w[1]), "ascending");
            }
        }
    }

    #[test]
    fn more_ranks_than_items_and_no_items() {
        assert_eq!(share_of(&[5, 3], 0, 4), vec![0]);
        assert_eq!(share_of(&[5, 3], 1, 4), vec![1]);
        assert!(share_of(&[5, 3], 3, 4).is_empty());
        assert!(share_of(&[], 0, 2).is_empty());
        // Equal weights: round robin from rank 0.
        assert_eq!(share_of(&[1; 5], 0, 2), vec![0, 2, 4]);
        assert_eq!(share_of(&[1; 5], 1, 2), vec![1, 3]);
    }

    #[test]
    fn one_rank_is_trivial() {
        let r = Ranks::single();
        assert!(r.is_root() && !r.is_parallel());
        assert_eq!(r.share(&[3, 1, 2]), vec![0, 1, 2]);
        assert_eq!(r.statuses(false), vec![false]);
        assert_eq!(r.gather(&[1u64, 2]).ok(), Some(Some(vec![1, 2])));
        assert_eq!(r.agree(Ok::<_, anyhow::Error>(3)).ok(), Some(3));
        let e = r.agree::<()>(Err(anyhow::anyhow!("bad"))).unwrap_err();
        assert_eq!(e.to_string(), "bad");
    }
}
