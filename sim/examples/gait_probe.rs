//! `cargo run --release -p lhm-sim --example gait_probe -- [ITERATIONS] [CLIP]`: can a handful of
//! balance-feedback gains turn open-loop tracking of a looped walk into a walk that does not fall?
//!
//! Open-loop tracking (the clip's own joint angles as PD targets, `track_clip`) falls within
//! ~1 s. SIMBICON (Yin, Loken, van de Panne 2007) and data-driven biped control (Lee, Kim, Lee
//! 2010) keep such a reference up with a few feedback terms on top of it: the swing hip places the
//! foot by the centre of mass's position and velocity error against the reference, the stance hip
//! holds the pelvis's tilt, the stance ankle brakes. Their gains are found here by an evolution
//! strategy on the simulator itself (a few hundred rollouts, each 10 s from one of eight phases of
//! the clip). If such a controller walks, it is a base a residual policy can steer (DReCon's
//! kinematic reference + learned correction) instead of discovering stepping from noise.

//!
//! Search: `gait_probe [ITERATIONS] [CLIP]` ((μ/μ, λ) ES from zeros, i.e. open-loop tracking;
//! `START=default` or `START=g0,g1,…` (the order of `BalanceGains::NAMES`) to start elsewhere,
//! `SIGMA`, `ELITIST=1` for a (1+λ) search around the best at a fixed step). It prints every new
//! best as an `eval` string. One set: `gait_probe eval g0,g1,…` (`TRACE=1` per-step errors,
//! `GIF=out.gif` [`GIF_PHASE`] a rollout, `STEER=gain GOAL_ANGLE=rad` steering toward a goal
//! 3 m away at that angle, travel then counts the distance gained toward it). `SYNC_WAIT=n
//! SYNC_SKIP=m` keep the cycle in time with the footfalls (`GaitReference::advance`).

use lhm_scenes::Benchmark;
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::gait::{balance, base_targets, steer, BalanceGains, GaitReference, Rig};
use lhm_sim::motion::demo::{AmpWindow, DemoMotion};
use lhm_sim::obs::HeadingFrame;
use lhm_sim::render::{render, write_gif, Camera, Image};
use lhm_sim::{CharacterModel, SimConfig};
use rapier3d::math::Vector;

const GAINS: usize = BalanceGains::LEN;

struct Setup {
    model: CharacterModel,
    rig: Rig,
    demo: DemoMotion,
    reference: GaitReference,
    bench: Benchmark,
    sim: SimConfig,
    env_config: EnvConfig,
    /// Steering toward a goal 3 m away at this angle (radians) off the start heading, with
    /// this gain per radian of heading error; 0 gain: no steering, walk on.
    goal_angle: f32,
    steer_gain: f32,
    /// Footfall synchronisation: (max_wait, max_skip) steps, `GaitReference::advance`.
    sync: (usize, usize),
}

/// One rollout from `phase` (fraction of the cycle): (control steps up, ground travel in m).
fn rollout(s: &Setup, g: &[f32; GAINS], phase: f32, steps: usize) -> (usize, f32) {
    rollout_traced(s, g, phase, steps, false, None)
}

fn rollout_traced(
    s: &Setup,
    g: &[f32; GAINS],
    phase: f32,
    steps: usize,
    trace: bool,
    mut frames: Option<&mut Vec<Image>>,
) -> (usize, f32) {
    let Some((_, task)) = s.bench.task("train-0001") else {
        return (0, 0.0);
    };
    let gains = BalanceGains::from_array(*g);
    let mut env = TaskEnv::new(
        &s.model,
        &task,
        &s.bench.catalogue,
        s.sim.clone(),
        s.env_config.clone(),
    );
    let k0 = (phase * s.reference.len() as f32) as usize;
    env.start_from_demo(&s.demo, s.reference.clip, s.reference.time(k0));
    let start = env.world.body_states()[0].pos;
    let start_yaw = task.start.yaw as f32;
    let goal = start
        + 3.0
            * Vector::new(
                (start_yaw + s.goal_angle).cos(),
                (start_yaw + s.goal_angle).sin(),
                0.0,
            );
    let ch = env.world.character.clone();
    let mut up = 0;
    let (mut step, mut waited) = (k0, 0);
    for k in 0..steps {
        let now = env.world.body_states();
        let (reference_now, angles) = s.reference.at(step);
        let mut targets = base_targets(&s.rig, &gains, &now, reference_now, angles);
        if s.steer_gain != 0.0 {
            let to = HeadingFrame::of(&now[0]).vector(goal - now[0].pos);
            let err = to.y.atan2(to.x);
            steer(&s.rig, &mut targets, reference_now, s.steer_gain * err, 0.3);
        }
        if trace && k % 3 == 0 {
            let stance = s.rig.stance(reference_now);
            let c = balance(&s.rig, &now, stance);
            let r = balance(&s.rig, reference_now, stance);
            println!(
                "  k {k:3} stance {stance} h {:.2} dd ({:+.2},{:+.2}) dv ({:+.2},{:+.2}) pos ({:+.2},{:+.2})",
                now[0].pos.z, c.d.x - r.d.x, c.d.y - r.d.y, c.v.x - r.v.x, c.v.y - r.v.y,
                now[0].pos.x - start.x, now[0].pos.y - start.y,
            );
        }
        let action: Vec<f32> = targets
            .iter()
            .enumerate()
            .map(|(i, q)| (q - ch.action_offset[i]) / ch.action_scale[i])
            .collect();
        step = s
            .reference
            .advance(&s.rig, step, &now, &mut waited, s.sync.0, s.sync.1);
        env.step(&action);
        if let Some(frames) = frames.as_deref_mut() {
            if k % 2 == 0 {
                let camera = Camera::third_person(&env.world, 240, 180);
                frames.push(render(&env.world, &camera, true));
            }
        }
        if env.world.root_height() < s.env_config.root_fall_height || !env.world.is_finite() {
            break;
        }
        up = k + 1;
    }
    let end = env.world.body_states()[0].pos;
    let travel = if s.steer_gain != 0.0 {
        // Steering: how much closer to the goal.
        (goal - start).length() - (goal - end).length()
    } else {
        ((end.x - start.x).powi(2) + (end.y - start.y).powi(2)).sqrt()
    };
    (up, travel)
}

/// Start phases: 8 evenly spaced fractions of the clip (4 overfit the chaotic rollouts: gains
/// rounded to 3 decimals lost half the steps).
const PHASES: [f32; 8] = [0.0, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875];
const STEPS: usize = 300;

fn score(s: &Setup, g: &[f32; GAINS]) -> (f32, usize, f32) {
    let (mut up, mut travel) = (0, 0.0);
    for p in PHASES {
        let (u, t) = rollout(s, g, p, STEPS);
        up += u;
        travel += t;
    }
    (up as f32 + 30.0 * travel, up, travel)
}

/// A tiny deterministic generator (xorshift) with Box-Muller normals.
struct Rng(u64);
impl Rng {
    fn uniform(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        ((self.0 >> 40) as f32 + 0.5) / (1u64 << 24) as f32
    }
    fn normal(&mut self) -> f32 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (std::f32::consts::TAU * b).cos()
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1).peekable();
    // `gait_probe eval G0,G1,...`: score one set of gains (missing ones 0), print the summary.
    let fixed: Option<[f32; GAINS]> = if args.peek().map(String::as_str) == Some("eval") {
        args.next();
        let mut g = [0f32; GAINS];
        for (x, v) in g.iter_mut().zip(args.next().unwrap_or_default().split(',')) {
            *x = v.parse()?;
        }
        Some(g)
    } else {
        None
    };
    let iterations: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(30);
    let clip_name = args.next().unwrap_or_else(|| "humanoid3d_walk".into());
    let home = std::env::var("HOME").unwrap_or_default();
    let dir = std::path::PathBuf::from(home).join(".cache/lhm/motions");
    let model = CharacterModel::amp_humanoid();
    let (env_config, sim) = (EnvConfig::default(), SimConfig::default());
    let demo = DemoMotion::load_dir(&model, &dir, AmpWindow::of(&env_config, &sim))?;
    let clip = demo
        .clips()
        .position(|(n, _)| n.contains(&clip_name))
        .ok_or("clip not installed")?;
    let reference =
        GaitReference::new(&model, &demo, clip, 1.0 / sim.control_hz).ok_or("clip too short")?;
    let env_f32 = |k: &str, d: f32| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let setup = Setup {
        rig: Rig::new(&model).ok_or("not the AMP humanoid")?,
        model,
        demo,
        reference,
        bench: Benchmark::embedded()?,
        sim,
        env_config,
        goal_angle: env_f32("GOAL_ANGLE", 0.0),
        steer_gain: env_f32("STEER", 0.0),
        sync: (
            env_f32("SYNC_WAIT", 0.0) as usize,
            env_f32("SYNC_SKIP", 0.0) as usize,
        ),
    };
    if let Some(g) = fixed {
        for p in PHASES {
            let (u, t) = rollout_traced(
                &setup,
                &g,
                p,
                STEPS,
                std::env::var_os("TRACE").is_some(),
                None,
            );
            println!("phase {p}: up {u}, travel {t:.2}");
        }
        // GIF=PATH: the rollout from the phase in $GIF_PHASE (default 0.5), every other step.
        if let Ok(path) = std::env::var("GIF") {
            let phase = env_f32("GIF_PHASE", 0.5);
            let mut frames = Vec::new();
            rollout_traced(&setup, &g, phase, STEPS, false, Some(&mut frames));
            write_gif(&frames, 7, std::fs::File::create(path)?)?;
        }
        return Ok(());
    }
    let mut mean = [0f32; GAINS];
    if std::env::var("START").as_deref() == Ok("default") {
        mean = BalanceGains::default().to_array();
    } else if let Ok(start) = std::env::var("START") {
        for (x, v) in mean.iter_mut().zip(start.split(',')) {
            *x = v.parse()?;
        }
    }
    let mut sigma: f32 = std::env::var("SIGMA")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0.2);
    let elitist = std::env::var_os("ELITIST").is_some();
    let (base, up, travel) = score(&setup, &mean);
    println!(
        "start point (zeros: open loop): score {base:.1}, steps up {up} of {}, travel {travel:.2} m",
        PHASES.len() * STEPS
    );
    let mut best = (base, mean);
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let lambda = 16;
    let mut mean_score = base;
    for it in 0..iterations {
        let candidates: Vec<[f32; GAINS]> = (0..lambda)
            .map(|_| {
                let mut c = mean;
                for x in &mut c {
                    *x += sigma * rng.normal();
                }
                c
            })
            .collect();
        let scores: Vec<(f32, usize, f32)> = std::thread::scope(|scope| {
            let halves: Vec<_> = candidates
                .chunks(lambda / 2)
                .map(|chunk| {
                    let setup = &setup;
                    scope.spawn(move || chunk.iter().map(|c| score(setup, c)).collect::<Vec<_>>())
                })
                .collect();
            halves
                .into_iter()
                .flat_map(|h| h.join().unwrap_or_default())
                .collect()
        });
        let mut order: Vec<usize> = (0..lambda).collect();
        order.sort_by(|&a, &b| scores[b].0.total_cmp(&scores[a].0));
        let mu = lambda / 2;
        let mut next = [0f32; GAINS];
        for &i in &order[..mu] {
            for (n, c) in next.iter_mut().zip(&candidates[i]) {
                *n += c / mu as f32;
            }
        }
        mean = next;
        let top = order[0];
        if scores[top].0 > best.0 {
            best = (scores[top].0, candidates[top]);
            let all: Vec<String> = best.1.iter().map(|g| g.to_string()).collect();
            println!("new best {:.1}: {}", best.0, all.join(","));
        }
        if elitist {
            // (1+λ): sample around the best so far at a fixed step size.
            mean = best.1;
        } else {
            // Step size: grow while the batch's best beats the previous mean, shrink otherwise.
            sigma = (sigma
                * if scores[top].0 > mean_score {
                    1.05
                } else {
                    0.9
                })
            .clamp(0.02, 1.0);
            mean_score = score(&setup, &mean).0;
        }
        println!(
            "it {it}: best of batch {:.1} (up {}, travel {:.2} m), best so far {:.1}, sigma {sigma:.3}",
            scores[top].0, scores[top].1, scores[top].2, best.0
        );
    }
    println!("best gains (score {:.1}):", best.0);
    for (n, g) in BalanceGains::NAMES.iter().zip(best.1) {
        println!("  {n} = {g:.3}");
    }
    for p in PHASES {
        println!("trace from phase {p}:");
        let (u, t) = rollout_traced(&setup, &best.1, p, STEPS, true, None);
        println!("  up {u}, travel {t:.2}");
    }
    let (_, up, travel) = score(&setup, &best.1);
    println!(
        "best: steps up {up} of {}, travel {travel:.2} m",
        PHASES.len() * STEPS
    );
    Ok(())
}
