/// Why a received (or about to be sent) message was rejected.
///
/// `message` is the fully qualified protobuf type name, e.g. `lhm.v1.TrajectoryChunk`.
#[derive(Debug, thiserror::Error)]
pub enum WireError {
    /// The bytes are not a valid protobuf encoding of the message.
    #[error("{message}: malformed protobuf encoding")]
    Malformed {
        message: &'static str,
        source: prost::DecodeError,
    },
    /// The sender speaks another schema version (0: it did not set `schema_version` at all).
    #[error("{message}.schema_version: got {found}, expected {expected}")]
    WrongVersion {
        message: &'static str,
        expected: u32,
        found: u32,
    },
    /// The message decoded but its contents are inconsistent (shapes, enums, non-finite floats...).
    #[error("{message}.{field}: {reason}")]
    Invalid {
        message: &'static str,
        field: &'static str,
        reason: String,
    },
}
