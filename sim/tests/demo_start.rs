//! Reference-state initialisation and the one velocity definition of the AMP features, on a
//! synthetic clip (no downloads): a start reproduces the clip's frame, and the environment's AMP
//! frames of a replayed clip agree with the demo's.

use lhm_scenes::Benchmark;
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::fidelity::joint_angles;
use lhm_sim::motion::demo::{AmpWindow, DemoMotion};
use lhm_sim::motion::retarget::{forward_kinematics, resting_states, KinematicPose};
use lhm_sim::obs::{amp_frame, finite_difference_states, BodyState};
use lhm_sim::{CharacterModel, SimConfig};
use rapier3d::math::{Rotation, Vector};

/// 3 s at 30 fps: the root glides forward at 0.8 m/s while turning, the right knee and hip swing.
fn synthetic_clip(model: &CharacterModel) -> Vec<KinematicPose> {
    let knee = model.body_index("right_shin").unwrap();
    let hip = model.body_index("right_thigh").unwrap();
    (0..90)
        .map(|i| {
            let t = i as f32 / 30.0;
            let mut local_rots = vec![Rotation::IDENTITY; model.bodies.len()];
            local_rots[knee] = Rotation::from_rotation_y(0.6 + 0.4 * (3.0 * t).sin());
            local_rots[hip] = Rotation::from_rotation_x(0.2 * t.sin())
                * Rotation::from_rotation_y(-0.4 * (2.0 * t).sin());
            KinematicPose {
                root_pos: Vector::new(0.8 * t, 0.1, 0.95),
                root_rot: Rotation::from_rotation_z(0.3 * t),
                local_rots,
            }
        })
        .collect()
}

fn setup() -> (CharacterModel, DemoMotion, TaskEnv) {
    let model = CharacterModel::amp_humanoid();
    let env_config = EnvConfig::default();
    let sim = SimConfig::default();
    let demo = DemoMotion::from_clips(
        &model,
        vec![("synthetic".into(), synthetic_clip(&model), 1.0 / 30.0)],
        AmpWindow::of(&env_config, &sim),
    )
    .unwrap();
    let bench = Benchmark::embedded().unwrap();
    let (_, task) = bench.task("train-0001").unwrap();
    let env = TaskEnv::new(&model, &task, &bench.catalogue, sim, env_config);
    (model, demo, env)
}

#[test]
fn a_demo_start_reproduces_the_clip_frame_pose_and_velocities() {
    let (model, demo, mut env) = setup();
    let t = 1.0;
    env.start_from_demo(&demo, 0, t);
    assert!(env.demo_start);
    let world = env.world.body_states();
    let (clip, _) = demo.start_states(0, t);
    // Joint angles and root height as in the clip; root over the task's start.
    let a = joint_angles(&model, &world);
    let b = joint_angles(&model, &clip);
    for (d, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!((x - y).abs() < 1e-3, "{}: {x} vs {y}", model.dofs[d].name);
    }
    assert!((world[0].pos.z - clip[0].pos.z).abs() < 1e-4);
    let start = &env.task.start;
    let dx = world[0].pos.x - start.pos[0] as f32;
    let dy = world[0].pos.y - start.pos[1] as f32;
    assert!(
        dx.hypot(dy) < 1e-4,
        "root {:?} vs start {:?}",
        world[0].pos,
        start.pos
    );
    // Speeds are the clip's (turned with the heading, so compared as lengths).
    for (w, c) in world.iter().zip(&clip) {
        assert!((w.linvel.length() - c.linvel.length()).abs() < 1e-3);
        assert!((w.angvel.length() - c.angvel.length()).abs() < 1e-3);
    }
    // The multibody itself moves that way (its generalised velocities, not only the rigid
    // bodies' reported ones): with the servos off, one pipeline step later the knee has turned
    // by about its clip velocity times the step.
    for d in env.world.character.model.dofs.iter_mut() {
        d.kp = 1e-9;
        d.kd = 0.0;
    }
    let knee = model
        .dofs
        .iter()
        .position(|d| d.name == "right_knee")
        .unwrap();
    let zero = vec![0.0; model.dofs.len()];
    env.world.step_targets(&zero);
    let dt = 1.0 / 30.0;
    let moved = joint_angles(&model, &env.world.body_states())[knee] - a[knee];
    let (later, _) = demo.start_states(0, t + dt);
    let expected = joint_angles(&model, &later)[knee] - b[knee];
    assert!(expected.abs() > 0.02, "the clip's knee moves: {expected}");
    assert!(
        (moved - expected).abs() < 0.35 * expected.abs(),
        "knee moved {moved} rad in one control step, the clip {expected}"
    );
}

#[test]
fn a_demo_start_turned_toward_the_object_faces_it() {
    let (_, demo, mut env) = setup();
    let t = 1.0;
    let yaw = env.yaw_toward_first_object();
    env.start_from_demo_heading(&demo, 0, t, yaw);
    let root = env.world.body_states()[0];
    let heading = root.rot * Vector::X;
    // The direction from the root (over the task's start) to the first object.
    let step = &env.task.sequence[0];
    let object = env
        .task
        .objects
        .iter()
        .find(|o| o.id == step.object)
        .unwrap();
    let to = Vector::new(
        (object.pos[0] - env.task.start.pos[0]) as f32,
        (object.pos[1] - env.task.start.pos[1]) as f32,
        0.0,
    )
    .normalize();
    let h = Vector::new(heading.x, heading.y, 0.0).normalize();
    assert!(
        h.dot(to) > 0.999,
        "heading {h:?} vs direction to the object {to:?}"
    );
    // The task's own start heading is another direction for this task, so the turn is real.
    let start = Vector::new(
        env.task.start.yaw.cos() as f32,
        env.task.start.yaw.sin() as f32,
        0.0,
    );
    assert!(
        start.dot(to) < 0.99,
        "train-0001's object lies ahead already"
    );
}

#[test]
fn replayed_clip_gives_the_demo_amp_frames() {
    // The environment's AMP path (backward differences of poses one control step apart) on a
    // kinematic replay equals DemoMotion's features frame for frame.
    let (model, demo, _) = setup();
    let dt = 1.0 / 30.0;
    let states = |t: f32| -> Vec<BodyState> { resting_states(&model, &demo.pose_at(0, t)) };
    for k in 2..80 {
        let t = k as f32 * dt;
        let env_frame = amp_frame(
            &model,
            &finite_difference_states(&states(t - dt), &states(t), dt),
        );
        let demo_frame = demo.amp_frame_at(0, t);
        let worst = env_frame
            .iter()
            .zip(&demo_frame)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "frame {k}: max difference {worst}");
    }
}

#[test]
fn a_looped_clip_repeats_past_its_end_moved_by_its_own_cycle_and_others_stop() {
    let (model, mut demo, _) = setup();
    let dt = 1.0 / 30.0;
    let period = 89.0 / 30.0;
    // Not looped: a start 0.51 s before the end tracks 15 steps and stops.
    let track = demo.reference_track(0, period - 0.51, 60, dt);
    assert_eq!(track.len(), 15, "{}", track.len());
    demo.set_looped(0, true);
    let t0 = period - 0.5;
    let track = demo.reference_track(0, t0, 60, dt);
    assert_eq!(track.len(), 60);
    // One period after its end, the clip's first-frame pose moved by its own cycle: the root
    // heading has turned by the clip's 0.3 rad/s × period and the root has moved on.
    let k = ((period + 1.0 - t0) / dt).round() as usize - 1; // t = period + 1 s
    let first_pass = demo.body_states_at(0, 1.0);
    let second = &track[k];
    let yaw = |r: Rotation| {
        let f = r * Vector::X;
        f.y.atan2(f.x)
    };
    let turn = 0.3 * period;
    let dyaw = (yaw(second[0].rot) - yaw(first_pass[0].rot) - turn).sin();
    assert!(dyaw.abs() < 1e-3, "heading off by {dyaw}");
    // Cycle move: the root frame of frame 0 onto the last frame's.
    let p0 = forward_kinematics(&model, &demo.pose_at(0, 0.0))[0].0;
    let pn = forward_kinematics(&model, &demo.pose_at(0, period))[0].0;
    let step = Rotation::from_rotation_z(turn);
    let want =
        Vector::new(pn.x, pn.y, 0.0) + step * (first_pass[0].pos - Vector::new(p0.x, p0.y, 0.0));
    assert!(
        (second[0].pos - want).length() < 1e-3,
        "{:?} vs {want:?}",
        second[0].pos
    );
    // Heights and joint angles repeat unchanged.
    assert!((second[0].pos.z - first_pass[0].pos.z).abs() < 1e-5);
    let a = joint_angles(&model, second);
    let b = joint_angles(&model, &first_pass);
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).abs() < 1e-3, "{x} vs {y}");
    }
}

#[test]
fn the_imitation_term_pays_for_following_the_demo_start_clip_and_only_then() {
    let (model, demo, _) = setup();
    let bench = Benchmark::embedded().unwrap();
    let (_, task) = bench.task("train-0001").unwrap();
    let mut config = EnvConfig::default();
    config.weights.imitation = 1.0;
    let sim = SimConfig::default();
    let make = || TaskEnv::new(&model, &task, &bench.catalogue, sim.clone(), config.clone());
    // From a demo start, holding the clip's own joint angles for one step follows the clip
    // closely: a high imitation term, paid into the task reward.
    let mut env = make();
    env.start_from_demo(&demo, 0, 1.0);
    let hold = zero_error_action(&model, &env);
    let r = env.step(&hold);
    assert!(r.terms.imitation > 0.6, "{}", r.terms.imitation);
    // A task start has nothing to imitate.
    let mut plain = make();
    let r = plain.step(&hold);
    assert_eq!(r.terms.imitation, 0.0);
    // Off by default: the same demo start with weight 0 records no term.
    let mut off = TaskEnv::new(
        &model,
        &task,
        &bench.catalogue,
        sim.clone(),
        EnvConfig::default(),
    );
    off.start_from_demo(&demo, 0, 1.0);
    assert_eq!(off.step(&hold).terms.imitation, 0.0);
    // Lying on the floor 1 s later earns far less than following.
    let mut lying = make();
    lying.start_from_demo(&demo, 0, 1.0);
    let mut last = 1.0;
    for _ in 0..30 {
        last = lying.step(&vec![-1.0; model.dofs.len()]).terms.imitation;
    }
    assert!(last < 0.5, "{last}");
}

/// The action whose PD targets are the character's current joint angles.
fn zero_error_action(model: &CharacterModel, env: &TaskEnv) -> Vec<f32> {
    let angles = joint_angles(model, &env.world.body_states());
    let c = &env.world.character;
    angles
        .iter()
        .enumerate()
        .map(|(i, q)| ((q - c.action_offset[i]) / c.action_scale[i]).clamp(-1.0, 1.0))
        .collect()
}
