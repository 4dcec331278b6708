//! A rollout of real environments with a small policy: chunks of the configured length per
//! environment, one policy version each, valid on the wire, and episodes replaced in place.

use lhm_actor::Rollout;
use lhm_cluster::{RunSpec, TaskSet};
use lhm_nets::{ActorCritic, ActorCriticConfig};
use lhm_protos::{Role, TrajectoryChunk, WireMessage};
use lhm_scenes::Benchmark;
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::{CharacterModel, SimConfig};

#[test]
fn chunks_are_whole_versioned_and_valid() {
    let bench = Benchmark::embedded().unwrap();
    let model = CharacterModel::amp_humanoid();
    let env = EnvConfig {
        max_episode_steps: 10,
        ..EnvConfig::default()
    };
    let spec = RunSpec {
        obs_dim: TaskEnv::obs_dim(&model, &env),
        act_dim: model.dofs.len(),
        amp_dim: TaskEnv::amp_dim(&model, &env),
        actor_critic: ActorCriticConfig::with_hidden(&[32]),
        env,
        sim: SimConfig::default(),
        tasks: TaskSet::Ids(vec!["train-0001.p1".into(), "train-0002.p2".into()]),
        chunk_steps: 12,
        record_every_episodes: 1,
        chunk_sets_per_version: 0,
    };
    let ac = ActorCritic::new(spec.obs_dim, spec.act_dim, &spec.actor_critic).unwrap();
    let mut rollout = Rollout::new(spec.clone(), &bench, "run", "a", Role::Teacher1, 2, 7).unwrap();
    let mut chunks: Vec<TrajectoryChunk> = Vec::new();
    let mut frames = Vec::new();
    for step in 0..24 {
        assert_eq!(rollout.at_chunk_boundary(), step % 12 == 0);
        let out = rollout.step(&ac, 5).unwrap();
        chunks.extend(out.chunks);
        frames.extend(out.episode_frames);
    }
    assert_eq!(chunks.len(), 4, "2 environments x 2 chunks");
    for c in &chunks {
        assert_eq!(c.num_steps, 12);
        assert_eq!(c.policy_version, 5);
        TrajectoryChunk::decode_checked(&c.encode_checked().unwrap()).unwrap();
        // 10-step time limit: step 10 is truncated with its bootstrap value, episodes restart.
        let cut: Vec<usize> = (0..12).filter(|&t| c.truncated[t] || c.dones[t]).collect();
        assert!(
            !cut.is_empty(),
            "an episode ends inside every 12-step chunk"
        );
        for e in &c.episodes {
            assert!(e.task_id == "train-0001.p1" || e.task_id == "train-0002.p2");
            assert_eq!(e.final_placement_error_m.len() as u32, e.cycles_attempted);
        }
    }
    // Chunk sequence numbers are unique and increasing.
    let seqs: Vec<u64> = chunks.iter().map(|c| c.chunk_seq).collect();
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{seqs:?}");
    // Environment 0's episodes are captured (record_every_episodes = 1).
    assert!(!frames.is_empty());
    assert!(frames[0].num_frames >= 2);
    lhm_protos::EpisodeFrames::decode_checked(&frames[0].encode_checked().unwrap()).unwrap();
}

#[test]
fn a_spec_that_does_not_fit_the_environment_is_refused() {
    let bench = Benchmark::embedded().unwrap();
    let spec = RunSpec {
        obs_dim: 7,
        act_dim: 28,
        amp_dim: 0,
        actor_critic: ActorCriticConfig::with_hidden(&[8]),
        env: EnvConfig::default(),
        sim: SimConfig::default(),
        tasks: TaskSet::TrainSingleObject,
        chunk_steps: 8,
        record_every_episodes: 0,
        chunk_sets_per_version: 0,
    };
    let err = Rollout::new(spec, &bench, "run", "a", Role::Teacher1, 1, 0)
        .err()
        .unwrap();
    assert!(err.to_string().contains("observations"), "{err}");
}
