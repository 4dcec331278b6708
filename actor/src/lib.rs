//! The stateless actor: [`rollout`] turns a policy and a batch of environments into fixed-length
//! trajectory chunks (no networking, so it is testable and benchmarkable alone); [`service`] puts
//! it on Zenoh — weights in, chunks out, a liveliness token, a clean stop on SIGTERM — with
//! [`labels`] asking the dagger-server for a student's teacher labels; [`eval`]
//! scores a policy on benchmark tasks with the paper's metrics, and [`agreement`] a VLA against
//! the policy it was distilled from.

pub mod agreement;
pub mod eval;
pub mod labels;
pub mod rollout;
pub mod service;

pub use rollout::{Behaviour, Labeller, Rollout, RolloutError};
pub use service::{run_actor, ActorConfig, ActorSummary};
