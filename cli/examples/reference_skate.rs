//! Diagnostic: does the gait's kinematic reference skate? Reads a `[env.gait]` run's reference cycle
//! (the clip as the gait plays it, one frame per control step) and prints, per foot, the share of the
//! cycle it is below the gait's contact height and how fast it moves (forward, along the root's heading)
//! while there, against the root's own forward speed. A stance foot that moves forward carries the root
//! with it: speed no physical character tracking the clip's joints can reach.
//! `cargo run --release -p lhm-cli --example reference_skate -- RUN_DIR`
// The shared loader also loads the run's learner and clips, which this diagnostic does not read.
#[allow(dead_code)]
#[path = "shared/gait_run.rs"]
mod gait_run;
use gait_run::GaitRun;
use lhm_sim::gait::{Rig, CONTACT_HEIGHT};
use lhm_sim::obs::HeadingFrame;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .ok_or("usage: reference_skate RUN_DIR")?,
    );
    let GaitRun {
        model, reference, ..
    } = GaitRun::load(&dir, "policy")?;
    let rig = Rig::new(&model).ok_or("the model lacks the AMP humanoid's legs")?;
    let n = reference.len();
    let mut root_fwd = 0.0f32;
    let mut down_fwd: [Vec<f32>; 2] = [Vec::new(), Vec::new()];
    let mut lowest = [f32::INFINITY; 2];
    println!("step,root_z,root_v_fwd,foot_z_0,foot_v_fwd_0,foot_z_1,foot_v_fwd_1");
    for k in 0..n {
        let bodies = reference.at(k).0;
        let root = &bodies[0];
        let heading = HeadingFrame::of(root);
        let v = heading.vector(root.linvel);
        root_fwd += v.x;
        let mut row = format!("{k},{:.3},{:.3}", root.pos.z, v.x);
        for i in 0..2 {
            let f = &bodies[rig.foot[i]];
            let fv = heading.vector(f.linvel);
            lowest[i] = lowest[i].min(f.pos.z);
            if f.pos.z < CONTACT_HEIGHT {
                down_fwd[i].push(fv.x);
            }
            row += &format!(",{:.3},{:.3}", f.pos.z, fv.x);
        }
        println!("{row}");
    }
    eprintln!(
        "cycle {n} steps; root forward speed mean {:.3} m/s",
        root_fwd / n as f32
    );
    for i in 0..2 {
        let v = &mut down_fwd[i];
        v.sort_by(f32::total_cmp);
        let mean = v.iter().sum::<f32>() / v.len().max(1) as f32;
        let median = v.get(v.len() / 2).copied().unwrap_or(f32::NAN);
        eprintln!(
            "foot {i}: lowest origin {:.3} m; below {CONTACT_HEIGHT} m for {} of {n} steps; forward speed there mean {mean:.3}, median {median:.3} m/s",
            lowest[i],
            v.len()
        );
    }
    Ok(())
}
