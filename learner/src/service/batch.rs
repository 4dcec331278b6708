//! Accepted chunks → one PPO batch: style rewards from the discriminator (AMP), GAE per chunk
//! (each chunk is one environment's contiguous run, so it is its own [T, 1] rollout with its own
//! bootstrap value), then everything concatenated.

use lhm_protos::TrajectoryChunk;

use crate::amp::AmpTrainer;
use crate::error::LearnerResult;
use crate::gae::{compute_gae, GaeInput, GaeParams};
use crate::ppo::PpoBatch;

/// Episode outcomes seen in a batch.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct EpisodeSummary {
    pub episodes: u64,
    pub mean_return: f64,
    pub mean_length: f64,
    /// Succeeded / attempted (object, goal) pairs.
    pub success_rate: f64,
    pub falls: u64,
    /// Episodes whose root came within the reach distance of the current object, and how many
    /// of all episodes started from the task's own start (not a demo frame) did.
    pub reached: u64,
    pub task_start_episodes: u64,
    pub task_start_reached: u64,
    /// Falls among the episodes from task starts (demo starts mid-stride fall more often).
    pub task_start_falls: u64,
    pub mean_task_reward: f64,
    pub mean_style_reward: f64,
    /// Per task-reward term, its weighted mean per step over the finished episodes.
    pub reward_terms: std::collections::BTreeMap<String, f64>,
}

impl EpisodeSummary {
    /// Falls per finished episode (NaN with no episodes).
    pub fn fall_fraction(&self) -> f64 {
        self.falls as f64 / self.episodes as f64
    }

    /// Falls per finished episode from a task start (NaN with none).
    pub fn task_start_fall_fraction(&self) -> f64 {
        self.task_start_falls as f64 / self.task_start_episodes as f64
    }

    /// Reach rate over episodes from task starts (NaN with none).
    pub fn reach_rate(&self) -> f64 {
        self.task_start_reached as f64 / self.task_start_episodes as f64
    }

    /// Reach rate over every finished episode, whatever its start (NaN with none).
    pub fn reach_rate_all(&self) -> f64 {
        self.reached as f64 / self.episodes as f64
    }
}

pub struct Assembled {
    pub batch: PpoBatch,
    /// Agent AMP features, rows of the discriminator's width (empty without AMP).
    pub amp_features: Vec<f32>,
    pub summary: EpisodeSummary,
}

/// Episode outcomes and the mean task reward per step of `chunks` (style reward left 0).
pub fn episode_summary(chunks: &[TrajectoryChunk]) -> EpisodeSummary {
    let mut summary = EpisodeSummary::default();
    let (mut attempted, mut succeeded) = (0u64, 0u64);
    let (mut task_sum, mut steps) = (0f64, 0u64);
    let mut episode_steps = 0u64;
    for c in chunks {
        task_sum += c.rewards.iter().map(|&x| x as f64).sum::<f64>();
        steps += c.rewards.len() as u64;
        for e in &c.episodes {
            summary.episodes += 1;
            summary.mean_return += e.episode_return as f64;
            summary.mean_length += e.length as f64;
            attempted += u64::from(e.cycles_attempted);
            succeeded += u64::from(e.cycles_succeeded);
            summary.falls += u64::from(e.fell);
            summary.reached += u64::from(e.reached);
            episode_steps += u64::from(e.length);
            for (name, v) in &e.reward_terms {
                *summary.reward_terms.entry(name.clone()).or_insert(0.0) += f64::from(*v);
            }
            if !e.demo_start {
                summary.task_start_episodes += 1;
                summary.task_start_reached += u64::from(e.reached);
                summary.task_start_falls += u64::from(e.fell);
            }
        }
    }
    if episode_steps > 0 {
        for v in summary.reward_terms.values_mut() {
            *v /= episode_steps as f64;
        }
    }
    if summary.episodes > 0 {
        summary.mean_return /= summary.episodes as f64;
        summary.mean_length /= summary.episodes as f64;
    }
    summary.success_rate = if attempted > 0 {
        succeeded as f64 / attempted as f64
    } else {
        f64::NAN
    };
    if steps > 0 {
        summary.mean_task_reward = task_sum / steps as f64;
    }
    summary
}

pub fn assemble(
    chunks: &[TrajectoryChunk],
    amp: Option<&AmpTrainer>,
    gae: GaeParams,
) -> LearnerResult<Assembled> {
    let mut batch = PpoBatch::default();
    let mut amp_features = Vec::new();
    let mut summary = episode_summary(chunks);
    let (mut style_sum, mut steps) = (0f64, 0u64);
    for c in chunks {
        let rewards = match amp {
            Some(amp) if c.amp_dim > 0 => {
                let style = amp.style_rewards(&c.amp_features)?;
                style_sum += style.iter().map(|&x| x as f64).sum::<f64>();
                amp_features.extend_from_slice(&c.amp_features);
                amp.combine_rewards(&c.rewards, &style)?
            }
            _ => c.rewards.clone(),
        };
        steps += c.rewards.len() as u64;
        let out = compute_gae(
            &GaeInput {
                steps: c.num_steps as usize,
                envs: 1,
                rewards: &rewards,
                values: &c.values,
                dones: &c.dones,
                truncated: &c.truncated,
                truncation_values: &c.truncation_values,
                last_values: &[c.bootstrap_value],
            },
            gae,
        )?;
        batch.obs.extend_from_slice(&c.observations);
        batch.actions.extend_from_slice(&c.actions);
        batch.old_log_probs.extend_from_slice(&c.log_probs);
        batch.old_values.extend_from_slice(&c.values);
        batch.advantages.extend(out.advantages);
        batch.returns.extend(out.returns);
    }
    if steps > 0 {
        summary.mean_style_reward = style_sum / steps as f64;
    }
    Ok(Assembled {
        batch,
        amp_features,
        summary,
    })
}
