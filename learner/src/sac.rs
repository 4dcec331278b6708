//! Soft actor-critic (Haarnoja et al. 2018, "Soft Actor-Critic Algorithms and Applications": twin
//! Q critics with Polyak-averaged targets, a tanh-squashed Gaussian actor, the temperature tuned
//! to a target entropy) and a uniform replay buffer.
//!
//! Why it is here: PPO + AMP has not learned to walk in ≤ 20 M samples on 2 cores (RESULTS.md),
//! while off-policy learners walk MuJoCo's Humanoid in well under a million environment steps.
//! It is an experiment beside PPO (the `sac_probe` example of lhm-cli drives it on the task
//! environment), not yet a learner seam of the service.

use candle_core::{DType, Device, Tensor, Var, D};
use serde::{Deserialize, Serialize};

use lhm_nets::adam::gradients;
use lhm_nets::{Adam, AdamConfig, Mlp, MlpConfig, RunningMeanStd, SplitMix64};

use crate::error::{check_len, LearnerError, LearnerResult};
use crate::ppo::scalar;

/// Hyper-parameters; the defaults are the SAC paper's (256-256, lr 3e-4, batch 256, τ 0.005,
/// target entropy −1 per action dimension).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SacConfig {
    pub actor: MlpConfig,
    pub critic: MlpConfig,
    pub gamma: f64,
    /// Polyak factor of the target critics.
    pub tau: f64,
    pub batch_size: usize,
    pub actor_adam: AdamConfig,
    pub critic_adam: AdamConfig,
    pub alpha_adam: AdamConfig,
    pub initial_alpha: f64,
    /// Target entropy per action dimension (the paper: −1, i.e. −|A| in all).
    pub target_entropy_per_dim: f64,
    /// Bounds of the actor's log-std (before the tanh squash).
    pub log_std_min: f64,
    pub log_std_max: f64,
    /// Normalise observations with running statistics of everything `observe`d.
    pub normalize_obs: bool,
    /// The actor and the temperature step once every this many critic steps (TD3's delayed
    /// policy updates, Fujimoto et al. 2018: the actor chases a critic that has had time to
    /// settle; 1: every step, as in SAC).
    pub actor_every: usize,
    pub seed: u64,
}

impl Default for SacConfig {
    fn default() -> Self {
        let adam = AdamConfig {
            lr: 3e-4,
            ..AdamConfig::default()
        };
        Self {
            actor: MlpConfig {
                hidden: vec![256, 256],
                activation: lhm_nets::Activation::Relu,
            },
            critic: MlpConfig {
                hidden: vec![256, 256],
                activation: lhm_nets::Activation::Relu,
            },
            gamma: 0.99,
            tau: 0.005,
            batch_size: 256,
            actor_adam: adam.clone(),
            critic_adam: adam.clone(),
            alpha_adam: adam,
            initial_alpha: 0.2,
            target_entropy_per_dim: -1.0,
            log_std_min: -5.0,
            log_std_max: 2.0,
            normalize_obs: true,
            actor_every: 1,
            seed: 0,
        }
    }
}

/// Transitions for one update, row-major; observations raw (normalised inside).
#[derive(Debug, Clone, Default)]
pub struct SacBatch {
    pub obs: Vec<f32>,
    pub actions: Vec<f32>,
    pub rewards: Vec<f32>,
    pub next_obs: Vec<f32>,
    /// Terminal (a fall): no bootstrap. A time limit is not terminal.
    pub terminals: Vec<bool>,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SacStats {
    pub critic_loss: f64,
    pub actor_loss: f64,
    pub alpha: f64,
    /// Mean −log π(a|s) of the actor's fresh actions (the entropy estimate).
    pub entropy: f64,
    pub mean_q: f64,
}

pub struct Sac {
    pub config: SacConfig,
    obs_dim: usize,
    act_dim: usize,
    actor: Mlp,
    q1: Mlp,
    q2: Mlp,
    q1_target: Mlp,
    q2_target: Mlp,
    log_alpha: Var,
    actor_adam: Adam,
    critic_adam: Adam,
    alpha_adam: Adam,
    /// Parameter lists, built once: the actor's, both critics' (q1 then q2) and their targets'
    /// in the same order.
    actor_vars: Vec<Var>,
    critic_vars: Vec<Var>,
    target_vars: Vec<Var>,
    pub obs_norm: RunningMeanStd,
    rng: SplitMix64,
    /// Critic steps taken (the actor steps on every `actor_every`-th).
    critic_steps: u64,
}

/// target ← (1 − τ) target + τ source, parameter by parameter (τ = 1 copies).
fn polyak(targets: &[Var], sources: &[Var], tau: f64) -> LearnerResult<()> {
    for (t, s) in targets.iter().zip(sources) {
        t.set(&((t.as_tensor() * (1.0 - tau))? + (s.as_tensor() * tau)?)?)?;
    }
    Ok(())
}

impl Sac {
    pub fn new(obs_dim: usize, act_dim: usize, config: SacConfig) -> LearnerResult<Self> {
        if config.tau.is_nan() || config.tau <= 0.0 || config.tau > 1.0 || config.batch_size == 0 {
            return Err(LearnerError::Invalid(format!(
                "sac: tau must lie in (0, 1] and batch_size be positive (tau {}, batch_size {})",
                config.tau, config.batch_size
            )));
        }
        if config.actor_every == 0 {
            return Err(LearnerError::Invalid(
                "sac: actor_every must be at least 1".into(),
            ));
        }
        if config.initial_alpha.is_nan()
            || config.initial_alpha <= 0.0
            || config.log_std_min.is_nan()
            || config.log_std_max.is_nan()
            || config.log_std_min >= config.log_std_max
        {
            return Err(LearnerError::Invalid(format!(
                "sac: initial_alpha must be positive and log_std_min < log_std_max (got {}, {}, {})",
                config.initial_alpha, config.log_std_min, config.log_std_max
            )));
        }
        let mut rng = SplitMix64::new(config.seed);
        let f = DType::F32;
        let actor = Mlp::new(obs_dim, 2 * act_dim, &config.actor, 0.01, &mut rng, f)?;
        let critic =
            |rng: &mut SplitMix64| Mlp::new(obs_dim + act_dim, 1, &config.critic, 1.0, rng, f);
        let (q1, q2) = (critic(&mut rng)?, critic(&mut rng)?);
        let (q1_target, q2_target) = (critic(&mut rng)?, critic(&mut rng)?);
        let actor_vars = Self::vars(&[&actor]);
        let critic_vars = Self::vars(&[&q1, &q2]);
        let target_vars = Self::vars(&[&q1_target, &q2_target]);
        polyak(&target_vars, &critic_vars, 1.0)?;
        let log_alpha = Var::from_tensor(&Tensor::new(
            &[config.initial_alpha.ln() as f32],
            &Device::Cpu,
        )?)?;
        let actor_adam = Adam::new(config.actor_adam.clone(), &actor_vars)?;
        let critic_adam = Adam::new(config.critic_adam.clone(), &critic_vars)?;
        let alpha_adam = Adam::new(config.alpha_adam.clone(), std::slice::from_ref(&log_alpha))?;
        Ok(Self {
            obs_norm: RunningMeanStd::new(obs_dim),
            rng: SplitMix64::new(config.seed ^ 0x5ac),
            critic_steps: 0,
            config,
            obs_dim,
            act_dim,
            actor,
            q1,
            q2,
            q1_target,
            q2_target,
            log_alpha,
            actor_adam,
            critic_adam,
            alpha_adam,
            actor_vars,
            critic_vars,
            target_vars,
        })
    }

    fn vars(nets: &[&Mlp]) -> Vec<Var> {
        nets.iter()
            .flat_map(|n| n.named_vars("").into_iter().map(|(_, v)| v))
            .collect()
    }

    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    pub fn act_dim(&self) -> usize {
        self.act_dim
    }

    pub fn alpha(&self) -> LearnerResult<f64> {
        scalar(&self.log_alpha.as_tensor().exp()?.sum_all()?)
    }

    /// Folds raw observations into the normaliser (call with what the environments produce).
    pub fn observe(&mut self, obs: &[f32]) -> LearnerResult<()> {
        if self.config.normalize_obs {
            self.obs_norm.update(obs)?;
        }
        Ok(())
    }

    fn input(&self, obs: &[f32]) -> LearnerResult<Tensor> {
        check_len("obs", obs.len() % self.obs_dim.max(1), 0)?;
        let n = obs.len() / self.obs_dim;
        Ok(if self.config.normalize_obs {
            self.obs_norm.normalize_tensor(obs)?
        } else {
            Tensor::from_vec(obs.to_vec(), (n, self.obs_dim), &Device::Cpu)?
        })
    }

    /// Mean and log-std (pre-squash) of π(·|s), log-std squashed into its bounds.
    fn distribution(&self, x: &Tensor) -> LearnerResult<(Tensor, Tensor)> {
        let out = self.actor.forward(x)?;
        let mean = out.narrow(D::Minus1, 0, self.act_dim)?;
        let raw = out.narrow(D::Minus1, self.act_dim, self.act_dim)?;
        let (lo, hi) = (self.config.log_std_min, self.config.log_std_max);
        let log_std = ((raw.tanh()? + 1.0)? * (0.5 * (hi - lo)))?.affine(1.0, lo)?;
        Ok((mean, log_std))
    }

    /// A reparameterised action tanh(μ + σ ε) and its log-probability [B, 1], tanh's Jacobian
    /// included.
    fn sample(&mut self, x: &Tensor) -> LearnerResult<(Tensor, Tensor)> {
        let (mean, log_std) = self.distribution(x)?;
        let mut eps = vec![0f32; mean.elem_count()];
        self.rng.fill_normal(&mut eps);
        let eps = Tensor::from_vec(eps, mean.shape(), &Device::Cpu)?;
        let u = (&mean + (log_std.exp()? * &eps)?)?;
        let action = u.tanh()?;
        let half_log_2pi = 0.5 * (2.0 * std::f64::consts::PI).ln();
        let gauss = ((eps.sqr()? * -0.5)? - &log_std)?.affine(1.0, -half_log_2pi)?;
        let jacobian = ((action.sqr()?.neg()? + 1.0)? + 1e-6)?.log()?;
        let log_prob = (gauss - jacobian)?.sum_keepdim(D::Minus1)?;
        Ok((action, log_prob))
    }

    /// Actions for raw observations: sampled, or tanh(μ) when `stochastic` is false.
    pub fn act(&mut self, obs: &[f32], stochastic: bool) -> LearnerResult<Vec<f32>> {
        let x = self.input(obs)?;
        let action = if stochastic {
            self.sample(&x)?.0
        } else {
            self.distribution(&x)?.0.tanh()?
        };
        Ok(action.flatten_all()?.to_vec1()?)
    }

    fn q_min(a: &Mlp, b: &Mlp, x: &Tensor, action: &Tensor) -> LearnerResult<Tensor> {
        let input = Tensor::cat(&[x, action], D::Minus1)?;
        Ok(a.forward(&input)?.minimum(&b.forward(&input)?)?)
    }

    /// One gradient step of the critics, the actor and the temperature, then the targets'
    /// Polyak step.
    pub fn update(&mut self, batch: &SacBatch) -> LearnerResult<SacStats> {
        let n = batch.rewards.len();
        if n == 0 {
            return Err(LearnerError::Invalid("empty SAC batch".into()));
        }
        check_len("obs", batch.obs.len(), n * self.obs_dim)?;
        check_len("next_obs", batch.next_obs.len(), n * self.obs_dim)?;
        check_len("actions", batch.actions.len(), n * self.act_dim)?;
        check_len("terminals", batch.terminals.len(), n)?;
        let dev = Device::Cpu;
        let x = self.input(&batch.obs)?;
        let x_next = self.input(&batch.next_obs)?;
        let actions = Tensor::from_vec(batch.actions.clone(), (n, self.act_dim), &dev)?;
        let rewards = Tensor::from_vec(batch.rewards.clone(), (n, 1), &dev)?;
        let continues: Vec<f32> = batch
            .terminals
            .iter()
            .map(|&t| if t { 0.0 } else { 1.0 })
            .collect();
        let continues = Tensor::from_vec(continues, (n, 1), &dev)?;
        let alpha = self.alpha()?;

        // Critics: y = r + γ (1 − terminal) (min Q_target(s', a') − α log π(a'|s')).
        let (next_action, next_log_prob) = self.sample(&x_next)?;
        let soft_next = (Self::q_min(&self.q1_target, &self.q2_target, &x_next, &next_action)?
            - (next_log_prob * alpha)?)?;
        let target = (rewards + ((soft_next * continues)? * self.config.gamma)?)?.detach();
        let input = Tensor::cat(&[&x, &actions], D::Minus1)?;
        let q1 = self.q1.forward(&input)?;
        let q2 = self.q2.forward(&input)?;
        let critic_loss =
            ((&q1 - &target)?.sqr()?.mean_all()? + (&q2 - &target)?.sqr()?.mean_all()?)?;
        let grads = gradients(&self.critic_vars, &critic_loss.backward()?)?;
        self.critic_adam.step(&self.critic_vars, &grads)?;

        // Actor: minimise α log π(a|s) − min Q(s, a) over fresh actions (the critics' own
        // gradients from this loss are computed and dropped).
        let (action, log_prob) = self.sample(&x)?;
        let q = Self::q_min(&self.q1, &self.q2, &x, &action)?;
        let actor_loss = ((&log_prob * alpha)? - &q)?.mean_all()?;
        let mean_log_prob = scalar(&log_prob.mean_all()?)?;
        self.critic_steps += 1;
        if (self.critic_steps - 1) % self.config.actor_every as u64 == 0 {
            let grads = gradients(&self.actor_vars, &actor_loss.backward()?)?;
            self.actor_adam.step(&self.actor_vars, &grads)?;

            // Temperature: d/d log α of −log α · (log π + H̄) is −(mean log π + H̄).
            let target_entropy = self.config.target_entropy_per_dim * self.act_dim as f64;
            let g = -(mean_log_prob + target_entropy) as f32;
            self.alpha_adam
                .step(std::slice::from_ref(&self.log_alpha), &[vec![g]])?;
        }

        polyak(&self.target_vars, &self.critic_vars, self.config.tau)?;
        Ok(SacStats {
            critic_loss: scalar(&critic_loss)?,
            actor_loss: scalar(&actor_loss)?,
            alpha,
            entropy: -mean_log_prob,
            mean_q: scalar(&q.mean_all()?)?,
        })
    }
}

/// A ring buffer of transitions with uniform sampling.
pub struct SacReplay {
    capacity: usize,
    obs_dim: usize,
    act_dim: usize,
    obs: Vec<f32>,
    next_obs: Vec<f32>,
    actions: Vec<f32>,
    rewards: Vec<f32>,
    terminals: Vec<bool>,
    len: usize,
    next: usize,
}

impl SacReplay {
    pub fn new(capacity: usize, obs_dim: usize, act_dim: usize) -> Self {
        Self {
            capacity: capacity.max(1),
            obs_dim,
            act_dim,
            obs: Vec::new(),
            next_obs: Vec::new(),
            actions: Vec::new(),
            rewards: Vec::new(),
            terminals: Vec::new(),
            len: 0,
            next: 0,
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn push(
        &mut self,
        obs: &[f32],
        action: &[f32],
        reward: f32,
        next_obs: &[f32],
        terminal: bool,
    ) -> LearnerResult<()> {
        check_len("obs", obs.len(), self.obs_dim)?;
        check_len("next_obs", next_obs.len(), self.obs_dim)?;
        check_len("action", action.len(), self.act_dim)?;
        let i = self.next;
        if self.len < self.capacity {
            self.obs.extend_from_slice(obs);
            self.next_obs.extend_from_slice(next_obs);
            self.actions.extend_from_slice(action);
            self.rewards.push(reward);
            self.terminals.push(terminal);
            self.len += 1;
        } else {
            let (o, a) = (i * self.obs_dim, i * self.act_dim);
            self.obs[o..o + self.obs_dim].copy_from_slice(obs);
            self.next_obs[o..o + self.obs_dim].copy_from_slice(next_obs);
            self.actions[a..a + self.act_dim].copy_from_slice(action);
            self.rewards[i] = reward;
            self.terminals[i] = terminal;
        }
        self.next = (i + 1) % self.capacity;
        Ok(())
    }

    /// `n` transitions drawn uniformly with replacement (empty when the buffer is).
    pub fn sample(&self, n: usize, rng: &mut SplitMix64) -> SacBatch {
        let mut batch = SacBatch::default();
        if self.len == 0 {
            return batch;
        }
        for _ in 0..n {
            let i = rng.below(self.len);
            let (o, a) = (i * self.obs_dim, i * self.act_dim);
            batch.obs.extend_from_slice(&self.obs[o..o + self.obs_dim]);
            batch
                .next_obs
                .extend_from_slice(&self.next_obs[o..o + self.obs_dim]);
            batch
                .actions
                .extend_from_slice(&self.actions[a..a + self.act_dim]);
            batch.rewards.push(self.rewards[i]);
            batch.terminals.push(self.terminals[i]);
        }
        batch
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-step bandit: reward −(a − 0.5)² per dimension, every step terminal. SAC's
    /// deterministic action must move from ~0 to near 0.5 within 1,500 updates (it
    /// overshoots first while the critics fit; ~1.5 s in release).
    #[test]
    fn sac_learns_a_one_step_bandit() {
        let (obs_dim, act_dim) = (3, 2);
        let config = SacConfig {
            actor: MlpConfig::with_hidden(&[32]),
            critic: MlpConfig::with_hidden(&[32]),
            batch_size: 64,
            actor_adam: AdamConfig {
                lr: 3e-3,
                ..AdamConfig::default()
            },
            critic_adam: AdamConfig {
                lr: 3e-3,
                ..AdamConfig::default()
            },
            initial_alpha: 0.01,
            normalize_obs: false,
            ..SacConfig::default()
        };
        let mut sac = Sac::new(obs_dim, act_dim, config).unwrap();
        let mut replay = SacReplay::new(10_000, obs_dim, act_dim);
        let mut rng = SplitMix64::new(1);
        let obs = [0.3f32, -0.2, 0.1];
        let error = |a: &[f32]| a.iter().map(|x| (x - 0.5).powi(2)).sum::<f32>();
        let first = error(&sac.act(&obs, false).unwrap());
        for _ in 0..1500 {
            for _ in 0..4 {
                let a = sac.act(&obs, true).unwrap();
                let r = -error(&a);
                replay.push(&obs, &a, r, &obs, true).unwrap();
            }
            let batch = replay.sample(64, &mut rng);
            let stats = sac.update(&batch).unwrap();
            assert!(stats.critic_loss.is_finite() && stats.alpha > 0.0);
        }
        let last = error(&sac.act(&obs, false).unwrap());
        assert!(first > 0.4, "starts near 0: {first}");
        assert!(last < 0.02, "learned the bandit: {first} -> {last}");
    }

    /// A reward of 1 on every step, never terminal, γ = 0.9: the critics' soft Q settles at
    /// 1 / (1 − γ) = 10 plus the small entropy bonus (α ≤ 1e-3 here), as the TD target says.
    #[test]
    fn the_critics_learn_the_discounted_return() {
        let (obs_dim, act_dim) = (2, 1);
        let config = SacConfig {
            actor: MlpConfig::with_hidden(&[16]),
            critic: MlpConfig::with_hidden(&[32]),
            gamma: 0.9,
            tau: 0.05,
            critic_adam: AdamConfig {
                lr: 3e-3,
                ..AdamConfig::default()
            },
            initial_alpha: 1e-3,
            alpha_adam: AdamConfig {
                lr: 0.0,
                ..AdamConfig::default()
            },
            normalize_obs: false,
            ..SacConfig::default()
        };
        let mut sac = Sac::new(obs_dim, act_dim, config).unwrap();
        let mut replay = SacReplay::new(1_000, obs_dim, act_dim);
        let mut rng = SplitMix64::new(2);
        for _ in 0..500 {
            let a = [rng.uniform(-1.0, 1.0) as f32];
            replay
                .push(&[0.1, 0.2], &a, 1.0, &[0.1, 0.2], false)
                .unwrap();
        }
        let mut q = 0.0;
        for _ in 0..1500 {
            q = sac.update(&replay.sample(64, &mut rng)).unwrap().mean_q;
        }
        assert!((q - 10.0).abs() < 1.0, "soft Q {q}, expected ~10");
    }

    #[test]
    fn the_replay_overwrites_its_oldest_rows_and_refuses_ragged_ones() {
        let mut replay = SacReplay::new(2, 1, 1);
        for k in 0..3 {
            replay
                .push(&[k as f32], &[0.0], k as f32, &[0.0], false)
                .unwrap();
        }
        assert_eq!(replay.len(), 2);
        let batch = replay.sample(50, &mut SplitMix64::new(0));
        assert!(batch.rewards.iter().all(|&r| r == 1.0 || r == 2.0));
        assert!(replay
            .push(&[0.0, 1.0], &[0.0], 0.0, &[0.0], false)
            .is_err());
    }

    #[test]
    fn bad_hyper_parameters_are_refused() {
        for config in [
            SacConfig {
                tau: 0.0,
                ..SacConfig::default()
            },
            SacConfig {
                initial_alpha: -1.0,
                ..SacConfig::default()
            },
            SacConfig {
                actor_every: 0,
                ..SacConfig::default()
            },
        ] {
            assert!(Sac::new(2, 1, config).is_err());
        }
    }

    /// With `actor_every` 3 the actor moves on critic steps 1, 4, 7, … and on no other.
    #[test]
    fn a_delayed_actor_steps_once_every_actor_every_updates() {
        let config = SacConfig {
            actor: MlpConfig::with_hidden(&[8]),
            critic: MlpConfig::with_hidden(&[8]),
            batch_size: 8,
            actor_every: 3,
            normalize_obs: false,
            ..SacConfig::default()
        };
        let mut sac = Sac::new(2, 1, config).unwrap();
        let mut replay = SacReplay::new(100, 2, 1);
        let mut rng = SplitMix64::new(3);
        for k in 0..20 {
            let o = [k as f32 * 0.1, 0.5];
            replay.push(&o, &[0.3], 1.0, &o, false).unwrap();
        }
        let probe = [0.2f32, 0.4];
        let mut moved = Vec::new();
        for _ in 0..7 {
            let before = sac.act(&probe, false).unwrap();
            sac.update(&replay.sample(8, &mut rng)).unwrap();
            moved.push(sac.act(&probe, false).unwrap() != before);
        }
        assert_eq!(moved, [true, false, false, true, false, false, true]);
    }
}
