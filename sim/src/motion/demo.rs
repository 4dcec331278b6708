//! Demo AMP features: windows of reference motion in exactly the layout the environment gives the
//! discriminator (`TaskEnv::amp_features`: the last N AMP frames, oldest first, one control step
//! apart), so the learner can compare policy and mocap feature for feature.
//!
//! A window starts at a continuous random time, not on a clip frame, so the discriminator never
//! sees a 30 fps grid the simulation does not share. Poses between clip frames are interpolated
//! (root position lerp, rotations slerp); velocities come from finite differences of the
//! interpolated poses, and every frame goes through [`amp_frame`], the one definition of the layout.

use super::deepmimic::DeepMimicClip;
use super::library::{self, Source};
use super::omomo::{self, OmomoClip};
use super::retarget::{
    deepmimic_poses, forward_kinematics, omomo_poses, resting_states, KinematicPose,
};
use super::MotionError;
use crate::env::EnvConfig;
use crate::mjcf::{BodyDef, CharacterModel};
use crate::obs::{amp_frame, amp_frame_dim, finite_difference_states, BodyState};
use crate::world::SimConfig;
use rapier3d::math::{Rotation, Vector};
use std::path::{Path, PathBuf};

/// The stretch of motion one discriminator input covers: `frames` AMP frames `control_dt` apart.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AmpWindow {
    pub frames: usize,
    pub control_dt: f32,
}

impl AmpWindow {
    /// The window the environment uses under these configurations.
    pub fn of(env: &EnvConfig, sim: &SimConfig) -> Self {
        Self {
            // AmpHistory keeps at least one frame; match it.
            frames: env.amp_frames.max(1),
            control_dt: 1.0 / sim.control_hz,
        }
    }

    /// Seconds from the first frame of the window to its last.
    pub fn span_s(&self) -> f32 {
        self.frames.saturating_sub(1) as f32 * self.control_dt
    }
}

impl Default for AmpWindow {
    fn default() -> Self {
        Self::of(&EnvConfig::default(), &SimConfig::default())
    }
}

/// How much of the discriminator's demo comes from each installed source, per second of clip:
/// 1 and 1 (the default) samples every second of every clip alike, which gives the OMOMO box
/// clips (13.9 s) about twice the DeepMimic walks' (7.4 s) share. A stage that only walks can
/// leave the box clips out (`omomo = 0`), as AMP and TokenHSI give each skill its own motion set.
/// Reference-state starts are not affected. Clips built with [`DemoMotion::from_clips`] count as
/// DeepMimic's.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SourceWeights {
    pub deepmimic: f64,
    pub omomo: f64,
}

impl Default for SourceWeights {
    fn default() -> Self {
        Self {
            deepmimic: 1.0,
            omomo: 1.0,
        }
    }
}

impl SourceWeights {
    /// Refuses a negative or non-finite weight, or both zero, naming the field.
    pub fn check(&self) -> Result<(), String> {
        for (name, w) in [("deepmimic", self.deepmimic), ("omomo", self.omomo)] {
            if !(w.is_finite() && w >= 0.0) {
                return Err(format!("{name} = {w}: a weight is finite and not negative"));
            }
        }
        if self.deepmimic == 0.0 && self.omomo == 0.0 {
            return Err("deepmimic and omomo are both 0: no demo to sample".into());
        }
        Ok(())
    }
}

/// One retargeted clip: at least two poses, uniformly `frame_dt` apart (checked on construction).
#[derive(Clone, Debug)]
struct DemoClip {
    name: String,
    poses: Vec<KinematicPose>,
    frame_dt: f32,
    /// The clip carries an object (OMOMO): a start from it needs the object placed too.
    with_object: bool,
    /// Relative weight of the clip's seconds in [`DemoMotion::sample_features`] (its source's
    /// [`SourceWeights`] entry; 1 unless set).
    weight: f64,
    /// The clip is one cycle of a periodic motion (DeepMimic `"Loop": "wrap"`): its last pose is
    /// its first moved along the ground, so it continues by repeating itself from there.
    looped: bool,
}

impl DemoClip {
    fn duration_s(&self) -> f32 {
        (self.poses.len() - 1) as f32 * self.frame_dt
    }

    /// The pose at time `t` (clamped to the clip), between its two neighbouring frames.
    fn pose_at(&self, t: f32) -> KinematicPose {
        let last = self.poses.len() - 1;
        let s = (t / self.frame_dt).clamp(0.0, last as f32);
        let i = (s.floor() as usize).min(last - 1);
        let a = s - i as f32;
        let (p, q) = (&self.poses[i], &self.poses[i + 1]);
        KinematicPose {
            root_pos: p.root_pos.lerp(q.root_pos, a),
            root_rot: p.root_rot.slerp(q.root_rot, a).normalize(),
            local_rots: p
                .local_rots
                .iter()
                .zip(&q.local_rots)
                .map(|(r, s)| r.slerp(*s, a).normalize())
                .collect(),
        }
    }
}

/// Retargeted reference clips to sample demo AMP features from.
#[derive(Clone, Debug)]
pub struct DemoMotion {
    model: CharacterModel,
    window: AmpWindow,
    clips: Vec<DemoClip>,
    /// Per body, its centre of mass in its own frame: rapier reports a body's linear velocity at
    /// its centre of mass, so the demo root velocity must be taken there too (the pelvis's is
    /// ~0.1 m above its origin, which matters whenever the pelvis pitches or rolls).
    com: Vec<Vector>,
}

impl DemoMotion {
    /// Clips given as (name, poses of `model`, seconds between poses). Refuses a clip with fewer
    /// than two poses, a non-positive frame time, poses of another model, or a duration shorter
    /// than `window` (naming the clip).
    pub fn from_clips(
        model: &CharacterModel,
        clips: Vec<(String, Vec<KinematicPose>, f32)>,
        window: AmpWindow,
    ) -> Result<Self, MotionError> {
        if window.frames == 0 || !(window.control_dt.is_finite() && window.control_dt > 0.0) {
            return Err(MotionError::Window(format!(
                "{} frames {} s apart; need at least one frame and a positive step",
                window.frames, window.control_dt
            )));
        }
        if clips.is_empty() {
            return Err(MotionError::NoClips {
                path: "demo motion".into(),
            });
        }
        let mut out = Vec::with_capacity(clips.len());
        for (name, poses, frame_dt) in clips {
            let corrupt = |message: String| MotionError::Corrupt {
                file: name.clone(),
                message,
            };
            if poses.len() < 2 {
                return Err(corrupt(format!(
                    "{} poses; a clip needs at least 2",
                    poses.len()
                )));
            }
            if !(frame_dt.is_finite() && frame_dt > 0.0) {
                return Err(corrupt(format!("frame time {frame_dt} s is not positive")));
            }
            let bodies = model.bodies.len();
            if let Some(i) = poses.iter().position(|p| p.local_rots.len() != bodies) {
                return Err(corrupt(format!(
                    "pose {i} has {} body rotations, the character {bodies}",
                    poses[i].local_rots.len()
                )));
            }
            let clip = DemoClip {
                name,
                poses,
                frame_dt,
                with_object: false,
                looped: false,
                weight: 1.0,
            };
            // A little slack so a clip exactly as long as the window is not lost to rounding.
            if clip.duration_s() < window.span_s() * (1.0 - 1e-5) {
                return Err(MotionError::TooShort {
                    duration_s: clip.duration_s(),
                    clip: clip.name,
                    frames: window.frames,
                    needed_s: window.span_s(),
                });
            }
            out.push(clip);
        }
        Ok(Self {
            model: model.clone(),
            window,
            clips: out,
            com: model.bodies.iter().map(centre_of_mass).collect(),
        })
    }

    /// Every clip installed under `dir` (`dir/deepmimic/` and `dir/omomo/`, as [`library::list`]
    /// finds them), retargeted onto `model`: DeepMimic joint for joint, OMOMO's SMPL-H through
    /// [`omomo_poses`]. A source folder that is missing is skipped; no clips at all is
    /// [`MotionError::NoClips`], and a missing install [`MotionError::NotInstalled`], which tells
    /// the user to run `scripts/install-motions`.
    pub fn load_dir(
        model: &CharacterModel,
        dir: &Path,
        window: AmpWindow,
    ) -> Result<Self, MotionError> {
        let mut clips = Vec::new();
        let mut looped = Vec::new();
        for (name, path) in installed(dir, Source::DeepMimic)? {
            let file = path.display().to_string();
            let text = std::fs::read_to_string(&path).map_err(|source| MotionError::Io {
                file: file.clone(),
                source,
            })?;
            let clip = DeepMimicClip::parse(&text, &file)?;
            let frame_dt = uniform_frame_dt(&clip, &file)?;
            looped.push(clip.looped);
            clips.push((name, deepmimic_poses(model, &clip), frame_dt));
        }
        let mut omomo_count = 0;
        for (name, path) in installed(dir, Source::Omomo)? {
            omomo_count += 1;
            let file = path.display().to_string();
            let bytes = std::fs::read(&path).map_err(|source| MotionError::Io {
                file: file.clone(),
                source,
            })?;
            let clip = OmomoClip::parse(&bytes, &file)?;
            clips.push((name, omomo_poses(model, &clip, &file)?, 1.0 / omomo::FPS));
        }
        if clips.is_empty() {
            return Err(MotionError::NoClips {
                path: dir.display().to_string(),
            });
        }
        let deepmimic = clips.len() - omomo_count;
        let mut demo = Self::from_clips(model, clips, window)?;
        for c in &mut demo.clips[deepmimic..] {
            c.with_object = true;
        }
        for (c, looped) in demo.clips.iter_mut().zip(looped) {
            c.looped = looped;
        }
        Ok(demo)
    }

    pub fn window(&self) -> AmpWindow {
        self.window
    }

    /// Weights [`Self::sample_features`]'s clips by source (OMOMO: the clips with an object).
    /// Refuses weights [`SourceWeights::check`] refuses, and weights that leave none of the
    /// loaded clips a chance (e.g. `deepmimic = 0` with only DeepMimic clips installed).
    pub fn with_source_weights(mut self, weights: SourceWeights) -> Result<Self, MotionError> {
        weights.check().map_err(MotionError::DemoWeights)?;
        for c in &mut self.clips {
            c.weight = if c.with_object {
                weights.omomo
            } else {
                weights.deepmimic
            };
        }
        if self.clips.iter().all(|c| c.weight == 0.0) {
            return Err(MotionError::DemoWeights(format!(
                "{weights:?} leaves none of the {} loaded clips",
                self.clips.len()
            )));
        }
        Ok(self)
    }

    /// These clips with only those whose name `keep` accepts and that [`Self::sample_features`]
    /// can draw (weight above 0): e.g. one clip held out of a discriminator's demo to see
    /// whether it still takes that clip for demo. `None` when no such clip is left.
    pub fn retain_clips(&self, keep: impl Fn(&str) -> bool) -> Option<Self> {
        let clips: Vec<DemoClip> = self
            .clips
            .iter()
            .filter(|c| c.weight > 0.0 && keep(&c.name))
            .cloned()
            .collect();
        (!clips.is_empty()).then(|| Self {
            model: self.model.clone(),
            window: self.window,
            clips,
            com: self.com.clone(),
        })
    }

    /// These clips and, after them, each clip's left–right mirror image (named `NAME~mirror`):
    /// the same motion seen in a mirror across the character's sagittal plane, left and right
    /// limbs exchanged. A demo set of a few walks holds each walk's asymmetries on one side only;
    /// the mirrors give a discriminator both. Refuses a character that is not left–right
    /// symmetric ([`mirror_map`]).
    pub fn with_mirrors(&self) -> Result<Self, MotionError> {
        let map = mirror_map(&self.model)?;
        let mirrors: Vec<DemoClip> = self
            .clips
            .iter()
            .map(|c| DemoClip {
                name: format!("{}~mirror", c.name),
                poses: c.poses.iter().map(|p| mirror_pose(p, &map)).collect(),
                ..c.clone()
            })
            .collect();
        let mut out = self.clone();
        out.clips.extend(mirrors);
        Ok(out)
    }

    /// Width of one sampled row: `window.frames × amp_frame_dim(model)`, as `TaskEnv::amp_dim`.
    pub fn feature_dim(&self) -> usize {
        self.window.frames * amp_frame_dim(&self.model)
    }

    /// (name, duration in seconds) of every clip, in load order.
    pub fn clips(&self) -> impl Iterator<Item = (&str, f32)> {
        self.clips.iter().map(|c| (c.name.as_str(), c.duration_s()))
    }

    /// `n` rows of [`Self::feature_dim`] numbers, row after row. Each row picks a clip with
    /// probability proportional to its duration, then a start time uniform over the times whose
    /// window fits in the clip, and holds the window's AMP frames oldest first. `rng` returns
    /// uniform numbers in [0, 1); each row draws two, the clip then the start.
    pub fn sample_features(&self, n: usize, rng: &mut impl FnMut() -> f64) -> Vec<f32> {
        let mut out = Vec::with_capacity(n * self.feature_dim());
        let share = |c: &DemoClip| f64::from(c.duration_s()) * c.weight;
        let total: f64 = self.clips.iter().map(share).sum();
        for _ in 0..n {
            let target = rng() * total;
            let mut acc = 0.0;
            // Rounding may leave `target` past the last sum: fall back to the last clip with a
            // share.
            let mut pick = self
                .clips
                .iter()
                .rposition(|c| c.weight > 0.0)
                .unwrap_or(self.clips.len() - 1);
            for (i, c) in self.clips.iter().enumerate() {
                acc += share(c);
                if target < acc {
                    pick = i;
                    break;
                }
            }
            // The first frame's velocities look one control step back.
            let dt = self.window.control_dt;
            let slack = (self.clips[pick].duration_s() - self.window.span_s() - dt).max(0.0);
            let start = dt + rng() as f32 * slack;
            self.push_window(pick, start, &mut out);
        }
        out
    }

    fn push_window(&self, clip: usize, start: f32, out: &mut Vec<f32>) {
        for k in 0..self.window.frames {
            let t = start + k as f32 * self.window.control_dt;
            out.extend(self.amp_frame_at(clip, t));
        }
    }

    /// The AMP frame at time `t` of `clip`, velocities as the environment takes them: backward
    /// differences of poses over one control step ([`finite_difference_states`]).
    pub fn amp_frame_at(&self, clip: usize, t: f32) -> Vec<f32> {
        let c = &self.clips[clip];
        let dt = self.window.control_dt;
        let now = self.poses_at(c, t);
        let prev = self.poses_at(c, t - dt);
        amp_frame(&self.model, &finite_difference_states(&prev, &now, dt))
    }

    /// Body states (zero velocities) of `clip`'s pose at `t`, clamped to the clip.
    fn poses_at(&self, c: &DemoClip, t: f32) -> Vec<BodyState> {
        resting_states(&self.model, &c.pose_at(t.clamp(0.0, c.duration_s())))
    }

    /// A reference-state start: a clip without an object, drawn with probability proportional to
    /// its duration, and a time late enough for a full AMP window before it. `None` when every
    /// clip carries an object. `rng` returns uniform numbers in [0, 1).
    pub fn sample_start(&self, rng: &mut impl FnMut() -> f64) -> Option<(usize, f32)> {
        let lead = self.window.span_s() + self.window.control_dt;
        let usable: Vec<usize> = (0..self.clips.len())
            .filter(|&i| !self.clips[i].with_object && self.clips[i].duration_s() > lead)
            .collect();
        let total: f64 = usable
            .iter()
            .map(|&i| f64::from(self.clips[i].duration_s() - lead))
            .sum();
        if usable.is_empty() || total <= 0.0 {
            return None;
        }
        let mut target = rng() * total;
        for &i in &usable {
            let span = f64::from(self.clips[i].duration_s() - lead);
            if target < span {
                return Some((i, lead + target as f32));
            }
            target -= span;
        }
        usable.last().map(|&i| (i, self.clips[i].duration_s()))
    }

    /// The AMP frames of the window ending at `t` (oldest first): the history a start at `t`
    /// has already seen.
    pub fn amp_history_at(&self, clip: usize, t: f32) -> Vec<Vec<f32>> {
        (0..self.window.frames)
            .rev()
            .map(|k| self.amp_frame_at(clip, t - k as f32 * self.window.control_dt))
            .collect()
    }

    /// Body states at `t` with the previous control step's poses, for continuing backward
    /// differences after a start: (states with central-difference velocities, poses one control
    /// step earlier).
    pub fn start_states(&self, clip: usize, t: f32) -> (Vec<BodyState>, Vec<BodyState>) {
        let c = &self.clips[clip];
        (
            self.body_states_at(clip, t),
            self.poses_at(c, t - self.window.control_dt),
        )
    }

    /// Clip `clip`'s pose at time `t` seconds (clamped to the clip). Panics if `clip` is not an
    /// index into [`Self::clips`].
    pub fn pose_at(&self, clip: usize, t: f32) -> KinematicPose {
        self.clips[clip].pose_at(t)
    }

    /// Every body's world state at time `t` of clip `clip`, as `World::body_states` would give
    /// it: body origin and rotation, linear velocity of the body's centre of mass, angular
    /// velocity. Velocities are central differences over one clip frame around `t` (one-sided
    /// at the clip's ends), which is exact within a frame interval of the interpolated motion
    /// and smooths the kinks at clip frames.
    pub fn body_states_at(&self, clip: usize, t: f32) -> Vec<BodyState> {
        let c = &self.clips[clip];
        let end = c.duration_s();
        let t = t.clamp(0.0, end);
        let h = 0.5 * c.frame_dt;
        let (ta, tb) = ((t - h).max(0.0), (t + h).min(end));
        // tb > ta: the clip is longer than zero and h > 0.
        let dt = tb - ta;
        let now = forward_kinematics(&self.model, &c.pose_at(t));
        let before = forward_kinematics(&self.model, &c.pose_at(ta));
        let after = forward_kinematics(&self.model, &c.pose_at(tb));
        now.iter()
            .zip(before.iter().zip(&after))
            .zip(&self.com)
            .map(|((&(pos, rot), (a, b)), &com)| {
                let com_a = a.0 + a.1 * com;
                let com_b = b.0 + b.1 * com;
                BodyState {
                    pos,
                    rot,
                    linvel: (com_b - com_a) / dt,
                    angvel: angular_velocity(a.1, b.1, dt),
                }
            })
            .collect()
    }
}

impl DemoMotion {
    /// Marks clip `clip` as one cycle of a periodic motion (as a DeepMimic `"Loop": "wrap"` file
    /// does), so [`Self::reference_track`] repeats it. Panics if `clip` is out of range.
    pub fn set_looped(&mut self, clip: usize, looped: bool) {
        self.clips[clip].looped = looped;
    }

    /// The reference an imitation reward tracks from a start at `t0`: every body's state (as
    /// [`Self::body_states_at`]) at `t0 + k·dt` for `k = 1..=steps`, the state the character
    /// should be in after its k-th control step. A looped clip repeats past its end, each
    /// repetition moved by the clip's own ground displacement (heading and horizontal position
    /// of its last root frame against its first, as DeepMimic cycles a walk); a clip that is not
    /// looped ends the track at its end (fewer than `steps` entries).
    pub fn reference_track(
        &self,
        clip: usize,
        t0: f32,
        steps: usize,
        dt: f32,
    ) -> Vec<Vec<BodyState>> {
        let c = &self.clips[clip];
        let period = c.duration_s();
        let cycle = c.looped.then(|| {
            let first = forward_kinematics(&self.model, &c.poses[0]);
            let last = forward_kinematics(&self.model, &c.poses[c.poses.len() - 1]);
            GroundMove::between(first[0], last[0])
        });
        let mut out = Vec::with_capacity(steps);
        for k in 1..=steps {
            let t = t0 + k as f32 * dt;
            let (repeats, local_t) = match &cycle {
                Some(_) if t > period && period > 0.0 => {
                    let n = (t / period).floor();
                    (n as u32, t - n * period)
                }
                _ if t > period => break,
                _ => (0, t),
            };
            let mut states = self.body_states_at(clip, local_t);
            if let Some(step) = &cycle {
                for _ in 0..repeats {
                    for s in &mut states {
                        *s = step.apply(s);
                    }
                }
            }
            out.push(states);
        }
        out
    }
}

/// A rigid motion along the ground: a turn about +z followed by a horizontal shift.
#[derive(Clone, Copy, Debug)]
struct GroundMove {
    turn: Rotation,
    from: Vector,
    to: Vector,
}

impl GroundMove {
    /// The ground move carrying root frame `a` onto root frame `b` (heading and horizontal
    /// position; height and tilt are left to the clip).
    fn between(a: (Vector, Rotation), b: (Vector, Rotation)) -> Self {
        let yaw = crate::obs::heading_yaw;
        Self {
            turn: Rotation::from_rotation_z(yaw(b.1) - yaw(a.1)),
            from: Vector::new(a.0.x, a.0.y, 0.0),
            to: Vector::new(b.0.x, b.0.y, 0.0),
        }
    }

    fn apply(&self, s: &BodyState) -> BodyState {
        BodyState {
            pos: self.to + self.turn * (s.pos - self.from),
            rot: (self.turn * s.rot).normalize(),
            linvel: self.turn * s.linvel,
            angvel: self.turn * s.angvel,
        }
    }
}

/// For every body of `model`, the body its left–right mirror image lands on: `left_X` and
/// `right_X` exchange, every other body maps onto itself. Refuses (naming the body) a `left_`
/// body without its `right_` twin or the other way round, a pair whose parents are not each
/// other's mirror, and a body whose offset from its parent is not its mirror's with the lateral
/// (y) component negated, since then the mirror of a pose is no pose of the same character.
pub fn mirror_map(model: &CharacterModel) -> Result<Vec<usize>, MotionError> {
    let file = format!("character {}", model.name);
    let refuse = |message: String| MotionError::Corrupt {
        file: file.clone(),
        message: format!("not left-right symmetric: {message}"),
    };
    let mut map = Vec::with_capacity(model.bodies.len());
    for b in &model.bodies {
        let twin = if let Some(rest) = b.name.strip_prefix("left_") {
            Some(format!("right_{rest}"))
        } else {
            b.name
                .strip_prefix("right_")
                .map(|rest| format!("left_{rest}"))
        };
        let index = match twin {
            Some(t) => model
                .body_index(&t)
                .ok_or_else(|| refuse(format!("{} has no {t}", b.name)))?,
            None => map.len(),
        };
        map.push(index);
    }
    for (i, b) in model.bodies.iter().enumerate() {
        let twin = &model.bodies[map[i]];
        if b.parent.map(|p| map[p]) != twin.parent {
            return Err(refuse(format!(
                "the parents of {} and {} are not each other's mirror",
                b.name, twin.name
            )));
        }
        let mirrored = [twin.pos[0], -twin.pos[1], twin.pos[2]];
        // The root's position is the pose's, not the model's.
        if b.parent.is_some()
            && b.pos
                .iter()
                .zip(mirrored)
                .any(|(a, m)| (a - m).abs() > 1e-6)
        {
            return Err(refuse(format!(
                "{} sits at {:?} in its parent, its mirror {} at {:?}",
                b.name, b.pos, twin.name, twin.pos
            )));
        }
    }
    Ok(map)
}

/// `pose` seen in a mirror across the world's x–z plane, bodies exchanged by `map`
/// ([`mirror_map`]): positions have y negated, and a rotation about axis (x, y, z) by θ becomes
/// one about (−x, y, −z) by θ (the reflection's conjugate), root and joints alike.
pub fn mirror_pose(pose: &KinematicPose, map: &[usize]) -> KinematicPose {
    let reflect = |q: Rotation| Rotation::from_xyzw(-q.x, q.y, -q.z, q.w);
    let p = pose.root_pos;
    KinematicPose {
        root_pos: Vector::new(p.x, -p.y, p.z),
        root_rot: reflect(pose.root_rot),
        local_rots: map.iter().map(|&b| reflect(pose.local_rots[b])).collect(),
    }
}

/// World-frame angular velocity turning `from` into `to` in `dt`: the relative rotation
/// `to · from⁻¹` as a scaled axis, the short way round.
fn angular_velocity(from: Rotation, to: Rotation, dt: f32) -> Vector {
    let mut d = (to * from.inverse()).normalize();
    if d.w < 0.0 {
        d = -d;
    }
    d.to_scaled_axis() / dt
}

/// Mass-weighted centre of a body's geoms in its frame, as rapier computes it from the colliders
/// (each geom's centroid is its `pos`). The origin for a massless body.
fn centre_of_mass(body: &BodyDef) -> Vector {
    let (mut sum, mut mass) = (Vector::ZERO, 0.0f64);
    for g in &body.geoms {
        let m = g.mass();
        sum += Vector::new(g.pos[0] as f32, g.pos[1] as f32, g.pos[2] as f32) * m as f32;
        mass += m;
    }
    if mass > 0.0 {
        sum / mass as f32
    } else {
        Vector::ZERO
    }
}

/// The clip files of one source, none if its folder is missing (an install of the other
/// source only); a missing install is still [`MotionError::NotInstalled`].
fn installed(dir: &Path, source: Source) -> Result<Vec<(String, PathBuf)>, MotionError> {
    match library::clip_files(dir, source) {
        Err(MotionError::Io { source: e, .. }) if e.kind() == std::io::ErrorKind::NotFound => {
            Ok(Vec::new())
        }
        other => other,
    }
}

/// A DeepMimic clip's frame time. Each frame carries its own duration; the installed clips use
/// one throughout, and interpolation here assumes so, so a clip whose frame times differ by more
/// than 5 % is refused rather than silently time-warped.
fn uniform_frame_dt(clip: &DeepMimicClip, file: &str) -> Result<f32, MotionError> {
    let n = clip.frames.len().saturating_sub(1).max(1);
    let mean = clip.duration() / n as f32;
    if let Some((i, f)) = clip.frames[..clip.frames.len().saturating_sub(1)]
        .iter()
        .enumerate()
        .find(|(_, f)| (f.duration - mean).abs() > 0.05 * mean)
    {
        return Err(MotionError::Corrupt {
            file: file.into(),
            message: format!(
                "frame {i}: duration {} s, the clip's mean is {mean} s; only uniformly timed \
                 clips are supported",
                f.duration
            ),
        });
    }
    Ok(mean)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mjcf::JointKind;
    use crate::obs::twist_angle;
    use lhm_scenes::rng::SplitMix64;

    const DT: f32 = 1.0 / 30.0;

    fn still(model: &CharacterModel, pos: Vector, rot: Rotation) -> KinematicPose {
        KinematicPose {
            root_pos: pos,
            root_rot: rot,
            local_rots: vec![Rotation::IDENTITY; model.bodies.len()],
        }
    }

    fn window(frames: usize) -> AmpWindow {
        AmpWindow {
            frames,
            control_dt: DT,
        }
    }

    /// Replays `values` in a loop: pins the clip and start time a row draws.
    fn replay(values: Vec<f64>) -> impl FnMut() -> f64 {
        let mut i = 0;
        move || {
            let v = values[i % values.len()];
            i += 1;
            v
        }
    }

    /// Where the AMP layout puts each body's joint rotation (by body) and where the joint
    /// velocities start (per DoF, in body order), read off the documented layout.
    fn joint_offsets(model: &CharacterModel) -> (Vec<Option<usize>>, usize) {
        let mut at = 13;
        let mut rot = vec![None; model.bodies.len()];
        for (i, b) in model.bodies.iter().enumerate() {
            match b.joint {
                JointKind::Ball { .. } => {
                    rot[i] = Some(at);
                    at += 6;
                }
                JointKind::Hinge { .. } => {
                    rot[i] = Some(at);
                    at += 1;
                }
                JointKind::Free | JointKind::Fixed => {}
            }
        }
        (rot, at)
    }

    fn knee(model: &CharacterModel) -> (usize, usize, Vector) {
        let shin = model.body_index("right_shin").expect("shin");
        let JointKind::Hinge { dof } = model.bodies[shin].joint else {
            panic!("the knee is a hinge");
        };
        let axis = Vector::from_array(model.dofs[dof].axis.map(|a| a as f32));
        (shin, dof, axis)
    }

    /// A pose with the root and every joint turned some arbitrary way.
    fn twisted_pose(model: &CharacterModel, seed: u64) -> KinematicPose {
        let mut rng = SplitMix64::new(seed);
        let mut turn = || {
            let mut u = || rng.unit() as f32 * 2.0 - 1.0;
            let axis = Vector::new(u(), u(), u()).normalize_or(Vector::Z);
            Rotation::from_axis_angle(axis, u() * 1.5)
        };
        KinematicPose {
            root_pos: Vector::new(0.4, 1.3, 0.9),
            root_rot: turn(),
            local_rots: (0..model.bodies.len()).map(|_| turn()).collect(),
        }
    }

    #[test]
    fn a_mirrored_pose_puts_each_body_where_the_mirror_shows_its_twin() {
        let m = CharacterModel::amp_humanoid();
        let map = mirror_map(&m).expect("the shipped humanoid is symmetric");
        let foot = |side: &str| m.body_index(&format!("{side}_foot")).expect("foot");
        assert_eq!(map[foot("left")], foot("right"));
        assert_eq!(map[foot("right")], foot("left"));
        let torso = m.body_index("torso").expect("torso");
        assert_eq!(map[torso], torso);
        for seed in 1..4 {
            let pose = twisted_pose(&m, seed);
            let seen = forward_kinematics(&m, &pose);
            let mirrored = forward_kinematics(&m, &mirror_pose(&pose, &map));
            for (i, &(pos, rot)) in mirrored.iter().enumerate() {
                let (tpos, trot) = seen[map[i]];
                let want = Vector::new(tpos.x, -tpos.y, tpos.z);
                assert!(
                    (pos - want).length() < 1e-4,
                    "{}: {pos} vs {want}",
                    m.bodies[i].name
                );
                // Each body axis is the mirror of its twin's: x and z flip their y component,
                // and y (the reflection's normal direction) keeps only its y component's sign.
                let flip = |v: Vector| Vector::new(v.x, -v.y, v.z);
                for (axis, sign) in [(Vector::X, 1.0), (Vector::Y, -1.0), (Vector::Z, 1.0)] {
                    let got = rot * axis;
                    let want = flip(trot * axis) * sign;
                    assert!(
                        (got - want).length() < 1e-4,
                        "{} axis {axis}",
                        m.bodies[i].name
                    );
                }
            }
            let back = mirror_pose(&mirror_pose(&pose, &map), &map);
            assert!((back.root_pos - pose.root_pos).length() < 1e-6);
            for (a, b) in back.local_rots.iter().zip(&pose.local_rots) {
                assert!(a.dot(*b).abs() > 1.0 - 1e-6, "mirrored twice is the pose");
            }
        }
    }

    #[test]
    fn a_character_that_is_not_symmetric_has_no_mirror() {
        let mut m = CharacterModel::amp_humanoid();
        let thigh = m.body_index("left_thigh").expect("thigh");
        m.bodies[thigh].pos[1] += 0.01;
        let e = mirror_map(&m).expect_err("asymmetric").to_string();
        assert!(e.contains("left_thigh") && e.contains("symmetric"), "{e}");
        let mut m = CharacterModel::amp_humanoid();
        m.bodies[thigh].name = "left_leg".into();
        let e = mirror_map(&m).expect_err("no twin").to_string();
        assert!(e.contains("right_thigh has no left_thigh"), "{e}");
    }

    #[test]
    fn mirrored_clips_follow_the_clips_and_walk_the_other_way_round() {
        let m = CharacterModel::amp_humanoid();
        // A root gliding forward and to the left, turning left.
        let poses: Vec<KinematicPose> = (0..8)
            .map(|k| {
                let t = k as f32 * DT;
                let mut p = twisted_pose(&m, 9);
                p.root_pos = Vector::new(t, 0.5 * t, 0.9);
                p.root_rot = Rotation::from_rotation_z(0.3 * t);
                p
            })
            .collect();
        let demo =
            DemoMotion::from_clips(&m, vec![("walk".into(), poses, DT)], window(2)).expect("valid");
        let both = demo.with_mirrors().expect("symmetric");
        let names: Vec<&str> = both.clips().map(|(n, _)| n).collect();
        assert_eq!(names, ["walk", "walk~mirror"]);
        let (a, b) = (both.amp_frame_at(0, 0.1), both.amp_frame_at(1, 0.1));
        // Root height the same; in the heading frame the sideways velocity and the yaw rate
        // change sign, the forward velocity does not.
        assert!((a[0] - b[0]).abs() < 1e-5);
        let (vel, ang) = (7, 10);
        assert!((a[vel] - b[vel]).abs() < 1e-4, "{} vs {}", a[vel], b[vel]);
        assert!(
            (a[vel + 1] + b[vel + 1]).abs() < 1e-4,
            "{} vs {}",
            a[vel + 1],
            b[vel + 1]
        );
        assert!(
            (a[ang + 2] + b[ang + 2]).abs() < 1e-4,
            "{} vs {}",
            a[ang + 2],
            b[ang + 2]
        );
        assert!(a[vel + 1].abs() > 0.1, "the clip moves sideways");
    }

    #[test]
    fn a_still_clip_has_zero_velocities_and_its_root_height() {
        let m = CharacterModel::amp_humanoid();
        let pose = still(
            &m,
            Vector::new(0.3, -1.0, 0.87),
            Rotation::from_rotation_z(0.7),
        );
        let demo = DemoMotion::from_clips(&m, vec![("stand".into(), vec![pose; 6], DT)], window(3))
            .expect("valid");
        let mut rng = SplitMix64::new(1);
        let rows = demo.sample_features(4, &mut || rng.unit());
        let dim = amp_frame_dim(&m);
        let (_, vel_start) = joint_offsets(&m);
        assert_eq!(rows.len(), 4 * 3 * dim);
        for f in rows.chunks(dim) {
            assert!((f[0] - 0.87).abs() < 1e-6, "root height {}", f[0]);
            assert!(f[7..13].iter().all(|v| v.abs() < 1e-5), "{:?}", &f[7..13]);
            let joint_vel = &f[vel_start..vel_start + m.dofs.len()];
            assert!(joint_vel.iter().all(|v| v.abs() < 1e-5), "{joint_vel:?}");
        }
    }

    #[test]
    fn retained_clips_are_the_only_ones_sampled_and_weighted_out_clips_are_dropped() {
        let m = CharacterModel::amp_humanoid();
        let at = |h: f32| still(&m, Vector::new(0.0, 0.0, h), Rotation::IDENTITY);
        let mut demo = DemoMotion::from_clips(
            &m,
            vec![
                ("walk_a".into(), vec![at(0.9); 7], DT),
                ("walk_b".into(), vec![at(0.8); 7], DT),
                ("box".into(), vec![at(0.7); 7], DT),
            ],
            window(2),
        )
        .expect("valid");
        demo.clips[2].with_object = true;
        let demo = demo
            .with_source_weights(SourceWeights {
                deepmimic: 1.0,
                omomo: 0.0,
            })
            .expect("walks only");
        let heights = |d: &DemoMotion| {
            let mut rng = SplitMix64::new(9);
            let rows = d.sample_features(200, &mut || rng.unit());
            // Root heights in centimetres: which clips the rows came from.
            let mut h: Vec<i32> = rows
                .chunks(amp_frame_dim(&m))
                .map(|f| (f[0] * 100.0).round() as i32)
                .collect();
            h.sort_unstable();
            h.dedup();
            h
        };
        let held = demo.retain_clips(|n| n == "walk_b").expect("walk_b");
        assert_eq!(held.clips().map(|(n, _)| n).collect::<Vec<_>>(), ["walk_b"]);
        assert_eq!(heights(&held), [80]);
        let rest = demo.retain_clips(|n| n != "walk_b").expect("walk_a");
        // The box clip, weighted out of the demo, is not kept either.
        assert_eq!(rest.clips().map(|(n, _)| n).collect::<Vec<_>>(), ["walk_a"]);
        assert_eq!(heights(&rest), [90]);
        assert!(demo.retain_clips(|n| n == "box").is_none());
        assert!(demo.retain_clips(|_| false).is_none());
    }

    #[test]
    fn source_weights_set_each_sources_share_of_the_demo_windows() {
        let m = CharacterModel::amp_humanoid();
        let at = |h: f32| still(&m, Vector::new(0.0, 0.0, h), Rotation::IDENTITY);
        // A 0.2-s walk (DeepMimic) at 0.9 m and a 0.6-s box clip (OMOMO) at 0.7 m.
        let demo = || {
            let mut d = DemoMotion::from_clips(
                &m,
                vec![
                    ("walk".into(), vec![at(0.9); 7], DT),
                    ("box".into(), vec![at(0.7); 19], DT),
                ],
                window(2),
            )
            .expect("valid");
            d.clips[1].with_object = true;
            d
        };
        let box_share = |d: &DemoMotion| {
            let mut rng = SplitMix64::new(5);
            let rows = d.sample_features(2000, &mut || rng.unit());
            let dim = amp_frame_dim(&m);
            let heights: Vec<f32> = rows.chunks(dim).map(|f| f[0]).collect();
            assert!(heights
                .iter()
                .all(|h| (h - 0.9).abs() < 1e-5 || (h - 0.7).abs() < 1e-5));
            heights.iter().filter(|h| (*h - 0.7).abs() < 1e-5).count() as f64 / heights.len() as f64
        };
        // Per second of clip by default: 0.6 / 0.8 of the windows from the box clip.
        let default = box_share(&demo());
        assert!((default - 0.75).abs() < 0.04, "{default}");
        let weighted =
            |deepmimic, omomo| demo().with_source_weights(SourceWeights { deepmimic, omomo });
        assert_eq!(box_share(&weighted(1.0, 0.0).expect("walks only")), 0.0);
        assert_eq!(box_share(&weighted(0.0, 2.0).expect("box only")), 1.0);
        let even = box_share(&weighted(3.0, 1.0).expect("even"));
        assert!((even - 0.5).abs() < 0.04, "{even}");
        for (deepmimic, omomo) in [(0.0, 0.0), (-1.0, 1.0), (1.0, f64::NAN)] {
            let err = weighted(deepmimic, omomo).expect_err("refused").to_string();
            assert!(err.starts_with("[amp] demo_weights:"), "{err}");
        }
        // Weights that leave none of the loaded clips: only the walk, weighted out.
        let walk_only =
            DemoMotion::from_clips(&m, vec![("walk".into(), vec![at(0.9); 7], DT)], window(2))
                .expect("valid");
        let err = walk_only
            .with_source_weights(SourceWeights {
                deepmimic: 0.0,
                omomo: 1.0,
            })
            .expect_err("nothing left")
            .to_string();
        assert!(err.contains("leaves none of the 1 loaded clips"), "{err}");
    }

    #[test]
    fn a_gliding_root_has_its_velocity_in_the_heading_frame() {
        // Facing +y while moving along world +x at v: in the heading frame that is -y.
        let m = CharacterModel::amp_humanoid();
        let v = 1.2;
        let facing = Rotation::from_rotation_z(std::f32::consts::FRAC_PI_2);
        let poses = (0..8)
            .map(|k| still(&m, Vector::new(v * k as f32 * DT, 0.0, 0.9), facing))
            .collect();
        let demo = DemoMotion::from_clips(&m, vec![("glide".into(), poses, DT)], window(4))
            .expect("valid");
        let mut rng = SplitMix64::new(2);
        let rows = demo.sample_features(3, &mut || rng.unit());
        for f in rows.chunks(amp_frame_dim(&m)) {
            let lin = Vector::new(f[7], f[8], f[9]);
            assert!((lin - Vector::new(0.0, -v, 0.0)).length() < 1e-3, "{lin:?}");
            assert!(f[10..13].iter().all(|w| w.abs() < 1e-4), "{:?}", &f[10..13]);
        }
    }

    #[test]
    fn between_frames_a_hinge_is_at_the_interpolated_angle() {
        let m = CharacterModel::amp_humanoid();
        let (shin, dof, axis) = knee(&m);
        let root = still(&m, Vector::new(0.0, 0.0, 0.9), Rotation::IDENTITY);
        let poses = (0..4)
            .map(|k| {
                let mut p = root.clone();
                p.local_rots[shin] = Rotation::from_axis_angle(axis, 0.3 * k as f32);
                p
            })
            .collect();
        let demo =
            DemoMotion::from_clips(&m, vec![("bend".into(), poses, DT)], window(2)).expect("valid");
        assert!(
            (twist_angle(demo.pose_at(0, 1.5 * DT).local_rots[shin], axis) - 0.45).abs() < 1e-5
        );
        // Windows start one control step in (their first frame's velocity looks back one step);
        // the slack is 3 frames - 1 frame (span) - 1 frame: half of it starts the window halfway
        // between frames 1 and 2.
        let row = demo.sample_features(1, &mut replay(vec![0.0, 0.5]));
        let (rot, vel_start) = joint_offsets(&m);
        let at = rot[shin].expect("the knee is in the layout");
        let dim = amp_frame_dim(&m);
        assert!((row[at] - 0.45).abs() < 1e-5, "{}", row[at]);
        assert!((row[dim + at] - 0.75).abs() < 1e-5, "{}", row[dim + at]);
        // Velocities are in body order, one per DoF: the knee's is its DoF's rank among them.
        let rank = m
            .bodies
            .iter()
            .take(shin)
            .map(|b| match b.joint {
                JointKind::Ball { .. } => 3,
                JointKind::Hinge { .. } => 1,
                _ => 0,
            })
            .sum::<usize>();
        assert_eq!(m.dofs[dof].body, shin);
        assert!((row[vel_start + rank] - 0.3 / DT).abs() < 1e-2);
    }

    #[test]
    fn rows_are_amp_frames_of_the_motion_in_the_env_layout() {
        // Root gliding along x and turning about z, right knee bending at a constant rate: the
        // exact body states are known at any time, so each row must equal amp_frame on them.
        let m = CharacterModel::amp_humanoid();
        let (shin, _, axis) = knee(&m);
        let (v, yaw_rate, knee_rate) = (0.8f32, 2.0f32, 3.0f32);
        let pose = |t: f32| {
            let mut p = still(
                &m,
                Vector::new(v * t, 0.0, 0.88),
                Rotation::from_rotation_z(0.2 + yaw_rate * t),
            );
            p.local_rots[shin] = Rotation::from_axis_angle(axis, 0.1 + knee_rate * t);
            p
        };
        let exact = |t: f32| -> Vec<BodyState> {
            let world = forward_kinematics(&m, &pose(t));
            let below_knee = |mut i: usize| loop {
                if i == shin {
                    return true;
                }
                match m.bodies[i].parent {
                    Some(p) => i = p,
                    None => return false,
                }
            };
            let thigh = m.bodies[shin].parent.expect("thigh");
            world
                .iter()
                .enumerate()
                .map(|(i, &(pos, rot))| {
                    let mut angvel = Vector::Z * yaw_rate;
                    if below_knee(i) {
                        angvel += world[thigh].1 * axis * knee_rate;
                    }
                    BodyState {
                        pos,
                        rot,
                        // Only the root's enters the features; its centre of mass lies on the
                        // yaw axis, so turning adds nothing.
                        linvel: Vector::X * v,
                        angvel,
                    }
                })
                .collect()
        };
        let poses = (0..12).map(|k| pose(k as f32 * DT)).collect();
        let w = window(5);
        let demo = DemoMotion::from_clips(&m, vec![("turn".into(), poses, DT)], w).expect("valid");
        let u = 0.37;
        let row = demo.sample_features(1, &mut replay(vec![0.5, u]));
        assert_eq!(row.len(), demo.feature_dim());
        assert_eq!(demo.feature_dim(), 5 * amp_frame_dim(&m));
        let start = DT + u as f32 * (11.0 * DT - w.span_s() - DT);
        let expected: Vec<f32> = (0..5)
            .flat_map(|k| amp_frame(&m, &exact(start + k as f32 * DT)))
            .collect();
        let worst = row
            .iter()
            .zip(&expected)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 2e-3, "largest difference {worst}");
    }

    #[test]
    fn clips_are_picked_in_proportion_to_their_duration() {
        let m = CharacterModel::amp_humanoid();
        let clip = |z: f32, frames: usize| {
            vec![still(&m, Vector::new(0.0, 0.0, z), Rotation::IDENTITY); frames]
        };
        let demo = DemoMotion::from_clips(
            &m,
            vec![
                ("short".into(), clip(0.8, 11), DT),
                ("long".into(), clip(0.9, 31), DT),
            ],
            window(1),
        )
        .expect("valid");
        let mut rng = SplitMix64::new(3);
        let rows = demo.sample_features(400, &mut || rng.unit());
        let long = rows
            .chunks(amp_frame_dim(&m))
            .filter(|f| f[0] > 0.85)
            .count();
        assert!(
            (250..350).contains(&long),
            "{long} of 400 from the 3x longer clip"
        );
    }

    #[test]
    fn bad_clips_are_refused_by_name() {
        let m = CharacterModel::amp_humanoid();
        let pose = still(&m, Vector::new(0.0, 0.0, 0.9), Rotation::IDENTITY);
        let e = DemoMotion::from_clips(
            &m,
            vec![("hop".into(), vec![pose.clone(); 3], DT)],
            window(10),
        )
        .expect_err("2 frames cannot hold a 10-frame window")
        .to_string();
        assert!(
            e.contains("hop") && e.contains("10-frame AMP window"),
            "{e}"
        );
        // Exactly as long as the window is enough.
        assert!(DemoMotion::from_clips(
            &m,
            vec![("ok".into(), vec![pose.clone(); 10], DT)],
            window(10)
        )
        .is_ok());
        let mut wrong = pose.clone();
        wrong.local_rots.pop();
        let e = DemoMotion::from_clips(&m, vec![("odd".into(), vec![wrong; 3], DT)], window(1))
            .expect_err("another model")
            .to_string();
        assert!(e.contains("odd") && e.contains("body rotations"), "{e}");
        assert!(
            DemoMotion::from_clips(&m, vec![("one".into(), vec![pose; 1], DT)], window(1)).is_err()
        );
        assert!(DemoMotion::from_clips(&m, vec![], window(1)).is_err());
    }

    #[test]
    fn load_dir_reads_installed_deepmimic_clips() {
        let m = CharacterModel::amp_humanoid();
        let e = DemoMotion::load_dir(&m, Path::new("/nonexistent/lhm-motions"), window(2))
            .expect_err("not installed")
            .to_string();
        assert!(e.contains("scripts/install-motions"), "{e}");

        let dir = std::env::temp_dir().join(format!("lhm-demo-motion-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("deepmimic")).expect("dir");
        std::fs::write(dir.join("MANIFEST"), "").expect("manifest");
        let frame = |x: f64| {
            let mut f = vec![1.0 / 30.0, x, 0.85, 0.0, 1.0, 0.0, 0.0, 0.0];
            for (_, len) in super::super::deepmimic::JOINTS {
                f.extend(if len == 4 {
                    vec![1.0, 0.0, 0.0, 0.0]
                } else {
                    vec![0.0]
                });
            }
            f
        };
        let frames: Vec<_> = (0..12).map(|k| frame(0.05 * f64::from(k))).collect();
        let json = serde_json::json!({"Loop": "none", "Frames": frames}).to_string();
        std::fs::write(dir.join("deepmimic/walk.txt"), json).expect("write");
        let demo = DemoMotion::load_dir(&m, &dir, AmpWindow::default());
        std::fs::remove_dir_all(&dir).ok();
        let demo = demo.expect("loads");
        assert_eq!(demo.clips().map(|(n, _)| n).collect::<Vec<_>>(), ["walk"]);
        let row = demo.sample_features(1, &mut replay(vec![0.5]));
        assert_eq!(row.len(), AmpWindow::default().frames * amp_frame_dim(&m));
        // DeepMimic x is ours: 1.5 m/s forward, facing +x.
        assert!(
            (row[7] - 1.5).abs() < 1e-3 && (row[0] - 0.85).abs() < 1e-5,
            "{:?}",
            &row[..10]
        );
    }

    #[test]
    fn load_dir_reads_omomo_clips_through_the_smplh_retargeting() {
        use crate::motion::omomo_retarget::tests::{clip_file, Frame};
        use crate::motion::smplh;
        // A subject gliding along its own +x at 0.9 m/s with the left knee bent 1 rad, turned
        // to face world +y: in the heading frame the root moves forward.
        let facing = Rotation::from_rotation_z(std::f32::consts::FRAC_PI_2);
        let frames: Vec<Frame> = (0..20)
            .map(|k| {
                Frame::standing(Vector::new(0.0, 0.9 * k as f32 * DT, 0.95))
                    .with(smplh::PELVIS, facing)
                    .with(smplh::L_KNEE, Rotation::from_rotation_y(1.0))
            })
            .collect();
        let dir = std::env::temp_dir().join(format!("lhm-demo-omomo-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("omomo")).expect("dir");
        std::fs::write(dir.join("MANIFEST"), "").expect("manifest");
        std::fs::write(dir.join("omomo/glide.pt"), clip_file(&frames)).expect("write");
        let m = CharacterModel::amp_humanoid();
        let demo = DemoMotion::load_dir(&m, &dir, AmpWindow::default());
        std::fs::remove_dir_all(&dir).ok();
        let demo = demo.expect("loads without a deepmimic folder");
        let names: Vec<_> = demo.clips().collect();
        assert_eq!(names.len(), 1);
        assert_eq!(names[0].0, "glide");
        assert!((names[0].1 - 19.0 * DT).abs() < 1e-5);
        let row = demo.sample_features(1, &mut replay(vec![0.5]));
        assert_eq!(row.len(), demo.feature_dim());
        let (rot, _) = joint_offsets(&m);
        let shin = m.body_index("left_shin").expect("shin");
        let knee = rot[shin].expect("in the layout");
        for f in row.chunks(amp_frame_dim(&m)) {
            assert!(
                (f[7] - 0.9).abs() < 1e-3 && f[8].abs() < 1e-3,
                "{:?}",
                &f[7..10]
            );
            // The subject's rest knee is bent a little already: about 1 rad in all.
            assert!((f[knee] - 1.0).abs() < 0.2, "knee {}", f[knee]);
            assert!((0.7..0.9).contains(&f[0]), "root height {}", f[0]);
        }
    }
}
