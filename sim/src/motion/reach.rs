//! Reaching: moves the joints between the root and some bodies so that those bodies get to world
//! targets, staying near the pose it starts from. Levenberg-Marquardt in the character's own
//! joint coordinates ([`super::joints`]), each kept within its DoF's range, so the result is a
//! pose the servos can hold; optionally the root may pitch too, the legs keeping their world
//! rotations.
//!
//! The pull back toward the starting pose is measured as rotation (each joint's angle away from
//! where it started), not in Euler angles, which near gimbal lock call nearby rotations far apart
//! and far ones near. A sequence of frames is solved warm-started from the previous frame's
//! solution ([`Reacher::reach`]), so that where several arm postures reach a target equally well
//! (the elbow's swivel about the shoulder-to-hand line) consecutive frames keep the same one.
//!
//! Retargeting uses it where proportions differ: a subject with a longer torso and arms grasps a
//! box our character can only reach by bending further.

use super::joints::{bound_side, joint_coordinates, local_rotation, System};
use super::retarget::{forward_kinematics, KinematicPose};
use crate::mjcf::{CharacterModel, JointKind};
use rapier3d::math::{Rotation, Vector};

/// A body of the model and where its origin should be (world).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Goal {
    pub body: usize,
    pub target: Vector,
}

/// Lets reaching pitch the root about its own y axis (radians, forward positive, within
/// `range`), as bending at the hips does. The root's other children (the legs) are turned back
/// by as much, so they keep their world rotations; the AMP humanoid's hip joints lie on that
/// axis, so its feet do not move either. The hips are not clamped afterwards: a deeper hip
/// flexion often leaves the Euler box only because x and z stop meaning anything near 90° of
/// flexion, and clamping there would flip the legs between frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RootPitch {
    pub stiffness: f32,
    pub range: [f32; 2],
}

const ITERATIONS: usize = 60;
/// Finite-difference step for the Jacobian (radians).
const STEP: f32 = 1e-3;
/// Longest step of any variable in one iteration (radians): the linearisation holds only so far.
const MAX_STEP: f64 = 0.25;

/// Reaching for one character: how firmly each joint holds its starting rotation
/// (`stiffness[b]` per model body, per radian², against metres² of goal error: a stiff joint
/// moves only where the others cannot make up the distance) and whether the root may pitch.
#[derive(Clone, Debug)]
pub struct Reacher<'a> {
    pub model: &'a CharacterModel,
    pub stiffness: Vec<f32>,
    pub pitch: Option<RootPitch>,
}

/// A solved reach: the pose, and its variables to warm-start the next frame from.
#[derive(Clone, Debug)]
pub struct Reached {
    pub pose: KinematicPose,
    vars: Vec<f32>,
}

/// What reaching may change.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Var {
    Dof(usize),
    RootPitch,
}

/// The variables of one reach, their bounds, and the pose they start from.
struct Problem<'a> {
    model: &'a CharacterModel,
    base: &'a KinematicPose,
    goals: &'a [Goal],
    vars: Vec<Var>,
    bounds: Vec<[f32; 2]>,
    start: Vec<f32>,
    /// Bodies whose joints the variables move, with √stiffness: their regularising residuals.
    held: Vec<(usize, f64)>,
    pitch_weight: f64,
    /// Root children off the goals' chains: turned back when the root pitches.
    counter_pitched: Vec<usize>,
}

impl Reacher<'_> {
    /// `pose` with the joints above the goals' bodies moved (and the root pitched) so that each
    /// body's origin reaches its target, as near as the joint ranges allow. `warm`, the previous
    /// frame's solution for the same goal bodies, is where the search starts.
    pub fn reach(&self, pose: &KinematicPose, goals: &[Goal], warm: Option<&Reached>) -> Reached {
        let problem = Problem::new(self, pose, goals);
        let mut x = match warm {
            Some(w) if w.vars.len() == problem.vars.len() => w.vars.clone(),
            _ => problem.start.clone(),
        };
        let mut out = problem.pose(&x);
        if problem.vars.is_empty() {
            return Reached { pose: out, vars: x };
        }
        let mut now = problem.cost(&out, &x);
        // Levenberg-Marquardt: a step that does not lower the cost is retried shorter.
        let mut damping = 1e-3;
        for _ in 0..ITERATIONS {
            let (error, jacobian) = problem.linearise(&x);
            let system = System {
                jacobian: &jacobian,
                error: &error,
                weight: &vec![0.0; x.len()],
                damping,
            };
            let at_bound: Vec<Option<f64>> = x
                .iter()
                .zip(&problem.bounds)
                .map(|(v, b)| bound_side(*v, *b))
                .collect();
            let Some(mut delta) = system.step(&vec![0.0; x.len()], &at_bound) else {
                break;
            };
            let longest = delta.iter().map(|d| d.abs()).fold(0.0, f64::max);
            if longest > MAX_STEP {
                delta.iter_mut().for_each(|d| *d *= MAX_STEP / longest);
            }
            let next: Vec<f32> = x
                .iter()
                .zip(&delta)
                .zip(&problem.bounds)
                .map(|((v, d), [lo, hi])| (v + *d as f32).clamp(*lo, *hi))
                .collect();
            let candidate = problem.pose(&next);
            let after = problem.cost(&candidate, &next);
            if after < now {
                (out, x, now) = (candidate, next, after);
                damping = (damping / 3.0).max(1e-6);
                if longest < 1e-5 {
                    break;
                }
            } else {
                damping *= 4.0;
                if damping > 1e3 {
                    break;
                }
            }
        }
        Reached { pose: out, vars: x }
    }
}

impl<'a> Problem<'a> {
    fn new(reacher: &Reacher<'a>, base: &'a KinematicPose, goals: &'a [Goal]) -> Self {
        let model = reacher.model;
        let q = joint_coordinates(model, base);
        let mut p = Self {
            model,
            base,
            goals,
            vars: Vec::new(),
            bounds: Vec::new(),
            start: Vec::new(),
            held: Vec::new(),
            pitch_weight: 0.0,
            counter_pitched: Vec::new(),
        };
        let chains = chain_bodies(model, goals);
        for &b in &chains {
            let dofs: Vec<usize> = match &model.bodies[b].joint {
                JointKind::Ball { dofs } => dofs.to_vec(),
                JointKind::Hinge { dof } => vec![*dof],
                JointKind::Free | JointKind::Fixed => continue,
            };
            let stiffness = reacher.stiffness.get(b).copied().unwrap_or(0.0);
            p.held.push((b, f64::from(stiffness.max(0.0)).sqrt()));
            for d in dofs {
                p.vars.push(Var::Dof(d));
                p.bounds.push(model.dofs[d].range.map(|r| r as f32));
                p.start.push(q[d]);
            }
        }
        if let Some(pitch) = reacher.pitch.filter(|_| !p.vars.is_empty()) {
            p.vars.push(Var::RootPitch);
            p.bounds.push(pitch.range);
            p.start.push(0.0f32.clamp(pitch.range[0], pitch.range[1]));
            p.pitch_weight = f64::from(pitch.stiffness.max(0.0)).sqrt();
            p.counter_pitched = (1..model.bodies.len())
                .filter(|&b| model.bodies[b].parent == Some(0) && !chains.contains(&b))
                .collect();
        }
        p
    }

    /// The base pose with the variables at `x`.
    fn pose(&self, x: &[f32]) -> KinematicPose {
        let mut out = self.base.clone();
        let mut q = vec![0.0; self.model.dofs.len()];
        for (var, v) in self.vars.iter().zip(x) {
            match var {
                Var::Dof(d) => q[*d] = *v,
                Var::RootPitch => {
                    out.root_rot = (self.base.root_rot * Rotation::from_rotation_y(*v)).normalize();
                    for &c in &self.counter_pitched {
                        out.local_rots[c] =
                            (Rotation::from_rotation_y(-*v) * self.base.local_rots[c]).normalize();
                    }
                }
            }
        }
        for &(b, _) in &self.held {
            out.local_rots[b] = local_rotation(self.model, b, &q);
        }
        out
    }

    /// What the variables are fitted to: the goal bodies' positions, then per moved joint
    /// √stiffness × its rotation away from the base pose (rotation vector; a hinge's angle),
    /// then √stiffness × the root pitch. The targets are the goals' positions and zeros.
    fn outputs(&self, pose: &KinematicPose, x: &[f32]) -> Vec<f64> {
        let world = forward_kinematics(self.model, pose);
        let mut out: Vec<f64> = self
            .goals
            .iter()
            .flat_map(|g| world[g.body].0.to_array())
            .map(f64::from)
            .collect();
        for &(b, w) in &self.held {
            let mut d = (self.base.local_rots[b].inverse() * pose.local_rots[b]).normalize();
            if d.w < 0.0 {
                d = -d;
            }
            let v = d.to_scaled_axis();
            match self.model.bodies[b].joint {
                JointKind::Hinge { dof } => {
                    let axis = Vector::from_array(self.model.dofs[dof].axis.map(|a| a as f32));
                    out.push(w * f64::from(v.dot(axis)));
                }
                _ => out.extend(v.to_array().map(|c| w * f64::from(c))),
            }
        }
        if let Some(k) = self.vars.iter().position(|v| *v == Var::RootPitch) {
            out.push(self.pitch_weight * f64::from(x[k] - self.start[k]));
        }
        out
    }

    fn targets(&self, len: usize) -> Vec<f64> {
        let mut t: Vec<f64> = self
            .goals
            .iter()
            .flat_map(|g| g.target.to_array())
            .map(f64::from)
            .collect();
        t.resize(len, 0.0);
        t
    }

    fn cost(&self, pose: &KinematicPose, x: &[f32]) -> f64 {
        let f = self.outputs(pose, x);
        self.targets(f.len())
            .iter()
            .zip(&f)
            .map(|(t, v)| (t - v).powi(2))
            .sum()
    }

    /// The error (targets − outputs) and, per variable, its column of ∂outputs, by forward
    /// differences.
    fn linearise(&self, x: &[f32]) -> (Vec<f64>, Vec<Vec<f64>>) {
        let now = self.outputs(&self.pose(x), x);
        let error = self
            .targets(now.len())
            .iter()
            .zip(&now)
            .map(|(t, v)| t - v)
            .collect();
        let columns = (0..x.len())
            .map(|k| {
                let mut moved = x.to_vec();
                moved[k] += STEP;
                self.outputs(&self.pose(&moved), &moved)
                    .iter()
                    .zip(&now)
                    .map(|(a, b)| (a - b) / f64::from(STEP))
                    .collect()
            })
            .collect();
        (error, columns)
    }
}

/// Every body from the goals' bodies up to the root (excluded), in model order.
fn chain_bodies(model: &CharacterModel, goals: &[Goal]) -> Vec<usize> {
    let mut out = Vec::new();
    for g in goals {
        let mut body = Some(g.body).filter(|&b| b < model.bodies.len());
        while let Some(b) = body.filter(|&b| b != 0) {
            out.push(b);
            body = model.bodies[b].parent;
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::joints::joint_coordinates;
    use crate::obs::twist_angle;

    fn standing(model: &CharacterModel) -> KinematicPose {
        KinematicPose {
            root_pos: Vector::new(0.0, 0.0, 0.89),
            root_rot: Rotation::IDENTITY,
            local_rots: vec![Rotation::IDENTITY; model.bodies.len()],
        }
    }

    /// Reaches `target` with `hand` from `pose`, every joint soft but the torso (given
    /// stiffness), and checks the hand got within 1 cm.
    fn reach_with_hand(
        m: &CharacterModel,
        pose: &KinematicPose,
        hand: usize,
        target: Vector,
        torso: usize,
        torso_stiffness: f32,
    ) -> KinematicPose {
        let mut stiffness = vec![0.0002; m.bodies.len()];
        stiffness[torso] = torso_stiffness;
        let reacher = Reacher {
            model: m,
            stiffness,
            pitch: None,
        };
        let out = reacher
            .reach(pose, &[Goal { body: hand, target }], None)
            .pose;
        let world = forward_kinematics(m, &out);
        assert!(
            (world[hand].0 - target).length() < 0.01,
            "{:?}",
            world[hand].0
        );
        out
    }

    #[test]
    fn a_hand_reaches_a_point_in_front_by_moving_its_arm() {
        let m = CharacterModel::amp_humanoid();
        let hand = m.body_index("right_hand").expect("hand");
        let torso = m.body_index("torso").expect("torso");
        let target = Vector::new(0.35, -0.2, 1.1);
        let pose = standing(&m);
        let out = reach_with_hand(&m, &pose, hand, target, torso, 1.0);
        assert!(out.local_rots[torso].angle_between(Rotation::IDENTITY) < 0.05);
        let legs = m.body_index("right_thigh").expect("thigh");
        assert_eq!(out.local_rots[legs], Rotation::IDENTITY, "legs stay");
        let q = joint_coordinates(&m, &out);
        for (d, def) in m.dofs.iter().enumerate() {
            assert!(
                q[d] >= def.range[0] as f32 - 1e-4 && q[d] <= def.range[1] as f32 + 1e-4,
                "{} at {}",
                def.name,
                q[d]
            );
        }
    }

    #[test]
    fn out_of_arm_reach_the_torso_bends_further() {
        let m = CharacterModel::amp_humanoid();
        let hand = m.body_index("left_hand").expect("hand");
        let torso = m.body_index("torso").expect("torso");
        let shoulder = m.body_index("left_upper_arm").expect("arm");
        // Stooping a little with the arm forward, as retargeting hands it over; the target is
        // lower than the arm alone can get from that shoulder.
        let mut pose = standing(&m);
        pose.local_rots[torso] = Rotation::from_rotation_y(0.5);
        pose.local_rots[shoulder] = Rotation::from_rotation_y(-0.5);
        let target = Vector::new(0.45, 0.2, 0.75);
        let world = forward_kinematics(&m, &pose);
        assert!(
            (world[shoulder].0 - target).length() > 0.6,
            "out of arm's reach"
        );
        let out = reach_with_hand(&m, &pose, hand, target, torso, 0.002);
        let bend = twist_angle(out.local_rots[torso], Vector::Y);
        assert!(bend > 0.6, "the torso bends further: {bend}");
    }
}
