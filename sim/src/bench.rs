//! `lhm bench env`: control and physics steps per second of the training configuration in a
//! benchmark room, on one core and on all cores. Medians over repetitions (machines are noisy).

use crate::batch::WorldBatch;
use crate::mjcf::CharacterModel;
use crate::world::{SimConfig, World};
use lhm_scenes::{Catalogue, Task};
use serde::Serialize;
use std::time::Instant;

#[derive(Serialize, Clone, Debug)]
pub struct EnvBench {
    pub task: String,
    pub control_hz: f32,
    pub physics_hz: f32,
    pub pipeline_steps_per_control: usize,
    pub steps_per_repetition: usize,
    pub repetitions: usize,
    /// Worlds are restored to their start every this many control steps (an episode).
    pub episode_steps: usize,
    pub threads_all_cores: usize,
    pub control_steps_per_s_per_core: f64,
    pub physics_steps_per_s_per_core: f64,
    pub control_steps_per_s_all_cores: f64,
    pub physics_steps_per_s_all_cores: f64,
}

/// A fixed exploration-like action stream: uniform in [-0.5, 0.5], the same every run.
fn action_stream(seed: u64, n: usize) -> Vec<f32> {
    let mut s = seed ^ 0x9E37_79B9_7F4A_7C15;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) - 0.5
        })
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        0.0
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Steps `worlds` for `steps` control steps with `threads` threads; returns control steps/s
/// summed over worlds.
fn timed_run(
    worlds: Vec<World>,
    threads: usize,
    steps: usize,
    episode: usize,
    act_dim: usize,
) -> f64 {
    let starts: Vec<_> = worlds.iter().map(World::snapshot).collect();
    let n = worlds.len();
    let mut batch = WorldBatch::new(worlds, threads);
    let actions = action_stream(7, episode * n * act_dim);
    let start = Instant::now();
    for step in 0..steps {
        let k = step % episode;
        if k == 0 && step > 0 {
            for (w, s) in batch.worlds.iter_mut().zip(&starts) {
                w.restore(s);
            }
        }
        batch.step(&actions[k * n * act_dim..(k + 1) * n * act_dim], act_dim);
    }
    (steps * n) as f64 / start.elapsed().as_secs_f64()
}

pub fn run_env_bench(
    model: &CharacterModel,
    config: &SimConfig,
    task: &Task,
    catalogue: &Catalogue,
    steps: usize,
    repetitions: usize,
    threads: usize,
) -> EnvBench {
    let act_dim = model.dofs.len();
    let episode = 150;
    let make = |k: usize| {
        (0..k)
            .map(|_| World::with_task(model, config.clone(), task, catalogue))
            .collect::<Vec<_>>()
    };
    // Warm-up (page faults, caches) before anything is timed.
    timed_run(make(1), 1, 30, episode, act_dim);
    let one: Vec<f64> = (0..repetitions)
        .map(|_| timed_run(make(1), 1, steps, episode, act_dim))
        .collect();
    let all: Vec<f64> = (0..repetitions)
        .map(|_| timed_run(make(threads), threads, steps, episode, act_dim))
        .collect();
    let per_control = config.physics_steps_per_control() as f64;
    let (one, all) = (median(one), median(all));
    EnvBench {
        task: task.id.clone(),
        control_hz: config.control_hz,
        physics_hz: config.physics_hz,
        pipeline_steps_per_control: config.pipeline_steps_per_control,
        steps_per_repetition: steps,
        repetitions,
        episode_steps: episode,
        threads_all_cores: threads,
        control_steps_per_s_per_core: one.round(),
        physics_steps_per_s_per_core: (one * per_control).round(),
        control_steps_per_s_all_cores: all.round(),
        physics_steps_per_s_all_cores: (all * per_control).round(),
    }
}
