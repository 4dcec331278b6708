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
        teacher_mix: 0.0,
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
        assert!(c.gait_stopped.is_empty(), "no gait, no stop flags");
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
        teacher_mix: 0.0,
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
        teacher_mix: 0.0,
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

/// A local teacher as the labeller: records the stages it was asked about.
struct LocalTeacher {
    teacher: ActorCritic,
    stages_seen: Vec<lhm_protos::Stage>,
}

impl lhm_actor::Labeller for LocalTeacher {
    fn label(
        &mut self,
        observations: &[f32],
        stages: &[lhm_protos::Stage],
    ) -> Result<Vec<f32>, String> {
        self.stages_seen.extend_from_slice(stages);
        self.teacher
            .act_deterministic(observations)
            .map_err(|e| e.to_string())
    }
}

/// The student's rollout (DAgger): every chunk row carries the teacher's label for the state it
/// records, whoever acted; with β = 1 the world follows the teacher exactly, with β = 0 the
/// student; the second cycle is labelled as a later cycle (Teacher 2's).
#[test]
fn a_student_rollout_records_teacher_labels_and_mixes_by_beta() {
    use lhm_actor::Behaviour;
    let bench = Benchmark::embedded().unwrap();
    let model = CharacterModel::amp_humanoid();
    let mut env = EnvConfig::default();
    // Short cycles: an untrained pair of policies hands off on the timeout.
    env.switching.max_cycle_steps = 5;
    let spec = RunSpec {
        obs_dim: TaskEnv::obs_dim(&model, &env),
        act_dim: model.dofs.len(),
        amp_dim: 0,
        actor_critic: ActorCriticConfig::with_hidden(&[16]),
        env,
        sim: SimConfig::default(),
        tasks: TaskSet::Ids(vec!["train-0004".into()]),
        chunk_steps: 8,
        record_every_episodes: 0,
        chunk_sets_per_version: 0,
        teacher_mix: 0.0,
    };
    let net = |seed| {
        ActorCritic::new(
            spec.obs_dim,
            spec.act_dim,
            &ActorCriticConfig {
                init_seed: seed,
                ..ActorCriticConfig::with_hidden(&[16])
            },
        )
        .unwrap()
    };
    let (student, teacher) = (net(1), net(2));
    // β = 1 and β = 0 from the same start, and a rollout driven by the policy itself.
    let run = |behaviour_beta: Option<f32>, acting: &ActorCritic| {
        let mut rollout =
            Rollout::new(spec.clone(), &bench, "run", "a", Role::Student, 2, 5).unwrap();
        let mut labeller = LocalTeacher {
            teacher: teacher.clone(),
            stages_seen: Vec::new(),
        };
        let mut chunks = Vec::new();
        for _ in 0..8 {
            let out = match behaviour_beta {
                Some(beta) => rollout
                    .step_with(
                        Behaviour::Dagger {
                            student: &student,
                            labeller: &mut labeller,
                            teacher_mix: beta,
                        },
                        3,
                    )
                    .unwrap(),
                None => {
                    // Mean actions of `acting`, as a deterministic reference trajectory.
                    let mut driver = LocalTeacher {
                        teacher: acting.clone(),
                        stages_seen: Vec::new(),
                    };
                    rollout
                        .step_with(
                            Behaviour::Dagger {
                                student: acting,
                                labeller: &mut driver,
                                teacher_mix: 1.0,
                            },
                            3,
                        )
                        .unwrap()
                }
            };
            chunks.extend(out.chunks);
        }
        (chunks, labeller.stages_seen)
    };
    let (beta1, stages) = run(Some(1.0), &teacher);
    let (beta0, _) = run(Some(0.0), &student);
    let (teacher_driven, _) = run(None, &teacher);
    let (student_driven, _) = run(None, &student);
    assert_eq!(beta1.len(), 2);
    for c in beta1.iter().chain(&beta0) {
        assert_eq!(c.num_steps, 8);
        assert_eq!(c.role, Role::Student as i32);
        TrajectoryChunk::decode_checked(&c.encode_checked().unwrap()).unwrap();
        // Each recorded action is the teacher's label of the recorded state (labelled in batches
        // of 2 there, of 8 here: matrix kernels may round differently by batch size).
        let relabelled = teacher.act_deterministic(&c.observations).unwrap();
        assert_eq!(c.actions.len(), relabelled.len());
        for (a, b) in c.actions.iter().zip(&relabelled) {
            assert!((a - b).abs() <= 1e-5 * (1.0 + b.abs()), "{a} vs {b}");
        }
        assert!(c.log_probs.iter().all(|&x| x == 0.0));
    }
    let states = |chunks: &[TrajectoryChunk]| -> Vec<Vec<f32>> {
        chunks.iter().map(|c| c.observations.clone()).collect()
    };
    assert_eq!(
        states(&beta1),
        states(&teacher_driven),
        "β = 1: the teacher acts"
    );
    assert_eq!(
        states(&beta0),
        states(&student_driven),
        "β = 0: the student acts"
    );
    assert_ne!(states(&beta1), states(&beta0));
    // 5-step cycles: steps 0-4 are the first cycle, then the second pair (Teacher 2's).
    assert_eq!(stages[0], lhm_protos::Stage::FirstCycle);
    assert!(stages.contains(&lhm_protos::Stage::NextCycle), "{stages:?}");
}

/// Under the Hierarchical RL baseline's skill machine, a skill's part of an episode that ends is
/// terminal in the chunk (no bootstrap across it) while the episode itself goes on: here the
/// first pair's object starts on its goal, so the place-and-release skill acts until the cycle
/// hands off to the second pair, which leaves it.
#[test]
fn a_skill_that_ends_is_terminal_in_the_chunk_and_the_episode_goes_on() {
    let mut bench = Benchmark::embedded().unwrap();
    let model = CharacterModel::amp_humanoid();
    let tasks = &mut bench
        .splits
        .get_mut(&lhm_scenes::Split::Train)
        .unwrap()
        .tasks;
    let task = tasks
        .iter_mut()
        .find(|t| t.sequence.len() >= 2)
        .expect("a two-object task");
    let first = task.sequence[0].clone();
    let object = task
        .objects
        .iter_mut()
        .find(|o| o.id == first.object)
        .unwrap();
    object.pos = first.goal;
    object.yaw = first.goal_yaw;
    let id = task.id.clone();
    let chunk = |skills: bool| {
        let env = EnvConfig {
            fall_height: -1.0,
            root_fall_height: -1.0,
            skills: skills.then(Default::default),
            ..EnvConfig::default()
        };
        let spec = RunSpec {
            obs_dim: TaskEnv::obs_dim(&model, &env),
            act_dim: model.dofs.len(),
            amp_dim: TaskEnv::amp_dim(&model, &env),
            actor_critic: ActorCriticConfig::with_hidden(&[16]),
            env,
            sim: SimConfig::default(),
            tasks: TaskSet::Ids(vec![id.clone()]),
            chunk_steps: 40,
            record_every_episodes: 0,
            chunk_sets_per_version: 0,
            teacher_mix: 0.0,
        };
        let ac = ActorCritic::new(spec.obs_dim, spec.act_dim, &spec.actor_critic).unwrap();
        let mut rollout = Rollout::new(spec, &bench, "run", "a", Role::Teacher1, 1, 3).unwrap();
        let mut chunks = Vec::new();
        for _ in 0..40 {
            let out = rollout.step(&ac, 1).unwrap();
            assert!(out.finished.is_empty(), "no episode ends in 40 steps");
            chunks.extend(out.chunks);
        }
        assert_eq!(chunks.len(), 1);
        chunks.remove(0)
    };
    let with = chunk(true);
    let ends: Vec<usize> = (0..40).filter(|&i| with.dones[i]).collect();
    assert_eq!(
        ends.len(),
        1,
        "one skill end, at the handoff: {:?}",
        with.dones
    );
    assert!(ends[0] >= 14, "the hold takes 15 steps: {ends:?}");
    assert!(!with.truncated[ends[0]] && with.episodes.is_empty());
    // The skill completion pays nothing here (the machine went back, to the next pair's walk);
    // the cycle's success does.
    assert!(with.rewards[ends[0]] > 10.0, "{}", with.rewards[ends[0]]);
    let without = chunk(false);
    assert!(without.dones.iter().all(|d| !d), "no skills, no ends");
}
