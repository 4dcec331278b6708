//! `lhm eval`: a policy's deterministic actions on every task of a split, the paper's metrics per
//! cycle, mean ± std over seeds (the work is `lhm_actor::eval`).

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use lhm_actor::eval::{episodes_csv, evaluate, summarize, EvalPolicy, EvalSetup, START_YAW_JITTER};
use lhm_nets::ActorCritic;
use lhm_scenes::{Benchmark, Split, Task};
use lhm_sim::render::{write_gif, Camera};
use lhm_sim::CharacterModel;
use std::path::PathBuf;

#[derive(Args)]
pub struct EvalArgs {
    /// A learner checkpoint (`runs/<run>/checkpoint` or `runs/<run>/policy`), or `zero`: every
    /// action 0 (the neutral pose; in a `[env.gait]` run, the gait alone), the baseline a
    /// trained policy is measured against.
    #[arg(long)]
    pub(crate) policy: PathBuf,
    /// `train` (350 two-object tasks), `unseen` (66), `extension` (3-5 objects), or `ext3`,
    /// `ext4`, `ext5` (the extension tasks with that many objects).
    #[arg(long, default_value = "unseen")]
    pub(crate) split: String,
    /// Seeds per task: seed 0 is the task as specified, later seeds turn the character's start
    /// heading by up to ±0.2 rad. For a run with `[env.gait]` every seed starts turned toward the
    /// first object and only the cycle step differs (seed 0 the first, later ones drawn from the
    /// seed).
    #[arg(long, default_value_t = 3)]
    pub(crate) seeds: u64,
    /// Only each task's first (object, goal) pair (Teacher 1's setting).
    #[arg(long)]
    pub(crate) first_pair: bool,
    /// The paper's "T" rows: this Teacher 1 checkpoint acts on each episode's first cycle and
    /// --policy (Teacher 2) on every later one, switched at the cycle handoff with no reset.
    #[arg(long, conflicts_with = "first_pair")]
    pub(crate) teacher1: Option<PathBuf>,
    /// In a run with `[env.gait]`: this checkpoint acts once the gait's base has stopped at
    /// `stop_distance`, --policy until then (a walking and a stopping policy trained apart,
    /// joined where the base switches from the walk to the stand). Each reads its own
    /// `config.toml`'s network; the environment is --policy's (or --config).
    #[arg(long, conflicts_with = "teacher1")]
    pub(crate) stop_policy: Option<PathBuf>,
    /// Only the first N tasks of the split (a quick look).
    #[arg(long)]
    pub(crate) limit: Option<usize>,
    /// The run's training config (default: the `config.toml` beside the checkpoint, else the
    /// built-in default).
    #[arg(long)]
    pub(crate) config: Option<PathBuf>,
    /// Print the table's keys as JSON (`success_k`, `dist_k`, `success_all`, `fall_rate`, each
    /// with `_std`) instead of the Markdown table.
    #[arg(long)]
    pub(crate) json: bool,
    /// Write `episodes.csv` (one line per task and seed), `table.md` and `table.json` here.
    #[arg(short, long)]
    pub(crate) output: Option<PathBuf>,
    /// Environments stepped in lockstep (one batched forward pass per step).
    #[arg(long, default_value_t = 64)]
    pub(crate) batch: usize,
    /// End every episode after at most N control steps (30 per second): e.g. 300 to measure
    /// how long a walk stays up within 10 s (`mean_steps`). Default: every pair's cycle limit.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) max_steps: Option<u32>,
    /// Add Gaussian noise of this standard deviation to every action (the policy's
    /// `exp(log_std)`, e.g. 0.0302 for log-std -3.5, is what the actors sample in training);
    /// each episode's noise is its own (task, seed) stream. Default 0: the mean actions.
    #[arg(long, default_value_t = 0.0)]
    pub(crate) action_std: f32,
    /// Also write a GIF of each of the first N episodes (mean actions, third person, until the
    /// episode ends; 10 fps) into the --output directory, named `<task>-s<seed>.gif`.
    #[arg(long, default_value_t = 0)]
    pub(crate) gifs: usize,
    /// A VLA policy runs with every instruction blanked (the paper's language ablation); an
    /// error for a state-based policy, which hears no instruction.
    #[arg(long)]
    pub(crate) no_language: bool,
    /// In a run with `[env.gait]`: start every episode at rest, standing still at the task's
    /// start turned toward the first object (`rest_start_fraction`'s start), instead of walking
    /// (at `start_distance` before the object when the config sets it). An error without a gait.
    #[arg(long)]
    pub(crate) from_rest: bool,
    #[command(flatten)]
    pub(crate) scenes: crate::scenes_cmd::Source,
}

/// The training iteration a checkpoint was saved at (`payload.counters.iteration` of
/// `<stem>.json`), to tell an evaluation of this policy from one of an earlier save.
pub(crate) fn policy_iteration(policy: &std::path::Path) -> Option<u64> {
    let stem = lhm_nets::checkpoint::stem_of(policy);
    let text = std::fs::read_to_string(stem.with_extension("json")).ok()?;
    let json: serde_json::Value = serde_json::from_str(&text).ok()?;
    json.pointer("/payload/counters/iteration")?.as_u64()
}

/// Whether `dir/table.json` evaluated exactly these policies (their saved iterations) with these
/// seeds over `tasks` tasks: then it can be reused.
pub(crate) fn table_is_current(
    dir: &std::path::Path,
    policy: &std::path::Path,
    teacher1: Option<&std::path::Path>,
    seeds: u64,
    tasks: Option<usize>,
) -> bool {
    let Some(table) = std::fs::read(dir.join("table.json"))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
    else {
        return false;
    };
    let field = |k: &str| table.get(k).and_then(|v| v.as_u64());
    field("seeds") == Some(seeds)
        && tasks.is_none_or(|n| field("tasks") == Some(n as u64))
        && field("policy_iteration") == policy_iteration(policy)
        && field("teacher1_iteration") == teacher1.and_then(policy_iteration)
        // A joined walk-and-stop evaluation (--stop-policy) is not this policy's table.
        && table.get("stop_policy").is_none_or(|v| v.is_null())
}

/// A policy whose mean action is exactly 0 in every state (its output layer's weights and bias
/// are 0): `--policy zero`.
fn zero_actions(model: &CharacterModel, env: &lhm_sim::env::EnvConfig) -> Result<ActorCritic> {
    let mut network = lhm_nets::ActorCriticConfig::with_hidden(&[8]);
    network.policy.output_init_scale = 0.0;
    ActorCritic::new(
        lhm_sim::env::TaskEnv::obs_dim(model, env),
        model.dofs.len(),
        &network,
    )
    .context("building the zero-action policy")
}

pub(crate) fn split_tasks(bench: &Benchmark, name: &str) -> Result<Vec<Task>> {
    let (split, pairs) = match name {
        "ext3" => (Split::Extension, Some(3)),
        "ext4" => (Split::Extension, Some(4)),
        "ext5" => (Split::Extension, Some(5)),
        other => match Split::parse(other) {
            Some(s) => (s, None),
            None => {
                bail!("--split {other:?}: expected train, unseen, extension, ext3, ext4 or ext5")
            }
        },
    };
    Ok(bench
        .tasks(split)
        .iter()
        .filter(|t| pairs.is_none_or(|n| t.sequence.len() == n))
        .cloned()
        .collect())
}

pub fn run(a: EvalArgs) -> Result<()> {
    if a.seeds == 0 {
        bail!("--seeds must be at least 1");
    }
    if !(a.action_std.is_finite() && a.action_std >= 0.0) {
        bail!(
            "--action-std {}: must be a finite number >= 0",
            a.action_std
        );
    }
    if a.gifs > 0 && a.action_std > 0.0 {
        bail!("--gifs shows the mean actions: run it without --action-std");
    }
    if a.gifs > 0 && a.output.is_none() {
        bail!("--gifs needs --output DIR (where the GIFs go)");
    }
    let bench = a.scenes.load()?;
    let model = CharacterModel::amp_humanoid();
    let zero_policy = a.policy.as_os_str() == "zero";
    let train = crate::render_cmd::without_training_aids(crate::render_cmd::train_config_for(
        (!zero_policy).then_some(a.policy.as_path()),
        a.config.as_deref(),
    )?);
    if zero_policy && a.teacher1.is_some() {
        bail!("--policy zero with --teacher1: the zero action is not a Teacher 2");
    }
    let actor_critic = if zero_policy {
        zero_actions(&model, &train.env)?
    } else {
        crate::render_cmd::load_policy(&a.policy, &train, &model)?.actor_critic
    };
    if a.no_language && actor_critic.policy.encoder().is_none() {
        bail!(
            "--no-language: {} is not a VLA policy (it reads the state, not an instruction)",
            a.policy.display()
        );
    }
    let teacher1 = match &a.teacher1 {
        Some(path) => {
            let t1_config = crate::render_cmd::train_config_for(Some(path), None)?;
            Some(crate::render_cmd::load_policy(path, &t1_config, &model)?)
        }
        None => None,
    };
    let stopper = match &a.stop_policy {
        Some(path) => {
            if train.env.gait.is_none() {
                bail!(
                    "--stop-policy {}: the run has no [env.gait], so its base never stops",
                    path.display()
                );
            }
            let config = crate::render_cmd::train_config_for(Some(path), None)?;
            Some(crate::render_cmd::load_policy(path, &config, &model)?)
        }
        None => None,
    };
    let policy = match (&teacher1, &stopper) {
        (Some(t1), _) => EvalPolicy::Teachers {
            first: &t1.actor_critic,
            later: &actor_critic,
        },
        (None, Some(stop)) => EvalPolicy::Joined {
            walk: &actor_critic,
            stop: &stop.actor_critic,
        },
        (None, None) => EvalPolicy::One(&actor_critic),
    };
    let mut tasks = split_tasks(&bench, &a.split)?;
    if a.first_pair {
        tasks = tasks.iter().filter_map(|t| t.single_pair(0)).collect();
    }
    if let Some(n) = a.limit {
        tasks.truncate(n);
    }
    if tasks.is_empty() {
        bail!("--split {}: no tasks", a.split);
    }
    let jobs: Vec<(Task, u64)> = tasks
        .iter()
        .flat_map(|t| (0..a.seeds).map(move |s| (t.clone(), s)))
        .collect();
    let total = jobs.len();
    let plain = !std::io::IsTerminal::is_terminal(&std::io::stderr());
    let bar = if plain {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(total as u64).with_style(
            ProgressStyle::with_template("eval {bar:30} {pos}/{len} episodes {elapsed}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        )
    };
    let started = std::time::Instant::now();
    // A run with [env.gait] is played in its gait, as its actors played it.
    let gait_clips = match &train.env.gait {
        Some(_) => {
            let dir = lhm_sim::motion::default_dir();
            Some(
                lhm_sim::motion::DemoMotion::load_dir(
                    &model,
                    &dir,
                    lhm_sim::motion::AmpWindow::of(&train.env, &train.sim),
                )
                .with_context(|| {
                    format!("[env.gait] needs the motion clips in {}", dir.display())
                })?,
            )
        }
        None => None,
    };
    let gait = match (&train.env.gait, &gait_clips) {
        (Some(g), Some(demo)) => Some(lhm_actor::eval::GaitStart {
            demo: {
                g.check(&model).map_err(anyhow::Error::msg)?;
                demo
            },
            reference: std::sync::Arc::new(
                lhm_sim::gait::reference_for_gait(&model, demo, g, 1.0 / train.sim.control_hz)
                    .map_err(anyhow::Error::msg)?,
            ),
            rest: a.from_rest,
        }),
        _ if a.from_rest => {
            anyhow::bail!("--from-rest starts the gait at rest: the run's config has no [env.gait]")
        }
        _ => None,
    };
    let setup = EvalSetup {
        model: &model,
        catalogue: &bench.catalogue,
        sim: &train.sim,
        env: &train.env,
        batch: a.batch,
        language: !a.no_language,
        gait,
        max_steps: a.max_steps,
        action_std: a.action_std,
    };
    let episodes = evaluate(policy, &setup, &jobs, &|done| {
        bar.set_position(done as u64);
        if plain {
            eprintln!("eval: {done}/{total} episodes");
        }
    })?;
    bar.finish_and_clear();
    let wall = started.elapsed().as_secs_f64();
    let table = summarize(&episodes);
    let steps: u64 = episodes.iter().map(|e| u64::from(e.steps)).sum();
    let method = match (&a.teacher1, &a.stop_policy) {
        (Some(t1), _) => format!("{} then {} (T)", t1.display(), a.policy.display()),
        (None, Some(stop)) => format!("{} walking, {} stopped", a.policy.display(), stop.display()),
        (None, None) => format!(
            "{}{}",
            a.policy.display(),
            if a.first_pair { " (first pair)" } else { "" }
        ),
    };
    let markdown = table.markdown(&method);
    let mut json = serde_json::json!({
        "split": a.split,
        "tasks": tasks.len(),
        "seeds": a.seeds,
        "max_steps": a.max_steps,
        "action_std": a.action_std,
        "from_rest": a.from_rest,
        "episodes": table.episodes,
        "start_yaw_jitter_rad": START_YAW_JITTER,
        "wall_s": wall,
        "episodes_per_s": table.episodes as f64 / wall,
        "control_steps_per_s": steps as f64 / wall,
        "policy": a.policy.display().to_string(),
        "policy_iteration": policy_iteration(&a.policy),
        "teacher1_iteration": a.teacher1.as_deref().and_then(policy_iteration),
        "stop_policy": a.stop_policy.as_ref().map(|p| p.display().to_string()),
    });
    if let Some(map) = json.as_object_mut() {
        for (k, v) in table.flat() {
            map.insert(k, serde_json::json!(v));
        }
    }
    if let Some(dir) = &a.output {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let write = |name: &str, text: String| {
            let path = dir.join(name);
            std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
        };
        write("episodes.csv", episodes_csv(&episodes))?;
        write("table.md", markdown.clone())?;
        write("table.json", serde_json::to_string_pretty(&json)?)?;
        for (task, seed) in jobs.iter().take(a.gifs) {
            let path = dir.join(format!("{}-s{seed}.gif", task.id));
            let mut env = setup.env_for(task, *seed);
            let steps = env.config.max_episode_steps as usize;
            let camera = |w: &lhm_sim::world::World| Camera::third_person(w, 240, 180);
            let shot = crate::render_cmd::Shot {
                steps,
                every: 3,
                camera: &camera,
                third_person: true,
                past_end: false,
            };
            let filmed = crate::render_cmd::film(
                &mut env,
                &shot,
                &mut |env| {
                    // The same switch as the evaluation: Teacher 1 on the first cycle, the
                    // stopping policy once the base has stopped.
                    let ac = match (&teacher1, &stopper) {
                        (Some(t1), _) if env.cycles.current == 0 => &t1.actor_critic,
                        (None, Some(stop)) if env.gait_stopped() => &stop.actor_critic,
                        _ => &actor_critic,
                    };
                    Ok(
                        ac.act_deterministic(&lhm_actor::rollout::policy_observation(
                            ac,
                            env,
                            !a.no_language,
                        ))?,
                    )
                },
                &mut || {},
            )?;
            let file = std::fs::File::create(&path)
                .with_context(|| format!("creating {}", path.display()))?;
            write_gif(&filmed.frames, 10, std::io::BufWriter::new(file))?;
            eprintln!(
                "wrote {} ({} frames){}",
                path.display(),
                filmed.frames.len(),
                filmed.end.map(|e| format!(": {e}")).unwrap_or_default()
            );
        }
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&json)?);
    } else {
        println!(
            "{} tasks of {} x {} seeds: {} episodes in {wall:.1} s ({:.1} episodes/s)\n",
            tasks.len(),
            a.split,
            a.seeds,
            table.episodes,
            table.episodes as f64 / wall
        );
        print!("{markdown}");
        println!(
            "\nsteps per episode (to a fall, the end, or the cap{}): {:.1} ± {:.1}",
            a.max_steps.map(|m| format!(" of {m}")).unwrap_or_default(),
            table.steps.mean,
            table.steps.std
        );
        println!(
            "episodes whose root came within the reach distance of its object: {:.1} ± {:.1} %",
            100.0 * table.reach_rate.mean,
            100.0 * table.reach_rate.std
        );
    }
    Ok(())
}
