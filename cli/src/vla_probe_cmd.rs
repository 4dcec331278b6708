//! `lhm vla-probe`: how closely a VLA policy reproduces the policy it was distilled from along its
//! own rollouts, with and without the instructions, per split (the work is
//! `lhm_actor::agreement`).

use anyhow::{bail, Context, Result};
use clap::Args;
use lhm_actor::agreement::vla_agreement;
use lhm_actor::eval::EvalSetup;
use lhm_sim::CharacterModel;
use std::path::PathBuf;

#[derive(Args)]
pub struct VlaProbeArgs {
    /// The VLA checkpoint (`runs/<pipeline>/vla/policy`).
    #[arg(long)]
    policy: PathBuf,
    /// The policy it was distilled from (the unified student, or a baseline's one policy), read
    /// with the configuration beside it.
    #[arg(long)]
    labeller: PathBuf,
    /// Splits to probe, comma-separated (`train`, `unseen`, `ext3`..`ext5`).
    #[arg(long, default_value = "train,unseen", value_delimiter = ',')]
    splits: Vec<String>,
    /// Only the first N tasks of each split.
    #[arg(long, default_value_t = 20)]
    limit: usize,
    /// Control steps probed per episode at most (the episode may end sooner).
    #[arg(long, default_value_t = 300)]
    steps: u32,
    /// Print the figures as JSON (one object per split) instead of a Markdown table.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    scenes: crate::scenes_cmd::Source,
}

pub fn run(a: VlaProbeArgs) -> Result<()> {
    if a.limit == 0 || a.steps == 0 {
        bail!("--limit and --steps must be at least 1");
    }
    let bench = a.scenes.load()?;
    let model = CharacterModel::amp_humanoid();
    let train = crate::render_cmd::without_training_aids(crate::render_cmd::train_config_for(
        Some(&a.policy),
        None,
    )?);
    let vla = crate::render_cmd::load_policy(&a.policy, &train, &model)?;
    if vla.actor_critic.policy.encoder().is_none() {
        bail!(
            "--policy {}: not a VLA policy (it reads the state, not images and words)",
            a.policy.display()
        );
    }
    let labeller_train = crate::render_cmd::train_config_for(Some(&a.labeller), None)?;
    let labeller = crate::render_cmd::load_policy(&a.labeller, &labeller_train, &model)?;
    if labeller.actor_critic.policy.encoder().is_some() {
        bail!(
            "--labeller {}: a VLA policy; the labeller reads the privileged state",
            a.labeller.display()
        );
    }
    // The episodes run in the VLA run's environment, whose state observation the labeller
    // must read (the VLA stage's actors ask its labels on exactly that).
    let want = lhm_sim::env::TaskEnv::obs_dim(&model, &train.env);
    if labeller.actor_critic.obs_dim() != want {
        bail!(
            "--labeller {} reads {} observations; the VLA run's environment gives {want}",
            a.labeller.display(),
            labeller.actor_critic.obs_dim()
        );
    }
    let setup = EvalSetup {
        model: &model,
        catalogue: &bench.catalogue,
        sim: &train.sim,
        env: &train.env,
        batch: 1,
        language: true,
        gait: None,
        max_steps: None,
        action_std: 0.0,
    };
    let mut rows = Vec::new();
    for split in &a.splits {
        let mut tasks = crate::eval_cmd::split_tasks(&bench, split)?;
        tasks.truncate(a.limit);
        let started = std::time::Instant::now();
        let agreement = vla_agreement(
            &vla.actor_critic,
            &labeller.actor_critic,
            &setup,
            &tasks,
            a.steps,
        )
        .with_context(|| format!("probing on {split}"))?;
        eprintln!(
            "{split}: {} episodes, {} steps in {:.0} s",
            agreement.episodes,
            agreement.steps,
            started.elapsed().as_secs_f64()
        );
        rows.push((split.clone(), agreement));
    }
    if a.json {
        let out: Vec<_> = rows
            .iter()
            .map(|(split, g)| {
                serde_json::json!({
                    "split": split,
                    "agreement": g,
                    "explained_language": g.explained_language(),
                    "explained_no_language": g.explained_no_language(),
                })
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "| split | episodes | steps | MSE with language | MSE without | MSE with vs without | \
         labeller variance | explained with | explained without |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for (split, g) in &rows {
        println!(
            "| {split} | {} | {} | {:.3e} | {:.3e} | {:.3e} | {:.3e} | {:.3} | {:.3} |",
            g.episodes,
            g.steps,
            g.mse_language,
            g.mse_no_language,
            g.mse_language_vs_blank,
            g.labeller_variance,
            g.explained_language(),
            g.explained_no_language()
        );
    }
    Ok(())
}
