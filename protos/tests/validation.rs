mod common;

use std::fmt::Debug;

use common::*;
use lhm_protos::{
    prost::Message, ActorStatus, EpisodeFrames, LabelReply, LabelRequest, Metrics, Normalizer,
    PolicyWeights, Role, Stage, TrajectoryChunk, WireError, WireMessage, SCHEMA_VERSION,
};

/// Both the receiver (decode_checked) and the sender (encode_checked) reject `message` as
/// `Invalid` naming `field`.
#[track_caller]
fn assert_invalid<M: WireMessage + Debug>(message: M, field: &str) {
    let bytes = message.encode_to_vec();
    match M::decode_checked(&bytes) {
        Err(WireError::Invalid {
            message: name,
            field: got,
            reason,
        }) => {
            assert_eq!(name, M::FULL_NAME);
            assert_eq!(got, field, "wrong field blamed (reason: {reason})");
        }
        other => panic!("expected Invalid {{ field: {field} }}, got {other:?}"),
    }
    assert!(matches!(
        message.encode_checked(),
        Err(WireError::Invalid { field: got, .. }) if got == field
    ));
}

#[track_caller]
fn assert_wrong_version<M: WireMessage + Debug>(mut message: M) {
    for found in [0, SCHEMA_VERSION + 1] {
        message.set_schema_version(found);
        let err = M::decode_checked(&message.encode_to_vec()).unwrap_err();
        assert!(
            matches!(
                err,
                WireError::WrongVersion { message, expected: SCHEMA_VERSION, found: f }
                    if message == M::FULL_NAME && f == found
            ),
            "{err:?}"
        );
        assert!(message.encode_checked().is_err());
    }
}

#[test]
fn wrong_versions_are_rejected() {
    assert_wrong_version(sample_chunk());
    assert_wrong_version(sample_weights());
    assert_wrong_version(sample_label_request());
    assert_wrong_version(sample_label_reply());
    assert_wrong_version(sample_actor_status());
    assert_wrong_version(sample_metrics());
    assert_wrong_version(sample_episode_frames());
}

#[test]
fn empty_input_is_an_unversioned_message() {
    // proto3 decodes zero bytes as the default message: version 0, which must not be accepted.
    assert!(matches!(
        TrajectoryChunk::decode_checked(&[]),
        Err(WireError::WrongVersion { found: 0, .. })
    ));
}

#[test]
fn malformed_bytes_are_reported_as_such() {
    let bytes = sample_chunk().encode_to_vec();
    let err = TrajectoryChunk::decode_checked(&bytes[..bytes.len() - 1]).unwrap_err();
    assert!(matches!(
        err,
        WireError::Malformed {
            message: "lhm.v1.TrajectoryChunk",
            ..
        }
    ));
    assert!(std::error::Error::source(&err).is_some());
}

#[test]
fn error_display_names_message_and_field() {
    let chunk = TrajectoryChunk {
        observations: vec![0.0; 3],
        ..sample_chunk()
    };
    let text = chunk.check().unwrap_err().to_string();
    assert_eq!(
        text,
        "lhm.v1.TrajectoryChunk.observations: has 3 elements, expected 32 * 8 = 256"
    );
    let text = TrajectoryChunk::decode_checked(&[])
        .unwrap_err()
        .to_string();
    assert_eq!(
        text,
        "lhm.v1.TrajectoryChunk.schema_version: got 0, expected 1"
    );
}

#[test]
fn chunk_shape_mismatches_are_rejected() {
    let c = sample_chunk;
    let mut m = c();
    m.observations.pop();
    assert_invalid(m, "observations");
    let mut m = c();
    m.actions.push(0.0);
    assert_invalid(m, "actions");
    let mut m = c();
    m.amp_features.clear();
    assert_invalid(m, "amp_features");
    let mut m = c();
    m.log_probs.pop();
    assert_invalid(m, "log_probs");
    let mut m = c();
    m.values.push(1.0);
    assert_invalid(m, "values");
    let mut m = c();
    m.rewards.clear();
    assert_invalid(m, "rewards");
    let mut m = c();
    m.dones.pop();
    assert_invalid(m, "dones");
    let mut m = c();
    m.truncated.push(false);
    assert_invalid(m, "truncated");
    let mut m = c();
    m.truncation_values.pop();
    assert_invalid(m, "truncation_values");
    let mut m = c();
    m.gait_stopped.pop();
    assert_invalid(m, "gait_stopped");
    let mut m = c();
    m.gait_ramping.push(true);
    assert_invalid(m, "gait_ramping");
    // No gait: no flags at all is valid.
    let m = TrajectoryChunk {
        gait_stopped: vec![],
        gait_ramping: vec![],
        ..c()
    };
    let decoded = TrajectoryChunk::decode_checked(&m.encode_to_vec());
    assert!(decoded.is_ok(), "{decoded:?}");
    // Dimensions that disagree with the data.
    assert_invalid(
        TrajectoryChunk {
            num_steps: 31,
            ..c()
        },
        "observations",
    );
    assert_invalid(TrajectoryChunk { obs_dim: 7, ..c() }, "observations");
    assert_invalid(TrajectoryChunk { amp_dim: 0, ..c() }, "amp_features");
    assert_invalid(
        TrajectoryChunk {
            num_steps: 0,
            ..c()
        },
        "num_steps",
    );
    assert_invalid(TrajectoryChunk { obs_dim: 0, ..c() }, "obs_dim");
    assert_invalid(TrajectoryChunk { act_dim: 0, ..c() }, "act_dim");
    // Products that would overflow u32 (and usize on 32-bit targets) must not panic.
    let huge = TrajectoryChunk {
        num_steps: u32::MAX,
        obs_dim: u32::MAX,
        ..c()
    };
    assert_invalid(huge, "observations");
}

#[test]
fn chunk_identity_and_enums_are_checked() {
    let c = sample_chunk;
    assert_invalid(
        TrajectoryChunk {
            run_id: String::new(),
            ..c()
        },
        "run_id",
    );
    assert_invalid(
        TrajectoryChunk {
            actor_id: String::new(),
            ..c()
        },
        "actor_id",
    );
    let unspecified = Role::Unspecified.into();
    assert_invalid(
        TrajectoryChunk {
            role: unspecified,
            ..c()
        },
        "role",
    );
    assert_invalid(TrajectoryChunk { role: 99, ..c() }, "role");
}

#[test]
fn non_finite_chunk_data_is_rejected() {
    let mut m = sample_chunk();
    m.observations[17] = f32::NAN;
    assert_invalid(m, "observations");
    let mut m = sample_chunk();
    m.actions[0] = f32::INFINITY;
    assert_invalid(m, "actions");
    let mut m = sample_chunk();
    m.rewards[3] = f32::NEG_INFINITY;
    assert_invalid(m, "rewards");
    let mut m = sample_chunk();
    m.values[31] = f32::NAN;
    assert_invalid(m, "values");
    let mut m = sample_chunk();
    m.log_probs[5] = f32::NAN;
    assert_invalid(m, "log_probs");
    let mut m = sample_chunk();
    m.amp_features[9] = f32::NAN;
    assert_invalid(m, "amp_features");
    let m = TrajectoryChunk {
        bootstrap_value: f32::NAN,
        ..sample_chunk()
    };
    assert_invalid(m, "bootstrap_value");
}

#[test]
fn nan_observation_error_names_the_index() {
    let mut m = sample_chunk();
    m.observations[17] = f32::NAN;
    let err = TrajectoryChunk::decode_checked(&m.encode_to_vec()).unwrap_err();
    assert_eq!(
        err.to_string(),
        "lhm.v1.TrajectoryChunk.observations: [17] = NaN is not finite"
    );
}

#[test]
fn chunk_episode_ends_must_be_consistent() {
    let mut m = sample_chunk();
    m.truncated[19] = true; // dones[19] is already set
    m.truncation_values[19] = 1.0;
    assert_invalid(m, "truncated");
    let mut m = sample_chunk();
    m.truncation_values[3] = 1.0; // step 3 is not truncated
    assert_invalid(m, "truncation_values");
}

#[test]
fn episode_stats_are_checked() {
    let with_episode = |edit: fn(&mut lhm_protos::EpisodeStats)| {
        let mut m = sample_chunk();
        edit(&mut m.episodes[0]);
        m
    };
    assert_invalid(
        with_episode(|e| e.cycles_succeeded = 3),
        "episodes.cycles_succeeded",
    );
    assert_invalid(
        with_episode(|e| e.final_placement_error_m.push(0.1)),
        "episodes.final_placement_error_m",
    );
    assert_invalid(
        with_episode(|e| e.final_placement_error_m[1] = -0.1),
        "episodes.final_placement_error_m",
    );
    assert_invalid(with_episode(|e| e.length = 0), "episodes.length");
    assert_invalid(
        with_episode(|e| e.episode_return = f32::NAN),
        "episodes.episode_return",
    );
}

#[test]
fn policy_weights_are_checked() {
    let w = sample_weights;
    let unspecified = Role::Unspecified.into();
    assert_invalid(
        PolicyWeights {
            role: unspecified,
            ..w()
        },
        "role",
    );
    assert_invalid(
        PolicyWeights {
            run_id: String::new(),
            ..w()
        },
        "run_id",
    );
    assert_invalid(
        PolicyWeights {
            safetensors: vec![],
            ..w()
        },
        "safetensors",
    );
    assert_invalid(
        PolicyWeights {
            config_json: String::new(),
            ..w()
        },
        "config_json",
    );
    let mut m = w();
    m.obs_normalizer.as_mut().unwrap().var.pop();
    assert_invalid(m, "obs_normalizer");
    let mut m = w();
    m.amp_normalizer.as_mut().unwrap().var[0] = -1.0;
    assert_invalid(m, "amp_normalizer");
    let mut m = w();
    m.obs_normalizer.as_mut().unwrap().mean[2] = f32::NAN;
    assert_invalid(m, "obs_normalizer");
    let m = PolicyWeights {
        obs_normalizer: Some(Normalizer {
            count: -1.0,
            ..Normalizer::default()
        }),
        ..w()
    };
    assert_invalid(m, "obs_normalizer");
    let mut m = w();
    m.obs_normalizer.as_mut().unwrap().clip = -5.0;
    assert_invalid(m, "obs_normalizer");
    let mut m = w();
    m.obs_normalizer.as_mut().unwrap().epsilon = f64::INFINITY;
    assert_invalid(m, "obs_normalizer");
}

#[test]
fn label_requests_are_checked() {
    let r = sample_label_request;
    let mut m = r();
    m.observations.pop();
    assert_invalid(m, "observations");
    let mut m = r();
    m.stages.pop();
    assert_invalid(m, "stages");
    let mut m = r();
    m.stages[4] = Stage::Unspecified.into();
    assert_invalid(m, "stages");
    let mut m = r();
    m.stages[4] = 7;
    assert_invalid(m, "stages");
    let mut m = r();
    m.observations[0] = f32::NAN;
    assert_invalid(m, "observations");
    assert_invalid(
        LabelRequest {
            num_states: 0,
            ..r()
        },
        "num_states",
    );
    assert_invalid(LabelRequest { obs_dim: 0, ..r() }, "obs_dim");
    assert_invalid(
        LabelRequest {
            run_id: String::new(),
            ..r()
        },
        "run_id",
    );
}

#[test]
fn label_replies_are_checked() {
    let r = sample_label_reply;
    let mut m = r();
    m.actions.pop();
    assert_invalid(m, "actions");
    let mut m = r();
    m.teachers.pop();
    assert_invalid(m, "teachers");
    let mut m = r();
    m.teachers[0] = Role::Unspecified.into();
    assert_invalid(m, "teachers");
    let mut m = r();
    m.teacher_versions.push(1);
    assert_invalid(m, "teacher_versions");
    let mut m = r();
    m.actions[2] = f32::NAN;
    assert_invalid(m, "actions");
    assert_invalid(LabelReply { act_dim: 0, ..r() }, "act_dim");
    // An error reply must not carry labels.
    let failed = LabelReply {
        error: "timeout".into(),
        ..r()
    };
    assert_invalid(failed, "actions");
}

#[test]
fn actor_status_and_metrics_are_checked() {
    let s = sample_actor_status;
    assert_invalid(ActorStatus { state: 0, ..s() }, "state");
    assert_invalid(ActorStatus { state: 9, ..s() }, "state");
    assert_invalid(ActorStatus { role: 0, ..s() }, "role");
    assert_invalid(
        ActorStatus {
            actor_id: String::new(),
            ..s()
        },
        "actor_id",
    );
    assert_invalid(
        Metrics {
            process: String::new(),
            ..sample_metrics()
        },
        "process",
    );
    let mut m = sample_metrics();
    m.values.insert(String::new(), 1.0);
    assert_invalid(m, "values");
}

#[test]
fn episode_frames_are_checked() {
    let e = sample_episode_frames;
    assert_invalid(EpisodeFrames { role: 0, ..e() }, "role");
    assert_invalid(
        EpisodeFrames {
            task_id: String::new(),
            ..e()
        },
        "task_id",
    );
    for frame_dt in [0.0, -0.1, f32::NAN, f32::INFINITY] {
        assert_invalid(EpisodeFrames { frame_dt, ..e() }, "frame_dt");
    }
    assert_invalid(
        EpisodeFrames {
            num_frames: 0,
            ..e()
        },
        "num_frames",
    );
    assert_invalid(
        EpisodeFrames {
            num_bodies: 0,
            ..e()
        },
        "num_bodies",
    );
    // One frame more than the arrays hold: every array is now short, the first one is blamed.
    assert_invalid(
        EpisodeFrames {
            num_frames: NUM_FRAMES + 1,
            ..e()
        },
        "body_positions",
    );
    let mut m = e();
    m.body_rotations.pop();
    assert_invalid(m, "body_rotations");
    assert_invalid(
        EpisodeFrames {
            num_objects: NUM_OBJECTS + 1,
            ..e()
        },
        "object_positions",
    );
    let mut m = e();
    m.object_rotations.push(1.0);
    assert_invalid(m, "object_rotations");
    let mut m = e();
    m.body_positions[5] = f32::NAN;
    assert_invalid(m, "body_positions");
    let mut m = e();
    m.object_rotations[0] = f32::INFINITY;
    assert_invalid(m, "object_rotations");
}
