//! `lhm record TASK_ID --policy CKPT -o episode.mcap`: one episode of a trained policy in a
//! benchmark room, written as an MCAP file that opens in Foxglove (scene, transforms, the raw
//! `lhm.v1.EpisodeFrames`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::ProgressBar;
use lhm_learner::Learner;
use lhm_nets::SplitMix64;
use lhm_protos::{EpisodeStats, Role};
use lhm_record::capture::{EpisodeCapture, EpisodeSource};
use lhm_record::{record_episode, EpisodeScene};
use lhm_sim::env::TaskEnv;
use lhm_sim::CharacterModel;

#[derive(Args)]
pub struct RecordArgs {
    /// Benchmark task id (e.g. train-0002, or train-0002.p1 for its first pair alone).
    task: String,
    /// Learner checkpoint: `runs/<run>/checkpoint` (with or without .json / .safetensors).
    #[arg(long)]
    policy: PathBuf,
    /// The run's training config (default: the `config.toml` beside the checkpoint, else the
    /// built-in default).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Sample actions instead of taking the policy's mean.
    #[arg(long)]
    stochastic: bool,
    /// Seed of the sampled actions (with --stochastic).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output MCAP file.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    scenes: crate::scenes_cmd::Source,
}

/// A learner checkpoint's stem, given with or without its `.json` / `.safetensors` extension.
pub(crate) fn checkpoint_stem(path: &Path) -> PathBuf {
    lhm_nets::checkpoint::stem_of(path)
}

pub fn run(args: RecordArgs) -> Result<()> {
    let bench = args.scenes.load()?;
    let config = crate::render_cmd::train_config_for(Some(&args.policy), args.config.as_deref())?;
    let stem = checkpoint_stem(&args.policy);
    let learner = Learner::load(&stem, None)
        .with_context(|| format!("loading the policy {}", stem.display()))?;
    let (_, task) = bench
        .task(&args.task)
        .with_context(|| format!("no task {:?} (see `lhm scenes stats`)", args.task))?;
    let model = CharacterModel::amp_humanoid();
    let mut env = TaskEnv::new(
        &model,
        &task,
        &bench.catalogue,
        config.sim.clone(),
        config.env.clone(),
    );
    let ac = &learner.actor_critic;
    if ac.obs_dim() != TaskEnv::obs_dim(&model, &config.env) || ac.act_dim() != model.dofs.len() {
        bail!(
            "{} takes {} observations and gives {} actions; this environment has {} and {} \
             (pass the run's --config)",
            stem.display(),
            ac.obs_dim(),
            ac.act_dim(),
            TaskEnv::obs_dim(&model, &config.env),
            model.dofs.len()
        );
    }
    let mut capture = EpisodeCapture::new(
        &env,
        EpisodeSource {
            run_id: "record".into(),
            actor_id: "lhm-record".into(),
            role: Role::Teacher1,
            policy_version: learner.counters.iteration,
        },
    );
    let mut rng = SplitMix64::new(args.seed);
    let bar = ProgressBar::new(u64::from(config.env.max_episode_steps));
    let (mut ret, mut len) = (0f32, 0u32);
    let last = loop {
        let obs = lhm_actor::rollout::policy_observation(ac, &env, true);
        let action = if args.stochastic {
            ac.act(&obs, &mut rng)?.actions
        } else {
            ac.act_deterministic(&obs)?
        };
        let r = env.step(&action);
        capture.push(&env);
        ret += r.reward;
        len += 1;
        bar.inc(1);
        if r.done || r.truncated {
            break r;
        }
    };
    bar.finish_and_clear();
    let errors = env.placement_errors();
    let stats = EpisodeStats {
        episode_return: ret,
        length: len,
        cycles_attempted: errors.len() as u32,
        cycles_succeeded: env.cycles.results.iter().filter(|r| r.success).count() as u32,
        final_placement_error_m: errors,
        fell: last.fell,
        physics_invalid: last.physics_invalid,
        task_id: task.id.clone(),
        reached: env.reached,
        demo_start: false,
        reward_terms: Default::default(),
    };
    let frames = capture.finish(stats.clone());
    record_episode(
        &args.output,
        &frames,
        &EpisodeScene::new(&model, &task, &bench.catalogue),
    )?;
    println!(
        "{}: {} steps, return {:.2}, {}/{} pairs placed{} → {}",
        task.id,
        len,
        ret,
        stats.cycles_succeeded,
        stats.cycles_attempted,
        if stats.fell { ", fell" } else { "" },
        args.output.display()
    );
    Ok(())
}

#[derive(Args)]
pub struct RecoverArgs {
    /// The damaged recording (e.g. runs/teacher1/run.mcap after a SIGKILL); only read.
    input: PathBuf,
    /// Where to write the recovered file (must differ from the input).
    #[arg(short, long)]
    output: PathBuf,
}

pub fn recover(a: RecoverArgs) -> Result<()> {
    let r = lhm_record::recover::recover(&a.input, &a.output)?;
    println!(
        "{}: {} messages on {} channels, {} metadata records, {} attachments{}",
        a.output.display(),
        r.messages,
        r.channels,
        r.metadata,
        r.attachments,
        match (&r.stopped_by, r.complete) {
            (_, true) => " (the input was whole)".to_owned(),
            (Some(why), false) => format!(" (the input stops there: {why})"),
            (None, false) => " (the input has no data-end record)".to_owned(),
        }
    );
    Ok(())
}
