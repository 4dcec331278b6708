//! What the `[env.gait]` diagnostics (`gait_style_probe`, `fall_trace`) load from a run directory:
//! its configuration, its learner, the clips and the gait's cycle. Included with `#[path]`; not an
//! example of its own.
use lhm_actor::eval::{EvalSetup, GaitStart};
use lhm_learner::service::TrainConfig;
use lhm_learner::Learner;
use lhm_scenes::Benchmark;
use lhm_sim::gait::GaitReference;
use lhm_sim::motion::demo::{AmpWindow, DemoMotion};
use lhm_sim::CharacterModel;
use std::path::Path;
use std::sync::Arc;

pub struct GaitRun {
    pub config: TrainConfig,
    #[allow(dead_code)] // not every diagnostic that includes this file plays the policy
    pub learner: Learner,
    pub model: CharacterModel,
    pub bench: Benchmark,
    /// The installed clips, weighted as the run's discriminator weighs them.
    pub demo: DemoMotion,
    pub reference: Arc<GaitReference>,
}

impl GaitRun {
    /// `dir`'s `config.toml` and checkpoint `stem` (e.g. "checkpoint" or "policy"); an error when
    /// the run has no `[env.gait]`. `config.env` is the environment in force at the checkpoint's
    /// iteration: a run with `[[stages]]` (a curriculum on the gait's angle offsets, say) trained
    /// that checkpoint under its stage's `[env]`, not the run's own.
    pub fn load(dir: &Path, stem: &str) -> Result<Self, Box<dyn std::error::Error>> {
        let mut config = TrainConfig::from_toml_file(&dir.join("config.toml"))?;
        let learner = Learner::load(&dir.join(stem), None)?;
        config.env = config.stage_at(learner.counters.iteration)?.spec.env;
        let gait = config.env.gait.clone().ok_or("the run has no [env.gait]")?;
        let model = CharacterModel::amp_humanoid();
        let bench = Benchmark::embedded()?;
        let demo = DemoMotion::load_dir(
            &model,
            &lhm_sim::motion::default_dir(),
            AmpWindow::of(&config.env, &config.sim),
        )?
        .with_source_weights(config.amp.demo_weights)?;
        let reference = Arc::new(lhm_sim::gait::reference_for_gait(
            &model,
            &demo,
            &gait,
            1.0 / config.sim.control_hz,
        )?);
        Ok(Self {
            config,
            learner,
            model,
            bench,
            demo,
            reference,
        })
    }
}

impl GaitRun {
    /// How the diagnostics play the run: one environment, episodes of at most 300 steps, no
    /// language, starting at rest (`rest`) or walking as `lhm eval` starts them.
    #[allow(dead_code)] // not every diagnostic that includes this file plays episodes this way
    pub fn eval_setup(&self, rest: bool) -> EvalSetup<'_> {
        EvalSetup {
            model: &self.model,
            catalogue: &self.bench.catalogue,
            sim: &self.config.sim,
            env: &self.config.env,
            batch: 1,
            language: false,
            gait: Some(GaitStart {
                demo: &self.demo,
                reference: Arc::clone(&self.reference),
                rest,
            }),
            max_steps: Some(300),
            action_std: 0.0,
        }
    }
}

/// Multiplies the policy's residual on the joints whose name contains `scaled.0` by `scaled.1`
/// (an empty name: every joint, so `k = 0` leaves the gait base alone).
#[allow(dead_code)] // not every diagnostic that includes this file scales the residual
pub fn scale_residual(actions: &mut [f32], model: &CharacterModel, scaled: Option<&(String, f32)>) {
    if let Some((joint, k)) = scaled {
        for (x, dof) in actions.iter_mut().zip(&model.dofs) {
            if dof.name.contains(joint.as_str()) {
                *x *= k;
            }
        }
    }
}
