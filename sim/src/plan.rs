//! Predictive sampling on the environment itself (Howell, Gileadi, Tunyasuvunakool, Zakka, Erez,
//! Tassa 2022, "Predictive Sampling: Real-time Behaviour Synthesis with MuJoCo", the simplest
//! planner of MuJoCo MPC): at every control step, from a snapshot of the environment, the nominal
//! plan of actions and `samples − 1` noisy copies of it are rolled out over `horizon` control
//! steps; the cheapest becomes the nominal, its first action is executed, and it shifts by a step.
//! Noise is drawn at knots every `knot` steps and interpolated linearly (a smooth plan in few
//! numbers). The planner needs nothing but `TaskEnv::snapshot`/`restore` and `step`: it is a
//! teacher for states a policy visits (guided policy search, Levine & Koltun 2013), not a policy.

use serde::{Deserialize, Serialize};

use rapier3d::math::Vector;

use crate::env::{EnvSnapshot, StepResult, TaskEnv};

/// A policy the plans are corrections to: observation → action (e.g. a student's mean action).
/// With a prior, a rollout's action at every step is the prior's action at that step's
/// observation plus the plan's, so the planner searches around the policy, closed loop, instead
/// of around the base alone; its chosen action is then the policy's action corrected — a label
/// that depends on the state through the policy rather than on the planner's own history (PLATO,
/// Kahn, Zhang, Levine, Abbeel 2017).
pub type Prior<'a> = &'a (dyn Fn(&[f32]) -> Vec<f32> + Sync);

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlannerConfig {
    /// Plans rolled out per decision, the nominal included.
    pub samples: usize,
    /// Control steps each plan looks ahead.
    pub horizon: usize,
    /// Control steps between the noise's knots.
    pub knot: usize,
    /// Standard deviation of the noise at a knot, in action units (actions live in [-1, 1]).
    pub sigma: f32,
    /// A rollout that falls costs this, times 2 at its first step down to 1 at the horizon's end.
    pub fall_cost: f32,
    /// Once the object is reached or the gait has stopped: cost per step per (m/s)² of the root's
    /// horizontal speed (standing still is what is asked).
    pub speed_cost: f32,
    /// Posture, per step: this times how far (m) the root is below `stand_height` (squats,
    /// lunges) …
    pub height_cost: f32,
    pub stand_height: f32,
    /// … and this times 1 − the torso's up axis · world up (leaning). Both 0: off.
    pub tilt_cost: f32,
    /// Per step: this times the mean squared difference (rad²) between the character's joint angles
    /// and the gait reference's (DeepMimic's pose term as a cost; 0: off; no gait: nothing).
    pub pose_cost: f32,
    /// Cost per step of the mean squared action.
    pub effort_cost: f32,
    /// A rollout whose root goes below this height (m) counts as fallen; the environment's own
    /// rule (0.4 m) lets a crouched character go on.
    pub up_height: f32,
    /// The warm start is multiplied by this at every step (1: plain predictive sampling; below 1
    /// the plan is pulled back toward zero, i.e. toward the base the actions are residuals on,
    /// instead of random-walking as the selected noise accumulates).
    pub decay: f32,
    /// 0: the cheapest plan becomes the nominal (predictive sampling). Above 0: the nominal is
    /// the plans' mean weighted by exp(−(cost − cheapest) / temperature) (MPPI, Williams et al.
    /// 2016), which averages the selected noise away.
    pub temperature: f32,
    /// Threads rolling plans out (each with its own copy of the environment).
    pub threads: usize,
    pub seed: u64,
}

impl Default for PlannerConfig {
    /// Settings measured with `mpc_probe` (RESULTS.md, fourteenth session): 24 samples over a 1-s
    /// horizon kept the gait up for 20 s on 8 of 10 unseen tasks, 12 over 0.8 s on 6.
    fn default() -> Self {
        Self {
            samples: 24,
            horizon: 30,
            knot: 6,
            sigma: 0.3,
            fall_cost: 50.0,
            speed_cost: 2.0,
            height_cost: 0.0,
            stand_height: 0.85,
            tilt_cost: 0.0,
            pose_cost: 0.0,
            effort_cost: 0.01,
            up_height: 0.7,
            decay: 1.0,
            temperature: 0.0,
            threads: 2,
            seed: 0x5eed,
        }
    }
}

impl PlannerConfig {
    pub fn check(&self) -> Result<(), String> {
        if self.samples == 0 || self.horizon == 0 || self.knot == 0 || self.threads == 0 {
            return Err(format!(
                "planner: samples ({}), horizon ({}), knot ({}) and threads ({}) must be positive",
                self.samples, self.horizon, self.knot, self.threads
            ));
        }
        if !(self.decay.is_finite() && (0.0..=1.0).contains(&self.decay)) {
            return Err(format!(
                "planner.decay must be within [0, 1], got {}",
                self.decay
            ));
        }
        if !(self.temperature.is_finite() && self.temperature >= 0.0) {
            return Err(format!(
                "planner.temperature must be finite and >= 0, got {}",
                self.temperature
            ));
        }
        if !(self.sigma.is_finite() && self.sigma >= 0.0) {
            return Err(format!(
                "planner.sigma must be finite and >= 0, got {}",
                self.sigma
            ));
        }
        Ok(())
    }
}

/// Whether a step ends the character's episode for the planner: the environment's fall, broken
/// physics, or the root below `up_height`.
pub fn down(env: &TaskEnv, result: &StepResult, up_height: f32) -> bool {
    result.fell || result.physics_invalid || env.world.root_height() < up_height
}

/// After the object is reached or the gait has stopped, standing still is what is asked.
pub fn stopping(env: &TaskEnv) -> bool {
    env.reached || (env.gait_running() && env.gait_phase().is_none())
}

pub fn horizontal_speed(env: &TaskEnv) -> f32 {
    let v = env.world.body_linvel(0);
    (v.x * v.x + v.y * v.y).sqrt()
}

/// SplitMix64 with Box-Muller normals: the planner's deterministic noise.
#[derive(Clone, Debug)]
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

/// The planner's state between decisions: the nominal plan (horizon × action dim, row-major)
/// and the noise generator.
#[derive(Clone, Debug)]
pub struct Planner {
    pub config: PlannerConfig,
    act_dim: usize,
    nominal: Vec<f32>,
    noise: Noise,
    /// Per DoF: whether the planner moves it (the rest keep a zero action).
    planned: Vec<bool>,
}

impl Planner {
    pub fn new(config: PlannerConfig, act_dim: usize) -> Result<Self, String> {
        config.check()?;
        Ok(Self {
            nominal: vec![0.0; config.horizon * act_dim],
            noise: Noise(config.seed),
            planned: vec![true; act_dim],
            act_dim,
            config,
        })
    }

    /// Plans only the DoFs whose entry is `true` (e.g. legs and trunk); the others keep a zero
    /// action. A mask of the wrong length is refused.
    pub fn with_planned(mut self, planned: Vec<bool>) -> Result<Self, String> {
        if planned.len() != self.act_dim {
            return Err(format!(
                "planner: a mask of {} DoFs for {} actions",
                planned.len(),
                self.act_dim
            ));
        }
        self.planned = planned;
        Ok(self)
    }

    /// Per DoF: whether the planner moves it.
    pub fn planned(&self) -> &[bool] {
        &self.planned
    }

    /// The nominal plan's first action: what the planner does next if no sample beats it.
    pub fn nominal_action(&self) -> &[f32] {
        &self.nominal[..self.act_dim]
    }

    /// The same planner (same plan) drawing its noise from `seed`: for measuring how much a
    /// decision depends on the draw rather than on the state and the plan.
    pub fn reseeded(&self, seed: u64) -> Self {
        Self {
            noise: Noise(seed),
            ..self.clone()
        }
    }

    /// Plans from `env`'s current state and returns the action to take now; `workers` are
    /// environments of the same task and configuration (at least one) that the rollouts run in.
    /// Afterwards the plan is shifted by a step: call once per control step.
    pub fn act(&mut self, env: &TaskEnv, workers: &mut [TaskEnv]) -> Vec<f32> {
        self.act_around(env, workers, None)
    }

    /// As [`Planner::act`], with the plans as corrections to `prior`'s actions (see [`Prior`]):
    /// the returned action is the prior's action at `env`'s observation plus the chosen plan's
    /// first, within [-1, 1].
    pub fn act_around(
        &mut self,
        env: &TaskEnv,
        workers: &mut [TaskEnv],
        prior: Option<Prior>,
    ) -> Vec<f32> {
        let snapshot = env.snapshot();
        let mut candidates = vec![self.nominal.clone()];
        for _ in 1..self.config.samples {
            let plan = self.perturbed();
            candidates.push(plan);
        }
        let costs = self.costs(&snapshot, &candidates, workers, prior);
        self.nominal = self.choose(candidates, &costs);
        let mut action = self.nominal[..self.act_dim].to_vec();
        if let Some(prior) = prior {
            add_clamped(&mut action, &prior(&env.observation()));
        }
        self.shift();
        action
    }

    /// The next nominal plan: the cheapest candidate, or with a temperature the candidates' mean
    /// weighted by exp(−(cost − cheapest) / temperature).
    fn choose(&self, mut candidates: Vec<Vec<f32>>, costs: &[f32]) -> Vec<f32> {
        let best = (0..costs.len())
            .min_by(|&a, &b| costs[a].total_cmp(&costs[b]))
            .unwrap_or(0);
        let t = self.config.temperature;
        if t <= 0.0 || !costs[best].is_finite() {
            return candidates.swap_remove(best);
        }
        let weights: Vec<f32> = costs
            .iter()
            .map(|c| (-(c - costs[best]) / t).exp())
            .map(|w| if w.is_finite() { w } else { 0.0 })
            .collect();
        let total: f32 = weights.iter().sum();
        let mut mean = vec![0.0f32; self.nominal.len()];
        for (plan, w) in candidates.iter().zip(&weights) {
            for (m, x) in mean.iter_mut().zip(plan) {
                *m += w / total * x;
            }
        }
        mean
    }

    /// Moves the plan a step on (its last action held; zero for a one-step horizon) and pulls
    /// it toward zero by `decay`.
    fn shift(&mut self) {
        let d = self.act_dim;
        let n = self.nominal.len();
        self.nominal.rotate_left(d);
        if n >= 2 * d {
            self.nominal.copy_within(n - 2 * d..n - d, n - d);
        } else {
            self.nominal[n - d..].fill(0.0);
        }
        for x in &mut self.nominal {
            *x *= self.config.decay;
        }
    }

    fn costs(
        &self,
        snapshot: &EnvSnapshot,
        plans: &[Vec<f32>],
        workers: &mut [TaskEnv],
        prior: Option<Prior>,
    ) -> Vec<f32> {
        if workers.is_empty() {
            return vec![f32::INFINITY; plans.len()];
        }
        let per = plans
            .len()
            .div_ceil(workers.len().min(self.config.threads).max(1));
        let config = &self.config;
        std::thread::scope(|scope| {
            let handles: Vec<_> = plans
                .chunks(per)
                .zip(workers.iter_mut())
                .map(|(chunk, worker)| {
                    scope.spawn(move || {
                        chunk
                            .iter()
                            .map(|plan| plan_cost(worker, snapshot, plan, config, prior))
                            .collect::<Vec<f32>>()
                    })
                })
                .collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().unwrap_or_else(|_| vec![f32::INFINITY; per]))
                .collect()
        })
    }

    /// The nominal plan plus noise drawn at knots, interpolated, within [-1, 1].
    fn perturbed(&mut self) -> Vec<f32> {
        let (c, d) = (&self.config, self.act_dim);
        let knots = c.horizon.div_ceil(c.knot) + 1;
        let drawn: Vec<f32> = (0..knots * d)
            .map(|_| c.sigma * self.noise.normal())
            .collect();
        let mut plan = self.nominal.clone();
        for k in 0..c.horizon {
            let (i, frac) = (k / c.knot, (k % c.knot) as f32 / c.knot as f32);
            for j in (0..d).filter(|&j| self.planned[j]) {
                let n = drawn[i * d + j] * (1.0 - frac) + drawn[(i + 1) * d + j] * frac;
                plan[k * d + j] = (plan[k * d + j] + n).clamp(-1.0, 1.0);
            }
        }
        plan
    }
}

/// The posture terms of a step's cost: root below the standing height, torso tilt, joint angles
/// off the gait reference's.
pub fn posture_cost(env: &TaskEnv, c: &PlannerConfig) -> f32 {
    let low = (c.stand_height - env.world.root_height()).max(0.0);
    let tilt = env
        .model
        .body_index("torso")
        .map_or(0.0, |i| 1.0 - (env.world.body_state(i).rot * Vector::Z).z);
    let pose = if c.pose_cost > 0.0 {
        env.gait_reference_angles().map_or(0.0, |reference| {
            let angles = crate::fidelity::joint_angles(&env.model, &env.world.body_states());
            let n = angles.len().min(reference.len()).max(1);
            angles
                .iter()
                .zip(&reference)
                .map(|(a, r)| (a - r) * (a - r))
                .sum::<f32>()
                / n as f32
        })
    } else {
        0.0
    };
    c.height_cost * low + c.tilt_cost * tilt + c.pose_cost * pose
}

/// `a += b` within [-1, 1] (the action range).
fn add_clamped(a: &mut [f32], b: &[f32]) {
    for (x, y) in a.iter_mut().zip(b) {
        *x = (*x + y).clamp(-1.0, 1.0);
    }
}

/// Cost of rolling `plan` (horizon × action dim) out of `snapshot` in `env`: minus the
/// environment's reward, a fall's cost, the speed cost while stopping, the effort. With a
/// `prior`, each step's action is the prior's (closed loop) plus the plan's.
pub fn plan_cost(
    env: &mut TaskEnv,
    snapshot: &EnvSnapshot,
    plan: &[f32],
    c: &PlannerConfig,
    prior: Option<Prior>,
) -> f32 {
    env.restore(snapshot);
    let d = plan.len() / c.horizon.max(1);
    let mut cost = 0.0;
    let mut action = Vec::with_capacity(d);
    for (k, step) in plan.chunks(d.max(1)).enumerate() {
        action.clear();
        action.extend_from_slice(step);
        if let Some(prior) = prior {
            add_clamped(&mut action, &prior(&env.observation()));
        }
        let a = action.as_slice();
        let r = env.step(a);
        if down(env, &r, c.up_height) {
            cost += c.fall_cost * (2.0 - k as f32 / c.horizon as f32);
            break;
        }
        cost -= r.reward;
        if stopping(env) {
            let v = horizontal_speed(env);
            cost += c.speed_cost * v * v;
        }
        cost += c.effort_cost * a.iter().map(|x| x * x).sum::<f32>() / d.max(1) as f32;
        if c.height_cost > 0.0 || c.tilt_cost > 0.0 || c.pose_cost > 0.0 {
            cost += posture_cost(env, c);
        }
        if r.done {
            break;
        }
    }
    cost
}
