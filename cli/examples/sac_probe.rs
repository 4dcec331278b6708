//! Experiment: does an off-policy learner (soft actor-critic, `lhm_learner::sac`) make the
//! character walk to its object on a CPU budget where PPO + AMP has not (RESULTS.md)? One process,
//! `--envs` task environments on Teacher 1's single-object training tasks, task starts only, the
//! task reward of the environment (no discriminator), `--utd` gradient steps per environment step.
//! Prints a line (and appends a CSV row to `--out`) every `--report-s` seconds over the episodes
//! finished since the last one: mean length, fall fraction, reach rate (root within the reach
//! distance of the object), task reward per step.
//!
//! `cargo run --release -p lhm-cli --example sac_probe -- --minutes 30 --out sac.csv`
use std::io::Write;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Parser;
use lhm_learner::sac::{Sac, SacConfig, SacReplay, SacStats};
use lhm_learner::service::TrainConfig;
use lhm_nets::SplitMix64;
use lhm_scenes::{Benchmark, Split};
use lhm_sim::env::TaskEnv;
use lhm_sim::CharacterModel;

#[derive(Parser, Debug)]
struct Args {
    /// Wall-clock budget in minutes.
    #[arg(long, default_value_t = 30.0)]
    minutes: f64,
    /// Environments stepped together.
    #[arg(long, default_value_t = 8)]
    envs: usize,
    /// Gradient steps per environment step.
    #[arg(long, default_value_t = 0.5)]
    utd: f64,
    /// Environment steps before the first update.
    #[arg(long, default_value_t = 5_000)]
    warmup: usize,
    /// Episode length limit in control steps (a time-out, not terminal).
    #[arg(long, default_value_t = 300)]
    episode_steps: u32,
    /// Task reward multiplier (SAC's temperature is relative to the reward scale).
    #[arg(long, default_value_t = 5.0)]
    reward_scale: f32,
    /// Target entropy per action dimension.
    #[arg(long, default_value_t = -1.0, allow_hyphen_values = true)]
    target_entropy: f64,
    /// Weights of the locomotion and facing terms (the training default: 0.2 and 0.1).
    #[arg(long)]
    locomotion: Option<f32>,
    #[arg(long)]
    facing: Option<f32>,
    /// Bounds of the actor's log-std (its initial log-std is their midpoint; SAC's usual
    /// [-5, 2] starts at σ ≈ 0.22, which topples the character within a second).
    #[arg(long, default_value_t = -5.0, allow_hyphen_values = true)]
    log_std_min: f64,
    #[arg(long, default_value_t = 2.0, allow_hyphen_values = true)]
    log_std_max: f64,
    #[arg(long, default_value_t = 300_000)]
    replay: usize,
    #[arg(long, default_value_t = 30.0)]
    report_s: f64,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Stop updating the observation normaliser after this many environment steps (0: never
    /// stop): critics whose inputs keep shifting under them can diverge.
    #[arg(long, default_value_t = 0)]
    freeze_norm_after: usize,
    /// Hidden widths of the actor and both critics (default: SAC's 256-256).
    #[arg(long, value_delimiter = ',')]
    hidden: Option<Vec<usize>>,
    /// The actor's learning rate (default: SAC's 3e-4). 0 freezes the actor, so the critics
    /// evaluate one fixed policy — its own data — and `mean_q` can be held against `mc_return`.
    #[arg(long)]
    actor_lr: Option<f64>,
    /// The entropy temperature's starting value (SAC's default: 0.2).
    #[arg(long)]
    initial_alpha: Option<f64>,
    /// The actor steps once every this many critic steps (TD3's delayed policy updates).
    #[arg(long, default_value_t = 1)]
    actor_every: usize,
    /// CSV file the report rows are appended to.
    #[arg(long)]
    out: Option<std::path::PathBuf>,
}

#[derive(Default)]
struct Window {
    episodes: u64,
    length: u64,
    falls: u64,
    reached: u64,
    reward: f64,
    steps: u64,
    /// Discounted returns-to-go (scaled reward) summed over every step of the finished episodes:
    /// the Monte-Carlo value of the states visited, to hold the critics' `mean_q` against (a
    /// lower bound for episodes cut by the time limit).
    mc_sum: f64,
    mc_steps: u64,
}

/// The sum over an episode's steps of the discounted return-to-go from each.
fn returns_to_go_sum(rewards: &[f32], gamma: f64) -> f64 {
    let mut g = 0.0;
    let mut sum = 0.0;
    for r in rewards.iter().rev() {
        g = f64::from(*r) + gamma * g;
        sum += g;
    }
    sum
}

/// SAC's defaults with the probe's options applied.
fn sac_config(args: &Args) -> SacConfig {
    let mut config = SacConfig {
        target_entropy_per_dim: args.target_entropy,
        log_std_min: args.log_std_min,
        log_std_max: args.log_std_max,
        actor_every: args.actor_every,
        seed: args.seed,
        ..SacConfig::default()
    };
    if let Some(lr) = args.actor_lr {
        config.actor_adam.lr = lr;
    }
    if let Some(alpha) = args.initial_alpha {
        config.initial_alpha = alpha;
    }
    if let Some(h) = &args.hidden {
        config.actor.hidden = h.clone();
        config.critic.hidden = h.clone();
    }
    config
}

fn main() -> Result<()> {
    let args = Args::parse();
    let bench = Benchmark::embedded().context("loading the embedded benchmark")?;
    let tasks = bench.single_object_tasks(Split::Train);
    let model = CharacterModel::amp_humanoid();
    let defaults = TrainConfig::default();
    let mut env_config = defaults.env.clone();
    env_config.max_episode_steps = args.episode_steps;
    if let Some(w) = args.locomotion {
        env_config.weights.locomotion = w;
    }
    if let Some(w) = args.facing {
        env_config.weights.facing = w;
    }
    let sim = defaults.sim.clone();
    let mut rng = SplitMix64::new(args.seed);
    let new_env = |rng: &mut SplitMix64| {
        let task = &tasks[rng.below(tasks.len())];
        TaskEnv::new(
            &model,
            task,
            &bench.catalogue,
            sim.clone(),
            env_config.clone(),
        )
    };
    let mut envs: Vec<TaskEnv> = (0..args.envs).map(|_| new_env(&mut rng)).collect();
    let obs_dim = TaskEnv::obs_dim(&model, &env_config);
    let act_dim = model.dofs.len();
    let mut sac = Sac::new(obs_dim, act_dim, sac_config(&args))?;
    let mut replay = SacReplay::new(args.replay, obs_dim, act_dim);
    let mut out = match &args.out {
        Some(p) => {
            let mut f = std::fs::File::create(p).with_context(|| format!("{}", p.display()))?;
            writeln!(f, "wall_s,env_steps,updates,episodes,mean_length,fall_fraction,reach_rate,reward_per_step,alpha,entropy,critic_loss,mean_q,mc_return")?;
            Some(f)
        }
        None => None,
    };
    println!(
        "sac_probe: {} tasks, {} envs, obs {obs_dim}, act {act_dim}, utd {}, {} min",
        tasks.len(),
        args.envs,
        args.utd,
        args.minutes
    );

    let start = Instant::now();
    let (mut env_steps, mut updates, mut owed) = (0usize, 0usize, 0.0f64);
    let mut window = Window::default();
    let mut stats = SacStats::default();
    let mut last_report = 0.0;
    let mut obs: Vec<f32> = envs.iter().flat_map(|e| e.observation()).collect();
    let mut episode_rewards: Vec<Vec<f32>> = vec![Vec::new(); envs.len()];
    while start.elapsed().as_secs_f64() < args.minutes * 60.0 {
        if args.freeze_norm_after == 0 || env_steps < args.freeze_norm_after {
            sac.observe(&obs)?;
        }
        let actions = sac.act(&obs, true)?;
        let mut next_obs = Vec::with_capacity(obs.len());
        for (k, env) in envs.iter_mut().enumerate() {
            let a = &actions[k * act_dim..(k + 1) * act_dim];
            let r = env.step(a);
            window.reward += f64::from(r.reward);
            window.steps += 1;
            episode_rewards[k].push(r.reward * args.reward_scale);
            let after = env.observation();
            if !r.physics_invalid {
                replay.push(
                    &obs[k * obs_dim..(k + 1) * obs_dim],
                    a,
                    r.reward * args.reward_scale,
                    &after,
                    r.done,
                )?;
            }
            if r.done || r.truncated || r.physics_invalid {
                window.episodes += 1;
                window.length += u64::from(env.steps());
                window.falls += u64::from(r.fell);
                window.reached += u64::from(env.reached);
                let rewards = std::mem::take(&mut episode_rewards[k]);
                window.mc_sum += returns_to_go_sum(&rewards, sac.config.gamma);
                window.mc_steps += rewards.len() as u64;
                *env = new_env(&mut rng);
                next_obs.extend(env.observation());
            } else {
                next_obs.extend(after);
            }
        }
        obs = next_obs;
        env_steps += envs.len();
        if env_steps >= args.warmup {
            owed += args.utd * envs.len() as f64;
            while owed >= 1.0 {
                let batch = replay.sample(sac.config.batch_size, &mut rng);
                stats = sac.update(&batch)?;
                updates += 1;
                owed -= 1.0;
            }
        }
        let t = start.elapsed().as_secs_f64();
        if t - last_report >= args.report_s {
            last_report = t;
            let e = window.episodes.max(1) as f64;
            let row = format!(
                "{t:.0},{env_steps},{updates},{},{:.1},{:.3},{:.3},{:.4},{:.4},{:.2},{:.4},{:.3},{:.3}",
                window.episodes,
                window.length as f64 / e,
                window.falls as f64 / e,
                window.reached as f64 / e,
                window.reward / window.steps.max(1) as f64,
                stats.alpha,
                stats.entropy,
                stats.critic_loss,
                stats.mean_q,
                window.mc_sum / window.mc_steps.max(1) as f64
            );
            println!("{row}");
            if let Some(f) = out.as_mut() {
                writeln!(f, "{row}")?;
                f.flush()?;
            }
            window = Window::default();
        }
    }
    Ok(())
}
