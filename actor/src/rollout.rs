//! Stepping a batch of task environments with one policy and cutting the experience into
//! `TrajectoryChunk`s of `chunk_steps` steps per environment.
//!
//! Environments step in lock-step, so every environment's chunk completes on the same step and
//! the actor can swap weights between chunks without ever mixing two policy versions in one
//! chunk. An episode that ends (fall, success of every pair, time limit) is replaced by a fresh
//! environment on a newly drawn task inside the same chunk; `dones`/`truncated` mark the seam.
//! A step on which the physics guard tripped poisons its environment's chunk: that chunk is
//! never sent, so its data can never reach an update.
//!
//! Teacher 2's rollouts (role `teacher2`) start where Teacher 1 ends, with no reset: each new
//! episode is a two-or-more-object task on which the frozen Teacher 1 first runs its first pair
//! (mean actions) until the cycle switch hands off; only then does the environment join the
//! batch, so every step in a chunk is Teacher 2's and Teacher 1's steps are simulation cost
//! ([`Rollout::teacher1_steps`]). A Teacher 1 that falls (or whose episode ends otherwise)
//! leaves no state Teacher 2 could start from in a reset-free episode: that episode is dropped
//! and another drawn. A cycle that times out unplaced still hands off, as at evaluation, where
//! the same switch hands Teacher 2 whatever Teacher 1 left.
//!
//! The student's rollouts (role `student`, [`Behaviour::Dagger`]) play the run's tasks (two
//! objects in the student stage) reset-free through every cycle; every state is labelled by the teachers through a [`Labeller`] (first cycle:
//! Teacher 1, later cycles: Teacher 2), a step executes the teachers' action with probability β
//! and the student's mean action otherwise, and the chunks carry the labels as actions.
//!
//! The VLA student (role `vla`, a policy with a VLA encoder) is the same DAgger rollout with
//! another view: the policy and the chunks see [`VlaView`] rows (egocentric image,
//! proprioception, the current cycle's instruction), while the labeller is asked about the
//! privileged state observation of the very same state.

use lhm_nets::{ActorCritic, SplitMix64};
use lhm_protos::{EpisodeStats, Role, Stage, TrajectoryChunk, WireMessage};
use lhm_scenes::{Benchmark, Catalogue, Task};
use lhm_sim::env::TaskEnv;
use lhm_sim::gait::GaitReference;
use lhm_sim::motion::demo::{AmpWindow, DemoMotion};
use lhm_sim::task::cycles::Handoff;
use lhm_sim::vla::{VlaLayout, VlaView, Vocabulary};
use lhm_sim::CharacterModel;
use std::collections::BTreeMap;
use std::sync::Arc;

use lhm_cluster::RunSpec;
use lhm_protos::EpisodeFrames;
use lhm_record::capture::{EpisodeCapture, EpisodeSource};

#[derive(Debug, thiserror::Error)]
pub enum RolloutError {
    #[error("run spec: {0}")]
    Spec(String),
    #[error(transparent)]
    Net(#[from] lhm_nets::NetError),
    #[error("Teacher 1 completed no first cycle in {0} episodes in a row (it fell or its episode ended each time): train it further before Teacher 2")]
    Teacher1Fails(u32),
    #[error("teacher labels: {0}")]
    Labels(String),
}

/// Teacher actions for a batch of student states: the dagger-server over Zenoh in a cluster, a
/// local teacher in tests.
pub trait Labeller {
    /// One row of `act_dim` actions per row of `observations`, each from the teacher that
    /// supervises its `stages` entry (first cycle: Teacher 1, later cycles: Teacher 2).
    fn label(&mut self, observations: &[f32], stages: &[Stage]) -> Result<Vec<f32>, String>;
}

/// Who acts in a rollout and what its chunks carry: the actor's seam between the stages.
pub enum Behaviour<'a> {
    /// PPO's behaviour policy (the teachers): sampled actions with their log-probabilities and
    /// the critic's values.
    Sampled(&'a ActorCritic),
    /// DAgger (the student): every state is labelled by the teachers and the chunk carries those
    /// labels as its actions (the regression targets; log-probabilities and values are 0). A step
    /// executes the teachers' action with probability `teacher_mix` (DAgger's β), else the
    /// student's mean action.
    Dagger {
        student: &'a ActorCritic,
        labeller: &'a mut dyn Labeller,
        teacher_mix: f32,
    },
}

/// What a VLA policy with this encoder sees (`language: false` blanks the instruction).
pub fn vla_view(encoder: &lhm_nets::VlaEncoderConfig, language: bool) -> VlaView {
    VlaView {
        layout: VlaLayout {
            proprio_dim: encoder.proprio_dim,
            max_tokens: encoder.max_tokens,
            image_size: encoder.image_size,
        },
        vocabulary: Vocabulary {
            words: encoder.vocabulary.clone(),
        },
        language,
    }
}

/// The observation row a policy reads: its VLA view, or the state observation.
pub fn observe(view: Option<&VlaView>, env: &TaskEnv) -> Vec<f32> {
    match view {
        Some(view) => view.observation(env),
        None => env.observation(),
    }
}

/// The row `ac` reads in `env`'s current state: the VLA view for a VLA policy (the instruction
/// blanked unless `language`), else the state observation.
pub fn policy_observation(ac: &ActorCritic, env: &TaskEnv, language: bool) -> Vec<f32> {
    match ac.policy.encoder() {
        Some(e) => vla_view(e.config(), language).observation(env),
        None => env.observation(),
    }
}

/// The supervising teacher's stage of a state: the episode's first cycle or a later one.
pub fn label_stage(env: &TaskEnv) -> Stage {
    if env.cycles.current == 0 {
        Stage::FirstCycle
    } else {
        Stage::NextCycle
    }
}

/// What a batch step executes and what its chunk rows record.
struct Acted {
    /// Actions the environments execute.
    executed: Vec<f32>,
    /// Actions the chunk records (sampled actions, or the teachers' labels).
    recorded: Vec<f32>,
    log_probs: Vec<f32>,
    values: Vec<f32>,
}

/// How Teacher 1's run on the first pair of an episode ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FirstCycleEnd {
    /// The cycle switch handed off to the second pair: the state Teacher 2 starts from.
    HandedOff,
    /// The character fell.
    Fell,
    /// The episode ended otherwise (physics guard, time limit, no second pair).
    Ended,
}

/// Runs `policy` (mean actions) on `env`'s current pair until the cycle switch; returns the
/// control steps taken and how it ended. The environment is left exactly where it stopped.
pub fn run_first_cycle(
    env: &mut TaskEnv,
    policy: &ActorCritic,
) -> Result<(u32, FirstCycleEnd), lhm_nets::NetError> {
    let mut steps = 0u32;
    loop {
        let action = policy.act_deterministic(&env.observation())?;
        let r = env.step(&action);
        steps += 1;
        if r.fell {
            return Ok((steps, FirstCycleEnd::Fell));
        }
        if r.handoff == Handoff::Next {
            return Ok((steps, FirstCycleEnd::HandedOff));
        }
        if r.done || r.truncated || r.physics_invalid {
            return Ok((steps, FirstCycleEnd::Ended));
        }
    }
}

/// Teacher 1 episodes in a row without a handoff before the rollout gives up with an error
/// (instead of spinning on a Teacher 1 that cannot do its cycle).
const TEACHER1_TRIES: u32 = 200;

/// Per-environment chunk buffers.
#[derive(Default)]
struct ChunkBuf {
    observations: Vec<f32>,
    actions: Vec<f32>,
    log_probs: Vec<f32>,
    values: Vec<f32>,
    rewards: Vec<f32>,
    dones: Vec<bool>,
    truncated: Vec<bool>,
    truncation_values: Vec<f32>,
    amp_features: Vec<f32>,
    gait_stopped: Vec<bool>,
    gait_ramping: Vec<bool>,
    episodes: Vec<EpisodeStats>,
    poisoned: bool,
}

struct Slot {
    env: TaskEnv,
    obs: Vec<f32>,
    episode_return: f32,
    episode_len: u32,
    /// Weighted task-reward terms summed over the episode.
    episode_terms: std::collections::BTreeMap<String, f32>,
    buf: ChunkBuf,
}

/// What one call to [`Rollout::step`] finished.
#[derive(Default)]
pub struct StepOutput {
    /// Complete chunks (one per environment whose chunk is full and clean).
    pub chunks: Vec<TrajectoryChunk>,
    /// Chunks thrown away because the physics guard tripped inside them.
    pub poisoned_chunks: u64,
    /// Episodes that ended on this step.
    pub finished: Vec<(usize, EpisodeStats)>,
    /// The poses of a sampled episode that ended on this step (for recording).
    pub episode_frames: Option<EpisodeFrames>,
}

pub struct Rollout {
    pub spec: RunSpec,
    model: CharacterModel,
    catalogue: Catalogue,
    tasks: Vec<Task>,
    slots: Vec<Slot>,
    rng: SplitMix64,
    run_id: String,
    actor_id: String,
    role: Role,
    chunk_seq: u64,
    pub env_steps: u64,
    /// Episodes environment 0 has finished; every `record_every_episodes`-th one is captured.
    env0_episodes: u64,
    capture: Option<EpisodeCapture>,
    policy_version: u64,
    /// Reference motion for demo starts (loaded when the run spec asks for them).
    demo: Option<DemoMotion>,
    /// With `[env.gait]`: the gait's cycle every episode starts in.
    gait: Option<Arc<GaitReference>>,
    /// Teacher 2's rollouts: the frozen Teacher 1 that plays each episode's first pair.
    teacher1: Option<ActorCritic>,
    /// Control steps Teacher 1 took (simulation cost of Teacher 2's starts).
    pub teacher1_steps: u64,
    /// Teacher 1 episodes dropped because they did not hand off.
    pub teacher1_failures: u64,
    /// The VLA student's view (from the run's policy config); `None`: the state observation.
    view: Option<VlaView>,
}

/// Logs the cycle `spec`'s `[env.gait]` walks (nothing without a gait): its clip and the mean
/// size of its `angle_offsets`.
fn log_cycle(actor_id: &str, what: &str, spec: &RunSpec) {
    let Some(gait) = &spec.env.gait else {
        return;
    };
    let values = gait.angle_offsets.values().flatten();
    let (sum, count) = values.fold((0.0f32, 0usize), |(s, n), v| (s + v.abs(), n + 1));
    tracing::info!(
        "actor {actor_id}: {what} the cycle of clip {:?} with angle_offsets on {} DoF \
         (mean |offset| {:.2}°)",
        gait.clip,
        gait.angle_offsets.len(),
        (sum / count.max(1) as f32).to_degrees()
    );
}

/// The cycle `spec`'s `[env.gait]` walks: its clip from `demo` with its `angle_offsets`, at the
/// control step (`None` without a gait). A gait with no reference motion loaded is an error.
fn gait_cycle_of(
    model: &CharacterModel,
    demo: Option<&DemoMotion>,
    spec: &RunSpec,
) -> Result<Option<Arc<GaitReference>>, RolloutError> {
    let Some(config) = &spec.env.gait else {
        return Ok(None);
    };
    let demo = demo.ok_or_else(|| {
        RolloutError::Spec(
            "[env.gait] needs reference motion, and this actor loaded none: the run started \
             without [env.gait] or demo starts (a stage cannot turn the gait on)"
                .into(),
        )
    })?;
    config.check(model).map_err(RolloutError::Spec)?;
    let dt = 1.0 / spec.sim.control_hz;
    lhm_sim::gait::reference_for_gait(model, demo, config, dt)
        .map(|cycle| Some(Arc::new(cycle)))
        .map_err(RolloutError::Spec)
}

/// Whether `new` walks another gait cycle than `old`: a gait on or off, another clip, other
/// `angle_offsets` or another control rate.
fn walks_another_cycle(old: &RunSpec, new: &RunSpec) -> bool {
    cycle_key(old) != cycle_key(new)
}

/// `[env.gait] angle_offsets`: radians per DoF name.
type AngleOffsets = BTreeMap<String, Vec<f32>>;

/// What decides the cycle a spec walks (see [`walks_another_cycle`]), borrowed.
fn cycle_key(spec: &RunSpec) -> Option<(&str, &AngleOffsets, u32)> {
    let g = spec.env.gait.as_ref()?;
    Some((&g.clip, &g.angle_offsets, spec.sim.control_hz.to_bits()))
}

/// Where an episode of a `[env.gait]` run starts ([`draw_gait_start`]).
#[derive(Debug, Clone, Copy, PartialEq)]
enum GaitStartDraw {
    /// Still, at the task's start (`rest_start_fraction`).
    Rest,
    /// Walking, this far (m) before the first object on the way (`start_distance_max`).
    OnWay(f32),
    /// Walking, `start_distance` before the object (`near`) or at the task's start.
    Walking { near: bool },
}

/// Draws an episode's gait start from `rng`: at rest with `rest_start_fraction`, else near the
/// object with `near_start_fraction`, and a near start anywhere on the way, uniform from
/// `start_distance` to the smaller of `start_distance_max` and `way_length()`, when that is
/// longer. A setting that mixes nothing draws nothing, so runs without it keep their random
/// streams.
fn draw_gait_start(
    gait: Option<&lhm_sim::env::GaitConfig>,
    way_length: impl FnOnce() -> f32,
    rng: &mut SplitMix64,
) -> GaitStartDraw {
    let Some(g) = gait else {
        return GaitStartDraw::Walking { near: false };
    };
    if g.rest_start_fraction > 0.0 && (rng.next_f64() as f32) < g.rest_start_fraction {
        return GaitStartDraw::Rest;
    }
    let near = if g.start_distance > 0.0 && g.near_start_fraction < 1.0 {
        (rng.next_f64() as f32) < g.near_start_fraction
    } else {
        g.start_distance > 0.0
    };
    if near && g.start_distance_max > g.start_distance {
        let hi = g.start_distance_max.min(way_length());
        if hi > g.start_distance {
            let d = g.start_distance + (hi - g.start_distance) * rng.next_f64() as f32;
            return GaitStartDraw::OnWay(d);
        }
    }
    GaitStartDraw::Walking { near }
}

impl Rollout {
    pub fn new(
        spec: RunSpec,
        bench: &Benchmark,
        run_id: &str,
        actor_id: &str,
        role: Role,
        num_envs: usize,
        seed: u64,
    ) -> Result<Self, RolloutError> {
        Self::with_teacher1(spec, bench, run_id, actor_id, role, num_envs, seed, None)
    }

    /// A rollout whose episodes start after `teacher1`'s first cycle (role `teacher2`, which
    /// requires it).
    #[allow(clippy::too_many_arguments)]
    pub fn with_teacher1(
        spec: RunSpec,
        bench: &Benchmark,
        run_id: &str,
        actor_id: &str,
        role: Role,
        num_envs: usize,
        seed: u64,
        teacher1: Option<ActorCritic>,
    ) -> Result<Self, RolloutError> {
        let model = CharacterModel::amp_humanoid();
        let mut tasks = spec.tasks.resolve(bench).map_err(RolloutError::Spec)?;
        match (role, &teacher1) {
            (Role::Teacher2, None) => {
                return Err(RolloutError::Spec(
                    "a teacher2 rollout needs Teacher 1's policy for each episode's first pair"
                        .into(),
                ))
            }
            (_, Some(t1)) => {
                if t1.obs_dim() != TaskEnv::obs_dim(&model, &spec.env)
                    || t1.act_dim() != model.dofs.len()
                {
                    return Err(RolloutError::Spec(format!(
                        "Teacher 1 takes {} observations and gives {} actions; this environment has {} and {}",
                        t1.obs_dim(),
                        t1.act_dim(),
                        TaskEnv::obs_dim(&model, &spec.env),
                        model.dofs.len()
                    )));
                }
                tasks.retain(|t| t.sequence.len() >= 2);
                if tasks.is_empty() {
                    return Err(RolloutError::Spec(
                        "Teacher 2 needs tasks of two or more objects; the task set has none"
                            .into(),
                    ));
                }
            }
            _ => {}
        }
        let view = spec
            .actor_critic
            .policy
            .vla
            .as_ref()
            .map(|encoder| vla_view(encoder, true));
        if let Some(view) = &view {
            if view.layout.proprio_dim != lhm_sim::obs::proprioception_dim(&model) {
                return Err(RolloutError::Spec(format!(
                    "the VLA reads {} proprioception values, the character gives {}",
                    view.layout.proprio_dim,
                    lhm_sim::obs::proprioception_dim(&model)
                )));
            }
        }
        let obs_dim = view
            .as_ref()
            .map_or(TaskEnv::obs_dim(&model, &spec.env), |v| v.layout.dim());
        let amp_dim = TaskEnv::amp_dim(&model, &spec.env);
        if obs_dim != spec.obs_dim {
            return Err(RolloutError::Spec(format!(
                "the learner's policy takes {} observations, this actor's environment gives {obs_dim}",
                spec.obs_dim
            )));
        }
        if spec.amp_dim != 0 && spec.amp_dim != amp_dim {
            return Err(RolloutError::Spec(format!(
                "the learner expects {} AMP features, this actor's environment gives {amp_dim}",
                spec.amp_dim
            )));
        }
        if spec.act_dim != model.dofs.len() {
            return Err(RolloutError::Spec(format!(
                "the learner's policy gives {} actions, the character has {} DoF",
                spec.act_dim,
                model.dofs.len()
            )));
        }
        if spec.chunk_steps == 0 {
            return Err(RolloutError::Spec("chunk_steps must be > 0".into()));
        }
        let demo = if spec.env.demo_start_probability > 0.0 || spec.env.gait.is_some() {
            let dir = lhm_sim::motion::default_dir();
            let demo = DemoMotion::load_dir(&model, &dir, AmpWindow::of(&spec.env, &spec.sim))
                .map_err(|e| {
                    RolloutError::Spec(format!(
                        "the run starts {:.0}% of episodes from reference motion{}: {e}",
                        100.0 * spec.env.demo_start_probability,
                        if spec.env.gait.is_some() {
                            " and runs [env.gait]"
                        } else {
                            ""
                        }
                    ))
                })?;
            Some(demo)
        } else {
            None
        };
        let gait = gait_cycle_of(&model, demo.as_ref(), &spec)?;
        // Also at the start, not only on a stage's change: a run resumed inside a curriculum's
        // stage says in its log (`lhm train`: the run's actor-N.log) which cycle it walks.
        log_cycle(actor_id, "episodes walk", &spec);
        let mut rollout = Self {
            model,
            catalogue: bench.catalogue.clone(),
            tasks,
            slots: Vec::new(),
            rng: SplitMix64::new(seed),
            run_id: run_id.to_owned(),
            actor_id: actor_id.to_owned(),
            role,
            chunk_seq: 0,
            env_steps: 0,
            env0_episodes: 0,
            capture: None,
            policy_version: 0,
            demo,
            gait,
            spec,
            teacher1,
            teacher1_steps: 0,
            teacher1_failures: 0,
            view,
        };
        for _ in 0..num_envs.max(1) {
            let env = rollout.fresh_env()?;
            let obs = observe(rollout.view.as_ref(), &env);
            rollout.slots.push(Slot {
                env,
                obs,
                episode_return: 0.0,
                episode_len: 0,
                episode_terms: Default::default(),
                buf: ChunkBuf::default(),
            });
        }
        rollout.maybe_start_capture();
        Ok(rollout)
    }

    /// Starts capturing environment 0's new episode if it is one of the sampled ones.
    fn maybe_start_capture(&mut self) {
        let every = u64::from(self.spec.record_every_episodes);
        self.capture = (every > 0 && self.env0_episodes % every == 0).then(|| {
            EpisodeCapture::new(
                &self.slots[0].env,
                EpisodeSource {
                    run_id: self.run_id.clone(),
                    actor_id: self.actor_id.clone(),
                    role: self.role,
                    policy_version: self.policy_version,
                },
            )
        });
    }

    pub fn num_envs(&self) -> usize {
        self.slots.len()
    }

    /// The next episode's environment: after Teacher 1's first cycle for Teacher 2, else
    /// [`Self::fresh_start`].
    fn fresh_env(&mut self) -> Result<TaskEnv, RolloutError> {
        let Some(teacher1) = self.teacher1.take() else {
            return Ok(self.fresh_start());
        };
        let env = self.after_teacher1(&teacher1);
        self.teacher1 = Some(teacher1);
        env
    }

    /// A task from its start pose, played by `teacher1` up to the handoff to its second pair
    /// (no demo starts: Teacher 2's starts are Teacher 1's terminal states).
    fn after_teacher1(&mut self, teacher1: &ActorCritic) -> Result<TaskEnv, RolloutError> {
        for _ in 0..TEACHER1_TRIES {
            let task = &self.tasks[self.rng.below(self.tasks.len())];
            let mut env = TaskEnv::new(
                &self.model,
                task,
                &self.catalogue,
                self.sim_now(),
                self.spec.env.clone(),
            );
            let (steps, end) = run_first_cycle(&mut env, teacher1)?;
            self.teacher1_steps += u64::from(steps);
            if end == FirstCycleEnd::HandedOff {
                // "Reached" is Teacher 2's statistic: its object, not Teacher 1's.
                env.reached = false;
                return Ok(env);
            }
            self.teacher1_failures += 1;
        }
        Err(RolloutError::Teacher1Fails(TEACHER1_TRIES))
    }

    /// The run's simulation settings with the upright assist at the current policy version's
    /// strength (new environments start under the same assist as the running ones).
    fn sim_now(&self) -> lhm_sim::SimConfig {
        let mut sim = self.spec.sim.clone();
        sim.assist = sim.assist.at_iteration(self.policy_version);
        sim
    }

    /// An environment on a task drawn uniformly from the task set, started from a reference
    /// motion frame with the run's demo-start probability.
    fn fresh_start(&mut self) -> TaskEnv {
        let task = &self.tasks[self.rng.below(self.tasks.len())];
        let mut env = TaskEnv::new(
            &self.model,
            task,
            &self.catalogue,
            self.sim_now(),
            self.spec.env.clone(),
        );
        if let (Some(demo), Some(gait)) = (&self.demo, &self.gait) {
            // In the gait: a random step of its cycle, turned toward the first object.
            let rng = &mut self.rng;
            let step = rng.below(gait.len());
            let noise = (2.0 * rng.next_f64() as f32 - 1.0) * self.spec.env.demo_start_yaw_noise;
            let yaw = env.yaw_toward_way() + noise;
            // A run's `[[stages]]` reach these settings through the spec of each version.
            let mix = self.spec.env.gait.as_ref();
            match draw_gait_start(mix, || env.way_length(), rng) {
                GaitStartDraw::Rest => {
                    env.start_at_rest_in_gait(Arc::clone(gait), step, yaw);
                }
                GaitStartDraw::OnWay(d) => {
                    env.start_in_gait_on_way(demo, Arc::clone(gait), step, noise, d);
                }
                GaitStartDraw::Walking { near } => {
                    env.start_in_gait_where(demo, Arc::clone(gait), step, yaw, near);
                }
            }
        } else if let Some(demo) = &self.demo {
            let rng = &mut self.rng;
            if (rng.next_f64() as f32) < self.spec.env.demo_start_probability {
                if let Some((clip, t)) = demo.sample_start(&mut || rng.next_f64()) {
                    let cfg = &self.spec.env;
                    if (rng.next_f64() as f32) < cfg.demo_start_toward_object {
                        let noise = (2.0 * rng.next_f64() as f32 - 1.0) * cfg.demo_start_yaw_noise;
                        let yaw = env.yaw_toward_first_object() + noise;
                        env.start_from_demo_heading(demo, clip, t, yaw);
                    } else {
                        env.start_from_demo(demo, clip, t);
                    }
                }
            }
        }
        env
    }

    /// The environment `i` (e.g. to capture its poses for recording).
    pub fn env(&self, i: usize) -> &TaskEnv {
        &self.slots[i].env
    }

    /// Whether the next step starts new chunks (the moment to swap weights).
    pub fn at_chunk_boundary(&self) -> bool {
        self.slots.iter().all(|s| s.buf.rewards.is_empty())
    }

    /// Replaces the run spec (new weights from a learner with other settings take effect at the
    /// next chunk boundary; environments already running keep going). A spec whose `[env.gait]`
    /// walks another cycle (a `[[stages]]` entry changing its clip or `angle_offsets`, e.g. a
    /// curriculum on the offsets) has it built here, so the episodes started after this walk it;
    /// an error (an unknown DoF, a clip not installed) leaves the old spec in place.
    pub fn set_spec(&mut self, spec: RunSpec) -> Result<(), RolloutError> {
        if walks_another_cycle(&self.spec, &spec) {
            self.gait = gait_cycle_of(&self.model, self.demo.as_ref(), &spec)?;
            log_cycle(&self.actor_id, "new episodes walk", &spec);
        }
        self.spec = spec;
        Ok(())
    }

    /// The gait cycle the episodes started from now on walk (`None`: the run has no `[env.gait]`).
    pub fn gait_cycle(&self) -> Option<&GaitReference> {
        self.gait.as_deref()
    }

    /// One control step of every environment with PPO's sampled actions of `ac` (policy version
    /// `version`).
    pub fn step(&mut self, ac: &ActorCritic, version: u64) -> Result<StepOutput, RolloutError> {
        self.step_with(Behaviour::Sampled(ac), version)
    }

    /// The actions of one batch step under `behaviour`.
    fn act(&mut self, behaviour: &mut Behaviour<'_>, obs: &[f32]) -> Result<Acted, RolloutError> {
        match behaviour {
            Behaviour::Sampled(ac) => {
                let act = ac.act(obs, &mut self.rng)?;
                Ok(Acted {
                    executed: act.actions.clone(),
                    recorded: act.actions,
                    log_probs: act.log_probs,
                    values: act.values,
                })
            }
            Behaviour::Dagger {
                student,
                labeller,
                teacher_mix,
            } => {
                let n = self.slots.len();
                let act_dim = self.spec.act_dim;
                let stages: Vec<Stage> = self.slots.iter().map(|s| label_stage(&s.env)).collect();
                // The labeller reads the privileged state even when the policy sees images.
                let privileged: Vec<f32>;
                let label_obs = if self.view.is_some() {
                    privileged = self
                        .slots
                        .iter()
                        .flat_map(|s| s.env.observation())
                        .collect();
                    &privileged
                } else {
                    obs
                };
                let labels = labeller
                    .label(label_obs, &stages)
                    .map_err(RolloutError::Labels)?;
                if labels.len() != n * act_dim {
                    return Err(RolloutError::Labels(format!(
                        "{} label values for {n} states of {act_dim} actions",
                        labels.len()
                    )));
                }
                // β = 1 (DAgger's first round): the teachers act alone, no student pass needed.
                let mut executed = if *teacher_mix >= 1.0 {
                    labels.clone()
                } else {
                    student.act_deterministic(obs)?
                };
                for i in 0..n {
                    if (self.rng.next_f64() as f32) < *teacher_mix {
                        executed[i * act_dim..(i + 1) * act_dim]
                            .copy_from_slice(&labels[i * act_dim..(i + 1) * act_dim]);
                    }
                }
                Ok(Acted {
                    executed,
                    recorded: labels,
                    log_probs: vec![0.0; n],
                    values: vec![0.0; n],
                })
            }
        }
    }

    /// One control step of every environment under `behaviour` (policy version `version`).
    pub fn step_with(
        &mut self,
        mut behaviour: Behaviour<'_>,
        version: u64,
    ) -> Result<StepOutput, RolloutError> {
        if version != self.policy_version && self.spec.sim.assist.is_active() {
            // The training aid's curriculum follows the policy version the actors act with.
            let assist = self.spec.sim.assist.at_iteration(version);
            for slot in &mut self.slots {
                slot.env.world.config.assist = assist.clone();
            }
        }
        self.policy_version = version;
        let obs: Vec<f32> = self.slots.iter().flat_map(|s| s.obs.clone()).collect();
        let act = self.act(&mut behaviour, &obs)?;
        let act_dim = self.spec.act_dim;
        let mut out = StepOutput::default();
        // Environments whose episode ended by time limit need V(final observation).
        let mut truncated_obs: Vec<(usize, Vec<f32>)> = Vec::new();
        for i in 0..self.slots.len() {
            let action = &act.executed[i * act_dim..(i + 1) * act_dim];
            let slot = &mut self.slots[i];
            let result = slot.env.step(action);
            self.env_steps += 1;
            slot.episode_len += 1;
            slot.episode_return += result.reward;
            for (name, v) in result.terms.weighted(&result.weights) {
                *slot.episode_terms.entry(name.to_owned()).or_insert(0.0) += v;
            }
            let buf = &mut slot.buf;
            buf.observations.extend_from_slice(&slot.obs);
            buf.actions
                .extend_from_slice(&act.recorded[i * act_dim..(i + 1) * act_dim]);
            buf.log_probs.push(act.log_probs[i]);
            buf.values.push(act.values[i]);
            buf.rewards.push(result.reward);
            // A skill's part of the episode that ends (the Hierarchical RL baseline) is terminal
            // for its return even where the episode's time runs out on the same step.
            let skill_terminal = result.skill_ended && !result.physics_invalid;
            buf.dones
                .push((result.done || skill_terminal) && !result.physics_invalid);
            buf.truncated
                .push((result.truncated && !skill_terminal) || result.physics_invalid);
            buf.truncation_values.push(0.0);
            if self.spec.amp_dim > 0 {
                let features = slot.env.amp_features();
                buf.amp_features.extend_from_slice(&features);
            }
            buf.gait_stopped.push(slot.env.gait_stopped());
            buf.gait_ramping.push(slot.env.gait_ramping());
            if result.physics_invalid {
                buf.poisoned = true;
            }
            if i == 0 {
                if let Some(capture) = self.capture.as_mut() {
                    capture.push(&slot.env);
                }
            }
            let ended = result.done || result.truncated || result.physics_invalid;
            if ended {
                let cycles = &slot.env.cycles;
                let errors = slot.env.placement_errors();
                let stats = EpisodeStats {
                    episode_return: slot.episode_return,
                    length: slot.episode_len,
                    cycles_attempted: errors.len() as u32,
                    cycles_succeeded: cycles.results.iter().filter(|r| r.success).count() as u32,
                    final_placement_error_m: errors,
                    fell: result.fell,
                    physics_invalid: result.physics_invalid,
                    task_id: slot.env.task.id.clone(),
                    reached: slot.env.reached,
                    demo_start: slot.env.demo_start,
                    reward_terms: std::mem::take(&mut slot.episode_terms),
                };
                if result.truncated && !result.physics_invalid && !skill_terminal {
                    truncated_obs.push((i, observe(self.view.as_ref(), &slot.env)));
                }
                slot.buf.episodes.push(stats.clone());
                if i == 0 {
                    if let Some(capture) = self.capture.take() {
                        if !result.physics_invalid {
                            out.episode_frames = Some(capture.finish(stats.clone()));
                        }
                    }
                }
                out.finished.push((i, stats));
            } else {
                slot.obs = observe(self.view.as_ref(), &slot.env);
            }
        }
        let critic = match &behaviour {
            Behaviour::Sampled(ac) => Some(*ac),
            // A regression target needs no value.
            Behaviour::Dagger { .. } => None,
        };
        if let (false, Some(ac)) = (truncated_obs.is_empty(), critic) {
            let rows: Vec<f32> = truncated_obs.iter().flat_map(|(_, o)| o.clone()).collect();
            let values = ac.values(&rows)?;
            for ((i, _), v) in truncated_obs.iter().zip(values) {
                if let Some(last) = self.slots[*i].buf.truncation_values.last_mut() {
                    *last = v;
                }
            }
        }
        // New episodes for the environments that ended.
        let ended: Vec<usize> = out.finished.iter().map(|(i, _)| *i).collect();
        for i in ended {
            let env = self.fresh_env()?;
            let slot = &mut self.slots[i];
            slot.obs = observe(self.view.as_ref(), &env);
            slot.env = env;
            slot.episode_return = 0.0;
            slot.episode_len = 0;
            if i == 0 {
                self.env0_episodes += 1;
                self.maybe_start_capture();
            }
        }
        if self.slots[0].buf.rewards.len() >= self.spec.chunk_steps as usize {
            self.emit_chunks(critic, version, &mut out)?;
        }
        Ok(out)
    }

    /// Cuts every environment's chunk; `critic` gives the bootstrap values (none: 0).
    fn emit_chunks(
        &mut self,
        critic: Option<&ActorCritic>,
        version: u64,
        out: &mut StepOutput,
    ) -> Result<(), RolloutError> {
        let bootstrap = match critic {
            Some(ac) => {
                let obs: Vec<f32> = self.slots.iter().flat_map(|s| s.obs.clone()).collect();
                ac.values(&obs)?
            }
            None => vec![0.0; self.slots.len()],
        };
        for (i, slot) in self.slots.iter_mut().enumerate() {
            let buf = std::mem::take(&mut slot.buf);
            self.chunk_seq += 1;
            if buf.poisoned {
                out.poisoned_chunks += 1;
                continue;
            }
            let num_steps = buf.rewards.len() as u32;
            out.chunks.push(TrajectoryChunk {
                run_id: self.run_id.clone(),
                actor_id: self.actor_id.clone(),
                role: self.role as i32,
                policy_version: version,
                chunk_seq: self.chunk_seq,
                env_index: i as u32,
                num_steps,
                obs_dim: self.spec.obs_dim as u32,
                act_dim: self.spec.act_dim as u32,
                amp_dim: self.spec.amp_dim as u32,
                observations: buf.observations,
                actions: buf.actions,
                log_probs: buf.log_probs,
                values: buf.values,
                rewards: buf.rewards,
                dones: buf.dones,
                truncated: buf.truncated,
                truncation_values: buf.truncation_values,
                amp_features: buf.amp_features,
                // Sent only where it says something: most chunks have no stopped step.
                gait_stopped: if buf.gait_stopped.contains(&true) {
                    buf.gait_stopped
                } else {
                    Vec::new()
                },
                gait_ramping: if buf.gait_ramping.contains(&true) {
                    buf.gait_ramping
                } else {
                    Vec::new()
                },
                bootstrap_value: bootstrap[i],
                episodes: buf.episodes,
                ..TrajectoryChunk::versioned()
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lhm_sim::env::GaitConfig;

    fn gait(rest: f32, near: f32, max: f32) -> GaitConfig {
        GaitConfig {
            start_distance: 1.2,
            rest_start_fraction: rest,
            near_start_fraction: near,
            start_distance_max: max,
            ..GaitConfig::default()
        }
    }

    #[test]
    fn gait_starts_mix_rest_and_walks_anywhere_on_the_way_up_to_its_length() {
        let g = gait(0.5, 1.0, 5.0);
        let mut rng = SplitMix64::new(11);
        let draws: Vec<GaitStartDraw> = (0..4000)
            .map(|_| draw_gait_start(Some(&g), || 3.0, &mut rng))
            .collect();
        let rest = draws.iter().filter(|d| **d == GaitStartDraw::Rest).count();
        let on_way: Vec<f32> = draws
            .iter()
            .filter_map(|d| match d {
                GaitStartDraw::OnWay(x) => Some(*x),
                _ => None,
            })
            .collect();
        assert_eq!(
            rest + on_way.len(),
            draws.len(),
            "only rest and on-way starts"
        );
        assert!((1850..2150).contains(&rest), "{rest} of 4000 at rest");
        // Uniform from start_distance (1.2) to the way's length (3.0 < start_distance_max).
        assert!(on_way.iter().all(|d| (1.2..=3.0).contains(d)), "{on_way:?}");
        let mean = on_way.iter().sum::<f32>() / on_way.len() as f32;
        assert!((mean - 2.1).abs() < 0.05, "mean distance {mean}");
        let far = on_way.iter().filter(|d| **d > 2.7).count() as f32 / on_way.len() as f32;
        assert!((far - 1.0 / 6.0).abs() < 0.03, "share beyond 2.7 m {far}");
    }

    #[test]
    fn a_way_no_longer_than_start_distance_starts_near_and_the_cap_bounds_long_ways() {
        let mut rng = SplitMix64::new(3);
        let g = gait(0.0, 1.0, 5.0);
        assert_eq!(
            draw_gait_start(Some(&g), || 1.0, &mut rng),
            GaitStartDraw::Walking { near: true }
        );
        for _ in 0..200 {
            match draw_gait_start(Some(&g), || 9.0, &mut rng) {
                GaitStartDraw::OnWay(d) => assert!((1.2..=5.0).contains(&d), "{d}"),
                other => panic!("{other:?}"),
            }
        }
        // near_start_fraction 0: every walking start at the task's start.
        let g = gait(0.0, 0.0, 5.0);
        assert_eq!(
            draw_gait_start(Some(&g), || 9.0, &mut rng),
            GaitStartDraw::Walking { near: false }
        );
    }

    #[test]
    fn a_run_that_mixes_no_starts_draws_nothing_from_the_stream() {
        // start_distance alone (the near starts of earlier runs): always near, no draw, and the
        // way's length is not even asked for.
        let mut rng = SplitMix64::new(5);
        let before = rng.state();
        let g = gait(0.0, 1.0, 0.0);
        let draw = draw_gait_start(Some(&g), || panic!("way length asked"), &mut rng);
        assert_eq!(draw, GaitStartDraw::Walking { near: true });
        let none = draw_gait_start(None, || panic!("way length asked"), &mut rng);
        assert_eq!(none, GaitStartDraw::Walking { near: false });
        assert_eq!(rng.state(), before);
    }
}
