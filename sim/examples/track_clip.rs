//! `cargo run --release -p lhm-sim --example track_clip [MOTION_DIR]`: how long the character
//! stays up when it starts from a frame of each installed clip (reference-state initialisation)
//! and then its PD servos are simply given the clip's own joint angles, step after step — an
//! open-loop "perfect imitation" policy with no balance feedback. It bounds what a policy gets
//! for free from a demo start: if even the reference's own targets fall within a few steps, the
//! policy must learn balance before it can walk on.
//!
//! Looped clips (the DeepMimic walks) are followed for up to 3 s, repeating as
//! `DemoMotion::reference_track` repeats them; the last columns are the imitation term
//! (`rewards::imitation`, DeepMimic's tracking reward) this open-loop tracker earns on its first
//! 10 steps and over all the steps it stays up.

use lhm_scenes::Benchmark;
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::fidelity::joint_angles;
use lhm_sim::motion::demo::{AmpWindow, DemoMotion};
use lhm_sim::{CharacterModel, SimConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args()
        .nth(1)
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            let home = std::env::var("HOME").unwrap_or_default();
            std::path::PathBuf::from(home).join(".cache/lhm/motions")
        });
    let model = CharacterModel::amp_humanoid();
    let (mut env_config, sim) = (EnvConfig::default(), SimConfig::default());
    env_config.weights.imitation = 1.0;
    env_config.imitation_seconds = 3.0;
    let demo = DemoMotion::load_dir(&model, &dir, AmpWindow::of(&env_config, &sim))?;
    let bench = Benchmark::embedded()?;
    let (_, task) = bench.task("train-0001").ok_or("no task train-0001")?;
    let dt = 1.0 / sim.control_hz;
    let lead = demo.window().span_s() + demo.window().control_dt;
    println!(
        "clip | start s | steps up (of the steps tracked) | root travel m (clip's) | root height at end m \
         | imitation, first 10 steps | imitation, all steps up"
    );
    let clips: Vec<(String, f32)> = demo.clips().map(|(n, d)| (n.to_owned(), d)).collect();
    for (clip, (name, duration)) in clips.iter().enumerate() {
        for frac in [0.0f32, 0.25, 0.5] {
            let t0 = lead + (duration - lead) * frac;
            let mut env = TaskEnv::new(
                &model,
                &task,
                &bench.catalogue,
                sim.clone(),
                env_config.clone(),
            );
            env.start_from_demo(&demo, clip, t0);
            let start = env.world.body_states()[0].pos;
            let clip_start = demo.body_states_at(clip, t0)[0].pos;
            // A looped clip repeats for up to 3 s; others end at their end.
            let reference = demo.reference_track(clip, t0, (3.0 / dt) as usize, dt);
            let horizon = reference.len();
            let (mut up, mut first10, mut all) = (0, 0.0, 0.0);
            let mut clip_end = clip_start;
            let c = env.world.character.clone();
            for (k, frame) in reference.iter().enumerate() {
                let action: Vec<f32> = joint_angles(&model, frame)
                    .iter()
                    .enumerate()
                    .map(|(i, q)| (q - c.action_offset[i]) / c.action_scale[i])
                    .collect();
                let imitation = env.step(&action).terms.imitation;
                clip_end = frame[0].pos;
                if env.world.root_height() < env_config.root_fall_height {
                    break;
                }
                up = k + 1;
                all += imitation;
                if k < 10 {
                    first10 += imitation / 10.0;
                }
            }
            let all = all / up.max(1) as f32;
            let end = env.world.body_states()[0].pos;
            let travel = ((end.x - start.x).powi(2) + (end.y - start.y).powi(2)).sqrt();
            let clip_travel =
                ((clip_end.x - clip_start.x).powi(2) + (clip_end.y - clip_start.y).powi(2)).sqrt();
            println!(
                "{name} | {t0:.2} | {up} of {horizon} | {travel:.2} ({clip_travel:.2}) | {:.2} \
                 | {first10:.3} | {all:.3}",
                env.world.root_height()
            );
        }
    }
    Ok(())
}
