mod common;

use std::fmt::Debug;

use common::*;
use lhm_protos::{
    prost::Message, ActorStatus, EpisodeFrames, LabelReply, LabelRequest, Metrics, PolicyWeights,
    TrajectoryChunk, WireMessage, FILE_DESCRIPTOR_SET, SCHEMA_VERSION,
};

fn round_trip<M: WireMessage + PartialEq + Debug>(message: M) {
    message.check().expect("fixture must be valid");
    let bytes = message.encode_checked().unwrap();
    assert_eq!(bytes, message.encode_to_vec());
    let decoded = M::decode_checked(&bytes).unwrap();
    assert_eq!(decoded, message);
    // Deterministic encoding (BTreeMap for maps): re-encoding gives the same bytes.
    assert_eq!(decoded.encode_to_vec(), bytes);
}

#[test]
fn trajectory_chunk_round_trips() {
    let chunk = sample_chunk();
    assert_eq!(chunk.observations.len(), 32 * 8);
    assert_eq!(chunk.actions.len(), 32 * 3);
    assert_eq!(chunk.amp_features.len(), 32 * 5);
    round_trip(chunk);
}

#[test]
fn chunk_without_amp_round_trips() {
    round_trip(TrajectoryChunk {
        amp_dim: 0,
        amp_features: vec![],
        ..sample_chunk()
    });
}

#[test]
fn policy_weights_round_trip() {
    round_trip(sample_weights());
    round_trip(PolicyWeights {
        obs_normalizer: None,
        amp_normalizer: None,
        ..sample_weights()
    });
}

#[test]
fn label_request_round_trips() {
    round_trip(sample_label_request());
}

#[test]
fn label_reply_round_trips() {
    round_trip(sample_label_reply());
    round_trip(LabelReply {
        error: "teacher 2 weights not loaded yet".into(),
        ..LabelReply::versioned()
    });
}

#[test]
fn actor_status_round_trips() {
    round_trip(sample_actor_status());
}

#[test]
fn metrics_round_trip() {
    round_trip(sample_metrics());
}

#[test]
fn episode_frames_round_trip() {
    round_trip(sample_episode_frames());
    // An episode in an empty room: no objects at all.
    round_trip(EpisodeFrames {
        num_objects: 0,
        object_positions: vec![],
        object_rotations: vec![],
        ..sample_episode_frames()
    });
}

#[test]
fn metrics_may_carry_non_finite_values() {
    let mut metrics = sample_metrics();
    metrics.values.insert("loss/value".into(), f64::NAN);
    metrics.values.insert("grad_norm".into(), f64::INFINITY);
    let decoded = Metrics::decode_checked(&metrics.encode_checked().unwrap()).unwrap();
    assert!(decoded.values["loss/value"].is_nan());
    assert_eq!(decoded.values["grad_norm"], f64::INFINITY);
}

#[test]
fn versioned_sets_the_schema_version() {
    assert_eq!(SCHEMA_VERSION, 1);
    assert_eq!(TrajectoryChunk::default().schema_version, 0);
    assert_eq!(TrajectoryChunk::versioned().schema_version, SCHEMA_VERSION);
    assert_eq!(PolicyWeights::versioned().schema_version(), SCHEMA_VERSION);
    assert_eq!(LabelRequest::versioned().schema_version, SCHEMA_VERSION);
    assert_eq!(LabelReply::versioned().schema_version, SCHEMA_VERSION);
    assert_eq!(ActorStatus::versioned().schema_version, SCHEMA_VERSION);
    assert_eq!(Metrics::versioned().schema_version, SCHEMA_VERSION);
    assert_eq!(EpisodeFrames::versioned().schema_version, SCHEMA_VERSION);
}

#[test]
fn encode_to_vec_versioned_stamps_the_version() {
    for stale in [0, 7] {
        let mut status = sample_actor_status();
        status.schema_version = stale;
        let decoded = ActorStatus::decode_checked(&status.encode_to_vec_versioned()).unwrap();
        status.schema_version = SCHEMA_VERSION;
        assert_eq!(decoded, status);
    }
    // Already versioned: exactly the plain encoding.
    let chunk = sample_chunk();
    assert_eq!(chunk.encode_to_vec_versioned(), chunk.encode_to_vec());
}

/// Just enough of descriptor.proto to read message names back out of FILE_DESCRIPTOR_SET.
#[derive(Clone, PartialEq, Message)]
struct FileDescriptorSet {
    #[prost(message, repeated, tag = "1")]
    file: Vec<FileDescriptorProto>,
}

#[derive(Clone, PartialEq, Message)]
struct FileDescriptorProto {
    #[prost(string, tag = "1")]
    name: String,
    #[prost(string, tag = "2")]
    package: String,
    #[prost(message, repeated, tag = "4")]
    message_type: Vec<DescriptorProto>,
}

#[derive(Clone, PartialEq, Message)]
struct DescriptorProto {
    #[prost(string, tag = "1")]
    name: String,
}

#[test]
fn file_descriptor_set_names_every_wire_message() {
    let set = FileDescriptorSet::decode(FILE_DESCRIPTOR_SET).unwrap();
    let file = set
        .file
        .iter()
        .find(|f| f.name == "lhm/v1/lhm.proto")
        .expect("lhm.proto in the descriptor set");
    assert_eq!(file.package, "lhm.v1");
    let names: Vec<String> = file
        .message_type
        .iter()
        .map(|m| format!("{}.{}", file.package, m.name))
        .collect();
    for full_name in [
        TrajectoryChunk::FULL_NAME,
        PolicyWeights::FULL_NAME,
        LabelRequest::FULL_NAME,
        LabelReply::FULL_NAME,
        ActorStatus::FULL_NAME,
        Metrics::FULL_NAME,
        EpisodeFrames::FULL_NAME,
        "lhm.v1.EpisodeStats",
        "lhm.v1.Normalizer",
    ] {
        assert!(
            names.iter().any(|n| n == full_name),
            "{full_name} not in {names:?}"
        );
    }
}
