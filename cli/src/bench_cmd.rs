use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use lhm_learner::bench::BenchSpec;
use lhm_nets::MlpConfig;
use lhm_scenes::Benchmark;
use lhm_sim::bench::run_env_bench;
use lhm_sim::character::ServoModel;
use lhm_sim::fidelity::{run_fidelity, FidelityReport};
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
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
        /// Benchmark task whose room is simulated.
        #[arg(long, default_value = "train-0001")]
        task: String,
        /// Control steps per timed repetition (per world).
        #[arg(long, default_value_t = 600)]
        steps: usize,
        /// Timed repetitions; the report gives their median.
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
        /// Servo model: implicit-spring (the training setting) or motor-constraint.
        #[arg(long, default_value = "implicit-spring")]
        servo: String,
        /// rapier PGS iterations per substep (default: the training setting).
        #[arg(long)]
        solver_iterations: Option<usize>,
    },
    /// Physics fidelity in rapier: passive drop, 5 s neutral-pose hold, zero action, landing and a
    /// root-pinned knee step, each with fall step, root height and pelvis tilt at 0.5/1/2/5 s,
    /// joint tracking error, foot slide, penetration and floor force (bench/mujoco-fidelity
    /// prints the same for MuJoCo).
    Fidelity {
        /// Print the full report as JSON.
        #[arg(long)]
        json: bool,
        /// Servo model: implicit-spring (the training setting) or motor-constraint.
        #[arg(long, default_value = "implicit-spring")]
        servo: String,
        /// rapier PGS iterations per substep (default: the training setting).
        #[arg(long)]
        solver_iterations: Option<usize>,
        /// Pipeline steps per control step (default: the training setting).
        #[arg(long)]
        pipeline_steps: Option<usize>,
        /// Physics rate in Hz (default: the training setting, 120).
        #[arg(long)]
        physics_hz: Option<f32>,
        /// Another MJCF character instead of the shipped AMP humanoid.
        #[arg(long, value_name = "XML")]
        character: Option<PathBuf>,
    },
    /// The training loop's samples/s (a real `lhm train`: learner plus one actor per core) against
    /// the environment alone on all cores, in one run.
    Train {
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
        /// Training iterations to run.
        #[arg(long, default_value_t = 30)]
        iterations: u64,
        /// Iterations left out of the median (start-up).
        #[arg(long, default_value_t = 5)]
        warmup: u64,
        /// Without AMP (no motion clips needed).
        #[arg(long)]
        no_amp: bool,
    },
    /// Learner update throughput: one PPO minibatch step (policy + value forward, loss, backward,
    /// Adam; 256-d observations, 28-d actions, minibatch 4096) and one AMP discriminator step,
    /// for the default (1024-512) and CPU (512-256) network presets. Threads: RAYON_NUM_THREADS,
    /// else all cores.
    Learner {
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
        /// Timed repetitions; the report gives their median.
        #[arg(long, default_value_t = 7)]
        repetitions: usize,
    },
    /// The dagger-server's label throughput: states/s answered for one request of N states (half
    /// in each cycle, so both teachers work), batched per teacher as the server does against one
    /// forward pass per state, with the default training network (512-256) at the environment's
    /// observation size. Threads: RAYON_NUM_THREADS, else all cores.
    Labels {
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
        /// States per request (each size is measured).
        #[arg(long, default_values_t = [64usize, 1024])]
        states: Vec<usize>,
        /// Timed repetitions; the report gives their median.
        #[arg(long, default_value_t = 7)]
        repetitions: usize,
    },
    /// The VLA's eyes on one core, per image size: env steps/s with the state observation vs
    /// with the VLA row (egocentric render + instruction), renders/s, the VLA policy's forward
    /// rows/s (batches of 16), its regression's rows/s (256-row minibatches), and the bytes a step
    /// adds to a chunk.
    Vla {
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
        /// Image sides to measure.
        #[arg(long, default_values_t = [48usize, 64, 96])]
        sizes: Vec<usize>,
        /// Control steps (and renders) per timed repetition.
        #[arg(long, default_value_t = 200)]
        steps: usize,
        /// Timed repetitions; the report gives their median.
        #[arg(long, default_value_t = 3)]
        repetitions: usize,
    },
    /// Distributed layer: actor env steps/s with and without publishing, one vs two actor
    /// processes, and weight-broadcast latency (p50/p99) of the default network.
    Cluster {
        /// Print the report as JSON.
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
        BenchCommand::Labels {
            json,
            states,
            repetitions,
        } => bench_labels(json, &states, repetitions),
        BenchCommand::Vla {
            json,
            sizes,
            steps,
            repetitions,
        } => {
            let rows = crate::vla_bench::run(&sizes, steps, repetitions)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&rows)?);
            } else {
                println!(
                    "| image | env steps/s (state obs) | env steps/s (VLA row) | renders/s | VLA forward rows/s | VLA train rows/s | bytes/step |\n|---|---|---|---|---|---|---|"
                );
                for r in rows {
                    println!(
                        "| {0}x{0} | {1:.0} | {2:.0} | {3:.0} | {4:.0} | {5:.0} | {6} |",
                        r.image_size,
                        r.state_steps_per_s,
                        r.vla_steps_per_s,
                        r.renders_per_s,
                        r.policy_rows_per_s,
                        r.train_rows_per_s,
                        r.row_bytes
                    );
                }
            }
            Ok(())
        }
        BenchCommand::Env {
            json,
            task,
            steps,
            repetitions,
            threads,
            character,
            pipeline_steps,
            servo,
            solver_iterations,
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
            let mut config = SimConfig {
                servo: parse_servo(&servo)?,
                ..SimConfig::default()
            };
            if let Some(n) = pipeline_steps {
                config.pipeline_steps_per_control = n.max(1);
            }
            if let Some(n) = solver_iterations {
                anyhow::ensure!(n > 0, "--solver-iterations must be at least 1");
                config.solver_iterations = n;
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
        BenchCommand::Fidelity {
            json,
            servo,
            solver_iterations,
            pipeline_steps,
            physics_hz,
            character,
        } => {
            let model = match character {
                Some(path) => CharacterModel::from_file(&path)?,
                None => CharacterModel::amp_humanoid(),
            };
            let defaults = SimConfig::default();
            let config = SimConfig {
                servo: parse_servo(&servo)?,
                solver_iterations: solver_iterations.unwrap_or(defaults.solver_iterations),
                pipeline_steps_per_control: pipeline_steps
                    .unwrap_or(defaults.pipeline_steps_per_control),
                physics_hz: physics_hz.unwrap_or(defaults.physics_hz),
                ..defaults
            };
            if config.solver_iterations == 0 || config.pipeline_steps_per_control == 0 {
                anyhow::bail!("--solver-iterations and --pipeline-steps must be at least 1");
            }
            if !(config.physics_hz.is_finite() && config.physics_hz >= config.control_hz) {
                anyhow::bail!("--physics-hz must be at least the control rate (30)");
            }
            let r = run_fidelity(&model, &config);
            if json {
                println!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                print_fidelity(&r);
            }
            Ok(())
        }
        BenchCommand::Train {
            json,
            iterations,
            warmup,
            no_amp,
        } => {
            let r = crate::train_bench::run(iterations, warmup, !no_amp)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                println!(
                    "training loop {:.0} samples/s vs environment alone {:.0} on all cores ({:.0}%); update {:.2} s; {:.1}% of chunks stale; median of iterations {}..{}",
                    r.loop_samples_per_s,
                    r.env_only_samples_per_s,
                    100.0 * r.ratio,
                    r.update_s,
                    100.0 * r.stale_fraction,
                    r.warmup + 1,
                    r.iterations
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

fn parse_servo(name: &str) -> Result<ServoModel> {
    match name {
        "implicit-spring" => Ok(ServoModel::ImplicitSpring),
        "motor-constraint" => Ok(ServoModel::MotorConstraint),
        other => anyhow::bail!("--servo {other:?}: expected implicit-spring or motor-constraint"),
    }
}

fn print_fidelity(r: &FidelityReport) {
    let opt = |v: Option<f32>, k: f32| v.map_or("-".to_string(), |v| format!("{:.2}", v * k));
    println!(
        "{:<13} {:>5} {:>26} {:>26} {:>8} {:>9} {:>8} {:>15}",
        "scenario",
        "fall",
        "root height m (0.5/1/2/5s)",
        "pelvis tilt deg",
        "err deg",
        "slide mm",
        "pen mm",
        "force N mean/sd"
    );
    for (name, s) in [
        ("passive_drop", &r.passive_drop),
        ("neutral_hold", &r.neutral_hold),
        ("zero_action", &r.zero_action),
        ("landing", &r.landing),
    ] {
        let series = |m: &std::collections::BTreeMap<String, f32>| {
            ["0.5", "1", "2", "5"]
                .iter()
                .map(|k| m.get(*k).map_or("-".into(), |v| format!("{v:.2}")))
                .collect::<Vec<String>>()
                .join("/")
        };
        println!(
            "{:<13} {:>5} {:>26} {:>26} {:>8} {:>9} {:>8.2} {:>15}",
            name,
            s.fall_step.map_or("-".into(), |f| f.to_string()),
            series(&s.root_height_m),
            series(&s.pelvis_tilt_deg),
            opt(s.max_tracking_error_deg, 1.0),
            opt(s.foot_slide_m, 1000.0),
            s.max_penetration_m * 1000.0,
            format!("{:.0}/{:.0}", s.contact_force_mean_n, s.contact_force_std_n),
        );
    }
    let knee: Vec<String> = r
        .servo_step
        .knee_error_deg
        .iter()
        .map(|(t, e)| format!("{t} s: {e:.1}"))
        .collect();
    println!(
        "servo_step (root pinned, right knee to 70 deg): error {}",
        knee.join(", ")
    );
    let mut worst: Vec<(&String, &f32)> = r.collapse.limit_excess_deg_by_joint.iter().collect();
    worst.sort_by(|a, b| b.1.total_cmp(a.1));
    let worst: Vec<String> = worst
        .iter()
        .take(3)
        .map(|(n, e)| format!("{n} {e:.1}"))
        .collect();
    println!(
        "collapse (servos off, {} s): worst joint past its range by {:.1} deg on average, at most {:.1} deg ({})",
        lhm_sim::fidelity::COLLAPSE_S,
        r.collapse.mean_limit_excess_deg,
        r.collapse.max_limit_excess_deg,
        worst.join(", ")
    );
}

/// `lhm bench labels`: both teachers as the default training run's networks, published and
/// decoded as the dagger-server receives them.
fn bench_labels(json: bool, states: &[usize], repetitions: usize) -> Result<()> {
    let config = lhm_learner::service::TrainConfig::default();
    let model = CharacterModel::amp_humanoid();
    let obs_dim = lhm_sim::env::TaskEnv::obs_dim(&model, &config.env);
    let act_dim = model.dofs.len();
    let mut teachers = lhm_dagger_server::Teachers::default();
    for (role, seed) in [
        (lhm_protos::Role::Teacher1, 1),
        (lhm_protos::Role::Teacher2, 2),
    ] {
        let mut net = config.network.clone();
        net.init_seed = seed;
        let ac = lhm_nets::ActorCritic::new(obs_dim, act_dim, &net)?;
        let spec = lhm_cluster::RunSpec {
            obs_dim,
            act_dim,
            amp_dim: 0,
            actor_critic: net,
            env: config.env.clone(),
            sim: config.sim.clone(),
            tasks: config.tasks.clone(),
            chunk_steps: config.chunk_steps,
            record_every_episodes: 0,
            chunk_sets_per_version: 0,
            teacher_mix: 0.0,
        };
        let message = lhm_cluster::encode_policy("bench", role, 1, &spec, &ac)?;
        teachers.update(&lhm_protos::WireMessage::encode_checked(&message)?)?;
    }
    let mut rows = Vec::new();
    for &n in states {
        let (batched, single) = lhm_dagger_server::bench_labels(&teachers, n.max(1), repetitions)
            .map_err(|e| anyhow::anyhow!("labelling: {e}"))?;
        rows.push(serde_json::json!({
            "states": n,
            "batched_states_per_s": batched,
            "per_state_states_per_s": single,
            "speedup": batched / single,
        }));
        if !json {
            println!(
                "{n} states per request: {batched:.0} states/s batched, {single:.0} one forward \
                 pass per state ({:.1}x)",
                batched / single
            );
        }
    }
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "obs_dim": obs_dim,
                "act_dim": act_dim,
                "hidden": [512, 256],
                "repetitions": repetitions,
                "requests": rows,
            }))?
        );
    }
    Ok(())
}
