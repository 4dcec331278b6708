//! Reference motion for AMP: the clips `scripts/install-motions` puts in a local cache (DESIGN.md
//! §5), parsed from their source formats. Retargeting onto the character comes next.

pub mod deepmimic;
pub mod library;
pub mod omomo;
pub mod retarget;

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum MotionError {
    #[error("{path}: motion clips are not installed: run `scripts/install-motions` (or set LHM_MOTION_DIR)")]
    NotInstalled { path: String },
    #[error("{file}: cannot read: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}: {message}")]
    Corrupt { file: String, message: String },
}

/// Where the clips live: `$LHM_MOTION_DIR`, else `~/.cache/lhm/motions`.
pub fn default_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("LHM_MOTION_DIR") {
        return PathBuf::from(dir);
    }
    let home = std::env::var_os("HOME").map_or_else(|| PathBuf::from("."), PathBuf::from);
    home.join(".cache").join("lhm").join("motions")
}
