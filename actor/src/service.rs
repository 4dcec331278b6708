//! The actor process: connect, fetch the latest weights, simulate, publish chunks, swap weights
//! between chunks, stop cleanly on SIGTERM.

use std::time::{Duration, Instant};

use lhm_cluster::session::open_session_retrying;
use lhm_cluster::{decode_policy, shutdown, ClusterError, Endpoints, NodeMode, ReceivedPolicy};
use lhm_protos::{keys, Metrics, Role, WireMessage};
use lhm_scenes::Benchmark;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::Wait;

use crate::labels::DaggerLabels;
use crate::rollout::{Behaviour, Rollout, RolloutError};

#[derive(Debug, Clone)]
pub struct ActorConfig {
    pub endpoints: Endpoints,
    pub run_id: String,
    pub role: Role,
    /// Unique among the run's processes; default `actor-<host>-<pid>`.
    pub actor_id: String,
    pub envs: usize,
    pub seed: u64,
    /// Stop after this many chunks sent (benchmarks, tests); `None`: until SIGTERM.
    pub max_chunks: Option<u64>,
    /// Build chunks but do not put them (the benchmark's no-publishing baseline).
    pub publish: bool,
    /// The benchmark's task files from this directory instead of the copy built in.
    pub scenes: Option<std::path::PathBuf>,
}

impl ActorConfig {
    pub fn default_actor_id() -> String {
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .map(|h| h.trim().to_owned())
            .unwrap_or_else(|_| "host".into());
        let host: String = host
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        format!("actor-{host}-{}", std::process::id())
    }
}

#[derive(Debug, Clone, Default, PartialEq)]
pub struct ActorSummary {
    pub chunks_sent: u64,
    pub env_steps: u64,
    pub poisoned_chunks: u64,
    pub policy_swaps: u64,
    pub last_version: u64,
    /// Times the actor paused because its learner was gone.
    pub learner_pauses: u64,
    /// Seconds spent simulating and acting (excludes waiting for the first weights).
    pub busy_s: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum ActorError {
    #[error(transparent)]
    Cluster(#[from] ClusterError),
    #[error(transparent)]
    Rollout(#[from] RolloutError),
    #[error("benchmark scenes: {0}")]
    Scenes(String),
    #[error("stopped before any weights arrived")]
    NoWeights,
}

fn zerr(e: impl std::fmt::Display) -> ClusterError {
    ClusterError::zenoh(e)
}

/// Asks the learner's queryable for the latest weights (`None` if nobody answered in time).
fn query_latest(
    session: &zenoh::Session,
    key: &str,
) -> Result<Option<ReceivedPolicy>, ClusterError> {
    let replies = session
        .get(key)
        .timeout(Duration::from_secs(3))
        .wait()
        .map_err(zerr)?;
    let mut newest: Option<ReceivedPolicy> = None;
    while let Ok(reply) = replies.recv() {
        let Ok(sample) = reply.result() else { continue };
        match decode_policy(&sample.payload().to_bytes()) {
            Ok(p) if newest.as_ref().is_none_or(|n| p.version > n.version) => newest = Some(p),
            Ok(_) => {}
            Err(e) => tracing::warn!("ignoring a weights reply: {e}"),
        }
    }
    Ok(newest)
}

/// How long an actor that sent its share of a version waits for the next one before it runs
/// on (a learner that lost another actor still gets data).
const SYNC_WAIT: Duration = Duration::from_secs(20);

/// Waits up to `limit` for weights newer than `version` (`None`: none came, or a stop request).
fn wait_for_newer(
    weights_sub: &zenoh::pubsub::Subscriber<
        zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>,
    >,
    version: u64,
    limit: Duration,
) -> Option<ReceivedPolicy> {
    let until = Instant::now() + limit;
    while Instant::now() < until && !shutdown::requested() {
        if let Ok(Some(sample)) = weights_sub.recv_timeout(Duration::from_millis(50)) {
            match decode_policy(&sample.payload().to_bytes()) {
                Ok(p) if p.version > version => return Some(p),
                Ok(_) => {}
                Err(e) => tracing::warn!("ignoring weights: {e}"),
            }
        }
    }
    None
}

/// How long the learner's liveliness token may be gone before the actor pauses: a restart of
/// the learner on the same machine takes longer, a network hiccup less.
pub const LEARNER_GONE_AFTER: Duration = Duration::from_secs(5);

type LivelinessSub =
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;

/// Watches the run's learner through its liveliness token (`keys::status(run, "learner")`),
/// which zenoh withdraws when the learner's process or its link dies.
struct LearnerWatch {
    sub: LivelinessSub,
    gone_since: Option<Instant>,
}

impl LearnerWatch {
    fn new(session: &zenoh::Session, run_id: &str) -> Result<Self, ActorError> {
        let sub = session
            .liveliness()
            .declare_subscriber(keys::status(run_id, "learner"))
            .history(true)
            .wait()
            .map_err(zerr)?;
        // The actor has the learner's weights: it is there, whether or not the token's history
        // has arrived yet.
        Ok(Self {
            sub,
            gone_since: None,
        })
    }

    /// Takes the queued token changes; whether the learner has been gone longer than
    /// `LEARNER_GONE_AFTER`.
    fn gone(&mut self) -> bool {
        while let Ok(Some(sample)) = self.sub.try_recv() {
            self.apply(sample.kind());
        }
        self.gone_since
            .is_some_and(|t| t.elapsed() >= LEARNER_GONE_AFTER)
    }

    fn apply(&mut self, kind: zenoh::sample::SampleKind) {
        match kind {
            zenoh::sample::SampleKind::Put => self.gone_since = None,
            zenoh::sample::SampleKind::Delete => {
                self.gone_since.get_or_insert_with(Instant::now);
            }
        }
    }

    /// Blocks, simulating nothing and sending nothing, until the learner's token is back or a
    /// stop is requested; whether it came back.
    fn wait_back(&mut self) -> bool {
        while !shutdown::requested() {
            match self.sub.recv_timeout(Duration::from_millis(200)) {
                Ok(Some(sample)) => {
                    self.apply(sample.kind());
                    if self.gone_since.is_none() {
                        return true;
                    }
                }
                Ok(None) => {}
                // The subscriber is gone (session closing): wait like a timeout would, not spin.
                Err(_) => std::thread::sleep(Duration::from_millis(200)),
            }
        }
        false
    }
}

/// The frozen Teacher 1 a Teacher 2 learner serves on the run's `teacher1` policy key.
fn fetch_teacher1(session: &zenoh::Session, run_id: &str) -> Result<ReceivedPolicy, ActorError> {
    let key = keys::policy(run_id, Role::Teacher1);
    tracing::info!("waiting for Teacher 1's weights on {key}");
    loop {
        if shutdown::requested() {
            return Err(ActorError::NoWeights);
        }
        if let Some(p) = query_latest(session, &key)? {
            return Ok(p);
        }
    }
}

pub fn run_actor(config: &ActorConfig) -> Result<ActorSummary, ActorError> {
    keys::check_chunk("run id", &config.run_id).map_err(ClusterError::from)?;
    keys::check_chunk("actor id", &config.actor_id).map_err(ClusterError::from)?;
    let bench = match &config.scenes {
        Some(dir) => Benchmark::load_dir(dir)
            .map_err(|e| ActorError::Scenes(format!("{}: {e}", dir.display())))?,
        None => Benchmark::embedded().map_err(|e| ActorError::Scenes(e.to_string()))?,
    };
    let session = open_session_retrying(
        NodeMode::Client,
        &config.endpoints,
        Duration::from_millis(500),
        || !shutdown::requested(),
    )?;
    let token = session
        .liveliness()
        .declare_token(keys::status(&config.run_id, &config.actor_id))
        .wait()
        .map_err(zerr)?;
    let policy_key = keys::policy(&config.run_id, config.role);
    let weights_sub = session
        .declare_subscriber(&policy_key)
        .wait()
        .map_err(zerr)?;
    tracing::info!(
        "actor {} waiting for {} weights",
        config.actor_id,
        keys::role_chunk(config.role)
    );
    let mut policy = loop {
        if shutdown::requested() {
            return Err(ActorError::NoWeights);
        }
        if let Ok(Some(sample)) = weights_sub.try_recv() {
            match decode_policy(&sample.payload().to_bytes()) {
                Ok(p) => break p,
                Err(e) => tracing::warn!("ignoring weights: {e}"),
            }
        }
        if let Some(p) = query_latest(&session, &policy_key)? {
            break p;
        }
    };
    tracing::info!(
        "actor {}: policy version {}, {} envs",
        config.actor_id,
        policy.version,
        config.envs
    );
    let teacher1 = if config.role == Role::Teacher2 {
        Some(fetch_teacher1(&session, &config.run_id)?.actor_critic)
    } else {
        None
    };
    let mut rollout = Rollout::with_teacher1(
        policy.spec.clone(),
        &bench,
        &config.run_id,
        &config.actor_id,
        config.role,
        config.envs,
        config.seed,
        teacher1,
    )?;
    let traj = session
        .declare_publisher(keys::trajectory(
            &config.run_id,
            config.role,
            &config.actor_id,
        ))
        .congestion_control(CongestionControl::Block)
        .priority(Priority::Data)
        .wait()
        .map_err(zerr)?;
    let metrics_key = keys::metrics(&config.run_id, &config.actor_id);
    let episode_key = keys::episode(&config.run_id, config.role, &config.actor_id);
    let mut summary = ActorSummary {
        last_version: policy.version,
        ..ActorSummary::default()
    };
    let started = Instant::now();
    let mut sets_at_version = 0u32;
    let mut version_counted = policy.version;
    let mut last_metrics = Instant::now();
    let mut steps_at_metrics = 0u64;
    let mut learner = LearnerWatch::new(&session, &config.run_id)?;
    // A student (and the VLA student) acts on its own weights, mixed with its labeller's, and
    // sends the labels.
    let mut labels = matches!(config.role, Role::Student | Role::Vla)
        .then(|| DaggerLabels::new(&session, &config.run_id));
    loop {
        // A stop request between steps drops the unfinished chunk: nothing partial is sent.
        if shutdown::requested() {
            break;
        }
        if config.max_chunks.is_some_and(|m| summary.chunks_sent >= m) {
            break;
        }
        if rollout.at_chunk_boundary() && learner.gone() {
            // Simulating for no one costs a core and publishes into the void: pause until the
            // learner (or its restart) is back, then take its weights.
            let gone_at = Instant::now();
            tracing::warn!(
                "learner of run {} gone for {} s: actor {} pauses (no simulation, nothing sent) until it is back",
                config.run_id,
                LEARNER_GONE_AFTER.as_secs(),
                config.actor_id
            );
            if !learner.wait_back() {
                break;
            }
            tracing::info!(
                "learner of run {} back after {:.0} s: actor {} resumes",
                config.run_id,
                gone_at.elapsed().as_secs_f64() + LEARNER_GONE_AFTER.as_secs_f64(),
                config.actor_id
            );
            summary.learner_pauses += 1;
        }
        if rollout.at_chunk_boundary() {
            let mut newest = None;
            while let Ok(Some(sample)) = weights_sub.try_recv() {
                newest = Some(sample);
            }
            if let Some(sample) = newest {
                match decode_policy(&sample.payload().to_bytes()) {
                    Ok(p) if p.version != policy.version => {
                        if p.spec != policy.spec {
                            rollout.set_spec(p.spec.clone())?;
                        }
                        policy = p;
                        summary.policy_swaps += 1;
                        summary.last_version = policy.version;
                    }
                    Ok(_) => {}
                    Err(e) => tracing::warn!("ignoring weights: {e}"),
                }
            }
        }
        let stepped = match labels.as_mut() {
            Some(labeller) => {
                labeller.student_version = policy.version;
                rollout.step_with(
                    Behaviour::Dagger {
                        student: &policy.actor_critic,
                        labeller,
                        teacher_mix: policy.spec.teacher_mix,
                    },
                    policy.version,
                )
            }
            None => rollout.step(&policy.actor_critic, policy.version),
        };
        let out = match stepped {
            // Stopped while waiting for labels: a clean stop, the unfinished chunk dropped.
            Err(RolloutError::Labels(_)) if shutdown::requested() => break,
            other => other?,
        };
        if let (true, Some(frames)) = (config.publish, out.episode_frames.as_ref()) {
            // Sampled episodes are for people to look at: they may be dropped under congestion.
            if let Ok(bytes) = frames.encode_checked() {
                let _ = session
                    .put(&episode_key, bytes)
                    .congestion_control(CongestionControl::Drop)
                    .priority(Priority::DataLow)
                    .wait();
            }
        }
        summary.poisoned_chunks += out.poisoned_chunks;
        let emitted_set = !out.chunks.is_empty() || out.poisoned_chunks > 0;
        for chunk in out.chunks {
            if config.publish {
                let bytes = chunk.encode_checked().map_err(ClusterError::from)?;
                traj.put(bytes).wait().map_err(zerr)?;
            }
            summary.chunks_sent += 1;
        }
        if emitted_set {
            sets_at_version += 1;
            let quota = policy.spec.chunk_sets_per_version;
            if quota > 0 && sets_at_version >= quota {
                if let Some(p) = wait_for_newer(&weights_sub, policy.version, SYNC_WAIT) {
                    if p.spec != policy.spec {
                        rollout.set_spec(p.spec.clone())?;
                    }
                    policy = p;
                    summary.policy_swaps += 1;
                    summary.last_version = policy.version;
                }
            }
        }
        if policy.version != version_counted {
            version_counted = policy.version;
            sets_at_version = 0;
        }
        if last_metrics.elapsed() >= Duration::from_secs(5) {
            let dt = last_metrics.elapsed().as_secs_f64();
            let mut m = Metrics {
                run_id: config.run_id.clone(),
                process: config.actor_id.clone(),
                unix_time_ms: lhm_cluster::clock::unix_ms(),
                iteration: policy.version,
                ..Metrics::versioned()
            };
            m.values.insert(
                "env_steps_per_s".into(),
                (rollout.env_steps - steps_at_metrics) as f64 / dt,
            );
            m.values
                .insert("chunks_sent".into(), summary.chunks_sent as f64);
            if config.role == Role::Teacher2 {
                // Teacher 1's share of the simulation, and its episodes dropped for a fall.
                m.values
                    .insert("teacher1_steps".into(), rollout.teacher1_steps as f64);
                m.values
                    .insert("teacher1_failures".into(), rollout.teacher1_failures as f64);
            }
            if let Ok(bytes) = m.encode_checked() {
                // Telemetry may be dropped under congestion; training data may not.
                let _ = session
                    .put(&metrics_key, bytes)
                    .congestion_control(CongestionControl::Drop)
                    .priority(Priority::DataLow)
                    .wait();
            }
            steps_at_metrics = rollout.env_steps;
            last_metrics = Instant::now();
        }
    }
    summary.env_steps = rollout.env_steps;
    summary.busy_s = started.elapsed().as_secs_f64();
    drop(traj);
    let _ = token.undeclare().wait();
    let _ = session.close().wait();
    tracing::info!(
        "actor {} stopped: {} chunks sent, {} env steps",
        config.actor_id,
        summary.chunks_sent,
        summary.env_steps
    );
    Ok(summary)
}
