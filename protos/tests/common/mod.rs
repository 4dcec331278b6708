//! Shared fixtures: a tiny deterministic PRNG and one realistic, valid message of each type.

// Each test binary uses a different subset of these helpers.
#![allow(dead_code)]

use std::collections::BTreeMap;

use lhm_protos::{
    ActorState, ActorStatus, EpisodeFrames, EpisodeStats, LabelReply, LabelRequest, Metrics,
    Normalizer, PolicyWeights, Role, Stage, TrajectoryChunk, WireMessage,
};

/// splitmix64: deterministic, dependency-free, good enough for fixtures and fuzzing.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `0..n` (n > 0); the modulo bias is irrelevant here.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    /// Uniform in [-1, 1).
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 23) as f32 - 1.0
    }

    pub fn floats(&mut self, n: usize, scale: f32) -> Vec<f32> {
        (0..n).map(|_| self.unit() * scale).collect()
    }

    pub fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.next_u64() as u8).collect()
    }
}

pub const NUM_STEPS: u32 = 32;
pub const OBS_DIM: u32 = 8;
pub const ACT_DIM: u32 = 3;
pub const AMP_DIM: u32 = 5;

/// 32 steps of one env: an episode ends terminally at step 19 and the next is truncated at 31.
pub fn sample_chunk() -> TrajectoryChunk {
    let mut rng = Rng::new(1);
    let n = NUM_STEPS as usize;
    let mut dones = vec![false; n];
    dones[19] = true;
    let mut truncated = vec![false; n];
    truncated[31] = true;
    let mut truncation_values = vec![0.0; n];
    truncation_values[31] = 4.25;
    TrajectoryChunk {
        run_id: "run-2024-06-01-a".into(),
        actor_id: "actor-03".into(),
        role: Role::Teacher1.into(),
        policy_version: 117,
        chunk_seq: 42,
        env_index: 5,
        num_steps: NUM_STEPS,
        obs_dim: OBS_DIM,
        act_dim: ACT_DIM,
        amp_dim: AMP_DIM,
        observations: rng.floats(n * OBS_DIM as usize, 3.0),
        actions: rng.floats(n * ACT_DIM as usize, 1.0),
        log_probs: (0..n).map(|_| -2.0 + rng.unit()).collect(),
        values: rng.floats(n, 10.0),
        rewards: rng.floats(n, 0.5),
        dones,
        truncated,
        truncation_values,
        amp_features: rng.floats(n * AMP_DIM as usize, 2.0),
        gait_stopped: (0..n).map(|t| t >= 24).collect(),
        gait_ramping: (0..n).map(|t| t < 6).collect(),
        bootstrap_value: 3.5,
        episodes: vec![EpisodeStats {
            episode_return: 12.75,
            length: 500,
            cycles_attempted: 2,
            cycles_succeeded: 1,
            final_placement_error_m: vec![0.012, 0.31],
            fell: false,
            physics_invalid: false,
            task_id: "shelf-pick-07".into(),
            reached: true,
            demo_start: false,
            reward_terms: [
                ("locomotion".to_string(), 12.5),
                ("power".to_string(), -3.25),
            ]
            .into_iter()
            .collect(),
        }],
        ..TrajectoryChunk::versioned()
    }
}

pub fn sample_weights() -> PolicyWeights {
    let mut rng = Rng::new(2);
    // A real (tiny) safetensors file: u64 LE header length, JSON header, 2x2 f32 tensor.
    let header = br#"{"pi.w":{"dtype":"F32","shape":[2,2],"data_offsets":[0,16]}}"#;
    let mut safetensors = (header.len() as u64).to_le_bytes().to_vec();
    safetensors.extend_from_slice(header);
    for v in [0.5f32, -1.0, 0.25, 2.0] {
        safetensors.extend_from_slice(&v.to_le_bytes());
    }
    let normalizer = |rng: &mut Rng, dim: usize| Normalizer {
        count: 1.5e7,
        mean: rng.floats(dim, 1.0),
        var: (0..dim).map(|_| 1.0 + rng.unit().abs()).collect(),
        epsilon: 1e-5,
        clip: 5.0,
    };
    PolicyWeights {
        run_id: "run-2024-06-01-a".into(),
        role: Role::Student.into(),
        version: 118,
        safetensors,
        obs_normalizer: Some(normalizer(&mut rng, OBS_DIM as usize)),
        amp_normalizer: Some(normalizer(&mut rng, AMP_DIM as usize)),
        config_json: r#"{"hidden":[256,256],"activation":"elu"}"#.into(),
        ..PolicyWeights::versioned()
    }
}

pub const NUM_STATES: u32 = 16;

pub fn sample_label_request() -> LabelRequest {
    let mut rng = Rng::new(3);
    let n = NUM_STATES as usize;
    LabelRequest {
        run_id: "run-2024-06-01-a".into(),
        request_id: 9001,
        student_version: 118,
        num_states: NUM_STATES,
        obs_dim: OBS_DIM,
        observations: rng.floats(n * OBS_DIM as usize, 3.0),
        stages: (0..n)
            .map(|i| {
                if i < 6 {
                    Stage::FirstCycle
                } else {
                    Stage::NextCycle
                }
                .into()
            })
            .collect(),
        ..LabelRequest::versioned()
    }
}

pub fn sample_label_reply() -> LabelReply {
    let mut rng = Rng::new(4);
    let n = NUM_STATES as usize;
    LabelReply {
        request_id: 9001,
        num_states: NUM_STATES,
        act_dim: ACT_DIM,
        actions: rng.floats(n * ACT_DIM as usize, 1.0),
        teachers: (0..n)
            .map(|i| {
                if i < 6 {
                    Role::Teacher1
                } else {
                    Role::Teacher2
                }
                .into()
            })
            .collect(),
        teacher_versions: (0..n).map(|i| if i < 6 { 80 } else { 95 }).collect(),
        error: String::new(),
        ..LabelReply::versioned()
    }
}

pub fn sample_actor_status() -> ActorStatus {
    ActorStatus {
        run_id: "run-2024-06-01-a".into(),
        actor_id: "actor-03".into(),
        role: Role::Teacher2.into(),
        state: ActorState::Running.into(),
        policy_version: 117,
        num_envs: 64,
        env_steps_total: 12_345_678,
        chunks_sent: 6_000,
        hostname: "gpu-node-7".into(),
        pid: 31_337,
        ..ActorStatus::versioned()
    }
}

pub fn sample_metrics() -> Metrics {
    let values = BTreeMap::from([
        ("loss/policy".to_string(), -0.0123),
        ("loss/value".to_string(), 0.87),
        ("episode/return_mean".to_string(), 153.2),
        ("amp/disc_accuracy".to_string(), 0.61),
    ]);
    Metrics {
        run_id: "run-2024-06-01-a".into(),
        process: "learner".into(),
        unix_time_ms: 1_717_200_000_123,
        iteration: 2_500,
        values,
        ..Metrics::versioned()
    }
}

pub const NUM_FRAMES: u32 = 6;
pub const NUM_BODIES: u32 = 4;
pub const NUM_OBJECTS: u32 = 2;

/// Six frames of a four-body character and two objects; rotations are unit quaternions.
pub fn sample_episode_frames() -> EpisodeFrames {
    let mut rng = Rng::new(6);
    let unit_quats = |rng: &mut Rng, n: usize| -> Vec<f32> {
        (0..n)
            .flat_map(|_| {
                let q = [rng.unit(), rng.unit(), rng.unit(), 1.0 + rng.unit().abs()];
                let norm = q.iter().map(|x| x * x).sum::<f32>().sqrt();
                q.map(|x| x / norm)
            })
            .collect()
    };
    let (f, b, o) = (
        NUM_FRAMES as usize,
        NUM_BODIES as usize,
        NUM_OBJECTS as usize,
    );
    EpisodeFrames {
        run_id: "run-2024-06-01-a".into(),
        actor_id: "actor-03".into(),
        role: Role::Teacher1.into(),
        policy_version: 117,
        task_id: "train-0001".into(),
        frame_dt: 1.0 / 30.0,
        num_frames: NUM_FRAMES,
        num_bodies: NUM_BODIES,
        num_objects: NUM_OBJECTS,
        body_positions: rng.floats(f * b * 3, 2.0),
        body_rotations: unit_quats(&mut rng, f * b),
        object_positions: rng.floats(f * o * 3, 2.0),
        object_rotations: unit_quats(&mut rng, f * o),
        stats: Some(EpisodeStats {
            episode_return: 3.5,
            length: NUM_FRAMES,
            cycles_attempted: 1,
            cycles_succeeded: 0,
            final_placement_error_m: vec![0.8],
            fell: false,
            physics_invalid: false,
            task_id: "train-0001".into(),
            // The new fields are exercised by the chunk sample; here they keep their defaults, so
            // the bit-flip rejection threshold below stays measured on the same bytes.
            reached: false,
            demo_start: false,
            reward_terms: Default::default(),
        }),
        ..EpisodeFrames::versioned()
    }
}
