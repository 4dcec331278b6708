//! `lhm bench env`: control and physics steps per second of the training configuration in a
//! benchmark room, on one core and on all cores. Medians over repetitions (machines are noisy).

use crate::batch::WorldBatch;
use crate::mjcf::CharacterModel;
use crate::task::terminations::{fall_exempt, fallen};
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
    /// Episodes end, and worlds are restored to their start, after this many control steps or
    /// on a fall (a body other than feet and hands below `fall_height`, the env's rule), as in
    /// training.
    pub episode_steps: usize,
    pub fall_height: f32,
    /// Control steps per episode on one core, averaged (how soon the random actions fell).
    pub mean_episode_steps: f64,
    pub threads_all_cores: usize,
    /// Worlds in the all-cores run (several per thread, as actors step many environments).
    pub worlds_all_cores: usize,
    pub control_steps_per_s_per_core: f64,
    pub physics_steps_per_s_per_core: f64,
    pub control_steps_per_s_all_cores: f64,
    pub physics_steps_per_s_all_cores: f64,
    /// One core, with episodes ended only by their length: a fallen character keeps lying on
    /// the floor (more contacts than in training, where a fall ends the episode).
    pub control_steps_per_s_per_core_without_fall_reset: f64,
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

/// When a benchmark episode ends and its world is restored to the start.
#[derive(Clone, Copy, Debug)]
enum EpisodeEnd {
    /// As in training: on a fall (the env's rule and height), or after [`EPISODE_STEPS`].
    FallOrLength,
    /// Only after [`EPISODE_STEPS`]: a fallen character keeps lying in contact with the floor.
    Length,
}

/// Control steps per benchmark episode at most (5 s at 30 Hz).
const EPISODE_STEPS: usize = 150;

/// Worlds each thread steps in the all-cores run: actors step many environments per process,
/// and one world per thread would time the thread hand-off rather than the physics.
const WORLDS_PER_THREAD: usize = 4;

struct Run {
    control_steps_per_s: f64,
    episodes: usize,
}

/// Steps `worlds` for `steps` control steps with `threads` threads; returns control steps/s
/// summed over worlds and how many episodes were run.
fn timed_run(
    worlds: Vec<World>,
    threads: usize,
    steps: usize,
    end: EpisodeEnd,
    fall: (&[bool], f32),
    act_dim: usize,
) -> Run {
    let starts: Vec<_> = worlds.iter().map(World::snapshot).collect();
    let n = worlds.len();
    let mut age = vec![0usize; n];
    let mut episodes = n;
    let mut batch = WorldBatch::new(worlds, threads);
    let actions = action_stream(7, EPISODE_STEPS * n * act_dim);
    let start = Instant::now();
    for _ in 0..steps {
        for (i, (w, s)) in batch.worlds.iter_mut().zip(&starts).enumerate() {
            let over = age[i] >= EPISODE_STEPS
                || matches!(end, EpisodeEnd::FallOrLength) && age[i] > 0 && has_fallen(w, fall);
            if over {
                w.restore(s);
                age[i] = 0;
                episodes += 1;
            }
        }
        // Every world replays the same action stream from its episode start, so both modes
        // see the same actions for the same states.
        let step_actions: Vec<f32> = (0..n)
            .flat_map(|i| {
                let k = age[i].min(EPISODE_STEPS - 1);
                let at = (k * n + i) * act_dim;
                actions[at..at + act_dim].iter().copied()
            })
            .collect();
        batch.step(&step_actions, act_dim);
        for a in &mut age {
            *a += 1;
        }
    }
    Run {
        control_steps_per_s: (steps * n) as f64 / start.elapsed().as_secs_f64(),
        episodes,
    }
}

fn has_fallen(world: &World, (exempt, height): (&[bool], f32)) -> bool {
    let heights: Vec<f32> = (0..world.character.bodies.len())
        .map(|b| world.body_pose(b).translation.z)
        .collect();
    fallen(&heights, exempt, height)
}

#[allow(clippy::too_many_arguments)]
pub fn run_env_bench(
    model: &CharacterModel,
    config: &SimConfig,
    task: &Task,
    catalogue: &Catalogue,
    steps: usize,
    repetitions: usize,
    threads: usize,
    fall_height: f32,
) -> EnvBench {
    let act_dim = model.dofs.len();
    let exempt = fall_exempt(model);
    let fall = (exempt.as_slice(), fall_height);
    let make = |k: usize| {
        (0..k)
            .map(|_| World::with_task(model, config.clone(), task, catalogue))
            .collect::<Vec<_>>()
    };
    // Warm-up (page faults, caches) before anything is timed.
    timed_run(make(1), 1, 30, EpisodeEnd::Length, fall, act_dim);
    let repeat = |worlds: usize, threads: usize, end: EpisodeEnd| {
        let runs: Vec<Run> = (0..repetitions)
            .map(|_| timed_run(make(worlds), threads, steps, end, fall, act_dim))
            .collect();
        let episodes: usize = runs.iter().map(|r| r.episodes).sum();
        let rate = median(runs.iter().map(|r| r.control_steps_per_s).collect());
        (
            rate,
            (repetitions * steps * worlds) as f64 / episodes as f64,
        )
    };
    let (one, mean_episode) = repeat(1, 1, EpisodeEnd::FallOrLength);
    let (all, _) = repeat(
        threads * WORLDS_PER_THREAD,
        threads,
        EpisodeEnd::FallOrLength,
    );
    let (one_lying, _) = repeat(1, 1, EpisodeEnd::Length);
    let per_control = config.physics_steps_per_control() as f64;
    EnvBench {
        task: task.id.clone(),
        control_hz: config.control_hz,
        physics_hz: config.physics_hz,
        pipeline_steps_per_control: config.pipeline_steps_per_control,
        steps_per_repetition: steps,
        repetitions,
        episode_steps: EPISODE_STEPS,
        fall_height,
        mean_episode_steps: (mean_episode * 10.0).round() / 10.0,
        threads_all_cores: threads,
        worlds_all_cores: threads * WORLDS_PER_THREAD,
        control_steps_per_s_per_core: one.round(),
        physics_steps_per_s_per_core: (one * per_control).round(),
        control_steps_per_s_all_cores: all.round(),
        physics_steps_per_s_all_cores: (all * per_control).round(),
        control_steps_per_s_per_core_without_fall_reset: one_lying.round(),
    }
}
