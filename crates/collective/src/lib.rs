//! Where the processes of a data-parallel run meet: the trainer's one seam to a launcher.
//!
//! Design decision: the trainer knows a run as `size` ranks that exchange numbers, not which
//! library moves them. [`Collective`] is the four exchanges data parallelism needs, and
//! [`SingleProcess`] is the world of one; the `dgstereo-distributed` crate implements it over
//! MPI. An exchange blocks until every rank has called it, so every rank must make the same
//! calls in the same order: where one rank can fail alone (a sample it cannot read, a loss that
//! is not finite), [`agree`] turns its error into the same error on every rank, and all ranks
//! stop together instead of waiting for each other. The crate is small on purpose (as ripgrep's
//! `grep-matcher` is to its searchers): the trainer and the launcher both depend on it, and
//! neither on the other.
#![deny(missing_docs)]

use dgstereo_core::{Error, Result};

/// The exchanges between the ranks of one run. Every rank calls each in the same order.
pub trait Collective {
    /// This process's rank, `0..size`.
    fn rank(&self) -> usize;
    /// The number of ranks.
    fn size(&self) -> usize;
    /// Sums `values` element-wise over all ranks, in place; every rank passes the same length.
    fn all_reduce_sum(&self, values: &mut [f32]);
    /// Every rank's `values` (the same length on all), concatenated in rank order.
    fn all_gather(&self, values: &[f64]) -> Vec<f64>;
    /// Every rank's `bytes` (lengths may differ), in rank order.
    fn all_gather_bytes(&self, bytes: &[u8]) -> Vec<Vec<u8>>;
    /// Replaces `values` with rank `root`'s on every rank.
    fn broadcast(&self, values: &mut [f32], root: usize);
}

/// The world of one process: every exchange is the identity.
#[derive(Debug, Clone, Copy, Default)]
pub struct SingleProcess;

impl Collective for SingleProcess {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        1
    }
    fn all_reduce_sum(&self, _values: &mut [f32]) {}
    fn all_gather(&self, values: &[f64]) -> Vec<f64> {
        values.to_vec()
    }
    fn all_gather_bytes(&self, bytes: &[u8]) -> Vec<Vec<u8>> {
        vec![bytes.to_vec()]
    }
    fn broadcast(&self, _values: &mut [f32], _root: usize) {}
}

/// Every rank's outcome of a phase that can fail on some ranks only: `result` where all ranks
/// succeeded, else on every rank [`Error::Rank`] with the lowest failing rank, the world's size
/// and that rank's error as text (`rank 1 of 2: ...`). In a world of one, `result` unchanged.
pub fn agree<T>(ranks: &dyn Collective, result: Result<T>) -> Result<T> {
    if ranks.size() == 1 {
        return result;
    }
    let failed = ranks.all_gather(&[if result.is_err() { 1.0 } else { 0.0 }]);
    let Some(first) = failed.iter().position(|&f| f != 0.0) else {
        return result;
    };
    let message = result.as_ref().err().map(ToString::to_string).unwrap_or_default();
    let messages = ranks.all_gather_bytes(message.as_bytes());
    let cause = String::from_utf8_lossy(&messages[first]).into_owned();
    Err(Error::Rank { rank: first, size: ranks.size(), cause })
}

/// Rank 0 of the world: the one that writes a run's files.
pub fn writes_files(ranks: &dyn Collective) -> bool {
    ranks.rank() == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_world_of_one_passes_results_through() {
        let ok: Result<u8> = Ok(3);
        assert_eq!(agree(&SingleProcess, ok).unwrap(), 3);
        let err: Result<u8> = Err(Error::config("train.lr", "bad"));
        let e = agree(&SingleProcess, err).unwrap_err();
        assert!(matches!(e, Error::Config(_)), "{e}");
        let mut values = [1.0, 2.0];
        SingleProcess.all_reduce_sum(&mut values);
        SingleProcess.broadcast(&mut values, 0);
        assert_eq!(values, [1.0, 2.0]);
        assert_eq!(SingleProcess.all_gather(&[4.0]), vec![4.0]);
        assert!(writes_files(&SingleProcess));
    }

    /// Rank 0 of two, where rank 1 failed with "boom".
    struct BesideAFailedRank;

    impl Collective for BesideAFailedRank {
        fn rank(&self) -> usize {
            0
        }
        fn size(&self) -> usize {
            2
        }
        fn all_reduce_sum(&self, _values: &mut [f32]) {}
        fn all_gather(&self, values: &[f64]) -> Vec<f64> {
            [values, &[1.0]].concat()
        }
        fn all_gather_bytes(&self, bytes: &[u8]) -> Vec<Vec<u8>> {
            vec![bytes.to_vec(), b"boom".to_vec()]
        }
        fn broadcast(&self, _values: &mut [f32], _root: usize) {}
    }

    #[test]
    fn another_ranks_failure_fails_this_rank_naming_it() {
        let e = agree(&BesideAFailedRank, Ok(3)).unwrap_err();
        assert!(matches!(&e, Error::Rank { rank: 1, size: 2, cause } if cause == "boom"), "{e:?}");
        assert!(e.is_rank_failure());
        // The lowest failing rank is named, this one's error included.
        let own: Result<u8> = Err(Error::config("train.lr", "bad"));
        let e = agree(&BesideAFailedRank, own).unwrap_err();
        assert!(matches!(&e, Error::Rank { rank: 0, cause, .. } if cause.contains("train.lr")), "{e:?}");
    }

    #[test]
    fn a_rank_failure_is_recognised_by_its_kind_under_context() {
        let e = Error::Rank { rank: 1, size: 2, cause: "step 2: cannot read".into() };
        assert_eq!(e.to_string(), "rank 1 of 2: step 2: cannot read");
        assert!(e.context("training stopped").context("run 'x'").is_rank_failure());
        // Text that reads like one is not one.
        assert!(!Error::format("rank 1 of 2.txt", "cannot read").context("run 'x'").is_rank_failure());
    }
}
