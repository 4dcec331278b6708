//! Diagnostic: how separable a `[env.gait]` run's policy is from the clips for a discriminator
//! trained afresh on frozen data, under discriminator settings of your choice. Plays the run's
//! checkpoint on training tasks (from rest and walking, as `lhm eval` starts them) with its own
//! action noise (`noise`) or mean actions (`mean`), keeps the windows the run's discriminator would
//! judge (the base walking; with `discriminate_stand = false` the stand after the stop stays out,
//! with `discriminate_ramp = false` the walk-off from rest),
//! splits them by episode into a training and a held-out half, and for each VARIANT trains a fresh
//! discriminator (the run's `[amp]` with the variant's keys changed) on the training half against
//! demo windows for UPDATES updates, printing its accuracy on both sides of the training and the
//! held-out data as it goes. The policy does not move here: what a variant cannot separate on frozen
//! data, the training run's discriminator cannot either.
//! `cargo run --release -p lhm-cli --example disc_fresh_probe -- RUN_DIR TASKS SEEDS noise|mean
//! UPDATES [scale=JOINT:K] [mask=CLASS+...] [holdout=CLIP] [mirror] VARIANT...` with VARIANT a comma-separated list of `gp=X`,
//! `logit_reg=X`, `lr=X`, `wd=X`, `hidden=256x128` (the discriminator's hidden widths), `target=X`
//! (the rate steered to that accuracy) (`base`: the
//! run's own settings); `scale=abdomen:0.5` multiplies the policy's residual on the joints whose
//! name contains `abdomen` by 0.5 while playing; `mask=jointvel+rootvel` zeroes those feature
//! classes (height, rootrot, rootvel, rootang, jointrot, jointvel, keybody; `older`: every frame
//! but the newest) in the agent's and the demo's windows alike, so the fresh discriminators judge
//! without them (the run's own discriminator is shown the whole windows); `target=0` in a
//! variant takes the accuracy target off; `holdout=NAME` leaves the clips whose name contains
//! NAME out of the fresh discriminators' demo and reports how many of their windows those
//! discriminators still take for demo (real motion they were not shown); `mirror` adds each demo
//! clip's left-right mirror image to the fresh discriminators' demo (`DemoMotion::with_mirrors`).
#[path = "shared/gait_run.rs"]
mod gait_run;
use gait_run::{scale_residual, GaitRun};
use lhm_learner::amp::{AmpConfig, AmpTrainer};
use lhm_nets::SplitMix64;
use lhm_scenes::Split;
use std::path::PathBuf;

/// Agent rows per update: about the judged rows of one 4,096-sample iteration.
const AGENT_ROWS: usize = 2048;
const REPORT_EVERY: usize = 50;
/// Steps before a stop or a fall that count as its phase.
const TAIL: usize = 15;

/// Where in an episode a judged window lies.
#[derive(Clone, Copy, PartialEq)]
enum Phase {
    /// The walk-off of a start at rest (`[env.gait.start] seconds`).
    Ramp,
    Cruise,
    /// The last steps before the base's stop.
    Stop,
    /// The last steps before a fall.
    Fall,
}

const PHASES: [(Phase, &str); 4] = [
    (Phase::Ramp, "ramp"),
    (Phase::Cruise, "cruise"),
    (Phase::Stop, "stop"),
    (Phase::Fall, "fall"),
];

/// Held-out windows of each phase and the fraction of them `amp` takes for demo.
fn by_phase(
    amp: &AmpTrainer,
    rows: &[f32],
    phases: &[Phase],
) -> Result<Vec<(usize, f64)>, Box<dyn std::error::Error>> {
    let logits = amp.logits(rows)?;
    Ok(PHASES
        .iter()
        .map(|(p, _)| {
            let of: Vec<f32> = logits
                .iter()
                .zip(phases)
                .filter(|(_, q)| *q == p)
                .map(|(d, _)| *d)
                .collect();
            let demo = of.iter().filter(|&&d| d > 0.0).count();
            (of.len(), demo as f64 / of.len().max(1) as f64)
        })
        .collect())
}

fn print_phases(who: &str, split: &[(usize, f64)]) {
    let cells: Vec<String> = PHASES
        .iter()
        .zip(split)
        .map(|((_, name), (n, demo))| format!("{name} {n} windows judged demo {demo:.3}"))
        .collect();
    println!("{who}: held-out {}", cells.join(", "));
}

fn variant(base: &AmpConfig, spec: &str) -> Result<AmpConfig, String> {
    let mut c = base.clone();
    if spec == "base" {
        return Ok(c);
    }
    for kv in spec.split(',') {
        let bad = || {
            format!(
                "{kv:?}: a variant's entries are gp=X, logit_reg=X, lr=X, wd=X, hidden=WxW... or target=ACCURACY"
            )
        };
        let (k, v) = kv.split_once('=').ok_or_else(bad)?;
        if k == "hidden" {
            c.disc.hidden = v
                .split('x')
                .map(|w| w.parse::<usize>().ok().filter(|&w| w > 0))
                .collect::<Option<Vec<_>>>()
                .ok_or_else(bad)?;
            continue;
        }
        let v: f64 = v.parse().map_err(|_| bad())?;
        match k {
            "gp" => c.grad_penalty = v,
            "logit_reg" => c.logit_reg = v,
            "lr" => c.adam.lr = v,
            "wd" => c.weight_decay = v,
            "target" if v == 0.0 => c.accuracy_target = None,
            "target" => {
                c.accuracy_target = Some(lhm_learner::AccuracyTarget {
                    accuracy: v,
                    ..Default::default()
                })
            }
            _ => return Err(bad()),
        }
    }
    Ok(c)
}

/// The feature classes of one AMP frame ([`lhm_sim::obs::amp_frame`]'s layout) and their
/// column ranges within it.
fn frame_classes(model: &lhm_sim::CharacterModel) -> Vec<(&'static str, std::ops::Range<usize>)> {
    let frame = lhm_sim::obs::amp_frame_dim(model);
    let keys = 3 * lhm_sim::obs::key_bodies(model).len();
    let dofs = model.dofs.len();
    let rotations = frame - 13 - dofs - keys;
    vec![
        ("height", 0..1),
        ("rootrot", 1..7),
        ("rootvel", 7..10),
        ("rootang", 10..13),
        ("jointrot", 13..13 + rotations),
        ("jointvel", 13 + rotations..13 + rotations + dofs),
        ("keybody", frame - keys..frame),
    ]
}

/// The window columns `mask` names: feature classes ([`frame_classes`]) in every frame, and
/// `older` for every frame but the newest (a one-frame window: no velocity from differences).
fn masked_columns(
    model: &lhm_sim::CharacterModel,
    dim: usize,
    mask: &[String],
) -> Result<Vec<usize>, String> {
    let frame = lhm_sim::obs::amp_frame_dim(model);
    let frames = dim / frame;
    let classes = frame_classes(model);
    let mut out = Vec::new();
    for name in mask {
        if name == "older" {
            out.extend(0..(frames - 1) * frame);
            continue;
        }
        let (_, range) = classes.iter().find(|(c, _)| c == name).ok_or_else(|| {
            let known: Vec<&str> = classes.iter().map(|(c, _)| *c).collect();
            format!(
                "mask={name:?}: the classes are {} and older",
                known.join(", ")
            )
        })?;
        for f in 0..frames {
            out.extend(range.clone().map(|c| f * frame + c));
        }
    }
    out.sort_unstable();
    out.dedup();
    Ok(out)
}

fn zero_columns(rows: &mut [f32], dim: usize, columns: &[usize]) {
    for row in rows.chunks_mut(dim) {
        for &c in columns {
            row[c] = 0.0;
        }
    }
}

fn sample_rows(rows: &[f32], dim: usize, n: usize, rng: &mut SplitMix64) -> Vec<f32> {
    let count = rows.len() / dim;
    let mut out = Vec::with_capacity(n * dim);
    for _ in 0..n {
        let k = ((rng.next_f64() * count as f64) as usize).min(count - 1);
        out.extend_from_slice(&rows[k * dim..(k + 1) * dim]);
    }
    out
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let usage = "usage: disc_fresh_probe RUN_DIR TASKS SEEDS noise|mean UPDATES VARIANT...";
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 6 {
        return Err(usage.into());
    }
    let dir = PathBuf::from(&args[0]);
    let tasks: usize = args[1].parse().map_err(|_| usage)?;
    let seeds: u64 = args[2].parse().map_err(|_| usage)?;
    let noisy = match args[3].as_str() {
        "noise" => true,
        "mean" => false,
        _ => return Err(usage.into()),
    };
    let updates: usize = args[4].parse().map_err(|_| usage)?;
    let mut scaled: Option<(String, f32)> = None;
    let mut masked: Vec<String> = Vec::new();
    let mut holdout: Option<String> = None;
    let mut mirror = false;
    let mut first_variant = 5;
    for arg in &args[5..] {
        if let Some(s) = arg.strip_prefix("scale=") {
            let bad = || format!("{arg:?}: expected scale=JOINT:K");
            let (joint, k) = s.split_once(':').ok_or_else(bad)?;
            let k: f32 = k.parse().map_err(|_| bad())?;
            scaled = Some((joint.to_string(), k));
        } else if let Some(s) = arg.strip_prefix("mask=") {
            masked = s.split('+').map(str::to_string).collect();
        } else if let Some(s) = arg.strip_prefix("holdout=") {
            holdout = Some(s.to_string());
        } else if arg == "mirror" {
            mirror = true;
        } else {
            break;
        }
        first_variant += 1;
    }
    let specs = &args[first_variant..];
    let run = GaitRun::load(&dir, "checkpoint")?;
    let GaitRun {
        config,
        learner,
        model,
        bench,
        demo,
        ..
    } = &run;
    let run_amp = learner
        .amp
        .as_ref()
        .ok_or("no discriminator in this checkpoint (AMP off)")?;
    let base = run_amp.config.clone();
    let variants = specs
        .iter()
        .map(|s| variant(&base, s).map(|c| (s.clone(), c)))
        .collect::<Result<Vec<_>, _>>()?;
    let train_tasks: Vec<_> = bench
        .tasks(Split::Train)
        .iter()
        .take(tasks)
        .cloned()
        .collect();
    // [training half, held-out half] of the judged windows, split by episode, and the held-out
    // windows' phases.
    let mut halves: [Vec<f32>; 2] = Default::default();
    let mut held_phases: Vec<Phase> = Vec::new();
    let (mut episodes, mut falls) = (0usize, 0usize);
    let mut act_rng = SplitMix64::new(11);
    for rest in [true, false] {
        let setup = run.eval_setup(rest);
        for task in &train_tasks {
            for seed in 0..seeds {
                let mut env = setup.env_for(task, seed);
                // (stopped, ramping, features) per step.
                let mut episode: Vec<(bool, bool, Vec<f32>)> = Vec::new();
                let fell = loop {
                    let obs = env.observation();
                    let mut a = if noisy {
                        learner.actor_critic.act(&obs, &mut act_rng)?.actions
                    } else {
                        learner.actor_critic.act_deterministic(&obs)?
                    };
                    scale_residual(&mut a, model, scaled.as_ref());
                    let r = env.step(&a);
                    episode.push((env.gait_stopped(), env.gait_ramping(), env.amp_features()));
                    if r.done || r.truncated || r.physics_invalid {
                        break r.fell;
                    }
                };
                let stop_at = episode.iter().position(|(stopped, _, _)| *stopped);
                let (half, n) = (episodes % 2, episode.len());
                for (k, (stopped, ramping, f)) in episode.into_iter().enumerate() {
                    let skipped = (stopped && !config.amp.discriminate_stand)
                        || (ramping && !config.amp.discriminate_ramp);
                    if skipped {
                        continue;
                    }
                    let phase = if fell && k + TAIL >= n {
                        Phase::Fall
                    } else if stop_at.is_some_and(|s| k < s && k + TAIL >= s) {
                        Phase::Stop
                    } else if ramping {
                        Phase::Ramp
                    } else {
                        Phase::Cruise
                    };
                    halves[half].extend(f);
                    if half == 1 {
                        held_phases.push(phase);
                    }
                }
                episodes += 1;
                falls += usize::from(fell);
            }
        }
    }
    let dim = run_amp.feature_dim();
    let zeroed = masked_columns(model, dim, &masked)?;
    if !zeroed.is_empty() {
        println!(
            "masked {} of {dim} columns ({}) on both sides",
            zeroed.len(),
            masked.join("+")
        );
    }
    println!(
        "{falls} of {episodes} episodes fell ({} actions); judged windows: {} training, {} held out",
        if noisy { "noisy" } else { "mean" },
        halves[0].len() / dim,
        halves[1].len() / dim
    );
    if halves.iter().any(|h| h.is_empty()) {
        return Err("no judged windows in one half: more tasks or seeds".into());
    }
    print_phases(
        "the run's discriminator",
        &by_phase(run_amp, &halves[1], &held_phases)?,
    );
    for half in &mut halves {
        zero_columns(half, dim, &zeroed);
    }
    // With `holdout`, the fresh discriminators' demo is the other clips, and the held-out clip's
    // windows are judged as a third set: real motion none of them was shown.
    let (demo, held_clip) = match &holdout {
        None => (demo.clone(), None),
        Some(name) => {
            let rest = demo.retain_clips(|n| !n.contains(name.as_str()));
            let held = demo.retain_clips(|n| n.contains(name.as_str()));
            let (Some(rest), Some(held)) = (rest, held) else {
                let names: Vec<&str> = demo.clips().map(|(n, _)| n).collect();
                return Err(format!(
                    "holdout={name:?} must name some but not all of the demo's clips: {}",
                    names.join(", ")
                )
                .into());
            };
            let names: Vec<&str> = held.clips().map(|(n, _)| n).collect();
            println!(
                "held out of the fresh discriminators' demo: {}",
                names.join(", ")
            );
            let mut rng = SplitMix64::new(13);
            let mut rows = held.sample_features(2048, &mut || rng.next_f64());
            zero_columns(&mut rows, dim, &zeroed);
            (rest, Some(rows))
        }
    };
    let demo = if mirror {
        let demo = demo.with_mirrors()?;
        let names: Vec<&str> = demo.clips().map(|(n, _)| n).collect();
        println!(
            "fresh discriminators' demo with mirrors: {}",
            names.join(", ")
        );
        demo
    } else {
        demo
    };
    let mut demo_rng = SplitMix64::new(7);
    let mut draw = || demo_rng.next_f64();
    let mut demo_held = demo.sample_features(8192, &mut draw);
    zero_columns(&mut demo_held, dim, &zeroed);
    println!(
        "{:<28} {:>7} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "variant", "update", "train", "train demo", "train agnt", "held demo", "held agnt"
    );
    println!("(train: the update's own accuracy; then the discriminator's rate and the held-out agent's mean style reward)");
    for (name, c) in &variants {
        let mut amp = AmpTrainer::new(dim, c.clone())?;
        let mut rng = SplitMix64::new(3);
        for u in 1..=updates {
            let agent = sample_rows(&halves[0], dim, AGENT_ROWS, &mut rng);
            let mut demo_rows = demo.sample_features(AGENT_ROWS, &mut || rng.next_f64());
            zero_columns(&mut demo_rows, dim, &zeroed);
            let stats = amp.update(&agent, &demo_rows)?;
            if u % REPORT_EVERY == 0 || u == updates {
                let (train_demo, train_agent) = amp.accuracy(&halves[0], &demo_rows)?;
                let (held_demo, held_agent) = amp.accuracy(&halves[1], &demo_held)?;
                let style = amp.style_rewards(&halves[1])?;
                let style = style.iter().map(|&r| f64::from(r)).sum::<f64>() / style.len() as f64;
                let clip = match &held_clip {
                    Some(rows) => format!(
                        " held-out clip judged demo {:.3}",
                        amp.accuracy(&halves[1], rows)?.0
                    ),
                    None => String::new(),
                };
                println!(
                    "{name:<28} {u:>7} {:>10.3} {train_demo:>10.3} {train_agent:>10.3} {held_demo:>10.3} {held_agent:>10.3} {:>6.3} {style:>6.3}{clip}",
                    stats.accuracy(),
                    stats.lr
                );
            }
        }
        print_phases(name, &by_phase(&amp, &halves[1], &held_phases)?);
    }
    Ok(())
}
