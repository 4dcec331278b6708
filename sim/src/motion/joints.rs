//! The character's joint coordinates, as its servos take them (`character::ball_target`): a
//! 3-DoF joint is `Rx(a)·Ry(b)·Rz(c)` with each angle in its DoF's range, a hinge is an angle
//! about its axis. Converting rotations to and from them, and projecting a rotation onto what a
//! joint can reach.

use super::retarget::KinematicPose;
use crate::mjcf::{CharacterModel, JointKind};
use crate::obs::twist_angle;
use rapier3d::math::{Matrix, Rotation, Vector};
use std::f32::consts::TAU;

/// The part of `rel` (child relative to parent) that `body`'s joint can take, within its ranges.
pub fn project_onto_joint(model: &CharacterModel, body: usize, rel: Rotation) -> Rotation {
    match &model.bodies[body].joint {
        JointKind::Free | JointKind::Fixed => Rotation::IDENTITY,
        JointKind::Hinge { dof } => {
            let d = &model.dofs[*dof];
            let axis = Vector::from_array(d.axis.map(|a| a as f32));
            let angle = twist_angle(rel, axis).clamp(d.range[0] as f32, d.range[1] as f32);
            Rotation::from_axis_angle(axis, angle)
        }
        JointKind::Ball { dofs } => {
            let ranges = dofs.map(|d| model.dofs[d].range.map(|r| r as f32));
            clamp_ball(rel, ranges)
        }
    }
}

/// `r` as `Rx(a)·Ry(b)·Rz(c)` with each angle within its range: `r` itself if one of its two
/// angle triples is within the ranges (no round trip through angles near gimbal lock), else the
/// nearest such rotation found by a few projected Gauss-Newton steps from the clamped triple
/// nearer the ranges. (Clamping each angle alone can be far off near gimbal lock, where x and z
/// turn about nearly the same axis and only their sum matters.)
pub fn clamp_ball(r: Rotation, ranges: [[f32; 2]; 3]) -> Rotation {
    let best = nearest_angles(r, ranges);
    if range_excess(best, ranges) == 0.0 {
        return r;
    }
    let clamp = |q: [f32; 3]| std::array::from_fn(|k| q[k].clamp(ranges[k][0], ranges[k][1]));
    let mut q: [f32; 3] = clamp(best);
    let mut distance = compose(q).angle_between(r);
    for _ in 0..10 {
        let mut e = (r * compose(q).inverse()).normalize();
        if e.w < 0.0 {
            e = -e;
        }
        let error = e.to_scaled_axis().to_array().map(f64::from);
        // How each angle turns the joint, in the parent frame.
        let ra = Rotation::from_rotation_x(q[0]);
        let axes = [
            Vector::X,
            ra * Vector::Y,
            ra * Rotation::from_rotation_y(q[1]) * Vector::Z,
        ];
        let jacobian = axes.map(|a| a.to_array().map(f64::from).to_vec());
        let system = System {
            jacobian: &jacobian,
            error: &error,
            weight: &[0.0; 3],
            damping: 1e-4,
        };
        let at_bound: Vec<Option<f64>> = (0..3).map(|k| bound_side(q[k], ranges[k])).collect();
        let Some(delta) = system.step(&[0.0; 3], &at_bound) else {
            break;
        };
        let next = clamp(std::array::from_fn(|k| q[k] + delta[k] as f32));
        let d = compose(next).angle_between(r);
        if d >= distance - 1e-6 {
            break;
        }
        (q, distance) = (next, d);
    }
    compose(q)
}

fn compose([a, b, c]: [f32; 3]) -> Rotation {
    Rotation::from_rotation_x(a) * Rotation::from_rotation_y(b) * Rotation::from_rotation_z(c)
}

/// Per DoF of the model, its coordinate in `pose`: a 3-DoF joint's Euler angles (of the two
/// triples that compose its rotation, the one nearer the ranges), a hinge's twist angle.
pub fn joint_coordinates(model: &CharacterModel, pose: &KinematicPose) -> Vec<f32> {
    let mut q = vec![0.0; model.dofs.len()];
    for (b, body) in model.bodies.iter().enumerate() {
        let r = pose.local_rots[b];
        match &body.joint {
            JointKind::Ball { dofs } => {
                let ranges = dofs.map(|d| model.dofs[d].range.map(|x| x as f32));
                let angles = nearest_angles(r, ranges);
                for (d, a) in dofs.iter().zip(angles) {
                    q[*d] = a;
                }
            }
            JointKind::Hinge { dof } => {
                let axis = Vector::from_array(model.dofs[*dof].axis.map(|a| a as f32));
                q[*dof] = twist_angle(r, axis);
            }
            JointKind::Free | JointKind::Fixed => {}
        }
    }
    q
}

/// Body `b`'s joint rotation at coordinates `q` (identity for the root and welds).
pub fn local_rotation(model: &CharacterModel, b: usize, q: &[f32]) -> Rotation {
    match &model.bodies[b].joint {
        JointKind::Ball { dofs } => {
            Rotation::from_rotation_x(q[dofs[0]])
                * Rotation::from_rotation_y(q[dofs[1]])
                * Rotation::from_rotation_z(q[dofs[2]])
        }
        JointKind::Hinge { dof } => Rotation::from_axis_angle(
            Vector::from_array(model.dofs[*dof].axis.map(|a| a as f32)),
            q[*dof],
        ),
        JointKind::Free | JointKind::Fixed => Rotation::IDENTITY,
    }
}

/// Angles (a, b, c) with `r = Rx(a)·Ry(b)·Rz(c)`, b in [-π/2, π/2].
pub fn xyz_angles(r: Rotation) -> [f32; 3] {
    // Rx·Ry·Rz has first row (cb·cc, −cb·sc, sb) and last column (sb, −sa·cb, ca·cb).
    let m = Matrix::from_quat(r.normalize());
    let b = m.z_axis.x.clamp(-1.0, 1.0).asin();
    let a = (-m.z_axis.y).atan2(m.z_axis.z);
    let c = (-m.y_axis.x).atan2(m.x_axis.x);
    [a, b, c]
}

/// The other angle triple giving the same rotation: (a + π, π − b, c + π), wrapped to (−π, π].
pub fn alternative_angles([a, b, c]: [f32; 3]) -> [f32; 3] {
    use std::f32::consts::PI;
    let wrap = |x: f32| {
        if x > PI {
            x - 2.0 * PI
        } else if x <= -PI {
            x + 2.0 * PI
        } else {
            x
        }
    };
    [wrap(a + PI), wrap(PI - b), wrap(c + PI)]
}

/// The x-y-z angles of `r` (of the two triples that give it) nearer `ranges`.
pub fn angles_nearest_ranges(r: Rotation, ranges: [[f32; 2]; 3]) -> [f32; 3] {
    let principal = xyz_angles(r);
    let other = alternative_angles(principal);
    if range_excess(other, ranges) < range_excess(principal, ranges) {
        other
    } else {
        principal
    }
}

/// How far `angles` lie outside `ranges`, summed (0 within them).
pub fn range_excess(angles: [f32; 3], ranges: [[f32; 2]; 3]) -> f32 {
    angles
        .iter()
        .zip(&ranges)
        .map(|(x, [lo, hi])| (lo - x).max(x - hi).max(0.0))
        .sum()
}

/// Of the two Euler triples of `r`, the one nearer `ranges` (possibly outside them), each angle
/// taken as whichever of x, x ± 2π lies nearest its range (a range may end at ±π, where the
/// decomposition can return either sign).
pub fn nearest_angles(r: Rotation, ranges: [[f32; 2]; 3]) -> [f32; 3] {
    let into_ranges = |a: [f32; 3]| -> [f32; 3] {
        std::array::from_fn(|k| {
            let [lo, hi] = ranges[k];
            let excess = |x: f32| (lo - x).max(x - hi).max(0.0);
            [a[k], a[k] - TAU, a[k] + TAU]
                .into_iter()
                .min_by(|x, y| excess(*x).total_cmp(&excess(*y)))
                .unwrap_or(a[k])
        })
    };
    let first = into_ranges(xyz_angles(r));
    let second = into_ranges(alternative_angles(xyz_angles(r)));
    if range_excess(second, ranges) < range_excess(first, ranges) {
        second
    } else {
        first
    }
}

/// The way out of `range` if `value` sits at one of its ends (−1 low, +1 high).
pub(crate) fn bound_side(value: f32, [lo, hi]: [f32; 2]) -> Option<f64> {
    if value <= lo + 1e-6 {
        Some(-1.0)
    } else if value >= hi - 1e-6 {
        Some(1.0)
    } else {
        None
    }
}

/// A linearised least-squares problem over bounded variables: per variable its Jacobian column
/// and stiffness (pulling it back to where it started), the error to close, and the Levenberg
/// damping.
pub(crate) struct System<'a> {
    pub jacobian: &'a [Vec<f64>],
    pub error: &'a [f64],
    pub weight: &'a [f64],
    pub damping: f64,
}

impl System<'_> {
    /// The step Δ solving (JᵀJ + W + λI) Δ = Jᵀe − W·offset over the variables not held. One at
    /// a bound (`at_bound`: the sign of the way out) that the step would push out is held and
    /// the step solved again without it: clamping it afterwards would leave the others moving
    /// as if it had given way.
    pub fn step(&self, offset: &[f64], at_bound: &[Option<f64>]) -> Option<Vec<f64>> {
        let n = self.jacobian.len();
        let mut held = vec![false; n];
        loop {
            let free: Vec<usize> = (0..n).filter(|&k| !held[k]).collect();
            let a = free
                .iter()
                .map(|&i| {
                    free.iter()
                        .map(|&j| {
                            let diagonal = if i == j {
                                self.weight[i] + self.damping
                            } else {
                                0.0
                            };
                            dot(&self.jacobian[i], &self.jacobian[j]) + diagonal
                        })
                        .collect()
                })
                .collect();
            let b = free
                .iter()
                .map(|&i| dot(&self.jacobian[i], self.error) - self.weight[i] * offset[i])
                .collect();
            let mut delta = vec![0.0; n];
            for (k, x) in free.iter().zip(solve(a, b)?) {
                delta[*k] = x;
            }
            let pushing_out: Vec<usize> = free
                .into_iter()
                .filter(|&k| at_bound[k].is_some_and(|out| delta[k] * out > 0.0))
                .collect();
            if pushing_out.is_empty() {
                return Some(delta);
            }
            for k in pushing_out {
                held[k] = true;
            }
        }
    }
}

pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Solves `a x = b` by Gaussian elimination with partial pivoting; `None` if singular.
pub(crate) fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for col in 0..n {
        let pivot = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-12 {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        let (upper, lower) = a.split_at_mut(col + 1);
        let pivot_row = &upper[col];
        for (row, r) in lower.iter_mut().enumerate() {
            let f = r[col] / pivot_row[col];
            for (x, p) in r[col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * p;
            }
            b[col + 1 + row] -= f * b[col];
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let s: f64 = (row + 1..n).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn xyz_angles_recompose_the_rotation() {
        for (a, b, c) in [(0.3, -0.4, 1.1), (-2.5, 1.2, 0.2), (1.0, -1.5, -3.0)] {
            let r = Rotation::from_rotation_x(a)
                * Rotation::from_rotation_y(b)
                * Rotation::from_rotation_z(c);
            let [x, y, z] = xyz_angles(r);
            assert!((x - a).abs() < 1e-4 && (y - b).abs() < 1e-4 && (z - c).abs() < 1e-4);
            let [x, y, z] = alternative_angles([x, y, z]);
            let again = Rotation::from_rotation_x(x)
                * Rotation::from_rotation_y(y)
                * Rotation::from_rotation_z(z);
            assert!(again.angle_between(r) < 1e-4);
        }
    }
    #[test]
    fn coordinates_round_trip_through_rotations() {
        let m = CharacterModel::amp_humanoid();
        let mut pose = KinematicPose {
            root_pos: Vector::new(0.0, 0.0, 0.89),
            root_rot: Rotation::IDENTITY,
            local_rots: vec![Rotation::IDENTITY; m.bodies.len()],
        };
        let thigh = m.body_index("left_thigh").expect("thigh");
        let JointKind::Ball { dofs } = m.bodies[thigh].joint else {
            panic!("the hip is a ball joint");
        };
        // Hip flexed 110°: beyond the first triple's b range, so the second triple is the one.
        let mut q = vec![0.0; m.dofs.len()];
        q[dofs[0]] = 0.2;
        q[dofs[1]] = -1.9;
        q[dofs[2]] = 0.3;
        pose.local_rots[thigh] = local_rotation(&m, thigh, &q);
        let back = joint_coordinates(&m, &pose);
        for d in dofs {
            assert!((back[d] - q[d]).abs() < 1e-4, "{} vs {}", back[d], q[d]);
        }
    }

    #[test]
    fn ball_joints_are_clamped_to_their_ranges_only_when_out_of_them() {
        let ranges = [[-1.0, 1.0], [-0.5, 0.5], [-2.0, 2.0]];
        let inside = Rotation::from_rotation_x(0.9) * Rotation::from_rotation_z(-1.5);
        assert_eq!(clamp_ball(inside, ranges), inside);
        for out in [
            Rotation::from_rotation_x(1.6) * Rotation::from_rotation_y(-0.2),
            Rotation::from_rotation_x(3.0),
            compose([1.4, 0.45, -1.3]),
        ] {
            let clamped = clamp_ball(out, ranges);
            let angles = nearest_angles(clamped, ranges);
            assert!(range_excess(angles, ranges) < 1e-4, "{angles:?}");
            let naive = compose(std::array::from_fn(|k| {
                nearest_angles(out, ranges)[k].clamp(ranges[k][0], ranges[k][1])
            }));
            assert!(
                clamped.angle_between(out) <= naive.angle_between(out) + 1e-5,
                "no farther than clamping each angle"
            );
        }
        // Near gimbal lock (y ≈ 86°) x and z turn about nearly the same axis: x = 1.6 beyond its
        // range is made up by z, where clamping x alone would leave 0.6 rad of it out.
        let ranges = [[-1.0, 1.0], [-1.55, 1.55], [-1.0, 1.0]];
        let near_lock = compose([1.6, 1.5, 0.0]);
        let naive = compose([1.0, 1.5, 0.0]);
        assert!(naive.angle_between(near_lock) > 0.5);
        let clamped = clamp_ball(near_lock, ranges);
        assert!(
            clamped.angle_between(near_lock) < 0.1,
            "{}",
            clamped.angle_between(near_lock)
        );
    }
}
