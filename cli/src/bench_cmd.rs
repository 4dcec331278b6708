use anyhow::{Context, Result};
use clap::{Args, Subcommand};
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
            let r = run_env_bench(
                &model,
                &SimConfig::default(),
                task,
                &bench.catalogue,
                steps,
                repetitions.max(1),
                threads,
            );
            if json {
                println!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                println!(
                    "{}: {:.0} control steps/s ({:.0} physics steps/s) on one core; {:.0} ({:.0}) on {} threads; median of {} x {} steps",
                    r.task,
                    r.control_steps_per_s_per_core,
                    r.physics_steps_per_s_per_core,
                    r.control_steps_per_s_all_cores,
                    r.physics_steps_per_s_all_cores,
                    r.threads_all_cores,
                    r.repetitions,
                    r.steps_per_repetition
                );
            }
            Ok(())
        }
    }
}
