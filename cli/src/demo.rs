//! Demo AMP features for the learner's discriminator, from the installed motion clips.

use std::path::PathBuf;

use anyhow::{Context, Result};
use lhm_learner::service::{DemoSource, TrainConfig};
use lhm_nets::SplitMix64;
use lhm_sim::motion::{AmpWindow, DemoMotion};
use lhm_sim::CharacterModel;

struct ClipFeatures {
    motion: DemoMotion,
    rng: SplitMix64,
}

impl DemoSource for ClipFeatures {
    fn sample(&mut self, rows: usize) -> Vec<f32> {
        let rng = &mut self.rng;
        self.motion
            .sample_features(rows, &mut || rng.uniform(0.0, 1.0))
    }
}

/// Loads every installed clip (DeepMimic and OMOMO), windowed like the environment's AMP history,
/// sampled by `[amp] demo_weights`.
pub fn load(dir: Option<PathBuf>, config: &TrainConfig) -> Result<Box<dyn DemoSource>> {
    let dir = dir.unwrap_or_else(lhm_sim::motion::default_dir);
    let model = CharacterModel::amp_humanoid();
    let motion = DemoMotion::load_dir(&model, &dir, AmpWindow::of(&config.env, &config.sim))
        .with_context(|| {
            format!(
                "AMP needs reference motion from {} (run scripts/install-motions, pass \
                 --motion-dir, or train without AMP with --no-amp)",
                dir.display()
            )
        })?
        .with_source_weights(config.amp.demo_weights)?;
    let clips: Vec<String> = motion
        .clips()
        .map(|(name, d)| format!("{name} {d:.1}s"))
        .collect();
    tracing::info!(
        "AMP demo motion: {} (per-second weights {:?})",
        clips.join(", "),
        config.amp.demo_weights
    );
    Ok(Box::new(ClipFeatures {
        motion,
        rng: SplitMix64::new(0x00A3_0DE3),
    }))
}
