//! `cargo run --release -p lhm-cli --example gait_tracking_probe -- RUN_DIR [TASKS] [SEEDS] [policy]`:
//! how closely the character's joints follow the gait base's targets while it walks, per joint.
//!
//! The forty-ninth session found the held discriminator's verdict on the policy's walk resting on
//! the arms, the head and the torso, and the gait base alone (zero residual) already holding them
//! off the clips. The base's targets for the arms and the neck are the clip's own joint angles (no
//! feedback acts on them), so any difference there is the servo's tracking (gravity sag, limits,
//! the legs' motion carried up the chain) — this probe measures it. Walking starts on the first
//! TASKS unseen tasks × SEEDS, zero residual (the base alone) unless `policy` (the run's mean
//! action); only steps where the gait walks (not ramping in from rest, not stopped) count. Prints,
//! per DoF, the mean target, the mean achieved angle, the mean and RMS tracking error (degrees),
//! and the root's mean horizontal speed against the clip's.
#[path = "shared/gait_run.rs"]
mod gait_run;
#[path = "shared/pose_error.rs"]
mod pose_error;

use gait_run::GaitRun;
use lhm_scenes::Split;
use lhm_sim::fidelity::joint_angles;
use pose_error::PoseError;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(
        args.next()
            .ok_or("usage: gait_tracking_probe RUN_DIR [TASKS] [SEEDS] [policy]")?,
    );
    let tasks: usize = args.next().map_or(Ok(8), |s| s.parse())?;
    let seeds: u64 = args.next().map_or(Ok(2), |s| s.parse())?;
    let use_policy = match args.next().as_deref() {
        None => false,
        Some("policy") => true,
        Some(other) => return Err(format!("{other:?}: the fourth argument is `policy`").into()),
    };
    let run = GaitRun::load(&dir, "checkpoint")?;
    let model = &run.model;
    let n = model.dofs.len();
    let action_dim = run.learner.actor_critic.act_dim();
    let setup = run.eval_setup(false);
    let (mut sum_t, mut sum_a, mut sum_e, mut sum_e2) =
        (vec![0f64; n], vec![0f64; n], vec![0f64; n], vec![0f64; n]);
    let (mut count, mut speed_sum, mut falls, mut episodes) = (0usize, 0f64, 0usize, 0usize);
    let mut pose = PoseError::default();
    // Per episode, the walking steps' (target, achieved) angles in step order, for the lag.
    let mut series: Vec<Vec<(Vec<f32>, Vec<f32>)>> = Vec::new();
    let unseen: Vec<_> = run
        .bench
        .tasks(Split::Unseen)
        .iter()
        .take(tasks)
        .cloned()
        .collect();
    for task in &unseen {
        for seed in 0..seeds {
            let mut env = setup.env_for(task, seed);
            episodes += 1;
            let mut episode = Vec::new();
            loop {
                let walking = env.gait_running() && !env.gait_stopped();
                let target = env.gait_reference_angles();
                let action = if use_policy {
                    run.learner
                        .actor_critic
                        .act_deterministic(&env.observation())?
                } else {
                    vec![0.0; action_dim]
                };
                // A stop or a fall breaks the walk: the lag is measured over unbroken runs only.
                if !walking {
                    series.push(std::mem::take(&mut episode));
                }
                let r = env.step(&action);
                if walking && !env.gait_ramping() && !r.fell {
                    if let Some(target) = target {
                        let states = env.world.body_states();
                        let achieved = joint_angles(model, &states);
                        for d in 0..n {
                            let (t, a) = (target[d] as f64, achieved[d] as f64);
                            sum_t[d] += t;
                            sum_a[d] += a;
                            sum_e[d] += a - t;
                            sum_e2[d] += (a - t) * (a - t);
                        }
                        episode.push((target.clone(), achieved));
                        let v = states[0].linvel;
                        speed_sum += (v.x as f64).hypot(v.y as f64);
                        count += 1;
                        if let Some(reference) = env.gait_imitation_target() {
                            pose.add(model, &states, &reference);
                        }
                    }
                }
                if r.done || r.truncated || r.physics_invalid {
                    falls += usize::from(r.fell);
                    series.push(episode);
                    break;
                }
            }
        }
    }
    if count == 0 {
        return Err("no walking steps were recorded".into());
    }
    let c = count as f64;
    let deg = 180.0 / std::f64::consts::PI;
    println!(
        "{} walking steps over {episodes} episodes ({falls} fell), {}; root speed {:.3} m/s",
        count,
        if use_policy {
            "the policy's mean action"
        } else {
            "zero residual (the base alone)"
        },
        speed_sum / c
    );
    pose.print();
    println!(
        "{:>18} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>5} {:>9}",
        "dof", "target°", "achieved°", "error°", "rms°", "t-std°", "a-std°", "lag", "rms@lag°"
    );
    for d in 0..n {
        let (mt, ma) = (sum_t[d] / c, sum_a[d] / c);
        let (st, sa) = (spread(&series, d, mt, true), spread(&series, d, ma, false));
        let (lag, rms_at_lag) = best_lag(&series, d, MAX_LAG);
        println!(
            "{:>18} {:9.2} {:9.2} {:9.2} {:9.2} {:9.2} {:9.2} {:>5} {:9.2}",
            model.dofs[d].name,
            mt * deg,
            ma * deg,
            (ma - mt) * deg,
            (sum_e2[d] / c).sqrt() * deg,
            st * deg,
            sa * deg,
            lag,
            rms_at_lag * deg
        );
    }
    Ok(())
}

/// Lags (control steps) tried for the achieved angle trailing the target.
const MAX_LAG: usize = 8;

/// Standard deviation of DoF `d`'s target (`target`) or achieved angle about `mean`.
fn spread(series: &[Vec<(Vec<f32>, Vec<f32>)>], d: usize, mean: f64, target: bool) -> f64 {
    let (mut sum, mut n) = (0f64, 0usize);
    for (t, a) in series.iter().flatten() {
        let x = if target { t[d] } else { a[d] } as f64 - mean;
        sum += x * x;
        n += 1;
    }
    (sum / n.max(1) as f64).sqrt()
}

/// The lag (0..=`max`) at which the achieved angle of DoF `d`, its mean error removed, best
/// matches the target `lag` steps earlier within each unbroken walk, and the RMS error there.
fn best_lag(series: &[Vec<(Vec<f32>, Vec<f32>)>], d: usize, max: usize) -> (usize, f64) {
    (0..=max)
        .filter_map(|lag| {
            let pairs: Vec<f64> = series
                .iter()
                .flat_map(|run| {
                    run.iter()
                        .skip(lag)
                        .zip(run.iter())
                        .map(|((_, a), (t, _))| (a[d] - t[d]) as f64)
                })
                .collect();
            if pairs.is_empty() {
                return None;
            }
            let m = pairs.iter().sum::<f64>() / pairs.len() as f64;
            let var = pairs.iter().map(|e| (e - m) * (e - m)).sum::<f64>() / pairs.len() as f64;
            Some((lag, var.sqrt()))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, f64::NAN))
}
