//! Recordings read back with the mcap crate's own readers: schemas, payloads, timing, and what
//! survives a crash.

use std::collections::BTreeMap;
use std::path::PathBuf;

use lhm_protos::foxglove::{scene_entity_deletion, FrameTransforms, SceneUpdate};
use lhm_protos::prost::Message;
use lhm_protos::{
    ActorState, ActorStatus, EpisodeFrames, EpisodeStats, Metrics, Role, WireMessage,
    FILE_DESCRIPTOR_SET, FOXGLOVE_DESCRIPTOR_SET,
};
use lhm_record::capture::{EpisodeCapture, EpisodeSource};
use lhm_record::{
    record_episode, EpisodeScene, McapRecorder, RecordError, METRICS_TOPIC, SCENE_TOPIC, TF_TOPIC,
};
use lhm_scenes::{Benchmark, Split, Task};
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::{CharacterModel, SimConfig};
use mcap::read::Options;

const STEPS: u32 = 20;

/// A fresh path under cargo's scratch directory for integration tests, in a directory that does
/// not exist yet (the recorder must create it).
fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("lhm-record-{}", std::process::id()))
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    dir.join("run.mcap")
}

struct Fixture {
    task: Task,
    scene: EpisodeScene,
    frames: EpisodeFrames,
}

/// A real episode: the first train task, the shipped humanoid, 20 control steps of zero action.
fn fixture() -> Fixture {
    let benchmark = Benchmark::embedded().expect("embedded benchmark");
    let model = CharacterModel::amp_humanoid();
    let task = benchmark.tasks(Split::Train)[0].clone();
    let mut env = TaskEnv::new(
        &model,
        &task,
        &benchmark.catalogue,
        SimConfig::default(),
        EnvConfig::default(),
    );
    let source = EpisodeSource {
        run_id: "test-run".into(),
        actor_id: "actor-0".into(),
        role: Role::Teacher1,
        policy_version: 3,
    };
    let mut capture = EpisodeCapture::new(&env, source);
    assert_eq!(capture.num_frames(), 1, "the start pose is frame 0");
    let zero = vec![0.0; model.dofs.len()];
    let mut ret = 0.0;
    for _ in 0..STEPS {
        ret += env.step(&zero).reward;
        assert!(capture.push(&env));
    }
    let frames = capture.finish(EpisodeStats {
        episode_return: ret,
        length: STEPS,
        cycles_attempted: 1,
        task_id: task.id.clone(),
        ..EpisodeStats::default()
    });
    let scene = EpisodeScene::new(&model, &task, &benchmark.catalogue);
    Fixture {
        task,
        scene,
        frames,
    }
}

fn metrics(t_ms: u64, iteration: u64) -> Metrics {
    Metrics {
        run_id: "test-run".into(),
        process: "learner".into(),
        unix_time_ms: t_ms,
        iteration,
        values: BTreeMap::from([("loss/policy".to_string(), 0.25 * iteration as f64)]),
        ..Metrics::versioned()
    }
}

fn status(chunks_sent: u64) -> ActorStatus {
    ActorStatus {
        run_id: "test-run".into(),
        actor_id: "actor-0".into(),
        role: Role::Teacher1.into(),
        state: ActorState::Running.into(),
        chunks_sent,
        ..ActorStatus::versioned()
    }
}

/// (topic, log time, payload) of a message read back.
type Read = (String, u64, Vec<u8>);

/// A linear, non-strict read (no end magic needed, as after a crash): every message up to the
/// first record that cannot be read, and whether the read ended on such an error.
fn read_linear(bytes: &[u8]) -> (Vec<Read>, bool) {
    let mut out = Vec::new();
    let Ok(stream) = mcap::MessageStream::new_with_options(bytes, Options::IgnoreEndMagic.into())
    else {
        return (out, true);
    };
    for message in stream {
        match message {
            Ok(m) => out.push((m.channel.topic.clone(), m.log_time, m.data.into_owned())),
            Err(_) => return (out, true),
        }
    }
    (out, false)
}

const EPISODE_START_NS: u64 = 1_700_000_000_000_000_000;

/// Metrics, raw messages and one episode, as a learner would record them.
fn write_run(path: &PathBuf, f: &Fixture) -> Result<(), RecordError> {
    let mut rec = McapRecorder::create(path)?;
    rec.write_metrics(&metrics(1_700_000_000_000, 1))?;
    rec.write_wire("/status/actor-0", EPISODE_START_NS - 10, &status(4))?;
    rec.write_wire("/status/actor-0", EPISODE_START_NS - 5, &status(5))?;
    rec.write_wire("/episodes", EPISODE_START_NS, &f.frames)?;
    rec.write_episode(&f.frames, &f.scene, EPISODE_START_NS)?;
    rec.write_metrics(&metrics(1_700_000_001_000, 2))?;
    rec.finish()
}

#[test]
fn recording_reads_back_with_foxglove_schemas() {
    let f = fixture();
    let path = scratch("read-back");
    write_run(&path, &f).expect("recording");
    let bytes = std::fs::read(&path).expect("read the recording");

    let n_frames = f.frames.num_frames as usize;
    assert_eq!(n_frames, STEPS as usize + 1);
    let n_bodies = f.scene.num_bodies();
    let n_objects = f.task.objects.len();
    assert_eq!(n_bodies, 15);
    assert_eq!(f.scene.num_objects(), n_objects);
    // Floor and walls, each obstacle, a goal marker per placement step.
    let n_room = 2 + f.task.obstacles.len() + f.task.sequence.len();
    assert_eq!(f.scene.num_entities(), n_bodies + n_objects + n_room);

    // The summary: one channel per topic, each protobuf with the right schema.
    let summary = mcap::Summary::read(&bytes)
        .expect("summary")
        .expect("a finished file has a summary");
    let mut by_topic = BTreeMap::new();
    for channel in summary.channels.values() {
        let schema = channel.schema.as_ref().expect("every channel has a schema");
        assert_eq!(channel.message_encoding, "protobuf", "{}", channel.topic);
        assert_eq!(schema.encoding, "protobuf", "{}", channel.topic);
        let previous = by_topic.insert(channel.topic.clone(), (channel.id, schema.clone()));
        assert!(previous.is_none(), "{} registered twice", channel.topic);
    }
    let expect = [
        (
            SCENE_TOPIC,
            "foxglove.SceneUpdate",
            FOXGLOVE_DESCRIPTOR_SET,
            n_frames,
        ),
        (
            TF_TOPIC,
            "foxglove.FrameTransforms",
            FOXGLOVE_DESCRIPTOR_SET,
            n_frames,
        ),
        (METRICS_TOPIC, "lhm.v1.Metrics", FILE_DESCRIPTOR_SET, 2),
        (
            "/status/actor-0",
            "lhm.v1.ActorStatus",
            FILE_DESCRIPTOR_SET,
            2,
        ),
        ("/episodes", "lhm.v1.EpisodeFrames", FILE_DESCRIPTOR_SET, 1),
    ];
    assert_eq!(by_topic.len(), expect.len(), "{:?}", by_topic.keys());
    let stats = summary.stats.as_ref().expect("statistics");
    for (topic, name, descriptor, count) in expect {
        let (id, schema) = &by_topic[topic];
        assert_eq!(schema.name, name, "{topic}");
        assert_eq!(&*schema.data, descriptor, "{topic}: schema data");
        assert_eq!(
            stats.channel_message_counts.get(id).copied(),
            Some(count as u64),
            "{topic}: message count"
        );
    }
    // Several chunks: the ones ended by metrics and the episode, and the episode's own cuts.
    assert!(
        summary.chunk_indexes.len() >= 3,
        "{}",
        summary.chunk_indexes.len()
    );

    // The messages, in the strict reader (end magic and all).
    let mut scenes = Vec::new();
    let mut transforms = Vec::new();
    let mut metrics_read = Vec::new();
    for message in mcap::MessageStream::new(&bytes).expect("strict read") {
        let m = message.expect("every message reads back");
        match m.channel.topic.as_str() {
            SCENE_TOPIC => scenes.push((m.log_time, SceneUpdate::decode(&*m.data).unwrap())),
            TF_TOPIC => transforms.push((m.log_time, FrameTransforms::decode(&*m.data).unwrap())),
            METRICS_TOPIC => metrics_read.push((m.log_time, Metrics::decode_checked(&m.data))),
            "/episodes" => {
                // The raw episode passes the receiver's checks and is what was captured.
                let decoded = EpisodeFrames::decode_checked(&m.data).expect("decode_checked");
                assert_eq!(decoded, f.frames);
            }
            "/status/actor-0" => {
                ActorStatus::decode_checked(&m.data).expect("decode_checked");
            }
            other => panic!("unexpected topic {other}"),
        }
    }
    assert_eq!(scenes.len(), n_frames);
    assert_eq!(transforms.len(), n_frames);
    assert_eq!(metrics_read.len(), 2);
    assert_eq!(metrics_read[0].0, 1_700_000_000_000 * 1_000_000);
    assert_eq!(
        metrics_read[1].1.as_ref().unwrap(),
        &metrics(1_700_000_001_000, 2)
    );

    let dt_ns = (f64::from(f.frames.frame_dt) * 1e9).round() as u64;
    for (k, ((t_scene, update), (t_tf, tf))) in scenes.iter().zip(&transforms).enumerate() {
        let t = EPISODE_START_NS + k as u64 * dt_ns;
        assert_eq!((*t_scene, *t_tf), (t, t), "frame {k} time");
        assert_eq!(
            update.entities.len(),
            n_bodies + n_objects + n_room,
            "frame {k}"
        );
        // Only the first frame clears what an earlier episode drew.
        if k == 0 {
            assert_eq!(update.deletions.len(), 1);
            assert_eq!(
                update.deletions[0].r#type,
                scene_entity_deletion::Type::All as i32
            );
        } else {
            assert!(update.deletions.is_empty());
        }
        let ids: Vec<&str> = update.entities.iter().map(|e| e.id.as_str()).collect();
        for o in &f.task.obstacles {
            assert!(ids.contains(&format!("obstacle/{}", o.id).as_str()));
        }
        for e in &update.entities {
            assert_eq!(e.frame_id, "world");
            let stamp = e.timestamp.expect("entity timestamp");
            assert_eq!(
                stamp.seconds as u64 * 1_000_000_000 + stamp.nanos as u64,
                t,
                "{}",
                e.id
            );
            assert!(
                e.cubes.len() + e.spheres.len() + e.cylinders.len() > 0,
                "{} draws nothing",
                e.id
            );
        }
        // World -> every body and object frame, at the captured poses.
        assert_eq!(tf.transforms.len(), n_bodies + n_objects);
        let pelvis = &tf.transforms[0];
        assert_eq!(
            (
                pelvis.parent_frame_id.as_str(),
                pelvis.child_frame_id.as_str()
            ),
            ("world", "body/pelvis")
        );
        let p = pelvis.translation.unwrap();
        let want = &f.frames.body_positions[k * n_bodies * 3..k * n_bodies * 3 + 3];
        assert!(
            (p.x as f32 - want[0]).abs() < 1e-6 && (p.z as f32 - want[2]).abs() < 1e-6,
            "frame {k}: pelvis at {p:?}, captured {want:?}"
        );
        // The pelvis sphere sits 7 cm above the pelvis origin, turned with the body.
        let pelvis_entity = update
            .entities
            .iter()
            .find(|e| e.id == "body/pelvis")
            .expect("pelvis entity");
        let sphere = pelvis_entity.spheres[0].pose.unwrap().position.unwrap();
        let offset =
            ((sphere.x - p.x).powi(2) + (sphere.y - p.y).powi(2) + (sphere.z - p.z).powi(2)).sqrt();
        assert!(
            (offset - 0.07).abs() < 1e-4,
            "pelvis sphere offset {offset}"
        );
    }
    // The capsule limbs: a cylinder plus two end spheres each.
    let thigh = scenes[0]
        .1
        .entities
        .iter()
        .find(|e| e.id == "body/left_thigh")
        .expect("thigh");
    assert_eq!((thigh.cylinders.len(), thigh.spheres.len()), (1, 2));
    // The character does move in 20 steps of zero action (it starts to sag).
    let first = &transforms[0].1.transforms[0].translation.unwrap();
    let last = &transforms[n_frames - 1].1.transforms[0]
        .translation
        .unwrap();
    assert!((first.z - last.z).abs() > 1e-4, "{first:?} vs {last:?}");

    // Who ran the episode, as MCAP metadata.
    assert_eq!(summary.metadata_indexes.len(), 1);
    let meta = mcap::read::metadata(&bytes, &summary.metadata_indexes[0]).expect("metadata");
    assert_eq!(meta.name, "episode");
    assert_eq!(meta.metadata["task_id"], f.task.id);
    assert_eq!(meta.metadata["role"], "ROLE_TEACHER1");
    assert_eq!(meta.metadata["num_frames"], n_frames.to_string());
}

#[test]
fn completed_chunks_survive_truncation() {
    let f = fixture();
    let path = scratch("truncated");
    write_run(&path, &f).expect("recording");
    let bytes = std::fs::read(&path).expect("read the recording");
    let (all, error) = read_linear(&bytes);
    assert!(!error);
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let total: u64 = summary
        .stats
        .as_ref()
        .unwrap()
        .channel_message_counts
        .values()
        .sum();
    assert_eq!(all.len() as u64, total);

    // Cut just before the summary section, and again before the data-end record in front of it
    // (13 bytes: opcode, length, CRC): the data section is whole, so nothing is lost.
    let footer = mcap::read::footer(&bytes).expect("footer");
    let summary_start = footer.summary_start as usize;
    assert!(summary_start > 0);
    for cut in [summary_start, summary_start - 13] {
        assert!(!matches!(mcap::Summary::read(&bytes[..cut]), Ok(Some(_))));
        let (read, _) = read_linear(&bytes[..cut]);
        assert_eq!(read, all, "cut at {cut} of {}", bytes.len());
    }

    // Cut inside the last chunk: every message of the earlier chunks, in order, and none of it.
    let messages_in = |index: &mcap::records::ChunkIndex| {
        summary.stream_chunk(&bytes, index).expect("chunk").count()
    };
    let last = summary.chunk_indexes.last().expect("chunks");
    let in_last = messages_in(last);
    assert!(in_last > 0);
    let cut = (last.chunk_start_offset + last.chunk_length / 2) as usize;
    let (read, error) = read_linear(&bytes[..cut]);
    assert!(error, "a half chunk is reported, not silently accepted");
    assert_eq!(read.len(), all.len() - in_last);
    assert_eq!(read[..], all[..read.len()]);

    // And inside the middle of the file: exactly the chunks that ended before the cut.
    let middle = &summary.chunk_indexes[summary.chunk_indexes.len() / 2];
    let cut = (middle.chunk_start_offset + 20) as usize;
    let complete: usize = summary
        .chunk_indexes
        .iter()
        .filter(|c| c.chunk_start_offset < middle.chunk_start_offset)
        .map(messages_in)
        .sum();
    let (read, _) = read_linear(&bytes[..cut]);
    assert_eq!(read.len(), complete);
    assert_eq!(read[..], all[..complete]);
}

#[test]
fn a_crash_keeps_everything_before_the_last_flush() {
    let f = fixture();
    let path = scratch("crash");
    let mut rec = McapRecorder::create(&path).expect("create");
    rec.write_metrics(&metrics(1_700_000_000_000, 1)).unwrap();
    rec.write_episode(&f.frames, &f.scene, EPISODE_START_NS)
        .unwrap();
    // Unflushed: enough to push part of an unfinished chunk through the 8 KiB write buffer.
    for i in 0..20 {
        rec.write_wire("/episodes", EPISODE_START_NS + i, &f.frames)
            .unwrap();
    }
    // A crash: no finish, no drop (which would write the summary), no buffer flush.
    std::mem::forget(rec);

    let bytes = std::fs::read(&path).expect("read the crashed recording");
    assert!(!matches!(mcap::Summary::read(&bytes), Ok(Some(_))));
    let (read, _) = read_linear(&bytes);
    let frames = f.frames.num_frames as usize;
    assert_eq!(read.len(), 1 + 2 * frames, "metrics and the whole episode");
    assert_eq!(read[0].0, METRICS_TOPIC);
    assert!(read[1..]
        .iter()
        .all(|(t, _, _)| t == SCENE_TOPIC || t == TF_TOPIC));
    assert!(read.iter().all(|(t, _, _)| t != "/episodes"));
}

#[test]
fn record_episode_writes_a_complete_file() {
    let f = fixture();
    let path = scratch("one-episode");
    record_episode(&path, &f.frames, &f.scene).expect("record");
    let bytes = std::fs::read(&path).unwrap();
    let messages: Vec<_> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .collect::<Result<_, _>>()
        .expect("strict read");
    assert_eq!(messages.len(), 2 * f.frames.num_frames as usize);
    // Episode time: the first frame at 0, the last at (frames - 1) control periods.
    assert_eq!(messages[0].log_time, 0);
    let last = messages.last().unwrap().log_time as f64 * 1e-9;
    let expected = f64::from(f.frames.num_frames - 1) * f64::from(f.frames.frame_dt);
    assert!((last - expected).abs() < 1e-6, "{last} vs {expected}");
}

#[test]
fn errors_name_the_file_and_the_problem() {
    let f = fixture();

    // A parent that is a file, not a directory.
    let blocker = scratch("errors");
    std::fs::create_dir_all(blocker.parent().unwrap()).unwrap();
    std::fs::write(&blocker, b"not a directory").unwrap();
    let inside = blocker.join("run.mcap");
    let e = McapRecorder::create(&inside).err().expect("cannot create");
    assert!(matches!(e, RecordError::CreateDir { .. }), "{e:?}");
    assert!(e.to_string().contains("run.mcap"), "{e}");

    let path = blocker.with_file_name("ok.mcap");
    let mut rec = McapRecorder::create(&path).unwrap();
    let shown = path.display().to_string();

    // Frames of one task drawn in another task's scene.
    let benchmark = Benchmark::embedded().unwrap();
    let other = &benchmark.tasks(Split::Train)[1];
    let other_scene =
        EpisodeScene::new(&CharacterModel::amp_humanoid(), other, &benchmark.catalogue);
    let e = rec
        .write_episode(&f.frames, &other_scene, 0)
        .expect_err("wrong scene");
    assert!(
        matches!(
            e,
            RecordError::SceneMismatch {
                field: "task_id",
                ..
            }
        ),
        "{e:?}"
    );
    assert!(
        e.to_string().contains(&shown) && e.to_string().contains("task_id"),
        "{e}"
    );

    // Frames that fail the lhm.v1 checks are refused, naming the field.
    let broken = EpisodeFrames {
        num_frames: f.frames.num_frames + 1,
        ..f.frames.clone()
    };
    let e = rec
        .write_episode(&broken, &f.scene, 0)
        .expect_err("invalid");
    assert!(e.to_string().contains("body_positions"), "{e}");
    let e = rec
        .write_metrics(&Metrics {
            run_id: String::new(),
            ..metrics(1, 1)
        })
        .expect_err("invalid metrics");
    assert!(e.to_string().contains("lhm.v1.Metrics.run_id"), "{e}");

    // One schema per topic.
    rec.write_metrics(&metrics(1, 1)).unwrap();
    let e = rec
        .write_wire(METRICS_TOPIC, 2, &status(1))
        .expect_err("schema conflict");
    assert!(
        matches!(
            e,
            RecordError::TopicSchema {
                existing: "lhm.v1.Metrics",
                ..
            }
        ),
        "{e:?}"
    );
    rec.finish().unwrap();
}
