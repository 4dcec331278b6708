//! Physics fidelity at the training settings: the character holds a standing pose as MuJoCo does.

use lhm_sim::character::ball_limit_error;
use lhm_sim::fidelity::{run_collapse, run_scenario, run_servo_step, Drive};
use lhm_sim::{CharacterModel, SimConfig, World};

#[test]
fn the_neutral_pose_holds_for_three_seconds_with_feet_that_stay_put() {
    let model = CharacterModel::amp_humanoid();
    let r = run_scenario(
        &model,
        &SimConfig::default(),
        Drive::Neutral,
        3.0,
        0.0,
        false,
    );
    assert_eq!(r.fall_step, None, "{r:?}");
    for (t, tilt) in &r.pelvis_tilt_deg {
        assert!(*tilt < 5.0, "pelvis tilt {tilt} deg at {t} s");
    }
    let slide = r.foot_slide_m.expect("standing after 0.5 s");
    assert!(slide < 0.01, "feet slid {slide} m");
    let err = r.max_tracking_error_deg.expect("servos on");
    assert!(
        err < 2.0,
        "tracking error {err} deg: MuJoCo's is under 1 deg"
    );
    assert!(r.max_penetration_m < 0.005, "{} m", r.max_penetration_m);
    // Standing still, the floor carries the body weight.
    let w = r.body_weight_n;
    assert!((r.contact_force_mean_n - w).abs() < 0.05 * w, "{r:?}");
}

#[test]
fn zero_action_is_the_neutral_pose_and_stands() {
    let model = CharacterModel::amp_humanoid();
    let world = World::new(&model, SimConfig::default());
    let targets = world.character.targets(&vec![0.0; model.dofs.len()]);
    assert!(targets.iter().all(|t| *t == 0.0), "{targets:?}");
    // Full range is still reachable within the action bound of 1.
    let far = world.character.targets(&vec![1.0; model.dofs.len()]);
    let knee = model
        .dofs
        .iter()
        .position(|d| d.name == "left_knee")
        .unwrap();
    assert!((far[knee] as f64 - model.dofs[knee].range[1]).abs() < 1e-5);
    let r = run_scenario(
        &model,
        &SimConfig::default(),
        Drive::ZeroAction,
        2.0,
        0.0,
        false,
    );
    assert_eq!(r.fall_step, None);
}

#[test]
fn servos_off_the_character_falls_and_the_knee_servo_reaches_its_target() {
    let model = CharacterModel::amp_humanoid();
    let sim = SimConfig::default();
    let r = run_scenario(&model, &sim, Drive::Passive, 3.0, 0.0, false);
    let fall = r.fall_step.expect("a limp character falls");
    assert!((10..40).contains(&fall), "fell at step {fall} (MuJoCo: 17)");
    let s = run_servo_step(&model, &sim);
    let at = |k: &str| s.knee_error_deg[k];
    // Torque-limited at first, then converging: MuJoCo 51.9, 29.7, 10.7, 1.3 deg.
    assert!(
        at("0.03") > 40.0 && at("0.1") < at("0.03") && at("0.5") < 3.0,
        "{s:?}"
    );
}

#[test]
fn three_dof_joints_stay_within_their_ranges_while_the_body_collapses() {
    let model = CharacterModel::amp_humanoid();
    let sim = SimConfig::default();
    let limited = run_collapse(&model, &sim);
    // MuJoCo (soft limits): 1.1 deg on average, 6.5 at most. Without the limit springs the hips
    // and a shoulder rest 15-30 deg past their ranges on the floor.
    assert!(limited.mean_limit_excess_deg < 4.0, "{limited:?}");
    for joint in ["left_ankle_y", "right_ankle_y", "abdomen_x", "abdomen_y"] {
        let e = limited.limit_excess_deg_by_joint[joint];
        assert!(e < 10.0, "{joint} {e} deg past its range");
    }
    // The same collapse on a world whose limit springs are removed goes far past.
    let mut world = World::new(&model, sim.clone());
    world.character.limit_stiffness.fill(0.0);
    world.character.limit_damping.fill(0.0);
    world.character.model.dofs.iter_mut().for_each(|d| {
        d.kp = 1e-9;
        d.kd = 0.0;
        d.torque_limit = 0.0;
    });
    let zeros = vec![0.0; model.dofs.len()];
    let steps = (lhm_sim::fidelity::COLLAPSE_S * sim.control_hz).round() as usize;
    let mut sum_worst = 0.0f32;
    for _ in 0..steps {
        world.step_targets(&zeros);
        let excess = lhm_sim::fidelity::limit_excess(&model, &world.body_states());
        sum_worst += excess.iter().copied().fold(0.0, f32::max).to_degrees();
    }
    let unlimited = sum_worst / steps as f32;
    println!(
        "worst DoF past its range, mean: {:.2} deg with limits, {unlimited:.2} without",
        limited.mean_limit_excess_deg
    );
    assert!(
        unlimited > 3.0 * limited.mean_limit_excess_deg,
        "without limits {unlimited} deg"
    );
}

#[test]
fn the_limit_error_of_a_three_dof_joint_points_back_into_its_ranges() {
    use rapier3d::math::Rotation;
    let ranges = [[-0.5, 0.5], [-1.0, 1.0], [-0.3, 0.3]];
    let inside = Rotation::from_rotation_x(0.4) * Rotation::from_rotation_y(-0.9);
    assert!(ball_limit_error(inside, ranges).is_none());
    let past_x = Rotation::from_rotation_x(0.8);
    let e = ball_limit_error(past_x, ranges).expect("0.8 rad is past 0.5");
    assert!(
        (e.x + 0.3).abs() < 1e-4 && e.y.abs() < 1e-4 && e.z.abs() < 1e-4,
        "{e:?}"
    );
    // Applying the error lands on the range's edge.
    let back = Rotation::from_scaled_axis(e) * past_x;
    assert!(ball_limit_error(back, ranges).is_none_or(|e| e.length() < 1e-4));
}

/// A saturated servo on a light DoF still reaches its target. Each of these asks for more torque
/// than the joint's limit at the start (shoulders: 100 N·m at kp 400, so past 14.3°; ankles:
/// 90 N·m, past 12.9°); the upper arm's twist has almost no inertia about its own axis. With the
/// servo's rest point moved every step to where kp pulled with the limit, rapier's multibody
/// left these stalled (a 16° twist target held at 1.2°, an ankle at −25° driven to +7°).
#[test]
fn saturated_servos_on_light_joints_reach_their_targets() {
    let model = CharacterModel::amp_humanoid();
    let config = SimConfig {
        pin_root: true,
        spawn_height: SimConfig::default().spawn_height + 0.5,
        ..SimConfig::default()
    };
    for (name, deg) in [
        ("right_shoulder_z", 16.0f32),
        ("left_shoulder_z", -40.0),
        ("right_ankle_y", -25.0),
        ("left_ankle_x", 25.0),
    ] {
        let d = model.dofs.iter().position(|x| x.name == name).unwrap();
        let mut targets = vec![0.0; model.dofs.len()];
        targets[d] = deg.to_radians();
        let mut world = World::new(&model, config.clone());
        for _ in 0..30 {
            assert!(world.step_targets(&targets));
        }
        let reached = lhm_sim::fidelity::joint_angles(&model, &world.body_states())[d].to_degrees();
        assert!(
            (reached - deg).abs() < 1.0,
            "{name}: target {deg}°, held at {reached}° after 1 s"
        );
    }
}
