//! Throughput of the learner's two inner steps, for the benchmark command: one PPO minibatch
//! step (policy and value forward, PPO loss, backward, gradient clipping, Adam) and one AMP
//! discriminator step (demo and agent forward, BCE + gradient penalty + regularisers, backward,
//! Adam). `bench/learner_torch.py` times the same steps in PyTorch for comparison.

use std::time::Instant;

use candle_core::{Device, Tensor, Var};
use lhm_nets::{ActorCritic, ActorCriticConfig, MlpConfig, SplitMix64};
use serde::{Deserialize, Serialize};

use crate::amp::{AmpConfig, AmpTrainer};
use crate::error::LearnerResult;
use crate::ppo::{PpoConfig, PpoMinibatch, PpoTrainer};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct BenchSpec {
    pub obs_dim: usize,
    pub act_dim: usize,
    /// Discriminator input width (10 frames of 105 AMP features by default).
    pub amp_feature_dim: usize,
    pub hidden: Vec<usize>,
    pub minibatch: usize,
    pub warmup: usize,
    pub repetitions: usize,
}

impl Default for BenchSpec {
    fn default() -> Self {
        Self {
            obs_dim: 256,
            act_dim: 28,
            amp_feature_dim: 1050,
            hidden: vec![1024, 512],
            minibatch: 4096,
            warmup: 2,
            repetitions: 7,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepTiming {
    /// Median wall time of one step, in milliseconds.
    pub median_ms: f64,
    pub min_ms: f64,
    pub max_ms: f64,
    /// minibatch / median time.
    pub samples_per_s: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LearnerBench {
    pub spec: BenchSpec,
    /// Worker threads candle's CPU kernels use (RAYON_NUM_THREADS, else all cores).
    pub threads: usize,
    pub ppo: StepTiming,
    pub ppo_samples_per_s: f64,
    pub amp: StepTiming,
    pub amp_samples_per_s: f64,
}

fn random_tensor(rng: &mut SplitMix64, rows: usize, cols: usize) -> LearnerResult<Tensor> {
    let mut data = vec![0f32; rows * cols];
    rng.fill_normal(&mut data);
    Ok(Tensor::from_vec(data, (rows, cols), &Device::Cpu)?)
}

fn time_steps(
    spec: &BenchSpec,
    mut step: impl FnMut() -> LearnerResult<()>,
) -> LearnerResult<StepTiming> {
    for _ in 0..spec.warmup {
        step()?;
    }
    let mut times = Vec::with_capacity(spec.repetitions.max(1));
    for _ in 0..spec.repetitions.max(1) {
        let start = Instant::now();
        step()?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    let median_ms = times[times.len() / 2];
    Ok(StepTiming {
        median_ms,
        min_ms: times[0],
        max_ms: times[times.len() - 1],
        samples_per_s: spec.minibatch as f64 / (median_ms / 1e3),
    })
}

/// Times one PPO minibatch step on random data.
pub fn ppo_minibatch_step_time(spec: &BenchSpec) -> LearnerResult<StepTiming> {
    let mut ac_config = ActorCriticConfig::with_hidden(&spec.hidden);
    ac_config.normalize_obs = false;
    let ac = ActorCritic::new(spec.obs_dim, spec.act_dim, &ac_config)?;
    let mut trainer = PpoTrainer::new(PpoConfig::default(), &ac)?;
    let vars: Vec<Var> = ac.named_vars().into_iter().map(|(_, v)| v).collect();
    let mut rng = SplitMix64::new(1);
    let n = spec.minibatch;
    let obs = random_tensor(&mut rng, n, spec.obs_dim)?;
    let actions = random_tensor(&mut rng, n, spec.act_dim)?;
    let old_log_probs = ac.policy.log_prob(&obs, &actions)?.detach();
    let old_values = ac.value.forward(&obs)?.detach();
    let advantages = random_tensor(&mut rng, n, 1)?.flatten_all()?;
    let returns = (&old_values + &advantages)?;
    let mb = PpoMinibatch {
        obs,
        actions,
        old_log_probs,
        old_values,
        advantages,
        returns,
    };
    time_steps(spec, || trainer.minibatch_step(&ac, &vars, &mb).map(|_| ()))
}

/// Times one AMP discriminator step (minibatch demo rows + minibatch agent rows).
pub fn amp_discriminator_step_time(spec: &BenchSpec) -> LearnerResult<StepTiming> {
    let config = AmpConfig {
        disc: MlpConfig::with_hidden(&spec.hidden),
        ..AmpConfig::default()
    };
    let mut trainer = AmpTrainer::new(spec.amp_feature_dim, config)?;
    let vars = trainer.vars();
    let mut rng = SplitMix64::new(2);
    let demo = random_tensor(&mut rng, spec.minibatch, spec.amp_feature_dim)?;
    let agent = random_tensor(&mut rng, spec.minibatch, spec.amp_feature_dim)?;
    time_steps(spec, || {
        trainer.minibatch_step(&vars, &demo, &agent).map(|_| ())
    })
}

/// Both timings.
pub fn run(spec: &BenchSpec) -> LearnerResult<LearnerBench> {
    let ppo = ppo_minibatch_step_time(spec)?;
    let amp = amp_discriminator_step_time(spec)?;
    Ok(LearnerBench {
        spec: spec.clone(),
        threads: candle_core::utils::get_num_threads(),
        ppo_samples_per_s: ppo.samples_per_s,
        ppo,
        amp_samples_per_s: amp.samples_per_s,
        amp,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiny_bench_reports_positive_throughput() {
        let spec = BenchSpec {
            obs_dim: 6,
            act_dim: 2,
            amp_feature_dim: 5,
            hidden: vec![8],
            minibatch: 16,
            warmup: 1,
            repetitions: 3,
        };
        let result = run(&spec).unwrap();
        assert!(result.ppo_samples_per_s > 0.0 && result.amp_samples_per_s > 0.0);
        assert!(
            result.ppo.min_ms <= result.ppo.median_ms && result.ppo.median_ms <= result.ppo.max_ms
        );
        assert!(serde_json::to_string(&result)
            .unwrap()
            .contains("ppo_samples_per_s"));
    }
}
