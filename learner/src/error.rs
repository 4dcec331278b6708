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
