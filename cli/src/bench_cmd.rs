use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use lhm_learner::bench::BenchSpec;
use lhm_nets::MlpConfig;
use lhm_scenes::Benchmark;
use lhm_sim::bench::run_env_bench;
use lhm_sim::{CharacterModel, SimConfig};
use std::path::PathBuf;

#[derive(Args)]
pub struct BenchArgs {
    #[command(subcommand)]
    command: BenchCommand,
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Environment throughput: control and physics steps/s, one core and all cores.
    Env {
        #[arg(long)]
        json: bool,
        /// Benchmark task whose room is simulated.
        #[arg(long, default_value = "train-0001")]
        task: String,
        /// Control steps per timed repetition (per world).
        #[arg(long, default_value_t = 600)]
        steps: usize,
        #[arg(long, default_value_t = 5)]
        repetitions: usize,
        /// Threads for the all-cores figure (default: all available cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Another MJCF character instead of the shipped AMP humanoid.
        #[arg(long, value_name = "XML")]
        character: Option<PathBuf>,
        /// Pipeline steps per control step (default: the training setting, 2 x 1/60 s with 2 substeps).
        #[arg(long)]
        pipeline_steps: Option<usize>,
    },
    /// Learner update throughput: one PPO minibatch step (policy + value forward, loss, backward,
    /// Adam; 256-d observations, 28-d actions, minibatch 4096) and one AMP discriminator step,
    /// for the default (1024-512) and CPU (512-256) network presets. Threads: RAYON_NUM_THREADS,
    /// else all cores.
    Learner {
        #[arg(long)]
        json: bool,
        #[arg(long, default_value_t = 7)]
        repetitions: usize,
    },
    /// Distributed layer: actor env steps/s with and without publishing, one vs two actor
    /// processes, and weight-broadcast latency (p50/p99) of the default network.
    Cluster {
        #[arg(long)]
        json: bool,
        /// Environments per actor process.
        #[arg(long, default_value_t = 16)]
        envs: usize,
        /// Chunks each actor sends per measurement (a chunk is 32 steps of one environment).
        #[arg(long, default_value_t = 256)]
        chunks: u64,
        /// Timed weight broadcasts.
        #[arg(long, default_value_t = 30)]
        broadcasts: usize,
    },
}

pub fn run(args: BenchArgs) -> Result<()> {
    match args.command {
        BenchCommand::Env {
            json,
            task,
            steps,
            repetitions,
            threads,
            character,
            pipeline_steps,
        } => {
            let bench = Benchmark::embedded()?;
            let (_, task) = bench
                .task(&task)
                .with_context(|| format!("no task {task:?}"))?;
            let model = match character {
                Some(path) => CharacterModel::from_file(&path)?,
                None => CharacterModel::amp_humanoid(),
            };
            let threads = threads
                .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, usize::from));
            let mut config = SimConfig::default();
            if let Some(n) = pipeline_steps {
                config.pipeline_steps_per_control = n.max(1);
            }
            let r = run_env_bench(
                &model,
                &config,
                &task,
                &bench.catalogue,
                steps,
                repetitions.max(1),
                threads,
                lhm_sim::env::EnvConfig::default().fall_height,
            );
            if json {
                println!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                println!(
                    "{}: {:.0} control steps/s ({:.0} physics steps/s) on one core; {:.0} ({:.0}) with {} worlds on {} threads; median of {} x {} steps; episodes end on a fall or after {} steps (mean {:.1}); {:.0} control steps/s on one core when only the length ends them",
                    r.task,
                    r.control_steps_per_s_per_core,
                    r.physics_steps_per_s_per_core,
                    r.control_steps_per_s_all_cores,
                    r.physics_steps_per_s_all_cores,
                    r.worlds_all_cores,
                    r.threads_all_cores,
                    r.repetitions,
                    r.steps_per_repetition,
                    r.episode_steps,
                    r.mean_episode_steps,
                    r.control_steps_per_s_per_core_without_fall_reset,
                );
            }
            Ok(())
        }
        BenchCommand::Cluster {
            json,
            envs,
            chunks,
            broadcasts,
        } => {
            let r = crate::cluster_bench::run(envs.max(1), chunks.max(1), broadcasts.max(1))?;
            if json {
                println!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                println!(
                    "actor ({} envs): {:.0} env steps/s publishing, {:.0} without ({:.1}% overhead)\n\
                     two actor processes: {:.0} env steps/s ({:.2}x one)\n\
                     weights {:?} ({:.1} MB): broadcast p50 {:.1} ms, p99 {:.1} ms over {} puts",
                    r.envs_per_actor,
                    r.actor_env_steps_per_s_publish,
                    r.actor_env_steps_per_s_no_publish,
                    r.publish_overhead_percent,
                    r.two_actors_env_steps_per_s,
                    r.scaling_two_vs_one,
                    r.network_hidden,
                    r.weights_bytes as f64 / 1e6,
                    r.weight_broadcast_ms_p50,
                    r.weight_broadcast_ms_p99,
                    r.weight_broadcast_samples
                );
            }
            Ok(())
        }
        BenchCommand::Learner { json, repetitions } => {
            let spec = |hidden: Vec<usize>| BenchSpec {
                hidden,
                repetitions: repetitions.max(1),
                ..BenchSpec::default()
            };
            let default = lhm_learner::bench::run(&spec(MlpConfig::default().hidden))?;
            let cpu = lhm_learner::bench::run(&spec(MlpConfig::cpu_preset().hidden))?;
            if json {
                let out = serde_json::json!({
                    "ppo_samples_per_s": default.ppo_samples_per_s,
                    "amp_samples_per_s": default.amp_samples_per_s,
                    "default": default,
                    "cpu": cpu,
                });
                println!("{}", serde_json::to_string_pretty(&out)?);
            } else {
                for (name, r) in [("default", &default), ("cpu", &cpu)] {
                    println!(
                        "{name} {:?}: PPO step {:.0} ms ({:.0} samples/s), AMP step {:.0} ms ({:.0} samples/s), {} threads",
                        r.spec.hidden, r.ppo.median_ms, r.ppo_samples_per_s, r.amp.median_ms, r.amp_samples_per_s, r.threads
                    );
                }
            }
            Ok(())
        }
    }
}
