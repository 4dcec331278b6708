use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use indicatif::ProgressBar;
use lhm_scenes::raster::Canvas;
use lhm_scenes::rng::SplitMix64;
use lhm_scenes::Benchmark;
use lhm_sim::render::{render, write_gif, Camera};
use lhm_sim::{CharacterModel, SimConfig, World};
use std::path::PathBuf;

#[derive(Clone, Copy, ValueEnum)]
enum Policy {
    /// All actions 0: the servos hold the neutral pose.
    Zero,
    /// Uniform random actions in [-1, 1].
    Random,
}

#[derive(Clone, Copy, ValueEnum)]
enum View {
    /// Behind the character, walls cut away.
    Third,
    /// From the character's eyes.
    Ego,
}

#[derive(Args)]
pub struct RenderRolloutArgs {
    task: String,
    #[arg(long, value_enum, default_value = "zero")]
    policy: Policy,
    /// An animated .gif, or a .png still of the last frame.
    #[arg(short, long, value_name = "GIF|PNG")]
    output: PathBuf,
    #[arg(long, value_enum, default_value = "third")]
    view: View,
    /// Length of the rollout.
    #[arg(long, default_value_t = 4.0)]
    seconds: f32,
    #[arg(long, default_value_t = 320)]
    width: u32,
    #[arg(long, default_value_t = 240)]
    height: u32,
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

pub fn run(a: RenderRolloutArgs) -> Result<()> {
    let png = match a.output.extension().and_then(|e| e.to_str()) {
        Some("gif") => false,
        Some("png") => true,
        _ => bail!("--output must end in .gif or .png"),
    };
    let bench = Benchmark::embedded()?;
    let (_, task) = bench
        .task(&a.task)
        .with_context(|| format!("no task {:?}", a.task))?;
    let model = CharacterModel::amp_humanoid();
    let config = SimConfig::default();
    let mut world = World::with_task(&model, config.clone(), &task, &bench.catalogue);
    let mut rng = SplitMix64::new(a.seed);
    let steps = (a.seconds * config.control_hz).round() as usize;
    // Every other control step: a 15 fps GIF.
    let bar = ProgressBar::new(steps as u64);
    let mut frames = Vec::new();
    for step in 0..steps {
        let action: Vec<f32> = match a.policy {
            Policy::Zero => vec![0.0; model.dofs.len()],
            Policy::Random => (0..model.dofs.len())
                .map(|_| rng.range(-1.0, 1.0) as f32)
                .collect(),
        };
        if step % 2 == 0 {
            let camera = match a.view {
                View::Third => Camera::third_person(&world, a.width, a.height),
                View::Ego => Camera::egocentric(&world, a.width, a.height),
            };
            frames.push(render(&world, &camera, matches!(a.view, View::Third)));
        }
        if !world.step(&action) {
            tracing::warn!("physics guard tripped at step {step}; stopping the rollout");
            break;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let file = std::fs::File::create(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let out = std::io::BufWriter::new(file);
    if png {
        let last = frames.pop().context("no frame rendered")?;
        let canvas = Canvas {
            width: last.width,
            height: last.height,
            pixels: last.rgb,
        };
        canvas.write_png(out)?;
        frames = vec![];
    } else {
        write_gif(&frames, 7, out)?;
    }
    println!(
        "wrote {} ({} frames, {}x{})",
        a.output.display(),
        frames.len().max(1),
        a.width,
        a.height
    );
    Ok(())
}
