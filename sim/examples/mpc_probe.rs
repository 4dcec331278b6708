//! `cargo run --release -p lhm-sim --example mpc_probe -- [TASKS] [STEPS]`: can corrections on
//! top of the gait base keep the character up, walk it to the object and stop it — found not by
//! learning but by planning on the simulator itself?
//!
//! Predictive sampling (Howell, Gileadi, Tunyasuvunakool, Zakka, Erez, Tassa 2022, MuJoCo MPC):
//! at every control step, from a snapshot of the environment, roll out the nominal plan of
//! residual actions and `SAMPLES − 1` noisy copies of it over `HORIZON` control steps (noise drawn
//! at knots every `KNOT` steps, σ = `SIGMA`, linearly interpolated), keep the cheapest as the new
//! nominal, execute its first action, shift it by a step. A rollout's cost: minus the
//! environment's reward, plus `FALL_COST` (scaled up the sooner it falls), plus `SPEED_COST` × the
//! root's horizontal speed² once the object is reached or the base has stopped, plus a small
//! effort term. This answers a question the residual PPO runs could not: whether the residual
//! action space holds a controller that does not fall at all. If it does, its rollouts are a
//! teacher a policy can be distilled from (guided policy search, Levine & Koltun 2013); if it
//! does not, no residual policy on this base will.
//!
//! Environment: the default `EnvConfig` with `[env.gait]` (`RESIDUAL`, default 1.0 of each
//! DoF's action scale; `STOP`, the base's `stop_distance`, default 0.8 m), started in the gait at
//! cycle step 0 toward the first object, as `lhm render-rollout` does; `STAND=1`: no gait, the
//! task's own standing start (actions are then the policy's: zero is the neutral pose);
//! `STAND_START=1`: the gait from the task's standing start (at rest, the task's heading).
//! `SPLIT` (unseen), `FIRST` (index of the first task, 0), `THREADS` (2), `REPLAN` (plan every
//! n steps, 1), `UP_HEIGHT` (a rollout with the root below it counts as fallen, 0.7 m),
//! `GIF=path` (the first task, every other step). Prints per task: control steps up, reached,
//! stopped, the root's speed at the end, wall time; then the totals.

use std::time::Instant;

use lhm_scenes::{Benchmark, Split, Task};
use lhm_sim::env::{EnvConfig, EnvSnapshot, GaitConfig, StepResult, TaskEnv};
use lhm_sim::gait::reference_for;
use lhm_sim::motion::demo::{AmpWindow, DemoMotion};
use lhm_sim::render::{render, write_gif, Camera, Image};
use lhm_sim::{CharacterModel, SimConfig};

struct Options {
    samples: usize,
    horizon: usize,
    knot: usize,
    sigma: f32,
    replan: usize,
    threads: usize,
    fall_cost: f32,
    speed_cost: f32,
    effort_cost: f32,
    up_height: f32,
    stand_start: bool,
}

fn var<T: std::str::FromStr>(key: &str, default: T) -> T {
    std::env::var(key)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// SplitMix64 with Box-Muller normals: deterministic noise for the plans.
struct Noise(u64);
impl Noise {
    fn uniform(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        ((z >> 40) as f32 + 0.5) / (1u64 << 24) as f32
    }
    fn normal(&mut self) -> f32 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (std::f32::consts::TAU * b).cos()
    }
}

/// Whether the episode is over for the probe: the environment's fall, broken physics, or the root
/// below `up_height` (the environment's own 0.4 m lets a crouch go on).
fn down(env: &TaskEnv, r: &StepResult, up_height: f32) -> bool {
    r.fell || r.physics_invalid || env.world.root_height() < up_height
}

/// After the object is reached or the base has stopped, standing still is what is asked.
fn stopping(env: &TaskEnv, gait: bool) -> bool {
    env.reached || (gait && env.gait_phase().is_none())
}

fn horizontal_speed(env: &TaskEnv) -> f32 {
    let v = env.world.body_states()[0].linvel;
    (v.x * v.x + v.y * v.y).sqrt()
}

/// Cost of rolling `plan` (horizon × dofs, row-major) out of `snap` in `env`.
fn plan_cost(env: &mut TaskEnv, snap: &EnvSnapshot, plan: &[f32], o: &Options, gait: bool) -> f32 {
    env.restore(snap);
    let d = plan.len() / o.horizon;
    let mut cost = 0.0;
    for (k, a) in plan.chunks(d).enumerate() {
        let r = env.step(a);
        if down(env, &r, o.up_height) {
            // The sooner, the worse: a fall at the horizon's end costs half one at its start.
            cost += o.fall_cost * (2.0 - k as f32 / o.horizon as f32);
            break;
        }
        cost -= r.reward;
        if stopping(env, gait) {
            let v = horizontal_speed(env);
            cost += o.speed_cost * v * v;
        }
        cost += o.effort_cost * a.iter().map(|x| x * x).sum::<f32>() / d as f32;
        if r.done {
            break;
        }
    }
    cost
}

/// The nominal plan plus noise drawn at knots every `knot` steps, linearly interpolated.
fn perturbed(nominal: &[f32], d: usize, o: &Options, noise: &mut Noise) -> Vec<f32> {
    let knots = o.horizon.div_ceil(o.knot) + 1;
    let drawn: Vec<f32> = (0..knots * d).map(|_| o.sigma * noise.normal()).collect();
    let mut plan = nominal.to_vec();
    for k in 0..o.horizon {
        let (i, frac) = (k / o.knot, (k % o.knot) as f32 / o.knot as f32);
        for j in 0..d {
            let n = drawn[i * d + j] * (1.0 - frac) + drawn[(i + 1) * d + j] * frac;
            plan[k * d + j] = (plan[k * d + j] + n).clamp(-1.0, 1.0);
        }
    }
    plan
}

struct Outcome {
    up: usize,
    reached: bool,
    stopped: bool,
    end_speed: f32,
}

struct Problem<'a> {
    model: &'a CharacterModel,
    bench: &'a Benchmark,
    demo: &'a DemoMotion,
    sim: SimConfig,
    config: EnvConfig,
    reference: Option<std::sync::Arc<lhm_sim::gait::GaitReference>>,
}

impl Problem<'_> {
    fn env(&self, task: &Task) -> TaskEnv {
        TaskEnv::new(
            self.model,
            task,
            &self.bench.catalogue,
            self.sim.clone(),
            self.config.clone(),
        )
    }

    /// One episode of `steps` control steps under predictive sampling.
    fn run(
        &self,
        task: &Task,
        steps: usize,
        o: &Options,
        seed: u64,
        mut frames: Option<&mut Vec<Image>>,
    ) -> Outcome {
        let mut env = self.env(task);
        let gait = self.reference.is_some();
        if let Some(reference) = &self.reference {
            if o.stand_start {
                env.start_gait(reference.clone(), 0);
            } else {
                let yaw = env.yaw_toward_first_object();
                env.start_in_gait(self.demo, reference.clone(), 0, yaw);
            }
        }
        let mut workers: Vec<TaskEnv> = (0..o.threads).map(|_| self.env(task)).collect();
        let d = self.model.dofs.len();
        let mut nominal = vec![0.0f32; o.horizon * d];
        let mut noise = Noise(seed);
        let mut up = 0;
        for t in 0..steps {
            if t % o.replan == 0 {
                let snap = env.snapshot();
                let mut candidates = vec![nominal.clone()];
                candidates.extend((1..o.samples).map(|_| perturbed(&nominal, d, o, &mut noise)));
                let per = candidates.len().div_ceil(o.threads);
                let costs: Vec<f32> = std::thread::scope(|scope| {
                    let handles: Vec<_> = candidates
                        .chunks(per)
                        .zip(workers.iter_mut())
                        .map(|(chunk, worker)| {
                            let snap = &snap;
                            scope.spawn(move || {
                                chunk
                                    .iter()
                                    .map(|c| plan_cost(worker, snap, c, o, gait))
                                    .collect::<Vec<_>>()
                            })
                        })
                        .collect();
                    handles
                        .into_iter()
                        .flat_map(|h| h.join().unwrap_or_default())
                        .collect()
                });
                let best = (0..costs.len())
                    .min_by(|&a, &b| costs[a].total_cmp(&costs[b]))
                    .unwrap_or(0);
                nominal = candidates.swap_remove(best);
            }
            let r = env.step(&nominal[..d]);
            if let Some(frames) = frames.as_deref_mut() {
                if t % 2 == 0 {
                    let camera = Camera::third_person(&env.world, 240, 180);
                    frames.push(render(&env.world, &camera, true));
                }
            }
            if down(&env, &r, o.up_height) {
                break;
            }
            up = t + 1;
            // Shift the plan a step; its last action is held.
            nominal.drain(..d);
            let last = nominal[nominal.len() - d..].to_vec();
            nominal.extend(last);
            if r.done {
                break;
            }
        }
        Outcome {
            up,
            reached: env.reached,
            stopped: stopping(&env, gait),
            end_speed: horizontal_speed(&env),
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let tasks: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(4);
    let steps: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(300);
    let o = Options {
        samples: var("SAMPLES", 12usize).max(1),
        horizon: var("HORIZON", 24usize).max(1),
        knot: var("KNOT", 6usize).max(1),
        sigma: var("SIGMA", 0.3f32),
        replan: var("REPLAN", 1usize).max(1),
        threads: var("THREADS", 2usize).max(1),
        fall_cost: var("FALL_COST", 50.0f32),
        speed_cost: var("SPEED_COST", 2.0f32),
        effort_cost: var("EFFORT_COST", 0.01f32),
        up_height: var("UP_HEIGHT", 0.7f32),
        stand_start: std::env::var_os("STAND_START").is_some(),
    };
    let model = CharacterModel::amp_humanoid();
    let sim = SimConfig::default();
    let mut config = EnvConfig::default();
    let stand = std::env::var_os("STAND").is_some();
    if !stand {
        config.gait = Some(GaitConfig {
            residual: var("RESIDUAL", 1.0f32),
            stop_distance: var("STOP", 0.8f32),
            ..GaitConfig::default()
        });
    }
    let home = std::env::var("HOME").unwrap_or_default();
    let dir = std::path::PathBuf::from(home).join(".cache/lhm/motions");
    let demo = DemoMotion::load_dir(&model, &dir, AmpWindow::of(&config, &sim))?;
    let reference = match &config.gait {
        Some(g) => Some(std::sync::Arc::new(reference_for(
            &model,
            &demo,
            &g.clip,
            1.0 / sim.control_hz,
        )?)),
        None => None,
    };
    let bench = Benchmark::embedded()?;
    let split = match std::env::var("SPLIT").as_deref() {
        Ok("train") => Split::Train,
        _ => Split::Unseen,
    };
    let first: usize = var("FIRST", 0usize);
    let chosen: Vec<Task> = bench
        .tasks(split)
        .iter()
        .skip(first)
        .take(tasks)
        .cloned()
        .collect();
    let problem = Problem {
        model: &model,
        bench: &bench,
        demo: &demo,
        sim,
        config,
        reference,
    };
    let gif = std::env::var("GIF").ok();
    let (mut up_all, mut reached, mut stood) = (0, 0, 0);
    for (i, task) in chosen.iter().enumerate() {
        let clock = Instant::now();
        let mut frames = Vec::new();
        let want_frames = gif.is_some() && i == 0;
        let out = problem.run(
            task,
            steps,
            &o,
            0x5eed + i as u64,
            want_frames.then_some(&mut frames),
        );
        if let (true, Some(path)) = (want_frames, &gif) {
            write_gif(&frames, 7, std::fs::File::create(path)?)?;
        }
        up_all += out.up;
        reached += out.reached as usize;
        stood += (out.up == steps) as usize;
        println!(
            "{}: up {} of {steps}, reached {}, stopped {}, end speed {:.2} m/s, {:.1} s",
            task.id,
            out.up,
            out.reached,
            out.stopped,
            out.end_speed,
            clock.elapsed().as_secs_f32()
        );
    }
    println!(
        "total: up {up_all} of {}, reached {reached} of {}, up to the end {stood} of {}",
        steps * chosen.len(),
        chosen.len(),
        chosen.len()
    );
    Ok(())
}
