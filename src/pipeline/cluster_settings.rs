//! `[cluster]`: per-job resources of the SLURM job graph.

use serde::{Deserialize, Serialize};

/// Per-job resources of the cluster job graph, from the measured peaks of
/// each stage (docs/cluster.md) with headroom.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClusterConfig {
    /// CPU cores per job (the libtorch threads of training and sampling).
    pub cpus_per_job: u32,
    /// Memory per job, GiB.
    pub encode_mem_gb: f64,
    pub train_mem_gb: f64,
    pub sample_mem_gb: f64,
    pub mesh_mem_gb: f64,
    pub eval_mem_gb: f64,
    /// Wall-time limits, minutes: one training task (a level), any other job.
    pub train_minutes: u32,
    pub job_minutes: u32,
    /// Variants per sampling and meshing job (the shard size).
    pub variants_per_job: usize,
}

impl Default for ClusterConfig {
    fn default() -> Self {
        ClusterConfig {
            cpus_per_job: 1,
            encode_mem_gb: 2.0,
            train_mem_gb: 4.0,
            sample_mem_gb: 4.0,
            mesh_mem_gb: 3.0,
            eval_mem_gb: 3.0,
            train_minutes: 120,
            job_minutes: 60,
            variants_per_job: 5,
        }
    }
}
