//! Adam (Kingma & Ba) over candle `Var`s, written here rather than taken from candle-nn so that
//! the moments and step count are plain data that a checkpoint can store and restore exactly.
//! Moments live on the host as f32; the update follows PyTorch's `torch.optim.Adam` formula.

use candle_core::backprop::GradStore;
use candle_core::{DType, Tensor, Var};
use serde::{Deserialize, Serialize};

use crate::{NetError, NetResult};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdamConfig {
    pub lr: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
}

impl Default for AdamConfig {
    fn default() -> Self {
        Self {
            lr: 3e-4,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Adam {
    pub config: AdamConfig,
    step: u64,
    m: Vec<Vec<f32>>,
    v: Vec<Vec<f32>>,
}

impl Adam {
    /// Zeroed moments for `vars`, which must be f32 and passed in this same order to every step.
    pub fn new(config: AdamConfig, vars: &[Var]) -> NetResult<Self> {
        for var in vars {
            if var.dtype() != DType::F32 {
                return Err(NetError::Config(format!(
                    "Adam needs f32 parameters, got {:?}",
                    var.dtype()
                )));
            }
        }
        let zeros = || {
            vars.iter()
                .map(|v| vec![0f32; v.elem_count()])
                .collect::<Vec<_>>()
        };
        Ok(Self {
            config,
            step: 0,
            m: zeros(),
            v: zeros(),
        })
    }

    pub fn step_count(&self) -> u64 {
        self.step
    }

    pub fn first_moments(&self) -> &[Vec<f32>] {
        &self.m
    }

    pub fn second_moments(&self) -> &[Vec<f32>] {
        &self.v
    }

    /// Replaces the optimiser state (from a checkpoint); sizes must match the parameters.
    pub fn restore(&mut self, step: u64, m: Vec<Vec<f32>>, v: Vec<Vec<f32>>) -> NetResult<()> {
        let sizes = |x: &[Vec<f32>]| x.iter().map(Vec::len).collect::<Vec<_>>();
        if sizes(&m) != sizes(&self.m) || sizes(&v) != sizes(&self.v) {
            return Err(NetError::Config(format!(
                "Adam moment sizes {:?} do not match the parameters {:?}",
                sizes(&m),
                sizes(&self.m)
            )));
        }
        self.step = step;
        self.m = m;
        self.v = v;
        Ok(())
    }

    /// One update p ← p - lr·m̂/(√v̂ + eps) with gradients in the order of `vars`.
    pub fn step(&mut self, vars: &[Var], grads: &[Vec<f32>]) -> NetResult<()> {
        if vars.len() != self.m.len() || grads.len() != self.m.len() {
            return Err(NetError::Config(format!(
                "Adam was built for {} parameters, got {} vars and {} gradients",
                self.m.len(),
                vars.len(),
                grads.len()
            )));
        }
        self.step += 1;
        let AdamConfig {
            lr,
            beta1,
            beta2,
            eps,
        } = self.config;
        let t = self.step as i32;
        let bias1 = 1.0 - beta1.powi(t);
        let bias2_sqrt = (1.0 - beta2.powi(t)).sqrt();
        let step_size = (lr / bias1) as f32;
        let (b1, b2, eps) = (beta1 as f32, beta2 as f32, eps as f32);
        let inv_bias2_sqrt = (1.0 / bias2_sqrt) as f32;
        for (((var, g), m), v) in vars.iter().zip(grads).zip(&mut self.m).zip(&mut self.v) {
            if g.len() != m.len() {
                return Err(NetError::Config(format!(
                    "gradient of {} values for a {}-value parameter",
                    g.len(),
                    m.len()
                )));
            }
            let mut p = var.as_tensor().flatten_all()?.to_vec1::<f32>()?;
            for i in 0..p.len() {
                m[i] = b1 * m[i] + (1.0 - b1) * g[i];
                v[i] = b2 * v[i] + (1.0 - b2) * g[i] * g[i];
                p[i] -= step_size * m[i] / (v[i].sqrt() * inv_bias2_sqrt + eps);
            }
            var.set(&Tensor::from_vec(p, var.shape(), var.device())?)?;
        }
        Ok(())
    }
}

/// Gradients of `vars` as host vectors (zeros for a parameter the loss does not touch).
pub fn gradients(vars: &[Var], store: &GradStore) -> NetResult<Vec<Vec<f32>>> {
    vars.iter()
        .map(|var| match store.get(var.as_tensor()) {
            Some(g) => Ok(g.flatten_all()?.to_dtype(DType::F32)?.to_vec1::<f32>()?),
            None => Ok(vec![0f32; var.elem_count()]),
        })
        .collect()
}

/// Scales all gradients together so their global L2 norm is at most `max_norm`; returns the norm
/// before clipping.
pub fn clip_global_norm(grads: &mut [Vec<f32>], max_norm: f64) -> f64 {
    let norm = grads
        .iter()
        .flatten()
        .map(|&g| (g as f64) * (g as f64))
        .sum::<f64>()
        .sqrt();
    if norm > max_norm && norm > 0.0 {
        let scale = (max_norm / (norm + 1e-6)) as f32;
        grads.iter_mut().flatten().for_each(|g| *g *= scale);
    }
    norm
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn first_adam_step_moves_each_parameter_by_lr_against_its_gradient() {
        let var =
            Var::from_tensor(&Tensor::new(&[1.0f32, -2.0, 0.5], &Device::Cpu).unwrap()).unwrap();
        let mut adam = Adam::new(
            AdamConfig {
                lr: 0.1,
                ..Default::default()
            },
            std::slice::from_ref(&var),
        )
        .unwrap();
        adam.step(std::slice::from_ref(&var), &[vec![3.0, -0.5, 0.0]])
            .unwrap();
        let p = var.as_tensor().to_vec1::<f32>().unwrap();
        // Bias-corrected first step: m̂/√v̂ = sign(g).
        assert!(
            (p[0] - 0.9).abs() < 1e-6 && (p[1] + 1.9).abs() < 1e-6 && p[2] == 0.5,
            "{p:?}"
        );
        assert_eq!(adam.step_count(), 1);
    }

    #[test]
    fn clipping_bounds_the_global_norm() {
        let mut g = vec![vec![3.0f32], vec![4.0]];
        assert_eq!(clip_global_norm(&mut g, 1.0), 5.0);
        assert!((g[0][0] - 0.6).abs() < 1e-5 && (g[1][0] - 0.8).abs() < 1e-5);
    }
}
