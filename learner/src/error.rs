//! Errors of the learner library.

use lhm_nets::checkpoint::CheckpointError;
use lhm_nets::NetError;

#[derive(Debug, thiserror::Error)]
pub enum LearnerError {
    #[error(transparent)]
    Net(#[from] NetError),
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error("tensor operation failed: {0}")]
    Candle(#[from] candle_core::Error),
    #[error("invalid input: {0}")]
    Invalid(String),
    #[error("{}: {source}", path.display())]
    Io {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
    /// A file on disk is not what it should be (named, with what is wrong).
    #[error("{}: {message}", path.display())]
    Corrupt {
        path: std::path::PathBuf,
        message: String,
    },
}

pub type LearnerResult<T> = Result<T, LearnerError>;

pub(crate) fn check_len(what: &str, len: usize, expected: usize) -> LearnerResult<()> {
    if len == expected {
        Ok(())
    } else {
        Err(LearnerError::Invalid(format!(
            "{what} has {len} values, expected {expected}"
        )))
    }
}
