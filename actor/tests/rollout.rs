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

/// Teacher 2 starts where Teacher 1 stopped: every environment of a teacher2 rollout is a
/// two-object task that Teacher 1 (mean actions) played up to the cycle switch, and replaying
/// that first cycle on a fresh copy of the task reaches exactly the same world, observation and
/// AMP history as the state Teacher 2's first chunk step records. No reset in between.
#[test]
fn teacher2_starts_from_teacher1s_last_state() {
    use lhm_actor::rollout::{run_first_cycle, FirstCycleEnd};
    let bench = Benchmark::embedded().unwrap();
    let model = CharacterModel::amp_humanoid();
    let mut env = EnvConfig::default();
    // A short cycle: Teacher 1 (an untrained policy here) hands off on the timeout.
    env.switching.max_cycle_steps = 6;
    let spec = RunSpec {
        obs_dim: TaskEnv::obs_dim(&model, &env),
        act_dim: model.dofs.len(),
        amp_dim: TaskEnv::amp_dim(&model, &env),
        actor_critic: ActorCriticConfig::with_hidden(&[32]),
        env,
        sim: SimConfig::default(),
        tasks: TaskSet::Ids(vec![
            "train-0001".into(),
            "train-0002.p1".into(),
            "train-0003".into(),
        ]),
        chunk_steps: 4,
        record_every_episodes: 0,
        chunk_sets_per_version: 0,
    };
    let teacher1 = ActorCritic::new(
        spec.obs_dim,
        spec.act_dim,
        &ActorCriticConfig {
            init_seed: 3,
            ..ActorCriticConfig::with_hidden(&[16])
        },
    )
    .unwrap();
    let teacher2 = ActorCritic::new(spec.obs_dim, spec.act_dim, &spec.actor_critic).unwrap();
    // Without Teacher 1 a teacher2 rollout is refused.
    let err = Rollout::new(spec.clone(), &bench, "run", "a", Role::Teacher2, 1, 0)
        .err()
        .unwrap();
    assert!(err.to_string().contains("Teacher 1"), "{err}");

    let mut rollout = Rollout::with_teacher1(
        spec.clone(),
        &bench,
        "run",
        "a",
        Role::Teacher2,
        3,
        11,
        Some(teacher1.clone()),
    )
    .unwrap();
    assert_eq!(
        rollout.teacher1_steps,
        3 * 6,
        "three first cycles of 6 steps"
    );
    for i in 0..rollout.num_envs() {
        let env = rollout.env(i);
        // The single-object task cannot host Teacher 2.
        assert_ne!(env.task.id, "train-0002.p1");
        assert_eq!(env.cycles.current, 1, "on the second pair");
        assert_eq!(env.steps(), 6);
        // The same task replayed from its start with the same Teacher 1.
        let task = bench.task(&env.task.id).unwrap().1;
        let mut replay = TaskEnv::new(
            &model,
            &task,
            &bench.catalogue,
            spec.sim.clone(),
            spec.env.clone(),
        );
        let (steps, end) = run_first_cycle(&mut replay, &teacher1).unwrap();
        assert_eq!((steps, end), (6, FirstCycleEnd::HandedOff));
        assert_eq!(replay.world.body_states(), env.world.body_states());
        assert_eq!(replay.observation(), env.observation());
        assert_eq!(replay.amp_features(), env.amp_features());
    }
    // Teacher 2's first chunk step records exactly that state.
    let first_obs: Vec<Vec<f32>> = (0..3).map(|i| rollout.env(i).observation()).collect();
    let mut chunks = Vec::new();
    for _ in 0..4 {
        chunks.extend(rollout.step(&teacher2, 1).unwrap().chunks);
    }
    assert_eq!(chunks.len(), 3);
    for c in &chunks {
        let obs_dim = spec.obs_dim;
        assert_eq!(
            c.observations[..obs_dim],
            first_obs[c.env_index as usize][..]
        );
        assert_eq!(c.role, Role::Teacher2 as i32);
    }
}
