use crate::{
    validate, ActorStatus, EpisodeFrames, LabelReply, LabelRequest, Metrics, PolicyWeights,
    TrajectoryChunk, WireError, SCHEMA_VERSION,
};

/// A top-level `lhm.v1` message: versioned, validated, safe to decode from untrusted bytes.
pub trait WireMessage: prost::Message + Default {
    /// Fully qualified protobuf name, e.g. `lhm.v1.TrajectoryChunk` (also the MCAP schema name).
    const FULL_NAME: &'static str;

    /// The message's `schema_version` field.
    fn schema_version(&self) -> u32;

    /// Sets the message's `schema_version` field.
    fn set_schema_version(&mut self, version: u32);

    /// Checks the contents (shapes, enum values, finiteness); does not look at `schema_version`.
    fn validate(&self) -> Result<(), WireError>;

    /// An empty message with `schema_version` set to [`SCHEMA_VERSION`]; use it as the base of
    /// struct-update syntax: `TrajectoryChunk { num_steps: 32, ..TrajectoryChunk::versioned() }`.
    fn versioned() -> Self {
        let mut message = Self::default();
        message.set_schema_version(SCHEMA_VERSION);
        message
    }

    /// What a receiver checks after decoding: the schema version, then [`WireMessage::validate`].
    fn check(&self) -> Result<(), WireError> {
        let found = self.schema_version();
        if found != SCHEMA_VERSION {
            return Err(WireError::WrongVersion {
                message: Self::FULL_NAME,
                expected: SCHEMA_VERSION,
                found,
            });
        }
        self.validate()
    }

    /// Encodes after [`WireMessage::check`], so a buggy sender fails loudly at the source.
    fn encode_checked(&self) -> Result<Vec<u8>, WireError> {
        self.check()?;
        Ok(self.encode_to_vec())
    }

    /// Encodes with `schema_version` forced to [`SCHEMA_VERSION`], without validating.
    fn encode_to_vec_versioned(&self) -> Vec<u8> {
        let mut buf = self.encode_to_vec();
        if self.schema_version() != SCHEMA_VERSION {
            // Protobuf decoders keep the last occurrence of a singular scalar field, so appending
            // field 1 overrides the version without cloning the message (weights are megabytes).
            prost::Message::encode_raw(
                &VersionStamp {
                    schema_version: SCHEMA_VERSION,
                },
                &mut buf,
            );
        }
        buf
    }

    /// Decodes untrusted bytes and runs [`WireMessage::check`]. Never panics.
    fn decode_checked(bytes: &[u8]) -> Result<Self, WireError> {
        let message = Self::decode(bytes).map_err(|source| WireError::Malformed {
            message: Self::FULL_NAME,
            source,
        })?;
        message.check()?;
        Ok(message)
    }
}

/// Just field 1 of every top-level message, for [`WireMessage::encode_to_vec_versioned`].
#[derive(Clone, PartialEq, prost::Message)]
struct VersionStamp {
    #[prost(uint32, tag = "1")]
    schema_version: u32,
}

macro_rules! wire_message {
    ($($ty:ident => $validate:path),* $(,)?) => {$(
        impl WireMessage for $ty {
            const FULL_NAME: &'static str = concat!("lhm.v1.", stringify!($ty));

            fn schema_version(&self) -> u32 {
                self.schema_version
            }

            fn set_schema_version(&mut self, version: u32) {
                self.schema_version = version;
            }

            fn validate(&self) -> Result<(), WireError> {
                $validate(self)
            }
        }
    )*};
}

wire_message! {
    TrajectoryChunk => validate::trajectory_chunk,
    PolicyWeights => validate::policy_weights,
    LabelRequest => validate::label_request,
    LabelReply => validate::label_reply,
    ActorStatus => validate::actor_status,
    Metrics => validate::metrics,
    EpisodeFrames => validate::episode_frames,
}
