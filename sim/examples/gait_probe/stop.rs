//! The stop the probe tries (`STOP_AFTER`): a braking step, then the pose of the moment both feet
//! are down held with ankle and hip strategies. Kept here, not in `lhm_sim::gait`: on the
//! simulator it does not stand (RESULTS.md, thirteenth session).

use lhm_sim::fidelity::joint_angles;
use lhm_sim::gait::{balance, balance_about, rotation_error, Rig};
use lhm_sim::mjcf::CharacterModel;
use lhm_sim::obs::BodyState;
use rapier3d::math::Rotation;

/// Gains of the standing balance the gait stops into (`stand_targets`): radians per unit of
/// error (m, m/s, rad, rad/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StandGains {
    /// Both ankles' pitch from the centre of mass's forward offset over the middle of the feet
    /// and its forward velocity (the ankle strategy), and their roll from the lateral ones.
    pub ankle_d_fwd: f32,
    pub ankle_v_fwd: f32,
    pub ankle_d_lat: f32,
    pub ankle_v_lat: f32,
    /// Both hips' pitch and roll from the pelvis's tilt and tilt rate against the held pelvis
    /// (the hip strategy).
    pub hip_pitch: f32,
    pub hip_pitch_rate: f32,
    pub hip_roll: f32,
    pub hip_roll_rate: f32,
    /// Abdomen pitch and roll from the torso's tilt against the held torso.
    pub abdomen_pitch: f32,
    pub abdomen_roll: f32,
    /// Both knees: a constant offset on the held angle (bend: +).
    pub knee_bias: f32,
    /// The braking step before the freeze (`braking_targets`): swing hip pitch and stance
    /// knee per m/s of the character's forward velocity (a longer last step that lands ahead of
    /// the centre of mass, a stance knee that gives).
    pub brake_hip: f32,
    pub brake_knee: f32,
}

impl Default for StandGains {
    fn default() -> Self {
        Self::from_array([0.0; Self::LEN])
    }
}

impl StandGains {
    pub const LEN: usize = 13;

    pub fn to_array(self) -> [f32; Self::LEN] {
        [
            self.ankle_d_fwd,
            self.ankle_v_fwd,
            self.ankle_d_lat,
            self.ankle_v_lat,
            self.hip_pitch,
            self.hip_pitch_rate,
            self.hip_roll,
            self.hip_roll_rate,
            self.abdomen_pitch,
            self.abdomen_roll,
            self.knee_bias,
            self.brake_hip,
            self.brake_knee,
        ]
    }

    pub fn from_array(a: [f32; Self::LEN]) -> Self {
        Self {
            ankle_d_fwd: a[0],
            ankle_v_fwd: a[1],
            ankle_d_lat: a[2],
            ankle_v_lat: a[3],
            hip_pitch: a[4],
            hip_pitch_rate: a[5],
            hip_roll: a[6],
            hip_roll_rate: a[7],
            abdomen_pitch: a[8],
            abdomen_roll: a[9],
            knee_bias: a[10],
            brake_hip: a[11],
            brake_knee: a[12],
        }
    }

    pub const NAMES: [&'static str; Self::LEN] = [
        "ankle_d_fwd",
        "ankle_v_fwd",
        "ankle_d_lat",
        "ankle_v_lat",
        "hip_pitch",
        "hip_pitch_rate",
        "hip_roll",
        "hip_roll_rate",
        "abdomen_pitch",
        "abdomen_roll",
        "knee_bias",
        "brake_hip",
        "brake_knee",
    ];
}

/// The pose a stopping gait holds: the character's own joint angles when both feet were down
/// (no foot moves), and the reference's pelvis and torso tilt (in its heading frame) to keep.
#[derive(Clone, Debug, PartialEq)]
pub struct StandHold {
    pub angles: Vec<f32>,
    pub pelvis: Rotation,
    pub torso: Rotation,
}

impl StandHold {
    /// Freezes `now` (the character) with the upper body's tilt of `reference_now`.
    pub fn freeze(
        model: &CharacterModel,
        rig: &Rig,
        now: &[BodyState],
        reference_now: &[BodyState],
    ) -> Self {
        let r = balance(rig, reference_now, 0);
        Self {
            angles: joint_angles(model, now),
            pelvis: r.pelvis,
            torso: r.torso,
        }
    }
}

/// PD targets that stand in `hold`: its joint angles with ankle and hip strategies moving the
/// centre of mass back over the middle of the feet and the pelvis and torso back to its tilt.
/// A stop is a motion that keeps both feet where they landed, not a switch to the neutral pose
/// (which fell on 18-19 of 20 stops from a walk: RESULTS.md, twelfth session).
pub fn stand_targets(
    rig: &Rig,
    gains: &StandGains,
    now: &[BodyState],
    hold: &StandHold,
) -> Vec<f32> {
    let g = gains;
    let mut t = hold.angles.clone();
    let mid = (now[rig.foot[0]].pos + now[rig.foot[1]].pos) * 0.5;
    let c = balance_about(rig, now, mid);
    let e = rotation_error(c.pelvis, hold.pelvis);
    let et = rotation_error(c.torso, hold.torso);
    for leg in 0..2 {
        t[rig.ankle_y[leg]] += g.ankle_d_fwd * c.d.x + g.ankle_v_fwd * c.v.x;
        t[rig.ankle_x[leg]] += g.ankle_d_lat * c.d.y + g.ankle_v_lat * c.v.y;
        t[rig.hip_y[leg]] += g.hip_pitch * e.y + g.hip_pitch_rate * c.rate.y;
        t[rig.hip_x[leg]] += g.hip_roll * e.x + g.hip_roll_rate * c.rate.x;
        t[rig.knee[leg]] += g.knee_bias;
    }
    t[rig.abdomen_y] += g.abdomen_pitch * et.y;
    t[rig.abdomen_x] += g.abdomen_roll * et.x;
    t
}

/// The braking step's terms on top of `braking_targets`: the swing hip and the stance knee per
/// m/s of the character's forward velocity.
pub fn add_brake(
    rig: &Rig,
    gains: &StandGains,
    t: &mut [f32],
    now: &[BodyState],
    reference_now: &[BodyState],
) {
    let stance = rig.stance(reference_now);
    let v = balance(rig, now, stance).v.x;
    t[rig.hip_y[1 - stance]] += gains.brake_hip * v;
    t[rig.knee[stance]] += gains.brake_knee * v;
}
