//! Reference motion for AMP: the clips `scripts/install-motions` puts in a local cache (DESIGN.md
//! §5), parsed from their source formats, retargeted onto the character ([`retarget`]), and
//! sampled as demo AMP features for the discriminator ([`demo`]).

pub mod deepmimic;
pub mod demo;
pub mod joints;
pub mod library;
pub mod omomo;
pub mod omomo_retarget;
pub mod reach;
pub mod retarget;
pub mod smplh;

pub use demo::{AmpWindow, DemoMotion, SourceWeights};

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
    #[error("{path}: no clips to sample demo AMP features from")]
    NoClips { path: String },
    #[error(
        "{clip}: {duration_s:.3} s long, shorter than the {frames}-frame AMP window ({needed_s:.3} s)"
    )]
    TooShort {
        clip: String,
        duration_s: f32,
        frames: usize,
        needed_s: f32,
    },
    #[error("AMP window: {0}")]
    Window(String),
    #[error("[amp] demo_weights: {0}")]
    DemoWeights(String),
}

/// Where the clips live: `$LHM_MOTION_DIR`, else `~/.cache/lhm/motions`.
pub fn default_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("LHM_MOTION_DIR") {
        return PathBuf::from(dir);
    }
    let home = std::env::var_os("HOME").map_or_else(|| PathBuf::from("."), PathBuf::from);
    home.join(".cache").join("lhm").join("motions")
}
