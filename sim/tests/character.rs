//! The character in rapier: plausible passive behaviour, exact snapshot/restore, determinism.

use lhm_sim::batch::WorldBatch;
use lhm_sim::{CharacterModel, SimConfig, World};

/// Deterministic actions in [-1, 1].
fn actions(seed: u64, n: usize) -> Vec<f32> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        })
        .collect()
}

fn all_poses(w: &World) -> Vec<[u32; 7]> {
    (0..w.character.bodies.len())
        .map(|b| {
            let p = w.body_pose(b);
            let (t, r) = (p.translation, p.rotation);
            [t.x, t.y, t.z, r.x, r.y, r.z, r.w].map(f32::to_bits)
        })
        .collect()
}

#[test]
fn a_mid_range_crouch_holds_for_a_moment_then_falls_without_flying() {
    let model = CharacterModel::amp_humanoid();
    let mut w = World::new(&model, SimConfig::default());
    // Knees and elbows to mid-range (80°), everything else neutral: the zero action of the
    // earlier action mapping (zero action now stands; test `zero_action_is_the_neutral_pose...`).
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
    let spawn = w.root_height();
    let (mut max_root, mut max_speed): (f32, f32) = (0.0, 0.0);
    let mut heights = Vec::new();
    for _ in 0..300 {
        assert!(
            w.step(&zero),
            "physics guard tripped at step {}",
            w.control_steps
        );
        assert!(w.is_finite());
        max_root = max_root.max(w.root_height());
        for b in 0..model.bodies.len() {
            max_speed = max_speed.max(w.body_linvel(b).length());
        }
        heights.push(w.root_height());
    }
    // A moment after spawn it is still upright; the knees bend to mid-range, so it sinks into a
    // crouch it holds for a while ...
    assert!(heights[2] > 0.8, "root at 0.1 s: {}", heights[2]);
    // (measured: 0.71 m at 0.33 s, 0.64 m at 0.53 s, then tipping over)
    assert!(
        heights[10..16].iter().all(|h| *h > 0.6),
        "crouch held: {:?}",
        &heights[10..16]
    );
    // ... it never rises above where it started or moves absurdly fast ...
    assert!(
        max_root < spawn + 0.02,
        "root rose to {max_root} (spawn {spawn})"
    );
    assert!(max_speed < 8.0, "a body reached {max_speed} m/s");
    // ... and ten seconds later it lies on the floor.
    let last = *heights.last().expect("stepped");
    assert!(last < 0.3, "root still at {last} after 10 s");
}

#[test]
fn snapshot_restore_replays_300_steps_exactly() {
    let model = CharacterModel::amp_humanoid();
    let n = model.dofs.len();
    let mut w = World::new(&model, SimConfig::default());
    let warmup = actions(1, 20 * n);
    for a in warmup.chunks(n) {
        w.step(&[a.iter().map(|x| x * 0.3).collect::<Vec<_>>(), vec![]].concat());
    }
    let snap = w.snapshot();
    let acts = actions(2, 300 * n);
    let mut first = Vec::new();
    for a in acts.chunks(n) {
        w.step(a);
        first.push(all_poses(&w));
    }
    w.restore(&snap);
    for (k, a) in acts.chunks(n).enumerate() {
        w.step(a);
        assert_eq!(
            all_poses(&w),
            first[k],
            "diverged at step {k} after restore"
        );
    }
}

#[test]
fn batch_results_do_not_depend_on_thread_count() {
    let model = CharacterModel::amp_humanoid();
    let n = model.dofs.len();
    let run = |threads: usize| {
        let worlds = (0..4)
            .map(|_| World::new(&model, SimConfig::default()))
            .collect();
        let mut batch = WorldBatch::new(worlds, threads);
        for step in 0..30u64 {
            let acts: Vec<f32> = (0..4).flat_map(|i| actions(step * 10 + i, n)).collect();
            batch.step(&acts, n);
        }
        batch.worlds.iter().map(all_poses).collect::<Vec<_>>()
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_ne!(one[0], one[1], "different actions give different worlds");
}

#[test]
fn nan_and_explosions_trip_the_guard_instead_of_a_panic() {
    let model = CharacterModel::amp_humanoid();
    let zero = vec![0.0; model.dofs.len()];
    for (what, value) in [("NaN", f32::NAN), ("explosion", 1.0e4)] {
        let mut w = World::new(&model, SimConfig::default());
        assert!(w.step(&zero));
        // Corrupt the root's generalized velocity the way a diverging solve would.
        let root_joint = w
            .state
            .multibody_joints
            .rigid_body_link(w.character.root())
            .copied()
            .expect("root link");
        let mb = w
            .state
            .multibody_joints
            .get_multibody_mut(root_joint.multibody)
            .expect("multibody");
        mb.generalized_velocity_mut()[2] = value;
        assert!(!w.step(&zero), "{what}: the guard trips");
        assert!(w.physics_invalid, "{what}: flagged");
        assert!(
            !w.step(&zero),
            "{what}: an invalid world is not stepped again"
        );
    }
}

#[test]
fn welded_hands_ride_on_their_forearms_with_the_mass_kept() {
    let model = CharacterModel::amp_humanoid();
    let mut w = World::new(&model, SimConfig::default());
    let index = |name: &str| model.body_index(name).expect(name);
    let (hand, forearm) = (index("right_hand"), index("right_lower_arm"));
    // 15 model bodies on 13 rigid bodies: each hand is part of its forearm's rigid body.
    let mut distinct = w.character.bodies.clone();
    distinct.sort_by_key(|h| h.into_raw_parts());
    distinct.dedup();
    assert_eq!((w.character.bodies.len(), distinct.len()), (15, 13));
    assert_eq!(w.character.bodies[hand], w.character.bodies[forearm]);
    let mass: f32 = distinct.iter().map(|h| w.state.bodies[*h].mass()).sum();
    assert!(
        (mass as f64 - model.total_mass()).abs() < 1e-3 * model.total_mass(),
        "simulated mass {mass} vs model {}",
        model.total_mass()
    );
    // The hand's frame stays at its fixed offset in the forearm while the arm moves, and its
    // velocity is that of that point.
    let offset = model_offset(&model, hand);
    for a in actions(3, 30 * model.dofs.len()).chunks(model.dofs.len()) {
        assert!(w.step(a));
    }
    let (h, f) = (w.body_state(hand), w.body_pose(forearm));
    assert!((h.pos - (f.translation + f.rotation * offset)).length() < 1e-5);
    assert!((h.rot.dot(f.rotation).abs() - 1.0).abs() < 1e-5);
    let carrier = &w.state.bodies[w.character.bodies[hand]];
    assert!((h.linvel - carrier.velocity_at_point(h.pos)).length() < 1e-4);
    assert!(
        (h.linvel - carrier.linvel()).length() > 1e-3,
        "not the forearm's own velocity"
    );
}

/// The hand's origin in its forearm's frame, from the model (frames are never rotated).
fn model_offset(model: &CharacterModel, body: usize) -> rapier3d::math::Vector {
    let p = model.bodies[body].pos;
    rapier3d::math::Vector::new(p[0] as f32, p[1] as f32, p[2] as f32)
}
