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
    /// Mean style reward per step the discriminator judged (see `[amp] discriminate_stand`).
    pub mean_style_reward: f64,
    /// Standard deviations per step over the batch: the style reward over the judged steps, and
    /// the task reward over the steps with AMP features (how much of the reward's step-to-step
    /// variation the discriminator makes). NaN without AMP.
    pub style_reward_std: f64,
    pub task_reward_std: f64,
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
    let mut summary = EpisodeSummary {
        style_reward_std: f64::NAN,
        task_reward_std: f64::NAN,
        ..EpisodeSummary::default()
    };
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

/// Which of the gait's steps stay out of the discriminator: the stand after its stop
/// (`[amp] discriminate_stand = false`) and its walk-off from rest (`discriminate_ramp = false`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Skip {
    stand: bool,
    ramp: bool,
}

impl Skip {
    fn of(amp: &AmpTrainer) -> Self {
        Self {
            stand: !amp.config.discriminate_stand,
            ramp: !amp.config.discriminate_ramp,
        }
    }

    fn any(self) -> bool {
        self.stand || self.ramp
    }
}

/// Whether step `t` of `chunk` goes to the discriminator: every step, unless `skip` leaves out
/// the gait's stand and the chunk says it had stopped by then, or its walk-off from rest and the
/// chunk says it ramped then.
fn judged(chunk: &TrajectoryChunk, t: usize, skip: Skip) -> bool {
    let flag = |flags: &[bool]| flags.get(t).copied().unwrap_or(false);
    let left_out =
        (skip.stand && flag(&chunk.gait_stopped)) || (skip.ramp && flag(&chunk.gait_ramping));
    !left_out
}

/// The style rewards of a batch's chunks.
#[derive(Debug)]
struct ChunkStyles {
    /// Per chunk, its style reward per step (`None` for chunks without AMP features).
    per_chunk: Vec<Option<Vec<f32>>>,
    /// Sum and count over the steps the discriminator judged.
    judged_sum: f64,
    judged_steps: u64,
    /// See [`EpisodeSummary::style_reward_std`] and the one after it.
    style_std: f64,
    task_std: f64,
}

impl Default for ChunkStyles {
    fn default() -> Self {
        Self {
            per_chunk: Vec::new(),
            judged_sum: 0.0,
            judged_steps: 0,
            style_std: f64::NAN,
            task_std: f64::NAN,
        }
    }
}

/// Mean and population standard deviation of `xs` (NaN, NaN when empty).
fn mean_std(xs: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let (n, sum) = xs.clone().fold((0u64, 0f64), |(n, s), x| (n + 1, s + x));
    if n == 0 {
        return (f64::NAN, f64::NAN);
    }
    let mean = sum / n as f64;
    let var = xs.map(|x| (x - mean) * (x - mean)).sum::<f64>() / n as f64;
    (mean, var.sqrt())
}

/// Each chunk's style reward per step, with the steps the discriminator does not judge
/// (`skip`) paid the mean style of those it does, so leaving a stand or a walk-off out makes it
/// neither cheaper nor dearer than walking.
fn chunk_styles(
    chunks: &[TrajectoryChunk],
    amp: &AmpTrainer,
    skip: Skip,
) -> LearnerResult<ChunkStyles> {
    let mut styles = Vec::with_capacity(chunks.len());
    let (mut sum, mut count) = (0f64, 0u64);
    for c in chunks {
        if c.amp_dim == 0 {
            styles.push(None);
            continue;
        }
        let style = amp.style_rewards(&c.amp_features)?;
        for (t, &x) in style.iter().enumerate() {
            if judged(c, t, skip) {
                sum += x as f64;
                count += 1;
            }
        }
        styles.push(Some(style));
    }
    let (_, style_std) = mean_std(chunks.iter().zip(&styles).flat_map(|(c, style)| {
        style
            .iter()
            .flatten()
            .enumerate()
            .filter(move |&(t, _)| judged(c, t, skip))
            .map(|(_, &x)| f64::from(x))
    }));
    let (_, task_std) = mean_std(
        chunks
            .iter()
            .filter(|c| c.amp_dim > 0)
            .flat_map(|c| c.rewards.iter().map(|&x| f64::from(x))),
    );
    if skip.any() {
        let fill = if count > 0 {
            (sum / count as f64) as f32
        } else {
            0.0
        };
        for (c, style) in chunks.iter().zip(&mut styles) {
            for (t, x) in style.iter_mut().flatten().enumerate() {
                if !judged(c, t, skip) {
                    *x = fill;
                }
            }
        }
    }
    Ok(ChunkStyles {
        per_chunk: styles,
        judged_sum: sum,
        judged_steps: count,
        style_std,
        task_std,
    })
}

pub fn assemble(
    chunks: &[TrajectoryChunk],
    amp: Option<&AmpTrainer>,
    gae: GaeParams,
) -> LearnerResult<Assembled> {
    let mut batch = PpoBatch::default();
    let mut amp_features = Vec::new();
    let mut summary = episode_summary(chunks);
    let skip = amp.map(Skip::of).unwrap_or_default();
    let styles = match amp {
        Some(amp) => chunk_styles(chunks, amp, skip)?,
        None => ChunkStyles {
            per_chunk: vec![None; chunks.len()],
            ..ChunkStyles::default()
        },
    };
    for (c, style) in chunks.iter().zip(&styles.per_chunk) {
        let rewards = match (amp, style) {
            (Some(amp), Some(style)) => {
                let dim = c.amp_dim as usize;
                for (t, row) in c.amp_features.chunks_exact(dim).enumerate() {
                    if judged(c, t, skip) {
                        amp_features.extend_from_slice(row);
                    }
                }
                amp.combine_rewards(&c.rewards, style)?
            }
            _ => c.rewards.clone(),
        };
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
    if styles.judged_steps > 0 {
        summary.mean_style_reward = styles.judged_sum / styles.judged_steps as f64;
    }
    summary.style_reward_std = styles.style_std;
    summary.task_reward_std = styles.task_std;
    Ok(Assembled {
        batch,
        amp_features,
        summary,
    })
}

#[cfg(test)]
mod tests {
    use lhm_nets::MlpConfig;
    use lhm_protos::WireMessage;

    use super::*;
    use crate::amp::AmpConfig;

    /// One env's 4 steps of 2 AMP features each, row t = (t, -t) + offset; the gait stops from
    /// step `stop_from` on (`None`: no gait flags).
    fn chunk(offset: f32, stop_from: Option<usize>) -> TrajectoryChunk {
        ramping_chunk(offset, stop_from, 0)
    }

    /// [`chunk`] whose gait walks off from rest in its first `ramp_steps` steps.
    fn ramping_chunk(offset: f32, stop_from: Option<usize>, ramp_steps: usize) -> TrajectoryChunk {
        let n = 4usize;
        TrajectoryChunk {
            run_id: "r".into(),
            actor_id: "a".into(),
            num_steps: n as u32,
            obs_dim: 1,
            act_dim: 1,
            amp_dim: 2,
            observations: vec![0.0; n],
            actions: vec![0.0; n],
            log_probs: vec![0.0; n],
            values: vec![0.0; n],
            rewards: vec![1.0; n],
            dones: vec![false; n],
            truncated: vec![false; n],
            truncation_values: vec![0.0; n],
            amp_features: (0..n)
                .flat_map(|t| [t as f32 + offset, -(t as f32) - offset])
                .collect(),
            gait_stopped: stop_from.map_or(vec![], |s| (0..n).map(|t| t >= s).collect()),
            gait_ramping: if ramp_steps > 0 {
                (0..n).map(|t| t < ramp_steps).collect()
            } else {
                vec![]
            },
            ..TrajectoryChunk::versioned()
        }
    }

    fn trainer(discriminate_stand: bool) -> AmpTrainer {
        judging_trainer(discriminate_stand, true)
    }

    fn judging_trainer(discriminate_stand: bool, discriminate_ramp: bool) -> AmpTrainer {
        let config = AmpConfig {
            disc: MlpConfig::with_hidden(&[8]),
            normalize_features: false,
            discriminate_stand,
            discriminate_ramp,
            ..AmpConfig::default()
        };
        AmpTrainer::new(2, config).unwrap()
    }

    const GAE: GaeParams = GaeParams {
        gamma: 0.9,
        lambda: 0.9,
    };

    #[test]
    fn stopped_steps_stay_out_of_the_discriminator_and_are_paid_the_judged_mean() {
        let chunks = [chunk(0.0, Some(2)), chunk(10.0, None)];
        let amp = trainer(false);
        let out = assemble(&chunks, Some(&amp), GAE).unwrap();
        // Steps 2 and 3 of the first chunk are left out: 6 of 8 rows, in order.
        let judged: Vec<f32> = [0.0f32, 1.0, 10.0, 11.0, 12.0, 13.0]
            .iter()
            .flat_map(|&x| [x, -x])
            .collect();
        assert_eq!(out.amp_features, judged);
        let style = amp.style_rewards(&judged).unwrap();
        let mean = style.iter().sum::<f32>() / style.len() as f32;
        assert!((out.summary.mean_style_reward as f32 - mean).abs() < 1e-5);
        let styles = chunk_styles(&chunks, &amp, Skip::of(&amp)).unwrap();
        assert_eq!(styles.judged_steps, 6);
        let first = styles.per_chunk[0].as_ref().unwrap();
        assert!((first[2] - mean).abs() < 1e-6 && (first[3] - mean).abs() < 1e-6);
        assert_eq!(first[..2], style[..2]);
        assert_eq!(styles.per_chunk[1].as_ref().unwrap()[..], style[2..]);
    }

    #[test]
    fn by_default_every_step_is_judged_whatever_the_gait() {
        let chunks = [chunk(0.0, Some(2)), chunk(10.0, None)];
        let amp = trainer(true);
        let out = assemble(&chunks, Some(&amp), GAE).unwrap();
        let all: Vec<f32> = chunks.iter().flat_map(|c| c.amp_features.clone()).collect();
        assert_eq!(out.amp_features, all);
        let style = amp.style_rewards(&all).unwrap();
        let mean = style.iter().sum::<f32>() / style.len() as f32;
        assert!((out.summary.mean_style_reward as f32 - mean).abs() < 1e-5);
    }

    #[test]
    fn walk_off_steps_stay_out_when_asked_and_are_paid_the_judged_mean() {
        // First chunk: ramps in steps 0-1, stops from step 3; second: no gait flags.
        let chunks = [ramping_chunk(0.0, Some(3), 2), chunk(10.0, None)];
        let amp = judging_trainer(false, false);
        let out = assemble(&chunks, Some(&amp), GAE).unwrap();
        // Only step 2 of the first chunk is judged, then the whole second chunk.
        let judged: Vec<f32> = [2.0f32, 10.0, 11.0, 12.0, 13.0]
            .iter()
            .flat_map(|&x| [x, -x])
            .collect();
        assert_eq!(out.amp_features, judged);
        let style = amp.style_rewards(&judged).unwrap();
        let mean = style.iter().sum::<f32>() / style.len() as f32;
        let styles = chunk_styles(&chunks, &amp, Skip::of(&amp)).unwrap();
        assert_eq!(styles.judged_steps, 5);
        let first = styles.per_chunk[0].as_ref().unwrap();
        for t in [0, 1, 3] {
            assert!(
                (first[t] - mean).abs() < 1e-6,
                "step {t}: {} vs {mean}",
                first[t]
            );
        }
        assert_eq!(first[2], style[0]);
        // The walk-off judged as before when only the stand is left out.
        let stand_only = judging_trainer(false, true);
        let out = assemble(&chunks, Some(&stand_only), GAE).unwrap();
        assert_eq!(out.amp_features.len(), (3 + 4) * 2);
        assert_eq!(out.amp_features[..6], chunks[0].amp_features[..6]);
    }
    #[test]
    fn the_batch_reports_the_spread_of_its_style_and_task_rewards() {
        // Task rewards 0, 1, 2, 3 in each chunk: population std √1.25 over the 8 steps.
        let mut chunks = [chunk(0.0, Some(3)), chunk(10.0, None)];
        for c in &mut chunks {
            c.rewards = vec![0.0, 1.0, 2.0, 3.0];
        }
        let amp = judging_trainer(false, true);
        let out = assemble(&chunks, Some(&amp), GAE).unwrap();
        assert!((out.summary.task_reward_std - 1.25f64.sqrt()).abs() < 1e-9);
        // The style's std over the 7 judged steps (the first chunk's step 3 is its stand).
        let judged: Vec<f32> = [0.0f32, 1.0, 2.0, 10.0, 11.0, 12.0, 13.0]
            .iter()
            .flat_map(|&x| [x, -x])
            .collect();
        let style: Vec<f64> = amp
            .style_rewards(&judged)
            .unwrap()
            .into_iter()
            .map(f64::from)
            .collect();
        let (_, std) = mean_std(style.iter().copied());
        assert!(std > 0.0);
        assert!((out.summary.style_reward_std - std).abs() < 1e-6);
        let plain = assemble(&chunks, None, GAE).unwrap();
        assert!(plain.summary.style_reward_std.is_nan() && plain.summary.task_reward_std.is_nan());
    }
}
