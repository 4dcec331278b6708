//! Diagnostic: where a `[env.gait]` run's discriminator tells the policy from the clips. Plays the
//! run's checkpoint with mean actions on unseen tasks (from rest and walking, as `lhm eval` starts
//! them), splits the agent's AMP windows into "walking" (the base runs the cycle), "stopped" (the
//! base stands after its stop) and "falling" (the last 15 steps before a fall), and prints the
//! discriminator's style reward and accuracy on each and on demo windows, and the features whose
//! means differ most from the clips' (in the clips' standard deviations).
//! `cargo run --release -p lhm-cli --example gait_style_probe -- RUN_DIR [TASKS] [SEEDS] [zero |
//! scale=JOINT:K]` (`zero`: the gait base alone acts, zero residuals, judged by the run's
//! discriminator; `scale=abdomen:0`: the residual on the joints whose name contains `abdomen` times 0).
//! Also prints how many episodes fell.
#[path = "shared/gait_run.rs"]
mod gait_run;
use gait_run::{scale_residual, GaitRun};
use lhm_learner::AmpTrainer;
use lhm_nets::SplitMix64;
use lhm_scenes::Split;
use lhm_sim::mjcf::JointKind;
use lhm_sim::obs::amp_frame_dim;
use std::path::PathBuf;

const FALL_TAIL: usize = 15;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(
        args.next()
            .ok_or("usage: gait_style_probe RUN_DIR [TASKS] [SEEDS] [zero | scale=JOINT:K]")?,
    );
    let tasks: usize = args.next().map_or(Ok(8), |s| s.parse())?;
    let seeds: u64 = args.next().map_or(Ok(4), |s| s.parse())?;
    // The policy's residual on the joints whose name contains `scaled.0` is multiplied by
    // `scaled.1` (`zero`: every joint by 0, the gait base alone).
    let scaled: Option<(String, f32)> = match args.next().as_deref() {
        None => None,
        Some("zero") => Some((String::new(), 0.0)),
        Some(arg) => {
            let bad = || format!("{arg:?}: the fourth argument is `zero` or `scale=JOINT:K`");
            let (joint, k) = arg
                .strip_prefix("scale=")
                .and_then(|s| s.split_once(':'))
                .ok_or_else(bad)?;
            Some((joint.to_string(), k.parse().map_err(|_| bad())?))
        }
    };
    let run = GaitRun::load(&dir, "checkpoint")?;
    let GaitRun {
        learner,
        model,
        bench,
        demo,
        ..
    } = &run;
    let amp = learner
        .amp
        .as_ref()
        .ok_or("no discriminator in this checkpoint (AMP off)")?;
    if let Some((joint, _)) = &scaled {
        if !model.dofs.iter().any(|d| d.name.contains(joint.as_str())) {
            let names: Vec<&str> = model.dofs.iter().map(|d| d.name.as_str()).collect();
            return Err(format!("scale={joint}: no joint's name contains it ({names:?})").into());
        }
    }
    let unseen: Vec<_> = bench
        .tasks(Split::Unseen)
        .iter()
        .take(tasks)
        .cloned()
        .collect();
    // [walking, stopped, falling] windows.
    let mut groups: [Vec<f32>; 3] = Default::default();
    let (mut episodes, mut falls) = (0usize, 0usize);
    for rest in [true, false] {
        let setup = run.eval_setup(rest);
        for task in &unseen {
            for seed in 0..seeds {
                let mut env = setup.env_for(task, seed);
                let mut episode: Vec<(bool, Vec<f32>)> = Vec::new();
                let fell = loop {
                    let mut a = learner.actor_critic.act_deterministic(&env.observation())?;
                    scale_residual(&mut a, model, scaled.as_ref());
                    let r = env.step(&a);
                    episode.push((env.gait_stopped(), env.amp_features()));
                    if r.done || r.truncated || r.physics_invalid {
                        break r.fell;
                    }
                };
                episodes += 1;
                falls += usize::from(fell);
                let tail = if fell {
                    episode.len().saturating_sub(FALL_TAIL)
                } else {
                    episode.len()
                };
                for (k, (stopped, f)) in episode.into_iter().enumerate() {
                    let g = if k >= tail { 2 } else { usize::from(stopped) };
                    groups[g].extend(f);
                }
            }
        }
    }
    let width = amp.feature_dim();
    let mut split = SplitMix64::new(7);
    let mut rng = || split.next_f64();
    let demo_rows = demo.sample_features(4096, &mut rng);
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len().max(1) as f32;
    let report = |name: &str, rows: &[f32]| -> Result<(), Box<dyn std::error::Error>> {
        if rows.is_empty() {
            println!("{name:>8}: no windows");
            return Ok(());
        }
        let style = amp.style_rewards(rows)?;
        let logits = amp.logits(rows)?;
        let real = logits.iter().filter(|&&d| d > 0.0).count() as f32 / logits.len() as f32;
        println!(
            "{name:>8}: {:6} windows, style {:.3}, judged demo {:.3}",
            rows.len() / width,
            mean(&style),
            real
        );
        Ok(())
    };
    println!("{falls} of {episodes} episodes fell");
    report("demo", &demo_rows)?;
    // Every window of each clip, one a control step: which clips the discriminator takes for demo
    // (the gait's reference is one of them, `[env.gait] clip`).
    let dt = 1.0 / run.config.sim.control_hz;
    let frames = width / amp_frame_dim(model);
    let span = dt * (frames - 1) as f32;
    let clips: Vec<(String, f32)> = demo.clips().map(|(n, d)| (n.to_string(), d)).collect();
    let mut clip_rows: Vec<(String, Vec<f32>)> = Vec::new();
    for (k, (name, duration)) in clips.iter().enumerate() {
        let mut rows = Vec::new();
        let mut start = dt;
        while start + span <= *duration {
            for f in 0..frames {
                rows.extend(demo.amp_frame_at(k, start + f as f32 * dt));
            }
            start += dt;
        }
        if rows.is_empty() {
            continue;
        }
        let logits = amp.logits(&rows)?;
        let real = logits.iter().filter(|&&d| d > 0.0).count() as f32 / logits.len() as f32;
        println!(
            "    clip {name:<20} {:4} windows, mean logit {:+.4}, judged demo {real:.3}",
            logits.len(),
            mean(&logits)
        );
        clip_rows.push((name.clone(), rows));
    }
    for (name, rows) in ["walking", "stopped", "falling"].iter().zip(&groups) {
        report(name, rows)?;
    }
    // Which features the stand differs on, in the clips' standard deviations.
    let frame = amp_frame_dim(model);
    let (dm, ds) = column_stats(&demo_rows, width);
    // The joint-rotation block's entries by body, in the AMP frame's order.
    let mut rotation_names = Vec::new();
    for b in &model.bodies {
        match b.joint {
            JointKind::Ball { .. } => {
                rotation_names.extend((0..6).map(|k| format!("{} rot6 {k}", b.name)))
            }
            JointKind::Hinge { .. } => rotation_names.push(format!("{} angle", b.name)),
            JointKind::Free | JointKind::Fixed => {}
        }
    }
    let keys = ["right hand", "left hand", "right foot", "left foot"];
    let label = |i: usize| -> String {
        let (w, j) = (i / frame, i % frame);
        let rotations = rotation_names.len();
        let what = match j {
            0 => "root height".to_string(),
            1..=6 => format!("root rot6 {}", j - 1),
            7..=9 => format!("root linvel {}", j - 7),
            10..=12 => format!("root angvel {}", j - 10),
            _ if j < 13 + rotations => rotation_names[j - 13].clone(),
            _ if j < 13 + rotations + model.dofs.len() => {
                model.dofs[j - 13 - rotations].name.clone() + " velocity"
            }
            _ => {
                let k = j - 13 - rotations - model.dofs.len();
                format!(
                    "{} {}",
                    keys.get(k / 3).unwrap_or(&"key body"),
                    ["x", "y", "z"][k % 3]
                )
            }
        };
        format!("frame {w} {what}")
    };
    for (name, rows) in ["walking", "stopped"].iter().zip(&groups) {
        if rows.is_empty() {
            continue;
        }
        let (am, _) = column_stats(rows, width);
        let mut z: Vec<(usize, f64)> = (0..width).map(|i| (i, (am[i] - dm[i]) / ds[i])).collect();
        z.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
        println!("{name}: features furthest from the clips' mean (z = (agent - demo) / demo std)");
        for (i, zi) in z.iter().take(8) {
            println!("  {:>6.2}  {}", zi, label(*i));
        }
        attribute(amp, rows, &demo_rows, frame, "the clips'", &label)?;
    }
    let reference_clip = run.config.env.gait.as_ref().map(|g| g.clip.clone());
    if let Some(reference) = clip_rows
        .iter()
        .find(|(n, _)| Some(n) == reference_clip.as_ref())
    {
        println!("walking against the gait's own clip, {}:", reference.0);
        attribute(amp, &groups[0], &reference.1, frame, "its clip's", &label)?;
    }
    Ok(())
}

/// Mean and standard deviation (floored at 1e-3) of each column of `rows` (`width` wide).
fn column_stats(rows: &[f32], width: usize) -> (Vec<f64>, Vec<f64>) {
    let n = (rows.len() / width).max(1) as f64;
    let mut m = vec![0.0f64; width];
    let mut s = vec![0.0f64; width];
    for row in rows.chunks_exact(width) {
        for (i, &x) in row.iter().enumerate() {
            m[i] += f64::from(x) / n;
        }
    }
    for row in rows.chunks_exact(width) {
        for (i, &x) in row.iter().enumerate() {
            s[i] += (f64::from(x) - m[i]).powi(2) / n;
        }
    }
    (m, s.into_iter().map(|v| v.sqrt().max(1e-3)).collect())
}

/// Which features the discriminator's verdict on `rows` rests on, against `target` windows: the
/// mean logit after one group of features (a body's rotation, a root quantity, a key body's
/// position; both frames) is moved by the target's mean minus the rows', against the unchanged
/// rows' mean logit. The groups whose move closes most of the gap to the target's mean logit
/// carry it (a mean shift: what it leaves is in the shape of the distributions).
fn attribute(
    amp: &AmpTrainer,
    rows: &[f32],
    target: &[f32],
    frame: usize,
    whose: &str,
    label: &dyn Fn(usize) -> String,
) -> Result<(), Box<dyn std::error::Error>> {
    let width = amp.feature_dim();
    let mean = |v: &[f32]| f64::from(v.iter().sum::<f32>()) / v.len().max(1) as f64;
    let (am, _) = column_stats(rows, width);
    let (tm, ts) = column_stats(target, width);
    let base = mean(&amp.logits(rows)?);
    let target_logit = mean(&amp.logits(target)?);
    // "frame 1 left_upper_arm rot6 4" -> "left_upper_arm rot6".
    let group_of = |i: usize| -> String {
        let text = label(i);
        let mut words: Vec<&str> = text.split(' ').skip(2).collect();
        if words.len() > 1
            && words
                .last()
                .is_some_and(|w| w.parse::<u32>().is_ok() || ["x", "y", "z"].contains(w))
        {
            words.pop();
        }
        words.join(" ")
    };
    let mut groups: Vec<(String, Vec<usize>)> = Vec::new();
    for i in 0..width {
        let g = group_of(i);
        match groups.iter_mut().find(|(name, _)| *name == g) {
            Some((_, members)) => members.push(i),
            None => groups.push((g, vec![i])),
        }
    }
    let shifted_logit =
        |members: &mut dyn Iterator<Item = usize>| -> Result<f64, Box<dyn std::error::Error>> {
            let members: Vec<usize> = members.collect();
            let mut shifted = rows.to_vec();
            for row in shifted.chunks_exact_mut(width) {
                for &i in &members {
                    row[i] += (tm[i] - am[i]) as f32;
                }
            }
            Ok(mean(&amp.logits(&shifted)?))
        };
    let mut moved: Vec<(&str, &[usize], f64)> = Vec::new();
    for (g, members) in &groups {
        let logit = shifted_logit(&mut members.iter().copied())?;
        moved.push((g.as_str(), members.as_slice(), logit - base));
    }
    moved.sort_by(|a, b| b.2.total_cmp(&a.2));
    println!(
        "  mean logit {base:.4} ({whose} {target_logit:.4}); change when one group is moved to \
         {whose} mean, largest first"
    );
    for (k, (g, members, d)) in moved.iter().take(10).enumerate() {
        println!("  {d:>+8.4}  {g}");
        if k < 5 {
            // Its components in the last frame: the two means and z in the target's std.
            for &i in members.iter().filter(|&&i| i >= width - frame) {
                println!(
                    "            {:<32} agent {:>+7.3}  target {:>+7.3} ± {:.3}  z {:>+6.2}",
                    label(i),
                    am[i],
                    tm[i],
                    ts[i],
                    (am[i] - tm[i]) / ts[i]
                );
            }
        }
    }
    let all = shifted_logit(&mut (0..width))?;
    println!("  every feature moved: mean logit {all:.4}");
    Ok(())
}
