//! The character in a rapier world: one reduced-coordinate multibody (multibody joints stayed
//! stable under PD control where impulse joints gained energy), PD servos as force-based joint
//! motors with torque limits, CCD off (on multibody links it pulled links off their joints).
//!
//! Actions are PD targets: target = offset + scale · a per DoF, clamped to the joint's range (see
//! `spawn` for the offsets and scales). A 3-DoF joint's target is the rotation Rx·Ry·Rz of its three targets; rapier's
//! own 3-DoF coordinates are integrated approximations, so the servo is driven by the exact error
//! rotation (target · current⁻¹, from the joint's rotation) added to those coordinates.

use crate::mjcf::{CharacterModel, GeomShape, JointKind};
use rapier3d::prelude::*;

/// Friction of the character's geoms (MuJoCo's default sliding friction).
const FRICTION: f32 = 1.0;

#[derive(Clone, Debug)]
pub struct Character {
    pub model: CharacterModel,
    /// Rigid body that carries each model body, in model order (a body welded to its parent
    /// is carried by the parent's rigid body).
    pub bodies: Vec<RigidBodyHandle>,
    /// Each model body's frame origin in its carrying rigid body's frame: zero unless welded.
    /// Body frames are never rotated relative to their parent, so an offset is a translation.
    pub offsets: Vec<Vector>,
    /// Multibody joint attaching each body to its parent (None for the root).
    pub joints: Vec<Option<MultibodyJointHandle>>,
    /// Per DoF: PD target for a zero action, and target change per unit action.
    pub action_offset: Vec<f32>,
    pub action_scale: Vec<f32>,
}

fn v3(a: [f64; 3]) -> Vector {
    Vector::new(a[0] as f32, a[1] as f32, a[2] as f32)
}

impl Character {
    /// Adds the character to the sets with its root at `root` (default pose: all joints at 0).
    pub fn spawn(
        model: &CharacterModel,
        root: Pose,
        bodies: &mut RigidBodySet,
        colliders: &mut ColliderSet,
        multibody_joints: &mut MultibodyJointSet,
        collision_groups: InteractionGroups,
    ) -> Self {
        let mut handles: Vec<RigidBodyHandle> = Vec::with_capacity(model.bodies.len());
        let mut world_pos: Vec<Vector> = Vec::with_capacity(model.bodies.len());
        let mut joints = Vec::with_capacity(model.bodies.len());
        let mut offsets: Vec<Vector> = Vec::with_capacity(model.bodies.len());
        for body in &model.bodies {
            // Body frames are never rotated relative to their parent (the loader refuses it), so
            // at spawn every body has the root's rotation.
            let local = v3(body.pos);
            let pos = match body.parent {
                None => root.translation,
                Some(p) => world_pos[p] + root.rotation * local,
            };
            world_pos.push(pos);
            // A body welded to its parent (no joint) is part of the parent's rigid body: its
            // geoms go on the parent's body and its pose is derived. Physically the same as a
            // fixed multibody link, but each link costs a share of every mass-matrix update,
            // the largest cost of a physics step (hands: +8-13 % control steps/s, measured).
            let welded_to = match body.joint {
                JointKind::Fixed => body.parent,
                _ => None,
            };
            // Where this body's frame sits in the rigid body that carries it.
            let shift = welded_to.map_or(Vector::ZERO, |p| offsets[p] + local);
            // The parent's frame in the rigid body that carries the parent: joint anchors.
            let anchor = body.parent.map_or(local, |p| offsets[p] + local);
            offsets.push(shift);
            if let Some(p) = welded_to {
                for g in &body.geoms {
                    colliders.insert_with_parent(
                        geom_collider(g, shift, collision_groups),
                        handles[p],
                        bodies,
                    );
                }
                joints.push(None);
                handles.push(handles[p]);
                continue;
            }
            let rb = RigidBodyBuilder::dynamic()
                .pose(Pose::from_parts(pos, root.rotation))
                .ccd_enabled(false)
                // A controlled character must never sleep: new servo targets do not wake it.
                .can_sleep(false)
                .build();
            let h = bodies.insert(rb);
            for g in &body.geoms {
                colliders.insert_with_parent(
                    geom_collider(g, Vector::ZERO, collision_groups),
                    h,
                    bodies,
                );
            }
            let joint = body.parent.and_then(|p| {
                let data: GenericJoint = match &body.joint {
                    JointKind::Hinge { dof } => {
                        let d = &model.dofs[*dof];
                        RevoluteJointBuilder::new(v3(d.axis))
                            .local_anchor1(anchor)
                            .local_anchor2(Vector::ZERO)
                            .contacts_enabled(false)
                            .limits([d.range[0] as f32, d.range[1] as f32])
                            .motor_model(MotorModel::ForceBased)
                            .motor_max_force(d.torque_limit as f32)
                            .build()
                            .into()
                    }
                    JointKind::Ball { dofs } => {
                        let mut b = SphericalJointBuilder::new()
                            .local_anchor1(anchor)
                            .local_anchor2(Vector::ZERO)
                            .contacts_enabled(false);
                        for (axis, dof) in [JointAxis::AngX, JointAxis::AngY, JointAxis::AngZ]
                            .into_iter()
                            .zip(dofs)
                        {
                            b = b
                                .motor_model(axis, MotorModel::ForceBased)
                                .motor_max_force(axis, model.dofs[*dof].torque_limit as f32);
                        }
                        b.build().into()
                    }
                    // Welded bodies were merged into their parent above.
                    JointKind::Fixed | JointKind::Free => return None,
                };
                multibody_joints.insert(handles[p], h, data, true)
            });
            joints.push(joint);
            handles.push(h);
        }
        // 3-DoF joints: zero action holds the neutral pose, ±1 reach the farther range end.
        // Hinges (elbows, knees) have their neutral pose at a range end, where a neutral offset
        // would waste half the action range; they map [-1, 1] onto their range, as IsaacGym's AMP
        // humanoid does.
        let mut action_offset = Vec::with_capacity(model.dofs.len());
        let mut action_scale = Vec::with_capacity(model.dofs.len());
        for d in &model.dofs {
            let hinge = matches!(model.bodies[d.body].joint, JointKind::Hinge { .. });
            let offset = if hinge {
                0.5 * (d.range[0] + d.range[1])
            } else {
                0f64.clamp(d.range[0], d.range[1])
            };
            action_offset.push(offset as f32);
            action_scale.push((d.range[1] - offset).max(offset - d.range[0]) as f32);
        }
        Self {
            model: model.clone(),
            bodies: handles,
            offsets,
            joints,
            action_offset,
            action_scale,
        }
    }

    /// PD targets (radians) for an action, within each joint's range. Missing or non-finite
    /// entries count as 0.
    pub fn targets(&self, action: &[f32]) -> Vec<f32> {
        self.model
            .dofs
            .iter()
            .enumerate()
            .map(|(i, d)| {
                let a = action
                    .get(i)
                    .copied()
                    .filter(|a| a.is_finite())
                    .unwrap_or(0.0);
                let t = self.action_offset[i] + self.action_scale[i] * a;
                t.clamp(d.range[0] as f32, d.range[1] as f32)
            })
            .collect()
    }

    /// Sets every servo toward `targets` (radians, one per DoF).
    pub fn drive(&self, targets: &[f32], multibody_joints: &mut MultibodyJointSet) {
        for (body, joint) in self.model.bodies.iter().zip(&self.joints) {
            let Some(handle) = joint else { continue };
            let Some((mb, link_id)) = multibody_joints.get_mut(*handle) else {
                continue;
            };
            let Some(link) = mb.link_mut(link_id) else {
                continue;
            };
            let joint = &mut link.joint;
            match &body.joint {
                JointKind::Hinge { dof } => {
                    let d = &self.model.dofs[*dof];
                    joint.data.set_motor_position(
                        JointAxis::AngX,
                        targets[*dof],
                        d.kp as f32,
                        d.kd as f32,
                    );
                }
                JointKind::Ball { dofs } => {
                    let target = ball_target(targets, dofs);
                    // rapier integrates a 3-DoF joint as joint_rot = exp(ω dt) · joint_rot, so the
                    // error rotation on the left, as a rotation vector, is in the coordinates'
                    // frame.
                    let error = (target * joint.joint_rot().inverse())
                        .normalize()
                        .to_scaled_axis();
                    let coords = joint.coords();
                    for (k, axis) in [JointAxis::AngX, JointAxis::AngY, JointAxis::AngZ]
                        .into_iter()
                        .enumerate()
                    {
                        let d = &self.model.dofs[dofs[k]];
                        joint.data.set_motor_position(
                            axis,
                            coords[3 + k] + error[k],
                            d.kp as f32,
                            d.kd as f32,
                        );
                    }
                }
                JointKind::Fixed | JointKind::Free => {}
            }
        }
    }

    pub fn root(&self) -> RigidBodyHandle {
        self.bodies[0]
    }
}

/// The collider of one geom, shifted by `shift` in its rigid body's frame.
fn geom_collider(g: &crate::mjcf::GeomDef, shift: Vector, groups: InteractionGroups) -> Collider {
    let builder = match &g.shape {
        GeomShape::Sphere { radius } => {
            ColliderBuilder::ball(*radius as f32).translation(shift + v3(g.pos))
        }
        GeomShape::Capsule { from, to, radius } => ColliderBuilder::capsule_from_endpoints(
            shift + v3(*from),
            shift + v3(*to),
            *radius as f32,
        ),
        GeomShape::Box { half } => {
            ColliderBuilder::cuboid(half[0] as f32, half[1] as f32, half[2] as f32)
                .translation(shift + v3(g.pos))
        }
    };
    builder
        .density(g.density as f32)
        .friction(FRICTION)
        .collision_groups(groups)
        .build()
}

/// The target rotation of a 3-DoF joint: its three hinge targets composed Rx·Ry·Rz, as MuJoCo
/// composes three hinges in one body.
pub fn ball_target(targets: &[f32], dofs: &[usize; 3]) -> Rotation {
    Rotation::from_rotation_x(targets[dofs[0]])
        * Rotation::from_rotation_y(targets[dofs[1]])
        * Rotation::from_rotation_z(targets[dofs[2]])
}
