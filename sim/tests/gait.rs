//! The residual base (`[env.gait]`, `lhm_sim::gait`) on hand-built states and a synthetic clip
//! (no downloads): feedback terms on known errors, the cycle's sampling, and the environment's
//! residual actions and phase observation.

use lhm_scenes::{Benchmark, Support};
use lhm_sim::env::{
    empty_room, stand_over, stop_now, without_furniture, EnvConfig, GaitConfig, StopOn, TaskEnv,
};
use lhm_sim::fidelity::joint_angles;
use lhm_sim::gait::{
    aligned_to, base_targets, braking_targets, reference_for, reference_for_gait, start_targets,
    stop_targets, synthetic_cycle_clip, synthetic_cycle_demo, BalanceGains, GaitReference, Rig,
    StartRamp, CONTACT_HEIGHT,
};
use lhm_sim::motion::demo::{AmpWindow, DemoMotion};
use lhm_sim::motion::retarget::{forward_kinematics, KinematicPose};
use lhm_sim::obs::BodyState;
use lhm_sim::task::rewards::imitation;
use lhm_sim::{CharacterModel, SimConfig};
use rapier3d::math::{Rotation, Vector};
use std::sync::Arc;

/// The right leg forward and lifted (left foot lower: left stance), slightly turned.
fn stride(model: &CharacterModel) -> Vec<BodyState> {
    let mut local_rots = vec![Rotation::IDENTITY; model.bodies.len()];
    local_rots[model.body_index("right_thigh").unwrap()] = Rotation::from_rotation_y(-0.5);
    local_rots[model.body_index("right_shin").unwrap()] = Rotation::from_rotation_y(0.6);
    let pose = KinematicPose {
        root_pos: Vector::new(0.3, -0.2, 0.9),
        root_rot: Rotation::from_rotation_z(0.4),
        local_rots,
    };
    forward_kinematics(model, &pose)
        .into_iter()
        .map(|(pos, rot)| BodyState {
            pos,
            rot,
            linvel: Vector::new(0.8, 0.3, 0.0),
            angvel: Vector::ZERO,
        })
        .collect()
}

fn dof(model: &CharacterModel, name: &str) -> usize {
    model.dofs.iter().position(|d| d.name == name).unwrap()
}

#[test]
fn feet_are_down_when_both_origins_are_below_the_height_and_a_missing_foot_is_up() {
    let model = CharacterModel::amp_humanoid();
    let rig = Rig::new(&model).unwrap();
    let mut frame = stride(&model);
    for &f in &rig.foot {
        frame[f].pos.z = 0.05;
    }
    assert!(rig.feet_down(&frame, CONTACT_HEIGHT));
    assert!(!rig.feet_down(&frame, 0.04), "below 0.05 m only");
    frame[rig.foot[1]].pos.z = 0.2;
    assert!(
        !rig.feet_down(&frame, CONTACT_HEIGHT),
        "one foot in the air"
    );
    frame[rig.foot[1]].pos.z = 0.05;
    let short = &frame[..rig.foot[0].min(rig.foot[1])];
    assert!(
        !rig.feet_down(short, CONTACT_HEIGHT),
        "a frame without the feet"
    );
}

#[test]
fn on_its_reference_the_base_is_the_reference_plus_the_constant_offsets() {
    let model = CharacterModel::amp_humanoid();
    let rig = Rig::new(&model).unwrap();
    let states = stride(&model);
    assert_eq!(rig.stance(&states), 1, "the left foot is the lower one");
    let angles: Vec<f32> = (0..model.dofs.len()).map(|i| 0.01 * i as f32).collect();
    let g = BalanceGains::default();
    let t = base_targets(&rig, &g, &states, &states, &angles);
    for (i, (t, a)) in t.iter().zip(&angles).enumerate() {
        let offset = match model.dofs[i].name.as_str() {
            "right_knee" => g.swing_knee_bias,
            "left_knee" => g.stance_knee_bias,
            "right_hip_y" => g.swing_hip_bias,
            _ => 0.0,
        };
        assert!(
            (t - a - offset).abs() < 1e-5,
            "{}: {t} vs {a} + {offset}",
            model.dofs[i].name
        );
    }
}

#[test]
fn a_faster_centre_of_mass_moves_the_swing_hip_and_the_stance_ankle_by_their_gains() {
    let model = CharacterModel::amp_humanoid();
    let rig = Rig::new(&model).unwrap();
    let reference = stride(&model);
    // The character 0.5 m/s faster along its own heading, everything else as the reference.
    let heading = Rotation::from_rotation_z(0.4);
    let faster: Vec<BodyState> = reference
        .iter()
        .map(|b| BodyState {
            linvel: b.linvel + heading * Vector::new(0.5, 0.0, 0.0),
            ..*b
        })
        .collect();
    let angles = vec![0.0; model.dofs.len()];
    let g = BalanceGains {
        swing_hip_bias: 0.0,
        swing_knee_bias: 0.0,
        stance_knee_bias: 0.0,
        ..BalanceGains::default()
    };
    let t = base_targets(&rig, &g, &faster, &reference, &angles);
    let expect = [
        ("right_hip_y", g.swing_v_fwd * 0.5),
        ("left_ankle_y", g.ankle_v_fwd * 0.5),
        ("right_hip_x", 0.0),
        ("left_hip_y", 0.0),
        ("left_ankle_x", 0.0),
    ];
    for (name, want) in expect {
        let got = t[dof(&model, name)];
        assert!((got - want).abs() < 1e-4, "{name}: {got} vs {want}");
    }
}

#[test]
fn braking_counts_the_reference_speed_it_drops_as_velocity_error() {
    let model = CharacterModel::amp_humanoid();
    let rig = Rig::new(&model).unwrap();
    let reference = stride(&model);
    // Both the reference and the character move at 0.8 m/s along the heading.
    let heading = Rotation::from_rotation_z(0.4);
    let moving: Vec<BodyState> = reference
        .iter()
        .map(|b| BodyState {
            linvel: heading * Vector::new(0.8, 0.0, 0.0),
            ..*b
        })
        .collect();
    let angles = vec![0.0; model.dofs.len()];
    let g = BalanceGains::default();
    let walking = braking_targets(&rig, &g, &moving, &moving, &angles, 1.0);
    assert_eq!(walking, base_targets(&rig, &g, &moving, &moving, &angles));
    // At speed 0 the reference's 0.8 m/s forward is all error; at 0.5, half of it.
    for (speed, error) in [(0.0, 0.8), (0.5, 0.4)] {
        let braking = braking_targets(&rig, &g, &moving, &moving, &angles, speed);
        for (name, gain) in [
            ("right_hip_y", g.swing_v_fwd),
            ("left_ankle_y", g.ankle_v_fwd),
        ] {
            let (d, want) = (
                braking[dof(&model, name)] - walking[dof(&model, name)],
                gain * error,
            );
            assert!(
                (d - want).abs() < 1e-4,
                "speed {speed}, {name}: {d} vs {want}"
            );
        }
        let lat = dof(&model, "right_hip_x");
        assert!((braking[lat] - walking[lat]).abs() < 1e-5);
    }
}

#[test]
fn the_start_ramp_goes_from_the_lean_on_the_neutral_pose_to_the_walks_base() {
    let model = CharacterModel::amp_humanoid();
    let rig = Rig::new(&model).unwrap();
    let reference = stride(&model);
    // The character at rest where the reference walks at 0.8 m/s.
    let still: Vec<BodyState> = reference
        .iter()
        .map(|b| BodyState {
            linvel: Vector::ZERO,
            ..*b
        })
        .collect();
    let angles: Vec<f32> = (0..model.dofs.len()).map(|i| 0.01 * i as f32).collect();
    let g = BalanceGains::default();
    let ramp = StartRamp {
        seconds: 1.0,
        feedback: 0.0,
        ankle_lean: 0.1,
        hip_lean: -0.2,
        abdomen_lean: 0.05,
        knee_bend: 0.3,
    };
    // At its first step: the neutral pose (zeros) with the whole lean, no feedback.
    let first = start_targets(&rig, &g, &ramp, 0.0, &still, &reference, &angles);
    for (i, t) in first.iter().enumerate() {
        let want = match model.dofs[i].name.as_str() {
            "right_ankle_y" | "left_ankle_y" => 0.1,
            "right_hip_y" | "left_hip_y" => -0.2,
            "abdomen_y" => 0.05,
            "right_knee" | "left_knee" => 0.3,
            _ => 0.0,
        };
        assert!(
            (t - want).abs() < 1e-6,
            "{}: {t} vs {want}",
            model.dofs[i].name
        );
    }
    // Half way: half the reference's angles, half the lean, the feedback at half weight
    // against half the reference's velocity.
    let half = start_targets(&rig, &g, &ramp, 0.5, &still, &reference, &angles);
    let braking = braking_targets(&rig, &g, &still, &reference, &angles, 0.5);
    let knee = dof(&model, "left_knee");
    let want = 0.5 * angles[knee] + 0.5 * (braking[knee] - angles[knee]) + 0.5 * 0.3;
    assert!((half[knee] - want).abs() < 1e-6, "{} vs {want}", half[knee]);
    // At and after its end: the walk's base, exactly; and no ramp at all is the base at once.
    let base = base_targets(&rig, &g, &still, &reference, &angles);
    assert_eq!(
        start_targets(&rig, &g, &ramp, 1.0, &still, &reference, &angles),
        base
    );
    assert_eq!(
        start_targets(&rig, &g, &ramp, 7.0, &still, &reference, &angles),
        base
    );
    let none = StartRamp::default();
    assert_eq!(
        start_targets(&rig, &g, &none, 0.0, &still, &reference, &angles),
        base
    );
}

#[test]
fn the_stop_ramp_is_the_start_ramp_backward_and_no_ramp_is_the_neutral_pose_at_once() {
    let model = CharacterModel::amp_humanoid();
    let rig = Rig::new(&model).unwrap();
    let reference = stride(&model);
    let angles: Vec<f32> = (0..model.dofs.len()).map(|i| 0.01 * i as f32).collect();
    let g = BalanceGains::default();
    let ramp = StartRamp {
        seconds: 1.0,
        feedback: 0.25,
        ankle_lean: 0.1,
        hip_lean: -0.2,
        abdomen_lean: 0.05,
        knee_bend: 0.3,
    };
    // The moment it stops: the walk's base, exactly.
    assert_eq!(
        stop_targets(&rig, &g, &ramp, 0.0, &reference, &reference, &angles),
        base_targets(&rig, &g, &reference, &reference, &angles)
    );
    // t seconds after the stop: the start ramp 1 − t seconds after its start.
    for t in [0.25, 0.5, 1.0, 5.0] {
        let back = (ramp.seconds - t).max(0.0);
        assert_eq!(
            stop_targets(&rig, &g, &ramp, t, &reference, &reference, &angles),
            start_targets(&rig, &g, &ramp, back, &reference, &reference, &angles),
            "{t} s after the stop"
        );
    }
    // From its end on: the neutral pose with the whole lean, the feedback at its share against a
    // velocity of 0 (every bit of the character's 0.8 m/s an error).
    let end = stop_targets(&rig, &g, &ramp, 3.0, &reference, &reference, &angles);
    let braking = braking_targets(&rig, &g, &reference, &reference, &angles, 0.0);
    let knee = dof(&model, "left_knee");
    let want = 0.25 * (braking[knee] - angles[knee]) + 0.3;
    assert!((end[knee] - want).abs() < 1e-6, "{} vs {want}", end[knee]);
    // No ramp: the neutral pose (zero joint angles) at once, as stops were before ramps.
    assert_eq!(
        stop_targets(
            &rig,
            &g,
            &StartRamp::default(),
            0.0,
            &reference,
            &reference,
            &angles
        ),
        vec![0.0; model.dofs.len()]
    );
}

/// `synthetic_cycle_demo` (1.2 s at 30 fps, thighs swinging, root moving forward).
fn cycle_demo(model: &CharacterModel) -> DemoMotion {
    let window = AmpWindow::of(&EnvConfig::default(), &SimConfig::default());
    synthetic_cycle_demo(model, window).unwrap()
}

#[test]
fn the_cycle_is_sampled_at_the_control_step_and_wraps() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let dt = 1.0 / 30.0;
    let r = GaitReference::new(&model, &demo, 0, dt).unwrap();
    assert_eq!(r.len(), 36, "1.2 s at 30 Hz");
    let (frame, angles) = r.at(5);
    let want = demo.body_states_at(0, 5.0 * dt);
    assert!((frame[0].pos - want[0].pos).length() < 1e-5);
    let next = joint_angles(&model, &demo.body_states_at(0, 6.0 * dt));
    for (a, b) in angles.iter().zip(&next) {
        assert!((a - b).abs() < 1e-4, "the angles are the next step's");
    }
    assert_eq!(r.at(36 + 5).0[0].pos, frame[0].pos, "wraps");
    assert!((r.phase(45) - 0.25).abs() < 1e-6);
    assert!(reference_for(&model, &demo, "cycle", dt).is_ok());
    let err = reference_for(&model, &demo, "run", dt).unwrap_err();
    assert!(err.contains("\"run\""), "{err}");
}

/// An environment on the embedded benchmark's task train-0001 with `config`.
fn task_env(model: &CharacterModel, config: EnvConfig) -> TaskEnv {
    let bench = Benchmark::embedded().unwrap();
    let (_, task) = bench.task("train-0001").unwrap();
    TaskEnv::new(model, &task, &bench.catalogue, SimConfig::default(), config)
}

fn gait_env(model: &CharacterModel, gait: Option<GaitConfig>) -> TaskEnv {
    task_env(
        model,
        EnvConfig {
            gait,
            ..EnvConfig::default()
        },
    )
}

/// The first object's position and the task's start, on the floor (z = 0).
fn first_object_and_start(env: &TaskEnv) -> (Vector, Vector) {
    let first = &env.task.sequence[0].object;
    let o = env.task.objects.iter().find(|o| &o.id == first).unwrap();
    let start = env.task.start.pos;
    (
        Vector::new(o.pos[0] as f32, o.pos[1] as f32, 0.0),
        Vector::new(start[0] as f32, start[1] as f32, 0.0),
    )
}

/// How far (m, horizontally) the character's root is from `p`.
fn horizontal_root_offset(env: &TaskEnv, p: Vector) -> f32 {
    let root = env.world.body_states()[0];
    Vector::new(root.pos.x - p.x, root.pos.y - p.y, 0.0).length()
}

#[test]
fn in_the_gait_actions_are_residuals_on_the_base_and_the_policy_reads_the_phase() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let plain = gait_env(&model, None);
    let mut env = gait_env(&model, Some(GaitConfig::default()));
    let dim = TaskEnv::obs_dim(&model, &env.config);
    assert_eq!(dim, TaskEnv::obs_dim(&model, &plain.config) + 2);
    // Before the gait starts the phase reads as zeros.
    let obs = env.observation();
    assert_eq!(obs.len(), dim);
    assert_eq!(&obs[dim - 2..], &[0.0, 0.0]);
    let yaw = env.yaw_toward_first_object();
    assert_eq!(env.gait_reference_angles(), None, "no gait yet");
    assert!(env.start_in_gait(&demo, Arc::clone(&reference), 9, yaw));
    assert!(env.demo_start);
    assert_eq!(env.gait_phase(), Some(0.25));
    assert_eq!(
        env.gait_reference_angles().as_deref(),
        Some(reference.at(9).1),
        "the reference's angles at the step the gait plays next"
    );
    let obs = env.observation();
    assert!(
        (obs[dim - 2] - 1.0).abs() < 1e-5 && obs[dim - 1].abs() < 1e-5,
        "sin, cos of 1/4 turn"
    );
    // Two copies of the same state: one zero action and one residual differ in the world by
    // what the residual adds to the base.
    let mut other = gait_env(&model, Some(GaitConfig::default()));
    other.start_in_gait(&demo, Arc::clone(&reference), 9, yaw);
    let knee = dof(&model, "left_knee");
    let mut action = vec![0.0; model.dofs.len()];
    action[knee] = 1.0;
    env.step(&vec![0.0; model.dofs.len()]);
    other.step(&action);
    assert_eq!(
        env.gait_phase(),
        Some(10.0 / 36.0),
        "the gait moved on a step"
    );
    let bend = |e: &TaskEnv| joint_angles(&model, &e.world.body_states())[knee];
    assert!(
        bend(&other) > bend(&env) + 0.01,
        "{} vs {}",
        bend(&other),
        bend(&env)
    );
    // Without [env.gait] nothing starts and actions stay absolute.
    let mut plain = plain;
    assert!(!plain.start_gait(reference, 0));
    assert_eq!(plain.gait_phase(), None);
}

#[test]
fn residual_joints_scale_the_residual_per_joint_and_a_key_naming_no_joint_is_refused() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let masked = GaitConfig {
        residual: 0.5,
        residual_joints: [("knee".to_string(), 0.0), ("left_knee".to_string(), 2.0)]
            .into_iter()
            .collect(),
        ..GaitConfig::default()
    };
    // The longest key a name contains wins; names without a key keep `residual`.
    assert_eq!(masked.residual_on("left_knee"), 1.0);
    assert_eq!(masked.residual_on("right_knee"), 0.0);
    assert_eq!(masked.residual_on("right_hip_x"), 0.5);
    assert!(masked.check(&model).is_ok());
    // An action on the knee with the factor 0 leaves the world exactly as zero action does (the
    // whole body: the knees are coupled through the root), while the knee with its own factor
    // bends.
    let (right, left) = (dof(&model, "right_knee"), dof(&model, "left_knee"));
    let run = |knee: Option<usize>| {
        let mut e = gait_env(&model, Some(masked.clone()));
        let yaw = e.yaw_toward_first_object();
        assert!(e.start_in_gait(&demo, Arc::clone(&reference), 9, yaw));
        let mut action = vec![0.0; model.dofs.len()];
        if let Some(k) = knee {
            action[k] = 1.0;
        }
        e.step(&action);
        joint_angles(&model, &e.world.body_states())
    };
    let zero = run(None);
    assert_eq!(
        run(Some(right)),
        zero,
        "the masked knee's action changed the world"
    );
    assert!(run(Some(left))[left] > zero[left] + 0.01);
    // A key that names no DoF, or a factor that is not a number, is refused by name.
    for (key, factor) in [("tail", 0.0), ("knee", f32::NAN)] {
        let bad = GaitConfig {
            residual_joints: [(key.to_string(), factor)].into_iter().collect(),
            ..GaitConfig::default()
        };
        let err = bad.check(&model).unwrap_err();
        assert!(
            err.contains("residual_joints") && err.contains(key),
            "{err}"
        );
    }
}

#[test]
fn angle_offsets_add_to_the_clips_joint_targets_per_step_and_bad_entries_are_refused() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let dt = 1.0 / 30.0;
    let clip = reference_for(&model, &demo, "cycle", dt).unwrap();
    let n = clip.len();
    let (elbow, knee) = (dof(&model, "right_elbow"), dof(&model, "left_knee"));
    let per_step: Vec<f32> = (0..n).map(|k| 0.01 * k as f32).collect();
    let gait = GaitConfig {
        clip: "cycle".into(),
        angle_offsets: [
            ("right_elbow".to_string(), vec![-0.3]),
            ("left_knee".to_string(), per_step.clone()),
        ]
        .into_iter()
        .collect(),
        ..GaitConfig::default()
    };
    let shifted = reference_for_gait(&model, &demo, &gait, dt).unwrap();
    for (k, knee_offset) in per_step.iter().enumerate() {
        let (frame, want) = clip.at(k);
        let (frame_shifted, got) = shifted.at(k);
        for d in 0..model.dofs.len() {
            let offset = match d {
                d if d == elbow => -0.3,
                d if d == knee => *knee_offset,
                _ => 0.0,
            };
            assert!(
                (got[d] - (want[d] + offset)).abs() < 1e-6,
                "step {k}, {}: {} against {} + {offset}",
                model.dofs[d].name,
                got[d],
                want[d]
            );
        }
        // What feedback and imitation compare with stays the clip's.
        assert_eq!(frame_shifted[0].pos, frame[0].pos);
        assert_eq!(frame_shifted[3].rot, frame[3].rot);
    }
    // In the environment the base walks on the shifted targets: with zero action the elbow ends
    // bent further one way than on the clip's own.
    let walk = |reference: GaitReference| {
        let mut e = gait_env(&model, Some(GaitConfig::default()));
        let yaw = e.yaw_toward_first_object();
        assert!(e.start_in_gait(&demo, Arc::new(reference), 9, yaw));
        for _ in 0..10 {
            e.step(&vec![0.0; model.dofs.len()]);
        }
        joint_angles(&model, &e.world.body_states())[elbow]
    };
    let (plain, offset) = (walk(clip.clone()), walk(shifted));
    assert!(
        offset < plain - 0.15,
        "elbow {offset} with a -0.3 offset against {plain} without"
    );
    // An unknown DoF, a length that is neither 1 nor the cycle's, a value that is not finite.
    for (name, values, says) in [
        ("right_wing", vec![0.1], "no DoF"),
        ("right_elbow", vec![0.1; n - 1], "values"),
        ("right_elbow", vec![f32::NAN], "finite"),
    ] {
        let bad = [(name.to_string(), values)].into_iter().collect();
        let err = clip.clone().with_angle_offsets(&model, &bad).unwrap_err();
        assert!(
            err.contains("angle_offsets") && err.contains(name) && err.contains(says),
            "{err}"
        );
    }
}

#[test]
fn within_the_stop_distance_the_base_stands_and_the_phase_reads_zero() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let gait = GaitConfig {
        stop_distance: 100.0,
        ..GaitConfig::default()
    };
    let mut env = gait_env(&model, Some(gait));
    let yaw = env.yaw_toward_first_object();
    env.start_in_gait(&demo, reference, 9, yaw);
    assert_eq!(env.gait_phase(), Some(0.25), "walking until the first step");
    // Zero action: the neutral pose's targets, which pull every joint toward 0 (the right hip
    // starts 0.3 rad back at a quarter of the synthetic cycle).
    let hip = dof(&model, "right_hip_y");
    let before = joint_angles(&model, &env.world.body_states())[hip].abs();
    assert!(before > 0.25, "{before}");
    for _ in 0..5 {
        env.step(&vec![0.0; model.dofs.len()]);
    }
    assert_eq!(env.gait_phase(), None, "stopped");
    assert_eq!(
        env.gait_reference_angles(),
        Some(vec![0.0; model.dofs.len()]),
        "stopped: the neutral pose"
    );
    let dim = TaskEnv::obs_dim(&model, &env.config);
    assert_eq!(&env.observation()[dim - 2..], &[0.0, 0.0]);
    let after = joint_angles(&model, &env.world.body_states())[hip].abs();
    assert!(after < before - 0.1, "hip {before} -> {after}");
}

#[test]
fn a_stop_waits_for_its_footfall_at_most_half_a_cycle() {
    // (armed for, footfall, feet down) -> stops now, for each rule; half a cycle is 18 steps.
    let cases = [
        (0, false, false, [true, false, false]),
        (3, true, false, [true, true, false]),
        (3, false, true, [true, false, true]),
        (17, false, false, [true, false, false]),
        (18, false, false, [true, true, true]),
    ];
    for (armed, footfall, feet, expect) in cases {
        let got = [StopOn::Distance, StopOn::Footfall, StopOn::FeetDown]
            .map(|rule| stop_now(rule, armed, 18, footfall, feet));
        assert_eq!(
            got, expect,
            "armed {armed}, footfall {footfall}, feet {feet}"
        );
    }
    // The config's spelling (TOML's is the same through serde).
    let g: GaitConfig = serde_json::from_str(r#"{"stop_on": "feet-down"}"#).unwrap();
    assert_eq!(g.stop_on, StopOn::FeetDown);
    assert_eq!(GaitConfig::default().stop_on, StopOn::Distance);
    assert!(serde_json::from_str::<GaitConfig>(r#"{"stop_on": "later"}"#).is_err());
}

#[test]
fn with_stop_on_footfall_the_base_walks_on_to_the_references_next_footfall() {
    let model = CharacterModel::amp_humanoid();
    let demo = stepping_demo(&model);
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let rig = Rig::new(&model).unwrap();
    // Armed at the first step (within 100 m), from cycle step 9: the first footfall after it.
    let first = (9..9 + reference.len())
        .find(|&k| reference.footfall(&rig, k))
        .expect("the cycle has footfalls");
    assert!(first > 9, "the test needs a start between footfalls");
    let gait = GaitConfig {
        stop_distance: 100.0,
        stop_on: StopOn::Footfall,
        ..GaitConfig::default()
    };
    let mut env = gait_env(&model, Some(gait));
    let yaw = env.yaw_toward_first_object();
    assert!(env.start_in_gait(&demo, reference, 9, yaw));
    let zero = vec![0.0; model.dofs.len()];
    for k in 9..first {
        env.step(&zero);
        assert!(env.gait_phase().is_some(), "walking on at cycle step {k}");
    }
    env.step(&zero);
    assert_eq!(
        env.gait_phase(),
        None,
        "stopped at the footfall (step {first})"
    );
}

#[test]
fn a_stand_is_over_stand_seconds_after_the_stop_and_never_when_off() {
    for (stopped_at, steps, seconds, over) in [
        (None, 500, 0.5, false),
        (Some(10), 24, 0.5, false),
        (Some(10), 25, 0.5, true),
        (Some(10), 400, 0.0, false),
        (Some(0), 0, 0.0, false),
    ] {
        assert_eq!(
            stand_over(stopped_at, steps, seconds, 30.0),
            over,
            "{stopped_at:?} {steps} {seconds}"
        );
    }
}

/// An environment started at rest in the gait within its stop distance (100 m): the base stops
/// on the first step. `gait` and `config` set the rest.
fn stopped_at_rest(model: &CharacterModel, gait: GaitConfig, config: EnvConfig) -> TaskEnv {
    let demo = cycle_demo(model);
    let reference = Arc::new(GaitReference::new(model, &demo, 0, 1.0 / 30.0).unwrap());
    let gait = GaitConfig {
        stop_distance: 100.0,
        ..gait
    };
    let mut env = task_env(
        model,
        EnvConfig {
            gait: Some(gait),
            ..config
        },
    );
    let yaw = env.yaw_toward_first_object();
    assert!(env.start_at_rest_in_gait(reference, 0, yaw));
    env
}

#[test]
fn the_env_says_when_its_gait_has_stopped() {
    let model = CharacterModel::amp_humanoid();
    let zero = vec![0.0; model.dofs.len()];
    let mut env = stopped_at_rest(&model, GaitConfig::default(), EnvConfig::default());
    env.step(&zero);
    assert!(env.gait_stopped());
    // Started walking with no stop distance: the base walks on.
    let demo = cycle_demo(&model);
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let mut walking = gait_env(&model, Some(GaitConfig::default()));
    let yaw = walking.yaw_toward_first_object();
    assert!(walking.start_in_gait(&demo, reference, 9, yaw));
    walking.step(&zero);
    assert!(walking.gait_running() && !walking.gait_stopped());
    let mut no_gait = gait_env(&model, None);
    no_gait.step(&zero);
    assert!(!no_gait.gait_stopped());
}

#[test]
fn the_env_says_while_its_gait_walks_off_from_rest() {
    let model = CharacterModel::amp_humanoid();
    let zero = vec![0.0; model.dofs.len()];
    let demo = cycle_demo(&model);
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let mut gait = GaitConfig::default();
    gait.start.seconds = 0.5;
    let mut env = gait_env(&model, Some(gait.clone()));
    assert!(!env.gait_ramping(), "no gait started yet");
    let yaw = env.yaw_toward_first_object();
    assert!(env.start_at_rest_in_gait(Arc::clone(&reference), 0, yaw));
    let ramping: Vec<bool> = (0..30)
        .map(|_| {
            env.step(&zero);
            env.gait_ramping()
        })
        .collect();
    // 0.5 s of ramp: the targets of the first 0.5 s × control rate steps are the ramp's.
    let ramp_steps = (0.5 * env.world.config.control_hz).round() as usize;
    assert!(ramp_steps > 0 && ramp_steps < ramping.len());
    assert!(ramping[..ramp_steps].iter().all(|&r| r), "{ramping:?}");
    assert!(!ramping[ramp_steps..].iter().any(|&r| r), "{ramping:?}");
    // A walking start never ramps.
    let mut walking = gait_env(&model, Some(gait));
    let yaw = walking.yaw_toward_first_object();
    assert!(walking.start_in_gait(&demo, reference, 9, yaw));
    for _ in 0..5 {
        walking.step(&zero);
        assert!(walking.gait_running() && !walking.gait_ramping());
    }
}

#[test]
fn with_stand_seconds_the_episode_is_truncated_that_long_after_the_stop() {
    let model = CharacterModel::amp_humanoid();
    let end = |stand_seconds: f32| {
        let gait = GaitConfig {
            stand_seconds,
            ..GaitConfig::default()
        };
        let config = EnvConfig {
            max_episode_steps: 40,
            ..EnvConfig::default()
        };
        let mut env = stopped_at_rest(&model, gait, config);
        let zero = vec![0.0; model.dofs.len()];
        (1..=40)
            .map(|k| (k, env.step(&zero)))
            .find(|(_, r)| r.done || r.truncated)
            .map(|(k, r)| (k, r.done, r.truncated))
    };
    // The base stops as the first step begins (step count 0): half a second at 30 Hz later is
    // the end of the 15th step.
    assert_eq!(end(0.5), Some((15, false, true)));
    assert_eq!(end(0.0), Some((40, false, true)), "off: the time limit");
}

#[test]
fn with_stand_imitation_the_stop_tracks_the_standing_pose() {
    let model = CharacterModel::amp_humanoid();
    // Started at rest (the standing pose) and stopped at once: the first steps' imitation term.
    let terms = |stand_imitation: bool, action: f32| {
        let gait = GaitConfig {
            stand_imitation,
            ..GaitConfig::default()
        };
        let mut config = EnvConfig::default();
        config.weights.imitation = 1.0;
        let mut env = stopped_at_rest(&model, gait, config);
        let action: Vec<f32> = (0..model.dofs.len())
            .map(|i| if i % 2 == 0 { action } else { -action })
            .collect();
        (0..10)
            .map(|_| env.step(&action).terms.imitation)
            .collect::<Vec<f32>>()
    };
    let standing = terms(true, 0.0);
    assert!(
        standing.iter().all(|&t| t > 0.8),
        "standing still in the standing pose: {standing:?}"
    );
    let bent = terms(true, 1.0);
    assert!(bent[9] < standing[9] - 0.2, "{bent:?} vs {standing:?}");
    assert_eq!(
        terms(false, 0.0),
        vec![0.0; 10],
        "off: the stop pays no tracking"
    );
}

#[test]
fn a_stop_ramp_fades_the_walk_out_from_the_moment_the_base_stops() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    // The joint angles 15 steps after a start in the gait, stopping at once (`stop_distance`
    // 100 m) with `stop`, or walking on.
    let after = |stop: Option<StartRamp>| {
        let gait = GaitConfig {
            stop_distance: if stop.is_some() { 100.0 } else { 0.0 },
            stop: stop.unwrap_or_default(),
            ..GaitConfig::default()
        };
        let mut env = gait_env(&model, Some(gait));
        let yaw = env.yaw_toward_first_object();
        env.start_in_gait(&demo, reference.clone(), 9, yaw);
        for _ in 0..15 {
            env.step(&vec![0.0; model.dofs.len()]);
        }
        assert_eq!(
            env.gait_phase().is_none(),
            stop.is_some(),
            "stopped or walking"
        );
        joint_angles(&model, &env.world.body_states())
    };
    let apart = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
    };
    // Without a ramp the joints are pulled to the neutral pose at once; over a 10-s ramp they
    // stay near the walk (its share 0.95 after 15 steps). (The largest difference of any joint,
    // radians.)
    let walking = after(None);
    let neutral = after(Some(StartRamp::default()));
    let ramped = after(Some(StartRamp {
        seconds: 10.0,
        feedback: 1.0,
        ..StartRamp::default()
    }));
    let (ramped, neutral) = (apart(&ramped, &walking), apart(&neutral, &walking));
    assert!(
        neutral > 0.2 && ramped < 0.5 * neutral,
        "from the walk: ramped {ramped}, neutral {neutral}"
    );
}

#[test]
fn a_start_distance_starts_the_gait_that_far_before_the_first_object_heading_at_it() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let gait = GaitConfig {
        start_distance: 1.5,
        ..GaitConfig::default()
    };
    let mut env = gait_env(&model, Some(gait));
    let (object, task_start) = first_object_and_start(&env);
    let yaw = env.yaw_toward_first_object() + 0.2;
    assert!(env.start_in_gait(&demo, reference, 0, yaw));
    let root = env.world.body_states()[0];
    let to = Vector::new(object.x - root.pos.x, object.y - root.pos.y, 0.0);
    // The synthetic clip's root is over its own origin at step 0.
    assert!((to.length() - 1.5).abs() < 0.02, "{}", to.length());
    assert!((to.y.atan2(to.x) - yaw).abs() < 0.02);
    let forward = root.rot * Vector::X;
    assert!((forward.y.atan2(forward.x) - yaw).abs() < 0.02);
    assert!(
        (root.pos - task_start).length() > 0.1,
        "not the task's start"
    );
    // Not near (a mixed run's other episodes): the task's start, whatever the distance.
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let mut env = gait_env(
        &model,
        Some(GaitConfig {
            start_distance: 1.5,
            near_start_fraction: 0.5,
            ..GaitConfig::default()
        }),
    );
    assert!(env.start_in_gait_where(&demo, reference, 0, yaw, false));
    let off = horizontal_root_offset(&env, task_start);
    assert!(off < 0.02, "{off}");
}

#[test]
fn a_start_on_the_way_is_that_far_before_the_object_on_the_line_from_the_tasks_start() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let gait = GaitConfig {
        start_distance: 0.5,
        start_distance_max: 10.0,
        ..GaitConfig::default()
    };
    let mut env = gait_env(&model, Some(gait.clone()));
    let (object, task_start) = first_object_and_start(&env);
    let way = (object - task_start).length();
    assert!((env.first_object_distance() - way).abs() < 1e-4);
    assert!(way > 0.8, "the fixture's object is {way} m away");
    assert!(
        (env.way_length() - way).abs() < 1e-4,
        "no route: the straight way"
    );
    let d = 0.6 * way;
    // Heading 0.4 rad off the object: the position stays on the way.
    let yaw = env.yaw_toward_first_object() + 0.4;
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    assert!(env.start_in_gait_on_way(&demo, reference, 0, 0.4, d));
    assert!(env.gait_running());
    let root = env.world.body_states()[0];
    let at = Vector::new(root.pos.x, root.pos.y, 0.0);
    assert!(((object - at).length() - d).abs() < 0.02);
    assert!(((at - task_start).length() - (way - d)).abs() < 0.02);
    let forward = root.rot * Vector::X;
    assert!((forward.y.atan2(forward.x) - yaw).abs() < 0.02);
    // Further than the way: the task's start.
    let mut env = gait_env(&model, Some(gait));
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    assert!(env.start_in_gait_on_way(&demo, reference, 0, 0.4, way + 1.0));
    let off = horizontal_root_offset(&env, task_start);
    assert!(off < 0.02, "{off}");
}

#[test]
fn a_route_steers_the_way_around_an_object_on_the_straight_line() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let bench = Benchmark::embedded().unwrap();
    let (_, mut task) = bench.task("train-0001").unwrap();
    // Another object put halfway along the straight way to the first.
    let first = task.sequence[0].object.clone();
    let target = task.objects.iter().find(|o| o.id == first).unwrap().pos;
    let start = task.start.pos;
    let mid = [(start[0] + target[0]) / 2.0, (start[1] + target[1]) / 2.0];
    let blocker = task.objects.iter_mut().find(|o| o.id != first).unwrap();
    blocker.pos = [mid[0], mid[1], blocker.size[2] / 2.0];
    blocker.on = Support::Floor;
    let config = EnvConfig {
        clear_furniture: true,
        gait: Some(GaitConfig {
            route_lookahead: 1.0,
            start_distance: 0.5,
            start_distance_max: 10.0,
            ..GaitConfig::default()
        }),
        ..EnvConfig::default()
    };
    let mut env = TaskEnv::new(
        &model,
        &task,
        &bench.catalogue,
        SimConfig::default(),
        config.clone(),
    );
    let route = env.route().expect("a route").to_vec();
    let mid = [mid[0] as f32, mid[1] as f32];
    let off = |p: [f32; 2]| (p[0] - mid[0]).hypot(p[1] - mid[1]);
    // Every point keeps the 0.45 m clearance from the blocker's footprint, so more from its
    // centre (one 0.1 m cell of slack).
    let shortest = route.iter().map(|p| off(*p)).fold(f32::MAX, f32::min);
    assert!(shortest > 0.45 - 0.1, "{shortest}");
    assert!(env.way_length() > env.first_object_distance() + 0.1);
    // The start turns along the route, not at the object behind the blocker.
    let turned = (env.yaw_toward_way() - env.yaw_toward_first_object()).abs();
    assert!(turned > 0.1, "{turned}");
    // A start halfway along the way stands on the route, beside the blocker, not in it.
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let half = env.way_length() / 2.0;
    assert!(env.start_in_gait_on_way(&demo, reference, 0, 0.0, half));
    let root = env.world.body_states()[0];
    assert!(off([root.pos.x, root.pos.y]) > 0.45 - 0.1);
    // Without route_lookahead: no route, the straight way.
    let mut straight = config;
    if let Some(g) = straight.gait.as_mut() {
        g.route_lookahead = 0.0;
    }
    let env = TaskEnv::new(
        &model,
        &task,
        &bench.catalogue,
        SimConfig::default(),
        straight,
    );
    assert!(env.route().is_none());
    assert_eq!(env.yaw_toward_way(), env.yaw_toward_first_object());
}

#[test]
fn a_rest_start_stands_still_at_the_tasks_start_turned_toward_the_object_with_the_gait_running() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let mut env = gait_env(&model, Some(GaitConfig::default()));
    let built = env.world.body_states();
    let yaw = env.yaw_toward_first_object() + 0.3;
    assert!(!env.gait_running());
    assert!(env.start_at_rest_in_gait(reference, 5, yaw));
    assert!(env.gait_running());
    let now = env.world.body_states();
    // Where the task starts it, at the same height, facing `yaw`, still.
    let (r0, r1) = (built[0].pos, now[0].pos);
    assert!((r1 - r0).length() < 1e-3, "{r0:?} -> {r1:?}");
    let forward = now[0].rot * Vector::X;
    assert!((forward.y.atan2(forward.x) - yaw).abs() < 0.02);
    for b in &now {
        assert!(b.linvel.length() < 1e-3 && b.angvel.length() < 1e-3);
    }
    // The neutral pose: every body keeps its height and its distance from the root.
    for (a, b) in built.iter().zip(&now) {
        assert!((a.pos.z - b.pos.z).abs() < 1e-3);
        let (da, db) = (a.pos - built[0].pos, b.pos - now[0].pos);
        assert!((da.length() - db.length()).abs() < 1e-3);
    }
    // Not the demo's walking start, so its falls and reaches count as the task's start.
    assert!(!env.demo_start);
    // Without [env.gait] nothing changes.
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let mut plain = gait_env(&model, None);
    let before = plain.world.body_states();
    assert!(!plain.start_at_rest_in_gait(reference, 0, yaw));
    assert_eq!(plain.world.body_states()[0].rot, before[0].rot);
}

#[test]
fn the_start_ramp_acts_after_a_rest_start_and_not_after_a_walking_one() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let ramped = GaitConfig {
        start: StartRamp {
            seconds: 1.0,
            knee_bend: 0.5,
            ..StartRamp::default()
        },
        ..GaitConfig::default()
    };
    let zero = vec![0.0; model.dofs.len()];
    let knee = dof(&model, "left_knee");
    let after_a_step = |config: &GaitConfig, rest: bool| {
        let mut env = gait_env(&model, Some(config.clone()));
        let yaw = env.yaw_toward_first_object();
        if rest {
            assert!(env.start_at_rest_in_gait(Arc::clone(&reference), 5, yaw));
        } else {
            assert!(env.start_in_gait(&demo, Arc::clone(&reference), 5, yaw));
        }
        for _ in 0..3 {
            env.step(&zero);
        }
        env.world.body_states()
    };
    let plain = GaitConfig::default();
    // From rest the ramp's bent knees show after a few steps ...
    let (bent, straight) = (after_a_step(&ramped, true), after_a_step(&plain, true));
    let (a, b) = (
        joint_angles(&model, &bent)[knee],
        joint_angles(&model, &straight)[knee],
    );
    assert!(a > b + 0.05, "ramped knee {a} vs unramped {b}");
    // ... and a walking start plays the base as before, the ramp configured or not.
    assert_eq!(after_a_step(&ramped, false), after_a_step(&plain, false));
}

/// `synthetic_cycle_clip` with the swinging leg's knee bent, so the feet take turns being lower.
fn stepping_demo(model: &CharacterModel) -> DemoMotion {
    let (rs, ls) = (
        model.body_index("right_shin").unwrap(),
        model.body_index("left_shin").unwrap(),
    );
    let mut clip = synthetic_cycle_clip(model).unwrap();
    for (i, pose) in clip.iter_mut().enumerate() {
        let s = (std::f32::consts::TAU * i as f32 / 36.0).sin();
        pose.local_rots[rs] = Rotation::from_rotation_y(0.6 * s.max(0.0));
        pose.local_rots[ls] = Rotation::from_rotation_y(0.6 * (-s).max(0.0));
    }
    DemoMotion::from_clips(
        model,
        vec![("cycle_walk".into(), clip, 1.0 / 30.0)],
        AmpWindow::of(&EnvConfig::default(), &SimConfig::default()),
    )
    .unwrap()
}

#[test]
fn the_cycle_waits_for_a_late_footfall_and_jumps_to_an_early_one() {
    let model = CharacterModel::amp_humanoid();
    let rig = Rig::new(&model).unwrap();
    let r = GaitReference::new(&model, &stepping_demo(&model), 0, 1.0 / 30.0).unwrap();
    let stance = |k: usize| rig.stance(r.at(k).0);
    // The reference's footfall: the last step before the stance foot changes.
    let before = (0..r.len()).find(|&k| stance(k + 1) != stance(k)).unwrap();
    let shifted = |dz: f32| -> Vec<BodyState> {
        r.at(before)
            .0
            .iter()
            .map(|b| BodyState {
                pos: b.pos + Vector::new(0.0, 0.0, dz),
                ..*b
            })
            .collect()
    };
    let (airborne, grounded) = (shifted(0.5), shifted(-1.0));
    let mut waited = 0;
    // The swing foot still in the air at the footfall: wait, at most twice.
    assert_eq!(
        r.advance(&rig, before, &airborne, &mut waited, 2, 0),
        before
    );
    assert_eq!(
        r.advance(&rig, before, &airborne, &mut waited, 2, 0),
        before
    );
    assert_eq!(
        r.advance(&rig, before, &airborne, &mut waited, 2, 0),
        before + 1
    );
    assert_eq!(waited, 0);
    // Landed at the footfall: on.
    assert_eq!(
        r.advance(&rig, before, &grounded, &mut waited, 2, 0),
        before + 1
    );
    // Landed 3 steps before the reference's footfall: a jump to where its new stance begins
    // (4 steps on) with max_skip 3, not with 1.
    let early = before + r.len() - 3;
    assert_eq!(
        r.advance(&rig, early, &grounded, &mut waited, 0, 3),
        early + 4
    );
    assert_eq!(
        r.advance(&rig, early, &grounded, &mut waited, 0, 1),
        early + 1
    );
    // The plain clock.
    assert_eq!(
        r.advance(&rig, before, &airborne, &mut waited, 0, 0),
        before + 1
    );
}

#[test]
fn with_sync_wait_the_envs_cycle_waits_at_each_footfall_while_the_swing_foot_is_in_the_air() {
    let model = CharacterModel::amp_humanoid();
    let r = Arc::new(GaitReference::new(&model, &stepping_demo(&model), 0, 1.0 / 30.0).unwrap());
    // The cycle steps the env runs through in two cycles' time, the character welded 1.6 m up
    // (its feet never land).
    let cycle_steps = |sync_wait: usize, sync_skip: usize| -> Vec<usize> {
        let bench = Benchmark::embedded().unwrap();
        let (_, task) = bench.task("train-0001").unwrap();
        let sim = SimConfig {
            pin_root: true,
            spawn_height: 1.6,
            ..SimConfig::default()
        };
        let gait = GaitConfig {
            sync_wait,
            sync_skip,
            ..GaitConfig::default()
        };
        let config = EnvConfig {
            gait: Some(gait),
            ..EnvConfig::default()
        };
        let mut env = TaskEnv::new(&model, &task, &bench.catalogue, sim, config);
        assert!(env.start_gait(Arc::clone(&r), 0));
        let zero = vec![0.0; model.dofs.len()];
        (0..2 * r.len())
            .map(|_| {
                env.step(&zero);
                (env.gait_phase().unwrap() * r.len() as f32).round() as usize % r.len()
            })
            .collect()
    };
    let repeats = |steps: &[usize]| steps.windows(2).filter(|w| w[0] == w[1]).count();
    let plain = cycle_steps(0, 0);
    assert_eq!(repeats(&plain), 0, "the plain clock moves on every step");
    // At each of the reference's footfalls the cycle holds 3 steps while the swing foot hangs in
    // the air, then moves on (skipping needs a landed foot, so it changes nothing here).
    let rig = Rig::new(&model).unwrap();
    let waiting = cycle_steps(3, 3);
    let mut held = 0;
    for (i, w) in waiting.windows(2).enumerate() {
        if w[0] == w[1] {
            held += 1;
            assert_ne!(
                rig.stance(r.at(w[0] + 1).0),
                rig.stance(r.at(w[0]).0),
                "held at step {i} off a footfall"
            );
        } else {
            assert!(held == 0 || held == 3, "held {held} steps before step {i}");
            held = 0;
        }
    }
    assert!(repeats(&waiting) >= 6, "{waiting:?}");
    assert_eq!(repeats(&cycle_steps(0, 3)), 0);
}

#[test]
fn the_clock_keeps_its_pace_during_the_start_ramp_and_jumps_to_footfalls_of_landed_feet_without() {
    let model = CharacterModel::amp_humanoid();
    let r = Arc::new(GaitReference::new(&model, &stepping_demo(&model), 0, 1.0 / 30.0).unwrap());
    // The cycle steps of the first 15 control steps from the task's standing start (both feet
    // on the ground), sync_skip 3, with a start ramp of `ramp_seconds`.
    let cycle_steps = |ramp_seconds: f32| -> Vec<usize> {
        let gait = GaitConfig {
            sync_skip: 3,
            start: StartRamp {
                seconds: ramp_seconds,
                ..StartRamp::default()
            },
            ..GaitConfig::default()
        };
        let mut env = gait_env(&model, Some(gait));
        let yaw = env.yaw_toward_first_object();
        assert!(env.start_at_rest_in_gait(Arc::clone(&r), 0, yaw));
        let zero = vec![0.0; model.dofs.len()];
        let mut steps = vec![0];
        for _ in 0..15 {
            env.step(&zero);
            steps.push((env.gait_phase().unwrap() * r.len() as f32).round() as usize % r.len());
        }
        steps
    };
    let ramped = cycle_steps(1.0);
    assert!(
        ramped.windows(2).all(|w| w[1] == (w[0] + 1) % r.len()),
        "one step a step during the ramp: {ramped:?}"
    );
    // Without a ramp the character stands, feet down, as the cycle starts: it jumps.
    let unramped = cycle_steps(0.0);
    assert!(
        unramped.windows(2).any(|w| w[1] > w[0] + 1),
        "a jump to a footfall: {unramped:?}"
    );
}

#[test]
fn a_frame_aligned_onto_a_root_takes_its_heading_and_ground_position_and_keeps_the_rest() {
    let model = CharacterModel::amp_humanoid();
    let frame = stride(&model);
    // Onto its own root: unchanged.
    let same = aligned_to(&frame, &frame[0]);
    for (a, b) in same.iter().zip(&frame) {
        assert!((a.pos - b.pos).length() < 1e-5 && a.rot.angle_between(b.rot) < 1e-4);
    }
    // Onto a root 3 m away, 1.5 m higher and turned by 1 rad (tilted too): the frame's root
    // takes its ground position and heading but keeps its own height and tilt.
    let onto = BodyState {
        pos: Vector::new(3.0, -1.0, 2.4),
        rot: Rotation::from_rotation_z(1.4) * Rotation::from_rotation_y(0.3),
        linvel: Vector::ZERO,
        angvel: Vector::ZERO,
    };
    let moved = aligned_to(&frame, &onto);
    assert!((moved[0].pos.x - 3.0).abs() < 1e-5 && (moved[0].pos.y + 1.0).abs() < 1e-5);
    assert!(
        (moved[0].pos.z - frame[0].pos.z).abs() < 1e-5,
        "height kept"
    );
    let heading = |b: &BodyState| {
        let f = b.rot * Vector::X;
        f.y.atan2(f.x)
    };
    assert!((heading(&moved[0]) - heading(&onto)).abs() < 1e-4);
    let turn = Rotation::from_rotation_z(1.0);
    for (a, b) in moved.iter().zip(&frame) {
        let rel_a = a.pos - moved[0].pos;
        let rel_b = turn * (b.pos - frame[0].pos);
        assert!(
            (rel_a - rel_b).length() < 1e-4,
            "the body's place about the root turns with it"
        );
        assert!((a.linvel - turn * b.linvel).length() < 1e-4);
    }
    // Tracking is blind to the move: a frame scores 1 against itself moved anywhere.
    let ends: Vec<usize> = ["left_foot", "right_foot", "left_hand", "right_hand"]
        .iter()
        .filter_map(|n| model.body_index(n))
        .collect();
    let score = imitation(&moved, &aligned_to(&frame, &moved[0]), &ends);
    assert!((score - 1.0).abs() < 1e-4, "{score}");
}

#[test]
fn in_a_gait_run_the_imitation_term_tracks_the_gait_wherever_it_heads() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    let env_with = |imitation: f32| {
        // No steering: it would turn the two headings below differently.
        let mut config = EnvConfig {
            gait: Some(GaitConfig {
                steer_gain: 0.0,
                ..GaitConfig::default()
            }),
            empty_room: true,
            ..EnvConfig::default()
        };
        config.weights.imitation = imitation;
        task_env(&model, config)
    };
    let zero = vec![0.0; model.dofs.len()];
    // The same start turned two ways earns the same tracking (the course is free).
    let mut terms = Vec::new();
    for yaw in [0.0, 2.0] {
        let mut env = env_with(1.0);
        assert!(env.start_in_gait(&demo, Arc::clone(&reference), 3, yaw));
        terms.push(
            (0..5)
                .map(|_| env.step(&zero).terms.imitation)
                .collect::<Vec<_>>(),
        );
    }
    for (a, b) in terms[0].iter().zip(&terms[1]) {
        assert!((a - b).abs() < 0.05, "{:?} vs {:?}", terms[0], terms[1]);
    }
    assert!(
        terms[0][0] > 0.5,
        "on the gait from its own frame: {:?}",
        terms[0]
    );
    // A large residual on every joint takes the character off its reference: tracked lower.
    let mut env = env_with(1.0);
    env.start_in_gait(&demo, Arc::clone(&reference), 3, 0.0);
    let off: Vec<f32> = (0..model.dofs.len())
        .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
        .collect();
    let bent: Vec<f32> = (0..5).map(|_| env.step(&off).terms.imitation).collect();
    assert!(bent[4] < terms[0][4] - 0.1, "{bent:?} vs {:?}", terms[0]);
    // With the weight at 0 the term is not computed.
    let mut env = env_with(0.0);
    env.start_in_gait(&demo, Arc::clone(&reference), 3, 0.0);
    assert_eq!(env.step(&zero).terms.imitation, 0.0);
}

#[test]
fn an_empty_room_has_no_furniture_and_its_objects_far_along_x() {
    let bench = Benchmark::embedded().unwrap();
    let (_, task) = bench.task("train-0001").unwrap();
    assert!(
        !task.obstacles.is_empty(),
        "the task has furniture to remove"
    );
    let empty = empty_room(&task);
    assert!(empty.obstacles.is_empty());
    assert_eq!(empty.room_size, [60.0, 60.0]);
    for (a, b) in empty.objects.iter().zip(&task.objects) {
        assert_eq!(a.pos[0], b.pos[0] + 25.0);
        assert_eq!((a.pos[1], a.pos[2]), (b.pos[1], b.pos[2]));
    }
    assert_eq!(empty.start.pos, task.start.pos);
}

#[test]
fn a_room_without_furniture_keeps_walls_start_and_objects_and_puts_raised_ones_on_the_floor() {
    let bench = Benchmark::embedded().unwrap();
    // A task with an object on furniture.
    let task = bench
        .all_tasks()
        .map(|(_, t)| t)
        .find(|t| t.objects.iter().any(|o| o.on != Support::Floor))
        .expect("the benchmark has an object on furniture");
    let bare = without_furniture(task);
    assert!(bare.obstacles.is_empty());
    assert_eq!(bare.room_size, task.room_size);
    assert_eq!(bare.start.pos, task.start.pos);
    for (a, b) in bare.objects.iter().zip(&task.objects) {
        assert_eq!(a.on, Support::Floor);
        assert_eq!((a.pos[0], a.pos[1]), (b.pos[0], b.pos[1]));
        assert_eq!(a.pos[2], b.size[2] / 2.0, "{} rests on the floor", a.id);
        if b.on == Support::Floor {
            assert_eq!(a.pos, b.pos);
        }
    }
    for (a, b) in bare.sequence.iter().zip(&task.sequence) {
        assert_eq!(a.on, Support::Floor);
        assert_eq!((a.goal[0], a.goal[1]), (b.goal[0], b.goal[1]));
        if b.on == Support::Floor {
            assert_eq!(a.goal, b.goal);
        } else {
            let o = task.objects.iter().find(|o| o.id == a.object).unwrap();
            assert_eq!(a.goal[2], o.size[2] / 2.0);
        }
    }
}

#[test]
fn with_bouts_the_walk_pauses_after_bout_distance_stands_pause_seconds_and_walks_on() {
    let model = CharacterModel::amp_humanoid();
    let demo = cycle_demo(&model);
    let reference = Arc::new(GaitReference::new(&model, &demo, 0, 1.0 / 30.0).unwrap());
    // Per step for 40 steps from a walking start (the synthetic cycle's 1 m/s): whether the
    // gait is stopped, and whether the step ended the episode early by the stand's rule.
    let run = |bout_min_left: f32| -> (Vec<bool>, bool) {
        let gait = GaitConfig {
            bout_distance: 0.2,
            bout_min_left,
            pause_seconds: 0.2,
            // A stand rule shorter than the pause: a pause is no stand and ends no episode.
            stand_seconds: 0.1,
            ..GaitConfig::default()
        };
        let mut env = gait_env(&model, Some(gait));
        let yaw = env.yaw_toward_first_object();
        assert!(env.start_in_gait(&demo, Arc::clone(&reference), 9, yaw));
        let zero = vec![0.0; model.dofs.len()];
        let mut truncated = false;
        let stopped = (0..40)
            .map(|_| {
                truncated |= env.step(&zero).truncated;
                env.gait_stopped()
            })
            .collect();
        (stopped, truncated)
    };
    let (stopped, truncated) = run(0.0);
    let first = stopped.iter().position(|&s| s).expect("the walk pauses");
    assert!(first >= 2, "it walks 0.2 m first: {stopped:?}");
    let pause = stopped[first..].iter().take_while(|&&s| s).count();
    assert!(
        (5..=7).contains(&pause),
        "0.2 s at 30 Hz: {pause} steps, {stopped:?}"
    );
    assert!(!stopped[first + pause], "and walks on: {stopped:?}");
    assert!(!truncated, "a pause is not the stand after the stop");
    // The object nearer than `bout_min_left`: no pause.
    let (stopped, _) = run(1000.0);
    assert!(stopped.iter().all(|&s| !s), "{stopped:?}");
}
