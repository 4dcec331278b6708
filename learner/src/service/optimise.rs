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
    let mut metrics = vec![
        metric("policy_loss", "ppo/policy_loss", ppo.policy_loss),
        metric("value_loss", "ppo/value_loss", ppo.value_loss),
        metric("approx_kl", "ppo/approx_kl", ppo.approx_kl),
        metric("lr", "ppo/lr", ppo.lr),
        metric("clip_fraction", "ppo/clip_fraction", ppo.clip_fraction),
    ];
    if let Some(a) = &amp {
        // Each side apart: a mean accuracy that dips can be the agent fooling the discriminator
        // or the discriminator losing the demo.
        metrics.extend([
            metric("disc_demo_accuracy", "amp/demo_accuracy", a.demo_accuracy),
            metric(
                "disc_agent_accuracy",
                "amp/agent_accuracy",
                a.agent_accuracy,
            ),
            metric("disc_demo_logit", "amp/demo_logit_mean", a.demo_logit_mean),
            metric(
                "disc_agent_logit",
                "amp/agent_logit_mean",
                a.agent_logit_mean,
            ),
            metric("disc_bce_loss", "amp/bce_loss", a.bce_loss),
            metric("disc_grad_penalty", "amp/grad_penalty", a.grad_penalty),
            metric("disc_lr", "amp/lr", a.lr),
        ]);
    }
    Ok(Update {
        summary: assembled.summary,
        disc_accuracy: amp.as_ref().map(|a| a.accuracy()),
        metrics,
    })
}

#[cfg(test)]
mod tests {
    use lhm_nets::{ActorCriticConfig, MlpConfig};
    use lhm_protos::WireMessage;

    use super::*;
    use crate::amp::AmpConfig;
    use crate::ppo::PpoConfig;
    use crate::state::{AmpSetup, LearnerConfig};

    /// Demo rows far from the agent's (features near +3 against the agent's near 0).
    struct FarDemo;
    impl DemoSource for FarDemo {
        fn sample(&mut self, rows: usize) -> Vec<f32> {
            (0..rows * 2).map(|i| 3.0 + (i % 5) as f32 * 0.1).collect()
        }
    }

    fn chunk(offset: f32) -> TrajectoryChunk {
        let n = 16usize;
        TrajectoryChunk {
            run_id: "r".into(),
            actor_id: "a".into(),
            num_steps: n as u32,
            obs_dim: 1,
            act_dim: 1,
            amp_dim: 2,
            observations: (0..n).map(|t| t as f32 * 0.1).collect(),
            actions: vec![0.0; n],
            log_probs: vec![0.0; n],
            values: vec![0.0; n],
            rewards: vec![1.0; n],
            dones: vec![false; n],
            truncated: vec![false; n],
            truncation_values: vec![0.0; n],
            amp_features: (0..n)
                .flat_map(|t| [offset + t as f32 * 0.01, -offset])
                .collect(),
            ..TrajectoryChunk::versioned()
        }
    }

    fn learner() -> Learner {
        Learner::new(LearnerConfig {
            obs_dim: 1,
            act_dim: 1,
            actor_critic: ActorCriticConfig::with_hidden(&[8]),
            ppo: PpoConfig {
                epochs: 1,
                minibatch_size: 16,
                ..PpoConfig::default()
            },
            amp: Some(AmpSetup {
                feature_dim: 2,
                config: AmpConfig {
                    disc: MlpConfig::with_hidden(&[8]),
                    minibatch_size: 16,
                    epochs: 4,
                    adam: lhm_nets::AdamConfig {
                        lr: 1e-2,
                        ..lhm_nets::AdamConfig::default()
                    },
                    ..AmpConfig::default()
                },
            }),
        })
        .unwrap()
    }

    fn value(update: &Update, column: &str) -> Option<f64> {
        update
            .metrics
            .iter()
            .find(|m| m.column == column)
            .map(|m| m.value)
    }

    #[test]
    fn an_amp_update_reports_each_side_of_the_discriminator() {
        let mut learner = learner();
        let mut optimiser = Optimiser::PpoAmp {
            demo: Some(Box::new(FarDemo)),
        };
        let chunks = [chunk(0.0), chunk(0.2)];
        // Without AMP (a stage with it off) no discriminator columns.
        let off = optimiser.update(&mut learner, &chunks, false).unwrap();
        assert!(off.disc_accuracy.is_none());
        assert!(value(&off, "disc_demo_accuracy").is_none());
        let mut last = None;
        for _ in 0..20 {
            last = Some(optimiser.update(&mut learner, &chunks, true).unwrap());
        }
        let update = last.unwrap();
        let demo = value(&update, "disc_demo_accuracy").expect("demo accuracy");
        let agent = value(&update, "disc_agent_accuracy").expect("agent accuracy");
        let mean = update.disc_accuracy.expect("accuracy");
        assert!(
            (0.5 * (demo + agent) - mean).abs() < 1e-12,
            "{demo} {agent} {mean}"
        );
        // Two separable sets: after a few updates both sides are told apart and the logits say so.
        assert!(demo > 0.9 && agent > 0.9, "{demo} {agent}");
        let demo_logit = value(&update, "disc_demo_logit").expect("demo logit");
        let agent_logit = value(&update, "disc_agent_logit").expect("agent logit");
        assert!(
            demo_logit > 0.0 && agent_logit < 0.0,
            "{demo_logit} {agent_logit}"
        );
        assert!(value(&update, "disc_bce_loss").is_some_and(|l| l.is_finite() && l > 0.0));
        assert!(value(&update, "disc_grad_penalty").is_some_and(|g| g.is_finite() && g >= 0.0));
        // Every column named is one metrics.csv has.
        for m in &update.metrics {
            assert!(
                super::super::metrics_csv::COLUMNS.contains(&m.column),
                "{}",
                m.column
            );
        }
    }
}
