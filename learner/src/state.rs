//! Everything the learner trains, bundled, and its checkpoint: weights, optimiser moments and
//! the AMP replay buffer in the safetensors file; configs, counters, normaliser statistics,
//! optimiser step counts, RNG states and the replay ring position in the JSON metadata. Restoring
//! a checkpoint into a fresh process continues training bit for bit.

use std::path::Path;

use candle_core::{Device, Tensor, Var};
use lhm_nets::checkpoint::{self, CheckpointError, Loaded};
use lhm_nets::{ActorCritic, ActorCriticConfig, Adam, RunningMeanStd, SplitMix64};
use serde::{Deserialize, Serialize};

use crate::amp::{AmpConfig, AmpTrainer, ReplayBuffer};
use crate::error::LearnerResult;
use crate::ppo::{PpoConfig, PpoTrainer};

/// The `kind` recorded in learner checkpoints.
pub const CHECKPOINT_KIND: &str = "lhm-learner";

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AmpSetup {
    /// Width of one discriminator input (N frames of AMP features), set by the simulator.
    pub feature_dim: usize,
    pub config: AmpConfig,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LearnerConfig {
    pub obs_dim: usize,
    pub act_dim: usize,
    pub actor_critic: ActorCriticConfig,
    pub ppo: PpoConfig,
    pub amp: Option<AmpSetup>,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Counters {
    pub iteration: u64,
    pub samples: u64,
}

#[derive(Debug, Clone)]
pub struct Learner {
    pub config: LearnerConfig,
    pub actor_critic: ActorCritic,
    pub ppo: PpoTrainer,
    pub amp: Option<AmpTrainer>,
    pub counters: Counters,
}

#[derive(Debug, Serialize, Deserialize)]
struct AmpMeta {
    adam_step: u64,
    rng: SplitMix64,
    feature_norm: Option<RunningMeanStd>,
    replay_rows: usize,
    replay_head: usize,
    /// The discriminator's learning rate now (differs from the configured one under
    /// `accuracy_target`); absent in older checkpoints, which had a constant rate.
    #[serde(default)]
    lr: Option<f64>,
}

#[derive(Debug, Serialize, Deserialize)]
struct LearnerMeta {
    config: LearnerConfig,
    counters: Counters,
    obs_norm: Option<RunningMeanStd>,
    /// Absent in checkpoints from before value normalisation.
    #[serde(default)]
    value_norm: Option<RunningMeanStd>,
    ppo_adam_step: u64,
    ppo_rng: SplitMix64,
    /// The PPO learning rate now (differs from the configured one under `kl_target`); absent
    /// in older checkpoints, which had a constant rate.
    #[serde(default)]
    ppo_lr: Option<f64>,
    /// Whether the weights file holds the PPO Adam moments: a full checkpoint does, a policy file
    /// (what actors and users load) does not; absent in older files, which always held them.
    #[serde(default = "holds_moments")]
    ppo_moments: bool,
    amp: Option<AmpMeta>,
}

fn holds_moments() -> bool {
    true
}

const REPLAY_TENSOR: &str = "amp.replay.features";

fn moment_tensors(
    prefix: &str,
    vars: &[(String, Var)],
    adam: &Adam,
) -> LearnerResult<Vec<(String, Tensor)>> {
    let mut out = Vec::with_capacity(2 * vars.len());
    for (((name, var), m), v) in vars
        .iter()
        .zip(adam.first_moments())
        .zip(adam.second_moments())
    {
        out.push((
            format!("{prefix}.m.{name}"),
            Tensor::from_slice(m, var.shape(), &Device::Cpu)?,
        ));
        out.push((
            format!("{prefix}.v.{name}"),
            Tensor::from_slice(v, var.shape(), &Device::Cpu)?,
        ));
    }
    Ok(out)
}

fn restore_adam<T>(
    loaded: &Loaded<T>,
    prefix: &str,
    vars: &[(String, Var)],
    adam: &mut Adam,
    step: u64,
) -> LearnerResult<()> {
    let mut m = Vec::with_capacity(vars.len());
    let mut v = Vec::with_capacity(vars.len());
    for (name, var) in vars {
        m.push(loaded.f32_values(&format!("{prefix}.m.{name}"), var.dims())?);
        v.push(loaded.f32_values(&format!("{prefix}.v.{name}"), var.dims())?);
    }
    adam.restore(step, m, v)?;
    Ok(())
}

impl Learner {
    pub fn new(config: LearnerConfig) -> LearnerResult<Self> {
        let actor_critic = ActorCritic::new(config.obs_dim, config.act_dim, &config.actor_critic)?;
        let ppo = PpoTrainer::new(config.ppo.clone(), &actor_critic)?;
        let amp = match &config.amp {
            Some(setup) => Some(AmpTrainer::new(setup.feature_dim, setup.config.clone())?),
            None => None,
        };
        Ok(Self {
            config,
            actor_critic,
            ppo,
            amp,
            counters: Counters::default(),
        })
    }

    /// The actor-critic's parameters under their checkpoint names.
    fn policy_tensors(&self) -> Vec<(String, Tensor)> {
        self.actor_critic
            .named_vars()
            .iter()
            .map(|(n, v)| (n.clone(), v.as_tensor().clone()))
            .collect()
    }

    /// Every tensor of the state under its checkpoint name: `policy.*`, `value.*`, `disc.*`,
    /// `optim.ppo.{m,v}.<param>`, `optim.amp.{m,v}.<param>`, `amp.replay.features`.
    pub fn named_tensors(&self) -> LearnerResult<Vec<(String, Tensor)>> {
        let mut tensors = self.policy_tensors();
        tensors.extend(moment_tensors(
            "optim.ppo",
            &self.actor_critic.named_vars(),
            &self.ppo.adam,
        )?);
        if let Some(amp) = &self.amp {
            let disc_vars = amp.disc.named_vars("disc");
            tensors.extend(
                disc_vars
                    .iter()
                    .map(|(n, v)| (n.clone(), v.as_tensor().clone())),
            );
            tensors.extend(moment_tensors("optim.amp", &disc_vars, &amp.adam)?);
            if !amp.replay.is_empty() {
                let rows = amp.replay.len();
                tensors.push((
                    REPLAY_TENSOR.to_owned(),
                    Tensor::from_slice(amp.replay.rows(), (rows, amp.feature_dim()), &Device::Cpu)?,
                ));
            }
        }
        Ok(tensors)
    }

    fn meta(&self) -> LearnerMeta {
        LearnerMeta {
            config: self.config.clone(),
            counters: self.counters.clone(),
            obs_norm: self.actor_critic.obs_norm.clone(),
            value_norm: self.actor_critic.value_norm.clone(),
            ppo_adam_step: self.ppo.adam.step_count(),
            ppo_rng: self.ppo.rng.clone(),
            ppo_lr: Some(self.ppo.adam.config.lr),
            ppo_moments: true,
            amp: self.amp.as_ref().map(|amp| AmpMeta {
                adam_step: amp.adam.step_count(),
                rng: amp.rng.clone(),
                feature_norm: amp.feature_norm.clone(),
                replay_rows: amp.replay.len(),
                replay_head: amp.replay.head(),
                lr: Some(amp.adam.config.lr),
            }),
        }
    }

    /// Writes `<stem>.safetensors` and `<stem>.json` atomically.
    pub fn save(&self, stem: &Path) -> LearnerResult<()> {
        checkpoint::save(stem, CHECKPOINT_KIND, &self.named_tensors()?, &self.meta())?;
        Ok(())
    }

    /// Writes the policy alone (the actor-critic's weights and normalisers; no optimiser
    /// moments, no discriminator, no replay buffer) to `<stem>.{safetensors,json}`: a third of
    /// the actor-critic's share of a checkpoint, what actors, `lhm record`, `lhm render-rollout`
    /// and `--init-from` load with [`Self::load`], and what can be committed. Training resumes
    /// from the full checkpoint, not from this (a learner loaded from it starts a fresh Adam).
    pub fn save_policy(&self, stem: &Path) -> LearnerResult<()> {
        let tensors = self.policy_tensors();
        let mut meta = self.meta();
        // The noise the policy acts with now: a schedule's stage sets its own fixed log_std on
        // the actor-critic, while the learner's configuration keeps the run's (which a resume
        // compares against).
        meta.config.actor_critic = self.actor_critic.config.clone();
        meta.config.amp = None;
        meta.amp = None;
        meta.ppo_moments = false;
        meta.ppo_adam_step = 0;
        checkpoint::save(stem, CHECKPOINT_KIND, &tensors, &meta)?;
        Ok(())
    }

    /// Rebuilds the learner stored at `stem`. With `expected`, the stored configuration must equal
    /// it (a run resumed with different settings is refused rather than silently changed), except
    /// for the AMP replay buffer's capacity and keep fraction: those are taken from `expected`,
    /// and a smaller capacity keeps the newest rows.
    pub fn load(stem: &Path, expected: Option<&LearnerConfig>) -> LearnerResult<Self> {
        let loaded = checkpoint::load::<LearnerMeta>(stem, CHECKPOINT_KIND)?;
        let meta = &loaded.payload;
        let mismatch = |what: String| CheckpointError::Mismatch {
            path: loaded.paths.meta.clone(),
            what,
        };
        let mut config = meta.config.clone();
        if let Some(expected) = expected {
            let differs = describe_differences(expected, &meta.config);
            if !differs.is_empty() {
                return Err(mismatch(format!(
                    "checkpoint differs from the requested configuration in {}",
                    differs.join(", ")
                ))
                .into());
            }
            // The replay buffer's size may change on resume (to shrink a run's checkpoint):
            // the requested settings apply from here on.
            if let (Some(to), Some(from)) = (&expected.amp, &mut config.amp) {
                let (a, b) = (&to.config, &mut from.config);
                if (a.replay_capacity, a.replay_keep_fraction)
                    != (b.replay_capacity, b.replay_keep_fraction)
                {
                    tracing::info!(
                        "AMP replay buffer resized on resume: capacity {} -> {}, keep fraction {} -> {} (the newest rows kept)",
                        b.replay_capacity,
                        a.replay_capacity,
                        b.replay_keep_fraction,
                        a.replay_keep_fraction
                    );
                    b.replay_capacity = a.replay_capacity;
                    b.replay_keep_fraction = a.replay_keep_fraction;
                }
            }
        }
        let mut learner = Learner::new(config)?;
        learner.counters = meta.counters.clone();

        let ac_vars = learner.actor_critic.named_vars();
        loaded.load_into(&ac_vars)?;
        if meta.ppo_moments {
            restore_adam(
                &loaded,
                "optim.ppo",
                &ac_vars,
                &mut learner.ppo.adam,
                meta.ppo_adam_step,
            )?;
        }
        learner.ppo.rng = meta.ppo_rng.clone();
        if let Some(lr) = meta.ppo_lr {
            learner.ppo.adam.config.lr = lr;
        }
        // A stored normaliser must match the configured one in presence and width.
        let same_shape = |stored: &Option<RunningMeanStd>, built: &Option<RunningMeanStd>| {
            stored.as_ref().map(RunningMeanStd::dim) == built.as_ref().map(RunningMeanStd::dim)
        };
        if !same_shape(&meta.obs_norm, &learner.actor_critic.obs_norm) {
            return Err(
                mismatch("observation normaliser missing or of the wrong width".into()).into(),
            );
        }
        if !same_shape(&meta.value_norm, &learner.actor_critic.value_norm) {
            return Err(mismatch("value normaliser missing or of the wrong width".into()).into());
        }
        learner.actor_critic.obs_norm = meta.obs_norm.clone();
        learner.actor_critic.value_norm = meta.value_norm.clone();

        match (&mut learner.amp, &meta.amp) {
            (None, None) => {}
            (Some(amp), Some(amp_meta)) => {
                let disc_vars = amp.disc.named_vars("disc");
                loaded.load_into(&disc_vars)?;
                restore_adam(
                    &loaded,
                    "optim.amp",
                    &disc_vars,
                    &mut amp.adam,
                    amp_meta.adam_step,
                )?;
                amp.rng = amp_meta.rng.clone();
                if let Some(lr) = amp_meta.lr {
                    amp.adam.config.lr = lr;
                }
                if amp_meta.feature_norm.as_ref().map(RunningMeanStd::dim)
                    != amp.feature_norm.as_ref().map(RunningMeanStd::dim)
                {
                    return Err(mismatch(
                        "AMP feature normaliser missing or of the wrong width".into(),
                    )
                    .into());
                }
                amp.feature_norm = amp_meta.feature_norm.clone();
                let dim = amp.feature_dim();
                let rows = if amp_meta.replay_rows == 0 {
                    Vec::new()
                } else {
                    loaded.f32_values(REPLAY_TENSOR, &[amp_meta.replay_rows, dim])?
                };
                let stored_capacity = meta
                    .config
                    .amp
                    .as_ref()
                    .map_or(amp.config.replay_capacity, |a| a.config.replay_capacity);
                amp.replay =
                    ReplayBuffer::from_parts(dim, stored_capacity, rows, amp_meta.replay_head)
                        .map_err(|e| mismatch(e.to_string()))?
                        .resized(amp.config.replay_capacity);
            }
            _ => {
                return Err(mismatch(
                    "AMP state present in only one of configuration and metadata".into(),
                )
                .into())
            }
        }
        Ok(learner)
    }
}

fn describe_differences(a: &LearnerConfig, b: &LearnerConfig) -> Vec<String> {
    let mut out = Vec::new();
    if a.obs_dim != b.obs_dim {
        out.push(format!(
            "obs_dim (requested {}, stored {})",
            a.obs_dim, b.obs_dim
        ));
    }
    if a.act_dim != b.act_dim {
        out.push(format!(
            "act_dim (requested {}, stored {})",
            a.act_dim, b.act_dim
        ));
    }
    if a.actor_critic != b.actor_critic {
        out.push("actor_critic".into());
    }
    if a.ppo != b.ppo {
        out.push("ppo".into());
    }
    // The replay buffer's size is not part of what must match (see [`Learner::load`]).
    let without_replay_size = |amp: &Option<AmpSetup>| {
        amp.clone().map(|mut setup| {
            setup.config.replay_capacity = 0;
            setup.config.replay_keep_fraction = 1.0;
            setup
        })
    };
    if without_replay_size(&a.amp) != without_replay_size(&b.amp) {
        out.push("amp".into());
    }
    out
}
