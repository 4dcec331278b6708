//! The upright assist: a PD torque on the root that a curriculum can lower to zero.

use lhm_sim::world::UprightAssist;
use lhm_sim::{CharacterModel, SimConfig, World};
use rapier3d::prelude::{Rotation, Vector};

/// Deterministic noise in [-1, 1].
fn noise(seed: &mut u64) -> f32 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    ((*seed >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
}

#[test]
fn the_assist_torque_turns_a_tilted_root_back_and_leaves_an_upright_one_alone() {
    let assist = UprightAssist {
        stiffness: 100.0,
        damping: 10.0,
        ..UprightAssist::default()
    };
    let yawed = Rotation::from_rotation_z(1.3);
    assert!(assist.torque(yawed, Vector::new(0.0, 0.0, 2.0)).length() < 1e-4);
    // Pitched forward by 0.3 rad about +y: the restoring torque is about -y, 100 × 0.3 N·m.
    let pitched = Rotation::from_rotation_y(0.3) * yawed;
    let t = assist.torque(pitched, Vector::ZERO);
    assert!((t - Vector::new(0.0, -30.0, 0.0)).length() < 1e-3, "{t:?}");
    // Damping opposes horizontal spin only.
    let d = assist.torque(yawed, Vector::new(1.0, 0.0, 5.0));
    assert!((d - Vector::new(-10.0, 0.0, 0.0)).length() < 1e-4, "{d:?}");
    // Upside down it still pushes, with the full half-turn's torque.
    let flipped = Rotation::from_rotation_x(std::f32::consts::PI);
    assert!(assist.torque(flipped, Vector::ZERO).length() > 300.0);
    assert!(!UprightAssist::default().is_active());
    // The hoist lifts a sagging root and never pulls a high one down.
    let hoist = UprightAssist {
        support_stiffness: 1000.0,
        support_damping: 100.0,
        support_height: 0.85,
        ..UprightAssist::default()
    };
    assert!((hoist.support(0.75, 0.0).z - 100.0).abs() < 1e-3);
    assert!((hoist.support(0.75, -0.5).z - 150.0).abs() < 1e-3);
    assert_eq!(hoist.support(0.95, 0.0), Vector::ZERO);
    assert_eq!(hoist.support(0.8, 2.0), Vector::ZERO);
}

/// Steps of noisy actions until the root drops below 0.5 m (or `steps`).
/// (Without the hoist, an upright torque alone keeps the root level but not up: the legs fold
/// under noise and the root sinks below 0.5 m within ~30-50 steps, measured while choosing these
/// gains; stronger torques, 2000 N·m/rad with 60-200 N·m·s/rad, made the explicit force
/// oscillate and fall sooner.)
fn steps_standing(config: SimConfig, amplitude: f32, steps: usize) -> (usize, f32) {
    let model = CharacterModel::amp_humanoid();
    let mut w = World::new(&model, config);
    let mut seed = 7;
    let mut max_tilt: f32 = 0.0;
    for i in 0..steps {
        let action: Vec<f32> = (0..model.dofs.len())
            .map(|_| amplitude * noise(&mut seed))
            .collect();
        if !w.step(&action) {
            panic!("physics invalid at step {i} (assist {:?})", w.config.assist);
        }
        let up = w.body_pose(0).rotation * Vector::Z;
        max_tilt = max_tilt.max(up.z.clamp(-1.0, 1.0).acos());
        if w.root_height() < 0.5 {
            return (i, max_tilt);
        }
    }
    (steps, max_tilt)
}

#[test]
fn the_assist_keeps_up_a_character_that_noisy_actions_topple() {
    let amplitude = 0.2;
    let (fell_at, _) = steps_standing(SimConfig::default(), amplitude, 300);
    let assisted = SimConfig {
        assist: UprightAssist {
            stiffness: 1000.0,
            damping: 40.0,
            support_stiffness: 5000.0,
            support_damping: 200.0,
            support_height: 0.85,
            ..UprightAssist::default()
        },
        ..SimConfig::default()
    };
    let (held, tilt) = steps_standing(assisted, amplitude, 300);
    eprintln!("unassisted fell at {fell_at}; assisted {held} steps, max tilt {tilt}");
    assert!(
        fell_at < 150,
        "noise this strong should topple it: {fell_at}"
    );
    assert_eq!(held, 300, "the assisted character fell at step {held}");
    assert!(tilt < 0.5, "assisted root tilted {tilt} rad");
}

#[test]
fn the_assist_fades_linearly_over_its_iterations_and_stays_when_no_fade_is_set() {
    let full = UprightAssist {
        stiffness: 1000.0,
        damping: 40.0,
        support_stiffness: 5000.0,
        support_damping: 200.0,
        support_height: 0.85,
        fade_from: 100,
        fade_to: 300,
    };
    assert_eq!(full.at_iteration(0), full);
    assert_eq!(full.at_iteration(100), full);
    let half = full.at_iteration(200);
    assert!((half.stiffness - 500.0).abs() < 1e-3 && (half.support_damping - 100.0).abs() < 1e-3);
    assert_eq!(half.support_height, 0.85);
    assert!(!full.at_iteration(300).is_active());
    assert!(!full.at_iteration(10_000).is_active());
    let constant = UprightAssist {
        fade_from: 0,
        fade_to: 0,
        ..full.clone()
    };
    assert_eq!(constant.at_iteration(1_000_000), constant);
}

#[test]
fn the_world_reports_the_assist_effort_and_a_faded_assist_leaves_no_push_behind() {
    let model = CharacterModel::amp_humanoid();
    let hoist = UprightAssist {
        stiffness: 1000.0,
        damping: 40.0,
        support_stiffness: 5000.0,
        // Above the standing root height: the hoist pulls up on every step.
        support_height: 1.2,
        ..UprightAssist::default()
    };
    let mut w = World::new(
        &model,
        SimConfig {
            assist: hoist,
            ..SimConfig::default()
        },
    );
    let zero = vec![0.0; model.dofs.len()];
    for _ in 0..5 {
        assert!(w.step(&zero));
    }
    assert!(w.assist_force.z > 500.0, "{:?}", w.assist_force);
    let effort = lhm_sim::task::rewards::assist_effort(w.assist_torque, w.assist_force);
    assert!(effort < -1.0, "{effort}");
    // The fade reached zero: the root's user force is cleared, and the effort reads zero.
    w.config.assist = UprightAssist::default();
    assert!(w.step(&zero));
    let root = &w.state.bodies[w.character.root()];
    assert_eq!(root.user_force(), Vector::ZERO);
    assert_eq!(root.user_torque(), Vector::ZERO);
    assert_eq!(w.assist_force, Vector::ZERO);
    assert_eq!(
        lhm_sim::task::rewards::assist_effort(Vector::ZERO, Vector::ZERO),
        0.0
    );
}
