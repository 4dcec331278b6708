//! The MCAP file writer: one channel per topic, protobuf messages described by embedded
//! `FileDescriptorSet`s, so Foxglove (or any MCAP reader) decodes them without our code.

use std::collections::hash_map::Entry;
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use lhm_protos::prost::Message;
use lhm_protos::{
    EpisodeFrames, Metrics, Role, WireMessage, FILE_DESCRIPTOR_SET, FOXGLOVE_DESCRIPTOR_SET,
};
use mcap::records::{MessageHeader, Metadata};
use mcap::{Compression, WriteOptions, Writer};

use crate::scene::EpisodeScene;
use crate::RecordError;

/// `foxglove.SceneUpdate` per episode frame: room, goals, objects, character.
pub const SCENE_TOPIC: &str = "/scene";
/// `foxglove.FrameTransforms` per episode frame: world → every body and object frame.
pub const TF_TOPIC: &str = "/tf";
/// `lhm.v1.Metrics`, at the metrics' own wall-clock time.
pub const METRICS_TOPIC: &str = "/metrics";

/// Target uncompressed chunk size. Small enough that a crash loses little (the unfinished chunk
/// is what a crash costs) and an episode spans several chunks; large enough that lz4 still finds
/// the repeated room geometry of consecutive frames.
pub const CHUNK_SIZE: u64 = 256 * 1024;

/// MCAP schema and message encoding of every channel we write.
const PROTOBUF: &str = "protobuf";

const SCENE_UPDATE: &str = "foxglove.SceneUpdate";
const FRAME_TRANSFORMS: &str = "foxglove.FrameTransforms";

struct Channel {
    id: u16,
    schema: &'static str,
    /// Per-channel message counter (MCAP's `sequence`), wrapping as the spec allows.
    sequence: u32,
}

/// A file-backed MCAP recording of a run.
///
/// Crash safety: messages are written into compressed chunks, and a chunk is only readable once
/// it is complete. [`McapRecorder::write_episode`] and [`McapRecorder::write_metrics`] end the
/// current chunk and hand it to the OS before returning, so if the process dies later everything
/// they wrote can still be read: `lhm recover` ([`crate::recover::recover`]) copies it into a
/// whole file, or read it linearly with `mcap::MessageStream` and `IgnoreEndMagic`. Messages
/// written with [`McapRecorder::write_wire`] are covered by the next such call or by
/// [`McapRecorder::flush`]. The OS is not asked to sync to disk except at
/// [`McapRecorder::finish`], so a power loss may still lose recent chunks.
pub struct McapRecorder {
    path: PathBuf,
    writer: Writer<BufWriter<File>>,
    channels: HashMap<String, Channel>,
    /// Reused encoding buffer: an episode is thousands of messages.
    buf: Vec<u8>,
}

impl McapRecorder {
    /// Creates (or truncates) the file at `path`, creating missing parent directories.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, RecordError> {
        let path = path.as_ref().to_path_buf();
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|source| RecordError::CreateDir {
                path: dir.to_path_buf(),
                source,
            })?;
        }
        let file = File::create(&path).map_err(|source| RecordError::Create {
            path: path.clone(),
            source,
        })?;
        let options = WriteOptions::new()
            // lz4: fast enough not to slow the learner down, and Foxglove reads it.
            .compression(Some(Compression::Lz4))
            .chunk_size(Some(CHUNK_SIZE))
            .library(concat!("lhm-record ", env!("CARGO_PKG_VERSION")));
        let writer = Writer::with_options(BufWriter::new(file), options).map_err(|source| {
            RecordError::Mcap {
                path: path.clone(),
                source,
            }
        })?;
        Ok(Self {
            path,
            writer,
            channels: HashMap::new(),
            buf: Vec::new(),
        })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn mcap_err(&self, source: mcap::McapError) -> RecordError {
        RecordError::Mcap {
            path: self.path.clone(),
            source,
        }
    }

    /// The channel of `topic`, registered with its schema on first use.
    fn channel(
        &mut self,
        topic: &str,
        schema: &'static str,
        descriptor_set: &[u8],
    ) -> Result<&mut Channel, RecordError> {
        let path = &self.path;
        let mcap_err = |source| RecordError::Mcap {
            path: path.clone(),
            source,
        };
        let channel = match self.channels.entry(topic.to_string()) {
            Entry::Occupied(entry) => entry.into_mut(),
            Entry::Vacant(entry) => {
                // add_schema returns the existing id for identical content, so topics sharing
                // a message type share one schema record.
                let schema_id = self
                    .writer
                    .add_schema(schema, PROTOBUF, descriptor_set)
                    .map_err(mcap_err)?;
                let id = self
                    .writer
                    .add_channel(schema_id, topic, PROTOBUF, &BTreeMap::new())
                    .map_err(mcap_err)?;
                entry.insert(Channel {
                    id,
                    schema,
                    sequence: 0,
                })
            }
        };
        if channel.schema != schema {
            return Err(RecordError::TopicSchema {
                path: path.clone(),
                topic: topic.into(),
                existing: channel.schema,
                requested: schema,
            });
        }
        Ok(channel)
    }

    /// Writes the bytes in `self.buf` as one message on `topic`.
    fn write_buf(
        &mut self,
        topic: &str,
        schema: &'static str,
        descriptor_set: &[u8],
        log_time_ns: u64,
    ) -> Result<(), RecordError> {
        let channel = self.channel(topic, schema, descriptor_set)?;
        let header = MessageHeader {
            channel_id: channel.id,
            sequence: channel.sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        channel.sequence = channel.sequence.wrapping_add(1);
        self.writer
            .write_to_known_channel(&header, &self.buf)
            .map_err(|e| RecordError::Mcap {
                path: self.path.clone(),
                source: e,
            })
    }

    fn write_proto<M: Message>(
        &mut self,
        topic: &str,
        schema: &'static str,
        descriptor_set: &[u8],
        log_time_ns: u64,
        message: &M,
    ) -> Result<(), RecordError> {
        self.buf.clear();
        // A Vec grows as needed, so the raw encoder can never run short of space.
        message.encode_raw(&mut self.buf);
        self.write_buf(topic, schema, descriptor_set, log_time_ns)
    }

    /// A raw `lhm.v1` message on `topic` (schema `lhm.v1.<Name>`), after the same checks a sender
    /// runs ([`WireMessage::encode_checked`]): an invalid message is an error, not a record.
    pub fn write_wire<M: WireMessage>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        message: &M,
    ) -> Result<(), RecordError> {
        message.check().map_err(|source| RecordError::Invalid {
            path: self.path.clone(),
            topic: topic.into(),
            source,
        })?;
        // `check` passed: this is `encode_checked` reusing our buffer.
        self.write_proto(
            topic,
            M::FULL_NAME,
            FILE_DESCRIPTOR_SET,
            log_time_ns,
            message,
        )
    }

    /// `metrics` on [`METRICS_TOPIC`] at its own `unix_time_ms`, then ends the chunk: metrics
    /// arrive a batch at a time and each batch should survive a crash.
    pub fn write_metrics(&mut self, metrics: &Metrics) -> Result<(), RecordError> {
        let log_time_ns = metrics.unix_time_ms.saturating_mul(1_000_000);
        self.write_wire(METRICS_TOPIC, log_time_ns, metrics)?;
        self.flush()
    }

    /// One episode: per frame a `foxglove.SceneUpdate` on [`SCENE_TOPIC`] and a
    /// `foxglove.FrameTransforms` on [`TF_TOPIC`], frame `k` at `start_time_ns + k·frame_dt`;
    /// then an MCAP metadata record `episode` (who ran it, its stats) and the end of the chunk.
    ///
    /// `frames` must pass `lhm.v1` checks and match `scene` (task, body and object counts).
    /// Episodes should be written in time order: the first frame deletes every entity older than
    /// itself, so nothing of an earlier episode (another room) lingers.
    pub fn write_episode(
        &mut self,
        frames: &EpisodeFrames,
        scene: &EpisodeScene,
        start_time_ns: u64,
    ) -> Result<(), RecordError> {
        frames.check().map_err(|source| RecordError::Invalid {
            path: self.path.clone(),
            topic: SCENE_TOPIC.into(),
            source,
        })?;
        let mismatch = |field: &'static str, reason: String| RecordError::SceneMismatch {
            path: self.path.clone(),
            field,
            reason,
        };
        if frames.task_id != scene.task_id() {
            return Err(mismatch(
                "task_id",
                format!(
                    "{:?}, but the scene is of task {:?}",
                    frames.task_id,
                    scene.task_id()
                ),
            ));
        }
        if frames.num_bodies as usize != scene.num_bodies() {
            return Err(mismatch(
                "num_bodies",
                format!(
                    "{}, but the character has {} bodies",
                    frames.num_bodies,
                    scene.num_bodies()
                ),
            ));
        }
        if frames.num_objects as usize != scene.num_objects() {
            return Err(mismatch(
                "num_objects",
                format!(
                    "{}, but the task has {} objects",
                    frames.num_objects,
                    scene.num_objects()
                ),
            ));
        }
        // `check` guarantees a finite, positive frame_dt.
        let dt_ns = (f64::from(frames.frame_dt) * 1e9).round() as u64;
        for frame in 0..frames.num_frames as usize {
            let t = start_time_ns.saturating_add(dt_ns.saturating_mul(frame as u64));
            let update = scene.scene_update(frames, frame, t);
            self.write_proto(
                SCENE_TOPIC,
                SCENE_UPDATE,
                FOXGLOVE_DESCRIPTOR_SET,
                t,
                &update,
            )?;
            let transforms = scene.frame_transforms(frames, frame, t);
            self.write_proto(
                TF_TOPIC,
                FRAME_TRANSFORMS,
                FOXGLOVE_DESCRIPTOR_SET,
                t,
                &transforms,
            )?;
        }
        let metadata = Metadata {
            name: "episode".into(),
            metadata: episode_metadata(frames, start_time_ns),
        };
        self.writer
            .write_metadata(&metadata)
            .map_err(|e| self.mcap_err(e))?;
        self.flush()
    }

    /// Ends the current chunk and hands everything written so far to the OS: from here on a
    /// crash cannot lose it.
    pub fn flush(&mut self) -> Result<(), RecordError> {
        self.writer.flush().map_err(|e| self.mcap_err(e))
    }

    /// Writes the summary (indexes, statistics) and footer, and syncs the file to disk.
    /// Dropping a recorder without `finish` also writes them but cannot report errors.
    pub fn finish(mut self) -> Result<(), RecordError> {
        self.writer.finish().map_err(|e| self.mcap_err(e))?;
        let Self { path, writer, .. } = self;
        let file = writer
            .into_inner()
            .into_inner()
            .map_err(|e| RecordError::Close {
                path: path.clone(),
                source: e.into_error(),
            })?;
        file.sync_all()
            .map_err(|source| RecordError::Close { path, source })
    }
}

/// Who ran an episode and how it went, as MCAP metadata (Foxglove lists it with the file).
fn episode_metadata(frames: &EpisodeFrames, start_time_ns: u64) -> BTreeMap<String, String> {
    let role = Role::try_from(frames.role)
        .map_or_else(|_| frames.role.to_string(), |r| r.as_str_name().to_string());
    let mut m = BTreeMap::from([
        ("run_id".to_string(), frames.run_id.clone()),
        ("actor_id".to_string(), frames.actor_id.clone()),
        ("role".to_string(), role),
        (
            "policy_version".to_string(),
            frames.policy_version.to_string(),
        ),
        ("task_id".to_string(), frames.task_id.clone()),
        ("start_time_ns".to_string(), start_time_ns.to_string()),
        ("num_frames".to_string(), frames.num_frames.to_string()),
        ("frame_dt".to_string(), frames.frame_dt.to_string()),
    ]);
    if let Some(s) = &frames.stats {
        m.extend([
            ("return".to_string(), s.episode_return.to_string()),
            ("length".to_string(), s.length.to_string()),
            (
                "cycles_attempted".to_string(),
                s.cycles_attempted.to_string(),
            ),
            (
                "cycles_succeeded".to_string(),
                s.cycles_succeeded.to_string(),
            ),
            (
                "final_placement_error_m".to_string(),
                format!("{:?}", s.final_placement_error_m),
            ),
            ("fell".to_string(), s.fell.to_string()),
            ("physics_invalid".to_string(), s.physics_invalid.to_string()),
        ]);
    }
    m
}
