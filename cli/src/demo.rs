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
    check_gait_cycles(&model, &motion, config)?;
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

/// For a run without AMP (whose learner needs no clips for a discriminator): loads the clips all
/// the same when the run or a stage walks on `[env.gait]`, and builds every cycle, so a bad
/// offset table or clip name stops it at its start as it does an AMP run, not its actors later.
/// Where this process has no clips (a learner whose actors run elsewhere) it says so and leaves
/// the check to the actors, which need the clips anyway.
pub fn check_gait_run(dir: Option<PathBuf>, config: &TrainConfig) -> Result<()> {
    if config
        .named_envs()?
        .iter()
        .all(|(_, env)| env.gait.is_none())
    {
        return Ok(());
    }
    let dir = dir.unwrap_or_else(lhm_sim::motion::default_dir);
    let model = CharacterModel::amp_humanoid();
    match DemoMotion::load_dir(&model, &dir, AmpWindow::of(&config.env, &config.sim)) {
        Ok(motion) => check_gait_cycles(&model, &motion, config),
        Err(e) => {
            tracing::warn!(
                "[env.gait] cycles not checked here: no clips in {} ({e}); the actors build them",
                dir.display()
            );
            Ok(())
        }
    }
}

/// Builds the gait cycle of the run's `[env.gait]` and of every stage's from `motion`: a clip no
/// installed clip is named after, or an `angle_offsets` table whose length is not the clip's
/// cycle, stops the run at its start with the stage's name, rather than its actors when the stage
/// comes hours later (the learner's own check knows the names but not the clip's length).
pub(crate) fn check_gait_cycles(
    model: &CharacterModel,
    motion: &DemoMotion,
    config: &TrainConfig,
) -> Result<()> {
    let dt = 1.0 / config.sim.control_hz;
    for (at, env) in config.named_envs()? {
        if let Some(gait) = &env.gait {
            lhm_sim::gait::reference_for_gait(model, motion, gait, dt)
                .map_err(|e| anyhow::anyhow!("{at}: {e}"))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use lhm_learner::service::RunStage;
    use lhm_sim::env::GaitConfig;

    /// A gait run on the synthetic `cycle_walk` whose one stage adds `offsets` (name, length).
    fn gait_run(offsets: &[(&str, usize)]) -> TrainConfig {
        let mut config = TrainConfig::default();
        config.env.gait = Some(GaitConfig {
            clip: "cycle_walk".into(),
            ..GaitConfig::default()
        });
        let table = offsets
            .iter()
            .map(|(name, len)| format!("{name} = {:?}", vec![0.01f32; *len]))
            .collect::<Vec<_>>()
            .join("\n");
        config.stages = vec![RunStage {
            until_iteration: 10,
            amp_enabled: None,
            log_std: None,
            env: toml::from_str(&format!("[gait.angle_offsets]\n{table}\n"))
                .expect("a stage's [env] parses"),
        }];
        config
    }

    #[test]
    fn a_stages_offsets_of_the_wrong_length_are_refused_at_the_start_by_name() {
        let model = CharacterModel::amp_humanoid();
        let motion = lhm_sim::gait::synthetic_cycle_demo(&model, AmpWindow::default())
            .expect("the synthetic clip loads");
        let dt = 1.0 / TrainConfig::default().sim.control_hz;
        let steps = lhm_sim::gait::reference_for(&model, &motion, "cycle_walk", dt)
            .expect("the synthetic cycle")
            .len();
        for ok in [1, steps] {
            check_gait_cycles(&model, &motion, &gait_run(&[("left_knee", ok)]))
                .unwrap_or_else(|e| panic!("{ok} values: {e:#}"));
        }
        let err = check_gait_cycles(&model, &motion, &gait_run(&[("left_knee", steps - 1)]))
            .expect_err("a table one short");
        let text = format!("{err:#}");
        assert!(text.contains("stages[0].env"), "{text}");
        assert!(text.contains("left_knee"), "{text}");
        let mut unknown = gait_run(&[]);
        unknown.env.gait.as_mut().unwrap().clip = "no_such_clip".into();
        let err = check_gait_cycles(&model, &motion, &unknown).expect_err("an unknown clip");
        assert!(format!("{err:#}").starts_with("env: "), "{err:#}");
    }

    #[test]
    fn a_run_without_amp_and_without_clips_here_leaves_its_cycles_to_the_actors() {
        let empty = std::env::temp_dir().join(format!("lhm-no-clips-{}", std::process::id()));
        std::fs::create_dir_all(&empty).expect("an empty clip dir");
        // A table no cycle has the length of: refused where the clips are (test above), let
        // through here, where none are to build it from.
        let run = gait_run(&[("left_knee", 2)]);
        check_gait_run(Some(empty.clone()), &run).expect("no clips: the actors check");
        check_gait_run(Some(empty.join("missing")), &TrainConfig::default())
            .expect("no [env.gait]: nothing to check, no clips read");
        let _ = std::fs::remove_dir_all(&empty);
    }
}
