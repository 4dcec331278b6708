//! Errors of the shared service layer.

use lhm_protos::WireError;

#[derive(Debug, thiserror::Error)]
pub enum ClusterError {
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error(transparent)]
    Key(#[from] lhm_protos::keys::KeyError),
    #[error(transparent)]
    Wire(#[from] WireError),
    #[error("policy weights: {0}")]
    Weights(String),
    #[error(transparent)]
    Net(#[from] lhm_nets::NetError),
}

impl ClusterError {
    pub fn zenoh(e: impl std::fmt::Display) -> Self {
        Self::Zenoh(e.to_string())
    }
}

pub type ClusterResult<T> = Result<T, ClusterError>;
