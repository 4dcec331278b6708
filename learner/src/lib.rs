//! The learner's update algorithms: GAE, PPO and the adversarial motion prior (AMP), the learner
//! state with its checkpoint, and throughput measurements for the benchmark.

pub mod amp;
pub mod bench;
pub mod dagger;
pub mod error;
pub mod gae;
pub mod ppo;
pub mod sac;
pub mod service;
pub mod state;

pub use amp::{
    style_reward_from_logit, AccuracyTarget, AmpConfig, AmpStats, AmpTrainer, ReplayBuffer,
};
pub use error::{LearnerError, LearnerResult};
pub use gae::{compute_gae, GaeInput, GaeOutput, GaeParams};
pub use ppo::{PpoBatch, PpoConfig, PpoStats, PpoTrainer};
pub use state::{AmpSetup, Counters, Learner, LearnerConfig, CHECKPOINT_KIND};
