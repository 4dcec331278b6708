//! `cargo run --release -p lhm-sim --example mpc_probe -- [TASKS] [STEPS]`: can corrections on
//! top of the gait base keep the character up, walk it to the object and stop it — found not by
//! learning but by planning on the simulator itself?
//!
//! Predictive sampling (`lhm_sim::plan`; Howell et al. 2022, MuJoCo MPC):
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
//! DoF's action scale; `STOP`, the base's `stop_distance`, default 0.5 m), started in the gait at
//! cycle step 0 toward the first object, as `lhm render-rollout` does; `STAND=1`: no gait, the
//! task's own standing start (actions are then the policy's: zero is the neutral pose);
//! `STAND_START=1`: the gait from the task's standing start (at rest, the task's heading).
//! `SPLIT` (unseen), `FIRST` (index of the first task, 0), `THREADS` (2), `UP_HEIGHT` (a rollout with the root below it counts as fallen, 0.7 m),
//! `GIF=path` (the first task, every other step). Planner settings (`PlannerConfig`): `SAMPLES`,
//! `HORIZON`, `KNOT`, `SIGMA`, `THREADS`, `FALL_COST`, `SPEED_COST`, `EFFORT_COST`, `HEIGHT_COST`,
//! `STAND_HEIGHT`, `TILT_COST`, `POSE_COST`, `DECAY`, `TEMPERATURE`; `PLAN_DOFS=legs` plans hips, knees,
//! ankles and abdomen only (arms, neck keep the base's targets). Prints per task: control steps up, reached,
//! stopped, the root's speed at the end, wall time; then the totals.
//!
//! `SPREAD=K`: every `SPREAD_EVERY` (50) control steps, the decision is also taken by K copies of
//! the planner (same plan, other noise seeds) from the same state, and the probe prints, over the
//! planned DoFs, the RMS spread of their actions across seeds (how much a label is the draw) and
//! the RMS of their mean minus the nominal plan's action (the correction the state calls for).

use std::time::Instant;

use lhm_scenes::{Benchmark, Split, Task};
use lhm_sim::env::{EnvConfig, GaitConfig, TaskEnv};
use lhm_sim::gait::{reference_for, GaitReference};
use lhm_sim::motion::demo::{AmpWindow, DemoMotion};
use lhm_sim::plan::{down, horizontal_speed, stopping, Planner, PlannerConfig};
use lhm_sim::render::{render, write_gif, Camera, Image};
use lhm_sim::{CharacterModel, SimConfig};

fn var<T: std::str::FromStr>(key: &str, default: T) -> T {
    std::env::var(key)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

struct Outcome {
    up: usize,
    reached: bool,
    stopped: bool,
    end_speed: f32,
    /// Root mean square of the executed actions (the residual's size).
    action_rms: f32,
}

struct Problem<'a> {
    model: &'a CharacterModel,
    bench: &'a Benchmark,
    demo: &'a DemoMotion,
    sim: SimConfig,
    config: EnvConfig,
    reference: Option<std::sync::Arc<GaitReference>>,
    planner: PlannerConfig,
    stand_start: bool,
    /// DoFs whose names contain one of these are planned (`PLAN_DOFS=legs`: hips, knees, ankles,
    /// abdomen; default: all).
    planned_prefixes: Vec<String>,
    /// `SPREAD`, `SPREAD_EVERY`: see the header.
    spread: usize,
    spread_every: usize,
}

/// The decision at `env` taken by `k` reseeded copies of `planner`: the RMS over planned DoFs of
/// the actions' standard deviation across seeds, and of their mean minus the nominal action.
fn label_spread(planner: &Planner, env: &TaskEnv, workers: &mut [TaskEnv], k: usize) -> (f32, f32) {
    let actions: Vec<Vec<f32>> = (0..k)
        .map(|i| planner.reseeded(0xabcd + i as u64).act(env, workers))
        .collect();
    let nominal = planner.nominal_action();
    let (mut var, mut corr, mut dofs) = (0.0f32, 0.0f32, 0usize);
    for j in (0..nominal.len()).filter(|&j| planner.planned()[j]) {
        let mean = actions.iter().map(|a| a[j]).sum::<f32>() / k as f32;
        var += actions.iter().map(|a| (a[j] - mean).powi(2)).sum::<f32>()
            / k.max(2).saturating_sub(1) as f32;
        corr += (mean - nominal[j]).powi(2);
        dofs += 1;
    }
    let dofs = dofs.max(1) as f32;
    ((var / dofs).sqrt(), (corr / dofs).sqrt())
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
        seed: u64,
        mut frames: Option<&mut Vec<Image>>,
    ) -> Result<Outcome, String> {
        let mut env = self.env(task);
        if let Some(reference) = &self.reference {
            if self.stand_start {
                env.start_gait(reference.clone(), 0);
            } else {
                let yaw = env.yaw_toward_first_object();
                env.start_in_gait(self.demo, reference.clone(), 0, yaw);
            }
        }
        let mut workers: Vec<TaskEnv> = (0..self.planner.threads).map(|_| self.env(task)).collect();
        let mut planner = Planner::new(
            PlannerConfig {
                seed,
                ..self.planner.clone()
            },
            self.model.dofs.len(),
        )?
        .with_planned(
            self.model
                .dofs
                .iter()
                .map(|d| {
                    self.planned_prefixes
                        .iter()
                        .any(|p| d.name.contains(p.as_str()))
                })
                .collect(),
        )?;
        let mut up = 0;
        let (mut sq, mut n) = (0.0f32, 0usize);
        for t in 0..steps {
            if self.spread > 0 && t % self.spread_every.max(1) == 0 {
                let (spread, correction) = label_spread(&planner, &env, &mut workers, self.spread);
                println!(
                    "  step {t}: label spread across {} seeds {spread:.3} RMS per planned DoF, \
                     mean correction {correction:.3} (σ {})",
                    self.spread, self.planner.sigma
                );
            }
            let action = planner.act(&env, &mut workers);
            sq += action.iter().map(|a| a * a).sum::<f32>();
            n += action.len();
            let r = env.step(&action);
            if let Some(frames) = frames.as_deref_mut() {
                if t % 2 == 0 {
                    let camera = Camera::third_person(&env.world, 240, 180);
                    frames.push(render(&env.world, &camera, true));
                }
            }
            if down(&env, &r, self.planner.up_height) {
                break;
            }
            up = t + 1;
            if r.done {
                break;
            }
        }
        Ok(Outcome {
            up,
            reached: env.reached,
            stopped: stopping(&env),
            end_speed: horizontal_speed(&env),
            action_rms: (sq / n.max(1) as f32).sqrt(),
        })
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let tasks: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(4);
    let steps: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(300);
    let d = PlannerConfig::default();
    let planner = PlannerConfig {
        samples: var("SAMPLES", d.samples),
        horizon: var("HORIZON", d.horizon),
        knot: var("KNOT", d.knot),
        sigma: var("SIGMA", d.sigma),
        threads: var("THREADS", d.threads),
        fall_cost: var("FALL_COST", d.fall_cost),
        speed_cost: var("SPEED_COST", d.speed_cost),
        effort_cost: var("EFFORT_COST", d.effort_cost),
        height_cost: var("HEIGHT_COST", d.height_cost),
        stand_height: var("STAND_HEIGHT", d.stand_height),
        tilt_cost: var("TILT_COST", d.tilt_cost),
        pose_cost: var("POSE_COST", d.pose_cost),
        up_height: var("UP_HEIGHT", d.up_height),
        decay: var("DECAY", d.decay),
        temperature: var("TEMPERATURE", d.temperature),
        seed: d.seed,
    };
    planner.check()?;
    let model = CharacterModel::amp_humanoid();
    let sim = SimConfig::default();
    let mut config = EnvConfig::default();
    let stand = std::env::var_os("STAND").is_some();
    if !stand {
        config.gait = Some(GaitConfig {
            residual: var("RESIDUAL", 1.0f32),
            stop_distance: var("STOP", 0.5f32),
            ..GaitConfig::default()
        });
    }
    let dir = lhm_sim::motion::default_dir();
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
        planner,
        stand_start: std::env::var_os("STAND_START").is_some(),
        planned_prefixes: match std::env::var("PLAN_DOFS").as_deref() {
            Ok("legs") => ["hip", "knee", "ankle", "abdomen"]
                .map(String::from)
                .to_vec(),
            _ => vec![String::new()],
        },
        spread: var("SPREAD", 0usize),
        spread_every: var("SPREAD_EVERY", 50usize),
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
            0x5eed + i as u64,
            want_frames.then_some(&mut frames),
        )?;
        if let (true, Some(path)) = (want_frames, &gif) {
            write_gif(&frames, 7, std::fs::File::create(path)?)?;
        }
        up_all += out.up;
        reached += out.reached as usize;
        stood += (out.up == steps) as usize;
        println!(
            "{}: up {} of {steps}, reached {}, stopped {}, end speed {:.2} m/s, action rms {:.2}, {:.1} s",
            task.id,
            out.up,
            out.reached,
            out.stopped,
            out.end_speed,
            out.action_rms,
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
