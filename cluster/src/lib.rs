//! The pieces every LHM service shares (DESIGN.md §3): a Zenoh session opened from explicit
//! endpoints (no multicast scouting), the policy weights message and the run spec inside it (so
//! actors need nothing but an endpoint, a run id and a role), and SIGINT/SIGTERM handling.

pub mod clock;
pub mod error;
pub mod session;
pub mod shutdown;
pub mod spec;
pub mod weights;

pub use error::{ClusterError, ClusterResult};
pub use session::{open_session, Endpoints, NodeMode};
pub use spec::{RunSpec, TaskSet};
pub use weights::{decode_policy, encode_policy, ReceivedPolicy};
