//! `lhm bench train`: the whole training loop's throughput against the environment alone, in one
//! run on the same machine: `lhm bench env`'s all-cores figure, then a real `lhm train` (learner
//! plus one actor process per core, the library's Teacher 1 stage) for a fixed number of
//! iterations, read back from its `metrics.csv`.

use anyhow::{bail, Context, Result};
use lhm_scenes::Benchmark;
use lhm_sim::bench::run_env_bench;
use lhm_sim::{CharacterModel, SimConfig};
use serde::Serialize;
use std::path::Path;
use std::process::Command;

#[derive(Debug, Serialize)]
pub struct TrainBench {
    /// Environment control steps/s on all cores, random actions, no learning (`lhm bench env`).
    pub env_only_samples_per_s: f64,
    /// Median samples/s of the training loop's iterations after the first `warmup`.
    pub loop_samples_per_s: f64,
    /// loop / env-only.
    pub ratio: f64,
    pub iterations: u64,
    pub warmup: u64,
    /// Median seconds of one PPO + AMP update.
    pub update_s: f64,
    /// Chunks dropped as stale / all chunks received.
    pub stale_fraction: f64,
    pub amp: bool,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Columns `names` of a metrics.csv, rows in order.
fn read_columns(path: &Path, names: &[&str]) -> Result<Vec<Vec<f64>>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .with_context(|| format!("{}: empty", path.display()))?
        .split(',')
        .collect();
    let idx: Vec<usize> = names
        .iter()
        .map(|n| {
            header
                .iter()
                .position(|h| h == n)
                .with_context(|| format!("{}: no column {n}", path.display()))
        })
        .collect::<Result<_>>()?;
    let mut out = vec![Vec::new(); names.len()];
    for (k, line) in lines.enumerate() {
        let fields: Vec<&str> = line.split(',').collect();
        for (col, &i) in idx.iter().enumerate() {
            let v = fields.get(i).copied().unwrap_or("");
            out[col].push(if v.is_empty() {
                f64::NAN
            } else {
                v.parse().with_context(|| {
                    format!(
                        "{}: line {}: {:?} is not a number",
                        path.display(),
                        k + 2,
                        v
                    )
                })?
            });
        }
    }
    Ok(out)
}

pub fn run(iterations: u64, warmup: u64, amp: bool) -> Result<TrainBench> {
    if iterations <= warmup {
        bail!("--iterations must be larger than --warmup");
    }
    let bench = Benchmark::embedded()?;
    let (_, task) = bench.task("train-0001").context("no task train-0001")?;
    let threads = std::thread::available_parallelism().map_or(1, usize::from);
    let env = run_env_bench(
        &CharacterModel::amp_humanoid(),
        &SimConfig::default(),
        &task,
        &bench.catalogue,
        600,
        3,
        threads,
        lhm_sim::env::EnvConfig::default().fall_height,
    );
    let dir = std::env::temp_dir().join(format!("lhm-bench-train-{}", std::process::id()));
    // A fresh run: an old one with this name would be resumed.
    let _ = std::fs::remove_dir_all(&dir);
    let exe = crate::cluster_cmd::this_executable()?;
    let mut cmd = Command::new(exe);
    // `--stage t1`: the library's Teacher 1 configuration, the environment `lhm bench env`
    // measures above (a plain `lhm train` runs the residual gait of `configs/teacher1.toml`).
    cmd.args([
        "train",
        "--stage",
        "t1",
        "--run-id",
        "bench-train",
        "--max-iterations",
    ])
    .arg(iterations.to_string())
    .arg("--runs-dir")
    .arg(&dir);
    if !amp {
        cmd.arg("--no-amp");
    }
    let status = cmd
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .context("running lhm train")?;
    if !status.success() {
        bail!("lhm train exited with {status}");
    }
    let cols = read_columns(
        &dir.join("bench-train").join("metrics.csv"),
        &[
            "samples_per_s",
            "update_s",
            "stale_chunks",
            "accepted_chunks",
        ],
    )?;
    let _ = std::fs::remove_dir_all(&dir);
    let skip = warmup as usize;
    let loop_rate = median(cols[0].iter().skip(skip).copied().collect());
    let update = median(cols[1].iter().skip(skip).copied().collect());
    let (stale, accepted) = (
        cols[2].last().copied().unwrap_or(0.0),
        cols[3].last().copied().unwrap_or(0.0),
    );
    Ok(TrainBench {
        env_only_samples_per_s: env.control_steps_per_s_all_cores,
        loop_samples_per_s: loop_rate,
        ratio: loop_rate / env.control_steps_per_s_all_cores,
        iterations,
        warmup,
        update_s: update,
        stale_fraction: stale / (stale + accepted).max(1.0),
        amp,
    })
}
