//! DeepMimic motion files: JSON `{"Loop": ..., "Frames": [[...44 numbers...], ...]}` at 30 fps,
//! Y up. Per frame: the frame's duration, root position (3), root rotation (quaternion w, x, y, z),
//! then the joints of the DeepMimic humanoid in [`JOINTS`] order, 4 numbers (a quaternion w, x, y, z)
//! for a 3-DoF joint and 1 (an angle, radians) for a hinge.

use super::MotionError;
use serde::Deserialize;

/// DeepMimic humanoid joints in file order, with their number of values; the names are this
/// project's character's bodies they drive.
pub const JOINTS: [(&str, usize); 12] = [
    ("torso", 4),
    ("head", 4),
    ("right_thigh", 4),
    ("right_shin", 1),
    ("right_foot", 4),
    ("right_upper_arm", 4),
    ("right_lower_arm", 1),
    ("left_thigh", 4),
    ("left_shin", 1),
    ("left_foot", 4),
    ("left_upper_arm", 4),
    ("left_lower_arm", 1),
];

pub const FRAME_LEN: usize = 44;

#[derive(Clone, Debug, PartialEq)]
pub struct DeepMimicFrame {
    /// Seconds until the next frame.
    pub duration: f32,
    pub root_pos: [f32; 3],
    /// w, x, y, z
    pub root_rot: [f32; 4],
    /// Per [`JOINTS`] entry: a quaternion (w, x, y, z) or `[angle, 0, 0, 0]` for a hinge.
    pub joints: Vec<[f32; 4]>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct DeepMimicClip {
    pub looped: bool,
    pub frames: Vec<DeepMimicFrame>,
}

impl DeepMimicClip {
    /// Length in seconds: the durations of every frame but the last.
    pub fn duration(&self) -> f32 {
        let n = self.frames.len().saturating_sub(1);
        self.frames[..n].iter().map(|f| f.duration).sum()
    }

    pub fn parse(text: &str, file: &str) -> Result<Self, MotionError> {
        #[derive(Deserialize)]
        struct Raw {
            #[serde(rename = "Loop", default)]
            looped: Option<String>,
            #[serde(rename = "Frames")]
            frames: Vec<Vec<f64>>,
        }
        let corrupt = |message: String| MotionError::Corrupt {
            file: file.into(),
            message,
        };
        let raw: Raw = serde_json::from_str(text)
            .map_err(|e| corrupt(format!("not a DeepMimic clip: {e}")))?;
        if raw.frames.len() < 2 {
            return Err(corrupt(format!(
                "{} frames; a clip needs at least 2",
                raw.frames.len()
            )));
        }
        let mut frames = Vec::with_capacity(raw.frames.len());
        for (i, f) in raw.frames.iter().enumerate() {
            if f.len() != FRAME_LEN {
                return Err(corrupt(format!(
                    "frame {i}: {} numbers, expected {FRAME_LEN}",
                    f.len()
                )));
            }
            if let Some(k) = f.iter().position(|x| !x.is_finite()) {
                return Err(corrupt(format!("frame {i}: value {k} is not finite")));
            }
            let v: Vec<f32> = f.iter().map(|x| *x as f32).collect();
            let quat = |at: usize, what: &str| -> Result<[f32; 4], MotionError> {
                let q = [v[at], v[at + 1], v[at + 2], v[at + 3]];
                let norm = q.iter().map(|x| x * x).sum::<f32>().sqrt();
                if (norm - 1.0).abs() > 0.05 {
                    return Err(corrupt(format!(
                        "frame {i}: {what} quaternion has norm {norm}"
                    )));
                }
                Ok(q.map(|x| x / norm))
            };
            let mut at = 8;
            let mut joints = Vec::with_capacity(JOINTS.len());
            for (name, len) in JOINTS {
                joints.push(if len == 4 {
                    quat(at, name)?
                } else {
                    [v[at], 0.0, 0.0, 0.0]
                });
                at += len;
            }
            if v[0] < 0.0 {
                return Err(corrupt(format!("frame {i}: negative duration {}", v[0])));
            }
            frames.push(DeepMimicFrame {
                duration: v[0],
                root_pos: [v[1], v[2], v[3]],
                root_rot: quat(4, "root")?,
                joints,
            });
        }
        Ok(Self {
            looped: raw.looped.as_deref() == Some("wrap"),
            frames,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(dt: f64, x: f64) -> Vec<f64> {
        let mut f = vec![dt, x, 0.85, 0.0, 1.0, 0.0, 0.0, 0.0];
        for (_, len) in JOINTS {
            f.extend(if len == 4 {
                vec![1.0, 0.0, 0.0, 0.0]
            } else {
                vec![-0.3]
            });
        }
        f
    }

    fn clip(frames: &[Vec<f64>]) -> String {
        serde_json::json!({"Loop": "wrap", "Frames": frames}).to_string()
    }

    #[test]
    fn parses_a_synthetic_clip() {
        let text = clip(&[
            frame(1.0 / 30.0, 0.0),
            frame(1.0 / 30.0, 0.05),
            frame(0.0, 0.1),
        ]);
        let c = DeepMimicClip::parse(&text, "walk.txt").expect("parses");
        assert!(c.looped);
        assert_eq!(c.frames.len(), 3);
        assert!((c.duration() - 2.0 / 30.0).abs() < 1e-6);
        assert_eq!(c.frames[1].root_pos, [0.05, 0.85, 0.0]);
        assert_eq!(c.frames[0].joints.len(), 12);
        assert_eq!(
            c.frames[0].joints[3],
            [-0.3, 0.0, 0.0, 0.0],
            "right knee is a hinge angle"
        );
    }

    #[test]
    fn malformed_clips_name_the_frame() {
        let mut short = frame(0.03, 0.0);
        short.pop();
        let e =
            DeepMimicClip::parse(&clip(&[frame(0.03, 0.0), short]), "walk.txt").expect_err("short");
        assert!(
            e.to_string().contains("walk.txt") && e.to_string().contains("frame 1: 43 numbers"),
            "{e}"
        );
        let mut bad = frame(0.03, 0.0);
        bad[4] = 3.0;
        let e = DeepMimicClip::parse(&clip(&[bad, frame(0.0, 0.0)]), "walk.txt").expect_err("quat");
        assert!(e.to_string().contains("frame 0: root quaternion"), "{e}");
        assert!(DeepMimicClip::parse("{", "walk.txt").is_err());
    }
}
