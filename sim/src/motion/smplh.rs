//! The SMPL-H skeleton as the OMOMO clips of holosoma-retargeting store it, and its rest pose
//! measured from a clip.
//!
//! The 52 bodies are **not** in SMPL-H's own joint order (pelvis, L_hip, R_hip, spine1, ...) but
//! in depth-first tree order, one limb after the other, as a MuJoCo SMPL-H humanoid lists its
//! bodies: pelvis; left leg (hip, knee, ankle, toe); right leg; spine (torso, spine, chest), neck,
//! head; left arm (thorax/collar, shoulder, elbow, wrist, 15 finger bodies); right arm. This was
//! read off the installed clips, not assumed: with these parents every child's offset in its
//! parent's body frame, `Q_parentᵀ (p_child − p_parent)`, is the same in every frame (to 1e-5 m),
//! and the offsets put the left limbs at +y, toes at +x, the head at +z. The body frames are
//! Z up, X forward, Y left, and all identity in SMPL's rest pose (a T-pose: arms along ±y).
//! [`RestSkeleton::from_clip`] checks the rigidity again on every clip it reads, so a clip in
//! another order is refused rather than retargeted into nonsense.

use super::omomo::OmomoClip;
use super::MotionError;
use rapier3d::math::{Rotation, Vector};

pub const BODIES: usize = 52;

pub const PELVIS: usize = 0;
pub const L_HIP: usize = 1;
pub const L_KNEE: usize = 2;
pub const L_ANKLE: usize = 3;
pub const L_TOE: usize = 4;
pub const R_HIP: usize = 5;
pub const R_KNEE: usize = 6;
pub const R_ANKLE: usize = 7;
pub const R_TOE: usize = 8;
pub const TORSO: usize = 9;
pub const SPINE: usize = 10;
pub const CHEST: usize = 11;
pub const NECK: usize = 12;
pub const HEAD: usize = 13;
pub const L_THORAX: usize = 14;
pub const L_SHOULDER: usize = 15;
pub const L_ELBOW: usize = 16;
pub const L_WRIST: usize = 17;
/// Base of the left middle finger (the knuckle), the second of the left hand's finger chains.
pub const L_MIDDLE1: usize = 21;
pub const R_THORAX: usize = 33;
pub const R_SHOULDER: usize = 34;
pub const R_ELBOW: usize = 35;
pub const R_WRIST: usize = 36;
pub const R_MIDDLE1: usize = 40;

/// First finger body of each hand: index, middle, pinky, ring, thumb, 3 bodies each, in a chain
/// from the wrist.
const L_FINGERS: usize = 18;
const R_FINGERS: usize = 37;

/// Each body's parent (`None` for the pelvis).
pub fn parent(body: usize) -> Option<usize> {
    let finger = |first: usize, wrist: usize| {
        // Three bodies per finger: the first hangs off the wrist, the others off the previous.
        if (body - first) % 3 == 0 {
            wrist
        } else {
            body - 1
        }
    };
    match body {
        PELVIS => None,
        L_HIP | R_HIP | TORSO => Some(PELVIS),
        L_THORAX | R_THORAX => Some(CHEST),
        b if (L_FINGERS..L_FINGERS + 15).contains(&b) => Some(finger(L_FINGERS, L_WRIST)),
        b if (R_FINGERS..R_FINGERS + 15).contains(&b) => Some(finger(R_FINGERS, R_WRIST)),
        b if b < BODIES => Some(b - 1),
        _ => None,
    }
}

/// Largest change of a child's offset in its parent's frame over a clip that still counts as
/// one rigid skeleton (metres). The installed clips stay within 1e-5 m; the wrong tree gives
/// decimetres as soon as anything moves.
const RIGID_TOLERANCE: f32 = 0.01;

/// Where each body sits in its parent's frame in the rest pose, measured from a clip.
#[derive(Clone, Debug, PartialEq)]
pub struct RestSkeleton {
    /// Per body: its origin in its parent's body frame (zero for the pelvis).
    pub offsets: Vec<Vector>,
}

impl RestSkeleton {
    /// The mean offset of every body over all frames of `clip`. Refuses (naming `file`, the body
    /// and its worst frame) a clip in which some offset moves by more than [`RIGID_TOLERANCE`]: its
    /// bodies are not in the order this module describes.
    pub fn from_clip(clip: &OmomoClip, file: &str) -> Result<Self, MotionError> {
        let mut offsets = vec![Vector::ZERO; BODIES];
        for (body, offset) in offsets.iter_mut().enumerate() {
            let Some(p) = parent(body) else { continue };
            let measured: Vec<Vector> = (0..clip.frames)
                .map(|t| offset_in_parent(clip, t, p, body))
                .collect();
            let mean = measured.iter().copied().sum::<Vector>() / measured.len().max(1) as f32;
            let worst = measured
                .iter()
                .map(|m| (*m - mean).length())
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(&b.1));
            if let Some((t, d)) = worst.filter(|(_, d)| *d > RIGID_TOLERANCE) {
                return Err(MotionError::Corrupt {
                    file: file.into(),
                    message: format!(
                        "frame {t}: SMPL-H body {body} moves {d:.3} m in its parent {p}'s frame; \
                         the clip's bodies are not in the expected (depth-first) order"
                    ),
                });
            }
            *offset = mean;
        }
        Ok(Self { offsets })
    }

    /// Hip to knee plus knee to ankle, averaged over both legs.
    pub fn leg_length(&self) -> f32 {
        let leg =
            |knee: usize, ankle: usize| self.offsets[knee].length() + self.offsets[ankle].length();
        0.5 * (leg(L_KNEE, L_ANKLE) + leg(R_KNEE, R_ANKLE))
    }
}

/// World rotation of `body` at frame `t`: the stored quaternion is x, y, z, w (the same numbers
/// as the clip's root quaternion for the pelvis), normalised.
pub fn body_rotation(clip: &OmomoClip, t: usize, body: usize) -> Rotation {
    let [x, y, z, w] = clip.body_quat(t, body);
    Rotation::from_xyzw(x, y, z, w).normalize()
}

pub fn body_position(clip: &OmomoClip, t: usize, body: usize) -> Vector {
    Vector::from_array(clip.joint_pos(t, body))
}

fn offset_in_parent(clip: &OmomoClip, t: usize, parent: usize, body: usize) -> Vector {
    body_rotation(clip, t, parent).inverse()
        * (body_position(clip, t, body) - body_position(clip, t, parent))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_body_but_the_pelvis_has_an_earlier_parent() {
        assert_eq!(parent(PELVIS), None);
        for b in 1..BODIES {
            let p = parent(b).expect("a parent");
            assert!(p < b, "body {b} parent {p}");
        }
        assert_eq!(parent(L_TOE), Some(L_ANKLE));
        assert_eq!(parent(R_HIP), Some(PELVIS));
        assert_eq!(parent(NECK), Some(CHEST));
        assert_eq!(parent(L_SHOULDER), Some(L_THORAX));
        assert_eq!(parent(R_THORAX), Some(CHEST));
        assert_eq!(parent(R_WRIST), Some(R_ELBOW));
        assert_eq!(parent(L_FINGERS), Some(L_WRIST));
        assert_eq!(parent(L_FINGERS + 2), Some(L_FINGERS + 1));
        assert_eq!(parent(L_FINGERS + 3), Some(L_WRIST));
        assert_eq!(parent(R_FINGERS + 14), Some(R_FINGERS + 13));
        assert_eq!(parent(BODIES), None);
    }
}
