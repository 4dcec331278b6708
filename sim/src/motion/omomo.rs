//! OMOMO clips as shipped by holosoma-retargeting: a PyTorch `.pt` file, which is a zip archive
//! whose `*/data/0` entry is the raw little-endian f32 tensor, T frames × 591 values, 30 fps, Z up:
//! [0:3] root position, [3:7] root quaternion (x, y, z, w), [162:318] 52 × 3 world joint positions,
//! [318:325] box pose, [383:591] 52 × 4 world body quaternions of the SMPL-H skeleton. The 52
//! bodies come in depth-first tree order, not SMPL-H's own joint order, and the quaternions are
//! x, y, z, w like the root's: see [`super::smplh`].
//!
//! torch stores these entries uncompressed, so a small reader of the zip's central directory
//! suffices; a compressed or truncated entry is an error, never a guess.

use super::MotionError;

pub const VALUES_PER_FRAME: usize = 591;
pub const FPS: f32 = 30.0;

#[derive(Clone, Debug, PartialEq)]
pub struct OmomoClip {
    pub frames: usize,
    data: Vec<f32>,
}

impl OmomoClip {
    pub fn duration(&self) -> f32 {
        self.frames.saturating_sub(1) as f32 / FPS
    }

    fn frame(&self, t: usize) -> &[f32] {
        &self.data[t * VALUES_PER_FRAME..(t + 1) * VALUES_PER_FRAME]
    }

    pub fn root_pos(&self, t: usize) -> [f32; 3] {
        let f = self.frame(t);
        [f[0], f[1], f[2]]
    }

    /// x, y, z, w
    pub fn root_quat(&self, t: usize) -> [f32; 4] {
        let f = self.frame(t);
        [f[3], f[4], f[5], f[6]]
    }

    /// World position of SMPL-H joint `j` (0..52, in [`super::smplh`]'s order).
    pub fn joint_pos(&self, t: usize, j: usize) -> [f32; 3] {
        let f = &self.frame(t)[162 + 3 * j..];
        [f[0], f[1], f[2]]
    }

    /// The box's pose: position (3) and quaternion (4, x, y, z, w: with it the hands keep fixed
    /// coordinates in the box's frame while carrying). The position is the OMOMO mesh's origin,
    /// a few centimetres off the box's centre.
    pub fn box_pose(&self, t: usize) -> [f32; 7] {
        let f = &self.frame(t)[318..325];
        [f[0], f[1], f[2], f[3], f[4], f[5], f[6]]
    }

    /// World rotation of SMPL-H body `j` (0..52), as stored: x, y, z, w (body 0's equals
    /// [`Self::root_quat`] in the installed clips).
    pub fn body_quat(&self, t: usize, j: usize) -> [f32; 4] {
        let f = &self.frame(t)[383 + 4 * j..];
        [f[0], f[1], f[2], f[3]]
    }

    pub fn parse(bytes: &[u8], file: &str) -> Result<Self, MotionError> {
        let corrupt = |message: String| MotionError::Corrupt {
            file: file.into(),
            message,
        };
        let data = stored_entry(bytes, |name| name.ends_with("/data/0")).map_err(corrupt)?;
        let stride = VALUES_PER_FRAME * 4;
        if data.is_empty() || data.len() % stride != 0 {
            return Err(MotionError::Corrupt {
                file: file.into(),
                message: format!(
                    "tensor of {} bytes is not a whole number of {VALUES_PER_FRAME}-value frames",
                    data.len()
                ),
            });
        }
        let values: Vec<f32> = data
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        if let Some(i) = values.iter().position(|x| !x.is_finite()) {
            return Err(MotionError::Corrupt {
                file: file.into(),
                message: format!(
                    "frame {}: value {} is not finite",
                    i / VALUES_PER_FRAME,
                    i % VALUES_PER_FRAME
                ),
            });
        }
        Ok(Self {
            frames: values.len() / VALUES_PER_FRAME,
            data: values,
        })
    }
}

/// The contents of the first stored (uncompressed) zip entry whose name satisfies `want`, found
/// through the archive's central directory (local headers may defer sizes to a data descriptor).
fn stored_entry(bytes: &[u8], want: impl Fn(&str) -> bool) -> Result<&[u8], String> {
    let u16_at = |at: usize| {
        bytes
            .get(at..at + 2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]) as usize)
    };
    let u32_at = |at: usize| {
        bytes
            .get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    // End of central directory: 22 bytes plus a comment of at most 64 KiB, at the end.
    let lowest = bytes.len().saturating_sub(22 + 0xFFFF);
    let eocd = (lowest..bytes.len().saturating_sub(21))
        .rev()
        .find(|&at| u32_at(at) == Some(0x0605_4b50))
        .ok_or("no end-of-central-directory record: not a zip archive, or truncated")?;
    let entries = u16_at(eocd + 10).ok_or("truncated end record")?;
    let mut at = u32_at(eocd + 16).ok_or("truncated end record")?;
    if at == 0xFFFF_FFFF {
        return Err("zip64 archives are not supported".into());
    }
    for _ in 0..entries {
        if u32_at(at) != Some(0x0201_4b50) {
            return Err(format!("central directory entry at byte {at} is damaged"));
        }
        let field = |off: usize| {
            u16_at(at + off)
                .ok_or_else(|| format!("central directory entry at byte {at} is truncated"))
        };
        let method = field(10)?;
        let size = u32_at(at + 20).ok_or("truncated central directory")?;
        let (name_len, extra_len, comment_len) = (field(28)?, field(30)?, field(32)?);
        let local = u32_at(at + 42).ok_or("truncated central directory")?;
        let name = bytes
            .get(at + 46..at + 46 + name_len)
            .ok_or("truncated central directory")?;
        let name = String::from_utf8_lossy(name).into_owned();
        if want(&name) {
            if method != 0 {
                return Err(format!(
                    "zip entry {name:?} is compressed (method {method}); expected stored"
                ));
            }
            if u32_at(local) != Some(0x0403_4b50) {
                return Err(format!("zip entry {name:?}: local header missing"));
            }
            let (n, e) = (u16_at(local + 26), u16_at(local + 28));
            let (Some(n), Some(e)) = (n, e) else {
                return Err(format!("zip entry {name:?} is truncated"));
            };
            let start = local + 30 + n + e;
            return bytes
                .get(start..start + size)
                .ok_or_else(|| format!("zip entry {name:?} is truncated"));
        }
        at += 46 + name_len + extra_len + comment_len;
    }
    Err("no `*/data/0` tensor entry: not a PyTorch-saved OMOMO clip".into())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A minimal zip with a central directory, entries stored (`method` 0) as torch writes them.
    pub(crate) fn zip(entries: &[(&str, &[u8])], method: u16) -> Vec<u8> {
        let mut out = Vec::new();
        let mut central = Vec::new();
        for (name, data) in entries {
            let offset = out.len() as u32;
            let header = |sig: u32, out: &mut Vec<u8>| {
                out.extend_from_slice(&sig.to_le_bytes());
                if sig == 0x0201_4b50 {
                    out.extend_from_slice(&20u16.to_le_bytes()); // version made by
                }
                out.extend_from_slice(&20u16.to_le_bytes());
                out.extend_from_slice(&0u16.to_le_bytes());
                out.extend_from_slice(&method.to_le_bytes());
                out.extend_from_slice(&[0; 8]); // time, date, crc (not checked)
                out.extend_from_slice(&(data.len() as u32).to_le_bytes());
                out.extend_from_slice(&(data.len() as u32).to_le_bytes());
                out.extend_from_slice(&(name.len() as u16).to_le_bytes());
                out.extend_from_slice(&0u16.to_le_bytes());
            };
            header(0x0403_4b50, &mut out);
            out.extend_from_slice(name.as_bytes());
            out.extend_from_slice(data);
            header(0x0201_4b50, &mut central);
            central.extend_from_slice(&[0; 6]); // comment length, disk, internal attributes
            central.extend_from_slice(&[0; 4]); // external attributes
            central.extend_from_slice(&offset.to_le_bytes());
            central.extend_from_slice(name.as_bytes());
        }
        let cd_offset = out.len() as u32;
        out.extend_from_slice(&central);
        out.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
        out.extend_from_slice(&[0; 4]);
        out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
        out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
        out.extend_from_slice(&(central.len() as u32).to_le_bytes());
        out.extend_from_slice(&cd_offset.to_le_bytes());
        out.extend_from_slice(&0u16.to_le_bytes());
        out
    }

    fn tensor(frames: usize) -> Vec<u8> {
        (0..frames * VALUES_PER_FRAME)
            .flat_map(|i| (i as f32 * 0.001).to_le_bytes())
            .collect()
    }

    #[test]
    fn parses_a_synthetic_pt_file() {
        let bytes = zip(
            &[
                ("clip/data.pkl", b"pickle"),
                ("clip/data/0", &tensor(3)),
                ("clip/version", b"3"),
            ],
            0,
        );
        let c = OmomoClip::parse(&bytes, "clip.pt").expect("parses");
        assert_eq!(c.frames, 3);
        assert!((c.duration() - 2.0 / 30.0).abs() < 1e-6);
        let base = VALUES_PER_FRAME as f32 * 0.001;
        assert!((c.root_pos(1)[0] - base).abs() < 1e-5);
        assert!((c.joint_pos(0, 1)[0] - 0.165).abs() < 1e-5);
        assert!((c.body_quat(2, 51)[3] - (2.0 * base + 0.590)).abs() < 1e-4);
    }

    #[test]
    fn broken_files_are_clear_errors() {
        let good = zip(&[("clip/data/0", &tensor(2))], 0);
        for cut in [10, 40, good.len() - 100] {
            let e = OmomoClip::parse(&good[..cut], "clip.pt")
                .expect_err("truncated")
                .to_string();
            assert!(e.contains("clip.pt"), "{e}");
        }
        let compressed = zip(&[("clip/data/0", &tensor(2))], 8);
        assert!(OmomoClip::parse(&compressed, "clip.pt")
            .expect_err("deflate")
            .to_string()
            .contains("compressed"));
        let ragged = zip(&[("clip/data/0", &tensor(2)[..100])], 0);
        assert!(OmomoClip::parse(&ragged, "clip.pt")
            .expect_err("ragged")
            .to_string()
            .contains("whole number"));
        let mut nan = tensor(1);
        nan[8..12].copy_from_slice(&f32::NAN.to_le_bytes());
        let e = OmomoClip::parse(&zip(&[("clip/data/0", &nan)], 0), "clip.pt")
            .expect_err("nan")
            .to_string();
        assert!(e.contains("frame 0: value 2 is not finite"), "{e}");
        assert!(OmomoClip::parse(b"not a zip", "clip.pt").is_err());
    }
}
