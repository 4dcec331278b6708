//! Retargeting clips onto the character as kinematic poses (root pose + each body's rotation
//! relative to its parent), and forward kinematics to world poses.
//!
//! DeepMimic's humanoid matches ours joint for joint, but is Y up: a rotation of +90° about x
//! takes its frame to ours (x stays, y → z, z → -y), and every rotation, world or local, is
//! conjugated by it (both humanoids' body frames are aligned at rest).
//!
//! OMOMO's SMPL-H clips need a real retargeting (another skeleton, another rest pose): see
//! [`super::omomo_retarget`], re-exported here as [`omomo_poses`].

use super::deepmimic::{DeepMimicClip, DeepMimicFrame, JOINTS};
pub use super::omomo_retarget::omomo_poses;
use crate::mjcf::CharacterModel;
use crate::obs::BodyState;
use rapier3d::math::{Rotation, Vector};

/// A pose of the character without dynamics.
#[derive(Clone, Debug, PartialEq)]
pub struct KinematicPose {
    pub root_pos: Vector,
    pub root_rot: Rotation,
    /// Per model body: its rotation relative to its parent (identity for the root and welds).
    pub local_rots: Vec<Rotation>,
}

/// Every body's state in `pose`, held still: [`forward_kinematics`] with zero velocities.
pub fn resting_states(model: &CharacterModel, pose: &KinematicPose) -> Vec<BodyState> {
    forward_kinematics(model, pose)
        .into_iter()
        .map(|(pos, rot)| BodyState {
            pos,
            rot,
            linvel: Vector::ZERO,
            angvel: Vector::ZERO,
        })
        .collect()
}

/// World position and rotation of every body, in model order.
pub fn forward_kinematics(model: &CharacterModel, pose: &KinematicPose) -> Vec<(Vector, Rotation)> {
    let mut out: Vec<(Vector, Rotation)> = Vec::with_capacity(model.bodies.len());
    for (i, body) in model.bodies.iter().enumerate() {
        let world = match body.parent {
            None => (pose.root_pos, pose.root_rot),
            Some(p) => {
                let (ppos, prot) = out[p];
                let offset =
                    Vector::new(body.pos[0] as f32, body.pos[1] as f32, body.pos[2] as f32);
                (
                    ppos + prot * offset,
                    (prot * pose.local_rots[i]).normalize(),
                )
            }
        };
        out.push(world);
    }
    out
}

fn y_up_to_z_up() -> Rotation {
    Rotation::from_rotation_x(std::f32::consts::FRAC_PI_2)
}

fn quat_wxyz(q: [f32; 4]) -> Rotation {
    Rotation::from_xyzw(q[1], q[2], q[3], q[0]).normalize()
}

/// One DeepMimic frame as a pose of `model` (bodies DeepMimic does not drive stay unrotated).
pub fn deepmimic_pose(model: &CharacterModel, frame: &DeepMimicFrame) -> KinematicPose {
    let m = y_up_to_z_up();
    let convert = |r: Rotation| (m * r * m.inverse()).normalize();
    let p = frame.root_pos;
    let mut local_rots = vec![Rotation::IDENTITY; model.bodies.len()];
    for ((name, len), value) in JOINTS.iter().zip(&frame.joints) {
        let Some(body) = model.body_index(name) else {
            continue;
        };
        // Hinges turn about DeepMimic's z axis.
        let r = if *len == 4 {
            quat_wxyz(*value)
        } else {
            Rotation::from_rotation_z(value[0])
        };
        local_rots[body] = convert(r);
    }
    KinematicPose {
        root_pos: m * Vector::new(p[0], p[1], p[2]),
        root_rot: convert(quat_wxyz(frame.root_rot)),
        local_rots,
    }
}

/// Every frame of a DeepMimic clip as a pose of `model`.
pub fn deepmimic_poses(model: &CharacterModel, clip: &DeepMimicClip) -> Vec<KinematicPose> {
    clip.frames
        .iter()
        .map(|f| deepmimic_pose(model, f))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::obs::twist_angle;

    fn frame_with(knee: f32, root_y_up: [f32; 3]) -> DeepMimicFrame {
        let mut joints: Vec<[f32; 4]> = JOINTS
            .iter()
            .map(|(_, len)| {
                if *len == 4 {
                    [1.0, 0.0, 0.0, 0.0]
                } else {
                    [0.0; 4]
                }
            })
            .collect();
        joints[3] = [knee, 0.0, 0.0, 0.0]; // right knee
        DeepMimicFrame {
            duration: 1.0 / 30.0,
            root_pos: root_y_up,
            root_rot: [1.0, 0.0, 0.0, 0.0],
            joints,
        }
    }

    #[test]
    fn rest_pose_stands_upright_with_feet_below_the_pelvis() {
        let model = CharacterModel::amp_humanoid();
        let pose = deepmimic_pose(&model, &frame_with(0.0, [0.0, 0.89, 0.0]));
        let world = forward_kinematics(&model, &pose);
        assert!(
            (world[0].0 - Vector::new(0.0, 0.0, 0.89)).length() < 1e-6,
            "y up becomes z up"
        );
        let head = model.body_index("head").expect("head");
        let foot = model.body_index("right_foot").expect("foot");
        assert!(
            world[head].0.z > 1.3 && world[foot].0.z < 0.1,
            "head {:?} foot {:?}",
            world[head].0,
            world[foot].0
        );
    }

    #[test]
    fn a_bent_deepmimic_knee_is_a_bent_knee_here() {
        // DeepMimic knees flex with negative angles about its z; ours flex positive about y.
        let model = CharacterModel::amp_humanoid();
        let pose = deepmimic_pose(&model, &frame_with(-1.0, [0.0, 0.89, 0.0]));
        let shin = model.body_index("right_shin").expect("shin");
        assert!((twist_angle(pose.local_rots[shin], Vector::Y) - 1.0).abs() < 1e-5);
        let world = forward_kinematics(&model, &pose);
        let foot = model.body_index("right_foot").expect("foot");
        assert!(
            world[foot].0.x < -0.2,
            "the foot swings back: {:?}",
            world[foot].0
        );
    }
}
