//! A reference gait with balance feedback: the base a residual policy acts on (`[env.gait]`).
//!
//! Open-loop tracking of a looped walk (the clip's joint angles as PD targets) falls within ~1 s
//! (RESULTS.md, fourth session), and eleven sessions of PPO + AMP from a standing character never
//! found a step. Character-animation controllers keep such a reference up with a few feedback
//! terms on top of it — SIMBICON (Yin, Loken, van de Panne 2007), data-driven biped control (Lee,
//! Kim, Lee 2010): the swing hip places the foot by the centre of mass's position and velocity
//! error, the stance hip holds the pelvis's tilt, the stance ankle brakes. DReCon (Bergamin et
//! al. 2019) lets a policy learn a residual on a kinematic reference instead of the whole action.
//! This module is that base: [`BalanceGains`] (found by an evolution strategy on the simulator,
//! `cargo run --release -p lhm-sim --example gait_probe`), the reference cycle sampled at the
//! control rate ([`GaitReference`]), and [`base_targets`], a pure function of the character's and
//! the reference's body states.

use crate::fidelity::joint_angles;
use crate::mjcf::CharacterModel;
use crate::motion::demo::{AmpWindow, DemoMotion};
use crate::motion::retarget::KinematicPose;
use crate::obs::{heading_yaw, BodyState, HeadingFrame};
use rapier3d::math::{Rotation, Vector};
use serde::{Deserialize, Serialize};

/// Feedback gains on top of the reference's joint angles (radians per unit of error: m, m/s,
/// rad, rad/s). "Swing" and "stance" are the reference's: its lower foot is the stance foot.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BalanceGains {
    /// Swing hip pitch from the centre of mass's forward offset over the stance foot and its
    /// forward velocity, both against the reference's.
    pub swing_d_fwd: f32,
    pub swing_v_fwd: f32,
    /// Swing hip roll from the lateral offset and velocity.
    pub swing_d_lat: f32,
    pub swing_v_lat: f32,
    /// Stance hip pitch and roll from the pelvis's tilt error and tilt rate error.
    pub stance_pitch: f32,
    pub stance_roll: f32,
    pub stance_pitch_rate: f32,
    pub stance_roll_rate: f32,
    /// Stance ankle pitch from the forward velocity error and the pelvis pitch error; stance
    /// ankle roll from the lateral velocity error.
    pub ankle_v_fwd: f32,
    pub ankle_pitch: f32,
    pub ankle_v_lat: f32,
    /// Swing hip pitch and roll from the pelvis's tilt error (the swing thigh held in the world).
    pub swing_tilt: f32,
    /// Abdomen pitch and roll from the torso's tilt error.
    pub abdomen_pitch: f32,
    pub abdomen_roll: f32,
    /// Constant offsets: swing knee, stance knee, swing hip pitch (clearance and sag).
    pub swing_knee_bias: f32,
    pub stance_knee_bias: f32,
    pub swing_hip_bias: f32,
}

impl Default for BalanceGains {
    /// The gait probe's best gains on the 8-phase objective (RESULTS.md, twelfth session).
    fn default() -> Self {
        Self {
            swing_d_fwd: -0.189,
            swing_v_fwd: -0.179,
            swing_d_lat: -0.0731,
            swing_v_lat: 0.275,
            stance_pitch: 4.11,
            stance_roll: 0.0793,
            stance_pitch_rate: 0.246,
            stance_roll_rate: 0.408,
            ankle_v_fwd: -0.273,
            ankle_pitch: 0.167,
            ankle_v_lat: -0.138,
            swing_tilt: 0.343,
            abdomen_pitch: 0.178,
            abdomen_roll: 0.133,
            swing_knee_bias: -0.3,
            stance_knee_bias: -0.332,
            swing_hip_bias: -0.296,
        }
    }
}

impl BalanceGains {
    /// Number of gains, in the order of [`Self::to_array`].
    pub const LEN: usize = 17;

    pub fn to_array(&self) -> [f32; Self::LEN] {
        [
            self.swing_d_fwd,
            self.swing_v_fwd,
            self.swing_d_lat,
            self.swing_v_lat,
            self.stance_pitch,
            self.stance_roll,
            self.stance_pitch_rate,
            self.stance_roll_rate,
            self.ankle_v_fwd,
            self.ankle_pitch,
            self.ankle_v_lat,
            self.swing_tilt,
            self.abdomen_pitch,
            self.abdomen_roll,
            self.swing_knee_bias,
            self.stance_knee_bias,
            self.swing_hip_bias,
        ]
    }

    pub fn from_array(a: [f32; Self::LEN]) -> Self {
        Self {
            swing_d_fwd: a[0],
            swing_v_fwd: a[1],
            swing_d_lat: a[2],
            swing_v_lat: a[3],
            stance_pitch: a[4],
            stance_roll: a[5],
            stance_pitch_rate: a[6],
            stance_roll_rate: a[7],
            ankle_v_fwd: a[8],
            ankle_pitch: a[9],
            ankle_v_lat: a[10],
            swing_tilt: a[11],
            abdomen_pitch: a[12],
            abdomen_roll: a[13],
            swing_knee_bias: a[14],
            stance_knee_bias: a[15],
            swing_hip_bias: a[16],
        }
    }

    /// The names of [`Self::to_array`]'s entries.
    pub const NAMES: [&'static str; Self::LEN] = [
        "swing_d_fwd",
        "swing_v_fwd",
        "swing_d_lat",
        "swing_v_lat",
        "stance_pitch",
        "stance_roll",
        "stance_pitch_rate",
        "stance_roll_rate",
        "ankle_v_fwd",
        "ankle_pitch",
        "ankle_v_lat",
        "swing_tilt",
        "abdomen_pitch",
        "abdomen_roll",
        "swing_knee_bias",
        "stance_knee_bias",
        "swing_hip_bias",
    ];
}

/// DoF and body indices the feedback acts on, legs as [right, left].
#[derive(Clone, Debug)]
pub struct Rig {
    pub hip_x: [usize; 2],
    pub hip_y: [usize; 2],
    pub hip_z: [usize; 2],
    pub knee: [usize; 2],
    pub ankle_x: [usize; 2],
    pub ankle_y: [usize; 2],
    pub abdomen_x: usize,
    pub abdomen_y: usize,
    pub foot: [usize; 2],
    pub torso: usize,
    pub masses: Vec<f32>,
}

impl Rig {
    /// `None` when the model lacks one of the AMP humanoid's legs, feet, abdomen or torso.
    pub fn new(model: &CharacterModel) -> Option<Self> {
        let dof = |n: &str| model.dofs.iter().position(|d| d.name == n);
        let body = |n: &str| model.body_index(n);
        Some(Self {
            hip_x: [dof("right_hip_x")?, dof("left_hip_x")?],
            hip_y: [dof("right_hip_y")?, dof("left_hip_y")?],
            hip_z: [dof("right_hip_z")?, dof("left_hip_z")?],
            knee: [dof("right_knee")?, dof("left_knee")?],
            ankle_x: [dof("right_ankle_x")?, dof("left_ankle_x")?],
            ankle_y: [dof("right_ankle_y")?, dof("left_ankle_y")?],
            abdomen_x: dof("abdomen_x")?,
            abdomen_y: dof("abdomen_y")?,
            foot: [body("right_foot")?, body("left_foot")?],
            torso: body("torso")?,
            masses: model
                .bodies
                .iter()
                .map(|b| b.geoms.iter().map(|g| g.mass() as f32).sum())
                .collect(),
        })
    }

    /// The stance foot of a frame (0 right, 1 left): the lower one.
    pub fn stance(&self, frame: &[BodyState]) -> usize {
        usize::from(frame[self.foot[1]].pos.z < frame[self.foot[0]].pos.z)
    }

    /// Whether both feet's origins are below `height` (a body missing from `now` counts as up).
    pub fn feet_down(&self, now: &[BodyState], height: f32) -> bool {
        self.foot
            .iter()
            .all(|&f| now.get(f).is_some_and(|b| b.pos.z < height))
    }
}

/// What the feedback compares between the character and its reference, each in its own heading
/// frame (x forward, y left).
#[derive(Clone, Copy, Debug)]
pub struct Balance {
    /// Centre of mass relative to the stance foot, horizontal.
    pub d: Vector,
    /// Centre-of-mass velocity.
    pub v: Vector,
    /// Pelvis and torso rotations, and the pelvis's angular velocity.
    pub pelvis: Rotation,
    pub torso: Rotation,
    pub rate: Vector,
}

/// The rotation vector of `a · b⁻¹`, the short way round.
pub fn rotation_error(a: Rotation, b: Rotation) -> Vector {
    let q = (a * b.inverse()).normalize();
    if q.w < 0.0 { -q } else { q }.to_scaled_axis()
}

pub fn balance(rig: &Rig, states: &[BodyState], stance: usize) -> Balance {
    balance_about(rig, states, states[rig.foot[stance]].pos)
}

/// [`Balance`] with the centre of mass's offset taken from `anchor` (a point on the ground).
pub fn balance_about(rig: &Rig, states: &[BodyState], anchor: Vector) -> Balance {
    let total: f32 = rig.masses.iter().sum::<f32>().max(f32::EPSILON);
    let (mut p, mut v) = (Vector::ZERO, Vector::ZERO);
    for (s, m) in states.iter().zip(&rig.masses) {
        p += s.pos * *m;
        v += s.linvel * *m;
    }
    let (p, v) = (p / total, v / total);
    let h = HeadingFrame::of(&states[0]);
    let mut d = h.vector(p - anchor);
    d.z = 0.0;
    Balance {
        d,
        v: h.vector(v),
        pelvis: h.rotation(states[0].rot),
        torso: h.rotation(states[rig.torso].rot),
        rate: h.vector(states[0].angvel),
    }
}

/// `frame` moved by the rigid motion in the ground plane (a turn about the vertical and a
/// horizontal shift) that takes its root's heading and ground position onto `onto`'s: the
/// reference as it would be had it walked where the character walks. Heights, tilts and
/// everything relative to the root are kept, so tracking it ([`crate::task::rewards::imitation`])
/// asks for the reference's posture and speed whatever course the steering took.
pub fn aligned_to(frame: &[BodyState], onto: &BodyState) -> Vec<BodyState> {
    let Some(root) = frame.first() else {
        return Vec::new();
    };
    let turn = Rotation::from_rotation_z(heading_yaw(onto.rot) - heading_yaw(root.rot));
    let (from, to) = (
        Vector::new(root.pos.x, root.pos.y, 0.0),
        Vector::new(onto.pos.x, onto.pos.y, 0.0),
    );
    frame
        .iter()
        .map(|b| BodyState {
            pos: to + turn * (b.pos - from),
            rot: (turn * b.rot).normalize(),
            linvel: turn * b.linvel,
            angvel: turn * b.angvel,
        })
        .collect()
}

/// PD targets (radians, one per DoF): the reference's next joint angles `reference_next` with the
/// feedback of `gains` for the character in `now` against the reference in `reference_now`.
pub fn base_targets(
    rig: &Rig,
    gains: &BalanceGains,
    now: &[BodyState],
    reference_now: &[BodyState],
    reference_next: &[f32],
) -> Vec<f32> {
    braking_targets(rig, gains, now, reference_now, reference_next, 1.0)
}

/// [`base_targets`] against the reference's centre-of-mass velocity times `speed`: at 0 every
/// bit of the character's velocity is an error, so the swing foot lands further ahead and the
/// stance ankle pushes back (a braking step before a stop).
pub fn braking_targets(
    rig: &Rig,
    gains: &BalanceGains,
    now: &[BodyState],
    reference_now: &[BodyState],
    reference_next: &[f32],
    speed: f32,
) -> Vec<f32> {
    let g = gains;
    let mut t = reference_next.to_vec();
    let stance = rig.stance(reference_now);
    let swing = 1 - stance;
    let c = balance(rig, now, stance);
    let mut r = balance(rig, reference_now, stance);
    r.v *= speed;
    let dd = c.d - r.d;
    let dv = c.v - r.v;
    let e = rotation_error(c.pelvis, r.pelvis);
    let et = rotation_error(c.torso, r.torso);
    let w = c.rate - r.rate;
    t[rig.hip_y[swing]] +=
        g.swing_d_fwd * dd.x + g.swing_v_fwd * dv.x + g.swing_tilt * e.y + g.swing_hip_bias;
    t[rig.hip_x[swing]] += g.swing_d_lat * dd.y + g.swing_v_lat * dv.y + g.swing_tilt * e.x;
    t[rig.hip_y[stance]] += g.stance_pitch * e.y + g.stance_pitch_rate * w.y;
    t[rig.hip_x[stance]] += g.stance_roll * e.x + g.stance_roll_rate * w.x;
    t[rig.ankle_y[stance]] += g.ankle_v_fwd * dv.x + g.ankle_pitch * e.y;
    t[rig.ankle_x[stance]] += g.ankle_v_lat * dv.y;
    t[rig.knee[swing]] += g.swing_knee_bias;
    t[rig.knee[stance]] += g.stance_knee_bias;
    t[rig.abdomen_y] += g.abdomen_pitch * et.y;
    t[rig.abdomen_x] += g.abdomen_roll * et.x;
    t
}

/// How the base walks off from rest (`[env.gait.start]`): over `seconds` the gait ramps in from
/// the neutral standing pose — its joint angles, the centre-of-mass velocity its feedback asks for
/// and (from `feedback`) the feedback itself grow from 0 to the walk's — while a lean into the
/// first step fades out. The base from the task's standing start falls within 22-50 steps from
/// every cycle phase (RESULTS.md, thirteenth session): it asks at once for the clip's ~1 m/s and
/// its stride, which a character at rest meets by toppling. Human gait initiation leans first
/// and shortens the first step; these terms are that, their values found by the gait probe's
/// search (`SEARCH=start`). `seconds` 0: no ramp (the base as from a walking start).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StartRamp {
    pub seconds: f32,
    /// Feedback's share at the ramp's first step, in [0, 1] (it grows to 1 with the ramp).
    pub feedback: f32,
    /// The lean at the ramp's first step (radians, fading to 0 with the ramp): both ankles'
    /// pitch, both hips' pitch, the abdomen's pitch, both knees.
    pub ankle_lean: f32,
    pub hip_lean: f32,
    pub abdomen_lean: f32,
    pub knee_bend: f32,
}

impl Default for StartRamp {
    fn default() -> Self {
        Self::from_array([0.0; Self::LEN])
    }
}

impl StartRamp {
    pub const LEN: usize = 6;

    pub fn to_array(&self) -> [f32; Self::LEN] {
        [
            self.seconds,
            self.feedback,
            self.ankle_lean,
            self.hip_lean,
            self.abdomen_lean,
            self.knee_bend,
        ]
    }

    pub fn from_array(a: [f32; Self::LEN]) -> Self {
        Self {
            seconds: a[0],
            feedback: a[1],
            ankle_lean: a[2],
            hip_lean: a[3],
            abdomen_lean: a[4],
            knee_bend: a[5],
        }
    }

    pub const NAMES: [&'static str; Self::LEN] = [
        "seconds",
        "feedback",
        "ankle_lean",
        "hip_lean",
        "abdomen_lean",
        "knee_bend",
    ];

    /// How far the ramp is at `elapsed` seconds after the start, in [0, 1] (1: the walk).
    pub fn progress(&self, elapsed: f32) -> f32 {
        if self.seconds > 0.0 && self.seconds.is_finite() {
            (elapsed / self.seconds).clamp(0.0, 1.0)
        } else {
            1.0
        }
    }
}

/// [`base_targets`] `elapsed` seconds after a start at rest, ramped in by `ramp`: at progress `s`
/// ([`StartRamp::progress`]) the reference's angles times `s`, the feedback against its velocity
/// times `s` weighted by `feedback + (1 − feedback) s`, and the lean times `1 − s`. At `s = 1` it
/// is [`base_targets`].
pub fn start_targets(
    rig: &Rig,
    gains: &BalanceGains,
    ramp: &StartRamp,
    elapsed: f32,
    now: &[BodyState],
    reference_now: &[BodyState],
    reference_next: &[f32],
) -> Vec<f32> {
    let s = ramp.progress(elapsed);
    ramp_targets(rig, gains, ramp, s, now, reference_now, reference_next)
}

/// The base `elapsed` seconds after it stopped (`[env.gait.stop]`): [`start_targets`] run
/// backward — at progress `s` the walk's share is `1 − s`, so over `ramp.seconds` the reference's
/// angles and the velocity its feedback asks for shrink to 0 (shorter steps against the
/// character's momentum, a braking walk) while the lean grows to the pose it then holds. A ramp of
/// 0 seconds: the neutral standing pose at once (zero joint angles), as before stops had ramps.
pub fn stop_targets(
    rig: &Rig,
    gains: &BalanceGains,
    ramp: &StartRamp,
    elapsed: f32,
    now: &[BodyState],
    reference_now: &[BodyState],
    reference_next: &[f32],
) -> Vec<f32> {
    if !(ramp.seconds > 0.0 && ramp.seconds.is_finite()) {
        return vec![0.0; reference_next.len()];
    }
    let s = 1.0 - ramp.progress(elapsed);
    ramp_targets(rig, gains, ramp, s, now, reference_now, reference_next)
}

/// The ramp's targets at progress `s` in [0, 1] (1: [`base_targets`]): see [`start_targets`].
fn ramp_targets(
    rig: &Rig,
    gains: &BalanceGains,
    ramp: &StartRamp,
    s: f32,
    now: &[BodyState],
    reference_now: &[BodyState],
    reference_next: &[f32],
) -> Vec<f32> {
    let base = braking_targets(rig, gains, now, reference_now, reference_next, s);
    if s >= 1.0 {
        return base;
    }
    let f = ramp.feedback.clamp(0.0, 1.0);
    let weight = f + (1.0 - f) * s;
    let mut t: Vec<f32> = base
        .iter()
        .zip(reference_next)
        .map(|(b, r)| s * r + weight * (b - r))
        .collect();
    let lean = 1.0 - s;
    for leg in 0..2 {
        t[rig.ankle_y[leg]] += lean * ramp.ankle_lean;
        t[rig.hip_y[leg]] += lean * ramp.hip_lean;
        t[rig.knee[leg]] += lean * ramp.knee_bend;
    }
    t[rig.abdomen_y] += lean * ramp.abdomen_lean;
    t
}

/// Turns the gait by `yaw` (radians, + left), spread over the hips' yaw: the swing hip turns the
/// leg it is about to land by `yaw`, the stance hip turns the pelvis over the planted foot.
/// Clamped to ±`max`.
pub fn steer(rig: &Rig, targets: &mut [f32], reference_now: &[BodyState], yaw: f32, max: f32) {
    let yaw = yaw.clamp(-max, max);
    let stance = rig.stance(reference_now);
    targets[rig.hip_z[1 - stance]] += yaw;
    targets[rig.hip_z[stance]] -= yaw;
}

/// A foot whose body origin is below this height (m) is on the ground: its box's sole is 5 cm
/// below the origin.
pub const CONTACT_HEIGHT: f32 = 0.07;

/// One cycle of a looped clip sampled at the control rate: per control step, every body's state
/// (in the clip's own frame) and the joint angles the step after it.
#[derive(Clone, Debug)]
pub struct GaitReference {
    pub clip: usize,
    /// The clip time of step 0 and the control step (s).
    pub dt: f32,
    frames: Vec<Vec<BodyState>>,
    angles: Vec<Vec<f32>>,
}

impl GaitReference {
    /// The cycle of `demo`'s clip `clip` at control step `dt`, its period rounded to whole steps.
    /// `None` for a clip shorter than two steps.
    pub fn new(model: &CharacterModel, demo: &DemoMotion, clip: usize, dt: f32) -> Option<Self> {
        let duration = demo.clips().nth(clip)?.1;
        let n = (duration / dt).round() as usize;
        if n < 2 {
            return None;
        }
        let frames: Vec<Vec<BodyState>> = (0..n)
            .map(|k| demo.body_states_at(clip, k as f32 * dt))
            .collect();
        let angles = (0..n)
            .map(|k| joint_angles(model, &frames[(k + 1) % n]))
            .collect();
        Some(Self {
            clip,
            dt,
            frames,
            angles,
        })
    }

    /// Control steps in one cycle.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The reference at step `k` of the cycle (wrapping), and the joint angles for the step after.
    pub fn at(&self, k: usize) -> (&[BodyState], &[f32]) {
        let k = k % self.frames.len();
        (&self.frames[k], &self.angles[k])
    }

    /// The clip time (s) of step `k`.
    pub fn time(&self, k: usize) -> f32 {
        (k % self.frames.len()) as f32 * self.dt
    }

    /// The cycle step after `step`, kept in time with the character's footfalls (SIMBICON switches
    /// its state machine on touchdown; a clock runs on while the foot lands early or late). When
    /// the reference's next step changes the stance foot but the character's swing foot (origin
    /// above `CONTACT_HEIGHT`) has not landed, the cycle waits, at most `max_wait` steps in a row
    /// (`waited` counts them); when the swing foot has landed up to `max_skip` steps before the
    /// reference's footfall, the cycle jumps to the step where the reference's new stance begins. `max_wait = max_skip = 0` is the plain clock.
    pub fn advance(
        &self,
        rig: &Rig,
        step: usize,
        now: &[BodyState],
        waited: &mut usize,
        max_wait: usize,
        max_skip: usize,
    ) -> usize {
        let stance = rig.stance(self.at(step).0);
        let landed = now[rig.foot[1 - stance]].pos.z < CONTACT_HEIGHT;
        if rig.stance(self.at(step + 1).0) != stance {
            if !landed && *waited < max_wait {
                *waited += 1;
                return step;
            }
        } else if landed {
            if let Some(k) = (2..=max_skip + 1).find(|&k| rig.stance(self.at(step + k).0) != stance)
            {
                *waited = 0;
                return step + k;
            }
        }
        *waited = 0;
        step + 1
    }

    /// Whether the reference's swing foot lands at step `k` (its lower foot changes): the step of
    /// the cycle where both its feet are down, the moment a stop can freeze without a foot in the air.
    pub fn footfall(&self, rig: &Rig, k: usize) -> bool {
        let n = self.frames.len();
        rig.stance(self.at(k).0) != rig.stance(self.at(k + n - 1).0)
    }

    /// The cycle's phase at step `k`, in [0, 1).
    pub fn phase(&self, k: usize) -> f32 {
        (k % self.frames.len()) as f32 / self.frames.len() as f32
    }

    /// This cycle with `offsets` (radians) added to the joint angles it asks for: per DoF named
    /// exactly as in `model`, one value for every step or one per step of the cycle (`len()`).
    /// The frames (what balance feedback and the imitation term compare with) stay the clip's:
    /// an offset is a feed-forward on the servo's target, for a joint that the servo holds off
    /// the clip (gravity sag of arms and knees; `[env.gait] angle_offsets`). An error names the
    /// DoF of an unknown name, a wrong length or a value that is not finite.
    pub fn with_angle_offsets(
        mut self,
        model: &CharacterModel,
        offsets: &std::collections::BTreeMap<String, Vec<f32>>,
    ) -> Result<Self, String> {
        let n = self.frames.len();
        for (name, values) in offsets {
            let d = angle_offset_dof(model, name, values)?;
            if values.len() != 1 && values.len() != n {
                return Err(format!(
                    "[env.gait] angle_offsets.{name}: {} values; give 1 (every step) or {n} (one \
                     per control step of the clip's cycle)",
                    values.len()
                ));
            }
            for (k, angles) in self.angles.iter_mut().enumerate() {
                angles[d] += values[if values.len() == 1 { 0 } else { k }];
            }
        }
        Ok(self)
    }
}

/// The index in `model` of the DoF an `[env.gait] angle_offsets` entry names exactly, once its
/// values are finite; an error names the entry (and lists the DoFs for an unknown name). The
/// number of values is checked against the cycle by [`GaitReference::with_angle_offsets`].
pub fn angle_offset_dof(
    model: &CharacterModel,
    name: &str,
    values: &[f32],
) -> Result<usize, String> {
    let d = model
        .dofs
        .iter()
        .position(|d| d.name == name)
        .ok_or_else(|| {
            let names: Vec<&str> = model.dofs.iter().map(|d| d.name.as_str()).collect();
            format!(
                "[env.gait] angle_offsets.{name}: no DoF has that name (the DoFs: {})",
                names.join(", ")
            )
        })?;
    if let Some(bad) = values.iter().find(|v| !v.is_finite()) {
        return Err(format!(
            "[env.gait] angle_offsets.{name}: {bad} is not a finite number"
        ));
    }
    Ok(d)
}

/// The gait cycle of the first clip in `demo` whose name contains `clip`, at control step `dt`;
/// an error naming the clip when none is installed or it is too short.
pub fn reference_for(
    model: &CharacterModel,
    demo: &DemoMotion,
    clip: &str,
    dt: f32,
) -> Result<GaitReference, String> {
    let index = demo
        .clips()
        .position(|(name, _)| name.contains(clip))
        .ok_or_else(|| format!("[env.gait] clip {clip:?}: no installed clip has that name"))?;
    GaitReference::new(model, demo, index, dt)
        .ok_or_else(|| format!("[env.gait] clip {clip:?}: shorter than two control steps"))
}

/// The cycle `gait` walks: its clip's ([`reference_for`]) with its `angle_offsets`
/// ([`GaitReference::with_angle_offsets`]).
pub fn reference_for_gait(
    model: &CharacterModel,
    demo: &DemoMotion,
    gait: &crate::env::GaitConfig,
    dt: f32,
) -> Result<GaitReference, String> {
    reference_for(model, demo, &gait.clip, dt)?.with_angle_offsets(model, &gait.angle_offsets)
}

/// A synthetic stepping cycle, a fixture for tests and probes that need a gait without installed
/// clips: 37 frames at 30 Hz (1.2 s, the last frame the first's pose one cycle on), the thighs
/// swinging ±0.3 rad in opposition while the root moves forward at 1 m/s, 0.9 m up. `None` for
/// a character without `right_thigh` and `left_thigh`.
pub fn synthetic_cycle_clip(model: &CharacterModel) -> Option<Vec<KinematicPose>> {
    let (rt, lt) = (
        model.body_index("right_thigh")?,
        model.body_index("left_thigh")?,
    );
    Some(
        (0..37)
            .map(|i| {
                let s = (std::f32::consts::TAU * i as f32 / 36.0).sin();
                let mut local_rots = vec![Rotation::IDENTITY; model.bodies.len()];
                local_rots[rt] = Rotation::from_rotation_y(-0.3 * s);
                local_rots[lt] = Rotation::from_rotation_y(0.3 * s);
                KinematicPose {
                    root_pos: Vector::new(i as f32 / 30.0, 0.0, 0.9),
                    root_rot: Rotation::IDENTITY,
                    local_rots,
                }
            })
            .collect(),
    )
}

/// [`synthetic_cycle_clip`] as a one-clip demo named `cycle_walk` (what [`GaitReference::new`]
/// and [`reference_for`] take), its AMP features over `window`. `None` where the clip is.
pub fn synthetic_cycle_demo(model: &CharacterModel, window: AmpWindow) -> Option<DemoMotion> {
    let clip = synthetic_cycle_clip(model)?;
    DemoMotion::from_clips(model, vec![("cycle_walk".into(), clip, 1.0 / 30.0)], window).ok()
}
