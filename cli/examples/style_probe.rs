//! Diagnostic: the discriminator's style reward for the same checkpoint's policy acting with its
//! mean action vs with its exploration noise, and for demo windows. `cargo run --release -p lhm-cli
//! --example style_probe -- runs/<run>/checkpoint`.
use lhm_learner::service::TrainConfig;
use lhm_learner::Learner;
use lhm_nets::SplitMix64;
use lhm_scenes::Benchmark;
use lhm_sim::env::TaskEnv;
use lhm_sim::motion::demo::{AmpWindow, DemoMotion};
use lhm_sim::CharacterModel;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let stem = std::env::args()
        .nth(1)
        .ok_or("usage: style_probe CHECKPOINT_STEM")?;
    let learner = Learner::load(std::path::Path::new(&stem), None)?;
    let amp = learner
        .amp
        .as_ref()
        .ok_or("no discriminator in this checkpoint")?;
    let config = TrainConfig::default();
    let model = CharacterModel::amp_humanoid();
    let bench = Benchmark::embedded()?;
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len().max(1) as f32;
    let demo = DemoMotion::load_dir(
        &model,
        &lhm_sim::motion::default_dir(),
        AmpWindow::of(&config.env, &config.sim),
    )?;
    let mut split = SplitMix64::new(7);
    let mut rng = || split.next_f64();
    let rows = demo.sample_features(512, &mut rng);
    println!(
        "demo windows: style {:.3}",
        mean(&amp.style_rewards(&rows)?)
    );
    for stochastic in [false, true] {
        let mut feats = Vec::new();
        let mut first = Vec::new();
        let mut net_rng = SplitMix64::new(3);
        for id in ["train-0001", "train-0002", "train-0003", "train-0004"] {
            let (_, task) = bench.task(id).ok_or("task")?;
            let mut env = TaskEnv::new(
                &model,
                &task,
                &bench.catalogue,
                config.sim.clone(),
                config.env.clone(),
            );
            for step in 0..90 {
                let obs = env.observation();
                let a = if stochastic {
                    learner.actor_critic.act(&obs, &mut net_rng)?.actions
                } else {
                    learner.actor_critic.act_deterministic(&obs)?
                };
                let r = env.step(&a);
                if step < 10 {
                    first.extend(env.amp_features());
                }
                feats.extend(env.amp_features());
                if r.done {
                    break;
                }
            }
        }
        println!(
            "policy {}: style {:.3} over all steps, {:.3} over the first 10 steps",
            if stochastic {
                "with noise"
            } else {
                "mean action"
            },
            mean(&amp.style_rewards(&feats)?),
            mean(&amp.style_rewards(&first)?)
        );
    }
    Ok(())
}
