//! The wired task environment.

use lhm_scenes::{Benchmark, Split};
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::task::cycles::Handoff;
use lhm_sim::{CharacterModel, SimConfig};
use rapier3d::prelude::*;

fn setup(config: EnvConfig) -> (CharacterModel, TaskEnv) {
    let b = Benchmark::embedded().expect("benchmark");
    let model = CharacterModel::amp_humanoid();
    let task = &b.tasks(Split::Train)[1];
    let env = TaskEnv::new(&model, task, &b.catalogue, SimConfig::default(), config);
    (model, env)
}

#[test]
fn observations_have_their_dimensions_and_a_fall_is_terminal() {
    let mut config = EnvConfig::default();
    config.weights.alive = 0.5;
    let (model, mut env) = setup(config.clone());
    // Knees and elbows at mid-range: a crouch that tips over (zero action would stand).
    let zero: Vec<f32> = model
        .dofs
        .iter()
        .map(|d| {
            if d.name.ends_with("knee") || d.name.ends_with("elbow") {
                0.5
            } else {
                0.0
            }
        })
        .collect();
    assert_eq!(env.observation().len(), TaskEnv::obs_dim(&model, &config));
    assert_eq!(env.amp_features().len(), TaskEnv::amp_dim(&model, &config));
    let mut ended = None;
    for step in 0..300 {
        let r = env.step(&zero);
        let obs = env.observation();
        assert!(
            obs.iter()
                .chain(env.amp_features().iter())
                .all(|x| x.is_finite()),
            "step {step}"
        );
        assert!(r.reward.is_finite() && r.terms.power <= 0.0);
        // The alive term pays on every step but the one that falls, and the step's reward is
        // the sum of the weighted terms.
        assert_eq!(r.terms.alive, if r.fell { 0.0 } else { 1.0 }, "step {step}");
        let sum: f32 = r
            .terms
            .weighted(&config.weights)
            .iter()
            .map(|(_, v)| v)
            .sum();
        assert!((r.reward - sum).abs() < 1e-6, "step {step}");
        if r.done {
            ended = Some((step, r));
            break;
        }
    }
    let (step, r) = ended.expect("the crouch falls within 10 s");
    assert!(r.fell && !r.truncated && !r.physics_invalid, "{r:?}");
    assert!(step > 10, "fell at step {step}");
}

#[test]
fn env_snapshot_restore_replays_observations_and_rewards() {
    let (model, mut env) = setup(EnvConfig {
        fall_height: -1.0,
        ..EnvConfig::default()
    });
    let action: Vec<f32> = (0..model.dofs.len())
        .map(|i| ((i * 7 % 5) as f32 - 2.0) * 0.15)
        .collect();
    for _ in 0..5 {
        env.step(&action);
    }
    let snap = env.snapshot();
    let run = |env: &mut TaskEnv| {
        (0..60)
            .map(|_| {
                let r = env.step(&action);
                (
                    env.observation(),
                    env.amp_features(),
                    r.reward.to_bits(),
                    r.done,
                )
            })
            .collect::<Vec<_>>()
    };
    let first = run(&mut env);
    env.restore(&snap);
    assert!(first == run(&mut env), "replay differs");
}

#[test]
fn pairs_hand_off_without_a_reset_when_objects_settle_on_their_goals() {
    let config = EnvConfig {
        fall_height: -1.0,
        ..EnvConfig::default()
    };
    let (model, mut env) = setup(config.clone());
    let zero = vec![0.0; model.dofs.len()];
    let mut handoffs = Vec::new();
    for pair in 0..env.task.sequence.len() {
        // Put the current object on its goal, at rest (as a perfect placement would leave it).
        let step = env.task.sequence[pair].clone();
        let i = env.task.object_index(&step.object).expect("object");
        let h = env.world.room.objects[i];
        let goal = Vector::new(
            step.goal[0] as f32,
            step.goal[1] as f32,
            step.goal[2] as f32 + 0.002,
        );
        let body = &mut env.world.state.bodies[h];
        body.set_position(
            Pose::from_parts(goal, Rotation::from_rotation_z(step.goal_yaw as f32)),
            true,
        );
        body.set_linvel(Vector::ZERO, true);
        body.set_angvel(Vector::ZERO, true);
        let mut steps = 0;
        loop {
            let r = env.step(&zero);
            steps += 1;
            if r.handoff != Handoff::Continue {
                handoffs.push((r.handoff, r.done));
                break;
            }
            assert!(steps < 100, "pair {pair} never handed off");
        }
        assert!(
            steps >= config.switching.hold_steps as usize,
            "held {steps} steps"
        );
    }
    assert_eq!(
        handoffs,
        vec![(Handoff::Next, false), (Handoff::Done, true)]
    );
    assert!(
        env.cycles
            .results
            .iter()
            .all(|r| r.success && r.dist < 0.05),
        "{:?}",
        env.cycles.results
    );
    // One continuous world: its step counter is the sum of the cycles' steps, and the first
    // object is still on its goal after the second pair.
    assert_eq!(
        env.world.control_steps as usize,
        env.cycles
            .results
            .iter()
            .map(|r| r.steps as usize)
            .sum::<usize>()
    );
    let first = &env.task.sequence[0];
    let i = env.task.object_index(&first.object).expect("object");
    let p = env.world.object_pose(i).expect("pose").translation;
    let goal = Vector::new(
        first.goal[0] as f32,
        first.goal[1] as f32,
        first.goal[2] as f32,
    );
    assert!((p - goal).length() < 0.05, "first object moved to {p:?}");
}

#[test]
fn under_the_skill_machine_each_step_pays_the_acting_skill_and_a_skill_ends_when_it_moves_on() {
    use lhm_sim::task::skills::Skill;
    let mut config = EnvConfig {
        fall_height: -1.0,
        root_fall_height: -1.0,
        skills: Some(Default::default()),
        ..EnvConfig::default()
    };
    config.weights.release_retreat = 0.5;
    let (model, mut env) = setup(config.clone());
    let plain = EnvConfig::default();
    assert_eq!(
        TaskEnv::obs_dim(&model, &config),
        TaskEnv::obs_dim(&model, &plain) + 5,
        "the skill one-hot follows the obstacle map"
    );
    let obs = env.observation();
    assert_eq!(obs.len(), TaskEnv::obs_dim(&model, &config));
    assert_eq!(
        env.current_skill(),
        Some(Skill::Walk),
        "objects start out of reach"
    );
    assert_eq!(&obs[obs.len() - 5..], &[1.0, 0.0, 0.0, 0.0, 0.0]);
    let zero = vec![0.0; model.dofs.len()];
    let r = env.step(&zero);
    assert!(!r.skill_ended && r.terms.skill == 0.0);
    assert_eq!(r.weights, Skill::Walk.reward_weights(&config.weights));
    assert_eq!((r.weights.hands, r.weights.place), (0.0, 0.0));
    let sum: f32 = r.terms.weighted(&r.weights).iter().map(|(_, v)| v).sum();
    assert!((r.reward - sum).abs() < 1e-6);
    // The object dropped onto its goal from 30 cm: once it lands, the machine moves on from
    // walking to placing, which completes the acting skill (its bonus, terminal for its
    // return) without ending the episode.
    let step = env.task.sequence[0].clone();
    let i = env.task.object_index(&step.object).expect("object");
    let h = env.world.room.objects[i];
    let body = &mut env.world.state.bodies[h];
    body.set_position(
        Pose::from_parts(
            Vector::new(
                step.goal[0] as f32,
                step.goal[1] as f32,
                step.goal[2] as f32 + 0.3,
            ),
            Rotation::from_rotation_z(step.goal_yaw as f32),
        ),
        true,
    );
    body.set_linvel(Vector::ZERO, true);
    body.set_angvel(Vector::ZERO, true);
    let mut landed = None;
    for k in 0..60 {
        assert_eq!(env.current_skill(), Some(Skill::Walk), "step {k}");
        let r = env.step(&zero);
        assert_eq!(r.weights, Skill::Walk.reward_weights(&config.weights));
        if r.skill_ended {
            landed = Some(r);
            break;
        }
        assert_eq!(r.terms.skill, 0.0);
    }
    let r = landed.expect("the dropped object lands on its goal within 2 s");
    assert!(r.terms.skill == 1.0 && !r.done, "{r:?}");
    assert_eq!(env.current_skill(), Some(Skill::Place));
    let obs = env.observation();
    assert_eq!(&obs[obs.len() - 5..], &[0.0, 0.0, 0.0, 0.0, 1.0]);
    // Placing until the cycle hands off: paid for placing, and the handoff leaves the skill
    // (no bonus: the cycle's own success pays) for the next pair's walk.
    let mut handed_off = false;
    for _ in 0..100 {
        let r = env.step(&zero);
        assert_eq!(r.weights, Skill::Place.reward_weights(&config.weights));
        assert!(r.weights.place > 0.0 && r.weights.locomotion == 0.0);
        if r.handoff == Handoff::Next {
            assert!(r.skill_ended && r.terms.skill == 0.0 && r.terms.success == 1.0);
            handed_off = true;
            break;
        }
        assert!(!r.skill_ended, "placing goes on until the handoff");
    }
    assert!(handed_off, "the placed pair never handed off");
    assert_eq!(env.current_skill(), Some(Skill::Walk));
}

/// The character lying on its back across the task's tallest piece of furniture, 10 cm above
/// its top, at rest.
fn lying_on_furniture(env: &mut TaskEnv, model: &CharacterModel) {
    use lhm_sim::motion::retarget::{resting_states, KinematicPose};
    let top = env
        .task
        .obstacles
        .iter()
        .max_by(|a, b| a.size[2].total_cmp(&b.size[2]))
        .expect("the task has furniture")
        .clone();
    assert!(top.size[2] > 0.4, "{top:?}");
    let pose = KinematicPose {
        root_pos: Vector::new(
            top.pos[0] as f32,
            top.pos[1] as f32,
            top.size[2] as f32 + 0.2,
        ),
        root_rot: Rotation::from_rotation_y(-std::f32::consts::FRAC_PI_2),
        local_rots: vec![Rotation::IDENTITY; model.bodies.len()],
    };
    env.world
        .set_character_state(&pose, &resting_states(model, &pose));
}

#[test]
fn lying_across_furniture_is_a_fall_though_every_body_is_high() {
    let (model, mut on) = setup(EnvConfig::default());
    let (_, mut off) = setup(EnvConfig {
        fall_on_furniture: false,
        ..EnvConfig::default()
    });
    lying_on_furniture(&mut on, &model);
    lying_on_furniture(&mut off, &model);
    let zero = vec![0.0; model.dofs.len()];
    let fell_at = (1..=15).find(|_| on.step(&zero).fell);
    let Some(k) = fell_at else {
        panic!("resting on the furniture never counted as a fall")
    };
    let mut off_fell = false;
    for _ in 0..k {
        off_fell |= off.step(&zero).fell;
    }
    assert!(
        !off_fell,
        "by the height rules alone it is up at step {k} (the test's premise)"
    );
    assert!(
        on.world.furniture_contacts()[0] || on.world.furniture_contacts()[1],
        "pelvis or torso on the furniture"
    );
}
