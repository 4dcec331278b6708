//! Diagonal Gaussian policy: an MLP for the mean plus a state-independent log standard deviation.

use candle_core::{DType, Device, Tensor, Var, D};
use serde::{Deserialize, Serialize};

use crate::{Mlp, MlpConfig, NetError, NetResult, SplitMix64, VlaEncoder, VlaEncoderConfig};

/// How the policy's log standard deviation is handled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LogStd {
    /// A constant, never trained (AMP's usual choice, e.g. -2.9 ≈ ln 0.055).
    Fixed(f32),
    /// A trained parameter per action dimension, starting at this value.
    Learned(f32),
    /// A constant per action dimension, never trained: more exploration on some joints than on
    /// others (e.g. the arms, which a discriminator reads and balance hardly needs).
    PerDim(Vec<f32>),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GaussianPolicyConfig {
    pub mlp: MlpConfig,
    pub log_std: LogStd,
    /// Scale of the output layer's initial weights, so initial means are near zero.
    pub output_init_scale: f64,
    /// The VLA student: an image, instruction and proprioception encoder in front of the MLP
    /// (observation rows in its layout); absent for state-based policies.
    pub vla: Option<VlaEncoderConfig>,
}

impl Default for GaussianPolicyConfig {
    fn default() -> Self {
        Self {
            mlp: MlpConfig::default(),
            log_std: LogStd::Fixed(-2.9),
            output_init_scale: 0.01,
            vla: None,
        }
    }
}

#[derive(Debug, Clone)]
enum LogStdParam {
    Fixed(Tensor),
    Learned(Var),
}

#[derive(Debug, Clone)]
pub struct GaussianPolicy {
    encoder: Option<VlaEncoder>,
    mean: Mlp,
    log_std: LogStdParam,
}

const HALF_LN_TWO_PI: f64 = 0.918_938_533_204_672_7;

impl GaussianPolicy {
    pub fn new(
        obs_dim: usize,
        act_dim: usize,
        config: &GaussianPolicyConfig,
        rng: &mut SplitMix64,
        dtype: DType,
    ) -> NetResult<Self> {
        let encoder = match &config.vla {
            Some(vla) => {
                if vla.obs_dim() != obs_dim {
                    return Err(NetError::Config(format!(
                        "the VLA encoder reads rows of {} values, the observations have {obs_dim}",
                        vla.obs_dim()
                    )));
                }
                Some(VlaEncoder::new(vla, rng, dtype)?)
            }
            None => None,
        };
        let mean = Mlp::new(
            encoder.as_ref().map_or(obs_dim, VlaEncoder::feature_dim),
            act_dim,
            &config.mlp,
            config.output_init_scale,
            rng,
            dtype,
        )?;
        let init = |v: f32| Tensor::full(v, act_dim, &Device::Cpu).and_then(|t| t.to_dtype(dtype));
        let log_std = match &config.log_std {
            LogStd::Fixed(v) => LogStdParam::Fixed(init(*v)?),
            LogStd::Learned(v) => LogStdParam::Learned(Var::from_tensor(&init(*v)?)?),
            LogStd::PerDim(values) => {
                if values.len() != act_dim || values.iter().any(|v| !v.is_finite()) {
                    return Err(NetError::Config(format!(
                        "log_std per_dim: {} finite values for {act_dim} action dimensions, got \
                         {values:?}",
                        act_dim
                    )));
                }
                LogStdParam::Fixed(
                    Tensor::from_vec(values.clone(), act_dim, &Device::Cpu)?.to_dtype(dtype)?,
                )
            }
        };
        Ok(Self {
            encoder,
            mean,
            log_std,
        })
    }

    pub fn obs_dim(&self) -> usize {
        self.encoder
            .as_ref()
            .map_or(self.mean.in_dim(), VlaEncoder::obs_dim)
    }

    /// The VLA encoder, if this is the VLA student.
    pub fn encoder(&self) -> Option<&VlaEncoder> {
        self.encoder.as_ref()
    }

    pub fn act_dim(&self) -> usize {
        self.mean.out_dim()
    }

    pub fn mean_net(&self) -> &Mlp {
        &self.mean
    }

    /// Action means, [B, A]: the deterministic action.
    pub fn mean(&self, obs: &Tensor) -> NetResult<Tensor> {
        match &self.encoder {
            Some(encoder) => self.mean.forward(&encoder.forward(obs)?),
            None => self.mean.forward(obs),
        }
    }

    /// Log standard deviation, [A].
    pub fn log_std(&self) -> &Tensor {
        match &self.log_std {
            LogStdParam::Fixed(t) => t,
            LogStdParam::Learned(v) => v.as_tensor(),
        }
    }

    /// log π(a | s) from precomputed means, [B].
    pub fn log_prob_from_mean(&self, mean: &Tensor, actions: &Tensor) -> NetResult<Tensor> {
        let log_std = self.log_std();
        let z = (actions - mean)?.broadcast_div(&log_std.exp()?)?;
        let act_dim = self.act_dim() as f64;
        let quad = (z.sqr()?.sum(D::Minus1)? * -0.5)?;
        let norm = (log_std.sum_all()? + act_dim * HALF_LN_TWO_PI)?;
        Ok(quad.broadcast_sub(&norm)?)
    }

    /// Replaces a fixed log standard deviation with `value` (a run's stage may change it), one
    /// for every dimension or one each; a learned one is a parameter of the optimiser and is
    /// refused, and so is a learned `value`.
    pub fn set_fixed_log_std(&mut self, value: &LogStd) -> NetResult<()> {
        match &mut self.log_std {
            LogStdParam::Fixed(t) => {
                let dim = t.dims1()?;
                let values = match value {
                    LogStd::Fixed(v) => vec![*v; dim],
                    LogStd::PerDim(v) if v.len() == dim => v.clone(),
                    other => {
                        return Err(NetError::Config(format!(
                            "cannot set the policy's {dim} fixed log_std values to {other:?}"
                        )))
                    }
                };
                *t = Tensor::from_vec(values, dim, t.device())?.to_dtype(t.dtype())?;
                Ok(())
            }
            LogStdParam::Learned(_) => Err(NetError::Config(
                "the policy's log_std is learned; only a fixed one can be set".into(),
            )),
        }
    }

    /// log π(a | s), [B].
    pub fn log_prob(&self, obs: &Tensor, actions: &Tensor) -> NetResult<Tensor> {
        self.log_prob_from_mean(&self.mean(obs)?, actions)
    }

    /// Entropy of the action distribution (the same for every state), a scalar tensor.
    pub fn entropy(&self) -> NetResult<Tensor> {
        let act_dim = self.act_dim() as f64;
        Ok((self.log_std().sum_all()? + act_dim * (0.5 + HALF_LN_TWO_PI))?)
    }

    /// Draws a ~ N(mean, std²) with noise from `rng`; returns (actions [B, A], log-probs [B]).
    pub fn sample(&self, obs: &Tensor, rng: &mut SplitMix64) -> NetResult<(Tensor, Tensor)> {
        let mean = self.mean(obs)?.detach();
        let mut noise = vec![0f32; mean.elem_count()];
        rng.fill_normal(&mut noise);
        let noise = Tensor::from_vec(noise, mean.shape(), &Device::Cpu)?.to_dtype(mean.dtype())?;
        let actions = (&mean + noise.broadcast_mul(&self.log_std().exp()?)?)?.detach();
        let log_probs = self.log_prob_from_mean(&mean, &actions)?.detach();
        Ok((actions, log_probs))
    }

    /// Trainable parameters named `{prefix}.mean.layers.{i}.*`, `{prefix}.log_std` and (the VLA)
    /// `{prefix}.encoder.*`.
    pub fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        let mut vars = self.mean.named_vars(&format!("{prefix}.mean"));
        if let Some(encoder) = &self.encoder {
            vars.extend(encoder.named_vars(&format!("{prefix}.encoder")));
        }
        if let LogStdParam::Learned(v) = &self.log_std {
            vars.push((format!("{prefix}.log_std"), v.clone()));
        }
        vars
    }
}

/// State-value network V(s).
#[derive(Debug, Clone)]
pub struct ValueNet {
    mlp: Mlp,
}

impl ValueNet {
    pub fn new(
        obs_dim: usize,
        config: &MlpConfig,
        rng: &mut SplitMix64,
        dtype: DType,
    ) -> NetResult<Self> {
        Ok(Self {
            mlp: Mlp::new(obs_dim, 1, config, 1.0, rng, dtype)?,
        })
    }

    /// V(s), [B].
    pub fn forward(&self, obs: &Tensor) -> NetResult<Tensor> {
        Ok(self.mlp.forward(obs)?.squeeze(D::Minus1)?)
    }

    pub fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        self.mlp.named_vars(prefix)
    }
}

/// AMP discriminator: an MLP from (normalised) motion features to one logit, D > 0 meaning
/// "looks like the demonstrations".
#[derive(Debug, Clone)]
pub struct Discriminator {
    mlp: Mlp,
}

impl Discriminator {
    pub fn new(
        input_dim: usize,
        config: &MlpConfig,
        rng: &mut SplitMix64,
        dtype: DType,
    ) -> NetResult<Self> {
        Ok(Self {
            mlp: Mlp::new(input_dim, 1, config, 1.0, rng, dtype)?,
        })
    }

    pub fn input_dim(&self) -> usize {
        self.mlp.in_dim()
    }

    pub fn mlp(&self) -> &Mlp {
        &self.mlp
    }

    /// Logits, [B].
    pub fn logits(&self, x: &Tensor) -> NetResult<Tensor> {
        Ok(self.mlp.forward(x)?.squeeze(D::Minus1)?)
    }

    /// Logits [B] and their input gradients [B, F], as a first-order graph (see
    /// [`Mlp::forward_with_input_gradient`]).
    pub fn logits_with_input_gradient(&self, x: &Tensor) -> NetResult<(Tensor, Tensor)> {
        let (y, g) = self.mlp.forward_with_input_gradient(x)?;
        Ok((y.squeeze(D::Minus1)?, g))
    }

    pub fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        self.mlp.named_vars(prefix)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small policy's config with `log_std`.
    fn cfg(log_std: LogStd) -> GaussianPolicyConfig {
        GaussianPolicyConfig {
            mlp: MlpConfig::with_hidden(&[8]),
            log_std,
            output_init_scale: 0.01,
            vla: None,
        }
    }

    #[test]
    fn a_per_dimension_log_std_samples_each_dimension_at_its_own_spread() {
        let mut rng = SplitMix64::new(3);
        let policy = GaussianPolicy::new(
            3,
            2,
            &cfg(LogStd::PerDim(vec![-4.5, -2.5])),
            &mut rng,
            DType::F32,
        )
        .unwrap();
        let obs = Tensor::zeros((4000, 3), DType::F32, &Device::Cpu).unwrap();
        let (actions, log_probs) = policy.sample(&obs, &mut rng).unwrap();
        let mean = policy.mean(&obs).unwrap();
        let dev: Vec<Vec<f32>> = (&actions - &mean).unwrap().to_vec2().unwrap();
        for (k, want) in [(-4.5f32).exp(), (-2.5f32).exp()].into_iter().enumerate() {
            let var = dev.iter().map(|r| r[k] * r[k]).sum::<f32>() / dev.len() as f32;
            assert!(
                (var.sqrt() / want - 1.0).abs() < 0.05,
                "dim {k}: {}",
                var.sqrt()
            );
        }
        // log π of each draw is the two one-dimensional normal densities' logs summed.
        let lp: Vec<f32> = log_probs.to_vec1().unwrap();
        let one = |x: f32, ls: f32| -0.5 * (x / ls.exp()).powi(2) - ls - HALF_LN_TWO_PI as f32;
        let want = one(dev[0][0], -4.5) + one(dev[0][1], -2.5);
        assert!((lp[0] - want).abs() < 1e-3, "{} vs {want}", lp[0]);
        for bad in [vec![-4.5], vec![-4.5, f32::NAN]] {
            let e = GaussianPolicy::new(3, 2, &cfg(LogStd::PerDim(bad)), &mut rng, DType::F32)
                .unwrap_err()
                .to_string();
            assert!(e.contains("per_dim"), "{e}");
        }
    }

    #[test]
    fn a_fixed_log_std_can_be_set_and_a_learned_one_cannot() {
        let mut rng = SplitMix64::new(1);
        let mut fixed =
            GaussianPolicy::new(3, 2, &cfg(LogStd::Fixed(-3.5)), &mut rng, DType::F32).unwrap();
        fixed.set_fixed_log_std(&LogStd::Fixed(-4.0)).unwrap();
        let set: Vec<f32> = fixed.log_std().to_vec1().unwrap();
        assert_eq!(set, vec![-4.0, -4.0]);
        let h: f32 = fixed.entropy().unwrap().to_scalar().unwrap();
        let want = 2.0 * (0.5 + HALF_LN_TWO_PI as f32 - 4.0);
        assert!((h - want).abs() < 1e-5, "{h} vs {want}");
        let mut learned =
            GaussianPolicy::new(3, 2, &cfg(LogStd::Learned(-1.0)), &mut rng, DType::F32).unwrap();
        assert!(learned.set_fixed_log_std(&LogStd::Fixed(-4.0)).is_err());
        let kept: Vec<f32> = learned.log_std().to_vec1().unwrap();
        assert_eq!(kept, vec![-1.0, -1.0]);
    }

    #[test]
    fn log_prob_and_entropy_match_closed_form() {
        let mut rng = SplitMix64::new(1);
        let cfg = GaussianPolicyConfig {
            mlp: MlpConfig::with_hidden(&[8]),
            log_std: LogStd::Learned(-0.5),
            output_init_scale: 0.01,
            vla: None,
        };
        let policy = GaussianPolicy::new(3, 2, &cfg, &mut rng, DType::F64).unwrap();
        let obs = Tensor::new(&[[0.1f64, -0.2, 0.3]], &Device::Cpu).unwrap();
        let mean: Vec<f64> = policy
            .mean(&obs)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let a = [0.4f64, -0.7];
        let actions = Tensor::new(&[a], &Device::Cpu).unwrap();
        let lp: Vec<f64> = policy.log_prob(&obs, &actions).unwrap().to_vec1().unwrap();
        let std = (-0.5f64).exp();
        let expected: f64 = (0..2)
            .map(|i| -0.5 * ((a[i] - mean[i]) / std).powi(2) - std.ln() - HALF_LN_TWO_PI)
            .sum();
        assert!((lp[0] - expected).abs() < 1e-12, "{} vs {expected}", lp[0]);
        let h: f64 = policy.entropy().unwrap().to_scalar().unwrap();
        assert!((h - 2.0 * (0.5 + HALF_LN_TWO_PI + std.ln())).abs() < 1e-12);
        // Sampling is reproducible from the RNG and consistent with log_prob.
        let (s1, lp1) = policy.sample(&obs, &mut SplitMix64::new(9)).unwrap();
        let (s2, _) = policy.sample(&obs, &mut SplitMix64::new(9)).unwrap();
        let s1v: Vec<f64> = s1.flatten_all().unwrap().to_vec1().unwrap();
        assert_eq!(s1v, s2.flatten_all().unwrap().to_vec1::<f64>().unwrap());
        let lp_again: Vec<f64> = policy.log_prob(&obs, &s1).unwrap().to_vec1().unwrap();
        assert!((lp1.to_vec1::<f64>().unwrap()[0] - lp_again[0]).abs() < 1e-12);
        assert_eq!(
            policy.named_vars("policy").last().unwrap().0,
            "policy.log_std"
        );
    }

    #[test]
    fn discriminator_input_gradient_matches_finite_differences() {
        for activation in [crate::Activation::Elu, crate::Activation::Relu] {
            let mut rng = SplitMix64::new(5);
            let cfg = MlpConfig {
                hidden: vec![16, 12],
                activation,
            };
            let disc = Discriminator::new(4, &cfg, &mut rng, DType::F64).unwrap();
            let x: Vec<f64> = (0..5 * 4).map(|_| rng.uniform(-2.0, 2.0)).collect();
            let xt = Tensor::from_vec(x.clone(), (5, 4), &Device::Cpu).unwrap();
            let (_, grad) = disc.logits_with_input_gradient(&xt).unwrap();
            let grad: Vec<Vec<f64>> = grad.to_vec2().unwrap();
            let h = 1e-6;
            let mut max_err = 0f64;
            for (b, grad_row) in grad.iter().enumerate() {
                for (f, &analytic) in grad_row.iter().enumerate() {
                    let eval = |delta: f64| -> f64 {
                        let mut xp = x[b * 4..b * 4 + 4].to_vec();
                        xp[f] += delta;
                        let t = Tensor::from_vec(xp, (1, 4), &Device::Cpu).unwrap();
                        disc.logits(&t).unwrap().to_vec1::<f64>().unwrap()[0]
                    };
                    let numeric = (eval(h) - eval(-h)) / (2.0 * h);
                    max_err = max_err.max((numeric - analytic).abs());
                }
            }
            println!("{activation:?}: max |dD/dx analytic - central difference| = {max_err:.3e}");
            assert!(max_err < 1e-7, "{activation:?}: {max_err}");
        }
    }
}
