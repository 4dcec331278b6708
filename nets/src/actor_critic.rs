//! The policy, its value function and the observation normaliser they share: what an actor needs
//! to act and what the learner trains.

use candle_core::{DType, Tensor, Var};
use serde::{Deserialize, Serialize};

use crate::{
    rows_tensor, GaussianPolicy, GaussianPolicyConfig, MlpConfig, NetError, NetResult,
    RunningMeanStd, SplitMix64, ValueNet,
};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ActorCriticConfig {
    pub policy: GaussianPolicyConfig,
    pub value: MlpConfig,
    /// Whiten observations with running statistics before both networks.
    pub normalize_obs: bool,
    /// The critic predicts returns standardised by a running mean and std of the returns
    /// (IsaacGymEnvs' `normalize_value`); its outputs are mapped back before anyone sees them.
    pub normalize_value: bool,
    /// Seed of the initial weights.
    pub init_seed: u64,
}

impl Default for ActorCriticConfig {
    fn default() -> Self {
        Self {
            policy: GaussianPolicyConfig::default(),
            value: MlpConfig::default(),
            normalize_obs: true,
            normalize_value: false,
            init_seed: 0,
        }
    }
}

impl ActorCriticConfig {
    /// The same layout with hidden sizes `hidden` for both networks (tests, CPU runs).
    pub fn with_hidden(hidden: &[usize]) -> Self {
        let mut config = Self::default();
        config.policy.mlp.hidden = hidden.to_vec();
        config.value.hidden = hidden.to_vec();
        config
    }
}

/// One batch of acting: flat row-major actions, their log-probabilities, and state values.
#[derive(Debug, Clone, PartialEq)]
pub struct ActOutput {
    pub actions: Vec<f32>,
    pub log_probs: Vec<f32>,
    pub values: Vec<f32>,
}

#[derive(Debug, Clone)]
pub struct ActorCritic {
    pub config: ActorCriticConfig,
    pub policy: GaussianPolicy,
    pub value: ValueNet,
    /// `None` when `normalize_obs` is off.
    pub obs_norm: Option<RunningMeanStd>,
    /// Running statistics of the returns (width 1); `None` when `normalize_value` is off.
    pub value_norm: Option<RunningMeanStd>,
}

impl ActorCritic {
    pub fn new(obs_dim: usize, act_dim: usize, config: &ActorCriticConfig) -> NetResult<Self> {
        let mut rng = SplitMix64::new(config.init_seed);
        let policy = GaussianPolicy::new(obs_dim, act_dim, &config.policy, &mut rng, DType::F32)?;
        let value = ValueNet::new(obs_dim, &config.value, &mut rng, DType::F32)?;
        let obs_norm = config.normalize_obs.then(|| RunningMeanStd::new(obs_dim));
        let value_norm = config.normalize_value.then(|| RunningMeanStd::new(1));
        Ok(Self {
            config: config.clone(),
            policy,
            value,
            obs_norm,
            value_norm,
        })
    }

    /// Returns' mean and std under the value normaliser ((0, 1) without one).
    fn value_scale(&self) -> (f64, f64) {
        match &self.value_norm {
            Some(n) => (n.mean()[0], (n.var()[0] + n.epsilon).sqrt()),
            None => (0.0, 1.0),
        }
    }

    /// Critic outputs → values on the returns' scale.
    pub fn denormalize_values(&self, outputs: &[f32]) -> Vec<f32> {
        let (mean, std) = self.value_scale();
        outputs
            .iter()
            .map(|&v| (v as f64 * std + mean) as f32)
            .collect()
    }

    /// Values on the returns' scale → what the critic is trained to output (not clipped).
    pub fn normalize_values(&self, values: &[f32]) -> Vec<f32> {
        let (mean, std) = self.value_scale();
        values
            .iter()
            .map(|&v| ((v as f64 - mean) / std) as f32)
            .collect()
    }

    pub fn obs_dim(&self) -> usize {
        self.policy.obs_dim()
    }

    pub fn act_dim(&self) -> usize {
        self.policy.act_dim()
    }

    /// Raw observation rows → the network input tensor [B, obs_dim].
    pub fn input_tensor(&self, raw_obs: &[f32]) -> NetResult<Tensor> {
        match &self.obs_norm {
            Some(norm) => norm.normalize_tensor(raw_obs),
            None => rows_tensor(raw_obs, self.obs_dim()),
        }
    }

    /// Samples actions for a batch of raw observations.
    pub fn act(&self, raw_obs: &[f32], rng: &mut SplitMix64) -> NetResult<ActOutput> {
        let obs = self.input_tensor(raw_obs)?;
        let (actions, log_probs) = self.policy.sample(&obs, rng)?;
        Ok(ActOutput {
            actions: actions.flatten_all()?.to_vec1()?,
            log_probs: log_probs.to_vec1()?,
            values: self.denormalize_values(&self.value.forward(&obs)?.to_vec1()?),
        })
    }

    /// Mean actions (evaluation / deployment).
    pub fn act_deterministic(&self, raw_obs: &[f32]) -> NetResult<Vec<f32>> {
        Ok(self
            .policy
            .mean(&self.input_tensor(raw_obs)?)?
            .flatten_all()?
            .to_vec1()?)
    }

    /// V(s) on the returns' scale for raw observations (e.g. to bootstrap a truncated episode).
    pub fn values(&self, raw_obs: &[f32]) -> NetResult<Vec<f32>> {
        let outputs = self
            .value
            .forward(&self.input_tensor(raw_obs)?)?
            .to_vec1()?;
        Ok(self.denormalize_values(&outputs))
    }

    /// Every trained parameter: `policy.*` then `value.*`.
    pub fn named_vars(&self) -> Vec<(String, Var)> {
        let mut vars = self.policy.named_vars("policy");
        vars.extend(self.value.named_vars("value"));
        vars
    }

    /// Policy and value parameters as a safetensors file in memory (what the learner broadcasts;
    /// a PyTorch user reads it with `safetensors.torch.load`).
    pub fn weights_safetensors(&self) -> NetResult<Vec<u8>> {
        let tensors: Vec<(String, Tensor)> = self
            .named_vars()
            .into_iter()
            .map(|(n, v)| Ok((n, v.as_tensor().contiguous()?)))
            .collect::<NetResult<_>>()?;
        safetensors::serialize(tensors.iter().map(|(n, t)| (n.as_str(), t)), None)
            .map_err(|e| NetError::Config(format!("cannot serialise weights: {e}")))
    }

    /// Loads parameters written by [`Self::weights_safetensors`] of a network with the same
    /// layout. Every parameter must be present with its exact shape and dtype; nothing is changed
    /// unless all of them are.
    pub fn load_weights_safetensors(&self, bytes: &[u8]) -> NetResult<()> {
        let bad = |what: String| NetError::Config(format!("policy weights: {what}"));
        let file = safetensors::SafeTensors::deserialize(bytes)
            .map_err(|e| bad(format!("not a safetensors file: {e}")))?;
        let vars = self.named_vars();
        let mut values = Vec::with_capacity(vars.len());
        for (name, var) in &vars {
            let view = file
                .tensor(name)
                .map_err(|_| bad(format!("tensor {name} is missing")))?;
            if view.dtype() != safetensors::Dtype::F32 || view.shape() != var.dims() {
                return Err(bad(format!(
                    "tensor {name} is {:?} {:?}, expected F32 {:?}",
                    view.dtype(),
                    view.shape(),
                    var.dims()
                )));
            }
            let data: Vec<f32> = view
                .data()
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            if data.iter().any(|x| !x.is_finite()) {
                return Err(bad(format!("tensor {name} holds non-finite values")));
            }
            values.push(Tensor::from_vec(
                data,
                var.dims(),
                &candle_core::Device::Cpu,
            )?);
        }
        for ((_, var), value) in vars.iter().zip(values) {
            var.set(&value)?;
        }
        Ok(())
    }
}
