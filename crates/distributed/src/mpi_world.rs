//! [`Collective`] over MPI's world communicator.

use dgstereo_collective::Collective;
use dgstereo_core::{Error, Result};
use mpi::collective::SystemOperation;
use mpi::datatype::PartitionMut;
use mpi::environment::Universe;
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::*;

/// MPI, initialised, with its world and this machine's part of it.
pub(crate) struct MpiWorld {
    world: SimpleCommunicator,
    local: SimpleCommunicator,
    /// Finalises MPI when dropped; declared last so the communicators go first.
    _universe: Universe,
}

impl MpiWorld {
    /// Initialises MPI (once per process).
    pub(crate) fn initialize() -> Result<Self> {
        let universe = mpi::initialize().ok_or_else(|| {
            Error::unsupported("initialising MPI twice", "MPI was already initialised in this process")
        })?;
        let world = universe.world();
        let local = world.split_shared(world.rank());
        Ok(Self { world, local, _universe: universe })
    }

    /// `(rank, size)` among the ranks sharing this machine's memory.
    pub(crate) fn local(&self) -> (usize, usize) {
        (self.local.rank() as usize, self.local.size() as usize)
    }

    /// `MPI_Abort` on the world: every rank ends.
    pub(crate) fn abort(&self, code: i32) -> ! {
        self.world.abort(code)
    }
}

impl Collective for MpiWorld {
    fn rank(&self) -> usize {
        self.world.rank() as usize
    }
    fn size(&self) -> usize {
        self.world.size() as usize
    }
    fn all_reduce_sum(&self, values: &mut [f32]) {
        let send = values.to_vec();
        self.world.all_reduce_into(&send[..], values, SystemOperation::sum());
    }
    fn all_gather(&self, values: &[f64]) -> Vec<f64> {
        let mut gathered = vec![0.0; values.len() * self.size()];
        self.world.all_gather_into(values, &mut gathered[..]);
        gathered
    }
    fn all_gather_bytes(&self, bytes: &[u8]) -> Vec<Vec<u8>> {
        let lengths = self.all_gather(&[bytes.len() as f64]);
        let counts: Vec<i32> = lengths.iter().map(|&n| n as i32).collect();
        let displs: Vec<i32> = counts
            .iter()
            .scan(0, |at, &n| {
                let start = *at;
                *at += n;
                Some(start)
            })
            .collect();
        let mut all = vec![0u8; counts.iter().map(|&n| n as usize).sum()];
        {
            let mut partition = PartitionMut::new(&mut all[..], &counts[..], &displs[..]);
            self.world.all_gather_varcount_into(bytes, &mut partition);
        }
        counts.iter().zip(&displs).map(|(&n, &at)| all[at as usize..(at + n) as usize].to_vec()).collect()
    }
    fn broadcast(&self, values: &mut [f32], root: usize) {
        self.world.process_at_rank(root as i32).broadcast_into(values);
    }
}
