//! Experiment: distil the predictive-sampling planner (`lhm_sim::plan`), which keeps the gait base
//! up and stops it at the object, into Teacher 1's policy network by DAgger (Ross, Gordon, Bagnell
//! 2011; guided policy search, Levine & Koltun 2013): each round rolls episodes out on training
//! tasks with the planner's action (probability β) or the student's mean action, labels every
//! visited state with the planner's action, aggregates, and regresses the student's mean onto all
//! labels so far (`lhm_learner::dagger`). After each round the student alone (deterministic) is
//! scored on unseen tasks: control steps up, objects reached, episodes up to the end — against
//! the gait base alone. The student is saved as a `lhm train` policy checkpoint with the run's
//! config, so `lhm render-rollout --policy OUT/policy --config OUT/config.toml` plays it and
//! `lhm train --init-from OUT/policy` fine-tunes it. `--prior` plans around the student instead
//! (PLATO: the labels are the student's actions corrected).
//!
//! `cargo run --release -p lhm-cli --example mpc_distill -- --config FILE --out DIR`
//! (the config must have `[env.gait]`; the planner's settings are `PlannerConfig::default()` but
//! for `--samples`, `--horizon`, `--decay`, `--temperature`, `--threads`). With `--parallel` above
//! 1 on a many-core machine, set `RAYON_NUM_THREADS=1`: the student's one-row products otherwise
//! may fan out over every core from every planner thread.
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Parser;
use lhm_learner::dagger::{DaggerDataset, StudentConfig, StudentTrainer};
use lhm_learner::service::TrainConfig;
use lhm_learner::state::Learner;
use lhm_nets::SplitMix64;
use lhm_scenes::{Benchmark, Split, Task};
use lhm_sim::env::TaskEnv;
use lhm_sim::gait::{reference_for_gait, GaitReference};
use lhm_sim::motion::demo::{AmpWindow, DemoMotion};
use lhm_sim::plan::{down, Planner, PlannerConfig};
use lhm_sim::CharacterModel;

#[derive(Parser, Debug)]
struct Args {
    /// A `lhm train` config with `[env.gait]`.
    #[arg(long)]
    config: PathBuf,
    /// Output directory: the aggregated dataset, the student's policy checkpoint, config.toml.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, default_value_t = 6)]
    rounds: usize,
    /// Episodes per round (on training tasks, drawn in order from a shuffled list).
    #[arg(long, default_value_t = 6)]
    episodes: usize,
    /// Control steps per collection episode.
    #[arg(long, default_value_t = 300)]
    episode_steps: usize,
    /// β of round r is beta^r (round 0: the planner alone).
    #[arg(long, default_value_t = 0.5)]
    beta: f64,
    /// Fraction of collection episodes started from the task's standing start (the rest in the
    /// gait at a random cycle step, as the actors start them).
    #[arg(long, default_value_t = 0.5)]
    stand_start: f64,
    #[arg(long, default_value_t = 24)]
    samples: usize,
    #[arg(long, default_value_t = 30)]
    horizon: usize,
    /// Unseen tasks the student is scored on after each round.
    #[arg(long, default_value_t = 10)]
    eval_tasks: usize,
    #[arg(long, default_value_t = 600)]
    eval_steps: usize,
    /// Regression passes per round, in multiples of the newest round's rows.
    #[arg(long, default_value_t = 8)]
    epochs: usize,
    #[arg(long, default_value_t = 1e-3)]
    lr: f64,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Plan hips, knees, ankles and abdomen only (arms and neck keep a zero residual).
    #[arg(long)]
    legs_only: bool,
    /// Plan around the student (PLATO): every rollout step's action is the student's mean action
    /// plus the plan's correction (`Planner::act_around`), so a label is the student's action
    /// corrected rather than the planner's own plan.
    #[arg(long)]
    prior: bool,
    /// The planner's `decay` (1: plain warm start; below 1 the corrections fade back to the
    /// student, or to the base without `--prior`).
    #[arg(long, default_value_t = 1.0)]
    decay: f32,
    /// The planner's `temperature` (0: the cheapest plan; above 0: MPPI's weighted mean, which
    /// averages the selected noise out of the labels).
    #[arg(long, default_value_t = 0.0)]
    temperature: f32,
    /// Collection episodes (and evaluation tasks) run this many at once.
    #[arg(long, default_value_t = 1)]
    parallel: usize,
    /// Planner threads per episode.
    #[arg(long, default_value_t = 2)]
    threads: usize,
}

struct Setup {
    model: CharacterModel,
    bench: Benchmark,
    demo: DemoMotion,
    reference: Arc<GaitReference>,
    train: TrainConfig,
}

impl Setup {
    fn env(&self, task: &Task) -> TaskEnv {
        TaskEnv::new(
            &self.model,
            task,
            &self.bench.catalogue,
            self.train.sim.clone(),
            self.train.env.clone(),
        )
    }

    /// A fresh episode: standing at the task's start with the gait from cycle step 0, or in the
    /// gait at `step`, turned toward the first object.
    fn start(&self, task: &Task, stand: bool, step: usize) -> TaskEnv {
        let mut env = self.env(task);
        if stand {
            env.start_gait(Arc::clone(&self.reference), 0);
        } else {
            let yaw = env.yaw_toward_first_object();
            env.start_in_gait(&self.demo, Arc::clone(&self.reference), step, yaw);
        }
        env
    }
}

#[derive(Default)]
struct Score {
    up: usize,
    reached: usize,
    to_end: usize,
    episodes: usize,
}

impl Score {
    /// One episode that stayed up `up` of `steps` control steps.
    fn add(&mut self, reached: bool, up: usize, steps: usize) {
        self.up += up;
        self.reached += reached as usize;
        self.to_end += (up == steps) as usize;
        self.episodes += 1;
    }
}

impl std::fmt::Display for Score {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "up {:.0} steps per episode, reached {} / {}, up to the end {} / {}",
            self.up as f64 / self.episodes.max(1) as f64,
            self.reached,
            self.episodes,
            self.to_end,
            self.episodes
        )
    }
}

/// Runs `jobs` on `parallel` threads (in order of the inputs) and collects their results.
fn in_parallel<I: Sync, T: Send>(
    inputs: &[I],
    parallel: usize,
    job: impl Fn(&I) -> Result<T> + Sync,
) -> Result<Vec<T>> {
    let per = inputs.len().div_ceil(parallel.max(1)).max(1);
    std::thread::scope(|scope| {
        let handles: Vec<_> = inputs
            .chunks(per)
            .map(|chunk| scope.spawn(|| chunk.iter().map(&job).collect::<Result<Vec<T>>>()))
            .collect();
        let mut out = Vec::new();
        for h in handles {
            match h.join() {
                Ok(r) => out.extend(r?),
                Err(_) => bail!("a worker thread panicked"),
            }
        }
        Ok(out)
    })
}

/// The student's mean action (`None`: zero residual, the base alone) on unseen tasks.
fn evaluate(s: &Setup, student: Option<&Learner>, args: &Args, stand: bool) -> Result<Score> {
    let zero = vec![0.0f32; s.model.dofs.len()];
    let tasks: Vec<&Task> = s
        .bench
        .tasks(Split::Unseen)
        .iter()
        .take(args.eval_tasks)
        .collect();
    let episodes = in_parallel(&tasks, args.parallel, |task| {
        let mut env = s.start(task, stand, 0);
        let mut up = 0;
        for t in 0..args.eval_steps {
            let action = match student {
                Some(l) => l.actor_critic.act_deterministic(&env.observation())?,
                None => zero.clone(),
            };
            let r = env.step(&action);
            if down(&env, &r, 0.7) {
                break;
            }
            up = t + 1;
            if r.done {
                break;
            }
        }
        Ok((env.reached, up))
    })?;
    let mut score = Score::default();
    for (reached, up) in episodes {
        score.add(reached, up, args.eval_steps);
    }
    Ok(score)
}

/// One collection episode's plan: where it starts and its random streams.
struct EpisodeSpec<'a> {
    task: &'a Task,
    stand: bool,
    cycle_step: usize,
    planner_seed: u64,
    mix_seed: u64,
}

/// The labelled rows of one episode: observations, the planner's actions, and how it went.
struct Episode {
    obs: Vec<f32>,
    labels: Vec<f32>,
    reached: bool,
    up: usize,
}

/// Rolls one episode out with the planner's action (probability β) or the student's, labelling
/// every visited state with the planner's action.
fn collect_episode(
    s: &Setup,
    spec: &EpisodeSpec,
    planner: &Planner,
    student: &Learner,
    args: &Args,
    beta: f64,
) -> Result<Episode> {
    let mut env = s.start(spec.task, spec.stand, spec.cycle_step);
    let mut workers: Vec<TaskEnv> = (0..planner.config.threads)
        .map(|_| s.env(spec.task))
        .collect();
    let mut planner = planner.reseeded(spec.planner_seed);
    // The prior cannot return an error through the planner: a failed inference is recorded
    // and ends the episode with that error below.
    let failure = std::sync::Mutex::new(None::<String>);
    let policy = |obs: &[f32]| -> Vec<f32> {
        student
            .actor_critic
            .act_deterministic(obs)
            .unwrap_or_else(|e| {
                if let Ok(mut f) = failure.lock() {
                    f.get_or_insert(e.to_string());
                }
                vec![0.0; student.config.act_dim]
            })
    };
    let prior: Option<lhm_sim::plan::Prior> = if args.prior { Some(&policy) } else { None };
    let mut rng = SplitMix64::new(spec.mix_seed);
    let mut episode = Episode {
        obs: Vec::new(),
        labels: Vec::new(),
        reached: false,
        up: 0,
    };
    for t in 0..args.episode_steps {
        let obs = env.observation();
        let label = planner.act_around(&env, &mut workers, prior);
        if let Some(e) = failure.lock().ok().and_then(|f| f.clone()) {
            bail!("the student's inference inside the planner failed: {e}");
        }
        let action = if rng.next_f64() < beta {
            label.clone()
        } else {
            student.actor_critic.act_deterministic(&obs)?
        };
        episode.obs.extend_from_slice(&obs);
        episode.labels.extend_from_slice(&label);
        let r = env.step(&action);
        if down(&env, &r, planner.config.up_height) {
            break;
        }
        episode.up = t + 1;
        if r.done {
            break;
        }
    }
    episode.reached = env.reached;
    Ok(episode)
}

/// The config, clips, gait reference and benchmark the run needs.
fn load_setup(args: &Args) -> Result<Setup> {
    let train = TrainConfig::from_toml_file(&args.config)?;
    let Some(gait) = train.env.gait.clone() else {
        bail!(
            "{}: the distillation needs [env.gait]",
            args.config.display()
        );
    };
    let model = CharacterModel::amp_humanoid();
    let dir = lhm_sim::motion::default_dir();
    let demo = DemoMotion::load_dir(&model, &dir, AmpWindow::of(&train.env, &train.sim))
        .with_context(|| format!("motion clips in {}", dir.display()))?;
    let reference = Arc::new(
        reference_for_gait(&model, &demo, &gait, 1.0 / train.sim.control_hz)
            .map_err(anyhow::Error::msg)?,
    );
    Ok(Setup {
        model,
        bench: Benchmark::embedded()?,
        demo,
        reference,
        train,
    })
}

/// A fresh planner with the run's settings, planning all DoFs or (`--legs-only`) hips, knees,
/// ankles and abdomen.
fn planner_template(args: &Args, model: &CharacterModel, act_dim: usize) -> Result<Planner> {
    let config = PlannerConfig {
        samples: args.samples,
        horizon: args.horizon,
        decay: args.decay,
        temperature: args.temperature,
        threads: args.threads,
        ..PlannerConfig::default()
    };
    let planned: Vec<bool> = model
        .dofs
        .iter()
        .map(|d| {
            !args.legs_only
                || ["hip", "knee", "ankle", "abdomen"]
                    .iter()
                    .any(|p| d.name.contains(p))
        })
        .collect();
    Planner::new(config, act_dim)
        .and_then(|p| p.with_planned(planned))
        .map_err(anyhow::Error::msg)
}

fn main() -> Result<()> {
    let args = Args::parse();
    let setup = load_setup(&args)?;
    let mut learner = Learner::new(setup.train.learner_config())?;
    let (obs_dim, act_dim) = (learner.config.obs_dim, learner.config.act_dim);
    std::fs::create_dir_all(&args.out)?;
    let mut data = DaggerDataset::open(&args.out.join("dataset"), obs_dim, act_dim, 1_000_000)?;
    let mut trainer = StudentTrainer::new(
        StudentConfig {
            adam: lhm_nets::AdamConfig {
                lr: args.lr,
                ..StudentConfig::default().adam
            },
            epochs: args.epochs,
            ..StudentConfig::default()
        },
        &learner.actor_critic,
    )?;
    let template = planner_template(&args, &setup.model, act_dim)?;
    let mut rng = SplitMix64::new(args.seed);
    let tasks = setup.bench.tasks(Split::Train);
    for stand in [false, true] {
        println!(
            "base alone, {} starts: {}",
            if stand { "standing" } else { "gait" },
            evaluate(&setup, None, &args, stand)?
        );
    }
    for round in 0..args.rounds {
        let clock = Instant::now();
        let beta = args.beta.powi(round as i32);
        let specs: Vec<EpisodeSpec> = (0..args.episodes)
            .map(|_| EpisodeSpec {
                task: &tasks[rng.below(tasks.len())],
                stand: rng.next_f64() < args.stand_start,
                cycle_step: rng.below(setup.reference.len()),
                planner_seed: rng.next_u64(),
                mix_seed: rng.next_u64(),
            })
            .collect();
        let episodes = in_parallel(&specs, args.parallel, |spec| {
            collect_episode(&setup, spec, &template, &learner, &args, beta)
        })?;
        let (mut obs_rows, mut label_rows) = (Vec::new(), Vec::new());
        let mut collected = Score::default();
        for e in episodes {
            obs_rows.extend_from_slice(&e.obs);
            label_rows.extend_from_slice(&e.labels);
            collected.add(e.reached, e.up, args.episode_steps);
        }
        let rows = label_rows.len() / act_dim;
        if rows == 0 {
            bail!("round {round} collected no rows");
        }
        data.append(&obs_rows, &label_rows)?;
        let stats = trainer.train_round(&mut learner.actor_critic, &data, rows, &mut rng)?;
        let gait_score = evaluate(&setup, Some(&learner), &args, false)?;
        let stand_score = evaluate(&setup, Some(&learner), &args, true)?;
        learner.save_policy(&args.out.join("policy"))?;
        setup.train.write_run_config(&args.out)?;
        println!(
            "round {round} (β {beta:.3}, {:.0} s): collected {rows} rows ({collected}); dataset {} rows; \
             loss {:.4} -> {:.4}; student from gait starts: {gait_score}; from standing: {stand_score}",
            clock.elapsed().as_secs_f64(),
            data.len(),
            stats.loss_before,
            stats.loss_after,
        );
    }
    Ok(())
}
