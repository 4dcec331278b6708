//! Demo AMP features for the learner's discriminator, from the installed motion clips.

use std::path::PathBuf;

use anyhow::Result;
use lhm_learner::service::{DemoSource, TrainConfig};

pub fn load(dir: Option<PathBuf>, config: &TrainConfig) -> Result<Box<dyn DemoSource>> {
    let dir = dir.unwrap_or_else(lhm_sim::motion::default_dir);
    let _ = config;
    anyhow::bail!(
        "AMP demo features from {} are not wired yet; pass --no-amp",
        dir.display()
    )
}
