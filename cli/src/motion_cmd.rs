use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use lhm_scenes::raster::Canvas;
use lhm_sim::motion::deepmimic::DeepMimicClip;
use lhm_sim::motion::omomo::{self, OmomoClip};
use lhm_sim::motion::retarget;
use lhm_sim::motion::{default_dir, library};
use lhm_sim::render::{write_gif, Camera, Image};
use lhm_sim::{CharacterModel, SimConfig, World};
use rapier3d::math::{Pose, Rotation, Vector};
use std::path::{Path, PathBuf};

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
    /// its middle frame, or of the frame at --at), so the retargeting can be judged by eye. OMOMO
    /// clips show their box too.
    Render(RenderArgs),
    /// Check every installed clip against the environment: start an episode from frames of the
    /// clip (reference-state initialisation) and compare the AMP frame the environment records
    /// with the demo's, feature by feature, in units of the demo's std. Fails above --tolerance.
    Check {
        /// Clip cache (default: $LHM_MOTION_DIR, else ~/.cache/lhm/motions).
        #[arg(long)]
        dir: Option<PathBuf>,
        /// Frames checked per clip (evenly spread).
        #[arg(long, default_value_t = 20)]
        frames: usize,
        /// Largest allowed difference on any feature, in demo standard deviations.
        #[arg(long, default_value_t = 0.05)]
        tolerance: f32,
    },
}

#[derive(Args)]
pub struct RenderArgs {
    /// Clip name as `lhm motion list` prints it (e.g. walk_forward).
    clip: String,
    /// Output file: .gif (the whole clip) or .png (one still).
    #[arg(short, long, value_name = "GIF|PNG")]
    output: PathBuf,
    /// PNG only: the still at this time (seconds from the clip's start) instead of the middle.
    #[arg(long, value_name = "SECONDS")]
    at: Option<f32>,
    /// `follow`: behind the character, turning with it; `side`: fixed, looking across the
    /// clip's path. Default: side for OMOMO clips (lifting is seen best in profile), follow
    /// for DeepMimic ones (they walk too far for one fixed view).
    #[arg(long, value_enum)]
    camera: Option<CameraKind>,
    /// Clip cache (default: $LHM_MOTION_DIR, else ~/.cache/lhm/motions).
    #[arg(long)]
    dir: Option<PathBuf>,
    /// Image width, pixels.
    #[arg(long, default_value_t = 320)]
    width: u32,
    /// Image height, pixels.
    #[arg(long, default_value_t = 240)]
    height: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum CameraKind {
    Follow,
    Side,
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
        MotionCommand::Render(args) => render(&args),
        MotionCommand::Check {
            dir,
            frames,
            tolerance,
        } => check(&dir.unwrap_or_else(default_dir), frames.max(1), tolerance),
    }
}

/// See [`MotionCommand::Check`].
fn check(dir: &Path, frames: usize, tolerance: f32) -> Result<()> {
    use lhm_sim::env::{EnvConfig, TaskEnv};
    use lhm_sim::motion::demo::{AmpWindow, DemoMotion};
    let model = CharacterModel::amp_humanoid();
    let (env_config, sim) = (EnvConfig::default(), SimConfig::default());
    let demo = DemoMotion::load_dir(&model, dir, AmpWindow::of(&env_config, &sim))?;
    let bench = lhm_scenes::Benchmark::embedded()?;
    let (_, task) = bench.task("train-0001").context("no task train-0001")?;
    // Per-feature std of the demo, from windows sampled across every clip.
    let mut split = lhm_nets::SplitMix64::new(1);
    let mut rng = || split.next_f64();
    let dim = lhm_sim::obs::amp_frame_dim(&model);
    let rows = demo.sample_features(2000, &mut rng);
    let n = rows.len() / dim;
    let mut std = vec![0f32; dim];
    for (k, s) in std.iter_mut().enumerate() {
        let col: Vec<f32> = (0..n).map(|r| rows[r * dim + k]).collect();
        let mean = col.iter().sum::<f32>() / n as f32;
        let var = col.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / n as f32;
        *s = var.sqrt().max(1e-3);
    }
    let lead = demo.window().span_s() + demo.window().control_dt;
    let mut worst_all = 0f32;
    for (clip, (name, duration)) in demo.clips().enumerate() {
        let mut worst = (0f32, 0usize);
        for i in 0..frames {
            let t = lead + (duration - lead) * (i as f32 + 0.5) / frames as f32;
            let mut env = TaskEnv::new(
                &model,
                &task,
                &bench.catalogue,
                sim.clone(),
                env_config.clone(),
            );
            env.start_from_demo(&demo, clip, t);
            let got = env.current_amp_frame();
            let want = demo.amp_frame_at(clip, t);
            for (k, (a, b)) in got.iter().zip(&want).enumerate() {
                let d = (a - b).abs() / std[k];
                if d > worst.0 {
                    worst = (d, k);
                }
            }
        }
        println!(
            "{name:<22} worst feature difference {:.4} std (feature {})",
            worst.0, worst.1
        );
        worst_all = worst_all.max(worst.0);
    }
    if worst_all > tolerance {
        bail!("a clip's AMP features differ from the environment's by {worst_all:.3} std (tolerance {tolerance})");
    }
    println!("all clips within {tolerance} std");
    Ok(())
}

/// A clip ready to play: the character's poses `frame_dt` apart, and for OMOMO its box.
struct Playback {
    poses: Vec<retarget::KinematicPose>,
    frame_dt: f32,
    prop: Option<BoxTrack>,
}

/// The clip's box: half extents and one pose per frame.
struct BoxTrack {
    half: Vector,
    poses: Vec<Pose>,
}

fn load(model: &CharacterModel, dir: &Path, info: &library::ClipInfo) -> Result<Playback> {
    let clip = &info.name;
    match info.source {
        library::Source::DeepMimic => {
            let path = dir.join("deepmimic").join(format!("{clip}.txt"));
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("reading {}", path.display()))?;
            let parsed = DeepMimicClip::parse(&text, &path.display().to_string())?;
            Ok(Playback {
                poses: retarget::deepmimic_poses(model, &parsed),
                frame_dt: parsed.duration() / parsed.frames.len().saturating_sub(1).max(1) as f32,
                prop: None,
            })
        }
        library::Source::Omomo => {
            let path = dir.join("omomo").join(format!("{clip}.pt"));
            let file = path.display().to_string();
            let bytes = std::fs::read(&path).with_context(|| format!("reading {file}"))?;
            let parsed = OmomoClip::parse(&bytes, &file)?;
            Ok(Playback {
                poses: retarget::omomo_poses(model, &parsed, &file)?,
                frame_dt: 1.0 / omomo::FPS,
                prop: Some(box_track(&parsed)),
            })
        }
    }
}

/// The clip's box where it was recorded (not moved with the character's height correction).
/// Its size is not in the clip: both installed clips start with the box on the floor, so its
/// first height is taken as the half size of a cube (0.18–0.19 m, a 0.37 m cube; the hands are
/// 0.38–0.45 m apart while carrying it). The pose's origin is the OMOMO mesh's, which is not
/// quite the box's centre, so the drawn box is an approximation.
fn box_track(clip: &OmomoClip) -> BoxTrack {
    let half = clip.box_pose(0)[2].clamp(0.05, 0.5);
    let poses = (0..clip.frames)
        .map(|t| {
            let [x, y, z, qx, qy, qz, qw] = clip.box_pose(t);
            Pose::from_parts(
                Vector::new(x, y, z),
                Rotation::from_xyzw(qx, qy, qz, qw).normalize(),
            )
        })
        .collect();
    BoxTrack {
        half: Vector::splat(half),
        poses,
    }
}

fn render(args: &RenderArgs) -> Result<()> {
    let (clip, output) = (&args.clip, &args.output);
    let dir = args.dir.clone().unwrap_or_else(default_dir);
    let info = library::list(&dir)?
        .into_iter()
        .find(|c| &c.name == clip)
        .with_context(|| {
            format!(
                "no clip {clip:?} in {} (see `lhm motion list`)",
                dir.display()
            )
        })?;
    let still = match output.extension().and_then(|e| e.to_str()) {
        Some("png") => true,
        Some("gif") if args.at.is_some() => {
            bail!("--at picks a PNG still; a GIF plays the whole clip")
        }
        Some("gif") => false,
        _ => bail!("--output must end in .gif or .png"),
    };
    let model = CharacterModel::amp_humanoid();
    let playback = load(&model, &dir, &info)?;
    let frames = if still {
        vec![still_frame(&playback, args.at)?]
    } else {
        (0..playback.poses.len()).collect()
    };
    let camera = args.camera.unwrap_or(match info.source {
        library::Source::Omomo => CameraKind::Side,
        library::Source::DeepMimic => CameraKind::Follow,
    });
    let images = draw(
        &model,
        &playback,
        &frames,
        camera,
        (args.width, args.height),
    );
    let file =
        std::fs::File::create(output).with_context(|| format!("creating {}", output.display()))?;
    let out = std::io::BufWriter::new(file);
    if still {
        let [image] =
            <[_; 1]>::try_from(images).map_err(|_| anyhow::anyhow!("expected one still"))?;
        Canvas {
            width: image.width,
            height: image.height,
            pixels: image.rgb,
        }
        .write_png(out)?;
        println!(
            "wrote {} (frame {} of {clip}, {:.2} s)",
            output.display(),
            frames[0],
            frames[0] as f32 * playback.frame_dt
        );
    } else {
        write_gif(&images, 3, out)?;
        println!(
            "wrote {} ({} frames of {clip})",
            output.display(),
            frames.len()
        );
    }
    Ok(())
}

/// The frame nearest `at` seconds (the middle one without), within the clip.
fn still_frame(playback: &Playback, at: Option<f32>) -> Result<usize> {
    let last = playback.poses.len().saturating_sub(1);
    let t = at.unwrap_or(0.5 * last as f32 * playback.frame_dt);
    if !(t.is_finite() && t >= 0.0) {
        bail!("--at {t}: expected seconds from the clip's start");
    }
    Ok(((t / playback.frame_dt).round() as usize).min(last))
}

/// A fixed camera across the clip's path: it looks from the side of the root track's longest
/// horizontal extent over the whole clip, at the middle of the frames drawn, far enough back to
/// keep their track (and a body's height around it) in view. A still is thus a close-up seen
/// from the same side as the clip's GIF.
fn side_camera(
    poses: &[retarget::KinematicPose],
    frames: &[usize],
    width: u32,
    height: u32,
) -> Camera {
    let bounds = |poses: &mut dyn Iterator<Item = &retarget::KinematicPose>| {
        poses.fold(
            (
                Vector::splat(f32::INFINITY),
                Vector::splat(f32::NEG_INFINITY),
            ),
            |(lo, hi), p| (lo.min(p.root_pos), hi.max(p.root_pos)),
        )
    };
    let (lo, hi) = bounds(&mut poses.iter());
    let along = if hi.x - lo.x >= hi.y - lo.y {
        Vector::X
    } else {
        Vector::Y
    };
    let across = Vector::Z.cross(along);
    let (lo, hi) = bounds(&mut frames.iter().filter_map(|&i| poses.get(i)));
    let extent = Vector::new(hi.x - lo.x, hi.y - lo.y, 0.0).length();
    let target = Vector::new(0.5 * (lo.x + hi.x), 0.5 * (lo.y + hi.y), 0.7);
    let fov_y: f32 = 50.0;
    let half_h = (0.5 * fov_y.to_radians()).tan();
    let half_w = half_h * width as f32 / height.max(1) as f32;
    // 0.8 m of margin each side for the limbs and the box; 1.1 m up and down around the target.
    let distance = ((0.5 * extent + 0.8) / half_w).max(1.1 / half_h);
    Camera {
        eye: target + across * distance + Vector::Z * 0.4,
        target,
        fov_y,
        width,
        height,
    }
}

/// The character (and the clip's box) at each of `frames`.
fn draw(
    model: &CharacterModel,
    playback: &Playback,
    frames: &[usize],
    camera: CameraKind,
    (width, height): (u32, u32),
) -> Vec<Image> {
    let mut world = World::new(model, SimConfig::default());
    let prop = playback
        .prop
        .as_ref()
        .map(|b| (world.add_prop_box(b.half, Pose::IDENTITY), b));
    let side = side_camera(&playback.poses, frames, width, height);
    frames
        .iter()
        .map(|&i| {
            world.set_kinematic_pose(&retarget::forward_kinematics(model, &playback.poses[i]));
            if let Some((handle, track)) = &prop {
                world.set_prop_pose(*handle, track.poses[i]);
            }
            let view = match camera {
                CameraKind::Follow => Camera::third_person(&world, width, height),
                CameraKind::Side => side,
            };
            lhm_sim::render::render(&world, &view, true)
        })
        .collect()
}
