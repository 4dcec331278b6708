use std::path::PathBuf;

/// Why a recording could not be written. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{}: cannot create the directory: {source}", path.display())]
    CreateDir {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: cannot create the file: {source}", path.display())]
    Create {
        path: PathBuf,
        source: std::io::Error,
    },
    /// Writing or closing the file failed (disk full, I/O error...).
    #[error("{}: writing MCAP: {source}", path.display())]
    Mcap {
        path: PathBuf,
        source: mcap::McapError,
    },
    #[error("{}: closing the file: {source}", path.display())]
    Close {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A topic keeps one schema for the whole file (Foxglove decodes a channel with one schema).
    #[error("{}: topic {topic} already carries {existing}, cannot also carry {requested}", path.display())]
    TopicSchema {
        path: PathBuf,
        topic: String,
        existing: &'static str,
        requested: &'static str,
    },
    /// A message failed its `lhm.v1` checks; nothing of it was written.
    #[error("{}: {topic}: {source}", path.display())]
    Invalid {
        path: PathBuf,
        topic: String,
        source: lhm_protos::WireError,
    },
    #[error("{}: cannot read: {source}", path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {reason}", path.display())]
    Recover { path: PathBuf, reason: String },
    /// An episode's frames do not belong to the scene they were to be drawn in.
    #[error("{}: lhm.v1.EpisodeFrames.{field}: {reason}", path.display())]
    SceneMismatch {
        path: PathBuf,
        field: &'static str,
        reason: String,
    },
}
