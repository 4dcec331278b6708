//! The label service's answers: the FSM picks the teacher per state, replies carry that teacher's
//! mean action and version, and every bad request becomes an error reply, never a panic.

use lhm_cluster::{encode_policy, RunSpec, TaskSet};
use lhm_dagger_server::{answer, teacher_for, Teachers};
use lhm_nets::{ActorCritic, ActorCriticConfig};
use lhm_protos::{prost::Message, LabelRequest, Role, Stage, WireMessage};

fn spec() -> RunSpec {
    RunSpec {
        obs_dim: 3,
        act_dim: 2,
        amp_dim: 0,
        actor_critic: ActorCriticConfig::with_hidden(&[8]),
        env: Default::default(),
        sim: Default::default(),
        tasks: TaskSet::TrainSingleObject,
        chunk_steps: 8,
        record_every_episodes: 0,
        chunk_sets_per_version: 0,
        teacher_mix: 0.0,
    }
}

fn teacher(role: Role, seed: u64, version: u64) -> (ActorCritic, Vec<u8>) {
    let mut s = spec();
    s.actor_critic.init_seed = seed;
    // Distinct output layers, so the two teachers' actions differ.
    s.actor_critic.policy.output_init_scale = 1.0;
    let ac = ActorCritic::new(3, 2, &s.actor_critic).unwrap();
    let bytes = encode_policy("run", role, version, &s, &ac)
        .unwrap()
        .encode_checked()
        .unwrap();
    (ac, bytes)
}

fn request(stages: &[Stage]) -> Vec<u8> {
    let n = stages.len();
    LabelRequest {
        run_id: "run".into(),
        request_id: 42,
        num_states: n as u32,
        obs_dim: 3,
        observations: (0..n * 3).map(|i| i as f32 * 0.1 - 0.2).collect(),
        stages: stages.iter().map(|s| *s as i32).collect(),
        ..LabelRequest::versioned()
    }
    .encode_checked()
    .unwrap()
}

#[test]
fn each_state_is_labelled_by_the_teacher_its_stage_selects() {
    assert_eq!(teacher_for(Stage::FirstCycle), Role::Teacher1);
    assert_eq!(teacher_for(Stage::NextCycle), Role::Teacher2);
    let (t1, b1) = teacher(Role::Teacher1, 1, 10);
    let (t2, b2) = teacher(Role::Teacher2, 2, 20);
    let mut teachers = Teachers::default();
    assert_eq!(teachers.update(&b1).unwrap(), Role::Teacher1);
    assert_eq!(teachers.update(&b2).unwrap(), Role::Teacher2);
    let reply = answer(&request(&[Stage::FirstCycle, Stage::NextCycle]), &teachers);
    assert_eq!(reply.error, "");
    assert_eq!(reply.request_id, 42);
    assert_eq!((reply.num_states, reply.act_dim), (2, 2));
    assert_eq!(
        reply.teachers,
        [Role::Teacher1 as i32, Role::Teacher2 as i32]
    );
    assert_eq!(reply.teacher_versions, [10, 20]);
    let obs: Vec<f32> = (0..6).map(|i| i as f32 * 0.1 - 0.2).collect();
    assert_eq!(
        reply.actions[..2],
        t1.act_deterministic(&obs[..3]).unwrap()[..]
    );
    assert_eq!(
        reply.actions[2..],
        t2.act_deterministic(&obs[3..]).unwrap()[..]
    );
    assert_ne!(reply.actions[..2], reply.actions[2..]);
    // The reply itself is a valid wire message.
    assert!(reply.encode_checked().is_ok());
}

#[test]
fn missing_teachers_and_bad_requests_are_error_replies() {
    let (_, b1) = teacher(Role::Teacher1, 1, 3);
    let mut teachers = Teachers::default();
    teachers.update(&b1).unwrap();
    let reply = answer(&request(&[Stage::NextCycle]), &teachers);
    assert!(reply.error.contains("teacher2"), "{}", reply.error);
    assert_eq!(reply.request_id, 42);

    let reply = answer(&[0xff; 17], &teachers);
    assert!(reply.error.contains("bad request"), "{}", reply.error);

    let mut wide = LabelRequest::decode(&request(&[Stage::FirstCycle])[..]).unwrap();
    wide.obs_dim = 1;
    wide.observations.truncate(1);
    let reply = answer(&wide.encode_to_vec(), &teachers);
    assert!(reply.error.contains("observations"), "{}", reply.error);
    assert!(teachers.update(&[1, 2, 3]).is_err());
}

#[test]
fn interleaved_stages_come_back_in_request_order_from_one_pass_per_teacher() {
    let (t1, b1) = teacher(Role::Teacher1, 1, 10);
    let (t2, b2) = teacher(Role::Teacher2, 2, 20);
    let mut teachers = Teachers::default();
    teachers.update(&b1).unwrap();
    teachers.update(&b2).unwrap();
    let stages = [
        Stage::NextCycle,
        Stage::FirstCycle,
        Stage::FirstCycle,
        Stage::NextCycle,
        Stage::FirstCycle,
    ];
    let reply = answer(&request(&stages), &teachers);
    assert_eq!(reply.error, "");
    assert_eq!(reply.actions.len(), stages.len() * 2);
    let obs: Vec<f32> = (0..stages.len() * 3)
        .map(|i| i as f32 * 0.1 - 0.2)
        .collect();
    for (i, stage) in stages.iter().enumerate() {
        let (net, role, version) = match stage {
            Stage::NextCycle => (&t2, Role::Teacher2, 20),
            _ => (&t1, Role::Teacher1, 10),
        };
        let want = net.act_deterministic(&obs[i * 3..i * 3 + 3]).unwrap();
        let got = &reply.actions[i * 2..i * 2 + 2];
        for (a, b) in got.iter().zip(&want) {
            // A batched pass may round differently from a single row.
            assert!((a - b).abs() < 1e-5, "row {i}: {got:?} vs {want:?}");
        }
        assert_eq!(reply.teachers[i], role as i32, "row {i}");
        assert_eq!(reply.teacher_versions[i], version, "row {i}");
    }
}
