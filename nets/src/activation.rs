//! Hidden-layer activations, with their derivatives written as ordinary forward ops.

use candle_core::Tensor;
use serde::{Deserialize, Serialize};

use crate::NetResult;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    #[default]
    Elu,
    Relu,
}

impl Activation {
    pub fn apply(self, z: &Tensor) -> NetResult<Tensor> {
        Ok(match self {
            Activation::Elu => crate::fused_elu::elu(z)?,
            Activation::Relu => z.relu()?,
        })
    }

    /// σ'(z) built from first-order ops, so a loss that contains it (the AMP gradient penalty) can
    /// be differentiated by one ordinary backward pass. Candle's gradient-of-a-gradient is wrong,
    /// which is why this exists at all.
    pub fn derivative(self, z: &Tensor) -> NetResult<Tensor> {
        Ok(match self {
            // ELU'(z) = 1 for z > 0, e^z otherwise = exp(min(z, 0)) = exp(-relu(-z)).
            Activation::Elu => z.neg()?.relu()?.neg()?.exp()?,
            // A constant mask: comparisons carry no gradient, and ReLU'' is zero anyway.
            Activation::Relu => z.gt(0.0)?.to_dtype(z.dtype())?,
        })
    }
}
