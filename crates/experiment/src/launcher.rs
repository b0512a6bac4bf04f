//! `[launcher]`: where `dgstereo ablate --launcher slurm` runs an experiment's runs.

use serde::{Deserialize, Serialize};

/// Scheduler options of an experiment (`[launcher]`); they do not change what a run trains.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LauncherConfig {
    /// Options for `sbatch`, one per element (`["--gres=gpu:1", "--time=72:00:00"]`).
    pub sbatch: Vec<String>,
}

impl LauncherConfig {
    /// Whether nothing is set (the table is then left out of the resolved file).
    pub fn is_default(&self) -> bool {
        self.sbatch.is_empty()
    }
}
