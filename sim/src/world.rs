//! A simulated world: floor, character, and (later) a benchmark room. Stepping, and exact
//! snapshot/restore by cloning every piece of rapier state.

use crate::character::{Character, ServoModel};
use crate::mjcf::{CharacterModel, JointKind};
use crate::motion::retarget::KinematicPose;
use crate::obs::BodyState;
use crate::room::{build_room, Room};
use lhm_scenes::{Catalogue, Task};
use rapier3d::prelude::*;

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    /// Policy rate.
    pub control_hz: f32,
    /// Physics rate: each control step advances `physics_hz / control_hz` physics steps.
    pub physics_hz: f32,
    /// Pipeline steps per control step; the rest of the physics steps are the solver's substeps
    /// (fewer, larger pipeline steps are cheaper: the multibody mass matrix is factorised once
    /// per pipeline step).
    pub pipeline_steps_per_control: usize,
    /// Contacts closer than this (metres) are handed to the solver before they touch
    /// (rapier's `normalized_prediction_distance`), so that limbs moving fast between two
    /// pipeline steps do not sink into the floor first.
    pub prediction_distance: f32,
    /// Height of the root at spawn, metres.
    pub spawn_height: f32,
    /// Contacts between the character's own links (parent-child pairs never collide).
    pub self_collisions: bool,
    /// Tests and debugging only: weld the root to the world where it spawns, so limbs can be
    /// exercised without balancing.
    pub pin_root: bool,
    /// How the PD servos act (see [`ServoModel`]).
    pub servo: ServoModel,
    /// rapier's PGS iterations inside each substep (`num_internal_pgs_iterations`).
    pub solver_iterations: usize,
    /// A training aid, off by default: a torque on the root that holds it upright (see
    /// [`UprightAssist`]).
    pub assist: UprightAssist,
}

/// A "virtual assistant" (Yu, Turk and Liu 2018, "Learning Symmetric and Low-Energy
/// Locomotion"; the "hand of god" of earlier curricula): an external PD torque on the root about
/// the horizontal axes that pulls its up axis back toward the vertical, and an upward PD force
/// that holds the root near a height (a hoist: it lifts, never pulls down), so a policy can
/// explore steps without every stumble ending in a fall; a curriculum lowers both to zero. Yaw
/// and horizontal travel are left free. All zero (the default) applies nothing.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UprightAssist {
    /// N·m per radian of tilt of the root's up axis from the vertical.
    pub stiffness: f32,
    /// N·m·s per rad/s of the root's horizontal angular velocity.
    pub damping: f32,
    /// N per metre the root is below `support_height`.
    pub support_stiffness: f32,
    /// N·s/m of the root's vertical velocity (the upward force is floored at zero).
    pub support_damping: f32,
    /// Root height the hoist holds, metres.
    pub support_height: f32,
    /// The curriculum, in training iterations (policy versions): full strength up to
    /// `fade_from`, then linearly down to nothing at `fade_to`. `fade_to` 0: no fade (the
    /// assist stays at full strength).
    pub fade_from: u64,
    pub fade_to: u64,
}

impl UprightAssist {
    pub fn is_active(&self) -> bool {
        self.stiffness != 0.0
            || self.damping != 0.0
            || self.support_stiffness != 0.0
            || self.support_damping != 0.0
    }

    /// The assist's strength at training iteration `iteration` (see `fade_from`), in [0, 1].
    pub fn strength_at(&self, iteration: u64) -> f32 {
        if self.fade_to == 0 || iteration <= self.fade_from {
            1.0
        } else if iteration >= self.fade_to {
            0.0
        } else {
            let span = (self.fade_to - self.fade_from) as f64;
            (1.0 - (iteration - self.fade_from) as f64 / span) as f32
        }
    }

    /// This assist with its gains scaled to its strength at training iteration `iteration`.
    pub fn at_iteration(&self, iteration: u64) -> Self {
        let k = self.strength_at(iteration);
        Self {
            stiffness: self.stiffness * k,
            damping: self.damping * k,
            support_stiffness: self.support_stiffness * k,
            support_damping: self.support_damping * k,
            ..self.clone()
        }
    }

    /// The hoist's force (world frame) on a root at `height` rising at `vz`.
    pub fn support(&self, height: f32, vz: f32) -> Vector {
        let up =
            self.support_stiffness * (self.support_height - height) - self.support_damping * vz;
        Vector::Z * up.max(0.0)
    }

    /// The torque (world frame) on a root at rotation `rot` turning at `angvel`.
    pub fn torque(&self, rot: Rotation, angvel: Vector) -> Vector {
        let up = rot * Vector::Z;
        // The axis that turns `up` onto +z, scaled by the angle between them.
        let axis = up.cross(Vector::Z);
        let sin = axis.length();
        let tilt = if sin > 1e-6 {
            axis * (sin.atan2(up.dot(Vector::Z)) / sin)
        } else if up.z < 0.0 {
            // Upside down: any horizontal axis will do.
            Vector::X * std::f32::consts::PI
        } else {
            Vector::ZERO
        };
        let horizontal_spin = angvel - Vector::Z * angvel.z;
        tilt * self.stiffness - horizontal_spin * self.damping
    }
}

impl Default for SimConfig {
    fn default() -> Self {
        // 120 Hz physics as 2 pipeline steps of 1/60 s with 2 substeps each (Isaac Gym's AMP
        // setting). Chosen by measurement (BENCHMARKS.md, "Choosing the step"): against a
        // 480 Hz reference it matches 4 pipeline steps of 1/120 s in the zero-action fall and in
        // the speed statistics of random-action episodes, at ~15 % more control steps/s; contacts
        // sink ~1 cm deeper at the 1st percentile. One 1/30 s step with 4 substeps is cheaper
        // still but produced 41 m/s bodies and 17 cm penetrations, and once NaN at a fall.
        Self {
            control_hz: 30.0,
            physics_hz: 120.0,
            pipeline_steps_per_control: 2,
            prediction_distance: 0.02,
            spawn_height: 0.89,
            self_collisions: true,
            pin_root: false,
            servo: ServoModel::ImplicitSpring,
            solver_iterations: 1,
            assist: UprightAssist::default(),
        }
    }
}

impl SimConfig {
    pub fn physics_steps_per_control(&self) -> usize {
        (self.physics_hz / self.control_hz).round().max(1.0) as usize
    }
}

/// Every piece of state a step reads or writes.
#[derive(Clone)]
pub struct PhysicsState {
    pub bodies: RigidBodySet,
    pub colliders: ColliderSet,
    pub impulse_joints: ImpulseJointSet,
    pub multibody_joints: MultibodyJointSet,
    pub islands: IslandManager,
    pub broad_phase: BroadPhaseBvh,
    pub narrow_phase: NarrowPhase,
    pub ccd: CCDSolver,
    pub soft_bodies: SoftBodySet,
}

pub struct World {
    pub config: SimConfig,
    pub params: IntegrationParameters,
    pub state: PhysicsState,
    pub character: Character,
    pub room: Room,
    /// The ground plane's collider (contacts with it are the feet's ground reaction).
    pub floor_collider: ColliderHandle,
    pipeline: PhysicsPipeline,
    gravity: Vector,
    pub control_steps: u64,
    /// Set when the physics produced a non-finite or exploding state; the world is not stepped
    /// any more and its data must not be used (the NaN/explosion guard).
    pub physics_invalid: bool,
    /// The upright assist's torque and force on the root, averaged over the last control step
    /// (zero without an assist).
    pub assist_torque: Vector,
    pub assist_force: Vector,
}

/// Speed no body of a sane simulation reaches (m/s); beyond it the state counts as exploded.
pub const EXPLOSION_SPEED: f32 = 50.0;

/// A copy of the world's state from which stepping continues exactly as it would have.
#[derive(Clone)]
pub struct Snapshot {
    state: PhysicsState,
    control_steps: u64,
    physics_invalid: bool,
}

impl World {
    /// The character alone on a floor, at the origin facing +x.
    pub fn new(model: &CharacterModel, config: SimConfig) -> Self {
        Self::build(model, config, None, Pose::IDENTITY)
    }

    /// The character at the task's start pose in the task's room.
    pub fn with_task(
        model: &CharacterModel,
        config: SimConfig,
        task: &Task,
        catalogue: &Catalogue,
    ) -> Self {
        let start = Pose::from_parts(
            Vector::new(task.start.pos[0] as f32, task.start.pos[1] as f32, 0.0),
            Rotation::from_rotation_z(task.start.yaw as f32),
        );
        Self::build(model, config, Some((task, catalogue)), start)
    }

    fn build(
        model: &CharacterModel,
        config: SimConfig,
        task: Option<(&Task, &Catalogue)>,
        start: Pose,
    ) -> Self {
        let mut state = PhysicsState {
            bodies: RigidBodySet::new(),
            colliders: ColliderSet::new(),
            impulse_joints: ImpulseJointSet::new(),
            multibody_joints: MultibodyJointSet::new(),
            islands: IslandManager::new(),
            broad_phase: BroadPhaseBvh::new(),
            narrow_phase: NarrowPhase::new(),
            ccd: CCDSolver::new(),
            soft_bodies: SoftBodySet::new(),
        };
        let floor = state.bodies.insert(RigidBodyBuilder::fixed().build());
        let floor_collider = state.colliders.insert_with_parent(
            ColliderBuilder::halfspace(rapier3d::na::Unit::new_unchecked(Vector::Z))
                .friction(1.0)
                .build(),
            floor,
            &mut state.bodies,
        );
        let room = task.map_or_else(Room::default, |(t, c)| {
            build_room(t, c, &mut state.bodies, &mut state.colliders)
        });
        let character = Character::spawn(
            model,
            Pose::from_parts(
                start.translation + Vector::new(0.0, 0.0, config.spawn_height),
                start.rotation,
            ),
            &mut state.bodies,
            &mut state.colliders,
            &mut state.multibody_joints,
            if config.self_collisions {
                InteractionGroups::all()
            } else {
                InteractionGroups::new(
                    Group::GROUP_1,
                    Group::ALL ^ Group::GROUP_1,
                    InteractionTestMode::And,
                )
            },
            config.servo,
        );
        if config.pin_root {
            let root = character.root();
            let pose = *state.bodies[root].position();
            let anchor = state
                .bodies
                .insert(RigidBodyBuilder::fixed().pose(pose).build());
            state.multibody_joints.insert(
                anchor,
                root,
                FixedJointBuilder::new().contacts_enabled(false).build(),
                true,
            );
        }
        let steps = config.pipeline_steps_per_control.max(1);
        let params = IntegrationParameters {
            dt: 1.0 / (config.control_hz * steps as f32),
            num_solver_iterations: (config.physics_steps_per_control() / steps).max(1),
            num_internal_pgs_iterations: config.solver_iterations.max(1),
            normalized_prediction_distance: config.prediction_distance,
            ..IntegrationParameters::default()
        };
        Self {
            config,
            params,
            state,
            character,
            room,
            floor_collider,
            pipeline: PhysicsPipeline::new(),
            gravity: Vector::new(0.0, 0.0, -9.81),
            control_steps: 0,
            physics_invalid: false,
            assist_torque: Vector::ZERO,
            assist_force: Vector::ZERO,
        }
    }

    /// One control step: PD targets from `action`, then the physics of one control period.
    /// Returns false (and stops stepping for good) once the state is non-finite or exploded.
    pub fn step(&mut self, action: &[f32]) -> bool {
        let targets = self.character.targets(action);
        self.step_targets(&targets)
    }

    /// One control step toward PD `targets` (radians, one per DoF, as [`Character::targets`]
    /// makes them), for callers that also need the targets themselves.
    pub fn step_targets(&mut self, targets: &[f32]) -> bool {
        if self.physics_invalid {
            return false;
        }
        self.assist_torque = Vector::ZERO;
        self.assist_force = Vector::ZERO;
        let pipeline_steps = self.config.pipeline_steps_per_control.max(1);
        for _ in 0..pipeline_steps {
            self.character
                .drive(targets, &mut self.state.multibody_joints);
            self.apply_assist(1.0 / pipeline_steps as f32);
            let s = &mut self.state;
            self.pipeline.step(
                self.gravity,
                &self.params,
                &mut s.islands,
                &mut s.broad_phase,
                &mut s.narrow_phase,
                &mut s.bodies,
                &mut s.colliders,
                &mut s.impulse_joints,
                &mut s.multibody_joints,
                &mut s.soft_bodies,
                &mut s.ccd,
                &(),
                &(),
            );
            // Checked after every pipeline step: rapier itself panics on the next step once a
            // joint coordinate is NaN.
            if !self.is_sane() {
                self.physics_invalid = true;
                return false;
            }
        }
        self.control_steps += 1;
        true
    }

    /// Sets the root's external torque and force to the upright assist's for the coming pipeline
    /// step, and adds `share` of them to the control step's means.
    fn apply_assist(&mut self, share: f32) {
        let root = &mut self.state.bodies[self.character.root()];
        if !self.config.assist.is_active() {
            // rapier keeps user forces until reset, and nothing but the assist sets them on the
            // root: an assist faded out must not leave its last push behind.
            if root.user_force() != Vector::ZERO || root.user_torque() != Vector::ZERO {
                root.reset_torques(false);
                root.reset_forces(false);
            }
            return;
        }
        let torque = self.config.assist.torque(*root.rotation(), root.angvel());
        let force = self
            .config
            .assist
            .support(root.translation().z, root.linvel().z);
        root.reset_torques(false);
        root.reset_forces(false);
        root.add_torque(torque, true);
        root.add_force(force, true);
        self.assist_torque += torque * share;
        self.assist_force += force * share;
    }

    /// Finite poses and velocities, no body faster than [`EXPLOSION_SPEED`], finite joints.
    fn is_sane(&self) -> bool {
        let bodies_ok = self.state.bodies.iter().all(|(_, b)| {
            b.position().is_finite()
                && b.linvel().is_finite()
                && b.angvel().is_finite()
                && b.linvel().length() < EXPLOSION_SPEED
        });
        bodies_ok
            && self.state.multibody_joints.multibodies().all(|mb| {
                mb.links()
                    .all(|l| l.joint().coords().iter().all(|c| c.is_finite()))
            })
    }

    /// World pose of model body `body` (a welded body's, from the rigid body carrying it).
    pub fn body_pose(&self, body: usize) -> Pose {
        let carrier = self.state.bodies[self.character.bodies[body]].position();
        let offset = self.character.offsets[body];
        Pose::from_parts(
            carrier.translation + carrier.rotation * offset,
            carrier.rotation,
        )
    }

    /// Linear velocity of model body `body`'s frame origin.
    pub fn body_linvel(&self, body: usize) -> Vector {
        self.body_state(body).linvel
    }

    /// Pose and velocities of model body `body`'s frame.
    pub fn body_state(&self, body: usize) -> crate::obs::BodyState {
        let b = &self.state.bodies[self.character.bodies[body]];
        let pose = self.body_pose(body);
        // A rigid body's own velocity is its centre of mass's; a welded body's is taken at its
        // origin (for the hands, a sphere about the origin, the same point as before merging).
        let linvel = if self.character.offsets[body] == Vector::ZERO {
            b.linvel()
        } else {
            b.velocity_at_point(pose.translation)
        };
        crate::obs::BodyState {
            pos: pose.translation,
            rot: pose.rotation,
            linvel,
            angvel: b.angvel(),
        }
    }

    /// Per model body, whether it pressed on a piece of furniture or a wall (a contact with a
    /// positive impulse in the last pipeline step). Model bodies welded to one rigid body share
    /// its contacts. Objects and the floor are not furniture.
    pub fn furniture_contacts(&self) -> Vec<bool> {
        let mut touching = vec![false; self.character.bodies.len()];
        let furniture = self.room.obstacles.iter().chain(self.room.walls.as_ref());
        for body in furniture.filter_map(|h| self.state.bodies.get(*h)) {
            for &c in body.colliders() {
                for pair in self.state.narrow_phase.contact_pairs_with(c) {
                    let pressed = pair
                        .manifolds()
                        .iter()
                        .any(|m| m.points.iter().any(|p| p.data.impulse > 0.0));
                    let other = if pair.collider1 == c {
                        pair.collider2
                    } else {
                        pair.collider1
                    };
                    let parent = self.state.colliders.get(other).and_then(|o| o.parent());
                    for (k, h) in self.character.bodies.iter().enumerate() {
                        touching[k] |= pressed && parent == Some(*h);
                    }
                }
            }
        }
        touching
    }

    pub fn root_height(&self) -> f32 {
        self.body_pose(0).translation.z
    }

    /// Whether every body's pose and velocity is finite (the NaN/explosion guard's first test).
    pub fn is_finite(&self) -> bool {
        self.character.bodies.iter().all(|h| {
            let b = &self.state.bodies[*h];
            b.position().is_finite() && b.linvel().is_finite() && b.angvel().is_finite()
        })
    }

    pub fn snapshot(&self) -> Snapshot {
        Snapshot {
            state: self.state.clone(),
            control_steps: self.control_steps,
            physics_invalid: self.physics_invalid,
        }
    }

    pub fn restore(&mut self, s: &Snapshot) {
        self.state = s.state.clone();
        self.control_steps = s.control_steps;
        self.physics_invalid = s.physics_invalid;
    }
}

impl World {
    /// Puts the character in `pose` (root pose and every joint's rotation relative to its
    /// parent) moving as `states` say (world-frame velocities per body, model order): a
    /// reference-state start. The multibody's joint coordinates and generalised velocities are
    /// set, so stepping continues from exactly this state. Only for a freshly built world (joint
    /// coordinates still 0); a joint rotation is projected onto the joint's degrees of freedom.
    pub fn set_character_state(&mut self, pose: &KinematicPose, states: &[BodyState]) {
        let model = &self.character.model;
        let root = self.character.root();
        let Some(any) = self.character.joints.iter().flatten().next().copied() else {
            return;
        };
        let n = match self.state.multibody_joints.get(any) {
            Some((mb, _)) => mb.ndofs(),
            None => return,
        };
        // Generalised coordinates (as displacements from the all-zero spawn) and velocities.
        let mut disp = vec![0.0f32; n];
        let mut vel = vec![0.0f32; n];
        if let Some(r) = states.first() {
            vel[..3].copy_from_slice(&[r.linvel.x, r.linvel.y, r.linvel.z]);
            vel[3..6].copy_from_slice(&[r.angvel.x, r.angvel.y, r.angvel.z]);
        }
        for (i, body) in model.bodies.iter().enumerate() {
            let (Some(p), Some(h)) = (body.parent, self.character.joints[i]) else {
                continue;
            };
            let Some(first) = self
                .state
                .multibody_joints
                .get(h)
                .and_then(|(mb, link)| mb.link(link).map(|l| l.assembly_id()))
            else {
                continue;
            };
            let (Some(parent), Some(child)) = (states.get(p), states.get(i)) else {
                continue;
            };
            let relvel = parent.rot.inverse() * (child.angvel - parent.angvel);
            let local = pose.local_rots[i];
            match &body.joint {
                JointKind::Hinge { dof } => {
                    let axis = Vector::from_array(model.dofs[*dof].axis.map(|a| a as f32));
                    disp[first] = crate::obs::twist_angle(local, axis);
                    vel[first] = relvel.dot(axis);
                }
                JointKind::Ball { .. } => {
                    let mut q = local.normalize();
                    if q.w < 0.0 {
                        q = -q;
                    }
                    let d = q.to_scaled_axis();
                    disp[first..first + 3].copy_from_slice(&[d.x, d.y, d.z]);
                    vel[first..first + 3].copy_from_slice(&[relvel.x, relvel.y, relvel.z]);
                }
                JointKind::Fixed | JointKind::Free => {}
            }
        }
        if let Some(rb) = self.state.bodies.get_mut(root) {
            rb.set_position(Pose::from_parts(pose.root_pos, pose.root_rot), true);
        }
        let s = &mut self.state;
        if let Some((mb, _)) = s.multibody_joints.get_mut(any) {
            mb.apply_displacements(&disp);
            mb.generalized_velocity_mut().copy_from_slice(&vel);
            mb.forward_kinematics(&s.bodies, true);
            mb.update_rigid_bodies(&mut s.bodies, true);
        }
        // The rigid bodies' own velocities, for observations read before the first step (the
        // step derives them from the generalised velocities again).
        for (i, h) in self.character.bodies.iter().enumerate() {
            if self.character.offsets[i] != Vector::ZERO {
                continue;
            }
            if let (Some(rb), Some(st)) = (s.bodies.get_mut(*h), states.get(i)) {
                rb.set_linvel(st.linvel, true);
                rb.set_angvel(st.angvel, true);
            }
        }
    }
}

impl World {
    /// Pose of the task's `i`-th movable object.
    pub fn object_pose(&self, i: usize) -> Option<Pose> {
        self.room
            .objects
            .get(i)
            .map(|h| *self.state.bodies[*h].position())
    }
}

impl World {
    /// Every character body's state, in model order.
    pub fn body_states(&self) -> Vec<crate::obs::BodyState> {
        (0..self.character.bodies.len())
            .map(|i| self.body_state(i))
            .collect()
    }
}

impl World {
    /// Places the character's bodies at `poses` (world, model order) without simulating: for
    /// kinematic playback of reference motion. Stepping afterwards starts from an inconsistent
    /// multibody state; rebuild the world to simulate again.
    pub fn set_kinematic_pose(&mut self, poses: &[(Vector, Rotation)]) {
        let carried = self.character.bodies.iter().zip(&self.character.offsets);
        for ((h, offset), (pos, rot)) in carried.zip(poses) {
            if *offset != Vector::ZERO {
                continue; // welded: placed with the body that carries it
            }
            if let Some(b) = self.state.bodies.get_mut(*h) {
                b.set_position(Pose::from_parts(*pos, *rot), false);
            }
        }
    }
}

impl World {
    /// Adds a box of half extents `half` that is only drawn, never simulated against: a
    /// kinematic body whose collider interacts with nothing (so stepping ignores it), listed in
    /// [`Room::props`] so the renderer paints it as an object. Move it with [`Self::set_prop_pose`].
    pub fn add_prop_box(&mut self, half: Vector, pose: Pose) -> RigidBodyHandle {
        let h = self.state.bodies.insert(
            RigidBodyBuilder::kinematic_position_based()
                .pose(pose)
                .build(),
        );
        self.state.colliders.insert_with_parent(
            ColliderBuilder::cuboid(half.x, half.y, half.z)
                .collision_groups(InteractionGroups::none())
                .solver_groups(InteractionGroups::none())
                .build(),
            h,
            &mut self.state.bodies,
        );
        self.room.props.push(h);
        h
    }

    /// Places a prop (see [`Self::add_prop_box`]); a handle that is not a body is ignored.
    pub fn set_prop_pose(&mut self, prop: RigidBodyHandle, pose: Pose) {
        if let Some(b) = self.state.bodies.get_mut(prop) {
            b.set_position(pose, false);
        }
    }
}
