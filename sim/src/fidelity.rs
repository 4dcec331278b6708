//! Physics fidelity: the same scenarios `bench/mujoco_fidelity.py` runs in MuJoCo, measured here in
//! rapier with the same keys, so the two can be compared side by side (BENCHMARKS.md, "Physics
//! fidelity").
//!
//! The character spawns standing (pelvis at the spawn height, joints at 0, at rest) on a bare floor
//! and runs 30 Hz control for a few seconds under one of:
//! - `passive_drop`: servos off; how long it takes to fall;
//! - `neutral_hold`: every PD target 0 (the neutral pose); does it stand, do its feet stay put;
//! - `zero_action`: the policy's action 0 through the action mapping (must equal `neutral_hold`);
//! - `landing`: the neutral hold dropped from 10 cm higher; does the ground reaction bounce;
//! - `servo_step`: root pinned, the right knee's target steps to 70°; the servo alone;
//! - `collapse`: servos off through the fall and after: do the joints stay within their ranges.

use crate::mjcf::{CharacterModel, JointKind};
use crate::motion::joints::{angles_nearest_ranges, xyz_angles};
use crate::obs::{joint_state, twist_angle, BodyState};
use crate::task::terminations::fall_exempt;
use crate::world::{SimConfig, World};
use rapier3d::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// Times (s) at which root height and pelvis tilt are reported.
pub const REPORT_TIMES: [f32; 4] = [0.5, 1.0, 2.0, 5.0];
/// Measurements "while standing" start here, after the spawn transient.
pub const SETTLE_S: f32 = 0.5;
/// A fall: pelvis below this (m) ...
pub const FALL_ROOT_HEIGHT: f32 = 0.5;
/// ... or a body other than feet and hands below this (m), the environment's rule.
pub const FALL_BODY_HEIGHT: f32 = 0.15;
/// The servo-step scenario's knee target, degrees, and the times its error is reported at (s).
pub const SERVO_STEP_TARGET_DEG: f32 = 70.0;
pub const SERVO_STEP_TIMES: [f32; 4] = [0.03, 0.1, 0.2, 0.5];

/// What one standing scenario measured (keys as `bench/mujoco_fidelity.py` prints them).
#[derive(Clone, Debug, Serialize)]
pub struct ScenarioReport {
    /// First control step (1-based) that ends fallen; `None` if it never falls.
    pub fall_step: Option<u32>,
    /// Pelvis height at [`REPORT_TIMES`] within the scenario, keyed "0.5", "1", "2", "5".
    pub root_height_m: BTreeMap<String, f32>,
    /// Angle between the pelvis's z axis and the vertical, degrees, at the same times.
    pub pelvis_tilt_deg: BTreeMap<String, f32>,
    /// Largest |angle − target| over every actuated DoF from [`SETTLE_S`] until the fall or the
    /// end (3-DoF joints read as x-y-z angles, as the MJCF composes them); `None` without servos.
    pub max_tracking_error_deg: Option<f32>,
    pub tracking_error_deg_by_joint: BTreeMap<String, f32>,
    /// Largest horizontal distance a foot moved from [`SETTLE_S`] to the last standing step.
    pub foot_slide_m: Option<f32>,
    pub foot_slide_m_per_s: Option<f32>,
    /// Deepest contact penetration into the floor (m) from [`SETTLE_S`] until the fall or the
    /// end (the whole run for `landing`).
    pub max_penetration_m: f32,
    /// Total floor normal force (N) at the end of each control step while standing.
    pub contact_force_mean_n: f32,
    pub contact_force_std_n: f32,
    /// Total floor normal force at the end of each of the first 10 control steps.
    pub first_contact_forces_n: Vec<f32>,
    /// Smallest total floor force once both feet touch, up to 2 s or the fall (a bounce shows
    /// as a value far under the body weight).
    pub min_force_after_both_feet_down_n: Option<f32>,
    pub body_weight_n: f32,
    pub wall_s: f64,
}

/// The servo alone: right-knee tracking error (degrees) at [`SERVO_STEP_TIMES`].
#[derive(Clone, Debug, Serialize)]
pub struct ServoStepReport {
    pub knee_error_deg: BTreeMap<String, f32>,
    pub wall_s: f64,
}

/// How long the `collapse` scenario runs (s): the body is down on the floor well before.
pub const COLLAPSE_S: f32 = 3.0;

/// Servos off through the fall and after: how far (degrees) joints went past their ranges, read
/// at the end of each control step. Near gimbal lock (a 3-DoF joint's y angle near ±90°) its x and
/// z angles are ill-defined and single steps can read large; the mean over steps of the worst DoF
/// is the robust figure.
#[derive(Clone, Debug, Serialize)]
pub struct CollapseReport {
    pub mean_limit_excess_deg: f32,
    pub max_limit_excess_deg: f32,
    pub limit_excess_deg_by_joint: BTreeMap<String, f32>,
    pub wall_s: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct FidelityReport {
    pub settings: SimConfig,
    pub passive_drop: ScenarioReport,
    pub neutral_hold: ScenarioReport,
    pub zero_action: ScenarioReport,
    pub landing: ScenarioReport,
    pub servo_step: ServoStepReport,
    pub collapse: CollapseReport,
}

/// What drives the servos during a scenario.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Drive {
    /// Servos off.
    Passive,
    /// Every target 0.
    Neutral,
    /// The policy's zero action through [`crate::Character::targets`].
    ZeroAction,
}

fn time_key(t: f32) -> String {
    if t.fract() == 0.0 {
        format!("{t:.0}")
    } else {
        format!("{t}")
    }
}

/// Every actuated DoF's angle (radians, model order) from body states: hinges by their twist,
/// 3-DoF joints as the angle triple `ball` reads from the joint rotation and the joint's DoFs.
fn dof_angles(
    model: &CharacterModel,
    bodies: &[BodyState],
    ball: impl Fn(Rotation, &[usize; 3]) -> [f32; 3],
) -> Vec<f32> {
    let mut out = vec![0.0; model.dofs.len()];
    for (i, body) in model.bodies.iter().enumerate() {
        let Some(p) = body.parent else { continue };
        let (rel, _) = joint_state(&bodies[p], &bodies[i]);
        match &body.joint {
            JointKind::Hinge { dof } => {
                let axis = Vector::from_array(model.dofs[*dof].axis.map(|a| a as f32));
                out[*dof] = twist_angle(rel, axis);
            }
            JointKind::Ball { dofs } => {
                let a = ball(rel, dofs);
                for k in 0..3 {
                    out[dofs[k]] = a[k];
                }
            }
            JointKind::Free | JointKind::Fixed => {}
        }
    }
    out
}

/// Every actuated DoF's angle (radians, model order) from body states: hinges by their twist,
/// 3-DoF joints as the x-y-z angles whose Rx·Ry·Rz is the joint rotation.
pub fn joint_angles(model: &CharacterModel, bodies: &[BodyState]) -> Vec<f32> {
    dof_angles(model, bodies, |rel, _| xyz_angles(rel))
}

/// How far (radians, ≥ 0) each actuated DoF's angle lies outside its range, model order. A 3-DoF
/// joint is read as the x-y-z angle triple nearer its ranges (two triples give each rotation).
pub fn limit_excess(model: &CharacterModel, bodies: &[BodyState]) -> Vec<f32> {
    let range = |d: usize| model.dofs[d].range.map(|r| r as f32);
    dof_angles(model, bodies, |rel, dofs| {
        angles_nearest_ranges(rel, dofs.map(range))
    })
    .into_iter()
    .enumerate()
    .map(|(d, x)| {
        let [lo, hi] = range(d);
        (lo - x).max(x - hi).max(0.0)
    })
    .collect()
}

/// Total normal force (N) of the floor's contacts in the last pipeline step, whether each foot
/// touches, and the deepest penetration (m, ≥ 0).
fn floor_contacts(world: &World, feet: [usize; 2]) -> (f32, [bool; 2], f32) {
    let foot_bodies = feet.map(|f| world.character.bodies[f]);
    let (mut force, mut touching, mut depth) = (0.0f32, [false; 2], 0.0f32);
    let inv_dt = 1.0 / world.params.dt;
    for pair in world
        .state
        .narrow_phase
        .contact_pairs_with(world.floor_collider)
    {
        let other = if pair.collider1 == world.floor_collider {
            pair.collider2
        } else {
            pair.collider1
        };
        let parent = world.state.colliders.get(other).and_then(|c| c.parent());
        for m in pair.manifolds() {
            for p in &m.points {
                if p.dist < 0.0 {
                    depth = depth.max(-p.dist);
                }
                if p.data.impulse > 0.0 {
                    force += p.data.impulse * inv_dt;
                    for (k, fb) in foot_bodies.iter().enumerate() {
                        if parent == Some(*fb) {
                            touching[k] = true;
                        }
                    }
                }
            }
        }
    }
    (force, touching, depth)
}

fn pelvis_tilt_deg(root: &BodyState) -> f32 {
    (root.rot * Vector::Z)
        .dot(Vector::Z)
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// Runs one standing scenario for `seconds`, spawned `lift` metres above the spawn height.
pub fn run_scenario(
    model: &CharacterModel,
    sim: &SimConfig,
    drive: Drive,
    seconds: f32,
    lift: f32,
    penetration_from_start: bool,
) -> ScenarioReport {
    let started = Instant::now();
    let config = SimConfig {
        spawn_height: sim.spawn_height + lift,
        pin_root: false,
        ..sim.clone()
    };
    let mut world = World::new(model, config);
    let dt = 1.0 / sim.control_hz;
    let steps = (seconds / dt).round() as u32;
    let settle = (SETTLE_S / dt).round() as u32;
    let exempt = fall_exempt(model);
    let feet = [
        model.body_index("left_foot").unwrap_or(0),
        model.body_index("right_foot").unwrap_or(0),
    ];
    let names: Vec<&str> = model.dofs.iter().map(|d| d.name.as_str()).collect();
    let targets = match drive {
        Drive::Passive | Drive::Neutral => vec![0.0; model.dofs.len()],
        Drive::ZeroAction => world.character.targets(&vec![0.0; model.dofs.len()]),
    };
    if drive == Drive::Passive {
        servos_off(&mut world);
    }
    let mut report = ScenarioReport {
        fall_step: None,
        root_height_m: BTreeMap::new(),
        pelvis_tilt_deg: BTreeMap::new(),
        max_tracking_error_deg: (drive != Drive::Passive).then_some(0.0),
        tracking_error_deg_by_joint: BTreeMap::new(),
        foot_slide_m: None,
        foot_slide_m_per_s: None,
        max_penetration_m: 0.0,
        contact_force_mean_n: 0.0,
        contact_force_std_n: 0.0,
        first_contact_forces_n: Vec::new(),
        min_force_after_both_feet_down_n: None,
        body_weight_n: (model.total_mass() * 9.81) as f32,
        wall_s: 0.0,
    };
    let mut feet_at_settle: Option<[Vector; 2]> = None;
    let mut last_feet = [Vector::ZERO; 2];
    let mut last_standing_step = 0u32;
    let mut forces = Vec::new();
    let mut both_down = false;
    for k in 1..=steps {
        if !world.step_targets(&targets) {
            report.fall_step = Some(k);
            break;
        }
        let bodies = world.body_states();
        let t = k as f32 * dt;
        let (force, touching, depth) = floor_contacts(&world, feet);
        if report.first_contact_forces_n.len() < 10 {
            report.first_contact_forces_n.push(force);
        }
        if both_down && t <= 2.0 + 1e-4 {
            let m = report.min_force_after_both_feet_down_n.get_or_insert(force);
            *m = m.min(force);
        }
        both_down |= touching[0] && touching[1];
        for rt in REPORT_TIMES {
            if (t - rt).abs() < 0.5 * dt {
                report.root_height_m.insert(time_key(rt), bodies[0].pos.z);
                report
                    .pelvis_tilt_deg
                    .insert(time_key(rt), pelvis_tilt_deg(&bodies[0]));
            }
        }
        let fell = bodies[0].pos.z < FALL_ROOT_HEIGHT
            || bodies
                .iter()
                .zip(&exempt)
                .any(|(b, skip)| !skip && b.pos.z < FALL_BODY_HEIGHT);
        if fell {
            report.fall_step = Some(k);
            break;
        }
        last_standing_step = k;
        if penetration_from_start || k > settle {
            report.max_penetration_m = report.max_penetration_m.max(depth);
        }
        let feet_now = feet.map(|f| bodies[f].pos);
        if k == settle {
            feet_at_settle = Some(feet_now);
        }
        last_feet = feet_now;
        if k >= settle {
            forces.push(force);
            if drive != Drive::Passive {
                let angles = joint_angles(model, &bodies);
                let mut worst = 0.0f32;
                for (d, name) in names.iter().enumerate() {
                    let v = (angles[d] - targets[d]).abs().to_degrees();
                    let slot = report
                        .tracking_error_deg_by_joint
                        .entry((*name).to_string())
                        .or_insert(0.0);
                    *slot = slot.max(v);
                    worst = worst.max(v);
                }
                if let Some(m) = report.max_tracking_error_deg.as_mut() {
                    *m = m.max(worst);
                }
            }
        }
    }
    if let Some(start) = feet_at_settle {
        let flat = |v: Vector| Vector::new(v.x, v.y, 0.0);
        let slide = start
            .iter()
            .zip(&last_feet)
            .map(|(a, b)| flat(*b - *a).length())
            .fold(0.0f32, f32::max);
        report.foot_slide_m = Some(slide);
        let elapsed = (last_standing_step.saturating_sub(settle)) as f32 * dt;
        report.foot_slide_m_per_s = Some(if elapsed > 0.0 { slide / elapsed } else { 0.0 });
    }
    if !forces.is_empty() {
        let n = forces.len() as f32;
        let mean = forces.iter().sum::<f32>() / n;
        let var = forces.iter().map(|f| (f - mean).powi(2)).sum::<f32>() / n;
        report.contact_force_mean_n = mean;
        report.contact_force_std_n = var.sqrt();
    }
    report.wall_s = started.elapsed().as_secs_f64();
    report
}

/// Removes the servo damping [`crate::character`] put on the multibody (passive drop).
/// Servos off: no spring, no motor, no servo damping (armature and range limits stay).
fn servos_off(world: &mut World) {
    world.character.model.dofs.iter_mut().for_each(|d| {
        d.kp = 1e-9;
        d.kd = 0.0;
        d.torque_limit = 0.0;
    });
    zero_servo_damping(world);
}

/// Servos off for [`COLLAPSE_S`], on through the fall: the range limits alone hold the joints.
pub fn run_collapse(model: &CharacterModel, sim: &SimConfig) -> CollapseReport {
    let started = Instant::now();
    let config = SimConfig {
        pin_root: false,
        ..sim.clone()
    };
    let mut world = World::new(model, config);
    servos_off(&mut world);
    let targets = vec![0.0; model.dofs.len()];
    let steps = (COLLAPSE_S * sim.control_hz).round() as u32;
    let mut by_joint: BTreeMap<String, f32> = BTreeMap::new();
    let mut sum_worst = 0.0f32;
    for _ in 0..steps {
        world.step_targets(&targets);
        let excess = limit_excess(model, &world.body_states());
        sum_worst += excess.iter().copied().fold(0.0, f32::max).to_degrees();
        for (d, e) in model.dofs.iter().zip(excess) {
            let slot = by_joint.entry(d.name.clone()).or_insert(0.0);
            *slot = slot.max(e.to_degrees());
        }
    }
    CollapseReport {
        mean_limit_excess_deg: sum_worst / steps.max(1) as f32,
        max_limit_excess_deg: by_joint.values().copied().fold(0.0, f32::max),
        limit_excess_deg_by_joint: by_joint,
        wall_s: started.elapsed().as_secs_f64(),
    }
}

fn zero_servo_damping(world: &mut World) {
    // Every link is in the one multibody: any joint's handle reaches it.
    if let Some(h) = world.character.joints.iter().flatten().next().copied() {
        if let Some((mb, _)) = world.state.multibody_joints.get_mut(h) {
            mb.damping_mut().fill(0.0);
        }
    }
}

/// The servo alone: root pinned, every target 0 but the right knee's, which steps to
/// [`SERVO_STEP_TARGET_DEG`] at t = 0.
pub fn run_servo_step(model: &CharacterModel, sim: &SimConfig) -> ServoStepReport {
    let started = Instant::now();
    let config = SimConfig {
        pin_root: true,
        ..sim.clone()
    };
    let mut world = World::new(model, config);
    let knee = model
        .dofs
        .iter()
        .position(|d| d.name == "right_knee")
        .unwrap_or(0);
    let mut targets = vec![0.0; model.dofs.len()];
    targets[knee] = SERVO_STEP_TARGET_DEG.to_radians();
    let dt = 1.0 / sim.control_hz;
    let last = SERVO_STEP_TIMES[SERVO_STEP_TIMES.len() - 1];
    let mut out = BTreeMap::new();
    for k in 1..=((last / dt).round() as u32) {
        world.step_targets(&targets);
        let t = k as f32 * dt;
        for st in SERVO_STEP_TIMES {
            // The control step nearest each time (0.03 s is the first: 1/30 s).
            if (t - st).abs() <= 0.5 * dt && !out.contains_key(&time_key(st)) {
                let angles = joint_angles(model, &world.body_states());
                out.insert(time_key(st), (targets[knee] - angles[knee]).to_degrees());
            }
        }
    }
    ServoStepReport {
        knee_error_deg: out,
        wall_s: started.elapsed().as_secs_f64(),
    }
}

/// Every scenario at `sim`'s settings.
pub fn run_fidelity(model: &CharacterModel, sim: &SimConfig) -> FidelityReport {
    FidelityReport {
        settings: sim.clone(),
        passive_drop: run_scenario(model, sim, Drive::Passive, 5.0, 0.0, false),
        neutral_hold: run_scenario(model, sim, Drive::Neutral, 5.0, 0.0, false),
        zero_action: run_scenario(model, sim, Drive::ZeroAction, 5.0, 0.0, false),
        landing: run_scenario(model, sim, Drive::Neutral, 2.0, 0.10, true),
        servo_step: run_servo_step(model, sim),
        collapse: run_collapse(model, sim),
    }
}
