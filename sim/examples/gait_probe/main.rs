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
//! `WALK=g0,…` (all 17, that order) the walk's gains when another vector is searched,
//! `SIGMA`, `ELITIST=1` for a (1+λ) search around the best at a fixed step, `HOLD=name=value,…`
//! to keep gains of the searched vector at a value, e.g. `HOLD=stance_knee_bias=0`). It prints every new
//! best as an `eval` string. One set: `gait_probe eval g0,g1,…` (`TRACE=1` per-step errors,
//! `GIF=out.gif` [`GIF_PHASE`] a rollout, `STEER=gain GOAL_ANGLE=rad` steering toward a goal
//! 3 m away at that angle, travel then counts the distance gained toward it). `SYNC_WAIT=n
//! SYNC_SKIP=m` keep the cycle in time with the footfalls (`GaitReference::advance`).
//!
//! What a rollout is: `PHASES=n` starts (default 8) on task train-0001 (`EMPTY=1`: its
//! furniture removed), or `ROOMS=1`: the environment's own `[env.gait]` in the first n training
//! tasks, steering toward the object, scored as steps up + 100 per room whose object was reached
//! (with `EMPTY=1` the rooms' furniture removed, with `STAND_START=1` from the task's standing start).
//! `THREADS=n` candidates scored at once (default: one per core, at most λ = 16).
//! A rollout is up while the environment does not call it a fall and the root is above
//! `UP_HEIGHT` (0.7 m). `TEMPO=x` plays the cycle at x of its speed. The stop (`stop.rs`):
//! `STOP_AFTER=n` stops the i-th rollout after n + 7 i steps — a braking step against the
//! reference's velocity times `BRAKE_SPEED`, then, once both feet are below `STOP_HEIGHT`
//! (after at least `STOP_MIN`, at most `STOP_WAIT` steps; `STOP_ON=footfall`: at the
//! reference's footfall), the pose held with ankle and hip strategies; `SEARCH=stand` (or
//! `both`) searches the stop's gains instead of (or with) the walk's. `STAND_START=1`: the
//! rollouts start from the task's standing start (at rest) instead of the clip's state, the gait
//! ramping in (`StartRamp`); `SEARCH=start` searches the ramp (`seconds,feedback,ankle_lean,…`),
//! `RAMP=seconds,feedback,…` fixes it otherwise. With `ROOMS=1`, `STOP_DISTANCE=m` stops the
//! gait that close to the object (`[env.gait] stop_distance`), `NEAR=m` starts that far before it
//! (`start_distance`), and `SEARCH=stop` searches the stop's ramp (`[env.gait.stop]`).
//! `OFFSETS=FILE` (JSON, DoF name → per-step radians; `OFFSETS_LEGS=k` scales the hips', knees'
//! and ankles') lays `[env.gait] angle_offsets` on the reference the search walks.
//! `gait_probe push`: the neutral standing pose (zero action) with every body moving at
//! 0.1-1.0 m/s forward or sideways — how much momentum standing alone absorbs.

use lhm_scenes::Benchmark;
use lhm_sim::env::{EnvConfig, GaitConfig, TaskEnv};
use lhm_sim::gait::{
    balance, balance_about, braking_targets, start_targets, steer, BalanceGains, GaitReference,
    Rig, StartRamp,
};
mod stop;
use lhm_sim::motion::demo::{AmpWindow, DemoMotion};
use lhm_sim::motion::retarget::KinematicPose;
use lhm_sim::obs::HeadingFrame;
use lhm_sim::render::{render, write_gif, Camera, Image};
use lhm_sim::{CharacterModel, SimConfig};
use rapier3d::math::Vector;
use stop::{add_brake, stand_targets, StandGains, StandHold};

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
    /// `STOP_AFTER=n`: the rollout from the i-th phase stops after n + 7 i steps: it walks on
    /// until both feet are down (at most `STOP_WAIT` steps), then stands in that pose
    /// (`stand_targets`). The search then tunes the standing gains (`SEARCH=stand`) or both.
    stop_after: Option<usize>,
    stop_wait: usize,
    /// What the search's vector is: the walk's gains, the stand's, or both (walk first).
    search: Search,
    /// The gains not searched.
    fixed: Gains,
    empty: bool,
    /// `STOP_ON=footfall`: freeze at the reference's next footfall instead of when both of the
    /// character's feet are down.
    stop_on_footfall: bool,
    /// `STOP_HEIGHT`: both feet's origins below this count as down for the stop.
    stop_height: f32,
    /// `BRAKE_SPEED`: from the stop's trigger to the freeze the walk runs against the
    /// reference's velocity times this (`braking_targets`); `STOP_MIN`: steps before a freeze.
    brake_speed: f32,
    stop_min: usize,
    up_height: f32,
    /// `TEMPO`: the cycle played at this fraction of its speed (its velocities scaled alike).
    tempo: f32,
    phases: usize,
    /// `ROOMS=1`: each "phase" is a training task instead (`rollout_room`).
    rooms: bool,
    stand_start: bool,
    /// `HORIZON`: control steps per rollout (default `STEPS`).
    horizon: usize,
    /// With `ROOMS=1`: `STOP_DISTANCE` (m; 0: no stop), the environment's `[env.gait]
    /// stop_distance`, and `NEAR` (m; 0: the task's start), its `start_distance`.
    stop_distance: f32,
    near: f32,
    shared_reference: std::sync::Arc<GaitReference>,
}

#[derive(Clone, Copy, PartialEq)]
enum Search {
    Walk,
    Stand,
    Both,
    /// The start from rest's ramp (`StartRamp`; with `STAND_START=1`).
    Start,
    /// The stop's ramp (`[env.gait.stop]`, `stop_targets`; with `ROOMS=1`).
    Stop,
}

#[derive(Clone, Copy)]
struct Gains {
    walk: BalanceGains,
    stand: StandGains,
    start: StartRamp,
    stop: StartRamp,
}

impl Setup {
    fn dim(&self) -> usize {
        match self.search {
            Search::Walk => BalanceGains::LEN,
            Search::Stand => StandGains::LEN,
            Search::Both => BalanceGains::LEN + StandGains::LEN,
            Search::Start | Search::Stop => StartRamp::LEN,
        }
    }

    fn gains(&self, v: &[f32]) -> Gains {
        let mut g = self.fixed;
        let walk = |v: &[f32]| BalanceGains::from_array(std::array::from_fn(|i| v[i]));
        let stand = |v: &[f32]| StandGains::from_array(std::array::from_fn(|i| v[i]));
        match self.search {
            Search::Walk => g.walk = walk(v),
            Search::Stand => g.stand = stand(v),
            Search::Both => {
                g.walk = walk(v);
                g.stand = stand(&v[BalanceGains::LEN..]);
            }
            Search::Start => g.start = StartRamp::from_array(std::array::from_fn(|i| v[i])),
            Search::Stop => g.stop = StartRamp::from_array(std::array::from_fn(|i| v[i])),
        }
        g
    }

    /// The names of the search vector's entries, in order.
    fn names(&self) -> Vec<&'static str> {
        match self.search {
            Search::Walk => BalanceGains::NAMES.to_vec(),
            Search::Stand => StandGains::NAMES.to_vec(),
            Search::Both => [&BalanceGains::NAMES[..], &StandGains::NAMES[..]].concat(),
            Search::Start | Search::Stop => StartRamp::NAMES.to_vec(),
        }
    }

    /// `HOLD=name=value,…`: search-vector entries the search keeps at a value (e.g.
    /// `stance_knee_bias=0`: a base that does not straighten the stance knee). An unknown name is
    /// refused with the list.
    fn held(&self, text: &str) -> Result<Vec<(usize, f32)>, String> {
        let names = self.names();
        text.split(',')
            .filter(|t| !t.is_empty())
            .map(|item| {
                let (name, value) = item
                    .split_once('=')
                    .ok_or_else(|| format!("HOLD: {item:?} is not name=value"))?;
                let i = names.iter().position(|n| *n == name).ok_or_else(|| {
                    format!("HOLD: no gain {name:?} in this search; its gains: {names:?}")
                })?;
                let v = value
                    .parse()
                    .map_err(|_| format!("HOLD: {value:?} ({name}) is not a number"))?;
                Ok((i, v))
            })
            .collect()
    }

    fn vector(&self, g: &Gains) -> Vec<f32> {
        match self.search {
            Search::Walk => g.walk.to_array().to_vec(),
            Search::Stand => g.stand.to_array().to_vec(),
            Search::Both => [&g.walk.to_array()[..], &g.stand.to_array()[..]].concat(),
            Search::Start => g.start.to_array().to_vec(),
            Search::Stop => g.stop.to_array().to_vec(),
        }
    }
}

/// One rollout from `phase` (fraction of the cycle): (control steps up, ground travel in m).
fn rollout(s: &Setup, g: &[f32], phase: usize, steps: usize) -> (usize, f32) {
    rollout_traced(s, g, phase, steps, false, None)
}

fn rollout_traced(
    s: &Setup,
    g: &[f32],
    phase_index: usize,
    steps: usize,
    trace: bool,
    mut frames: Option<&mut Vec<Image>>,
) -> (usize, f32) {
    let Some(mut env) = probe_env(s, s.empty) else {
        return (0, 0.0);
    };
    let phase = s.phase(phase_index);
    let Gains {
        walk: gains,
        stand,
        start: ramp,
        ..
    } = s.gains(g);
    let stop_at = s.stop_after.map(|n| n + 7 * phase_index);
    let mut hold: Option<StandHold> = None;
    let k0 = (phase * s.reference.len() as f32) as usize;
    // STAND_START=1 keeps the task's own standing start (neutral pose, at rest) instead of the
    // clip's state; the gait's feedback starts from there at the cycle step.
    if !s.stand_start {
        env.start_from_demo(&s.demo, s.reference.clip, s.reference.time(k0));
    }
    let start = env.world.body_states()[0].pos;
    let start_yaw = env.task.start.yaw as f32;
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
        if hold.is_none()
            && stop_at.is_some_and(|n| {
                k >= n + s.stop_wait
                    || (k >= n + s.stop_min
                        && if s.stop_on_footfall {
                            s.reference.footfall(&s.rig, step)
                        } else {
                            s.rig.feet_down(&now, s.stop_height)
                        })
            })
        {
            hold = Some(StandHold::freeze(&s.model, &s.rig, &now, reference_now));
            if trace {
                println!(
                    "  stop at k {k}: feet down {}, heights {:.3} {:.3}, root h {:.2}",
                    s.rig.feet_down(&now, s.stop_height),
                    now[s.rig.foot[0]].pos.z,
                    now[s.rig.foot[1]].pos.z,
                    now[0].pos.z
                );
            }
        }
        let braking = stop_at.is_some_and(|n| k >= n);
        let mut targets = match &hold {
            Some(h) => stand_targets(&s.rig, &stand, &now, h),
            None if braking => {
                let mut t =
                    braking_targets(&s.rig, &gains, &now, reference_now, angles, s.brake_speed);
                add_brake(&s.rig, &stand, &mut t, &now, reference_now);
                t
            }
            // From rest the gait ramps in (`StartRamp`; `seconds` 0: none).
            None if s.stand_start => start_targets(
                &s.rig,
                &gains,
                &ramp,
                k as f32 / s.sim.control_hz,
                &now,
                reference_now,
                angles,
            ),
            None => braking_targets(&s.rig, &gains, &now, reference_now, angles, s.tempo),
        };
        if s.steer_gain != 0.0 && hold.is_none() {
            let to = HeadingFrame::of(&now[0]).vector(goal - now[0].pos);
            let err = to.y.atan2(to.x);
            steer(&s.rig, &mut targets, reference_now, s.steer_gain * err, 0.3);
        }
        if trace && k % 3 == 0 && hold.is_some() {
            let mid = (now[s.rig.foot[0]].pos + now[s.rig.foot[1]].pos) * 0.5;
            let c = balance_about(&s.rig, &now, mid);
            let t = c.pelvis.to_scaled_axis();
            let (y, p, r) = (t.z, t.y, t.x);
            println!(
                "  k {k:3} standing h {:.2} d ({:+.2},{:+.2}) v ({:+.2},{:+.2}) pelvis pitch {p:+.2} roll {r:+.2} yaw {y:+.2} feet {:.2} {:.2}",
                now[0].pos.z, c.d.x, c.d.y, c.v.x, c.v.y,
                now[s.rig.foot[0]].pos.z, now[s.rig.foot[1]].pos.z,
            );
        } else if trace && k % 3 == 0 {
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
        let result = env.step(&action);
        if let Some(frames) = frames.as_deref_mut() {
            if k % 2 == 0 {
                let camera = Camera::third_person(&env.world, 240, 180);
                frames.push(render(&env.world, &camera, true));
            }
        }
        if down(s, &env, &result) {
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

/// Start phases: `PHASES` (default 8) evenly spaced fractions of the clip (4 overfit the chaotic
/// rollouts: gains rounded to 3 decimals lost half the steps).
impl Setup {
    fn phase(&self, i: usize) -> f32 {
        (i % self.phases) as f32 / self.phases as f32
    }
}
const STEPS: usize = 300;

/// `ROOMS=n`: one rollout of the environment's own gait (`[env.gait]` with these walking gains,
/// zero residual actions, steering toward the object) in training task `i` (of the first n),
/// started at cycle step 7 i toward its first object, as actors and `lhm render-rollout` run it:
/// (control steps up, 1 if the root came within reach of the object).
fn rollout_room(s: &Setup, g: &[f32], i: usize, steps: usize) -> (usize, f32) {
    let Some(mut task) = s.bench.tasks(lhm_scenes::Split::Train).get(i).cloned() else {
        return (0, 0.0);
    };
    if s.empty {
        // EMPTY=1 with ROOMS=1: the room without its furniture (`[env] clear_furniture`).
        task = lhm_sim::env::without_furniture(&task);
    }
    let gains = s.gains(g);
    let mut config = s.env_config.clone();
    config.gait = Some(GaitConfig {
        gains: gains.walk,
        start: gains.start,
        stop: gains.stop,
        stop_distance: s.stop_distance,
        start_distance: s.near,
        // SYNC_WAIT / SYNC_SKIP, as the probe's own rollouts use them.
        sync_wait: s.sync.0,
        sync_skip: s.sync.1,
        ..GaitConfig::default()
    });
    let mut env = TaskEnv::new(&s.model, &task, &s.bench.catalogue, s.sim.clone(), config);
    let yaw = env.yaw_toward_first_object();
    if s.stand_start {
        // STAND_START=1: the task's standing start, the gait ramping in (`[env.gait.start]`).
        env.start_at_rest_in_gait(s.shared_reference.clone(), 7 * i, yaw);
    } else {
        env.start_in_gait(&s.demo, s.shared_reference.clone(), 7 * i, yaw);
    }
    let action = vec![0.0; s.model.dofs.len()];
    let mut up = 0;
    for k in 0..steps {
        let result = env.step(&action);
        if down(s, &env, &result) {
            break;
        }
        up = k + 1;
        if result.done {
            break;
        }
    }
    (up, if env.reached { 1.0 } else { 0.0 })
}

/// The probe's environment: task train-0001 (`empty`: emptied), the default configuration.
fn probe_env(s: &Setup, empty: bool) -> Option<TaskEnv> {
    let (_, mut task) = s.bench.task("train-0001")?;
    if empty {
        // EMPTY=1: the character's own falls only.
        task = lhm_sim::env::empty_room(&task);
    }
    Some(TaskEnv::new(
        &s.model,
        &task,
        &s.bench.catalogue,
        s.sim.clone(),
        s.env_config.clone(),
    ))
}

/// Whether a rollout is over: the environment calls it a fall (or the physics broke), or the root
/// is below `UP_HEIGHT` (the environment's 0.4 m lets a crouched character go on).
fn down(s: &Setup, env: &TaskEnv, result: &lhm_sim::env::StepResult) -> bool {
    result.fell || result.physics_invalid || env.world.root_height() < s.up_height
}

/// `push V`: the neutral standing pose (zero action) at task train-0001's start (room emptied), every body
/// moving at V m/s along the heading: how much momentum standing alone absorbs (steps up of 300).
fn push(s: &Setup, v: f32, lateral: bool) -> usize {
    // Always in the empty room: a push toward furniture ends leaning on it.
    let Some(mut env) = probe_env(s, true) else {
        return 0;
    };
    let mut states = env.world.body_states();
    let heading = states[0].rot * if lateral { Vector::Y } else { Vector::X };
    let dir = Vector::new(heading.x, heading.y, 0.0).normalize_or_zero();
    for b in &mut states {
        b.linvel = dir * v;
        b.angvel = Vector::ZERO;
    }
    let pose = KinematicPose {
        root_pos: states[0].pos,
        root_rot: states[0].rot,
        local_rots: vec![rapier3d::math::Rotation::IDENTITY; s.model.bodies.len()],
    };
    env.world.set_character_state(&pose, &states);
    if std::env::var_os("TRACE").is_some() {
        let b = env.world.body_states();
        println!(
            "  after the push: root velocity {:?}, feet {:?} {:?}",
            b[0].linvel, b[s.rig.foot[0]].linvel, b[s.rig.foot[1]].linvel
        );
    }
    let action = vec![0.0; s.model.dofs.len()];
    let start = env.world.body_states()[0].pos;
    for k in 0..STEPS {
        let r = env.step(&action);
        if std::env::var_os("TRACE").is_some() && k % 15 == 0 {
            let b = env.world.body_states();
            println!(
                "  k {k}: root moved {:.2} m, height {:.2}, speed {:.2}",
                (b[0].pos - start).length(),
                b[0].pos.z,
                b[0].linvel.length()
            );
        }
        if down(s, &env, &r) {
            return k;
        }
    }
    STEPS
}

fn score(s: &Setup, g: &[f32]) -> (f32, usize, f32) {
    let (mut up, mut travel) = (0, 0.0);
    for p in 0..s.phases {
        let (u, t) = if s.rooms {
            rollout_room(s, g, p, s.horizon)
        } else {
            rollout(s, g, p, s.horizon)
        };
        up += u;
        travel += t;
    }
    if s.rooms {
        // Travel is the count of rooms where the object was reached.
        return (up as f32 + 100.0 * travel, up, travel);
    }
    // Standing still is the goal after a stop: travel counts only in a pure walk search.
    let w = if s.stop_after.is_some() { 0.0 } else { 30.0 };
    (up as f32 + w * travel, up, travel)
}

/// `WALK=g0,g1,…`: all `BalanceGains::LEN` walking gains in `BalanceGains::NAMES` order; empty:
/// `BalanceGains::default()`. A short list is refused rather than filled with zeros, which would
/// silently be another base.
fn walk_gains(text: &str) -> Result<BalanceGains, String> {
    if text.is_empty() {
        return Ok(BalanceGains::default());
    }
    let values = text
        .split(',')
        .map(|t| {
            t.trim()
                .parse::<f32>()
                .map_err(|_| format!("WALK: {t:?} is not a number"))
        })
        .collect::<Result<Vec<f32>, String>>()?;
    let array: [f32; BalanceGains::LEN] = values.as_slice().try_into().map_err(|_| {
        format!(
            "WALK: {} numbers, the walk has {} gains: {:?}",
            values.len(),
            BalanceGains::LEN,
            BalanceGains::NAMES
        )
    })?;
    Ok(BalanceGains::from_array(array))
}

/// `OFFSETS=FILE`: the base's `[env.gait] angle_offsets` as JSON (`{"left_knee": [..], ..}`, e.g.
/// converted from a run's TOML overlay), the hips', knees' and ankles' times `OFFSETS_LEGS`
/// (default 1): a search of the walking gains for the clip's posture (the fifty-sixth to sixtieth
/// sessions' feed-forward), which the default gains were not searched under.
fn offsets_from(
    path: &str,
    legs: f32,
) -> Result<std::collections::BTreeMap<String, Vec<f32>>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("OFFSETS: {path}: {e}"))?;
    let mut offsets: std::collections::BTreeMap<String, Vec<f32>> =
        serde_json::from_str(&text).map_err(|e| format!("OFFSETS: {path}: {e}"))?;
    for (name, values) in offsets.iter_mut() {
        if ["hip", "knee", "ankle"].iter().any(|j| name.contains(j)) {
            values.iter_mut().for_each(|v| *v *= legs);
        }
    }
    Ok(offsets)
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
    let push_mode = args.peek().map(String::as_str) == Some("push");
    if push_mode {
        args.next();
    }
    let eval: Option<String> = if args.peek().map(String::as_str) == Some("eval") {
        args.next();
        Some(args.next().unwrap_or_default())
    } else {
        None
    };
    let iterations: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(30);
    let clip_name = args.next().unwrap_or_else(|| "humanoid3d_walk".into());
    let dir = lhm_sim::motion::default_dir();
    let model = CharacterModel::amp_humanoid();
    let (env_config, sim) = (EnvConfig::default(), SimConfig::default());
    let demo = DemoMotion::load_dir(&model, &dir, AmpWindow::of(&env_config, &sim))?;
    let clip = demo
        .clips()
        .position(|(n, _)| n.contains(&clip_name))
        .ok_or("clip not installed")?;
    let tempo = std::env::var("TEMPO")
        .ok()
        .and_then(|v| v.parse::<f32>().ok())
        .unwrap_or(1.0);
    let reference =
        GaitReference::new(&model, &demo, clip, tempo / sim.control_hz).ok_or("clip too short")?;
    let reference = match std::env::var("OFFSETS") {
        Ok(path) => {
            let legs = std::env::var("OFFSETS_LEGS")
                .ok()
                .map(|v| {
                    v.parse::<f32>()
                        .map_err(|_| format!("OFFSETS_LEGS: {v:?} is not a number"))
                })
                .transpose()?
                .unwrap_or(1.0);
            reference.with_angle_offsets(&model, &offsets_from(&path, legs)?)?
        }
        Err(_) => reference,
    };
    let env_f32 = |k: &str, d: f32| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let shared_reference = std::sync::Arc::new(reference.clone());
    // A comma list of StartRamp::LEN numbers from the environment (missing entries 0).
    let floats = |k: &str| -> Result<[f32; StartRamp::LEN], std::num::ParseFloatError> {
        let mut a = [0f32; StartRamp::LEN];
        let text = std::env::var(k).unwrap_or_default();
        for (x, t) in a.iter_mut().zip(text.split(',').filter(|t| !t.is_empty())) {
            *x = t.parse()?;
        }
        Ok(a)
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
        stop_after: std::env::var("STOP_AFTER")
            .ok()
            .and_then(|v| v.parse().ok()),
        stop_wait: env_f32("STOP_WAIT", 10.0) as usize,
        search: match std::env::var("SEARCH").as_deref() {
            Ok("stand") => Search::Stand,
            Ok("both") => Search::Both,
            Ok("start") => Search::Start,
            Ok("stop") => Search::Stop,
            _ => Search::Walk,
        },
        fixed: Gains {
            // `WALK=g0,g1,…` (`BalanceGains::NAMES` order): the walk's gains when they are not
            // searched, e.g. to search the start ramp of another base (default: the defaults).
            walk: walk_gains(&std::env::var("WALK").unwrap_or_default())?,
            stand: StandGains::default(),
            // `RAMP=seconds,feedback,…`: the start ramp when it is not searched.
            start: StartRamp::from_array(floats("RAMP")?),
            stop: StartRamp::default(),
        },
        empty: std::env::var_os("EMPTY").is_some(),
        stop_on_footfall: std::env::var("STOP_ON").as_deref() == Ok("footfall"),
        stop_height: env_f32("STOP_HEIGHT", 0.07),
        brake_speed: env_f32("BRAKE_SPEED", 1.0),
        stop_min: env_f32("STOP_MIN", 0.0) as usize,
        up_height: env_f32("UP_HEIGHT", 0.7),
        tempo: env_f32("TEMPO", 1.0),
        phases: env_f32("PHASES", 8.0).max(1.0) as usize,
        rooms: std::env::var_os("ROOMS").is_some(),
        stand_start: std::env::var_os("STAND_START").is_some(),
        horizon: env_f32("HORIZON", STEPS as f32).max(1.0) as usize,
        stop_distance: env_f32("STOP_DISTANCE", 0.0),
        near: env_f32("NEAR", 0.0),
        shared_reference,
    };
    if push_mode {
        for v in [0.0f32, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0] {
            println!(
                "push {v:.1} m/s: forward up {} of {STEPS}, lateral up {} of {STEPS}",
                push(&setup, v, false),
                push(&setup, v, true)
            );
        }
        return Ok(());
    }
    // A comma list in the search vector's order (missing entries 0), or "default".
    let parse = |text: &str| -> Result<Vec<f32>, std::num::ParseFloatError> {
        let mut v = vec![0f32; setup.dim()];
        if text == "default" {
            return Ok(setup.vector(&setup.fixed));
        }
        for (x, t) in v.iter_mut().zip(text.split(',').filter(|t| !t.is_empty())) {
            *x = t.parse()?;
        }
        Ok(v)
    };
    if let Some(text) = eval {
        let g = parse(&text)?;
        let (total, _, _) = score(&setup, &g);
        for p in (0..setup.phases).filter(|_| setup.rooms) {
            let (u, r) = rollout_room(&setup, &g, p, setup.horizon);
            println!("room {p}: up {u}, reached {r}");
        }
        for p in (0..setup.phases).filter(|_| !setup.rooms) {
            let (u, t) = rollout_traced(
                &setup,
                &g,
                p,
                setup.horizon,
                std::env::var_os("TRACE").is_some(),
                None,
            );
            println!("phase {}: up {u}, travel {t:.2}", setup.phase(p));
        }
        println!("score {total:.1}");
        // GIF=PATH: the rollout from the phase in $GIF_PHASE (default 0.5), every other step.
        if let Ok(path) = std::env::var("GIF") {
            let phase = (env_f32("GIF_PHASE", 0.5) * setup.phases as f32) as usize;
            let mut frames = Vec::new();
            rollout_traced(&setup, &g, phase, setup.horizon, false, Some(&mut frames));
            write_gif(&frames, 7, std::fs::File::create(path)?)?;
        }
        return Ok(());
    }
    let held = setup.held(&std::env::var("HOLD").unwrap_or_default())?;
    let hold = |v: &mut Vec<f32>| {
        for &(i, x) in &held {
            v[i] = x;
        }
    };
    let mut mean = parse(&std::env::var("START").unwrap_or_default())?;
    hold(&mut mean);
    let mut sigma: f32 = std::env::var("SIGMA")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0.2);
    let elitist = std::env::var_os("ELITIST").is_some();
    let (base, up, travel) = score(&setup, &mean);
    println!(
        "start point (zeros: open loop): score {base:.1}, steps up {up} of {}, travel {travel:.2} m",
        setup.phases * setup.horizon
    );
    let mut best = (base, mean.clone());
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let lambda = 16;
    // THREADS (default: every core, at most λ): candidates scored in parallel.
    let threads = std::env::var("THREADS")
        .ok()
        .and_then(|t| t.parse::<usize>().ok())
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(2, |n| n.get()))
        .clamp(1, lambda);
    let mut mean_score = base;
    for it in 0..iterations {
        let candidates: Vec<Vec<f32>> = (0..lambda)
            .map(|_| {
                let mut c = mean.clone();
                for x in &mut c {
                    *x += sigma * rng.normal();
                }
                hold(&mut c);
                c
            })
            .collect();
        let scores: Vec<(f32, usize, f32)> = std::thread::scope(|scope| {
            let workers: Vec<_> = candidates
                .chunks(lambda.div_ceil(threads))
                .map(|chunk| {
                    let setup = &setup;
                    scope.spawn(move || chunk.iter().map(|c| score(setup, c)).collect::<Vec<_>>())
                })
                .collect();
            workers
                .into_iter()
                .flat_map(|h| h.join().unwrap_or_default())
                .collect()
        });
        let mut order: Vec<usize> = (0..lambda).collect();
        order.sort_by(|&a, &b| scores[b].0.total_cmp(&scores[a].0));
        let mu = lambda / 2;
        let mut next = vec![0f32; setup.dim()];
        for &i in &order[..mu] {
            for (n, c) in next.iter_mut().zip(&candidates[i]) {
                *n += c / mu as f32;
            }
        }
        mean = next;
        let top = order[0];
        if scores[top].0 > best.0 {
            best = (scores[top].0, candidates[top].clone());
            let all: Vec<String> = best.1.iter().map(|g| g.to_string()).collect();
            println!("new best {:.1}: {}", best.0, all.join(","));
        }
        if elitist {
            // (1+λ): sample around the best so far at a fixed step size.
            mean = best.1.clone();
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
    for (n, g) in setup.names().iter().zip(&best.1) {
        println!("  {n} = {g:.3}");
    }
    for p in 0..setup.phases {
        println!("trace from phase {}:", setup.phase(p));
        let (u, t) = rollout_traced(&setup, &best.1, p, setup.horizon, true, None);
        println!("  up {u}, travel {t:.2}");
    }
    let (_, up, travel) = score(&setup, &best.1);
    println!(
        "best: steps up {up} of {}, travel {travel:.2} m",
        setup.phases * setup.horizon
    );
    Ok(())
}
