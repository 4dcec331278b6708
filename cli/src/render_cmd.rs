use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use indicatif::ProgressBar;
use lhm_learner::service::{TrainConfig, RUN_CONFIG_FILE};
use lhm_learner::Learner;
use lhm_scenes::raster::Canvas;
use lhm_scenes::rng::SplitMix64;
use lhm_sim::env::TaskEnv;
use lhm_sim::render::{render, write_gif, Camera};
use lhm_sim::CharacterModel;
use std::path::PathBuf;

/// What acts: a built-in policy or a trained checkpoint.
enum Policy {
    /// All actions 0: the servos hold the neutral pose.
    Zero,
    /// Uniform random actions in [-1, 1].
    Random,
    /// A learner checkpoint's policy (its mean action, or samples with --stochastic).
    Trained(Box<Learner>),
}

#[derive(Clone, Copy, ValueEnum)]
enum View {
    /// Behind the character, walls cut away.
    Third,
    /// From the character's eyes.
    Ego,
}

#[derive(Args)]
pub struct RenderRolloutArgs {
    /// Benchmark task id (e.g. unseen-0003, or train-0002.p1 for its first pair alone).
    task: String,
    /// `zero` (the neutral pose), `random` (uniform actions in [-1, 1]) or a learner checkpoint
    /// (`runs/<run>/checkpoint`, with or without .json / .safetensors).
    #[arg(long, default_value = "zero")]
    policy: String,
    /// The run's training config (checkpoints only; default: the `config.toml` beside the
    /// checkpoint, else the built-in default).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Sample the trained policy's actions instead of taking its mean.
    #[arg(long)]
    stochastic: bool,
    /// Keep rendering after the episode ends (a fall or the last handoff), as the physics goes on.
    #[arg(long)]
    past_end: bool,
    /// An animated .gif, or a .png still of the last frame.
    #[arg(short, long, value_name = "GIF|PNG")]
    output: PathBuf,
    #[command(flatten)]
    scenes: crate::scenes_cmd::Source,
    /// Camera: third person or the character's eyes.
    #[arg(long, value_enum, default_value = "third")]
    view: View,
    /// Length of the rollout, seconds.
    #[arg(long, default_value_t = 4.0)]
    seconds: f32,
    /// Frame width in pixels.
    #[arg(long, default_value_t = 320)]
    width: u32,
    /// Frame height in pixels.
    #[arg(long, default_value_t = 240)]
    height: u32,
    /// Seed of the random and stochastic policies.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Start as `lhm eval`'s seed S of this task does (its `episodes.csv` rows): the start heading
    /// turned by the seed, and in a gait run (`[env.gait]`) the cycle step drawn from the seed.
    /// Default: the task as specified, in a gait run at the cycle's first step. The episode
    /// itself replays `lhm eval --batch 1`'s: eval's batched forward pass differs in the last
    /// bits, and a long rollout can drift apart from there.
    #[arg(long, value_name = "S")]
    eval_seed: Option<u64>,
    /// In a run with `[env.gait]`: start at rest, standing still at the task's start turned
    /// toward the first object, as `lhm eval --from-rest` does.
    #[arg(long, conflicts_with = "demo_start")]
    from_rest: bool,
    /// Start from a reference-motion frame instead of the task's start pose, as training's demo
    /// starts do: `CLIP` (an installed clip's name, e.g. walk_forward) at `SECONDS` into it
    /// (default 0.5), turned toward the first object. Walking clips: an OMOMO clip starts without
    /// its box.
    #[arg(long, value_name = "CLIP[@SECONDS]")]
    demo_start: Option<String>,
    /// Where `scripts/install-motions` put the clips (for --demo-start; default: $LHM_MOTION_DIR or
    /// ~/.cache/lhm/motions).
    #[arg(long)]
    motion_dir: Option<std::path::PathBuf>,
    /// Keep the run's training aid (`sim.assist`, at full strength) instead of playing the
    /// policy unassisted as evaluation does.
    #[arg(long)]
    assisted: bool,
}

/// Starts `env` from `spec` (`CLIP[@SECONDS]`) of the installed clips, turned toward the first
/// object; the clip's name, time and the clips there are in the error when it is not found.
fn demo_start(
    env: &mut TaskEnv,
    spec: &str,
    motion_dir: Option<std::path::PathBuf>,
    train: &TrainConfig,
) -> Result<()> {
    let (name, t) = match spec.split_once('@') {
        Some((n, t)) => (
            n,
            t.parse::<f32>()
                .ok()
                .filter(|t| t.is_finite() && *t >= 0.0)
                .with_context(|| {
                    format!("--demo-start {spec:?}: {t:?} is not a time in seconds")
                })?,
        ),
        None => (spec, 0.5),
    };
    let dir = motion_dir.unwrap_or_else(lhm_sim::motion::default_dir);
    let demo = lhm_sim::motion::DemoMotion::load_dir(
        &env.model,
        &dir,
        lhm_sim::motion::AmpWindow::of(&train.env, &train.sim),
    )
    .with_context(|| format!("--demo-start needs the motion clips in {}", dir.display()))?;
    let clips: Vec<(String, f32)> = demo.clips().map(|(n, d)| (n.to_owned(), d)).collect();
    let Some(index) = clips.iter().position(|(n, _)| n == name) else {
        let names: Vec<&str> = clips.iter().map(|(n, _)| n.as_str()).collect();
        bail!(
            "--demo-start: no clip {name:?}; installed: {}",
            names.join(", ")
        );
    };
    let duration = clips[index].1;
    if t > duration {
        bail!("--demo-start: {name} is {duration:.2} s long, not {t} s");
    }
    let yaw = env.yaw_toward_first_object();
    env.start_from_demo_heading(&demo, index, t, yaw);
    Ok(())
}

pub fn run(a: RenderRolloutArgs) -> Result<()> {
    let png = match a.output.extension().and_then(|e| e.to_str()) {
        Some("gif") => false,
        Some("png") => true,
        _ => bail!("--output must end in .gif or .png"),
    };
    let bench = a.scenes.load()?;
    let (_, task) = bench
        .task(&a.task)
        .with_context(|| format!("no task {:?}", a.task))?;
    let task = match a.eval_seed {
        Some(seed) => lhm_actor::eval::seeded_task(&task, seed),
        None => task,
    };
    let model = CharacterModel::amp_humanoid();
    let trained = !matches!(a.policy.as_str(), "zero" | "random");
    let train = train_config_for(
        trained.then(|| std::path::Path::new(a.policy.as_str())),
        a.config.as_deref(),
    )?;
    let train = if a.assisted {
        train
    } else {
        without_training_aids(train)
    };
    let policy = match a.policy.as_str() {
        "zero" => Policy::Zero,
        "random" => Policy::Random,
        path => Policy::Trained(Box::new(load_policy(
            std::path::Path::new(path),
            &train,
            &model,
        )?)),
    };
    let mut env = TaskEnv::new(
        &model,
        &task,
        &bench.catalogue,
        train.sim.clone(),
        train.env.clone(),
    );
    if let Some(spec) = &a.demo_start {
        demo_start(&mut env, spec, a.motion_dir.clone(), &train)?;
    } else if let Some(gait) = &train.env.gait {
        // A run with [env.gait] plays in the gait, as its actors start every episode.
        let dir = a
            .motion_dir
            .clone()
            .unwrap_or_else(lhm_sim::motion::default_dir);
        let demo = lhm_sim::motion::DemoMotion::load_dir(
            &model,
            &dir,
            lhm_sim::motion::AmpWindow::of(&train.env, &train.sim),
        )
        .with_context(|| format!("[env.gait] needs the motion clips in {}", dir.display()))?;
        gait.check(&model).map_err(anyhow::Error::msg)?;
        let reference =
            lhm_sim::gait::reference_for_gait(&model, &demo, gait, 1.0 / train.sim.control_hz)
                .map_err(anyhow::Error::msg)?;
        let yaw = env.yaw_toward_way();
        let step = a.eval_seed.map_or(0, |seed| {
            lhm_actor::eval::gait_start_step(&task.id, seed, reference.len())
        });
        env.start_in_gait_from(
            &demo,
            std::sync::Arc::new(reference),
            step,
            yaw,
            a.from_rest,
        );
    } else if a.from_rest {
        anyhow::bail!("--from-rest starts the gait at rest: the run's config has no [env.gait]");
    }
    let mut rng = SplitMix64::new(a.seed);
    let mut net_rng = lhm_nets::SplitMix64::new(a.seed);
    let steps = (a.seconds * train.sim.control_hz).round() as usize;
    let bar = ProgressBar::new(steps as u64);
    let (width, height, view) = (a.width, a.height, a.view);
    let camera = |w: &lhm_sim::world::World| match view {
        View::Third => Camera::third_person(w, width, height),
        View::Ego => Camera::egocentric(w, width, height),
    };
    let shot = Shot {
        steps,
        // Every other control step: a 15 fps GIF.
        every: 2,
        camera: &camera,
        third_person: matches!(view, View::Third),
        past_end: a.past_end,
    };
    let filmed = film(
        &mut env,
        &shot,
        &mut |env| {
            Ok(match &policy {
                Policy::Zero => vec![0.0; model.dofs.len()],
                Policy::Random => (0..model.dofs.len())
                    .map(|_| rng.range(-1.0, 1.0) as f32)
                    .collect(),
                Policy::Trained(l) => {
                    let obs = lhm_actor::rollout::policy_observation(&l.actor_critic, env, true);
                    if a.stochastic {
                        l.actor_critic.act(&obs, &mut net_rng)?.actions
                    } else {
                        l.actor_critic.act_deterministic(&obs)?
                    }
                }
            })
        },
        &mut || bar.inc(1),
    )?;
    if let Some(end) = &filmed.end {
        println!("{end}");
    }
    let mut frames = filmed.frames;
    bar.finish_and_clear();
    let file = std::fs::File::create(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let out = std::io::BufWriter::new(file);
    if png {
        let last = frames.pop().context("no frame rendered")?;
        let canvas = Canvas {
            width: last.width,
            height: last.height,
            pixels: last.rgb,
        };
        canvas.write_png(out)?;
        frames = vec![];
    } else {
        write_gif(&frames, 7, out)?;
    }
    println!(
        "wrote {} ({} frames, {}x{})",
        a.output.display(),
        frames.len().max(1),
        a.width,
        a.height
    );
    Ok(())
}

/// What [`film`] shot: the frames, and how the episode ended (if it did).
pub(crate) struct Filmed {
    pub frames: Vec<lhm_sim::render::Image>,
    pub end: Option<String>,
}

type Act<'a> = dyn FnMut(&TaskEnv) -> Result<Vec<f32>> + 'a;

/// How [`film`] shoots: up to `steps` control steps, one frame every `every` steps through
/// `camera`, walls cut away for a `third_person` view, on after the episode's end if `past_end`.
pub(crate) struct Shot<'a> {
    pub steps: usize,
    pub every: usize,
    pub camera: &'a dyn Fn(&lhm_sim::world::World) -> Camera,
    pub third_person: bool,
    pub past_end: bool,
}

/// Steps `env` with `act` as `shot` says, rendering its frames.
pub(crate) fn film(
    env: &mut TaskEnv,
    shot: &Shot<'_>,
    act: &mut Act<'_>,
    on_step: &mut dyn FnMut(),
) -> Result<Filmed> {
    let Shot {
        steps,
        every,
        camera,
        third_person,
        past_end,
    } = *shot;
    let mut frames = Vec::new();
    let mut end = None;
    for step in 0..steps {
        let action = act(env)?;
        if step % every.max(1) == 0 {
            frames.push(render(&env.world, &camera(&env.world), third_person));
        }
        let r = env.step(&action);
        if r.physics_invalid {
            tracing::warn!("physics guard tripped at step {step}; stopping the rollout");
            break;
        }
        if (r.done || r.truncated) && end.is_none() {
            let hz = env.world.config.control_hz;
            end = Some(format!(
                "episode ended at step {} ({:.2} s): fell {}, reached the object {}, pairs succeeded {}",
                step + 1,
                (step + 1) as f32 / hz,
                r.fell,
                env.reached,
                env.cycles.results.iter().filter(|c| c.success).count()
            ));
            if !past_end {
                break;
            }
        }
        on_step();
    }
    Ok(Filmed { frames, end })
}

/// The configuration a checkpoint was trained with: `explicit` (`--config`) if given, else the
/// `config.toml` its learner wrote beside it, else the built-in default (runs from before that
/// file existed). Its `env` is the one in force at the checkpoint's iteration: a run with
/// `[[stages]]` (the built-in schedule before its last stage, a curriculum on the gait's angle
/// offsets) trained that checkpoint under its stage's `[env]`, not the run's own.
pub(crate) fn train_config_for(
    policy: Option<&std::path::Path>,
    explicit: Option<&std::path::Path>,
) -> Result<TrainConfig> {
    let mut config = run_config_for(policy, explicit)?;
    if let Some(path) = policy.filter(|_| !config.stages.is_empty()) {
        let stem = crate::record_cmd::checkpoint_stem(path);
        // The policy file is a few MB; reading it twice (here and in `load_policy`) keeps every
        // caller's order (configuration first, then the policy that must fit it) as it is.
        let iteration = Learner::load(&stem, None)
            .with_context(|| format!("loading the policy {}", stem.display()))?
            .counters
            .iteration;
        let stage = config.stage_at(iteration)?;
        match stage.index {
            Some(i) => tracing::info!(
                "{} was saved at iteration {iteration}, under stages[{i}]: playing in that \
                 stage's [env]",
                stem.display()
            ),
            None => tracing::info!(
                "{} was saved at iteration {iteration}, past the run's stages: playing in the \
                 run's own [env]",
                stem.display()
            ),
        }
        config.env = stage.spec.env;
    }
    Ok(config)
}

/// The run's configuration as written, before a stage is chosen (see [`train_config_for`]).
fn run_config_for(
    policy: Option<&std::path::Path>,
    explicit: Option<&std::path::Path>,
) -> Result<TrainConfig> {
    if let Some(path) = explicit {
        return Ok(TrainConfig::from_toml_file(path)?);
    }
    let beside = policy
        .map(crate::record_cmd::checkpoint_stem)
        .and_then(|stem| stem.parent().map(|d| d.join(RUN_CONFIG_FILE)))
        .filter(|p| p.is_file());
    match beside {
        Some(path) => {
            tracing::info!("using the run's configuration {}", path.display());
            Ok(TrainConfig::from_toml_file(&path)?)
        }
        None => Ok(TrainConfig::default()),
    }
}

/// `train` without the upright assist and without `[env.gait] stand_seconds`' early end: a
/// trained policy is judged, and shown, on its own and to the time limit.
pub(crate) fn without_training_aids(mut train: TrainConfig) -> TrainConfig {
    if train.sim.assist.is_active() {
        tracing::info!("the run trained with sim.assist; playing without it");
        train.sim.assist = Default::default();
    }
    if let Some(g) = train.env.gait.as_ref().filter(|g| g.stand_seconds > 0.0) {
        tracing::info!(
            "the run's episodes ended {} s after the stop; playing on",
            g.stand_seconds
        );
    }
    train.env.gait = train
        .env
        .gait
        .map(lhm_sim::env::GaitConfig::played_to_the_limit);
    train
}

/// A learner checkpoint (`runs/<run>/checkpoint` or `policy`, with or without its extension) whose
/// policy fits `train`'s environment for `model`.
pub(crate) fn load_policy(
    path: &std::path::Path,
    train: &TrainConfig,
    model: &CharacterModel,
) -> Result<Learner> {
    let stem = crate::record_cmd::checkpoint_stem(path);
    let learner = Learner::load(&stem, None)
        .with_context(|| format!("loading the policy {}", stem.display()))?;
    let (obs, act) = (
        learner.actor_critic.obs_dim(),
        learner.actor_critic.act_dim(),
    );
    // A VLA policy reads its own rows; every other policy the state observation.
    let want = match learner.actor_critic.policy.encoder() {
        Some(e) => {
            let proprio = lhm_sim::obs::proprioception_dim(model);
            if e.config().proprio_dim != proprio {
                bail!(
                    "{}: its VLA encoder reads {} proprioception values, this character gives \
                     {proprio}",
                    stem.display(),
                    e.config().proprio_dim
                );
            }
            e.obs_dim()
        }
        None => TaskEnv::obs_dim(model, &train.env),
    };
    if obs != want || act != model.dofs.len() {
        bail!(
            "{} takes {obs} observations and gives {act} actions; this environment has \
             {want} and {} (pass the run's --config)",
            stem.display(),
            model.dofs.len()
        );
    }
    Ok(learner)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run whose `[env.gait]` changes by stage, as a curriculum on the gait does.
    const STAGED: &str = r#"
[env.gait]
rest_start_fraction = 0.5

[[stages]]
until_iteration = 100
[stages.env.gait]
rest_start_fraction = 1.0

[[stages]]
until_iteration = 200
[stages.env.gait]
rest_start_fraction = 0.25
"#;

    fn rest_start_fraction(config: &TrainConfig) -> f32 {
        config
            .env
            .gait
            .as_ref()
            .expect("[env.gait]")
            .rest_start_fraction
    }

    #[test]
    fn a_checkpoint_is_played_under_the_stage_in_force_at_its_iteration() {
        let dir = std::env::temp_dir().join(format!("lhm-render-stage-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let written = dir.join("written.toml");
        std::fs::write(&written, STAGED).unwrap();
        let config = TrainConfig::from_toml_file(&written).unwrap();
        config.write_run_config(&dir).unwrap();
        let mut learner = Learner::new(config.learner_config()).unwrap();
        let policy = dir.join("policy");
        for (iteration, want) in [(0, 1.0), (99, 1.0), (100, 0.25), (250, 0.5)] {
            learner.counters.iteration = iteration;
            learner.save_policy(&policy).unwrap();
            // Beside the checkpoint, and given with --config: the same stage.
            for explicit in [None, Some(written.as_path())] {
                let got = train_config_for(Some(&policy), explicit).unwrap();
                assert_eq!(rest_start_fraction(&got), want, "iteration {iteration}");
                assert_eq!(got.stages, config.stages);
            }
        }
        // Without a policy there is no iteration: the run's own [env].
        let own = train_config_for(None, Some(&written)).unwrap();
        assert_eq!(rest_start_fraction(&own), 0.5);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
