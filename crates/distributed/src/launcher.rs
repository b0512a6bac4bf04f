//! What a launcher tells the processes it starts, read from their environment.
//!
//! `mpirun` and `srun` start every rank with variables that say how many ranks there are,
//! before any MPI library is touched. Reading them lets a build without MPI refuse to run as
//! one of several ranks (which would be several independent runs writing one folder), and lets
//! a build with MPI skip initialising it for a plain single process.

/// The variables that carry the number of ranks, by launcher, in the order they are read:
/// Open MPI's `mpirun`, MPICH's and Intel MPI's Hydra (and Slurm's PMI-2), Slurm's `srun`.
pub const RANK_COUNT_VARIABLES: [&str; 3] = ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "SLURM_STEP_NUM_TASKS"];

/// The ranks a launcher started, as `(count, variable)`, when a variable of
/// [`RANK_COUNT_VARIABLES`] is set to a number; `var` reads the environment.
pub fn launched_ranks(var: impl Fn(&str) -> Option<String>) -> Option<(usize, &'static str)> {
    RANK_COUNT_VARIABLES.iter().find_map(|&name| {
        let count = var(name)?.trim().parse::<usize>().ok()?;
        Some((count, name))
    })
}

/// The error of a build without MPI started as `count` ranks (read from `variable`).
pub fn without_mpi(count: usize, variable: &str) -> dgstereo_core::Error {
    dgstereo_core::Error::unsupported(
        format!("running as one of {count} ranks ({variable}={count})"),
        "this dgstereo was built without MPI: \
         each rank would train alone into the same folder. Build it with `cargo build --release -p dgstereo \
         --features mpi` (needs an MPI library and libclang: Debian's libopenmpi-dev and libclang-dev), or \
         start one process",
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(pairs: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let pairs: Vec<(String, String)> = pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        move |name| pairs.iter().find(|(k, _)| k == name).map(|(_, v)| v.clone())
    }

    #[test]
    fn each_launcher_is_recognised_and_a_plain_process_is_not() {
        assert_eq!(launched_ranks(env(&[("OMPI_COMM_WORLD_SIZE", "4")])), Some((4, "OMPI_COMM_WORLD_SIZE")));
        assert_eq!(launched_ranks(env(&[("PMI_SIZE", "2")])), Some((2, "PMI_SIZE")));
        assert_eq!(launched_ranks(env(&[("SLURM_STEP_NUM_TASKS", "8")])), Some((8, "SLURM_STEP_NUM_TASKS")));
        assert_eq!(launched_ranks(env(&[("SLURM_NTASKS", "8"), ("HOME", "/root")])), None);
        assert_eq!(launched_ranks(env(&[("OMPI_COMM_WORLD_SIZE", "many")])), None);
    }

    #[test]
    fn the_refusal_says_how_to_build_with_mpi() {
        let e = without_mpi(2, "OMPI_COMM_WORLD_SIZE").to_string();
        assert!(e.contains("2 ranks") && e.contains("--features mpi") && e.contains("libopenmpi-dev"), "{e}");
    }
}
