//! The installed clips: what there is and how long each is.

use super::deepmimic::DeepMimicClip;
use super::omomo::OmomoClip;
use super::MotionError;
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    DeepMimic,
    Omomo,
}

#[derive(Clone, Debug)]
pub struct ClipInfo {
    pub name: String,
    pub source: Source,
    pub frames: usize,
    pub duration_s: f32,
}

/// The clip files of one source under `dir` (as laid out by `scripts/install-motions`), sorted
/// by path, each with its clip name (the file stem).
pub fn clip_files(dir: &Path, source: Source) -> Result<Vec<(String, PathBuf)>, MotionError> {
    if !dir.join("MANIFEST").is_file() {
        return Err(MotionError::NotInstalled {
            path: dir.display().to_string(),
        });
    }
    let folder = dir.join(match source {
        Source::DeepMimic => "deepmimic",
        Source::Omomo => "omomo",
    });
    let entries = std::fs::read_dir(&folder).map_err(|source| MotionError::Io {
        file: folder.display().to_string(),
        source,
    })?;
    let mut paths: Vec<_> = entries.filter_map(Result::ok).map(|e| e.path()).collect();
    paths.sort();
    Ok(paths
        .into_iter()
        .map(|path| {
            let name = path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            (name, path)
        })
        .collect())
}

/// Parses every clip under `dir` (as laid out by `scripts/install-motions`).
pub fn list(dir: &Path) -> Result<Vec<ClipInfo>, MotionError> {
    let mut out = Vec::new();
    for source in [Source::DeepMimic, Source::Omomo] {
        for (name, path) in clip_files(dir, source)? {
            let file = path.display().to_string();
            let read_err = |source| MotionError::Io {
                file: file.clone(),
                source,
            };
            let (frames, duration_s) = match source {
                Source::DeepMimic => {
                    let c = DeepMimicClip::parse(
                        &std::fs::read_to_string(&path).map_err(read_err)?,
                        &file,
                    )?;
                    (c.frames.len(), c.duration())
                }
                Source::Omomo => {
                    let c = OmomoClip::parse(&std::fs::read(&path).map_err(read_err)?, &file)?;
                    (c.frames, c.duration())
                }
            };
            out.push(ClipInfo {
                name,
                source,
                frames,
                duration_s,
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_install_says_how_to_install() {
        let e = list(Path::new("/nonexistent/lhm-motions"))
            .expect_err("not installed")
            .to_string();
        assert!(e.contains("scripts/install-motions"), "{e}");
    }

    #[test]
    fn lists_a_synthetic_install() {
        let dir = std::env::temp_dir().join(format!("lhm-motion-lib-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("deepmimic")).expect("dir");
        std::fs::create_dir_all(dir.join("omomo")).expect("dir");
        std::fs::write(dir.join("MANIFEST"), "").expect("manifest");
        let mut frame = vec![1.0 / 30.0, 0.0, 0.85, 0.0, 1.0, 0.0, 0.0, 0.0];
        for (_, len) in super::super::deepmimic::JOINTS {
            frame.extend(if len == 4 {
                vec![1.0, 0.0, 0.0, 0.0]
            } else {
                vec![0.0]
            });
        }
        let json =
            serde_json::json!({"Loop": "none", "Frames": [frame.clone(), frame.clone(), frame]})
                .to_string();
        std::fs::write(dir.join("deepmimic/walk.txt"), json).expect("write");
        let tensor: Vec<u8> = vec![0u8; 4 * super::super::omomo::VALUES_PER_FRAME * 31];
        let pt = super::super::omomo::tests::zip(&[("c/data/0", &tensor)], 0);
        std::fs::write(dir.join("omomo/lift.pt"), pt).expect("write");
        let clips = list(&dir).expect("lists");
        assert_eq!(clips.len(), 2);
        assert_eq!((clips[0].name.as_str(), clips[0].frames), ("walk", 3));
        assert_eq!(
            (clips[1].name.as_str(), clips[1].source, clips[1].frames),
            ("lift", Source::Omomo, 31)
        );
        assert!((clips[1].duration_s - 1.0).abs() < 1e-6);
        std::fs::remove_dir_all(&dir).ok();
    }
}
