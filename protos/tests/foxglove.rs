//! Our Foxglove schemas: the descriptor set MCAP files embed must describe every message with
//! Foxglove's exact package, names and field numbers (the Foxglove app matches on them), and be
//! self-contained (google/protobuf imports included).

use lhm_protos::foxglove::{
    scene_entity_deletion, Color, CubePrimitive, Pose, Quaternion, SceneEntity,
    SceneEntityDeletion, SceneUpdate, Vector3,
};
use lhm_protos::prost::Message;
use lhm_protos::prost_types::{FileDescriptorSet, Timestamp};
use lhm_protos::FOXGLOVE_DESCRIPTOR_SET;

/// (message, field, number) for every field we declare, from Foxglove's published schemas.
const FIELDS: &[(&str, &str, i32)] = &[
    ("Vector3", "x", 1),
    ("Vector3", "y", 2),
    ("Vector3", "z", 3),
    ("Quaternion", "x", 1),
    ("Quaternion", "y", 2),
    ("Quaternion", "z", 3),
    ("Quaternion", "w", 4),
    ("Pose", "position", 1),
    ("Pose", "orientation", 2),
    ("Color", "r", 1),
    ("Color", "g", 2),
    ("Color", "b", 3),
    ("Color", "a", 4),
    ("KeyValuePair", "key", 1),
    ("KeyValuePair", "value", 2),
    ("CubePrimitive", "pose", 1),
    ("CubePrimitive", "size", 2),
    ("CubePrimitive", "color", 3),
    ("SpherePrimitive", "pose", 1),
    ("SpherePrimitive", "size", 2),
    ("SpherePrimitive", "color", 3),
    ("CylinderPrimitive", "pose", 1),
    ("CylinderPrimitive", "size", 2),
    ("CylinderPrimitive", "bottom_scale", 3),
    ("CylinderPrimitive", "top_scale", 4),
    ("CylinderPrimitive", "color", 5),
    ("SceneEntity", "timestamp", 1),
    ("SceneEntity", "frame_id", 2),
    ("SceneEntity", "id", 3),
    ("SceneEntity", "lifetime", 4),
    ("SceneEntity", "frame_locked", 5),
    ("SceneEntity", "metadata", 6),
    ("SceneEntity", "cubes", 8),
    ("SceneEntity", "spheres", 9),
    ("SceneEntity", "cylinders", 10),
    ("SceneEntityDeletion", "timestamp", 1),
    ("SceneEntityDeletion", "type", 2),
    ("SceneEntityDeletion", "id", 3),
    ("SceneUpdate", "deletions", 1),
    ("SceneUpdate", "entities", 2),
    ("FrameTransform", "timestamp", 1),
    ("FrameTransform", "parent_frame_id", 2),
    ("FrameTransform", "child_frame_id", 3),
    ("FrameTransform", "translation", 4),
    ("FrameTransform", "rotation", 5),
    ("FrameTransforms", "transforms", 1),
];

#[test]
fn descriptor_set_has_foxglove_names_and_field_numbers() {
    let set = FileDescriptorSet::decode(FOXGLOVE_DESCRIPTOR_SET).expect("valid descriptor set");
    let files: Vec<&str> = set.file.iter().map(|f| f.name()).collect();
    for import in [
        "google/protobuf/timestamp.proto",
        "google/protobuf/duration.proto",
    ] {
        assert!(files.contains(&import), "{import} missing from {files:?}");
    }
    let messages: Vec<_> = set
        .file
        .iter()
        .filter(|f| f.package() == "foxglove")
        .flat_map(|f| &f.message_type)
        .collect();
    let mut names: Vec<&str> = messages.iter().map(|m| m.name()).collect();
    names.sort_unstable();
    assert_eq!(
        names,
        [
            "Color",
            "CubePrimitive",
            "CylinderPrimitive",
            "FrameTransform",
            "FrameTransforms",
            "KeyValuePair",
            "Pose",
            "Quaternion",
            "SceneEntity",
            "SceneEntityDeletion",
            "SceneUpdate",
            "SpherePrimitive",
            "Vector3",
        ]
    );
    for m in &messages {
        let declared = m.field.len();
        let expected = FIELDS.iter().filter(|(msg, _, _)| *msg == m.name()).count();
        assert_eq!(declared, expected, "foxglove.{}: field count", m.name());
    }
    for (message, field, number) in FIELDS {
        let m = messages
            .iter()
            .find(|m| m.name() == *message)
            .unwrap_or_else(|| panic!("foxglove.{message} missing"));
        let f = m
            .field
            .iter()
            .find(|f| f.name() == *field)
            .unwrap_or_else(|| panic!("foxglove.{message}.{field} missing"));
        assert_eq!(f.number(), *number, "foxglove.{message}.{field}");
    }
    // Timestamps and durations are the well-known types, as Foxglove declares them.
    let entity = messages.iter().find(|m| m.name() == "SceneEntity").unwrap();
    let type_of = |field: &str| {
        entity
            .field
            .iter()
            .find(|f| f.name() == field)
            .map(|f| f.type_name().to_string())
    };
    assert_eq!(
        type_of("timestamp").as_deref(),
        Some(".google.protobuf.Timestamp")
    );
    assert_eq!(
        type_of("lifetime").as_deref(),
        Some(".google.protobuf.Duration")
    );
}

#[test]
fn deletion_type_values_match_foxglove() {
    assert_eq!(scene_entity_deletion::Type::MatchingId as i32, 0);
    assert_eq!(scene_entity_deletion::Type::All as i32, 1);
}

#[test]
fn scene_update_round_trips() {
    let stamp = Timestamp {
        seconds: 12,
        nanos: 500,
    };
    let update = SceneUpdate {
        deletions: vec![SceneEntityDeletion {
            timestamp: Some(stamp),
            r#type: scene_entity_deletion::Type::All.into(),
            id: String::new(),
        }],
        entities: vec![SceneEntity {
            timestamp: Some(stamp),
            frame_id: "world".into(),
            id: "box".into(),
            cubes: vec![CubePrimitive {
                pose: Some(Pose {
                    position: Some(Vector3 {
                        x: 1.0,
                        y: 2.0,
                        z: 0.5,
                    }),
                    orientation: Some(Quaternion {
                        x: 0.0,
                        y: 0.0,
                        z: 0.0,
                        w: 1.0,
                    }),
                }),
                size: Some(Vector3 {
                    x: 0.3,
                    y: 0.3,
                    z: 1.0,
                }),
                color: Some(Color {
                    r: 1.0,
                    g: 0.5,
                    b: 0.0,
                    a: 1.0,
                }),
            }],
            ..SceneEntity::default()
        }],
    };
    let bytes = update.encode_to_vec();
    assert_eq!(SceneUpdate::decode(bytes.as_slice()).unwrap(), update);
}
