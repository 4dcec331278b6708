//! `cargo run --release -p lhm-cli --example gait_ilc_probe -- RUN_DIR [TASKS] [SEEDS] [ITERS]
//! [GAIN] [policy] [joints=KEY+KEY…] [smooth=N] [out=FILE]`: fits `[env.gait] angle_offsets`,
//! the feed-forward that brings the walking character's joints onto the clip's, by iterative
//! learning control.
//!
//! The fifty-fifth session found a fresh discriminator telling the trained walk from the clips on
//! one frame's posture (0.95 agent side without any velocity) and the servos holding the arms 7-9°
//! and the knees 10-14° off the clip on average. The base's targets are the clip's angles plus
//! balance feedback; what the servo misses under gravity and load it misses the same way every
//! cycle, so a per-cycle-step offset learnt from the mean error takes it out (ILC: offset_k +=
//! GAIN · mean over walking steps at cycle step k of (clip angle − achieved angle), smoothed over
//! ±`smooth` steps of the cycle).
//!
//! Each of ITERS+1 rounds plays walking starts on the first TASKS training tasks × SEEDS (zero
//! residual, the base alone, unless `policy`: the run's mean action) with the offsets so far, and
//! prints falls, root speed, the imitation term's pose error and the mean and RMS joint error
//! over the fitted DoFs (the DoFs whose name contains a `joints` key; default every DoF); every
//! round but the last then updates the offsets. The `angle_offsets` in force at the checkpoint's
//! iteration (its stage's, in a run with stages) are the start.
//! `out=FILE` writes the last offsets as a TOML `[env.gait.angle_offsets]` table, to lay over the
//! run's config with `--config`.
#[path = "shared/gait_run.rs"]
mod gait_run;
#[path = "shared/pose_error.rs"]
mod pose_error;

use gait_run::GaitRun;
use lhm_scenes::Split;
use lhm_sim::fidelity::joint_angles;
use pose_error::PoseError;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

struct Args {
    dir: PathBuf,
    tasks: usize,
    seeds: u64,
    iters: usize,
    gain: f32,
    policy: bool,
    joints: Vec<String>,
    smooth: usize,
    out: Option<PathBuf>,
}

fn parse() -> Result<Args, Box<dyn std::error::Error>> {
    let usage = "usage: gait_ilc_probe RUN_DIR [TASKS] [SEEDS] [ITERS] [GAIN] [policy] \
                 [joints=KEY+KEY] [smooth=N] [out=FILE]";
    let mut positional = Vec::new();
    let mut a = Args {
        dir: PathBuf::new(),
        tasks: 8,
        seeds: 2,
        iters: 4,
        gain: 0.7,
        policy: false,
        joints: Vec::new(),
        smooth: 1,
        out: None,
    };
    for arg in std::env::args().skip(1) {
        if arg == "policy" {
            a.policy = true;
        } else if let Some(v) = arg.strip_prefix("joints=") {
            a.joints = v.split('+').map(str::to_string).collect();
        } else if let Some(v) = arg.strip_prefix("smooth=") {
            a.smooth = v.parse()?;
        } else if let Some(v) = arg.strip_prefix("out=") {
            a.out = Some(PathBuf::from(v));
        } else {
            positional.push(arg);
        }
    }
    let mut p = positional.into_iter();
    a.dir = PathBuf::from(p.next().ok_or(usage)?);
    if let Some(v) = p.next() {
        a.tasks = v.parse()?;
    }
    if let Some(v) = p.next() {
        a.seeds = v.parse()?;
    }
    if let Some(v) = p.next() {
        a.iters = v.parse()?;
    }
    if let Some(v) = p.next() {
        a.gain = v.parse()?;
    }
    if let Some(extra) = p.next() {
        return Err(format!("{extra:?}: unexpected; {usage}").into());
    }
    Ok(a)
}

/// What one round measured: per DoF and cycle step, the summed error (clip − achieved) and count.
struct Round {
    error: Vec<Vec<f64>>,
    count: Vec<usize>,
    pose: PoseError,
    steps: usize,
    episodes: usize,
    falls: usize,
    speed: f64,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = parse()?;
    let mut run = GaitRun::load(&args.dir, "checkpoint")?;
    let model = run.model.clone();
    let n_dof = model.dofs.len();
    let mut gait = run
        .config
        .env
        .gait
        .clone()
        .ok_or("the run has no [env.gait]")?;
    let dt = 1.0 / run.config.sim.control_hz;
    let clip = lhm_sim::gait::reference_for(&model, &run.demo, &gait.clip, dt)?;
    let len = clip.len();
    let fitted: Vec<bool> = model
        .dofs
        .iter()
        .map(|d| args.joints.is_empty() || args.joints.iter().any(|k| d.name.contains(k)))
        .collect();
    // offsets[d][k], from the run's own.
    let mut offsets = vec![vec![0f32; len]; n_dof];
    for (name, values) in &gait.angle_offsets {
        let d = model
            .dofs
            .iter()
            .position(|d| &d.name == name)
            .ok_or_else(|| format!("angle_offsets.{name}: no such DoF"))?;
        for (k, o) in offsets[d].iter_mut().enumerate() {
            *o = values[if values.len() == 1 { 0 } else { k }];
        }
    }
    let tasks: Vec<_> = run
        .bench
        .tasks(Split::Train)
        .iter()
        .take(args.tasks)
        .cloned()
        .collect();
    let deg = 180.0 / std::f64::consts::PI;
    println!(
        "ILC on {} DoFs, {} training tasks x {} seeds, {}, gain {}, smooth ±{}, cycle {len} steps",
        fitted.iter().filter(|f| **f).count(),
        tasks.len(),
        args.seeds,
        if args.policy {
            "the policy's mean action"
        } else {
            "zero residual (the base alone)"
        },
        args.gain,
        args.smooth
    );
    for round in 0..=args.iters {
        gait.angle_offsets = offset_table(&model, &offsets, &fitted);
        run.reference = Arc::new(
            clip.clone()
                .with_angle_offsets(&model, &gait.angle_offsets)?,
        );
        let r = play(&run, &tasks, args.seeds, args.policy, &clip)?;
        let (mut mean_err, mut sq_err, mut cells) = (0f64, 0f64, 0usize);
        let mut per_dof = Vec::new();
        for d in (0..n_dof).filter(|&d| fitted[d]) {
            let (s, c): (f64, usize) = (r.error[d].iter().sum(), r.count.iter().sum());
            let m = s / c.max(1) as f64;
            per_dof.push(format!("{} {:+.1}", model.dofs[d].name, m * deg));
            for k in 0..len {
                if r.count[k] > 0 {
                    let e = r.error[d][k] / r.count[k] as f64;
                    mean_err += e.abs();
                    sq_err += e * e;
                    cells += 1;
                }
            }
        }
        let c = cells.max(1) as f64;
        let s = r.pose.steps.max(1) as f64;
        println!(
            "round {round}: {} walking steps, {} episodes ({} fell), root speed {:.3} m/s; pose \
             error world {:.3} rad² (pose part {:.4}), per joint {:.3} rad² ({:.4}); fitted DoFs' \
             per-step mean error |e| {:.2}°, rms {:.2}°",
            r.steps,
            r.episodes,
            r.falls,
            r.speed / r.steps.max(1) as f64,
            r.pose.world / s,
            r.pose.world_term / s,
            r.pose.joint / s,
            r.pose.joint_term / s,
            mean_err / c * deg,
            (sq_err / c).sqrt() * deg
        );
        println!("  mean error (clip − achieved, °): {}", per_dof.join(", "));
        if round == args.iters {
            break;
        }
        for d in (0..n_dof).filter(|&d| fitted[d]) {
            let mean: Vec<f64> = (0..len)
                .map(|k| {
                    if r.count[k] > 0 {
                        r.error[d][k] / r.count[k] as f64
                    } else {
                        0.0
                    }
                })
                .collect();
            let w = args.smooth as isize;
            for (k, o) in offsets[d].iter_mut().enumerate() {
                let avg = (-w..=w)
                    .map(|j| mean[(k as isize + j).rem_euclid(len as isize) as usize])
                    .sum::<f64>()
                    / (2 * w + 1) as f64;
                *o += args.gain * avg as f32;
            }
        }
    }
    if let Some(out) = &args.out {
        let mut text = format!(
            "# gait_ilc_probe {} {} {} {} {}{} joints={} smooth={}: the last round's offsets \
             (radians per control step of the {len}-step cycle).\n[env.gait.angle_offsets]\n",
            args.dir.display(),
            args.tasks,
            args.seeds,
            args.iters,
            args.gain,
            if args.policy { " policy" } else { "" },
            if args.joints.is_empty() {
                "(all)".to_string()
            } else {
                args.joints.join("+")
            },
            args.smooth
        );
        for (name, values) in &gait.angle_offsets {
            let v: Vec<String> = values.iter().map(|x| format!("{x:.4}")).collect();
            text += &format!("{name} = [{}]\n", v.join(", "));
        }
        std::fs::write(out, text).map_err(|e| format!("{}: {e}", out.display()))?;
        println!("wrote {}", out.display());
    }
    Ok(())
}

/// The offsets of the fitted DoFs as `angle_offsets` (the others' left out).
fn offset_table(
    model: &lhm_sim::CharacterModel,
    offsets: &[Vec<f32>],
    fitted: &[bool],
) -> BTreeMap<String, Vec<f32>> {
    model
        .dofs
        .iter()
        .zip(offsets)
        .zip(fitted)
        .filter(|((_, o), f)| **f && o.iter().any(|x| *x != 0.0))
        .map(|((d, o), _)| (d.name.clone(), o.clone()))
        .collect()
}

/// Walking starts on `tasks` × `seeds` under the run's current reference; the error of every
/// walking step (not ramping, not stopped, not fallen) at the cycle step it was asked at.
fn play(
    run: &GaitRun,
    tasks: &[lhm_scenes::Task],
    seeds: u64,
    policy: bool,
    clip: &lhm_sim::gait::GaitReference,
) -> Result<Round, Box<dyn std::error::Error>> {
    let model = &run.model;
    let (n_dof, len) = (model.dofs.len(), clip.len());
    let action_dim = run.learner.actor_critic.act_dim();
    let setup = run.eval_setup(false);
    let mut r = Round {
        error: vec![vec![0.0; len]; n_dof],
        count: vec![0; len],
        pose: PoseError::default(),
        steps: 0,
        episodes: 0,
        falls: 0,
        speed: 0.0,
    };
    for task in tasks {
        for seed in 0..seeds {
            let mut env = setup.env_for(task, seed);
            r.episodes += 1;
            loop {
                let walking = env.gait_running() && !env.gait_stopped() && !env.gait_ramping();
                let k = env
                    .gait_phase()
                    .map(|p| (p * len as f32).round() as usize % len);
                let action = if policy {
                    run.learner
                        .actor_critic
                        .act_deterministic(&env.observation())?
                } else {
                    vec![0.0; action_dim]
                };
                let step = env.step(&action);
                if let (true, Some(k), false) = (walking, k, step.fell) {
                    let states = env.world.body_states();
                    let achieved = joint_angles(model, &states);
                    let want = clip.at(k).1;
                    for d in 0..n_dof {
                        r.error[d][k] += f64::from(want[d] - achieved[d]);
                    }
                    r.count[k] += 1;
                    r.steps += 1;
                    let v = states[0].linvel;
                    r.speed += f64::from(v.x.hypot(v.y));
                    if let Some(reference) = env.gait_imitation_target() {
                        r.pose.add(model, &states, &reference);
                    }
                }
                if step.done || step.truncated || step.physics_invalid {
                    r.falls += usize::from(step.fell);
                    break;
                }
            }
        }
    }
    Ok(r)
}
