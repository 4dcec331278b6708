//! Physics fidelity at the training settings: the character holds a standing pose as MuJoCo does.

use lhm_sim::fidelity::{run_scenario, run_servo_step, Drive};
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
