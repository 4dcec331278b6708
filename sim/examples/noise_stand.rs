//! `cargo run --release -p lhm-sim --example noise_stand -- SIGMA`: how long the character stands
//! in three benchmark rooms when every control step's action is the neutral pose plus Gaussian
//! noise of `SIGMA` (action units), as a fresh policy with a fixed log-std acts. Measures whether
//! exploration noise alone makes the first episodes fall (it does: RESULTS.md).

use lhm_scenes::Benchmark;
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::{CharacterModel, SimConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let sigma: f32 = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(0.055);
    let bench = Benchmark::embedded()?;
    let model = CharacterModel::amp_humanoid();
    // Irwin-Hall approximation of a standard normal from an LCG: deterministic, no dependency.
    let mut state: u64 = 12345;
    let mut gauss = || {
        let mut acc = 0.0f32;
        for _ in 0..12 {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            acc += (state >> 40) as f32 / (1u64 << 24) as f32;
        }
        acc - 6.0
    };
    for id in ["train-0001", "train-0002", "train-0003"] {
        let (_, task) = bench.task(id).ok_or(format!("no task {id}"))?;
        let mut env = TaskEnv::new(
            &model,
            &task,
            &bench.catalogue,
            SimConfig::default(),
            EnvConfig::default(),
        );
        for n in 1..=300 {
            let action: Vec<f32> = (0..model.dofs.len()).map(|_| sigma * gauss()).collect();
            let r = env.step(&action);
            if r.done || r.truncated || n == 300 {
                println!(
                    "{id}: sigma {sigma}: {n} steps, fell {}, root {:.2} m",
                    r.fell,
                    env.world.root_height()
                );
                break;
            }
        }
    }
    Ok(())
}
