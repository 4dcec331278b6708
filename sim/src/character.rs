//! The character in a rapier world: one reduced-coordinate multibody (multibody joints stayed
//! stable under PD control where impulse joints gained energy), PD servos with torque limits
//! ([`ServoModel`]), CCD off (on multibody links it pulled links off their joints).
//!
//! Actions are PD targets: target = offset + scale · a per DoF, clamped to the joint's range (see
//! `spawn` for the offsets and scales). A 3-DoF joint's target is the rotation Rx·Ry·Rz of its three targets; rapier's
//! own 3-DoF coordinates are integrated approximations, so the servo is driven by the exact error
//! rotation (target · current⁻¹, from the joint's rotation) added to those coordinates.

use crate::mjcf::{CharacterModel, GeomShape, JointKind};
use crate::motion::joints::{angles_nearest_ranges, range_excess};
use rapier3d::prelude::*;

/// A 3-DoF joint past one of its ranges is pulled back by an implicit spring of this many times
/// its servo's kp, damped by this many times its kd. MuJoCo limits each of the three hinges a
/// 3-DoF MJCF joint is made of; rapier's spherical multibody joint has no such limits (its
/// coordinates are integrated approximations), so they are enforced here on the x-y-z angles.
/// With ten times kp the worst joint of a collapsing body is 2.5° past its range on average
/// (MuJoCo's soft limits: 1.1°; with free ball joints: 94°; `lhm bench fidelity`, `collapse`);
/// implicit integration keeps the stiff spring stable.
const LIMIT_STIFFNESS_PER_KP: f32 = 10.0;
const LIMIT_DAMPING_PER_KD: f32 = 3.0;

/// How the PD servos act on the joints.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ServoModel {
    /// PD inside the multibody dynamics, as MuJoCo's `implicitfast` integrates a position
    /// actuator: kp as an implicit joint spring toward the target and kd as implicit joint
    /// damping, both scaled down together when kp·error − kd·velocity passes the torque limit.
    /// The servo is solved exactly with the joint's inertia, not as a constraint competing with
    /// contacts in a few solver iterations: with the feet on the floor
    /// the motor constraints left the servos far softer than kp (15-24° standing errors, a
    /// neutral pose that collapsed in 2 s; BENCHMARKS.md, "Physics fidelity"). The torque clamp
    /// is applied at the state at the start of each pipeline step.
    #[default]
    ImplicitSpring,
    /// rapier's force-based joint motors: velocity constraints with a force limit, solved
    /// together with the contacts (the model before the fidelity work; kept for comparison).
    MotorConstraint,
}

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
    /// Per DoF: stiffness and damping pulling a 3-DoF joint back within its range, fixed at spawn
    /// from the servo's gains (limits stay when the servos are switched off).
    pub limit_stiffness: Vec<f32>,
    pub limit_damping: Vec<f32>,
    pub servo: ServoModel,
}

/// Per-DoF armature and damping on the multibody (the servo's kd too, for implicit servos).
fn set_passive_dynamics(
    model: &CharacterModel,
    joints: &[Option<MultibodyJointHandle>],
    multibody_joints: &mut MultibodyJointSet,
    servo: ServoModel,
) {
    for (body, joint) in model.bodies.iter().zip(joints) {
        let dofs: &[usize] = match &body.joint {
            JointKind::Hinge { dof } => std::slice::from_ref(dof),
            JointKind::Ball { dofs } => dofs,
            JointKind::Fixed | JointKind::Free => continue,
        };
        let Some((mb, link_id)) = joint.and_then(|h| multibody_joints.get_mut(h)) else {
            continue;
        };
        let Some(first) = mb.link(link_id).map(|l| l.assembly_id()) else {
            continue;
        };
        for (k, dof) in dofs.iter().enumerate() {
            let d = &model.dofs[*dof];
            let servo_damping = match servo {
                ServoModel::ImplicitSpring => d.kd,
                ServoModel::MotorConstraint => 0.0,
            };
            mb.armature_mut()[first + k] = d.armature as f32;
            mb.damping_mut()[first + k] = (d.damping + servo_damping) as f32;
        }
    }
}

/// One implicit servo DoF at coordinate `q` moving at `qd`, `error` from its target: the spring's
/// rest point, stiffness and the servo's share of the joint damping. Unsaturated (|kp·error −
/// kd·qd| within `limit`), the spring pulls toward the target with kp and implicit damping kd:
/// MuJoCo's position actuator under `implicitfast`. Saturated, both are scaled down by the same
/// factor so the torque at the current state is the limit (MuJoCo clamps the force), still toward
/// the target itself. An earlier model kept kp and moved the rest point to where the spring
/// pulled with the limit: that rest point moved with the joint every step, and on a light DoF
/// (the upper arm's twist, the ankles) rapier's multibody integrator did not follow it — the
/// joint stalled far from its target (a 16° twist target held at 1.2°; `servo_replay_probe`).
fn implicit_servo(q: f32, error: f32, qd: f32, kp: f32, kd: f32, limit: f32) -> (f32, f32, f32) {
    let torque = kp * error - kd * qd;
    let scale = if torque.abs() <= limit {
        1.0
    } else {
        limit / torque.abs()
    };
    (q + error, scale * kp, scale * kd)
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
        servo: ServoModel,
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
        // Zero action holds the neutral pose (every joint at 0, within its range): a fresh policy
        // stands instead of crouching. ±1 reach the farther range end, so the whole range is
        // within the policy's action bound; hinges (elbows, knees) have their neutral pose at a
        // range end, so half of their action range clamps there.
        let mut action_offset = Vec::with_capacity(model.dofs.len());
        let mut action_scale = Vec::with_capacity(model.dofs.len());
        for d in &model.dofs {
            let offset = 0f64.clamp(d.range[0], d.range[1]);
            action_offset.push(offset as f32);
            action_scale.push((d.range[1] - offset).max(offset - d.range[0]) as f32);
        }
        set_passive_dynamics(model, &joints, multibody_joints, servo);
        Self {
            model: model.clone(),
            bodies: handles,
            offsets,
            joints,
            action_offset,
            action_scale,
            limit_stiffness: model
                .dofs
                .iter()
                .map(|d| LIMIT_STIFFNESS_PER_KP * d.kp as f32)
                .collect(),
            limit_damping: model
                .dofs
                .iter()
                .map(|d| LIMIT_DAMPING_PER_KD * d.kd as f32)
                .collect(),
            servo,
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
            let dofs: &[usize] = match &body.joint {
                JointKind::Hinge { dof } => std::slice::from_ref(dof),
                JointKind::Ball { dofs } => dofs,
                JointKind::Fixed | JointKind::Free => continue,
            };
            let Some(link) = mb.link(link_id) else {
                continue;
            };
            let first = link.assembly_id();
            let joint = &link.joint;
            let coords = joint.coords();
            // Per DoF: its coordinate and the error to its target, in the coordinates' frame.
            let mut errors = [0.0f32; 3];
            match &body.joint {
                JointKind::Ball { dofs } => {
                    // rapier integrates a 3-DoF joint as joint_rot = exp(ω dt) · joint_rot and its
                    // coordinates are integrated approximations, so the exact error rotation
                    // (on the left, as a rotation vector) is added to the coordinates.
                    let e = (ball_target(targets, dofs) * joint.joint_rot().inverse())
                        .normalize()
                        .to_scaled_axis();
                    errors = [e.x, e.y, e.z];
                }
                _ => errors[0] = targets[dofs[0]] - coords[3],
            }
            // Past a range (3-DoF joints; rapier limits hinges itself): the way back into it.
            let limit_error = match &body.joint {
                JointKind::Ball { dofs } => {
                    let ranges = dofs.map(|d| self.model.dofs[d].range.map(|r| r as f32));
                    ball_limit_error(joint.joint_rot(), ranges)
                }
                _ => None,
            };
            let mut velocities = [0.0f32; 3];
            for (v, out) in mb.joint_velocity(link).iter().zip(&mut velocities) {
                *out = *v;
            }
            let axes = [JointAxis::AngX, JointAxis::AngY, JointAxis::AngZ];
            for (k, dof) in dofs.iter().enumerate() {
                let d = &self.model.dofs[*dof];
                let (kp, kd, limit) = (d.kp as f32, d.kd as f32, d.torque_limit as f32);
                let q = coords[3 + k];
                match self.servo {
                    ServoModel::ImplicitSpring => {
                        let (mut rest, mut stiffness, mut damping) =
                            implicit_servo(q, errors[k], velocities[k], kp, kd, limit);
                        if let Some(e) = limit_error {
                            // Two springs on one coordinate are one spring of the summed
                            // stiffness with its rest at their stiffness-weighted mean.
                            let k_limit = self.limit_stiffness[*dof];
                            rest =
                                (stiffness * rest + k_limit * (q + e[k])) / (stiffness + k_limit);
                            stiffness += k_limit;
                            damping += self.limit_damping[*dof];
                        }
                        if let Some(link) = mb.link_mut(link_id) {
                            link.joint.set_spring(3 + k, stiffness, rest);
                        }
                        mb.damping_mut()[first + k] = d.damping as f32 + damping;
                    }
                    ServoModel::MotorConstraint => {
                        if let Some(link) = mb.link_mut(link_id) {
                            link.joint
                                .data
                                .set_motor_position(axes[k], q + errors[k], kp, kd);
                        }
                    }
                }
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
        .friction(g.friction as f32)
        .collision_groups(groups)
        .build()
}

/// How a 3-DoF joint at rotation `rot` gets back within its x-y-z angle `ranges` (radians): the
/// error rotation, as a rotation vector on the left like the servo's error, to the rotation whose
/// angles are clamped into their ranges; `None` when within them. Of the two angle triples that
/// give `rot`, the one nearer its ranges is read.
pub fn ball_limit_error(rot: Rotation, ranges: [[f32; 2]; 3]) -> Option<Vector> {
    let angles = angles_nearest_ranges(rot, ranges);
    if range_excess(angles, ranges) <= 0.0 {
        return None;
    }
    let c = std::array::from_fn::<f32, 3, _>(|k| angles[k].clamp(ranges[k][0], ranges[k][1]));
    let clamped = Rotation::from_rotation_x(c[0])
        * Rotation::from_rotation_y(c[1])
        * Rotation::from_rotation_z(c[2]);
    Some((clamped * rot.inverse()).normalize().to_scaled_axis())
}

/// The target rotation of a 3-DoF joint: its three hinge targets composed Rx·Ry·Rz, as MuJoCo
/// composes three hinges in one body.
pub fn ball_target(targets: &[f32], dofs: &[usize; 3]) -> Rotation {
    Rotation::from_rotation_x(targets[dofs[0]])
        * Rotation::from_rotation_y(targets[dofs[1]])
        * Rotation::from_rotation_z(targets[dofs[2]])
}
