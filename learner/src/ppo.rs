//! PPO (Schulman et al. 2017) update over a batch of collected experience: clipped surrogate,
//! optionally clipped value loss, action-bound loss, entropy bonus, global gradient-norm
//! clipping and Adam, over several epochs of deterministically shuffled minibatches.

use candle_core::{Device, Tensor, Var, D};
use lhm_nets::adam::{clip_global_norm, gradients};
use lhm_nets::{ActorCritic, Adam, AdamConfig, SplitMix64};
use serde::{Deserialize, Serialize};

use crate::error::{check_len, LearnerError, LearnerResult};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PpoConfig {
    pub adam: AdamConfig,
    pub gamma: f32,
    pub lambda: f32,
    pub clip_ratio: f64,
    /// Clip the value prediction to old_value ± this (PPO2 style); `None`: plain squared error.
    /// Absent from a config file means `None` (TOML has no null, so a default of `Some` could not
    /// be switched off).
    #[serde(default)]
    pub value_clip: Option<f64>,
    pub value_coef: f64,
    pub entropy_coef: f64,
    /// Weight of the penalty on action means outside [-action_bound, action_bound].
    pub bound_coef: f64,
    pub action_bound: f64,
    pub max_grad_norm: f64,
    pub epochs: usize,
    pub minibatch_size: usize,
    pub normalize_advantages: bool,
    /// Seed of the minibatch shuffle.
    pub seed: u64,
    /// KL-adaptive learning rate (rl_games' `lr_schedule: adaptive`, `kl_threshold`): after each
    /// epoch, the Adam learning rate is divided by 1.5 when the epoch's mean approx-KL is above
    /// twice this, and multiplied by 1.5 when below half of it, within [1e-6, 1e-2]. `None` or
    /// 0 (`kl_target = 0.0` in a config file, which lays its keys over defaults that may set one):
    /// a constant rate, as IsaacGymEnvs' HumanoidAMP trains.
    #[serde(default)]
    pub kl_target: Option<f64>,
}

impl Default for PpoConfig {
    fn default() -> Self {
        Self {
            adam: AdamConfig {
                lr: 2e-5,
                ..AdamConfig::default()
            },
            gamma: 0.99,
            lambda: 0.95,
            clip_ratio: 0.2,
            value_clip: Some(0.2),
            value_coef: 5.0,
            entropy_coef: 0.0,
            bound_coef: 10.0,
            action_bound: 1.0,
            max_grad_norm: 1.0,
            epochs: 6,
            minibatch_size: 4096,
            normalize_advantages: true,
            seed: 0,
            kl_target: None,
        }
    }
}

/// The learning rate after an epoch whose mean approx-KL was `kl` (rl_games' adaptive rule).
pub fn adapt_lr(lr: f64, kl: f64, target: f64) -> f64 {
    const MIN_LR: f64 = 1e-6;
    const MAX_LR: f64 = 1e-2;
    if kl > 2.0 * target {
        (lr / 1.5).max(MIN_LR)
    } else if kl < 0.5 * target {
        (lr * 1.5).min(MAX_LR)
    } else {
        lr
    }
}

/// Experience for one update, row-major; observations are raw (the trainer normalises them with
/// the actor-critic's normaliser, exactly as the actors did).
#[derive(Debug, Clone, Default)]
pub struct PpoBatch {
    pub obs: Vec<f32>,
    pub actions: Vec<f32>,
    pub old_log_probs: Vec<f32>,
    pub old_values: Vec<f32>,
    pub advantages: Vec<f32>,
    pub returns: Vec<f32>,
}

impl PpoBatch {
    pub fn len(&self) -> usize {
        self.old_log_probs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.old_log_probs.is_empty()
    }
}

/// Means over the minibatches of one update.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct PpoStats {
    pub policy_loss: f64,
    pub value_loss: f64,
    pub bound_loss: f64,
    pub entropy: f64,
    pub total_loss: f64,
    /// Fraction of samples whose probability ratio left [1-ε, 1+ε].
    pub clip_fraction: f64,
    /// E[(r - 1) - ln r], an unbiased, non-negative estimate of KL(old ‖ new).
    pub approx_kl: f64,
    /// Global gradient norm before clipping.
    pub grad_norm: f64,
    pub minibatches: usize,
    /// The learning rate after the update (changes only with `kl_target`).
    pub lr: f64,
}

/// The PPO optimiser state: Adam over the actor-critic's parameters and the shuffle RNG.
#[derive(Debug, Clone)]
pub struct PpoTrainer {
    pub config: PpoConfig,
    pub adam: Adam,
    pub rng: SplitMix64,
}

/// Minibatch tensors for one PPO loss evaluation.
pub struct PpoMinibatch {
    pub obs: Tensor,
    pub actions: Tensor,
    pub old_log_probs: Tensor,
    pub old_values: Tensor,
    pub advantages: Tensor,
    pub returns: Tensor,
}

/// Loss tensors of one minibatch (the scalar `total` is what is differentiated).
pub struct PpoLosses {
    pub total: Tensor,
    pub policy: Tensor,
    pub value: Tensor,
    pub bound: Tensor,
    pub entropy: Tensor,
    pub ratio: Tensor,
}

impl PpoTrainer {
    pub fn new(config: PpoConfig, ac: &ActorCritic) -> LearnerResult<Self> {
        if let Some(t) = config.kl_target {
            if t.is_nan() || t.is_infinite() || t < 0.0 {
                return Err(LearnerError::Invalid(format!(
                    "ppo.kl_target must be a finite number >= 0 (0.0 turns it off), got {t}"
                )));
            }
        }
        let vars: Vec<Var> = ac.named_vars().into_iter().map(|(_, v)| v).collect();
        let adam = Adam::new(config.adam.clone(), &vars)?;
        let rng = SplitMix64::new(config.seed);
        Ok(Self { config, adam, rng })
    }

    /// The PPO loss on one minibatch (normalised observations).
    pub fn losses(&self, ac: &ActorCritic, mb: &PpoMinibatch) -> LearnerResult<PpoLosses> {
        let c = &self.config;
        let mean = ac.policy.mean(&mb.obs)?;
        let log_probs = ac.policy.log_prob_from_mean(&mean, &mb.actions)?;
        let ratio = (log_probs - &mb.old_log_probs)?.exp()?;
        let surrogate = (&ratio * &mb.advantages)?;
        let clipped = (ratio.clamp(1.0 - c.clip_ratio, 1.0 + c.clip_ratio)? * &mb.advantages)?;
        let policy = surrogate.minimum(&clipped)?.mean_all()?.neg()?;

        let values = ac.value_outputs(&mb.obs)?;
        let error = (&values - &mb.returns)?.sqr()?;
        let value_error = match c.value_clip {
            Some(clip) => {
                let clipped_values =
                    (&mb.old_values + (&values - &mb.old_values)?.clamp(-clip, clip)?)?;
                error.maximum(&(clipped_values - &mb.returns)?.sqr()?)?
            }
            None => error,
        };
        let value = (value_error.mean_all()? * 0.5)?;

        let b = c.action_bound;
        let above = (&mean - b)?.relu()?.sqr()?;
        let below = (mean.neg()? - b)?.relu()?.sqr()?;
        let bound = (above + below)?.sum(D::Minus1)?.mean_all()?;

        let entropy = ac.policy.entropy()?;
        let total = (&policy + (&value * c.value_coef)? + (&bound * c.bound_coef)?
            - (&entropy * c.entropy_coef)?)?;
        Ok(PpoLosses {
            total,
            policy,
            value,
            bound,
            entropy,
            ratio,
        })
    }

    /// Loss, backward, gradient clipping and one Adam step on one minibatch (`vars` =
    /// `ac.named_vars()` in order). Returns the losses and the pre-clipping gradient norm.
    pub fn minibatch_step(
        &mut self,
        ac: &ActorCritic,
        vars: &[Var],
        mb: &PpoMinibatch,
    ) -> LearnerResult<(PpoLosses, f64)> {
        let losses = self.losses(ac, mb)?;
        let store = losses.total.backward()?;
        let mut grads = gradients(vars, &store)?;
        let grad_norm = clip_global_norm(&mut grads, self.config.max_grad_norm);
        self.adam.step(vars, &grads)?;
        Ok((losses, grad_norm))
    }

    /// One PPO update of `ac` on `batch`; afterwards folds the batch's observations into the
    /// normaliser (after, so the policy that produced `old_log_probs` is the one evaluated first).
    pub fn update(&mut self, ac: &mut ActorCritic, batch: &PpoBatch) -> LearnerResult<PpoStats> {
        let n = batch.len();
        let (obs_dim, act_dim) = (ac.obs_dim(), ac.act_dim());
        if n == 0 {
            return Err(LearnerError::Invalid("empty PPO batch".into()));
        }
        check_len("obs", batch.obs.len(), n * obs_dim)?;
        check_len("actions", batch.actions.len(), n * act_dim)?;
        check_len("old_values", batch.old_values.len(), n)?;
        check_len("advantages", batch.advantages.len(), n)?;
        check_len("returns", batch.returns.len(), n)?;
        let mb_size = self.config.minibatch_size.clamp(1, n);

        let obs = ac.input_rows(&batch.obs)?;
        // With a value normaliser the critic learns standardised returns; its statistics take
        // this batch's returns in first, so the targets are on the scale it will be read at.
        if let Some(norm) = &mut ac.value_norm {
            norm.update(&batch.returns)?;
        }
        let returns = ac.normalize_values(&batch.returns);
        let old_values = ac.normalize_values(&batch.old_values);
        let advantages = if self.config.normalize_advantages {
            standardize(&batch.advantages)
        } else {
            batch.advantages.clone()
        };

        let named = ac.named_vars();
        let vars: Vec<Var> = named.iter().map(|(_, v)| v.clone()).collect();
        let mut sums = PpoStats::default();
        for _ in 0..self.config.epochs {
            let (kl_before, minibatches_before) = (sums.approx_kl, sums.minibatches);
            let order = self.rng.permutation(n);
            for chunk in order.chunks(mb_size) {
                let mb = PpoMinibatch {
                    obs: gather_rows(&obs, obs_dim, chunk)?,
                    actions: gather_rows(&batch.actions, act_dim, chunk)?,
                    old_log_probs: gather(&batch.old_log_probs, chunk)?,
                    old_values: gather(&old_values, chunk)?,
                    advantages: gather(&advantages, chunk)?,
                    returns: gather(&returns, chunk)?,
                };
                let (losses, grad_norm) = self.minibatch_step(ac, &vars, &mb)?;
                sums.grad_norm += grad_norm;

                let ratio: Vec<f32> = losses.ratio.to_vec1()?;
                let eps = self.config.clip_ratio;
                let m = ratio.len() as f64;
                sums.clip_fraction += ratio
                    .iter()
                    .filter(|&&r| ((r as f64) - 1.0).abs() > eps)
                    .count() as f64
                    / m;
                sums.approx_kl += ratio
                    .iter()
                    .map(|&r| (r as f64 - 1.0) - (r as f64).ln())
                    .sum::<f64>()
                    / m;
                sums.policy_loss += scalar(&losses.policy)?;
                sums.value_loss += scalar(&losses.value)?;
                sums.bound_loss += scalar(&losses.bound)?;
                sums.entropy += scalar(&losses.entropy)?;
                sums.total_loss += scalar(&losses.total)?;
                sums.minibatches += 1;
            }
            if let Some(target) = self.config.kl_target.filter(|&t| t > 0.0) {
                let epoch_kl = (sums.approx_kl - kl_before)
                    / (sums.minibatches - minibatches_before).max(1) as f64;
                self.adam.config.lr = adapt_lr(self.adam.config.lr, epoch_kl, target);
            }
        }
        ac.update_obs_norm(&batch.obs)?;
        let k = sums.minibatches as f64;
        Ok(PpoStats {
            policy_loss: sums.policy_loss / k,
            value_loss: sums.value_loss / k,
            bound_loss: sums.bound_loss / k,
            entropy: sums.entropy / k,
            total_loss: sums.total_loss / k,
            clip_fraction: sums.clip_fraction / k,
            approx_kl: sums.approx_kl / k,
            grad_norm: sums.grad_norm / k,
            minibatches: sums.minibatches,
            lr: self.adam.config.lr,
        })
    }
}

pub(crate) fn scalar(t: &Tensor) -> LearnerResult<f64> {
    Ok(t.to_dtype(candle_core::DType::F64)?.to_scalar::<f64>()?)
}

/// Zero mean, unit variance (left centred only if the spread is ~0).
pub(crate) fn standardize(x: &[f32]) -> Vec<f32> {
    let n = x.len() as f64;
    let mean = x.iter().map(|&v| v as f64).sum::<f64>() / n;
    let var = x.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n;
    let inv = 1.0 / (var.sqrt() + 1e-8);
    x.iter()
        .map(|&v| ((v as f64 - mean) * inv) as f32)
        .collect()
}

/// Rows `indices` of a row-major matrix `width` wide, as a [indices.len(), width] tensor.
pub(crate) fn gather_rows(data: &[f32], width: usize, indices: &[usize]) -> LearnerResult<Tensor> {
    let mut out = Vec::with_capacity(indices.len() * width);
    for &i in indices {
        out.extend_from_slice(&data[i * width..(i + 1) * width]);
    }
    Ok(Tensor::from_vec(out, (indices.len(), width), &Device::Cpu)?)
}

pub(crate) fn gather(data: &[f32], indices: &[usize]) -> LearnerResult<Tensor> {
    let out: Vec<f32> = indices.iter().map(|&i| data[i]).collect();
    Ok(Tensor::from_vec(out, indices.len(), &Device::Cpu)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use lhm_nets::ActorCriticConfig;

    /// Returns around 50 while a fresh critic outputs about 0: with a value normaliser one update
    /// puts its values on the returns' scale; without, a raw critic is still far below.
    #[test]
    fn a_normalised_critic_reads_on_the_returns_scale_after_one_update() {
        let (obs_dim, act_dim, n) = (4, 2, 256);
        let mut rng = SplitMix64::new(5);
        let obs: Vec<f32> = (0..n * obs_dim)
            .map(|_| rng.uniform(-1.0, 1.0) as f32)
            .collect();
        let mean_value = |normalize_value: bool| {
            let config = ActorCriticConfig {
                normalize_value,
                ..ActorCriticConfig::with_hidden(&[16])
            };
            let mut ac = ActorCritic::new(obs_dim, act_dim, &config).unwrap();
            let mut act_rng = SplitMix64::new(9);
            let act = ac.act(&obs, &mut act_rng).unwrap();
            let returns: Vec<f32> = (0..n).map(|i| 50.0 + (i % 11) as f32 - 5.0).collect();
            let batch = PpoBatch {
                obs: obs.clone(),
                actions: act.actions,
                old_log_probs: act.log_probs,
                old_values: act.values.clone(),
                advantages: returns
                    .iter()
                    .zip(&act.values)
                    .map(|(r, v)| r - v)
                    .collect(),
                returns,
            };
            let config = PpoConfig {
                value_clip: None,
                epochs: 1,
                minibatch_size: n,
                ..PpoConfig::default()
            };
            let mut trainer = PpoTrainer::new(config, &ac).unwrap();
            trainer.update(&mut ac, &batch).unwrap();
            let values = ac.values(&obs).unwrap();
            values.iter().sum::<f32>() / n as f32
        };
        let normalised = mean_value(true);
        let raw = mean_value(false);
        assert!(
            (normalised - 50.0).abs() < 5.0,
            "normalised critic reads {normalised}"
        );
        assert!(raw.abs() < 10.0, "raw critic reads {raw}");
    }

    #[test]
    fn the_adaptive_rate_follows_the_rl_games_rule() {
        let target = 0.008;
        assert_eq!(adapt_lr(3e-4, 0.02, target), 3e-4 / 1.5);
        assert_eq!(adapt_lr(3e-4, 0.001, target), 3e-4 * 1.5);
        assert_eq!(adapt_lr(3e-4, 0.008, target), 3e-4);
        assert_eq!(adapt_lr(1e-6, 1.0, target), 1e-6);
        assert_eq!(adapt_lr(1e-2, 0.0, target), 1e-2);
    }

    /// With a KL target far below what an update moves, every epoch divides the rate by 1.5;
    /// far above, every epoch multiplies it; without a target it stays.
    #[test]
    fn a_kl_target_moves_the_learning_rate_epoch_by_epoch() {
        let (obs_dim, act_dim, n) = (4, 2, 128);
        let mut rng = SplitMix64::new(3);
        let obs: Vec<f32> = (0..n * obs_dim)
            .map(|_| rng.uniform(-1.0, 1.0) as f32)
            .collect();
        let lr_after = |kl_target: Option<f64>| {
            let mut ac =
                ActorCritic::new(obs_dim, act_dim, &ActorCriticConfig::with_hidden(&[16])).unwrap();
            let act = ac.act(&obs, &mut SplitMix64::new(4)).unwrap();
            let batch = PpoBatch {
                obs: obs.clone(),
                actions: act.actions,
                old_log_probs: act.log_probs,
                old_values: act.values.clone(),
                advantages: (0..n).map(|i| (i % 7) as f32 - 3.0).collect(),
                returns: vec![1.0; n],
            };
            let config = PpoConfig {
                epochs: 3,
                minibatch_size: 32,
                kl_target,
                ..PpoConfig::default()
            };
            let lr = config.adam.lr;
            let mut trainer = PpoTrainer::new(config, &ac).unwrap();
            let stats = trainer.update(&mut ac, &batch).unwrap();
            assert_eq!(stats.lr, trainer.adam.config.lr);
            stats.lr / lr
        };
        assert!((lr_after(Some(1e-12)) - 1.5f64.powi(-3)).abs() < 1e-9);
        assert!((lr_after(Some(1e3)) - 1.5f64.powi(3)).abs() < 1e-9);
        assert_eq!(lr_after(None), 1.0);
        assert_eq!(lr_after(Some(0.0)), 1.0);
    }

    /// A negative or NaN KL target is refused, naming the field.
    #[test]
    fn a_negative_kl_target_is_refused() {
        let ac = ActorCritic::new(4, 2, &ActorCriticConfig::with_hidden(&[8])).unwrap();
        for bad in [-0.01, f64::NAN] {
            let config = PpoConfig {
                kl_target: Some(bad),
                ..PpoConfig::default()
            };
            let Err(err) = PpoTrainer::new(config, &ac) else {
                panic!("a kl_target of {bad} was accepted");
            };
            assert!(err.to_string().contains("ppo.kl_target"), "{err}");
        }
    }
}
