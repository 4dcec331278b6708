use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use lhm_scenes::raster::Canvas;
use lhm_sim::motion::deepmimic::DeepMimicClip;
use lhm_sim::motion::retarget;
use lhm_sim::motion::{default_dir, library};
use lhm_sim::render::{write_gif, Camera};
use lhm_sim::{CharacterModel, SimConfig, World};
use std::path::PathBuf;

#[derive(Args)]
pub struct MotionArgs {
    #[command(subcommand)]
    command: MotionCommand,
}

#[derive(Subcommand)]
enum MotionCommand {
    /// The installed reference clips with their lengths (install: scripts/install-motions).
    List {
        /// Clip cache (default: $LHM_MOTION_DIR, else ~/.cache/lhm/motions).
        #[arg(long)]
        dir: Option<PathBuf>,
    },
    /// Play a clip kinematically on the character and write an animated GIF (or a PNG still of
    /// its middle frame), so the retargeting can be judged by eye.
    Render {
        clip: String,
        #[arg(short, long, value_name = "GIF|PNG")]
        output: PathBuf,
        #[arg(long)]
        dir: Option<PathBuf>,
        #[arg(long, default_value_t = 320)]
        width: u32,
        #[arg(long, default_value_t = 240)]
        height: u32,
    },
}

pub fn run(args: MotionArgs) -> Result<()> {
    match args.command {
        MotionCommand::List { dir } => {
            let dir = dir.unwrap_or_else(default_dir);
            let clips = library::list(&dir)?;
            println!("{} clips in {}", clips.len(), dir.display());
            for c in clips {
                println!(
                    "  {:<22} {:<10} {:>4} frames  {:>5.2} s",
                    c.name,
                    format!("{:?}", c.source),
                    c.frames,
                    c.duration_s
                );
            }
            Ok(())
        }
        MotionCommand::Render {
            clip,
            output,
            dir,
            width,
            height,
        } => render(&clip, &output, dir, width, height),
    }
}

fn render(
    clip: &str,
    output: &std::path::Path,
    dir: Option<PathBuf>,
    width: u32,
    height: u32,
) -> Result<()> {
    let dir = dir.unwrap_or_else(default_dir);
    let info = library::list(&dir)?
        .into_iter()
        .find(|c| c.name == clip)
        .with_context(|| {
            format!(
                "no clip {clip:?} in {} (see `lhm motion list`)",
                dir.display()
            )
        })?;
    if info.source != library::Source::DeepMimic {
        bail!("{clip}: retargeting OMOMO (SMPL-H) clips onto the character is not implemented yet");
    }
    let path = dir.join("deepmimic").join(format!("{clip}.txt"));
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let parsed = DeepMimicClip::parse(&text, &path.display().to_string())?;
    let model = CharacterModel::amp_humanoid();
    let poses = retarget::deepmimic_poses(&model, &parsed);
    let mut world = World::new(&model, SimConfig::default());
    let mut frames = Vec::with_capacity(poses.len());
    for pose in &poses {
        world.set_kinematic_pose(&retarget::forward_kinematics(&model, pose));
        frames.push(lhm_sim::render::render(
            &world,
            &Camera::third_person(&world, width, height),
            true,
        ));
    }
    let file =
        std::fs::File::create(output).with_context(|| format!("creating {}", output.display()))?;
    let out = std::io::BufWriter::new(file);
    match output.extension().and_then(|e| e.to_str()) {
        Some("png") => {
            let mid = frames.swap_remove(frames.len() / 2);
            Canvas {
                width: mid.width,
                height: mid.height,
                pixels: mid.rgb,
            }
            .write_png(out)?;
        }
        Some("gif") => write_gif(&frames, 3, out)?,
        _ => bail!("--output must end in .gif or .png"),
    }
    println!(
        "wrote {} ({} frames of {clip})",
        output.display(),
        poses.len()
    );
    Ok(())
}
