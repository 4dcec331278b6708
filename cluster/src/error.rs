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
    #[error("stopped while waiting for {0}")]
    Stopped(String),
    #[error(transparent)]
    Net(#[from] lhm_nets::NetError),
}

impl ClusterError {
    pub fn zenoh(e: impl std::fmt::Display) -> Self {
        Self::Zenoh(without_source_location(&e.to_string()))
    }
}

/// Zenoh's errors end in the source location that raised them (` at /…/zenoh-1.x/src/….rs:447.`),
/// which tells a user nothing: cut it.
pub fn without_source_location(message: &str) -> String {
    // The last " at /…rs:N" is the location; an earlier " at /path" may be part of the message.
    match message.rfind(" at /") {
        Some(i) if message[i..].contains(".rs:") => message[..i].trim_end().to_owned(),
        _ => message.to_owned(),
    }
}

pub type ClusterResult<T> = Result<T, ClusterError>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zenoh_source_locations_are_cut() {
        let raw = "Unable to connect to any of [Single(tcp/127.0.0.1:9)]!  at \
                   /root/.cargo/registry/src/x/zenoh-1.10.2/src/net/runtime/orchestrator.rs:447.";
        assert_eq!(
            without_source_location(raw),
            "Unable to connect to any of [Single(tcp/127.0.0.1:9)]!"
        );
        let with_path = "cannot read config at /etc/zenoh.json5 at /src/x.rs:3";
        assert_eq!(
            without_source_location(with_path),
            "cannot read config at /etc/zenoh.json5"
        );
        assert_eq!(without_source_location("look at /tmp/x"), "look at /tmp/x");
    }
}
