//! How the choice of pipeline steps per control step changes the physics, against a 480 Hz
//! reference (16 pipeline steps of 1/480 s). Prints, per setting:
//! - the root height of a zero-action fall from the spawn pose at control steps 10..90,
//! - over 40 random-action episodes (uniform actions in [-1, 1], 60 control steps each): the
//!   median, 90th percentile and maximum of each episode's peak body speed, the mean link
//!   angular speed, how many episodes the NaN/explosion guard ended, and the 1st percentile of
//!   the deepest contact per step (negative = penetration, metres).
//!
//! `cargo run --release -p lhm-sim --example step_accuracy` (BENCHMARKS.md, "Choosing the step").

use lhm_scenes::Benchmark;
use lhm_sim::{CharacterModel, SimConfig, World};

fn uniform(seed: u64) -> impl FnMut() -> f32 {
    let mut s = seed ^ 0x9E37_79B9_7F4A_7C15;
    move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        2.0 * ((s >> 40) as f32 / (1u64 << 24) as f32) - 1.0
    }
}

fn deepest_contact(world: &World) -> f32 {
    let mut deepest = 0.0f32;
    for pair in world.state.narrow_phase.contact_pairs() {
        for manifold in pair.manifolds() {
            for point in &manifold.points {
                deepest = deepest.min(point.dist);
            }
        }
    }
    deepest
}

fn main() {
    let bench = Benchmark::embedded().expect("embedded benchmark");
    let (_, task) = bench.task("train-0001").expect("train-0001");
    let model = CharacterModel::amp_humanoid();
    let dofs = model.dofs.len();
    let make = |pipeline_steps: usize| {
        let config = SimConfig {
            pipeline_steps_per_control: pipeline_steps,
            physics_hz: 30.0 * pipeline_steps.max(4) as f32,
            ..SimConfig::default()
        };
        World::with_task(&model, config, &task, &bench.catalogue)
    };
    // 16 = 480 Hz pipeline steps (the reference); the others are 120 Hz physics split into
    // pipeline steps and substeps: 4 x 1/120, 2 x (1/60, 2 substeps), 1 x (1/30, 4 substeps).
    for pipeline_steps in [16usize, 4, 2, 1] {
        let mut world = make(pipeline_steps);
        let zero = vec![0.0; dofs];
        let mut heights = vec![];
        for k in 1..=90 {
            world.step(&zero);
            if [10, 20, 30, 45, 60, 90].contains(&k) {
                heights.push((world.root_height() * 1000.0).round() / 1000.0);
            }
        }
        let (mut peaks, mut deepest) = (vec![], vec![]);
        let (mut angular, mut samples, mut invalid) = (0.0f64, 0usize, 0);
        for episode in 0..40u64 {
            let mut world = make(pipeline_steps);
            let mut action = uniform(episode);
            let mut peak = 0.0f32;
            for _ in 0..60 {
                let a: Vec<f32> = (0..dofs).map(|_| action()).collect();
                if !world.step(&a) {
                    invalid += 1;
                    break;
                }
                for body in world.body_states() {
                    peak = peak.max(body.linvel.length());
                    angular += body.angvel.length() as f64;
                    samples += 1;
                }
                deepest.push(deepest_contact(&world));
            }
            peaks.push(peak);
        }
        peaks.sort_by(f32::total_cmp);
        deepest.sort_by(f32::total_cmp);
        println!(
            "{pipeline_steps:2} pipeline steps: zero-action root height at 10,20,30,45,60,90 {heights:?} | \
             peak body speed median {:.2} p90 {:.2} max {:.2} m/s | mean link |w| {:.2} rad/s | \
             guard tripped {invalid}/40 | deepest contact p1 {:.3} m",
            peaks[peaks.len() / 2],
            peaks[peaks.len() * 9 / 10],
            peaks[peaks.len() - 1],
            angular / samples.max(1) as f64,
            deepest[deepest.len() / 100],
        );
    }
}
