//! Compiles `proto/lhm/v1/lhm.proto` with protox (pure Rust, so no `protoc` install is needed) and
//! generates the prost types from the resulting descriptor set.

use std::{env, fs, path::PathBuf};

use prost::Message as _;

const PROTO: &str = "proto/lhm/v1/lhm.proto";

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // The whole directory, so that a newly added import also triggers a rebuild.
    println!("cargo:rerun-if-changed=proto");

    // Source info is kept: prost-build turns the .proto comments into rustdoc, and the descriptor
    // recorded in MCAP files then documents its fields too.
    let fds = protox::compile([PROTO], ["proto"])?;

    let out_dir = PathBuf::from(env::var_os("OUT_DIR").ok_or("OUT_DIR is not set")?);
    fs::write(out_dir.join("lhm_v1_descriptor.bin"), fds.encode_to_vec())?;

    prost_build::Config::new()
        // BTreeMap instead of HashMap: encoding order is deterministic, so equal messages give equal
        // bytes (reproducible logs, byte-level tests).
        .btree_map(["."])
        .compile_fds(fds)?;
    Ok(())
}
