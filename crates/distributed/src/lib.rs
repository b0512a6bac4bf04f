//! Data-parallel training across processes and machines: which ranks this process belongs to,
//! and the exchanges between them.
//!
//! Design decision: the trainer meets other ranks through one trait,
//! [`dgstereo_collective::Collective`]; this crate decides which world a process is in and gives it
//! one. A process no launcher started is a world of one and never touches MPI. With the `mpi`
//! feature, a process that `mpirun` or `srun` started as one of several ranks joins MPI's world
//! (Open MPI, MPICH, Intel MPI: whatever the `mpi` crate was built against); without it, such a
//! process refuses to start ([`launcher::without_mpi`]). burn's own `all_reduce` exists only on
//! CUDA with NCCL, while MPI runs on every backend and every cluster, as Horovod did.
#![deny(missing_docs)]

pub mod launcher;
#[cfg(feature = "mpi")]
mod mpi_world;

use dgstereo_collective::{Collective, SingleProcess};
use dgstereo_core::Result;

/// The ranks of this run, as this process sees them.
pub struct World {
    ranks: Ranks,
    local_rank: usize,
    local_size: usize,
}

enum Ranks {
    Single(SingleProcess),
    #[cfg(feature = "mpi")]
    Mpi(mpi_world::MpiWorld),
}

/// The world this process belongs to: MPI's when a launcher started several ranks (and the
/// `mpi` feature is built), else a world of one. Call it once, first: MPI is initialised here.
///
/// # Errors
/// Started as several ranks by a build without MPI ([`launcher::without_mpi`]), or MPI was
/// already initialised.
pub fn join() -> Result<World> {
    let launched = launcher::launched_ranks(|name| std::env::var(name).ok());
    match launched {
        Some((count, _)) if count > 1 => join_several(launched),
        _ => Ok(World { ranks: Ranks::Single(SingleProcess), local_rank: 0, local_size: 1 }),
    }
}

#[cfg(not(feature = "mpi"))]
fn join_several(launched: Option<(usize, &'static str)>) -> Result<World> {
    let (count, variable) = launched.expect("called for a launched process");
    Err(launcher::without_mpi(count, variable))
}

#[cfg(feature = "mpi")]
fn join_several(_launched: Option<(usize, &'static str)>) -> Result<World> {
    let world = mpi_world::MpiWorld::initialize()?;
    let (local_rank, local_size) = world.local();
    Ok(World { ranks: Ranks::Mpi(world), local_rank, local_size })
}

impl World {
    fn collective(&self) -> &dyn Collective {
        match &self.ranks {
            Ranks::Single(single) => single,
            #[cfg(feature = "mpi")]
            Ranks::Mpi(world) => world,
        }
    }

    /// This process's rank among those on its machine.
    pub fn local_rank(&self) -> usize {
        self.local_rank
    }

    /// The number of ranks on this machine.
    pub fn local_size(&self) -> usize {
        self.local_size
    }

    /// Divides this machine's cores among its ranks: rayon's global pool gets
    /// `cores / local ranks` threads (at least one), unless `RAYON_NUM_THREADS` says otherwise
    /// or the pool already exists. Returns the pool's thread count. Call before any work.
    pub fn share_cores(&self) -> usize {
        if self.local_size > 1 && std::env::var_os("RAYON_NUM_THREADS").is_none() {
            let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
            let threads = (cores / self.local_size).max(1);
            // An error means the pool already exists; it keeps its size.
            let _ = rayon::ThreadPoolBuilder::new().num_threads(threads).build_global();
        }
        rayon::current_num_threads()
    }

    /// Ends every rank of the job now, with exit status `code`: the way out for an error that
    /// only this rank met (the others would wait for it forever). In a world of one, returns.
    pub fn abort(&self, code: i32) {
        match &self.ranks {
            Ranks::Single(_) => {}
            #[cfg(feature = "mpi")]
            Ranks::Mpi(world) => world.abort(code),
        }
        let _ = code;
    }
}

impl Collective for World {
    fn rank(&self) -> usize {
        self.collective().rank()
    }
    fn size(&self) -> usize {
        self.collective().size()
    }
    fn all_reduce_sum(&self, values: &mut [f32]) {
        self.collective().all_reduce_sum(values);
    }
    fn all_gather(&self, values: &[f64]) -> Vec<f64> {
        self.collective().all_gather(values)
    }
    fn all_gather_bytes(&self, bytes: &[u8]) -> Vec<Vec<u8>> {
        self.collective().all_gather_bytes(bytes)
    }
    fn broadcast(&self, values: &mut [f32], root: usize) {
        self.collective().broadcast(values, root);
    }
}
