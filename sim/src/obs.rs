//! Observations as pure functions over plain state, all in the character's heading frame (root
//! position on the floor, rotated by the root's yaw), so they do not change when the whole scene
//! is moved or turned about the vertical.
//!
//! The AMP feature layout is defined here, once: the discriminator (nets) only sees its width.

use crate::mjcf::{CharacterModel, JointKind};
use lhm_scenes::geometry::Rect;
use rapier3d::math::{Rotation, Vector};

/// One body's state in the world frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyState {
    pub pos: Vector,
    pub rot: Rotation,
    pub linvel: Vector,
    pub angvel: Vector,
}

/// The yaw-only frame of a root: origin under the root on the floor, x along its facing.
#[derive(Clone, Copy, Debug)]
pub struct HeadingFrame {
    origin: Vector,
    inv_yaw: Rotation,
}

/// The heading (radians about +z, 0 along +x) of a body whose forward axis is its local x.
pub fn heading_yaw(rot: Rotation) -> f32 {
    let forward = rot * Vector::X;
    forward.y.atan2(forward.x)
}

impl HeadingFrame {
    pub fn of(root: &BodyState) -> Self {
        let yaw = heading_yaw(root.rot);
        Self {
            origin: Vector::new(root.pos.x, root.pos.y, 0.0),
            inv_yaw: Rotation::from_rotation_z(-yaw),
        }
    }

    pub fn point(&self, p: Vector) -> Vector {
        self.inv_yaw * (p - self.origin)
    }

    pub fn vector(&self, v: Vector) -> Vector {
        self.inv_yaw * v
    }

    pub fn rotation(&self, r: Rotation) -> Rotation {
        self.inv_yaw * r
    }
}

/// A rotation as 6 numbers (its first and third columns: "tangent-normal"), continuous unlike
/// Euler angles or quaternions.
pub fn rot6(r: Rotation) -> [f32; 6] {
    let t = r * Vector::X;
    let n = r * Vector::Z;
    [t.x, t.y, t.z, n.x, n.y, n.z]
}

fn push3(out: &mut Vec<f32>, v: Vector) {
    out.extend_from_slice(&[v.x, v.y, v.z]);
}

/// Proprioception: root height, then per body its position relative to the root, 6-D rotation,
/// linear and angular velocity, all in the heading frame. 1 + 15 · 15 = 226 for the humanoid.
pub fn proprioception(bodies: &[BodyState]) -> Vec<f32> {
    let Some(root) = bodies.first() else {
        return Vec::new();
    };
    let h = HeadingFrame::of(root);
    let root_local = h.point(root.pos);
    let mut out = Vec::with_capacity(1 + bodies.len() * 15);
    out.push(root.pos.z);
    for b in bodies {
        push3(&mut out, h.point(b.pos) - root_local);
        out.extend_from_slice(&rot6(h.rotation(b.rot)));
        push3(&mut out, h.vector(b.linvel));
        push3(&mut out, h.vector(b.angvel));
    }
    out
}

pub fn proprioception_dim(model: &CharacterModel) -> usize {
    1 + model.bodies.len() * 15
}

/// The current object and its goal: position, 6-D rotation, linear and angular velocity, the 8
/// corners of its bounding box, and the goal position, in the heading frame (42 numbers).
pub fn task_observation(
    root: &BodyState,
    object: &BodyState,
    half_extents: Vector,
    goal: Vector,
) -> Vec<f32> {
    let h = HeadingFrame::of(root);
    let mut out = Vec::with_capacity(TASK_OBS_DIM);
    push3(&mut out, h.point(object.pos));
    out.extend_from_slice(&rot6(h.rotation(object.rot)));
    push3(&mut out, h.vector(object.linvel));
    push3(&mut out, h.vector(object.angvel));
    for i in 0..8 {
        let sign = |bit: usize| if i >> bit & 1 == 1 { 1.0 } else { -1.0 };
        let corner = Vector::new(
            sign(0) * half_extents.x,
            sign(1) * half_extents.y,
            sign(2) * half_extents.z,
        );
        push3(&mut out, h.point(object.pos + object.rot * corner));
    }
    push3(&mut out, h.point(goal));
    out
}

pub const TASK_OBS_DIM: usize = 3 + 6 + 3 + 3 + 24 + 3;

/// A square obstacle map around the character, aligned with its heading: `cells` × `cells` cells
/// of `cell` metres, centred on the root, each holding the height of the tallest obstacle
/// covering its centre (0 for free floor). Row-major, x (forward) outer.
pub fn obstacle_map(
    root: &BodyState,
    obstacles: &[(Rect, f32)],
    cells: usize,
    cell: f32,
) -> Vec<f32> {
    let (s, c) = heading_yaw(root.rot).sin_cos();
    let half = cells as f32 * cell / 2.0;
    let mut out = vec![0.0f32; cells * cells];
    for i in 0..cells {
        for j in 0..cells {
            // Cell centre in the heading frame, then in the world.
            let lx = -half + (i as f32 + 0.5) * cell;
            let ly = -half + (j as f32 + 0.5) * cell;
            let wx = root.pos.x + c * lx - s * ly;
            let wy = root.pos.y + s * lx + c * ly;
            let p = [f64::from(wx), f64::from(wy)];
            for (rect, height) in obstacles {
                if rect.contains_point(p, 0.0) {
                    out[i * cells + j] = out[i * cells + j].max(*height);
                }
            }
        }
    }
    out
}

/// Indices of the key bodies whose positions the AMP features include: hands and feet.
pub fn key_bodies(model: &CharacterModel) -> Vec<usize> {
    ["right_hand", "left_hand", "right_foot", "left_foot"]
        .iter()
        .filter_map(|n| model.body_index(n))
        .collect()
}

/// Width of one AMP frame: root height (1), root 6-D rotation (6), root linear and angular
/// velocity (3 + 3), joint rotations (6 per 3-DoF joint, 1 per hinge), joint velocities (one per
/// DoF), key body positions (3 each). 105 for the AMP humanoid.
pub fn amp_frame_dim(model: &CharacterModel) -> usize {
    let rotations: usize = model
        .bodies
        .iter()
        .map(|b| match b.joint {
            JointKind::Ball { .. } => 6,
            JointKind::Hinge { .. } => 1,
            JointKind::Free | JointKind::Fixed => 0,
        })
        .sum();
    1 + 6 + 3 + 3 + rotations + model.dofs.len() + 3 * key_bodies(model).len()
}

/// Angle of `r` about the unit `axis` (its twist), in (-π, π].
pub fn twist_angle(r: Rotation, axis: Vector) -> f32 {
    let v = Vector::new(r.x, r.y, r.z);
    let a = 2.0 * v.dot(axis).atan2(r.w);
    if a > std::f32::consts::PI {
        a - 2.0 * std::f32::consts::PI
    } else if a <= -std::f32::consts::PI {
        a + 2.0 * std::f32::consts::PI
    } else {
        a
    }
}

/// A joint's rotation and angular velocity, child relative to parent in the parent's frame, read
/// from body states (rapier's own 3-DoF joint coordinates are integrated approximations).
pub fn joint_state(parent: &BodyState, child: &BodyState) -> (Rotation, Vector) {
    let inv = parent.rot.inverse();
    (
        (inv * child.rot).normalize(),
        inv * (child.angvel - parent.angvel),
    )
}

/// One AMP frame. Joint rotations are read from body poses (parent⁻¹ · child): rapier's own 3-DoF
/// joint coordinates are integrated approximations.
pub fn amp_frame(model: &CharacterModel, bodies: &[BodyState]) -> Vec<f32> {
    let mut out = Vec::with_capacity(amp_frame_dim(model));
    let Some(root) = bodies.first() else {
        return out;
    };
    let h = HeadingFrame::of(root);
    out.push(root.pos.z);
    out.extend_from_slice(&rot6(h.rotation(root.rot)));
    push3(&mut out, h.vector(root.linvel));
    push3(&mut out, h.vector(root.angvel));
    let mut velocities = Vec::with_capacity(model.dofs.len());
    for (i, body) in model.bodies.iter().enumerate() {
        let Some(p) = body.parent else { continue };
        let (parent, child) = (&bodies[p], &bodies[i]);
        let (rel, relvel) = joint_state(parent, child);
        match &body.joint {
            JointKind::Ball { .. } => {
                out.extend_from_slice(&rot6(rel));
                velocities.extend_from_slice(&[relvel.x, relvel.y, relvel.z]);
            }
            JointKind::Hinge { dof } => {
                let axis = Vector::from_array(model.dofs[*dof].axis.map(|a| a as f32));
                out.push(twist_angle(rel, axis));
                velocities.push(relvel.dot(axis));
            }
            JointKind::Free | JointKind::Fixed => {}
        }
    }
    out.extend_from_slice(&velocities);
    let root_local = h.point(root.pos);
    for k in key_bodies(model) {
        push3(&mut out, h.point(bodies[k].pos) - root_local);
    }
    out
}

/// Body states whose velocities are backward differences of poses over `dt`: body origin
/// displacement / dt, and the rotation from `prev` to `now` as an angular velocity (world frame).
/// The one velocity definition both sides of the discriminator use (the environment's frames
/// and the demo clips'): rapier's instantaneous velocities against finite differences of mocap
/// differed by 1.5 σ RMS on the same motion, enough for a discriminator to tell them apart.
pub fn finite_difference_states(prev: &[BodyState], now: &[BodyState], dt: f32) -> Vec<BodyState> {
    now.iter()
        .zip(prev)
        .map(|(n, p)| {
            let mut d = (n.rot * p.rot.inverse()).normalize();
            if d.w < 0.0 {
                d = -d;
            }
            BodyState {
                pos: n.pos,
                rot: n.rot,
                linvel: (n.pos - p.pos) / dt,
                angvel: d.to_scaled_axis() / dt,
            }
        })
        .collect()
}

/// The discriminator's input: the last `frames` AMP frames, oldest first. Before enough frames
/// exist the first one is repeated (as after a reset).
#[derive(Clone, Debug, PartialEq)]
pub struct AmpHistory {
    frames: usize,
    dim: usize,
    buffer: Vec<Vec<f32>>,
}

impl AmpHistory {
    pub fn new(frames: usize, dim: usize) -> Self {
        Self {
            frames: frames.max(1),
            dim,
            buffer: Vec::new(),
        }
    }

    pub fn push(&mut self, frame: Vec<f32>) {
        debug_assert_eq!(frame.len(), self.dim);
        if self.buffer.is_empty() {
            self.buffer = vec![frame; self.frames];
        } else {
            self.buffer.remove(0);
            self.buffer.push(frame);
        }
    }

    /// Replaces the whole history with `frames` (oldest first; a start mid-motion has a past).
    /// Fewer frames than the window repeat the oldest, as after a reset.
    pub fn fill(&mut self, frames: Vec<Vec<f32>>) {
        self.buffer.clear();
        for f in frames
            .into_iter()
            .rev()
            .take(self.frames)
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
        {
            self.push(f);
        }
    }

    /// frames × dim numbers (zeros before the first push).
    pub fn features(&self) -> Vec<f32> {
        if self.buffer.is_empty() {
            return vec![0.0; self.frames * self.dim];
        }
        self.buffer.concat()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn body(pos: Vector, rot: Rotation) -> BodyState {
        BodyState {
            pos,
            rot,
            linvel: Vector::ZERO,
            angvel: Vector::ZERO,
        }
    }

    #[test]
    fn heading_frame_removes_position_and_yaw() {
        let root = body(
            Vector::new(2.0, 3.0, 0.9),
            Rotation::from_rotation_z(std::f32::consts::FRAC_PI_2),
        );
        let h = HeadingFrame::of(&root);
        // A point one metre in front of a character facing +y is at +x in its heading frame.
        let p = h.point(Vector::new(2.0, 4.0, 0.5));
        assert!((p - Vector::new(1.0, 0.0, 0.5)).length() < 1e-6, "{p:?}");
        // Pitch does not change the heading.
        let leaning = body(root.pos, root.rot * Rotation::from_rotation_y(0.4));
        let p2 = HeadingFrame::of(&leaning).point(Vector::new(2.0, 4.0, 0.5));
        assert!((p2 - p).length() < 1e-5);
    }

    #[test]
    fn twist_angle_reads_hinges() {
        for a in [-2.5f32, -0.3, 0.0, 1.0, 2.9] {
            let r = Rotation::from_rotation_y(a);
            assert!((twist_angle(r, Vector::Y) - a).abs() < 1e-5);
            assert!(twist_angle(r, Vector::X).abs() < 1e-6);
        }
    }

    #[test]
    fn amp_layout_is_105_for_the_humanoid_and_history_stacks_frames() {
        let m = CharacterModel::amp_humanoid();
        assert_eq!(amp_frame_dim(&m), 105);
        assert_eq!(proprioception_dim(&m), 226);
        let still: Vec<BodyState> = m
            .bodies
            .iter()
            .map(|_| body(Vector::new(0.0, 0.0, 0.9), Rotation::IDENTITY))
            .collect();
        let f = amp_frame(&m, &still);
        assert_eq!(f.len(), 105);
        assert_eq!(f[0], 0.9);
        let mut h = AmpHistory::new(3, 105);
        h.push(f.clone());
        assert_eq!(h.features(), [f.clone(), f.clone(), f.clone()].concat());
        let mut g = f.clone();
        g[0] = 0.5;
        h.push(g.clone());
        assert_eq!(h.features(), [f.clone(), f, g].concat());
    }

    #[test]
    fn task_observation_and_obstacle_map_on_hand_built_scenes() {
        let root = body(Vector::new(1.0, 0.0, 0.9), Rotation::IDENTITY);
        let object = body(Vector::new(2.0, 0.0, 0.2), Rotation::IDENTITY);
        let o = task_observation(
            &root,
            &object,
            Vector::new(0.2, 0.1, 0.2),
            Vector::new(1.0, 2.0, 0.0),
        );
        assert_eq!(o.len(), TASK_OBS_DIM);
        let close = |a: &[f32], b: [f32; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6);
        assert!(close(&o[..3], [1.0, 0.0, 0.2]));
        assert!(
            close(&o[15..18], [0.8, -0.1, 0.0]),
            "first corner (-x, -y, -z): {:?}",
            &o[15..18]
        );
        assert!(close(&o[39..42], [0.0, 2.0, 0.0]));
        // A 0.75 m table one metre ahead fills the cells in front, not those behind.
        let table = (Rect::new([2.0, 0.0], [0.5, 1.0], 0.0), 0.75);
        let map = obstacle_map(&root, &[table], 8, 0.5);
        let at = |x: f32, y: f32| {
            let i = ((x + 2.0) / 0.5) as usize;
            let j = ((y + 2.0) / 0.5) as usize;
            map[i * 8 + j]
        };
        assert_eq!(at(1.1, 0.1), 0.75);
        assert_eq!(at(-1.1, 0.1), 0.0);
        // Turning the character around puts the table behind it.
        let turned = body(root.pos, Rotation::from_rotation_z(std::f32::consts::PI));
        let map = obstacle_map(&turned, &[table], 8, 0.5);
        assert_eq!(map[((-1.1f32 + 2.0) / 0.5) as usize * 8 + 4], 0.75);
    }
}
