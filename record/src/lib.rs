//! Recording runs to MCAP, so that a user opens them in Foxglove and sees the character and the
//! room moving, next to the run's metrics and any raw `lhm.v1` messages.
//!
//! * [`capture::EpisodeCapture`] samples a running environment into an `lhm.v1.EpisodeFrames`
//!   (actors send those to the learner; `lhm record` uses them directly).
//! * [`EpisodeScene`] knows what to draw for a task and a character.
//! * [`McapRecorder`] writes the file: per episode frame a `foxglove.SceneUpdate` on `/scene` and
//!   a `foxglove.FrameTransforms` on `/tf`, `lhm.v1.Metrics` on `/metrics`, raw `lhm.v1`
//!   messages on topics of the caller's choice. Every channel is protobuf with its
//!   `FileDescriptorSet` as schema data.

pub mod capture;
mod error;
mod recorder;
pub mod recover;
mod scene;

use std::path::Path;

pub use error::RecordError;
pub use recorder::{McapRecorder, CHUNK_SIZE, METRICS_TOPIC, SCENE_TOPIC, TF_TOPIC};
pub use scene::{EpisodeScene, WORLD_FRAME};

use lhm_protos::EpisodeFrames;

/// Writes one episode to a new file at `path`, starting at time 0 so that Foxglove's clock reads
/// seconds into the episode.
pub fn record_episode(
    path: impl AsRef<Path>,
    frames: &EpisodeFrames,
    scene: &EpisodeScene,
) -> Result<(), RecordError> {
    let mut recorder = McapRecorder::create(path)?;
    recorder.write_episode(frames, scene, 0)?;
    recorder.finish()
}
