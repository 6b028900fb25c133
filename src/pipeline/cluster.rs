//! @brief The pipeline as a SLURM job graph: one script per stage, chained
//! by dependencies, each job running one `shapeshifter stage ...` command on
//! a shared run folder, exactly the code `run` runs in one process.
//!
//! 1. **encode** (one job per exemplar) records the configuration in the run
//!    folder and encodes the exemplar.
//! 2. **train** (a job array, one task per level, after encode): levels are
//!    independent by design, so they train side by side. `--requeue`: a
//!    preempted or requeued task starts the same command again, which resumes
//!    from the level's last checkpoint.
//! 3. **sample** (a job array of shards of `variants_per_job` variants, after
//!    every training task): each variant is computed alone from its own seed,
//!    so the shards together are exactly what one `sample -n` writes.
//! 4. **mesh** (a job array of the same shards, after sampling).
//! 5. **eval** (one job, after meshing): `eval.json` and `contact_sheet.png`.
//!
//! Resources per job (cores, memory, time, GPUs) come from the configuration's
//! `[cluster]` section and `--gpus-per-job`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::config::Config;
use crate::error::{Error, Result};

/// What the job graph runs and asks for.
#[derive(Clone, Debug)]
pub struct GraphOptions {
    /// The `shapeshifter` executable the jobs run (an absolute path every
    /// node can reach).
    pub binary: PathBuf,
    /// Profile name or file, and overrides, as given to `run`.
    pub profile: String,
    pub overrides: Vec<String>,
    /// Variants and seed.
    pub n: usize,
    pub seed: u64,
    pub partition: Option<String>,
    /// GPUs per training and sampling job (0: CPU only).
    pub gpus_per_job: u32,
}

/// One sbatch script of the graph.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    /// Stage name: encode, train, sample, mesh, eval.
    pub stage: &'static str,
    /// File name of the script in the graph's folder.
    pub file: String,
    pub script: String,
    /// Array tasks (`0-K`), if an array.
    pub array: Option<String>,
}


fn quote(p: &Path) -> String {
    format!("'{}'", p.display().to_string().replace('\'', r"'\''"))
}

fn quote_str(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// The five scripts for one exemplar (`mesh`) and its run folder (`out`), in
/// submission order. Paths are made absolute (jobs start elsewhere).
pub fn job_graph(mesh: &Path, out: &Path, config: &Config, opts: &GraphOptions) -> Result<Vec<Job>> {
    if opts.n == 0 {
        return Err(Error::Invalid("-n 0: nothing to sample".into()));
    }
    let abs = |p: &Path| -> Result<PathBuf> {
        std::path::absolute(p).map_err(|e| Error::file(p, e.to_string()))
    };
    let (mesh, out, bin) = (abs(mesh)?, abs(out)?, abs(&opts.binary)?);
    // `#SBATCH` lines are split at whitespace and `%` starts a file-name
    // pattern there: refuse such a run folder rather than write a broken script.
    let shown = out.display().to_string();
    if shown.contains(char::is_whitespace) || shown.contains('%') {
        return Err(Error::file(&out, "a cluster run folder must not contain whitespace or '%' (#SBATCH lines cannot quote them)"));
    }
    // A profile given as a file: absolute, since jobs start in another folder.
    let profile = if Path::new(&opts.profile).is_file() {
        abs(Path::new(&opts.profile))?.display().to_string()
    } else {
        opts.profile.clone()
    };
    let c = &config.cluster;
    // One training task per level with a network (detail transfer makes the rest).
    let levels = config.trained_levels();
    let shard = c.variants_per_job.max(1);
    let shards = opts.n.div_ceil(shard);
    let logs = out.join("slurm").join("logs");
    let gpu = opts.gpus_per_job > 0;
    let device = if gpu { "cuda" } else { "cpu" };
    // The job name, reduced to characters every #SBATCH parser takes.
    let stem: String = mesh
        .file_stem()
        .map(|s| s.to_string_lossy().chars().map(|c| if c.is_ascii_alphanumeric() || "_.-".contains(c) { c } else { '_' }).collect())
        .unwrap_or_else(|| "exemplar".into());

    let header = |stage: &str, mem: f64, minutes: u32, array: Option<&str>, gpus: bool| {
        let mut h = String::from("#!/bin/bash\n");
        let _ = writeln!(h, "#SBATCH --job-name=ss-{stage}-{stem}");
        let pattern = if array.is_some() { "%x-%A_%a.out" } else { "%x-%j.out" };
        let _ = writeln!(h, "#SBATCH --output={}", logs.join(pattern).display());
        let _ = writeln!(h, "#SBATCH --cpus-per-task={}", c.cpus_per_job.max(1));
        let _ = writeln!(h, "#SBATCH --mem={}M", (mem * 1024.0).ceil() as u64);
        let _ = writeln!(h, "#SBATCH --time={minutes}");
        if let Some(a) = array {
            let _ = writeln!(h, "#SBATCH --array={a}");
        }
        if let Some(p) = &opts.partition {
            let _ = writeln!(h, "#SBATCH --partition={p}");
        }
        if gpus && gpu {
            let _ = writeln!(h, "#SBATCH --gres=gpu:{}", opts.gpus_per_job);
        }
        h += "set -euo pipefail\n";
        h
    };
    let exe = format!("{} --threads {}", quote(&bin), c.cpus_per_job.max(1));
    let run = quote(&out);

    let mut encode = header("encode", c.encode_mem_gb, c.job_minutes, None, false);
    let sets: String = opts.overrides.iter().map(|o| format!(" --set {}", quote_str(o))).collect();
    let _ = writeln!(encode, "exec {exe} stage encode {} -o {run} --profile {}{sets}", quote(&mesh), quote_str(&profile));

    let train_array = format!("0-{}", levels - 1);
    let mut train = header("train", c.train_mem_gb, c.train_minutes, Some(&train_array), true);
    // Requeued (preempted, or `scontrol requeue`): the same command resumes
    // from the level's last checkpoint.
    train = train.replacen("set -euo pipefail\n", "#SBATCH --requeue\n#SBATCH --open-mode=append\nset -euo pipefail\n", 1);
    let _ = writeln!(train, "exec {exe} stage train {run} --level \"$SLURM_ARRAY_TASK_ID\" --device {device}");

    let shard_array = format!("0-{}", shards - 1);
    let shard_lines = format!(
        "FIRST=$(( SLURM_ARRAY_TASK_ID * {shard} ))\nCOUNT=$(( {n} - FIRST < {shard} ? {n} - FIRST : {shard} ))\n",
        n = opts.n
    );
    let mut sample = header("sample", c.sample_mem_gb, c.job_minutes, Some(&shard_array), true);
    sample += &shard_lines;
    let _ = writeln!(sample, "exec {exe} stage sample {run} --first \"$FIRST\" -n \"$COUNT\" --seed {} --device {device}", opts.seed);
    let mut meshing = header("mesh", c.mesh_mem_gb, c.job_minutes, Some(&shard_array), false);
    meshing += &shard_lines;
    let _ = writeln!(meshing, "exec {exe} stage mesh {run} --first \"$FIRST\" -n \"$COUNT\"");
    let mut eval = header("eval", c.eval_mem_gb, c.job_minutes, None, false);
    // The USD asset over every variant, then the scores.
    let _ = writeln!(eval, "{exe} stage usd {run} -n {} || exit $?", opts.n);
    let _ = writeln!(eval, "exec {exe} stage eval {run} -n {}", opts.n);

    Ok(vec![
        Job { stage: "encode", file: "encode.sbatch".into(), script: encode, array: None },
        Job { stage: "train", file: "train.sbatch".into(), script: train, array: Some(train_array) },
        Job { stage: "sample", file: "sample.sbatch".into(), script: sample, array: Some(shard_array.clone()) },
        Job { stage: "mesh", file: "mesh.sbatch".into(), script: meshing, array: Some(shard_array) },
        Job { stage: "eval", file: "eval.sbatch".into(), script: eval, array: None },
    ])
}

/// `submit.sh`: submits the jobs in order, each after the previous one
/// succeeded (`afterok` on an array waits for all its tasks), and prints
/// `stage job_id` lines.
pub fn submit_script(jobs: &[Job]) -> String {
    let mut s = String::from("#!/bin/bash\n# Submits the job graph in order; prints one 'stage job_id' line per job.\nset -euo pipefail\ncd \"$(dirname \"$0\")\"\nmkdir -p logs\nprev=\"\"\n");
    for j in jobs {
        let _ = writeln!(
            s,
            "id=$(sbatch --parsable ${{prev:+--dependency=afterok:$prev --kill-on-invalid-dep=yes}} {}); id=${{id%%;*}}; echo \"{} $id\"; prev=$id",
            j.file, j.stage
        );
    }
    s
}

/// Writes the scripts and `submit.sh` into `dir` (created).
pub fn write_graph(dir: &Path, jobs: &[Job]) -> Result<PathBuf> {
    std::fs::create_dir_all(dir.join("logs")).map_err(|e| Error::file(dir, e.to_string()))?;
    for j in jobs {
        let p = dir.join(&j.file);
        crate::util::fs::write_file(&p, &j.script)?;
    }
    let submit = dir.join("submit.sh");
    let text = submit_script(jobs);
    crate::util::fs::write_file(&submit, &text)?;
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&submit, std::fs::Permissions::from_mode(0o755)).map_err(|e| Error::file(&submit, e.to_string()))?;
    Ok(submit)
}

/// The `slurm` command: every input checked before anything is submitted
/// (it exists; several inputs need distinct names, one run folder
/// `OUT/<stem>` each), then each exemplar's job graph written under
/// `<run folder>/slurm` and submitted with its `submit.sh` (or only written,
/// `dry_run`). `report` gets, per exemplar as soon as it is submitted, the
/// submitter's output (job ids) or where the graph was written.
pub fn submit(meshes: &[PathBuf], output: &Path, config: &Config, opts: &GraphOptions, dry_run: bool, mut report: impl FnMut(&str)) -> Result<()> {
    let several = meshes.len() > 1;
    let stem = |m: &Path| m.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let mut stems = std::collections::HashSet::new();
    for m in meshes {
        if !m.is_file() {
            return Err(Error::file(m, "no such mesh file"));
        }
        if several && !stems.insert(stem(m)) {
            return Err(Error::file(m, format!("a second mesh named '{}': each exemplar needs its own run folder OUT/{}", stem(m), stem(m))));
        }
    }
    for m in meshes {
        let out = if several { output.join(stem(m)) } else { output.to_path_buf() };
        let jobs = job_graph(m, &out, config, opts)?;
        let submit = write_graph(&out.join("slurm"), &jobs)?;
        if dry_run {
            report(&format!("{}: {} jobs written, submit with {}\n", m.display(), jobs.len(), submit.display()));
            continue;
        }
        let o = std::process::Command::new("bash")
            .arg(&submit)
            .output()
            .map_err(|e| Error::file(&submit, format!("cannot run: {e}")))?;
        if !o.status.success() {
            return Err(Error::file(
                &submit,
                format!("submission failed: {}", String::from_utf8_lossy(&o.stderr).trim().replace('\n', " | ")),
            ));
        }
        report(&String::from_utf8_lossy(&o.stdout));
    }
    Ok(())
}

/// What a user asks of the `slurm` command.
pub struct SlurmRequest<'a> {
    pub meshes: &'a [PathBuf],
    pub output: &'a Path,
    pub n: usize,
    pub seed: u64,
    pub profile: &'a str,
    pub overrides: &'a [String],
    pub partition: Option<&'a str>,
    pub gpus_per_job: u32,
    /// Only write the scripts.
    pub dry_run: bool,
}

/// The `slurm` command: the configuration checked (a bad profile or
/// `--set` is [`Error::Usage`]), then [`submit`] with jobs that run this
/// program; `report` as there.
pub fn slurm_command(r: &SlurmRequest, report: impl FnMut(&str)) -> Result<()> {
    let config = Config::load(r.profile, r.overrides)?;
    let opts = GraphOptions {
        binary: super::run::this_program()?,
        profile: r.profile.to_string(),
        overrides: r.overrides.to_vec(),
        n: r.n,
        seed: r.seed,
        partition: r.partition.map(str::to_string),
        gpus_per_job: r.gpus_per_job,
    };
    submit(r.meshes, r.output, &config, &opts, r.dry_run, report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn graph_has_arrays_dependencies_and_resources() {
        let config = Config::load("cpu", &["cluster.variants_per_job=4".into()]).unwrap();
        let opts = GraphOptions {
            binary: "/opt/ss/shapeshifter".into(),
            profile: "cpu".into(),
            overrides: vec!["train.lr=1e-3".into()],
            n: 10,
            seed: 3,
            partition: Some("gpu".into()),
            gpus_per_job: 1,
        };
        let jobs = job_graph(Path::new("/data/tower.obj"), Path::new("/runs/tower"), &config, &opts).unwrap();
        let stages: Vec<&str> = jobs.iter().map(|j| j.stage).collect();
        assert_eq!(stages, ["encode", "train", "sample", "mesh", "eval"]);
        // One task per level with a network: 16, 32, 64 (128 and 256 are transferred).
        assert_eq!(config.trained_levels(), 3);
        assert_eq!(jobs[1].array.as_deref(), Some("0-2"), "one task per level");
        assert_eq!(jobs[2].array.as_deref(), Some("0-2"), "10 variants in shards of 4");
        assert!(jobs[1].script.contains("--requeue") && jobs[1].script.contains("--level \"$SLURM_ARRAY_TASK_ID\""));
        assert!(jobs[1].script.contains("--gres=gpu:1") && jobs[1].script.contains("--device cuda"));
        assert!(!jobs[0].script.contains("--gres"), "encoding needs no GPU");
        assert!(jobs[0].script.contains("--set 'train.lr=1e-3'") && jobs[0].script.contains("/data/tower.obj"));
        assert!(jobs.iter().all(|j| j.script.contains("--partition=gpu") && j.script.contains("--mem=")));
        assert!(jobs[2].script.contains("--seed 3") && jobs[4].script.contains("-n 10"));
        let submit = submit_script(&jobs);
        assert_eq!(submit.matches("sbatch --parsable").count(), 5);
        assert!(submit.contains("--dependency=afterok:$prev --kill-on-invalid-dep=yes"));
        // The script's own shard lines, run by bash for every array task,
        // cover variants 0..10 exactly once.
        let lines: String = jobs[2].script.lines().filter(|l| l.starts_with("FIRST=") || l.starts_with("COUNT=")).collect::<Vec<_>>().join("\n");
        let mut covered = Vec::new();
        for task in 0..3 {
            let o = std::process::Command::new("bash")
                .arg("-c")
                .arg(format!("SLURM_ARRAY_TASK_ID={task}\n{lines}\necho $FIRST $COUNT"))
                .output()
                .unwrap();
            let text = String::from_utf8_lossy(&o.stdout);
            let v: Vec<usize> = text.split_whitespace().map(|x| x.parse().unwrap()).collect();
            covered.extend(v[0]..v[0] + v[1]);
        }
        assert_eq!(covered, (0..10).collect::<Vec<_>>());
        // A run folder that #SBATCH cannot hold.
        assert!(job_graph(Path::new("/data/t.obj"), Path::new("/runs/my run"), &config, &opts).is_err());
    }
}
