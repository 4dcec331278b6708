//! `lhm bench vla`: what the VLA's eyes cost on one core, per image size: the environment's
//! control steps/s with the state observation against with the VLA row (egocentric render,
//! proprioception, instruction), the renders/s alone, the VLA policy's forward rows/s (a batch
//! of 16, as an actor acts), its regression's forward + backward rows/s (a 256-row minibatch, as
//! the learner trains), and the bytes a step adds to a chunk. Medians over repetitions.

use anyhow::{Context, Result};
use lhm_actor::rollout::vla_view;
use lhm_nets::{ActorCritic, ActorCriticConfig, SplitMix64, VlaEncoderConfig};
use lhm_scenes::Benchmark;
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::vla::egocentric_image;
use lhm_sim::{CharacterModel, SimConfig};
use serde::Serialize;
use std::time::Instant;

#[derive(Debug, Serialize)]
pub struct VlaBenchRow {
    pub image_size: usize,
    /// Control steps/s with the state observation after each step (what teachers see).
    pub state_steps_per_s: f64,
    /// Control steps/s with the VLA row after each step.
    pub vla_steps_per_s: f64,
    /// Egocentric renders/s alone.
    pub renders_per_s: f64,
    /// VLA policy forward passes, rows/s, in batches of 16.
    pub policy_rows_per_s: f64,
    /// The DAgger regression: forward, MSE loss and backward of the whole VLA policy on a
    /// 256-row minibatch, rows/s.
    pub train_rows_per_s: f64,
    /// f32 values of one VLA row (4 bytes each in a chunk).
    pub row_values: usize,
    pub row_bytes: usize,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Steps/s of `steps` control steps with `observe` after each; an ended episode starts again.
fn steps_per_s(
    fresh: &dyn Fn() -> TaskEnv,
    steps: usize,
    rng: &mut SplitMix64,
    observe: &dyn Fn(&TaskEnv) -> Vec<f32>,
) -> f64 {
    let mut env = fresh();
    let act_dim = env.model.dofs.len();
    let started = Instant::now();
    let mut sink = 0.0f32;
    for _ in 0..steps {
        let action: Vec<f32> = (0..act_dim)
            .map(|_| rng.uniform(-0.3, 0.3) as f32)
            .collect();
        let r = env.step(&action);
        sink += observe(&env)[0];
        if r.done || r.truncated || r.physics_invalid {
            env = fresh();
        }
    }
    std::hint::black_box(sink);
    steps as f64 / started.elapsed().as_secs_f64()
}

pub fn run(sizes: &[usize], steps: usize, repetitions: usize) -> Result<Vec<VlaBenchRow>> {
    let bench = Benchmark::embedded()?;
    let (_, task) = bench.task("train-0001").context("no task train-0001")?;
    let model = CharacterModel::amp_humanoid();
    let fresh = || {
        TaskEnv::new(
            &model,
            &task,
            &bench.catalogue,
            SimConfig::default(),
            EnvConfig::default(),
        )
    };
    let vocabulary = lhm_learner::service::stage::training_vocabulary(None)?;
    let mut rows = Vec::new();
    for &size in sizes {
        let encoder = VlaEncoderConfig {
            proprio_dim: lhm_sim::obs::proprioception_dim(&model),
            image_size: size,
            vocabulary: vocabulary.clone(),
            ..VlaEncoderConfig::default()
        };
        encoder.check().map_err(anyhow::Error::msg)?;
        let view = vla_view(&encoder, true);
        let mut network = ActorCriticConfig::with_hidden(&[512, 256]);
        network.policy.vla = Some(encoder.clone());
        let policy = ActorCritic::new(encoder.obs_dim(), model.dofs.len(), &network)?;
        let mut rng = SplitMix64::new(7);
        let (mut state, mut vla, mut renders, mut forward) = (vec![], vec![], vec![], vec![]);
        let mut train = vec![];
        for _ in 0..repetitions.max(1) {
            state.push(steps_per_s(&fresh, steps, &mut rng, &|e| e.observation()));
            vla.push(steps_per_s(&fresh, steps, &mut rng, &|e| {
                view.observation(e)
            }));
            let env = fresh();
            let started = Instant::now();
            for _ in 0..steps {
                std::hint::black_box(egocentric_image(&env, size));
            }
            renders.push(steps as f64 / started.elapsed().as_secs_f64());
            let batch: Vec<f32> = (0..16).flat_map(|_| view.observation(&env)).collect();
            let passes = (steps / 16).max(1);
            let started = Instant::now();
            for _ in 0..passes {
                std::hint::black_box(policy.act_deterministic(&batch)?);
            }
            forward.push((passes * 16) as f64 / started.elapsed().as_secs_f64());
            let rows: Vec<f32> = (0..256).flat_map(|_| view.observation(&env)).collect();
            train.push(256.0 / lhm_nets::vla::regression_step_seconds(&policy, &rows)?);
        }
        rows.push(VlaBenchRow {
            image_size: size,
            state_steps_per_s: median(state),
            vla_steps_per_s: median(vla),
            renders_per_s: median(renders),
            policy_rows_per_s: median(forward),
            train_rows_per_s: median(train),
            row_values: encoder.obs_dim(),
            row_bytes: 4 * encoder.obs_dim(),
        });
    }
    Ok(rows)
}
