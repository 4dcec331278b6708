//! What the learner optimises on one batch of accepted chunks: the service's seam between the
//! stages. The teachers (t1, t1-rr, t2) and the baselines' one policy run PPO on the task reward
//! plus AMP's style reward; the student aggregates the chunks' (state, teacher label) rows into
//! the DAgger dataset and regresses onto rows drawn from all of it. Everything else — intake, weights, checkpoints, status — is the one
//! service loop.

use std::path::Path;

use lhm_nets::SplitMix64;
use lhm_protos::TrajectoryChunk;

use super::batch::{assemble, episode_summary, EpisodeSummary};
use super::{DemoSource, ServiceError};
use crate::dagger::{DaggerConfig, DaggerDataset, StudentTrainer};
use crate::gae::GaeParams;
use crate::state::Learner;

/// One metric of an update: its `metrics.csv` column and its name in the recorded metrics.
pub struct UpdateMetric {
    pub column: &'static str,
    pub key: &'static str,
    pub value: f64,
}

/// What one update did.
pub struct Update {
    pub summary: EpisodeSummary,
    /// Discriminator accuracy on this batch (AMP only).
    pub disc_accuracy: Option<f64>,
    pub metrics: Vec<UpdateMetric>,
}

fn metric(column: &'static str, key: &'static str, value: f64) -> UpdateMetric {
    UpdateMetric { column, key, value }
}

pub enum Optimiser {
    /// PPO (+ AMP when the learner has a discriminator and demo motion is given).
    PpoAmp { demo: Option<Box<dyn DemoSource>> },
    /// DAgger's aggregation and the student's regression.
    Dagger(Box<DaggerRounds>),
}

/// The student's side of the learner: its dataset and regression.
pub struct DaggerRounds {
    config: DaggerConfig,
    dataset: DaggerDataset,
    trainer: StudentTrainer,
    rng: SplitMix64,
}

impl Optimiser {
    /// The student's optimiser over the dataset in `<run_dir>/dagger/` (opened, or created
    /// empty). The regression's Adam moments start fresh in each process; the dataset and the
    /// student's weights are what a resumed run continues from.
    pub fn dagger(
        config: &DaggerConfig,
        learner: &Learner,
        run_dir: &Path,
    ) -> Result<Self, ServiceError> {
        config.check().map_err(ServiceError::Config)?;
        let ac = &learner.actor_critic;
        let dataset = DaggerDataset::open(
            &run_dir.join("dagger"),
            ac.obs_dim(),
            ac.act_dim(),
            config.capacity,
        )?;
        tracing::info!(
            "DAgger dataset: {} rows in {} rounds",
            dataset.len(),
            dataset.rounds()
        );
        Ok(Self::Dagger(Box::new(DaggerRounds {
            trainer: StudentTrainer::new(config.regression.clone(), ac)?,
            dataset,
            // Seeded by the iteration it starts at: a resumed run draws other rows than its first
            // session did (two processes resuming the same checkpoint draw the same).
            rng: SplitMix64::new(learner.counters.iteration ^ 0x5eed_da66),
            config: config.clone(),
        })))
    }

    /// DAgger's β for the rollouts after `rounds` updates (0 for PPO: no teacher to mix in).
    pub fn teacher_mix(&self, rounds: u64) -> f32 {
        match self {
            Self::PpoAmp { .. } => 0.0,
            Self::Dagger(d) => d.config.teacher_mix_at(rounds),
        }
    }

    /// One update on `chunks`; `amp_active` false leaves the style reward out and the
    /// discriminator untouched (a run's stage without AMP).
    pub fn update(
        &mut self,
        learner: &mut Learner,
        chunks: &[TrajectoryChunk],
        amp_active: bool,
    ) -> Result<Update, ServiceError> {
        match self {
            Self::PpoAmp { demo } => ppo_amp(learner, demo.as_mut().filter(|_| amp_active), chunks),
            Self::Dagger(d) => {
                let DaggerRounds {
                    config,
                    dataset,
                    trainer,
                    rng,
                } = d.as_mut();
                // β of the rollouts that made this round (chunks lag a version at most here).
                let beta = config.teacher_mix_at(learner.counters.iteration);
                let mut obs = Vec::new();
                let mut labels = Vec::new();
                for c in chunks {
                    obs.extend_from_slice(&c.observations);
                    labels.extend_from_slice(&c.actions);
                }
                let rows = chunks.iter().map(|c| c.num_steps as usize).sum::<usize>();
                dataset.append(&obs, &labels)?;
                let stats = trainer.train_round(&mut learner.actor_critic, dataset, rows, rng)?;
                Ok(Update {
                    summary: episode_summary(chunks),
                    disc_accuracy: None,
                    metrics: vec![
                        metric("teacher_mix", "dagger/teacher_mix", f64::from(beta)),
                        metric(
                            "student_loss_before",
                            "dagger/loss_before",
                            stats.loss_before,
                        ),
                        metric("student_loss", "dagger/loss", stats.loss_after),
                        metric("dagger_rows", "dagger/rows", dataset.len() as f64),
                        metric("dagger_rounds", "dagger/rounds", dataset.rounds() as f64),
                    ],
                })
            }
        }
    }
}

fn ppo_amp(
    learner: &mut Learner,
    demo: Option<&mut Box<dyn DemoSource>>,
    chunks: &[TrajectoryChunk],
) -> Result<Update, ServiceError> {
    let gae = GaeParams {
        gamma: learner.config.ppo.gamma,
        lambda: learner.config.ppo.lambda,
    };
    // Without the demo (a stage without AMP) the task reward alone.
    let amp = learner.amp.as_ref().filter(|_| demo.is_some());
    let assembled = assemble(chunks, amp, gae)?;
    let ppo = learner
        .ppo
        .update(&mut learner.actor_critic, &assembled.batch)?;
    let amp = match (learner.amp.as_mut(), demo) {
        (Some(amp), Some(demo)) if !assembled.amp_features.is_empty() => {
            let rows = assembled.amp_features.len() / amp.feature_dim();
            let demo_rows = demo.sample(rows);
            Some(amp.update(&assembled.amp_features, &demo_rows)?)
        }
        _ => None,
    };
    let metrics = vec![
        metric("policy_loss", "ppo/policy_loss", ppo.policy_loss),
        metric("value_loss", "ppo/value_loss", ppo.value_loss),
        metric("approx_kl", "ppo/approx_kl", ppo.approx_kl),
        metric("lr", "ppo/lr", ppo.lr),
        metric("clip_fraction", "ppo/clip_fraction", ppo.clip_fraction),
    ];
    Ok(Update {
        summary: assembled.summary,
        disc_accuracy: amp.as_ref().map(|a| a.accuracy()),
        metrics,
    })
}
