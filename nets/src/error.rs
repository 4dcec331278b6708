//! Errors of the network crate.

/// Anything that can go wrong building or running a network (tensor errors, bad sizes).
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    #[error("tensor operation failed: {0}")]
    Candle(#[from] candle_core::Error),
    #[error("invalid network configuration: {0}")]
    Config(String),
    #[error("data of length {len} is not a whole number of rows of width {width}")]
    RaggedRows { len: usize, width: usize },
}

pub type NetResult<T> = Result<T, NetError>;
