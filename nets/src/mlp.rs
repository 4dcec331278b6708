//! Fully connected networks over candle `Var`s with PyTorch's layout (`weight` is [out, in]).

use candle_core::{DType, Device, Tensor, Var};
use serde::{Deserialize, Serialize};

use crate::{Activation, NetError, NetResult, SplitMix64};

/// Hidden sizes and activation of an MLP; input and output sizes come from the task.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MlpConfig {
    pub hidden: Vec<usize>,
    pub activation: Activation,
}

impl Default for MlpConfig {
    /// The paper-scale network: [1024, 512], ELU.
    fn default() -> Self {
        Self {
            hidden: vec![1024, 512],
            activation: Activation::Elu,
        }
    }
}

impl MlpConfig {
    /// A smaller network for CPU-only training: [512, 256], ELU.
    pub fn cpu_preset() -> Self {
        Self {
            hidden: vec![512, 256],
            activation: Activation::Elu,
        }
    }

    pub fn with_hidden(hidden: &[usize]) -> Self {
        Self {
            hidden: hidden.to_vec(),
            ..Self::default()
        }
    }
}

/// One affine layer y = x Wᵀ + b.
#[derive(Debug, Clone)]
pub struct Linear {
    pub weight: Var,
    pub bias: Var,
}

impl Linear {
    /// PyTorch's default initialisation, U(-1/√in, 1/√in) for weight and bias, times `scale`
    /// (a small scale on output layers keeps initial policy means and logits near zero).
    pub fn new(
        in_dim: usize,
        out_dim: usize,
        scale: f64,
        rng: &mut SplitMix64,
        dtype: DType,
    ) -> NetResult<Self> {
        let bound = scale / (in_dim as f64).sqrt();
        let mut draw =
            |n: usize| -> Vec<f64> { (0..n).map(|_| rng.uniform(-bound, bound)).collect() };
        let w = Tensor::from_vec(draw(in_dim * out_dim), (out_dim, in_dim), &Device::Cpu)?;
        let b = Tensor::from_vec(draw(out_dim), out_dim, &Device::Cpu)?;
        Ok(Self {
            weight: Var::from_tensor(&w.to_dtype(dtype)?)?,
            bias: Var::from_tensor(&b.to_dtype(dtype)?)?,
        })
    }

    pub fn in_dim(&self) -> usize {
        self.weight.dims()[1]
    }

    pub fn out_dim(&self) -> usize {
        self.weight.dims()[0]
    }

    pub fn forward(&self, x: &Tensor) -> NetResult<Tensor> {
        let product = x.matmul(&self.weight.as_tensor().t()?)?;
        Ok(crate::bias_add::bias_add(&product, self.bias.as_tensor())?)
    }
}

/// An MLP: hidden layers with an activation, then a linear output layer.
#[derive(Debug, Clone)]
pub struct Mlp {
    layers: Vec<Linear>,
    activation: Activation,
}

impl Mlp {
    pub fn new(
        in_dim: usize,
        out_dim: usize,
        config: &MlpConfig,
        output_scale: f64,
        rng: &mut SplitMix64,
        dtype: DType,
    ) -> NetResult<Self> {
        if in_dim == 0 || out_dim == 0 || config.hidden.contains(&0) {
            return Err(NetError::Config(format!(
                "MLP sizes must be positive (in {in_dim}, hidden {:?}, out {out_dim})",
                config.hidden
            )));
        }
        let mut layers = Vec::with_capacity(config.hidden.len() + 1);
        let mut fan_in = in_dim;
        for &width in &config.hidden {
            layers.push(Linear::new(fan_in, width, 1.0, rng, dtype)?);
            fan_in = width;
        }
        layers.push(Linear::new(fan_in, out_dim, output_scale, rng, dtype)?);
        Ok(Self {
            layers,
            activation: config.activation,
        })
    }

    pub fn in_dim(&self) -> usize {
        self.layers[0].in_dim()
    }

    pub fn out_dim(&self) -> usize {
        self.layers[self.layers.len() - 1].out_dim()
    }

    pub fn layers(&self) -> &[Linear] {
        &self.layers
    }

    pub fn output_layer(&self) -> &Linear {
        &self.layers[self.layers.len() - 1]
    }

    pub fn forward(&self, x: &Tensor) -> NetResult<Tensor> {
        let (hidden, output) = self.layers.split_at(self.layers.len() - 1);
        let mut h = x.clone();
        for layer in hidden {
            h = self.activation.apply(&layer.forward(&h)?)?;
        }
        output[0].forward(&h)
    }

    /// Output and d(output)/d(input) for a scalar-output MLP, both [B, ·]. The input gradient is
    /// built from forward ops only (dy/dx = W_1ᵀ diag σ'(z_1) … W_Lᵀ, applied right to left as
    /// row-vector products), so any loss on it is an ordinary first-order graph that candle's
    /// backward differentiates correctly with respect to every weight.
    pub fn forward_with_input_gradient(&self, x: &Tensor) -> NetResult<(Tensor, Tensor)> {
        if self.out_dim() != 1 {
            return Err(NetError::Config(format!(
                "input gradient needs a scalar output, this MLP has {}",
                self.out_dim()
            )));
        }
        let (hidden, output) = self.layers.split_at(self.layers.len() - 1);
        let mut pre_activations = Vec::with_capacity(hidden.len());
        let mut h = x.clone();
        for layer in hidden {
            let z = layer.forward(&h)?;
            h = self.activation.apply(&z)?;
            pre_activations.push(z);
        }
        let y = output[0].forward(&h)?;
        let batch = x.dim(0)?;
        // Row vector dy/dh_{L-1} = W_L (1 × H), the same for every sample.
        let mut g = output[0]
            .weight
            .as_tensor()
            .broadcast_as((batch, output[0].in_dim()))?;
        for (layer, z) in hidden.iter().zip(&pre_activations).rev() {
            g = (g * self.activation.derivative(z)?)?.matmul(layer.weight.as_tensor())?;
        }
        Ok((y, g))
    }

    /// Parameters named PyTorch-style under `prefix`: `{prefix}.layers.{i}.weight|bias`.
    pub fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        self.layers
            .iter()
            .enumerate()
            .flat_map(|(i, l)| {
                [
                    (format!("{prefix}.layers.{i}.weight"), l.weight.clone()),
                    (format!("{prefix}.layers.{i}.bias"), l.bias.clone()),
                ]
            })
            .collect()
    }

    /// Weight matrices only (for weight decay / regularisers that skip biases).
    pub fn weights(&self) -> Vec<&Var> {
        self.layers.iter().map(|l| &l.weight).collect()
    }
}

/// Rows of `width` floats as a [rows, width] tensor on the CPU.
pub fn rows_tensor(data: &[f32], width: usize) -> NetResult<Tensor> {
    if width == 0 || data.len() % width != 0 {
        return Err(NetError::RaggedRows {
            len: data.len(),
            width,
        });
    }
    Ok(Tensor::from_slice(
        data,
        (data.len() / width, width),
        &Device::Cpu,
    )?)
}
