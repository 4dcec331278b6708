//! OMOMO (SMPL-H) clips as poses of the character.
//!
//! **Body mapping.** Each of our bodies takes the world rotation of one SMPL-H body
//! ([`smplh`] indices): pelvis ← pelvis (the root), torso ← chest (spine3), head ← head (our neck
//! joint sums SMPL's neck and head), upper arm ← shoulder, lower arm ← elbow, hand ← wrist, thigh
//! ← hip, shin ← knee, foot ← ankle. SMPL's thorax (collar) rotation ends up in our shoulder, its
//! toes are dropped. Our abdomen joint sits where SMPL's spine1 does, so the torso is then swung
//! to point along the subject's spine1-to-neck line (keeping the chest's twist): one rigid torso
//! stands in for SMPL's three spine bodies.
//!
//! **Rest pose.** Both skeletons have identity body frames at rest, Z up, X forward, Y left, but
//! SMPL rests in a T-pose while our arms hang. So our body's world rotation is `Q_smpl · C`. For
//! an arm or leg, `C` is the shortest-arc rotation taking our straight rest limb (shoulder to
//! hand, hip to foot: the sum of our body offsets) onto SMPL's rest limb (shoulder to wrist, hip
//! to ankle), measured from the clip: the sum of the rest offsets `Q_parentᵀ (p_child − p_parent)`
//! ([`RestSkeleton`]); about 85° for the arms, 3° for the legs. The whole limb shares it, so
//! SMPL's rest limb is our straight limb and SMPL's elbow and knee rotations stay about our
//! hinge axes. (Matching each bone instead would copy SMPL's rest bends, 16° sideways at the knee
//! and 25° at the elbow in these subjects, which a hinge can only mimic by twisting the limb.)
//! Pelvis, torso, head and feet have `C = I`: both stand upright with flat feet at rest.
//!
//! **Projection onto the joints.** Joints are taken in body order, each relative to the rotation
//! its parent actually got: a 3-DoF joint becomes `Rx(a)·Ry(b)·Rz(c)` (the character's own servo
//! convention, `character::ball_target`) within its DoFs' ranges ([`super::joints::clamp_ball`]);
//! a hinge takes the rotation's twist about its axis (swing-twist), clamped. Before that, each
//! hinge's parent is twisted about its own bone so that the subject's next bone lies in the
//! hinge's plane, on the side the hinge can bend to, so the knee bends the shin toward where the
//! subject's is instead of losing the off-axis part. The twist fades in between 3° and 15° of
//! bend, where the bend plane is defined.
//!
//! **Heights.** Our pelvis origin sits at hip height, SMPL's ~0.11 m above its hips, so the root
//! is placed at the midpoint of SMPL's hips. Horizontally it keeps the subject's path unscaled (the
//! clip's box stays between the hands); vertically it is scaled by the ratio of leg lengths (hip
//! to ankle, ours / the subject's), so a squat is as deep relative to our legs. Then one height
//! shift per clip puts the feet on the floor: the lowest point of our feet is computed in every
//! frame and its median over the clip is moved to z = 0. Box carrying always has a foot on the
//! floor, so that per-frame minimum is the floor contact; the median ignores the odd frame with a
//! toe through the floor, and one shift per clip keeps the subject's own vertical motion (the
//! installed clips float 2–5 cm above z = 0 on their own).
//!
//! **Reaching.** Joint rotations alone leave our hands where our shorter torso and arms put
//! them: 15–20 cm above the box a taller subject grasps off the floor. So, last, every frame's
//! arms, spine and hip bend are moved ([`super::reach`]) until each hand is at the subject's palm
//! (halfway from the wrist to the middle finger's base), in the world, where the clip's box is;
//! the arms give first, the spine and the hips only where the arms cannot make up the distance,
//! and the legs keep their world pose, so the feet stay put.

use super::joints::project_onto_joint;
use super::omomo::OmomoClip;
use super::reach::{Goal, Reached, Reacher, RootPitch};
use super::retarget::{forward_kinematics, KinematicPose};
use super::smplh::{self, body_position, body_rotation, RestSkeleton};
use super::MotionError;
use crate::mjcf::{CharacterModel, GeomShape, JointKind};
use rapier3d::math::{Rotation, Vector};

/// How one of our bodies' rest pose relates to its SMPL-H body's.
#[derive(Clone, Copy)]
enum Rest {
    /// Same rest orientation.
    Same,
    /// Part of a limb that is straight in our rest pose and reaches from our body `ours.0` to
    /// `ours.1`; SMPL's counterpart reaches from `smpl.0` to `smpl.1`.
    Limb {
        ours: (&'static str, &'static str),
        smpl: (usize, usize),
    },
    /// Same rest orientation, then in every frame swung so that our bone toward `child` points
    /// along the subject's line from `smpl.0` to `smpl.1` (world positions).
    Aimed {
        child: &'static str,
        smpl: (usize, usize),
    },
}

const RIGHT_ARM: Rest = Rest::Limb {
    ours: ("right_upper_arm", "right_hand"),
    smpl: (smplh::R_SHOULDER, smplh::R_WRIST),
};
const LEFT_ARM: Rest = Rest::Limb {
    ours: ("left_upper_arm", "left_hand"),
    smpl: (smplh::L_SHOULDER, smplh::L_WRIST),
};
const RIGHT_LEG: Rest = Rest::Limb {
    ours: ("right_thigh", "right_foot"),
    smpl: (smplh::R_HIP, smplh::R_ANKLE),
};
const LEFT_LEG: Rest = Rest::Limb {
    ours: ("left_thigh", "left_foot"),
    smpl: (smplh::L_HIP, smplh::L_ANKLE),
};

/// Our bodies by name, the SMPL-H body each follows, and how their rest poses relate.
const MAPPING: [(&str, usize, Rest); 14] = [
    (
        "torso",
        smplh::CHEST,
        Rest::Aimed {
            child: "head",
            smpl: (smplh::TORSO, smplh::NECK),
        },
    ),
    ("head", smplh::HEAD, Rest::Same),
    ("right_upper_arm", smplh::R_SHOULDER, RIGHT_ARM),
    ("right_lower_arm", smplh::R_ELBOW, RIGHT_ARM),
    ("right_hand", smplh::R_WRIST, RIGHT_ARM),
    ("left_upper_arm", smplh::L_SHOULDER, LEFT_ARM),
    ("left_lower_arm", smplh::L_ELBOW, LEFT_ARM),
    ("left_hand", smplh::L_WRIST, LEFT_ARM),
    ("right_thigh", smplh::R_HIP, RIGHT_LEG),
    ("right_shin", smplh::R_KNEE, RIGHT_LEG),
    ("right_foot", smplh::R_ANKLE, Rest::Same),
    ("left_thigh", smplh::L_HIP, LEFT_LEG),
    ("left_shin", smplh::L_KNEE, LEFT_LEG),
    ("left_foot", smplh::L_ANKLE, Rest::Same),
];

/// One of our bodies driven by an SMPL-H body.
#[derive(Clone, Debug)]
struct Link {
    smpl: usize,
    /// Our body's world rotation is the SMPL body's times this.
    correction: Rotation,
    /// Unit direction to our body's first child, in our body frame (none for a leaf).
    bone: Option<Vector>,
    /// A bone of ours (unit, body frame) to point along the subject's line between two SMPL-H
    /// bodies.
    aim: Option<(Vector, usize, usize)>,
}

/// Per model body, its link (the root always follows SMPL's pelvis, unrotated).
fn links(model: &CharacterModel, rest: &RestSkeleton) -> Vec<Option<Link>> {
    let mut out: Vec<Option<Link>> = vec![None; model.bodies.len()];
    out[0] = Some(Link {
        smpl: smplh::PELVIS,
        correction: Rotation::IDENTITY,
        bone: first_child_direction(model, 0),
        aim: None,
    });
    for (name, smpl, how) in MAPPING {
        let Some(b) = model.body_index(name).filter(|&b| b != 0) else {
            continue;
        };
        let aim = match how {
            Rest::Aimed { child, smpl } => model
                .body_index(child)
                .and_then(|c| direction_of(model.bodies[c].pos))
                .map(|bone| (bone, smpl.0, smpl.1)),
            _ => None,
        };
        let correction = match how {
            Rest::Same | Rest::Aimed { .. } => Some(Rotation::IDENTITY),
            Rest::Limb { ours, smpl } => {
                let ours = model
                    .body_index(ours.0)
                    .zip(model.body_index(ours.1))
                    .and_then(|(from, to)| model_chain(model, from, to));
                let theirs = smpl_chain(rest, smpl.0, smpl.1);
                ours.zip(theirs).map(|(ours, theirs)| {
                    Rotation::from_rotation_arc(ours.normalize(), theirs.normalize())
                })
            }
        };
        out[b] = Some(Link {
            smpl,
            // A limb this model does not have end to end: take SMPL's rest pose as is.
            correction: correction.unwrap_or(Rotation::IDENTITY),
            bone: first_child_direction(model, b),
            aim,
        });
    }
    out
}

fn first_child_direction(model: &CharacterModel, body: usize) -> Option<Vector> {
    let child = model.bodies.iter().find(|c| c.parent == Some(body))?;
    direction_of(child.pos)
}

fn direction_of(p: [f64; 3]) -> Option<Vector> {
    Some(Vector::new(p[0] as f32, p[1] as f32, p[2] as f32))
        .filter(|v| v.length() > 1e-6)
        .map(Vector::normalize)
}

/// From our body `from` to its descendant `to` in our rest pose (all body frames aligned).
fn model_chain(model: &CharacterModel, from: usize, mut to: usize) -> Option<Vector> {
    let mut sum = Vector::ZERO;
    while to != from {
        let body = &model.bodies[to];
        sum += Vector::new(body.pos[0] as f32, body.pos[1] as f32, body.pos[2] as f32);
        to = body.parent?;
    }
    Some(sum).filter(|v| v.length() > 1e-6)
}

/// From SMPL body `from` to its descendant `to` in SMPL's rest pose (all body frames identity).
fn smpl_chain(rest: &RestSkeleton, from: usize, mut to: usize) -> Option<Vector> {
    let mut sum = Vector::ZERO;
    while to != from {
        sum += rest.offsets[to];
        to = smplh::parent(to)?;
    }
    Some(sum).filter(|v| v.length() > 1e-6)
}

/// Every frame of an OMOMO clip as a pose of `model` (see the module notes for the mapping and
/// the height choice). `file` names the clip in errors: a clip whose bodies do not form the
/// expected SMPL-H skeleton is refused.
pub fn omomo_poses(
    model: &CharacterModel,
    clip: &OmomoClip,
    file: &str,
) -> Result<Vec<KinematicPose>, MotionError> {
    let rest = RestSkeleton::from_clip(clip, file)?;
    let links = links(model, &rest);
    let height_scale = leg_length(model, &links)
        .filter(|l| *l > 0.0 && rest.leg_length() > 0.0)
        .map_or(1.0, |ours| ours / rest.leg_length());
    let mut poses: Vec<KinematicPose> = (0..clip.frames)
        .map(|t| frame_pose(model, &links, clip, t, height_scale))
        .collect();
    let floor = median(
        poses
            .iter()
            .map(|p| lowest_foot_point(model, &links, p))
            .collect(),
    );
    let reacher = Reacher {
        model,
        stiffness: reach_stiffness(&links),
        pitch: Some(HIP_BEND),
    };
    // Each frame starts from the last one's solution: see `reach`.
    let mut warm: Option<Reached> = None;
    for (t, p) in poses.iter_mut().enumerate() {
        p.root_pos.z -= floor;
        let reached = reacher.reach(p, &hand_goals(&links, clip, t), warm.as_ref());
        *p = reached.pose.clone();
        warm = Some(reached);
    }
    Ok(poses)
}

/// Reaching may bend further at the hips too (up to 45° forward, or back 20°), as firmly held
/// as the spine: a shorter character gets down to a box on the floor.
const HIP_BEND: RootPitch = RootPitch {
    stiffness: 2e-3,
    range: [-0.35, 0.8],
};

/// How firmly reaching holds each body's joint to its retargeted angles (per radian², against
/// metres² of hand error): arms give first, the spine (ten times stiffer) only bends further
/// where the arms cannot make up the distance; everything else is not on the way to a hand.
fn reach_stiffness(links: &[Option<Link>]) -> Vec<f32> {
    links
        .iter()
        .map(|l| match l.as_ref().map(|l| l.smpl) {
            Some(smplh::CHEST) => 2e-3,
            _ => 2e-4,
        })
        .collect()
}

/// Our hands at the subject's palms (halfway from the wrist to the middle finger's base), in
/// the world: where the clip's box is held.
fn hand_goals(links: &[Option<Link>], clip: &OmomoClip, t: usize) -> Vec<Goal> {
    let palm = |wrist: usize, knuckle: usize| {
        0.5 * (body_position(clip, t, wrist) + body_position(clip, t, knuckle))
    };
    links
        .iter()
        .enumerate()
        .filter_map(|(body, l)| {
            let target = match l.as_ref()?.smpl {
                smplh::L_WRIST => palm(smplh::L_WRIST, smplh::L_MIDDLE1),
                smplh::R_WRIST => palm(smplh::R_WRIST, smplh::R_MIDDLE1),
                _ => return None,
            };
            Some(Goal { body, target })
        })
        .collect()
}

/// Hip to ankle of our right leg: the offsets of the bodies following SMPL's knee and ankle.
fn leg_length(model: &CharacterModel, links: &[Option<Link>]) -> Option<f32> {
    let offset = |smpl: usize| {
        let b = links
            .iter()
            .position(|l| l.as_ref().is_some_and(|l| l.smpl == smpl))?;
        let p = model.bodies[b].pos;
        Some(Vector::new(p[0] as f32, p[1] as f32, p[2] as f32).length())
    };
    Some(offset(smplh::R_KNEE)? + offset(smplh::R_ANKLE)?)
}

fn frame_pose(
    model: &CharacterModel,
    links: &[Option<Link>],
    clip: &OmomoClip,
    t: usize,
    height_scale: f32,
) -> KinematicPose {
    let mut target: Vec<Option<Rotation>> = links
        .iter()
        .map(|l| {
            l.as_ref()
                .map(|l| (body_rotation(clip, t, l.smpl) * l.correction).normalize())
        })
        .collect();
    aim_bones(links, clip, t, &mut target);
    align_hinge_planes(model, links, &mut target);
    let n = model.bodies.len();
    let root_rot = target[0].unwrap_or(Rotation::IDENTITY);
    let mut world = vec![root_rot; n];
    let mut local_rots = vec![Rotation::IDENTITY; n];
    for b in 1..n {
        let Some(p) = model.bodies[b].parent else {
            continue;
        };
        // An unmapped body keeps its parent's rotation (identity joint).
        let want = target[b].unwrap_or(world[p]);
        local_rots[b] = project_onto_joint(model, b, world[p].inverse() * want);
        world[b] = (world[p] * local_rots[b]).normalize();
    }
    let hips = 0.5 * (body_position(clip, t, smplh::L_HIP) + body_position(clip, t, smplh::R_HIP));
    KinematicPose {
        root_pos: Vector::new(hips.x, hips.y, hips.z * height_scale),
        root_rot,
        local_rots,
    }
}

/// Swings each aimed body (see [`Rest::Aimed`]) so its bone points along the subject's line.
fn aim_bones(links: &[Option<Link>], clip: &OmomoClip, t: usize, target: &mut [Option<Rotation>]) {
    for (link, rot) in links.iter().zip(target.iter_mut()) {
        let (Some((bone, from, to)), Some(r)) = (link.as_ref().and_then(|l| l.aim), rot.as_mut())
        else {
            continue;
        };
        let line = body_position(clip, t, to) - body_position(clip, t, from);
        if line.length() > 1e-6 {
            *r = (Rotation::from_rotation_arc(*r * bone, line.normalize()) * *r).normalize();
        }
    }
}

/// Twists each hinge's parent about the parent's bone so that the hinge's own bone (the
/// subject's next limb segment) lies in the plane the hinge bends in, on the side its range
/// allows. Assumes, as for our elbows and knees, that the hinge axis is perpendicular to the
/// parent's bone and that the two bones are collinear at zero angle.
fn align_hinge_planes(
    model: &CharacterModel,
    links: &[Option<Link>],
    target: &mut [Option<Rotation>],
) {
    for (b, body) in model.bodies.iter().enumerate() {
        let (JointKind::Hinge { dof }, Some(p)) = (&body.joint, body.parent) else {
            continue;
        };
        let bones = links[p]
            .as_ref()
            .and_then(|l| l.bone)
            .zip(links[b].as_ref().and_then(|l| l.bone));
        let (Some((parent_bone, own_bone)), Some(parent_rot), Some(own_rot)) =
            (bones, target[p], target[b])
        else {
            continue;
        };
        let d = &model.dofs[*dof];
        let axis = Vector::from_array(d.axis.map(|a| a as f32));
        let u = parent_rot * parent_bone;
        let f = own_rot * own_bone;
        let normal = u.cross(f);
        let bend = normal.length();
        if bend < 1e-6 {
            continue;
        }
        // Rotating about u × f by a positive angle takes u toward f.
        let sign = if d.range[1] <= 0.0 {
            -1.0
        } else if d.range[0] >= 0.0 {
            1.0
        } else {
            (parent_rot * axis).dot(normal).signum()
        };
        let want = normal * (sign / bend);
        let h = parent_rot * axis;
        let h = (h - u * u.dot(h)).normalize_or_zero();
        let psi = h.cross(want).dot(u).atan2(h.dot(want));
        let weight = smoothstep(0.05, 0.25, bend);
        target[p] = Some((Rotation::from_axis_angle(u, weight * psi) * parent_rot).normalize());
    }
}

fn smoothstep(lo: f32, hi: f32, x: f32) -> f32 {
    let s = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

/// Lowest point (world z) of the geoms of the bodies following SMPL's ankles and toes.
fn lowest_foot_point(model: &CharacterModel, links: &[Option<Link>], pose: &KinematicPose) -> f32 {
    let world = forward_kinematics(model, pose);
    let feet = [smplh::L_ANKLE, smplh::R_ANKLE, smplh::L_TOE, smplh::R_TOE];
    let mut lowest = f32::INFINITY;
    for (b, link) in links.iter().enumerate() {
        if !link.as_ref().is_some_and(|l| feet.contains(&l.smpl)) {
            continue;
        }
        let (pos, rot) = world[b];
        let at = |p: [f64; 3]| (pos + rot * Vector::new(p[0] as f32, p[1] as f32, p[2] as f32)).z;
        for g in &model.bodies[b].geoms {
            let z = match &g.shape {
                GeomShape::Sphere { radius } => at(g.pos) - *radius as f32,
                GeomShape::Capsule { from, to, radius } => at(*from).min(at(*to)) - *radius as f32,
                GeomShape::Box { half } => (0..8)
                    .map(|k| {
                        let s = |i: usize| if k >> i & 1 == 1 { 1.0 } else { -1.0 };
                        at(std::array::from_fn(|i| g.pos[i] + s(i) * half[i]))
                    })
                    .fold(f32::INFINITY, f32::min),
            };
            lowest = lowest.min(z);
        }
    }
    if lowest.is_finite() {
        lowest
    } else {
        0.0
    }
}

/// The middle value (the lower middle of an even count); 0 for none.
fn median(mut values: Vec<f32>) -> f32 {
    values.sort_by(f32::total_cmp);
    values
        .get(values.len().saturating_sub(1) / 2)
        .copied()
        .unwrap_or(0.0)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::motion::omomo::{self, VALUES_PER_FRAME};
    use crate::obs::twist_angle;

    /// A subject's rest skeleton: the offsets of sub3_largebox_003 (rounded to mm) for the
    /// bodies the retargeting reads, so the rest-pose correction meets SMPL's real quirks
    /// (drooping shoulders, a slightly bent rest elbow, splayed legs); fingers in a row.
    fn rest_offsets() -> Vec<Vector> {
        let mut o = vec![Vector::ZERO; smplh::BODIES];
        let known: [(usize, [f32; 3]); 22] = [
            (1, [-0.022, 0.060, -0.104]),
            (2, [0.002, 0.066, -0.410]),
            (3, [-0.044, -0.050, -0.451]),
            (4, [0.149, 0.047, -0.066]),
            (5, [-0.015, -0.063, -0.116]),
            (6, [-0.007, -0.048, -0.391]),
            (7, [-0.042, 0.019, -0.466]),
            (8, [0.156, -0.037, -0.065]),
            (9, [-0.045, -0.003, 0.130]),
            (10, [0.002, 0.014, 0.178]),
            (11, [0.026, -0.011, 0.067]),
            (12, [-0.032, -0.011, 0.188]),
            (13, [0.018, 0.024, 0.165]),
            (14, [-0.006, 0.043, 0.086]),
            (15, [-0.020, 0.144, 0.070]),
            (16, [-0.049, 0.270, -0.086]),
            (17, [0.001, 0.298, 0.029]),
            (33, [-0.010, -0.048, 0.087]),
            (34, [-0.017, -0.133, 0.067]),
            (35, [-0.035, -0.290, -0.051]),
            (36, [-0.011, -0.288, 0.001]),
            (0, [0.0, 0.0, 0.0]),
        ];
        for (b, v) in known {
            o[b] = Vector::from_array(v);
        }
        for b in (18..33).chain(37..52) {
            let side = if b < 33 { 1.0 } else { -1.0 };
            o[b] = Vector::new(0.01 * ((b % 5) as f32 - 2.0), side * 0.03, -0.01);
        }
        o
    }

    /// One frame of a subject: where the pelvis is, and each body's rotation relative to its
    /// parent (the pelvis's is its world rotation); bodies not listed keep their rest pose.
    #[derive(Clone)]
    pub(crate) struct Frame {
        pub pelvis: Vector,
        pub local: Vec<(usize, Rotation)>,
    }

    impl Frame {
        pub fn standing(pelvis: Vector) -> Self {
            Self {
                pelvis,
                local: Vec::new(),
            }
        }

        pub fn with(mut self, body: usize, rot: Rotation) -> Self {
            self.local.push((body, rot));
            self
        }

        /// World positions and rotations of all 52 bodies.
        fn world(&self, rest: &[Vector]) -> (Vec<Vector>, Vec<Rotation>) {
            let mut local = vec![Rotation::IDENTITY; smplh::BODIES];
            for (b, r) in &self.local {
                local[*b] = *r;
            }
            let mut pos = vec![self.pelvis; smplh::BODIES];
            let mut rot = vec![local[0]; smplh::BODIES];
            for b in 1..smplh::BODIES {
                let p = smplh::parent(b).expect("a parent");
                pos[b] = pos[p] + rot[p] * rest[b];
                rot[b] = rot[p] * local[b];
            }
            (pos, rot)
        }

        fn values(&self, rest: &[Vector]) -> Vec<f32> {
            let (pos, rot) = self.world(rest);
            let mut v = vec![0.0; VALUES_PER_FRAME];
            v[0..3].copy_from_slice(&pos[0].to_array());
            v[3..7].copy_from_slice(&rot[0].to_array());
            for b in 0..smplh::BODIES {
                v[162 + 3 * b..165 + 3 * b].copy_from_slice(&pos[b].to_array());
                v[383 + 4 * b..387 + 4 * b].copy_from_slice(&rot[b].to_array());
            }
            v[318..325].copy_from_slice(&[1.0, 0.0, 0.185, 0.0, 0.0, 0.0, 1.0]);
            v
        }
    }

    /// The `.pt` file (a zip, as torch writes it) of a clip of these frames.
    pub(crate) fn clip_file(frames: &[Frame]) -> Vec<u8> {
        let rest = rest_offsets();
        let tensor: Vec<u8> = frames
            .iter()
            .flat_map(|f| f.values(&rest))
            .flat_map(f32::to_le_bytes)
            .collect();
        omomo::tests::zip(&[("clip/data/0", &tensor)], 0)
    }

    fn clip(frames: &[Frame]) -> OmomoClip {
        OmomoClip::parse(&clip_file(frames), "synthetic.pt").expect("parses")
    }

    /// The subject's world positions of `body` at frame `t`.
    fn subject(frames: &[Frame], t: usize, body: usize) -> Vector {
        frames[t].world(&rest_offsets()).0[body]
    }

    fn retarget(frames: &[Frame]) -> (CharacterModel, Vec<KinematicPose>) {
        let model = CharacterModel::amp_humanoid();
        let poses = omomo_poses(&model, &clip(frames), "synthetic.pt").expect("retargets");
        assert_eq!(poses.len(), frames.len());
        (model, poses)
    }

    fn index(model: &CharacterModel, name: &str) -> usize {
        model.body_index(name).expect(name)
    }

    fn hinge_angle(model: &CharacterModel, pose: &KinematicPose, body: &str) -> f32 {
        let b = index(model, body);
        let JointKind::Hinge { dof } = model.bodies[b].joint else {
            panic!("{body} is a hinge");
        };
        twist_angle(
            pose.local_rots[b],
            Vector::from_array(model.dofs[dof].axis.map(|a| a as f32)),
        )
    }

    /// Unit direction from `from` to `to`, both world positions of our bodies.
    fn direction(world: &[(Vector, Rotation)], from: usize, to: usize) -> Vector {
        (world[to].0 - world[from].0).normalize()
    }

    #[test]
    fn a_standing_subject_stands_on_the_floor_with_straight_legs() {
        // 4 cm above z = 0, as the installed clips float.
        let frames = vec![Frame::standing(Vector::new(0.3, -0.2, 0.99)); 3];
        let (m, poses) = retarget(&frames);
        let world = forward_kinematics(&m, &poses[1]);
        let hips = 0.5 * (subject(&frames, 1, smplh::L_HIP) + subject(&frames, 1, smplh::R_HIP));
        assert!((poses[1].root_pos.truncate() - hips.truncate()).length() < 1e-5);
        // Thigh 0.4215, shin 0.4099, sole 0.05 below the ankle: a little less with the splay.
        let z = poses[1].root_pos.z;
        assert!((0.865..0.882).contains(&z), "pelvis at {z}");
        let foot = index(&m, "left_foot");
        assert!(
            world[foot].1.angle_between(Rotation::IDENTITY) < 1e-3,
            "flat feet"
        );
        assert!(lowest_foot_point(&m, &links_of(&m, &frames), &poses[1]).abs() < 1e-5);
        for knee in ["left_shin", "right_shin"] {
            assert!(hinge_angle(&m, &poses[1], knee).abs() < 1e-4, "{knee}");
        }
    }

    fn rest_leg_length(frames: &[Frame]) -> f32 {
        RestSkeleton::from_clip(&clip(frames), "synthetic.pt")
            .expect("rigid")
            .leg_length()
    }

    fn links_of(model: &CharacterModel, frames: &[Frame]) -> Vec<Option<Link>> {
        let rest = RestSkeleton::from_clip(&clip(frames), "synthetic.pt").expect("rigid");
        links(model, &rest)
    }

    #[test]
    fn t_pose_arms_stay_out_to_the_sides() {
        let frames = vec![Frame::standing(Vector::new(0.0, 0.0, 0.95)); 2];
        let (m, poses) = retarget(&frames);
        let world = forward_kinematics(&m, &poses[0]);
        for (side, upper, hand, sign) in [
            ("left", "left_upper_arm", "left_hand", 1.0),
            ("right", "right_upper_arm", "right_hand", -1.0),
        ] {
            let d = direction(&world, index(&m, upper), index(&m, hand));
            assert!(d.y * sign > 0.98, "{side} arm points {d:?}");
        }
        // The subject's palms are beyond our arms' reach: they stretch, and the torso stays up.
        for elbow in ["left_lower_arm", "right_lower_arm"] {
            assert!(hinge_angle(&m, &poses[0], elbow) > -0.05, "{elbow}");
        }
        let up = world[index(&m, "torso")].1 * Vector::Z;
        assert!(up.z > 0.97, "{up:?}");
    }

    #[test]
    fn joint_rotations_alone_carry_the_rest_pose_correction() {
        // Before reaching: SMPL's T-pose is our arms out to the sides, and its elbow flexion is
        // our elbow hinge.
        let rest = rest_offsets();
        let down = |elbow: usize, wrist: usize| {
            Rotation::from_rotation_arc((rest[elbow] + rest[wrist]).normalize(), -Vector::Z)
        };
        let frames = vec![
            Frame::standing(Vector::new(0.0, 0.0, 0.95)),
            Frame::standing(Vector::new(0.0, 0.0, 0.95))
                .with(smplh::L_SHOULDER, down(smplh::L_ELBOW, smplh::L_WRIST))
                .with(smplh::L_ELBOW, Rotation::from_rotation_z(-1.2)),
        ];
        let m = CharacterModel::amp_humanoid();
        let c = clip(&frames);
        let links = links_of(&m, &frames);
        let t_pose = forward_kinematics(&m, &frame_pose(&m, &links, &c, 0, 1.0));
        for (upper, hand, sign) in [
            ("left_upper_arm", "left_hand", 1.0),
            ("right_upper_arm", "right_hand", -1.0),
        ] {
            let d = direction(&t_pose, index(&m, upper), index(&m, hand));
            assert!(d.y * sign > 0.99, "{upper}: {d:?}");
        }
        let bent = frame_pose(&m, &links, &c, 1, 1.0);
        let world = forward_kinematics(&m, &bent);
        let upper = direction(
            &world,
            index(&m, "left_upper_arm"),
            index(&m, "left_lower_arm"),
        );
        assert!(upper.z < -0.99, "the upper arm hangs: {upper:?}");
        let elbow = hinge_angle(&m, &bent, "left_lower_arm");
        assert!((elbow + 1.2).abs() < 0.03, "elbow {elbow}");
        let fore = direction(&world, index(&m, "left_lower_arm"), index(&m, "left_hand"));
        assert!(fore.x > 0.9, "the forearm points forward: {fore:?}");
    }

    /// The subject's palm: our hand's goal.
    fn palm(frames: &[Frame], t: usize, wrist: usize, knuckle: usize) -> Vector {
        0.5 * (subject(frames, t, wrist) + subject(frames, t, knuckle))
    }

    #[test]
    fn hands_reach_the_subjects_palms_with_the_elbows_bent_forward() {
        let rest = rest_offsets();
        // Both arms swung down from the T-pose, then the elbows flexed 1.4 rad (forearms toward
        // +x), as when holding a box at the belly.
        let down = |elbow: usize, wrist: usize| {
            Rotation::from_rotation_arc((rest[elbow] + rest[wrist]).normalize(), -Vector::Z)
        };
        let frame = Frame::standing(Vector::new(0.0, 0.0, 0.95))
            .with(smplh::L_SHOULDER, down(smplh::L_ELBOW, smplh::L_WRIST))
            .with(smplh::L_ELBOW, Rotation::from_rotation_z(-1.4))
            .with(smplh::R_SHOULDER, down(smplh::R_ELBOW, smplh::R_WRIST))
            .with(smplh::R_ELBOW, Rotation::from_rotation_z(1.4));
        let frames = vec![frame; 2];
        let (m, poses) = retarget(&frames);
        let world = forward_kinematics(&m, &poses[0]);
        for (hand, elbow, wrist, knuckle) in [
            (
                "left_hand",
                "left_lower_arm",
                smplh::L_WRIST,
                smplh::L_MIDDLE1,
            ),
            (
                "right_hand",
                "right_lower_arm",
                smplh::R_WRIST,
                smplh::R_MIDDLE1,
            ),
        ] {
            let target = palm(&frames, 0, wrist, knuckle);
            let at = world[index(&m, hand)].0;
            assert!(
                (at - target).length() < 0.01,
                "{hand} at {at:?}, palm {target:?}"
            );
            let angle = hinge_angle(&m, &poses[0], elbow);
            assert!(angle < -0.8, "{elbow} bends: {angle}");
            let fore = direction(&world, index(&m, elbow), index(&m, hand));
            assert!(fore.x > 0.6, "{elbow} points forward: {fore:?}");
        }
    }

    #[test]
    fn a_box_on_the_floor_is_reached_by_bending_further_than_the_subject() {
        let rest = rest_offsets();
        // The subject stoops 70° at the hips with straight legs and arms hanging: its longer
        // torso and arms get the palms lower than ours would with the same joint angles.
        let stoop = Rotation::from_rotation_y(1.2);
        let down = |elbow: usize, wrist: usize| {
            stoop.inverse()
                * Rotation::from_rotation_arc((rest[elbow] + rest[wrist]).normalize(), -Vector::Z)
        };
        let frame = Frame::standing(Vector::new(0.0, 0.0, 0.95))
            .with(smplh::PELVIS, stoop)
            .with(smplh::L_HIP, stoop.inverse())
            .with(smplh::R_HIP, stoop.inverse())
            .with(smplh::L_SHOULDER, down(smplh::L_ELBOW, smplh::L_WRIST))
            .with(smplh::R_SHOULDER, down(smplh::R_ELBOW, smplh::R_WRIST));
        let frames = vec![frame; 2];
        let (m, poses) = retarget(&frames);
        let world = forward_kinematics(&m, &poses[0]);
        let target = palm(&frames, 0, smplh::L_WRIST, smplh::L_MIDDLE1);
        let hand = world[index(&m, "left_hand")].0;
        assert!((hand - target).length() < 0.01, "{hand:?} vs {target:?}");
        // Joint rotations alone (no reaching) leave our hand well short of it.
        let c = clip(&frames);
        let links = links_of(&m, &frames);
        let scale = leg_length(&m, &links).expect("legs") / rest_leg_length(&frames);
        let unreached = forward_kinematics(&m, &frame_pose(&m, &links, &c, 0, scale));
        let unreached_root = unreached[0].0;
        let short =
            (unreached[index(&m, "left_hand")].0 - unreached_root) - (target - poses[0].root_pos);
        assert!(short.length() > 0.05, "{short:?}");
        // The feet stay flat on the floor through it all.
        for foot in ["left_foot", "right_foot"] {
            let f = world[index(&m, foot)].1;
            assert!(f.angle_between(Rotation::IDENTITY) < 0.05, "{foot}");
        }
    }

    #[test]
    fn a_bent_knee_bends_our_knee_as_far_and_keeps_the_foot_flat() {
        let frame = Frame::standing(Vector::new(0.0, 0.0, 0.8))
            .with(smplh::L_HIP, Rotation::from_rotation_y(-0.8))
            .with(smplh::L_KNEE, Rotation::from_rotation_y(1.2))
            .with(smplh::L_ANKLE, Rotation::from_rotation_y(-0.4));
        let frames = vec![frame; 2];
        let (m, poses) = retarget(&frames);
        let knee = hinge_angle(&m, &poses[0], "left_shin");
        assert!((knee - 1.2).abs() < 0.02, "knee {knee}");
        let world = forward_kinematics(&m, &poses[0]);
        let (thigh, shin, foot) = (
            index(&m, "left_thigh"),
            index(&m, "left_shin"),
            index(&m, "left_foot"),
        );
        // The subject's ankle ends up level: so does our foot.
        assert!(world[foot].1.angle_between(Rotation::IDENTITY) < 1e-3);
        assert!(world[foot].0.x < world[shin].0.x, "the shin slopes back");
        assert!(
            world[shin].0.x > world[thigh].0.x + 0.2,
            "the thigh reaches forward"
        );
        let theirs = subject(&frames, 0, smplh::L_ANKLE) - subject(&frames, 0, smplh::L_HIP);
        let ours = world[foot].0 - world[thigh].0;
        assert!(theirs.angle_between(ours) < 0.1, "{theirs:?} vs {ours:?}");
    }

    #[test]
    fn a_turned_subject_turns_the_root() {
        let yaw = Rotation::from_rotation_z(0.7);
        let frames = vec![Frame::standing(Vector::new(1.0, 2.0, 0.95)).with(smplh::PELVIS, yaw); 2];
        let (m, poses) = retarget(&frames);
        // Reaching may tilt the pelvis a little (the subject's palms are out of reach).
        assert!(poses[0].root_rot.angle_between(yaw) < 0.1);
        let forward = poses[0].root_rot * Vector::X;
        assert!(
            (forward.y.atan2(forward.x) - 0.7).abs() < 1e-3,
            "{forward:?}"
        );
        let world = forward_kinematics(&m, &poses[0]);
        // The left foot sits to the left of the turned body: along the rotated +y.
        let left = (world[index(&m, "left_foot")].0 - poses[0].root_pos).dot(yaw * Vector::Y);
        assert!(left > 0.05, "{left}");
    }

    #[test]
    fn a_clip_in_another_body_order_is_refused() {
        let mut frames = vec![Frame::standing(Vector::new(0.0, 0.0, 0.95)); 3];
        frames[2] = frames[2]
            .clone()
            .with(smplh::L_KNEE, Rotation::from_rotation_y(1.0));
        let mut bytes = clip_file(&frames);
        // Swap the stored positions of the left knee and ankle in every frame: the ankle now
        // seems to hang off the hip, which only a rigid skeleton in another order could do.
        let clip = OmomoClip::parse(&bytes, "x.pt").expect("parses");
        // The tensor follows the entry's 30-byte local header and name.
        let data_start = 30 + "clip/data/0".len();
        for t in 0..clip.frames {
            let at = |b: usize| data_start + 4 * (t * VALUES_PER_FRAME + 162 + 3 * b);
            let (knee, ankle) = (at(smplh::L_KNEE), at(smplh::L_ANKLE));
            for k in 0..12 {
                bytes.swap(knee + k, ankle + k);
            }
        }
        let clip = OmomoClip::parse(&bytes, "swapped.pt").expect("parses");
        let e = omomo_poses(&CharacterModel::amp_humanoid(), &clip, "swapped.pt")
            .expect_err("not rigid")
            .to_string();
        assert!(e.contains("swapped.pt") && e.contains("frame 2"), "{e}");
    }
}
