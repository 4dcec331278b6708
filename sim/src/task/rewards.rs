//! Reward terms as small pure functions over plain state, each in [0, 1] unless it is a penalty.
//! The task reward of a step is their weighted sum ([`RewardWeights`]); the style reward comes
//! from the AMP discriminator elsewhere.

use crate::obs::BodyState;
use rapier3d::math::Vector;
use serde::{Deserialize, Serialize};

/// Horizontal part of a vector.
fn flat(v: Vector) -> Vector {
    Vector::new(v.x, v.y, 0.0)
}

/// Walking to the object: 1 once within `near` metres (horizontally); before that, half for
/// closeness and half for speed toward it, up to `target_speed`.
pub fn locomotion(
    root_pos: Vector,
    root_vel: Vector,
    object_pos: Vector,
    target_speed: f32,
    near: f32,
) -> f32 {
    let to = flat(object_pos - root_pos);
    let d = to.length();
    if d < near {
        return 1.0;
    }
    let dir = to / d;
    let speed_toward = flat(root_vel).dot(dir);
    let speed_gap = (target_speed - speed_toward).max(0.0);
    0.5 * (-0.5 * d * d).exp() + 0.5 * (-2.0 * speed_gap * speed_gap).exp()
}

/// Facing the object: the cosine between the root's horizontal heading and the horizontal
/// direction to the object, floored at 0; 1 once within `near` metres (where turning to face it
/// no longer matters). The median task object starts 93° off the start heading.
pub fn facing(root_pos: Vector, heading: Vector, object_pos: Vector, near: f32) -> f32 {
    let to = flat(object_pos - root_pos);
    let d = to.length();
    if d < near {
        return 1.0;
    }
    let h = flat(heading);
    let hl = h.length();
    if hl < 1e-6 {
        return 0.0;
    }
    (h.dot(to) / (hl * d)).max(0.0)
}

/// Distance from `p` to an axis-aligned box (object frame) of half extents `half` (0 inside).
pub fn distance_to_box(p_local: Vector, half: Vector) -> f32 {
    let q = p_local.abs() - half;
    q.max(Vector::ZERO).length()
}

/// Both hands on the object: exp(-k · mean squared hand-to-surface distance). Hand positions are
/// in the object's frame.
pub fn hands_to_object(left_local: Vector, right_local: Vector, half: Vector, k: f32) -> f32 {
    let dl = distance_to_box(left_local, half);
    let dr = distance_to_box(right_local, half);
    (-k * 0.5 * (dl * dl + dr * dr)).exp()
}

/// Lifting: fraction of `target_lift` metres the object has risen above where it started, in
/// [0, 1].
pub fn lift(object_z: f32, start_z: f32, target_lift: f32) -> f32 {
    ((object_z - start_z) / target_lift).clamp(0.0, 1.0)
}

/// Carrying: the object's horizontal speed toward its goal, up to `target_speed`; 1 once within
/// `near` of the goal.
pub fn carry(
    object_pos: Vector,
    object_vel: Vector,
    goal: Vector,
    target_speed: f32,
    near: f32,
) -> f32 {
    let to = flat(goal - object_pos);
    let d = to.length();
    if d < near {
        return 1.0;
    }
    let gap = (target_speed - flat(object_vel).dot(to / d)).max(0.0);
    (-2.0 * gap * gap).exp()
}

/// Placing: exp(-k · |object - goal|²) in 3-D.
pub fn place(object_pos: Vector, goal: Vector, k: f32) -> f32 {
    (-k * (object_pos - goal).length_squared()).exp()
}

/// Leaning on the upright assist (`sim::world::UprightAssist`), as a penalty: -(|τ| / 100 N·m +
/// |F| / 500 N), the root torque and hoist force it applied (500 N is about the character's
/// weight). Paying it teaches the policy to stand on its own while the assist still catches falls.
pub fn assist_effort(torque: Vector, force: Vector) -> f32 {
    -(torque.length() / 100.0 + force.length() / 500.0)
}

/// Mechanical power, as a penalty: -Σ |τ_i · q̇_i| (W).
pub fn power_penalty(torques: &[f32], joint_velocities: &[f32]) -> f32 {
    -torques
        .iter()
        .zip(joint_velocities)
        .map(|(t, v)| (t * v).abs())
        .sum::<f32>()
}

/// Imitation of a reference motion, DeepMimic's tracking reward (Peng et al. 2018, eq. 5-9), over
/// body states in the world frame: `sim` is the character now, `reference` where the clip says it
/// should be (the same bodies, the root first), `end_effectors` the indices of the feet and hands.
/// In [0, 1], the sum of
/// - pose: 0.65 · exp(-2 Σ angle(body rotation)²),
/// - velocity: 0.1 · exp(-0.1 Σ |angular velocity error|²),
/// - end effectors: 0.15 · exp(-40 Σ |end-effector error relative to the root|²),
/// - root: 0.1 · exp(-10 (|root position error|² + 0.1 |root velocity error|²)).
///
/// DeepMimic sums local joint rotations; world rotations are used here (the root's included), so
/// a wrong heading costs on every body, which keeps the character on the reference's course.
pub fn imitation(sim: &[BodyState], reference: &[BodyState], end_effectors: &[usize]) -> f32 {
    let (Some(root), Some(ref_root)) = (sim.first(), reference.first()) else {
        return 0.0;
    };
    let mut pose = 0.0;
    let mut spin = 0.0;
    for (s, r) in sim.iter().zip(reference) {
        let angle = s.rot.angle_between(r.rot);
        pose += angle * angle;
        spin += (s.angvel - r.angvel).length_squared();
    }
    let mut ends = 0.0;
    for &e in end_effectors {
        if let (Some(s), Some(r)) = (sim.get(e), reference.get(e)) {
            ends += ((s.pos - root.pos) - (r.pos - ref_root.pos)).length_squared();
        }
    }
    let root_err = (root.pos - ref_root.pos).length_squared()
        + 0.1 * (root.linvel - ref_root.linvel).length_squared();
    0.65 * (-2.0 * pose).exp()
        + 0.1 * (-0.1 * spin).exp()
        + 0.15 * (-40.0 * ends).exp()
        + 0.1 * (-10.0 * root_err).exp()
}

/// Parameters of the release-and-retreat reward (paper, Algorithm 1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReleaseRetreat {
    /// Growth rate of the distance terms, 1/m.
    pub alpha: f32,
    /// Root-to-object distance beyond which the root term is capped at 1, m.
    pub delta_r: f32,
    /// Hand-to-object distance beyond which the hand term is capped at 1, m.
    pub delta_h: f32,
    /// The reward stays 0 until the object is within this distance of its goal, m.
    pub tau_object2goal: f32,
    /// Weight of the root term (1 - beta: hand term).
    pub beta: f32,
}

impl Default for ReleaseRetreat {
    fn default() -> Self {
        Self {
            alpha: 5.0,
            delta_r: 0.8,
            delta_h: 0.5,
            tau_object2goal: 0.2,
            beta: 0.5,
        }
    }
}

/// Release-and-retreat, line for line as Algorithm 1 of the paper.
pub fn release_and_retreat(
    p: &ReleaseRetreat,
    d_root2object: f32,
    d_hand2object_left: f32,
    d_hand2object_right: f32,
    d_object2goal: f32,
) -> f32 {
    let d_hand2object = d_hand2object_left.min(d_hand2object_right); // line 1
    let mut r_root2object = 1.0 - (-p.alpha * d_root2object).exp(); // line 2
    let mut r_hand2object = 1.0 - (-p.alpha * d_hand2object).exp(); // line 3
    if d_root2object > p.delta_r {
        r_root2object = 1.0; // lines 4-6
    }
    if d_hand2object > p.delta_h {
        r_hand2object = 1.0; // lines 7-9
    }
    if d_object2goal >= p.tau_object2goal {
        r_root2object = 0.0; // lines 10-13
        r_hand2object = 0.0;
    }
    p.beta * r_root2object + (1.0 - p.beta) * r_hand2object // line 14
}

/// Weights of the task reward terms (the power term is a penalty: its weight is positive and its
/// value negative).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RewardWeights {
    pub locomotion: f32,
    pub hands: f32,
    pub lift: f32,
    pub carry: f32,
    pub place: f32,
    pub power: f32,
    /// 0 during pretraining, > 0 for release-and-retreat fine-tuning.
    pub release_retreat: f32,
    pub facing: f32,
    /// One-off reward on the step a pair is placed within the success radius: a successful
    /// cycle ends the episode (terminal), so it must pay at least what staying on would.
    pub success: f32,
    /// Per step the character has not fallen (Gym's Humanoid `healthy_reward`): with AMP the
    /// discriminator's reward shrinks on everything the early policy does, so without it the
    /// only reason to stay up was ~0.05 of task reward per step (RESULTS.md, third session).
    pub alive: f32,
    /// Tracking the clip a demo start came from ([`imitation`]) for `EnvConfig::imitation_seconds`
    /// after the start — or, while an `[env.gait]` walks, the gait's own reference moved onto the
    /// character's heading and ground position, every step; 0 (off) by default.
    pub imitation: f32,
    /// One-off reward on the step a Hierarchical-RL skill hands over to the next one (its
    /// completion); paid only under the skill machine (`EnvConfig::skills`).
    pub skill: f32,
    /// Leaning on the upright assist ([`assist_effort`]); 0 (off) by default.
    pub assist: f32,
}

impl Default for RewardWeights {
    fn default() -> Self {
        Self {
            locomotion: 0.2,
            hands: 0.2,
            lift: 0.1,
            carry: 0.2,
            place: 0.3,
            // 2e-5 made the power term -0.26 per step while the early policy flails and falls: the
            // step reward went negative once the discriminator won, so falling sooner paid
            // (docs/runs/t1-power). IsaacGymEnvs' HumanoidAMP has no power term at all.
            power: 1e-6,
            release_retreat: 0.0,
            facing: 0.1,
            success: 20.0,
            // 0.5 (x the learner's task weight 0.5): survival now pays 0.25 per step.
            alive: 0.5,
            imitation: 0.0,
            skill: 5.0,
            assist: 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f32, y: f32, z: f32) -> Vector {
        Vector::new(x, y, z)
    }

    fn body(pos: Vector, rot: rapier3d::math::Rotation) -> BodyState {
        BodyState {
            pos,
            rot,
            linvel: Vector::ZERO,
            angvel: Vector::ZERO,
        }
    }

    /// A root, a hand 0.5 m in front of it and a foot 0.9 m below it.
    fn three_bodies(root: Vector, yaw: f32) -> Vec<BodyState> {
        let r = rapier3d::math::Rotation::from_rotation_z(yaw);
        vec![
            body(root, r),
            body(root + r * v(0.5, 0.0, 0.0), r),
            body(root + v(0.0, 0.0, -0.9), r),
        ]
    }

    #[test]
    fn imitation_is_one_on_the_reference_and_falls_off_with_each_error() {
        let reference = three_bodies(v(1.0, 2.0, 0.9), 0.3);
        let ends = [1, 2];
        assert!((imitation(&reference, &reference, &ends) - 1.0).abs() < 1e-6);
        // Displaced as a whole by 0.3 m: only the root term pays less.
        let shifted = three_bodies(v(1.3, 2.0, 0.9), 0.3);
        let r = imitation(&shifted, &reference, &ends);
        assert!(
            (r - (0.9 + 0.1 * (-10.0f32 * 0.09).exp())).abs() < 1e-5,
            "{r}"
        );
        // Turned by 0.5 rad: the pose term (every body) and the hand relative to the root.
        let turned = three_bodies(v(1.0, 2.0, 0.9), 0.8);
        let r_turn = imitation(&turned, &reference, &ends);
        assert!(r_turn < r && r_turn > 0.0, "{r_turn}");
        let pose = 0.65 * (-2.0f32 * 3.0 * 0.25).exp();
        let hand_err = 2.0 * 0.5 * (0.25f32).sin(); // chord of 0.5 rad on a 0.5 m arm
        let ends_term = 0.15 * (-40.0 * hand_err * hand_err).exp();
        assert!(
            (r_turn - (pose + 0.1 + ends_term + 0.1)).abs() < 1e-4,
            "{r_turn}"
        );
        // Spinning where the reference does not: only the velocity term.
        let mut spinning = reference.clone();
        spinning[0].angvel = v(0.0, 0.0, 3.0);
        let r_spin = imitation(&spinning, &reference, &ends);
        assert!(
            (r_spin - (0.9 + 0.1 * (-0.9f32).exp())).abs() < 1e-5,
            "{r_spin}"
        );
        // A fallen character earns almost nothing.
        let fallen = three_bodies(v(1.0, 2.0, 0.1), 2.5);
        assert!(imitation(&fallen, &reference, &ends) < 0.15);
        assert_eq!(imitation(&[], &reference, &ends), 0.0);
    }

    #[test]
    fn locomotion_rewards_closing_in_fast() {
        let obj = v(3.0, 0.0, 0.4);
        let standing = locomotion(v(0.0, 0.0, 0.9), Vector::ZERO, obj, 1.5, 0.5);
        let walking_to = locomotion(v(0.0, 0.0, 0.9), v(1.5, 0.0, 0.0), obj, 1.5, 0.5);
        let walking_away = locomotion(v(0.0, 0.0, 0.9), v(-1.5, 0.0, 0.0), obj, 1.5, 0.5);
        assert!(walking_to > standing && standing > walking_away);
        assert!((walking_to - (0.5 * (-4.5f32).exp() + 0.5)).abs() < 1e-6);
        assert_eq!(
            locomotion(v(2.7, 0.1, 0.9), Vector::ZERO, obj, 1.5, 0.5),
            1.0
        );
        // Height does not count.
        assert_eq!(
            locomotion(v(0.0, 0.0, 5.0), Vector::ZERO, obj, 1.5, 0.5),
            standing
        );
    }

    #[test]
    fn facing_rewards_turning_toward_the_object() {
        let obj = v(0.0, 3.0, 0.4);
        let root = v(0.0, 0.0, 0.9);
        assert!((facing(root, v(0.0, 1.0, 0.0), obj, 0.6) - 1.0).abs() < 1e-6);
        assert_eq!(facing(root, v(1.0, 0.0, 0.0), obj, 0.6), 0.0, "sideways");
        assert_eq!(facing(root, v(0.0, -1.0, 0.0), obj, 0.6), 0.0, "away");
        let half = facing(root, v(1.0, 1.0, 0.3), obj, 0.6);
        assert!(
            (half - std::f32::consts::FRAC_1_SQRT_2).abs() < 1e-5,
            "{half}"
        );
        assert_eq!(
            facing(v(0.0, 2.7, 0.9), v(1.0, 0.0, 0.0), obj, 0.6),
            1.0,
            "near"
        );
    }

    #[test]
    fn hands_reward_peaks_on_the_surface() {
        let half = v(0.2, 0.15, 0.1);
        assert_eq!(distance_to_box(v(0.0, 0.0, 0.0), half), 0.0);
        assert!((distance_to_box(v(0.5, 0.0, 0.0), half) - 0.3).abs() < 1e-6);
        let on = hands_to_object(v(0.2, 0.0, 0.0), v(-0.2, 0.0, 0.0), half, 20.0);
        let off = hands_to_object(v(0.6, 0.0, 0.0), v(-0.2, 0.0, 0.0), half, 20.0);
        assert_eq!(on, 1.0);
        assert!((off - (-20.0f32 * 0.5 * 0.16).exp()).abs() < 1e-6);
    }

    #[test]
    fn lift_carry_place_on_hand_built_states() {
        assert_eq!(lift(0.2, 0.2, 0.3), 0.0);
        assert!((lift(0.35, 0.2, 0.3) - 0.5).abs() < 1e-6);
        assert_eq!(lift(1.0, 0.2, 0.3), 1.0);
        assert_eq!(
            lift(0.1, 0.2, 0.3),
            0.0,
            "pushed into the floor is not lifting"
        );
        let goal = v(2.0, 0.0, 0.2);
        assert_eq!(
            carry(v(0.0, 0.0, 0.5), v(1.0, 0.0, 0.0), goal, 1.0, 0.3),
            1.0
        );
        assert!(
            (carry(v(0.0, 0.0, 0.5), Vector::ZERO, goal, 1.0, 0.3) - (-2.0f32).exp()).abs() < 1e-6
        );
        assert_eq!(carry(v(1.8, 0.0, 0.5), Vector::ZERO, goal, 1.0, 0.3), 1.0);
        assert_eq!(place(goal, goal, 10.0), 1.0);
        assert!((place(v(2.0, 0.3, 0.2), goal, 10.0) - (-0.9f32).exp()).abs() < 1e-6);
        assert_eq!(power_penalty(&[10.0, -5.0], &[2.0, 1.0]), -25.0);
    }

    #[test]
    fn release_and_retreat_follows_algorithm_1() {
        let p = ReleaseRetreat {
            alpha: 2.0,
            delta_r: 1.0,
            delta_h: 0.6,
            tau_object2goal: 0.2,
            beta: 0.7,
        };
        // Masked (lines 10-13): object not yet within tau of its goal, however far the retreat.
        assert_eq!(release_and_retreat(&p, 3.0, 3.0, 3.0, 0.2), 0.0);
        assert_eq!(release_and_retreat(&p, 3.0, 3.0, 3.0, 0.5), 0.0);
        // Unmasked, below both caps: uses the closer hand (line 1).
        let r = release_and_retreat(&p, 0.5, 0.3, 0.1, 0.05);
        let expect = 0.7 * (1.0 - (-1.0f32).exp()) + 0.3 * (1.0 - (-0.2f32).exp());
        assert!((r - expect).abs() < 1e-6, "{r} vs {expect}");
        // Root cap (lines 4-6) only.
        let r = release_and_retreat(&p, 1.01, 0.1, 0.1, 0.0);
        assert!((r - (0.7 + 0.3 * (1.0 - (-0.2f32).exp()))).abs() < 1e-6);
        // Hand cap (lines 7-9) only: both hands beyond delta_h.
        let r = release_and_retreat(&p, 0.5, 0.61, 0.7, 0.0);
        assert!((r - (0.7 * (1.0 - (-1.0f32).exp()) + 0.3)).abs() < 1e-6);
        // Both capped: the maximum, beta + (1 - beta) = 1.
        assert_eq!(release_and_retreat(&p, 2.0, 2.0, 2.0, 0.1), 1.0);
        // Exactly at a cap the exponential form still applies (strict >).
        let r = release_and_retreat(&p, 1.0, 2.0, 2.0, 0.1);
        assert!((r - (0.7 * (1.0 - (-2.0f32).exp()) + 0.3)).abs() < 1e-6);
    }
}
