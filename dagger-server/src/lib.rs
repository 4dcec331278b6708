//! The teacher-label service. Student rollouts send batches of states with their episode stage;
//! the finite-state machine of the paper picks the supervising teacher per state (first cycle →
//! Teacher 1, later cycles → Teacher 2) and the reply carries that teacher's mean action.
//! Teachers are the weights published on the run's `policy/teacher1` and `policy/teacher2` keys (a
//! student learner serves its two frozen teachers there), kept current by subscription; each
//! teacher labels its rows of a request in one batched forward pass. The server keeps no state:
//! the student's learner aggregates the labelled rows (`lhm_learner::dagger`).

use std::sync::{Arc, Mutex};
use std::time::Duration;

use lhm_cluster::session::open_session_retrying;
use lhm_cluster::{decode_policy, shutdown, ClusterError, Endpoints, NodeMode, ReceivedPolicy};
use lhm_protos::{keys, LabelReply, LabelRequest, Role, Stage, WireMessage};
use zenoh::Wait;

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
    let roles: Vec<Role> = (0..n)
        .map(|i| teacher_for(Stage::try_from(req.stages[i]).unwrap_or(Stage::Unspecified)))
        .collect();
    // One batched forward pass per teacher over the rows it labels, then the rows back in order.
    let mut actions: Vec<f32> = Vec::new();
    let mut versions = vec![0u64; n];
    let mut act_dim = 0usize;
    for role in [Role::Teacher1, Role::Teacher2] {
        let rows: Vec<usize> = (0..n).filter(|&i| roles[i] == role).collect();
        if rows.is_empty() {
            continue;
        }
        let teacher = match role {
            Role::Teacher2 => &teachers.teacher2,
            _ => &teachers.teacher1,
        };
        let Some(teacher) = teacher else {
            return fail(
                req.request_id,
                format!(
                    "{}: no {} weights have been published",
                    lhm_protos::LABEL_ERROR_NO_WEIGHTS,
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
        let batch: Vec<f32> = rows
            .iter()
            .flat_map(|&i| &req.observations[i * obs_dim..(i + 1) * obs_dim])
            .copied()
            .collect();
        let labelled = match teacher.actor_critic.act_deterministic(&batch) {
            Ok(a) => a,
            Err(e) => return fail(req.request_id, format!("teacher inference: {e}")),
        };
        let width = labelled.len() / rows.len();
        if act_dim == 0 {
            act_dim = width;
            actions = vec![0.0; n * act_dim];
        } else if width != act_dim {
            return fail(
                req.request_id,
                format!("the teachers' action sizes differ: {act_dim} and {width}"),
            );
        }
        for (k, &i) in rows.iter().enumerate() {
            actions[i * act_dim..(i + 1) * act_dim]
                .copy_from_slice(&labelled[k * act_dim..(k + 1) * act_dim]);
            versions[i] = teacher.version;
        }
    }
    LabelReply {
        request_id: req.request_id,
        num_states: req.num_states,
        act_dim: act_dim as u32,
        actions,
        teachers: roles.iter().map(|&r| r as i32).collect(),
        teacher_versions: versions,
        ..LabelReply::versioned()
    }
}

/// Labels `rows` made-up states of the teachers' observation size `repeats` times, batched as
/// [`answer`] does and one forward pass per state as it did before, half the states in each
/// cycle: (batched states/s, per-state states/s), the median of `repeats` timings each. For
/// BENCHMARKS.md (`lhm-dagger-server --bench`).
pub fn bench_labels(
    teachers: &Teachers,
    rows: usize,
    repeats: usize,
) -> Result<(f64, f64), String> {
    let t1 = teachers.teacher1.as_ref().ok_or("no teacher1")?;
    let obs_dim = t1.spec.obs_dim;
    let request = LabelRequest {
        run_id: "bench".into(),
        request_id: 1,
        num_states: rows as u32,
        obs_dim: obs_dim as u32,
        // Spread over [-1, 1) without a random number generator.
        observations: (0..rows * obs_dim)
            .map(|i| ((i * 7919) % 2000) as f32 / 1000.0 - 1.0)
            .collect(),
        stages: (0..rows)
            .map(|i| if i % 2 == 0 { Stage::FirstCycle } else { Stage::NextCycle } as i32)
            .collect(),
        ..LabelRequest::versioned()
    };
    let bytes = request.encode_checked().map_err(|e| e.to_string())?;
    let median = |mut xs: Vec<f64>| {
        xs.sort_by(f64::total_cmp);
        xs[xs.len() / 2]
    };
    let mut batched = Vec::new();
    let mut single = Vec::new();
    for _ in 0..repeats.max(1) {
        let start = std::time::Instant::now();
        let reply = answer(&bytes, teachers);
        if !reply.error.is_empty() {
            return Err(reply.error);
        }
        batched.push(rows as f64 / start.elapsed().as_secs_f64());
        let start = std::time::Instant::now();
        for i in 0..rows {
            let teacher =
                match teacher_for(Stage::try_from(request.stages[i]).unwrap_or(Stage::Unspecified))
                {
                    Role::Teacher2 => teachers.teacher2.as_ref().unwrap_or(t1),
                    _ => t1,
                };
            teacher
                .actor_critic
                .act_deterministic(&request.observations[i * obs_dim..(i + 1) * obs_dim])
                .map_err(|e| e.to_string())?;
        }
        single.push(rows as f64 / start.elapsed().as_secs_f64());
    }
    Ok((median(batched), median(single)))
}

/// Shared, updatable teachers for the queryable callback.
pub type SharedTeachers = Arc<Mutex<Teachers>>;

fn zerr(e: impl std::fmt::Display) -> ClusterError {
    ClusterError::zenoh(e)
}

/// Serves `lhm/<run_id>/dagger/label` until SIGTERM/Ctrl-C: connects (waiting for the learner),
/// keeps both teachers' latest weights by subscription (and asks for them once at start), and
/// answers each label query with [`answer`]. A stop while still waiting for the learner is a
/// clean stop.
pub fn serve(endpoints: &Endpoints, run_id: &str) -> Result<(), ClusterError> {
    keys::check_chunk("run id", run_id)?;
    let session = match open_session_retrying(
        NodeMode::Client,
        endpoints,
        Duration::from_millis(500),
        || !shutdown::requested(),
    ) {
        Ok(s) => s,
        Err(e @ ClusterError::Stopped(_)) => {
            tracing::info!("{e}");
            return Ok(());
        }
        Err(e) => return Err(e),
    };
    let teachers = SharedTeachers::default();
    let mut subscribers = Vec::new();
    for role in [Role::Teacher1, Role::Teacher2] {
        let t = teachers.clone();
        let key = keys::policy(run_id, role);
        subscribers.push(
            session
                .declare_subscriber(&key)
                .callback(move |sample| {
                    let bytes = sample.payload().to_bytes();
                    match t.lock().map(|mut t| t.update(&bytes)) {
                        Ok(Ok(role)) => tracing::debug!("new {} weights", keys::role_chunk(role)),
                        Ok(Err(e)) => tracing::warn!("ignoring weights: {e}"),
                        Err(_) => {}
                    }
                })
                .wait()
                .map_err(zerr)?,
        );
        // The latest weights now, rather than at the learner's next update.
        if let Ok(replies) = session.get(&key).timeout(Duration::from_secs(2)).wait() {
            while let Ok(reply) = replies.recv() {
                if let (Ok(sample), Ok(mut t)) = (reply.result(), teachers.lock()) {
                    let _ = t.update(&sample.payload().to_bytes());
                }
            }
        }
    }
    let t = teachers.clone();
    let label_key = keys::dagger_label(run_id);
    let _queryable = session
        .declare_queryable(&label_key)
        .callback(move |query| {
            let bytes = query
                .payload()
                .map(|p| p.to_bytes().to_vec())
                .unwrap_or_default();
            let snapshot = t.lock().map(|t| t.clone()).unwrap_or_default();
            let reply = answer(&bytes, &snapshot);
            match reply.encode_checked() {
                Ok(bytes) => {
                    // A reply travels with the query's QoS: students query with Block and a high
                    // priority so labels are never dropped.
                    if let Err(e) = query.reply(query.key_expr().clone(), bytes).wait() {
                        tracing::warn!("replying to a label query: {e}");
                    }
                }
                Err(e) => tracing::warn!("label reply does not encode: {e}"),
            }
        })
        .wait()
        .map_err(zerr)?;
    let _token = session
        .liveliness()
        .declare_token(keys::status(run_id, "dagger-server"))
        .wait()
        .map_err(zerr)?;
    tracing::info!("dagger-server answering {label_key}");
    while !shutdown::requested() {
        std::thread::sleep(Duration::from_millis(100));
    }
    drop(subscribers);
    session.close().wait().map_err(zerr)
}
