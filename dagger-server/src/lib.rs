//! The teacher-label service. Student rollouts send batches of states with their episode stage;
//! the finite-state machine of the paper picks the supervising teacher per state (first cycle →
//! Teacher 1, later cycles → Teacher 2) and the reply carries that teacher's mean action.
//! Teachers are the learners' latest published weights (`policy/teacher1`, `policy/teacher2`),
//! kept current by subscription. DAgger aggregation itself comes with the student pipeline.

use std::sync::{Arc, Mutex};

use lhm_cluster::{decode_policy, ReceivedPolicy};
use lhm_protos::{LabelReply, LabelRequest, Role, Stage, WireMessage};

/// The teachers currently loaded.
#[derive(Default, Clone)]
pub struct Teachers {
    pub teacher1: Option<Arc<ReceivedPolicy>>,
    pub teacher2: Option<Arc<ReceivedPolicy>>,
}

impl Teachers {
    /// Takes a weights message for either teacher; other roles are ignored.
    pub fn update(&mut self, bytes: &[u8]) -> Result<Role, lhm_cluster::ClusterError> {
        let p = decode_policy(bytes)?;
        let role = p.role;
        match role {
            Role::Teacher1 => self.teacher1 = Some(Arc::new(p)),
            Role::Teacher2 => self.teacher2 = Some(Arc::new(p)),
            _ => {}
        }
        Ok(role)
    }
}

/// Which teacher supervises a state (the FSM of the paper's DAgger stage).
pub fn teacher_for(stage: Stage) -> Role {
    match stage {
        Stage::NextCycle => Role::Teacher2,
        Stage::FirstCycle | Stage::Unspecified => Role::Teacher1,
    }
}

/// Answers one encoded `LabelRequest`. Every failure becomes a reply with `error` set (the
/// student must learn why it got no labels), never a panic.
pub fn answer(bytes: &[u8], teachers: &Teachers) -> LabelReply {
    let fail = |request_id: u64, error: String| LabelReply {
        request_id,
        error,
        ..LabelReply::versioned()
    };
    let req = match LabelRequest::decode_checked(bytes) {
        Ok(r) => r,
        Err(e) => return fail(0, format!("bad request: {e}")),
    };
    let n = req.num_states as usize;
    let obs_dim = req.obs_dim as usize;
    let mut actions = Vec::new();
    let mut roles = Vec::with_capacity(n);
    let mut versions = Vec::with_capacity(n);
    let mut act_dim = 0usize;
    for i in 0..n {
        let stage = Stage::try_from(req.stages[i]).unwrap_or(Stage::Unspecified);
        let role = teacher_for(stage);
        let teacher = match role {
            Role::Teacher2 => &teachers.teacher2,
            _ => &teachers.teacher1,
        };
        let Some(teacher) = teacher else {
            return fail(
                req.request_id,
                format!(
                    "no {} weights have been published yet",
                    lhm_protos::keys::role_chunk(role)
                ),
            );
        };
        if teacher.spec.obs_dim != obs_dim {
            return fail(
                req.request_id,
                format!(
                    "states have {obs_dim} observations, {} takes {}",
                    lhm_protos::keys::role_chunk(role),
                    teacher.spec.obs_dim
                ),
            );
        }
        let row = &req.observations[i * obs_dim..(i + 1) * obs_dim];
        match teacher.actor_critic.act_deterministic(row) {
            Ok(a) => {
                act_dim = a.len();
                actions.extend(a);
            }
            Err(e) => return fail(req.request_id, format!("teacher inference: {e}")),
        }
        roles.push(role as i32);
        versions.push(teacher.version);
    }
    LabelReply {
        request_id: req.request_id,
        num_states: req.num_states,
        act_dim: act_dim as u32,
        actions,
        teachers: roles,
        teacher_versions: versions,
        ..LabelReply::versioned()
    }
}

/// Shared, updatable teachers for the queryable callback.
pub type SharedTeachers = Arc<Mutex<Teachers>>;
