//! `cargo run --release -p lhm-cli --example servo_replay_probe -- RUN_DIR [CYCLES] [MODE]`: the
//! servos alone following targets, root pinned, per DoF.
//!
//! `gait_tracking_probe` found the shoulders' z (the upper arm's twist about its own long axis)
//! following the clip no better than a constant while the character walks. Pinned at the root
//! (no balance, no contacts but the floor far below), every DoF is driven open loop for CYCLES
//! cycles of the gait's clip (the first cycle more, not counted) with, by MODE:
//! none: the gait's reference angles; `clip:PART`: those on the DoFs whose name contains PART,
//! the rest at 0; `hold:K`: the reference's step K held still; `set:NAME=DEG,...`: those static
//! targets; a DoF name: a 15° sine on it at the cycle's period. Prints per DoF the mean error,
//! the RMS error, the target's and the achieved angle's spread, the lag (control steps) that
//! best lines them up with the error's spread and the correlation there, and the mean target.
//! This found the saturated servo's stall fixed in `lhm_sim::character` (RESULTS.md, fifty-first
//! session).
#[path = "shared/gait_run.rs"]
mod gait_run;

use gait_run::GaitRun;
use lhm_sim::fidelity::joint_angles;
use lhm_sim::{SimConfig, World};
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(
        args.next()
            .ok_or("usage: servo_replay_probe RUN_DIR [CYCLES]")?,
    );
    let cycles: usize = args.next().map_or(Ok(4), |s| s.parse())?;
    let alone = args.next();
    let run = GaitRun::load(&dir, "checkpoint")?;
    let model = &run.model;
    let n = model.dofs.len();
    let config = SimConfig {
        pin_root: true,
        spawn_height: run.config.sim.spawn_height + 0.5,
        ..run.config.sim.clone()
    };
    let mut world = World::new(model, config);
    let len = run.reference.len();
    let mut target_log = Vec::new();
    let mut achieved_log = Vec::new();
    // The first cycle settles from the neutral pose; it is not counted.
    for k in 0..len * (cycles + 1) {
        let target = mode_targets(alone.as_deref(), &run, k)?;
        world.step_targets(&target);
        if k >= len {
            target_log.push(target);
            achieved_log.push(joint_angles(model, &world.body_states()));
        }
    }
    let deg = 1f64.to_degrees();
    println!(
        "{} steps ({} cycles of {len}), root pinned",
        target_log.len(),
        cycles
    );
    println!(
        "{:>18} {:>8} {:>8} {:>8} {:>8} {:>4} {:>8} {:>6} {:>8}",
        "dof", "error°", "rms°", "t-std°", "a-std°", "lag", "rms@lag°", "corr", "t-mean°"
    );
    for d in 0..n {
        let t: Vec<f64> = target_log.iter().map(|x| x[d] as f64).collect();
        let a: Vec<f64> = achieved_log.iter().map(|x| x[d] as f64).collect();
        let e: Vec<f64> = a.iter().zip(&t).map(|(a, t)| a - t).collect();
        let (mean_e, rms) = (
            mean(&e),
            (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt(),
        );
        let (lag, rms_lag, corr) = (0..=8)
            .map(|lag| {
                let ts = &t[..t.len() - lag];
                let as_ = &a[lag..];
                let err: Vec<f64> = as_.iter().zip(ts).map(|(a, t)| a - t).collect();
                (lag, std(&err), correlation(ts, as_))
            })
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .unwrap_or((0, f64::NAN, f64::NAN));
        println!(
            "{:>18} {:8.2} {:8.2} {:8.2} {:8.2} {:>4} {:8.2} {:6.3} {:8.2}",
            model.dofs[d].name,
            mean_e * deg,
            rms * deg,
            std(&t) * deg,
            std(&a) * deg,
            lag,
            rms_lag * deg,
            corr,
            mean(&t) * deg
        );
    }
    Ok(())
}

/// The targets of step `k` for MODE (see the header).
fn mode_targets(
    alone: Option<&str>,
    run: &GaitRun,
    k: usize,
) -> Result<Vec<f32>, Box<dyn std::error::Error>> {
    let (model, n, len) = (&run.model, run.model.dofs.len(), run.reference.len());
    let mut target = run.reference.at(k).1.to_vec();
    if let Some(list) = alone.and_then(|a| a.strip_prefix("set:")) {
        // Static targets: `NAME=DEG,...`, the rest at 0.
        target = vec![0.0; n];
        for item in list.split(',') {
            let (name, deg) = item.split_once('=').ok_or("set:NAME=DEG,...")?;
            let d = model
                .dofs
                .iter()
                .position(|d| d.name == name)
                .ok_or_else(|| format!("{name:?}: no such DoF"))?;
            target[d] = deg.parse::<f32>()?.to_radians();
        }
    } else if let Some(step) = alone.and_then(|a| a.strip_prefix("hold:")) {
        // The clip's targets of one step held still: the static error alone.
        target = run.reference.at(step.parse::<usize>()?).1.to_vec();
    } else if let Some(part) = alone.and_then(|a| a.strip_prefix("clip:")) {
        // The clip's targets on the DoFs whose name contains `part`, the rest at 0.
        for (x, dof) in target.iter_mut().zip(&model.dofs) {
            if !dof.name.contains(part) {
                *x = 0.0;
            }
        }
    } else if let Some(name) = alone {
        let d = model
            .dofs
            .iter()
            .position(|d| d.name == name)
            .ok_or_else(|| format!("{name:?}: no such DoF"))?;
        target = vec![0.0; n];
        let phase = std::f32::consts::TAU * (k % len) as f32 / len as f32;
        target[d] = 15f32.to_radians() * phase.sin();
    }
    Ok(target)
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len().max(1) as f64
}

fn std(x: &[f64]) -> f64 {
    let m = mean(x);
    (x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len().max(1) as f64).sqrt()
}

fn correlation(x: &[f64], y: &[f64]) -> f64 {
    let (mx, my) = (mean(x), mean(y));
    let cov: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    cov / (std(x) * std(y) * x.len() as f64)
}
