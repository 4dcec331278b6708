//! What arrives on the trajectory key, sorted into what an update may use and what it must not:
//! malformed bytes, other schema versions, invalid or mismatched chunks (rejected and counted by
//! reason), and chunks too old for the current policy (dropped and counted).

use lhm_protos::{Role, TrajectoryChunk, WireError, WireMessage};
use serde::Serialize;

use lhm_cluster::RunSpec;

/// Counters of the learner's intake, written to `status.json` and the metrics.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct IntakeCounters {
    pub accepted: u64,
    pub accepted_steps: u64,
    pub stale: u64,
    pub malformed: u64,
    pub wrong_version: u64,
    pub invalid: u64,
    /// Well-formed chunks of another run, role or network shape.
    pub mismatched: u64,
}

impl IntakeCounters {
    pub fn rejected(&self) -> u64 {
        self.malformed + self.wrong_version + self.invalid + self.mismatched
    }
}

/// The verdict on one message.
#[derive(Debug, PartialEq)]
pub enum Intake {
    Accepted(Box<TrajectoryChunk>),
    Stale { version: u64, actor_id: String },
    Rejected(String),
}

/// Decodes and checks one message against the run; updates `counters`.
pub fn admit(
    bytes: &[u8],
    run_id: &str,
    role: Role,
    spec: &RunSpec,
    current_version: u64,
    max_lag: u64,
    counters: &mut IntakeCounters,
) -> Intake {
    let chunk = match TrajectoryChunk::decode_checked(bytes) {
        Ok(c) => c,
        Err(e) => {
            match e {
                WireError::WrongVersion { .. } => counters.wrong_version += 1,
                WireError::Malformed { .. } => counters.malformed += 1,
                _ => counters.invalid += 1,
            }
            return Intake::Rejected(e.to_string());
        }
    };
    let mismatch = if chunk.run_id != run_id {
        Some(format!("run {:?}, not {run_id:?}", chunk.run_id))
    } else if chunk.role != role as i32 {
        Some(format!("role {}, not {}", chunk.role, role as i32))
    } else if chunk.obs_dim as usize != spec.obs_dim
        || chunk.act_dim as usize != spec.act_dim
        || chunk.amp_dim as usize != spec.amp_dim
    {
        Some(format!(
            "shape obs {} act {} amp {}, expected {} {} {}",
            chunk.obs_dim, chunk.act_dim, chunk.amp_dim, spec.obs_dim, spec.act_dim, spec.amp_dim
        ))
    } else {
        None
    };
    if let Some(why) = mismatch {
        counters.mismatched += 1;
        return Intake::Rejected(format!("chunk from {}: {why}", chunk.actor_id));
    }
    // Older than the allowed lag, or from a version this learner never published (an actor that
    // outlived a learner restart from an earlier checkpoint).
    if chunk.policy_version > current_version || current_version - chunk.policy_version > max_lag {
        counters.stale += 1;
        return Intake::Stale {
            version: chunk.policy_version,
            actor_id: chunk.actor_id,
        };
    }
    counters.accepted += 1;
    counters.accepted_steps += u64::from(chunk.num_steps);
    Intake::Accepted(Box::new(chunk))
}
