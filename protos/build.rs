//! Compiles the `.proto` files with protox (pure Rust, so no `protoc` install is needed) and
//! generates the prost types from the resulting descriptor sets:
//! * `proto/lhm/v1/lhm.proto`, our wire protocol;
//! * `proto/foxglove/*.proto`, our own minimal copies of the Foxglove schemas that MCAP recordings
//!   use, so Foxglove draws the scene (their `google.protobuf` imports map to `prost-types`).

use std::{env, fs, path::PathBuf};

use prost::Message as _;

const LHM_PROTO: &str = "proto/lhm/v1/lhm.proto";

/// Every Foxglove schema we write (alphabetical; protox orders them by their imports).
const FOXGLOVE_PROTOS: [&str; 13] = [
    "proto/foxglove/Color.proto",
    "proto/foxglove/CubePrimitive.proto",
    "proto/foxglove/CylinderPrimitive.proto",
    "proto/foxglove/FrameTransform.proto",
    "proto/foxglove/FrameTransforms.proto",
    "proto/foxglove/KeyValuePair.proto",
    "proto/foxglove/Pose.proto",
    "proto/foxglove/Quaternion.proto",
    "proto/foxglove/SceneEntity.proto",
    "proto/foxglove/SceneEntityDeletion.proto",
    "proto/foxglove/SceneUpdate.proto",
    "proto/foxglove/SpherePrimitive.proto",
    "proto/foxglove/Vector3.proto",
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // The whole directory, so that a newly added import also triggers a rebuild.
    println!("cargo:rerun-if-changed=proto");

    // Source info is kept: prost-build turns the .proto comments into rustdoc, and the descriptor
    // recorded in MCAP files then documents its fields too. Each set includes its imports
    // (protox bundles google/protobuf/*), so it is self-contained MCAP schema data.
    let lhm = protox::compile([LHM_PROTO], ["proto"])?;
    let foxglove = protox::compile(FOXGLOVE_PROTOS, ["proto"])?;

    let out_dir = PathBuf::from(env::var_os("OUT_DIR").ok_or("OUT_DIR is not set")?);
    fs::write(out_dir.join("lhm_v1_descriptor.bin"), lhm.encode_to_vec())?;
    fs::write(
        out_dir.join("foxglove_descriptor.bin"),
        foxglove.encode_to_vec(),
    )?;

    // One generation pass over both sets, duplicate imports dropped, so prost-build sees every
    // package at once and writes `lhm.v1.rs` and `foxglove.rs`. It maps google.protobuf types to
    // prost-types by default, so Timestamp and Duration are not generated again.
    let mut all = lhm;
    for file in foxglove.file {
        if !all.file.iter().any(|f| f.name == file.name) {
            all.file.push(file);
        }
    }
    prost_build::Config::new()
        // BTreeMap instead of HashMap: encoding order is deterministic, so equal messages give equal
        // bytes (reproducible logs, byte-level tests).
        .btree_map(["."])
        .compile_fds(all)?;
    Ok(())
}
