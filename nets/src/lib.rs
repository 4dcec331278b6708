//! Candle networks shared by every process: MLPs, the Gaussian policy, value and discriminator
//! networks, an observation normaliser, Adam with checkpointable moments, and the checkpoint file
//! format. Depends on candle only (no simulator).

mod activation;
mod actor_critic;
pub mod adam;
mod bias_add;
pub mod checkpoint;
mod error;
mod fused_elu;
mod mlp;
mod normalizer;
mod policy;
mod rng;
pub mod vla;

pub use activation::Activation;
pub use actor_critic::{ActOutput, ActorCritic, ActorCriticConfig};
pub use adam::{Adam, AdamConfig};
pub use error::{NetError, NetResult};
pub use mlp::{rows_tensor, Linear, Mlp, MlpConfig};
pub use normalizer::RunningMeanStd;
pub use policy::{Discriminator, GaussianPolicy, GaussianPolicyConfig, LogStd, ValueNet};
pub use rng::SplitMix64;
pub use vla::{VlaEncoder, VlaEncoderConfig};
