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

/// The first `lead` values of each `dim`-wide row.
fn leading_columns(rows: &[f32], dim: usize, lead: usize) -> NetResult<Vec<f32>> {
    if rows.len() % dim != 0 {
        return Err(NetError::RaggedRows {
            len: rows.len(),
            width: dim,
        });
    }
    Ok(rows
        .chunks_exact(dim)
        .flat_map(|row| row[..lead].iter().copied())
        .collect())
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
        // The VLA student is trained by regression alone; its critic (kept so every policy has
        // one layout) reads the proprioception only, instead of tens of thousands of pixels.
        let normalized_dim = config
            .policy
            .vla
            .as_ref()
            .map_or(obs_dim, |v| v.proprio_dim);
        let value = ValueNet::new(normalized_dim, &config.value, &mut rng, DType::F32)?;
        let obs_norm = config
            .normalize_obs
            .then(|| RunningMeanStd::new(normalized_dim));
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

    /// Sets the policy's fixed log standard deviation, in the network and in its config (what
    /// a saved policy records); an error for a learned one.
    pub fn set_fixed_log_std(&mut self, value: &crate::LogStd) -> NetResult<()> {
        self.policy.set_fixed_log_std(value)?;
        self.config.policy.log_std = value.clone();
        Ok(())
    }

    pub fn obs_dim(&self) -> usize {
        self.policy.obs_dim()
    }

    pub fn act_dim(&self) -> usize {
        self.policy.act_dim()
    }

    /// Leading columns of an observation row that the normaliser whitens: all of them, except
    /// for the VLA, whose word ids and pixels go to its encoder raw.
    pub fn normalized_dim(&self) -> usize {
        self.policy
            .encoder()
            .map_or(self.obs_dim(), |e| e.config().proprio_dim)
    }

    /// Raw observation rows → the network's input rows (normalised as [`Self::normalized_dim`]
    /// says).
    pub fn input_rows(&self, raw_obs: &[f32]) -> NetResult<Vec<f32>> {
        let Some(norm) = &self.obs_norm else {
            return Ok(raw_obs.to_vec());
        };
        let (dim, lead) = (self.obs_dim(), self.normalized_dim());
        if lead == dim {
            return norm.normalize(raw_obs);
        }
        let leading = leading_columns(raw_obs, dim, lead)?;
        let whitened = norm.normalize(&leading)?;
        let mut out = raw_obs.to_vec();
        for (row, w) in out.chunks_exact_mut(dim).zip(whitened.chunks_exact(lead)) {
            row[..lead].copy_from_slice(w);
        }
        Ok(out)
    }

    /// Folds raw observation rows into the normaliser's statistics (no-op without one).
    pub fn update_obs_norm(&mut self, raw_obs: &[f32]) -> NetResult<()> {
        let (dim, lead) = (self.obs_dim(), self.normalized_dim());
        let Some(norm) = &mut self.obs_norm else {
            return Ok(());
        };
        if lead == dim {
            return norm.update(raw_obs);
        }
        let leading = leading_columns(raw_obs, dim, lead)?;
        norm.update(&leading)
    }

    /// Raw observation rows → the network input tensor [B, obs_dim].
    pub fn input_tensor(&self, raw_obs: &[f32]) -> NetResult<Tensor> {
        rows_tensor(&self.input_rows(raw_obs)?, self.obs_dim())
    }

    /// V(s) outputs for network input rows (the critic's own leading columns).
    pub fn value_outputs(&self, input: &Tensor) -> NetResult<Tensor> {
        let lead = self.normalized_dim();
        if lead == self.obs_dim() {
            self.value.forward(input)
        } else {
            self.value.forward(&input.narrow(1, 0, lead)?)
        }
    }

    /// Samples actions for a batch of raw observations.
    pub fn act(&self, raw_obs: &[f32], rng: &mut SplitMix64) -> NetResult<ActOutput> {
        let obs = self.input_tensor(raw_obs)?;
        let (actions, log_probs) = self.policy.sample(&obs, rng)?;
        Ok(ActOutput {
            actions: actions.flatten_all()?.to_vec1()?,
            log_probs: log_probs.to_vec1()?,
            values: self.denormalize_values(&self.value_outputs(&obs)?.to_vec1()?),
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
            .value_outputs(&self.input_tensor(raw_obs)?)?
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
