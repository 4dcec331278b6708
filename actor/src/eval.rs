//! Evaluation: a policy's deterministic actions on benchmark tasks, scored with the paper's
//! metrics (Sec. 4.1) per cycle: Success k (the k-th object's root within 0.2 m of its goal when
//! its cycle ends), Dist k (its placement error then, m), Success All (every cycle of the episode
//! succeeded), and falls. Episodes run in lockstep batches: one batched forward pass per control
//! step, the environments stepped in parallel on every core.

use lhm_nets::{ActorCritic, NetError, SplitMix64};
use lhm_scenes::{Catalogue, Task};
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::{CharacterModel, SimConfig};
use rayon::prelude::*;
use serde::Serialize;

/// Seeds ≥ 1 turn the character's start heading by a uniform angle within ± this (radians), so
/// seeds differ while the physics and the actions stay deterministic; seed 0 is every task
/// exactly as specified.
pub const START_YAW_JITTER: f64 = 0.2;

/// Control steps an episode may run after its pairs' cycle time limits (the last handoff needs a
/// step to register).
const EPISODE_SLACK_STEPS: u32 = 30;

/// One (task, seed) episode's outcome.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EpisodeEval {
    pub task_id: String,
    pub seed: u64,
    /// Per pair, in order: placed within the success radius when its cycle ended (a cycle that
    /// never ended, after a fall or at the time limit, failed).
    pub success: Vec<bool>,
    /// Per pair: placement error (m) when its cycle ended, or at the episode's end for a pair
    /// whose cycle did not end.
    pub dist: Vec<f32>,
    pub fell: bool,
    /// The physics guard tripped: the episode was cut and counts as failed.
    pub physics_invalid: bool,
    pub steps: u32,
    /// The control step at which the root first came within the reach distance of its current
    /// object (horizontally; `[env] reach_distance`); `None` if it never did.
    pub reach_step: Option<u32>,
}

impl EpisodeEval {
    pub fn success_all(&self) -> bool {
        self.success.iter().all(|&s| s)
    }
}

/// The random stream of seed `seed` on task `task_id`: the task id keeps seeds independent
/// across tasks.
fn seed_stream(task_id: &str, seed: u64) -> SplitMix64 {
    let id_hash = task_id.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    });
    SplitMix64::new(seed ^ id_hash)
}

/// `task` as seed `seed` runs it (see [`START_YAW_JITTER`]).
pub fn seeded_task(task: &Task, seed: u64) -> Task {
    let mut t = task.clone();
    if seed > 0 {
        let mut rng = seed_stream(&task.id, seed);
        t.start.yaw += START_YAW_JITTER * (2.0 * rng.next_f64() - 1.0);
    }
    t
}

/// The step of a `cycle_len`-step gait cycle that seed `seed` of task `task_id` starts in: the
/// first for seed 0 (the task as specified), a uniform draw for later seeds, so that several
/// seeds see the walk from several phases as the actors' starts do.
pub fn gait_start_step(task_id: &str, seed: u64, cycle_len: usize) -> usize {
    if seed == 0 || cycle_len == 0 {
        return 0;
    }
    let mut rng = seed_stream(task_id, seed);
    rng.next_f64(); // the start-yaw draw of `seeded_task`
    rng.below(cycle_len)
}

/// The random stream of the action noise of the `(task, seed)` episode: apart from the stream
/// that turns its start ([`seeded_task`], [`gait_start_step`]).
fn action_noise_stream(task_id: &str, seed: u64) -> SplitMix64 {
    const SALT: u64 = 0x6163_7469_6f6e_5f73; // "action_s"
    SplitMix64::new(seed_stream(task_id, seed).next_u64() ^ SALT)
}

struct Slot {
    env: TaskEnv,
    seed: u64,
    action: Vec<f32>,
    noise: SplitMix64,
    reach_step: Option<u32>,
    result: Option<EpisodeEval>,
}

impl Slot {
    fn finish(&mut self, fell: bool, physics_invalid: bool, steps: u32) {
        let pairs = self.env.task.sequence.len();
        let mut success: Vec<bool> = self.env.cycles.results.iter().map(|r| r.success).collect();
        success.resize(pairs, false);
        if physics_invalid {
            success.fill(false);
        }
        self.result = Some(EpisodeEval {
            task_id: self.env.task.id.clone(),
            seed: self.seed,
            success,
            dist: self.env.pair_errors(),
            fell,
            physics_invalid,
            steps,
            reach_step: self.reach_step,
        });
    }
}

/// Where and how episodes run: the character, the objects, the simulator and environment
/// settings (the run's), and how many environments step in lockstep.
pub struct EvalSetup<'a> {
    pub model: &'a CharacterModel,
    pub catalogue: &'a Catalogue,
    pub sim: &'a SimConfig,
    pub env: &'a EnvConfig,
    pub batch: usize,
    /// A VLA policy hears each cycle's instruction; `false` blanks it (the no-language
    /// ablation). State-based policies ignore it.
    pub language: bool,
    /// With `[env.gait]`: the clips and the gait cycle every episode starts in, turned toward
    /// the first object as the run's actors start theirs: seed 0 at the cycle's first step,
    /// later seeds at a step drawn from the seed ([`gait_start_step`]). `None` without a gait.
    pub gait: Option<GaitStart<'a>>,
    /// Ends every episode after at most this many control steps (e.g. 300, 10 s at 30 Hz, to
    /// measure how long a walk stays up); `None`: every pair's cycle time limit.
    pub max_steps: Option<u32>,
    /// Gaussian noise of this standard deviation added to every action component, as the
    /// actors' sampled actions carry the policy's `exp(log_std)` in training; 0: the mean
    /// actions. Each episode draws from its own stream of (task, seed) ([`action_noise_stream`]),
    /// so results do not depend on `batch` or the job order.
    pub action_std: f32,
}

/// What an episode in `[env.gait]` starts from.
#[derive(Clone)]
pub struct GaitStart<'a> {
    pub demo: &'a lhm_sim::motion::demo::DemoMotion,
    pub reference: std::sync::Arc<lhm_sim::gait::GaitReference>,
    /// Every episode starts at rest at the task's start ([`TaskEnv::start_at_rest_in_gait`],
    /// `[env.gait] rest_start_fraction`'s start) instead of walking.
    pub rest: bool,
}

impl EvalSetup<'_> {
    /// The environment of the `(task, seed)` episode, exactly as [`evaluate`] runs it: the
    /// seeded start, no demo start (in the gait with `[env.gait]`), and a time limit of every
    /// pair's cycle limit.
    pub fn env_for(&self, task: &Task, seed: u64) -> TaskEnv {
        let task = seeded_task(task, seed);
        let pairs = task.sequence.len() as u32;
        let cycles_limit = pairs * self.env.switching.max_cycle_steps + EPISODE_SLACK_STEPS;
        let config = EnvConfig {
            max_episode_steps: self.max_steps.map_or(cycles_limit, |m| m.min(cycles_limit)),
            demo_start_probability: 0.0,
            gait: self
                .env
                .gait
                .clone()
                .map(lhm_sim::env::GaitConfig::played_to_the_limit),
            ..self.env.clone()
        };
        let mut env = TaskEnv::new(self.model, &task, self.catalogue, self.sim.clone(), config);
        if let Some(g) = &self.gait {
            let yaw = env.yaw_toward_way();
            let step = gait_start_step(&task.id, seed, g.reference.len());
            env.start_in_gait_from(
                g.demo,
                std::sync::Arc::clone(&g.reference),
                step,
                yaw,
                g.rest,
            );
        }
        env
    }
}

/// Which policy acts: one policy throughout (a teacher on its own pairs, the student), or the
/// paper's "T" rows: Teacher 1 on each episode's first cycle and Teacher 2 on every later one,
/// switched by the environment's cycle tracker (the same finite-state machine the
/// dagger-server's labels follow), with no reset between them.
#[derive(Clone, Copy)]
pub enum EvalPolicy<'a> {
    One(&'a ActorCritic),
    Teachers {
        first: &'a ActorCritic,
        later: &'a ActorCritic,
    },
    /// In a `[env.gait]` run: `walk` until the gait's base stops at `stop_distance`, `stop`
    /// from then on (two policies trained apart, joined where the environment switches the base
    /// from the walk to the stand: what one policy learning both would at best do).
    Joined {
        walk: &'a ActorCritic,
        stop: &'a ActorCritic,
    },
}

impl<'a> EvalPolicy<'a> {
    /// The policies, in the order [`Self::index_for_cycle`] indexes them.
    fn policies(&self) -> Vec<&'a ActorCritic> {
        match *self {
            EvalPolicy::One(ac) => vec![ac],
            EvalPolicy::Teachers { first, later } => vec![first, later],
            EvalPolicy::Joined { walk, stop } => vec![walk, stop],
        }
    }

    /// Which of [`Self::policies`] acts in `env` now.
    pub fn index_for(&self, env: &TaskEnv) -> usize {
        match self {
            EvalPolicy::Joined { .. } => usize::from(env.gait_stopped()),
            _ => self.index_for_cycle(env.cycles.current),
        }
    }

    /// Which of [`Self::policies`] acts during cycle `cycle` (0-based).
    pub fn index_for_cycle(&self, cycle: usize) -> usize {
        match self {
            EvalPolicy::One(_) => 0,
            EvalPolicy::Teachers { .. } => usize::from(cycle > 0),
            EvalPolicy::Joined { .. } => 0,
        }
    }
}

impl<'a> From<&'a ActorCritic> for EvalPolicy<'a> {
    fn from(ac: &'a ActorCritic) -> Self {
        EvalPolicy::One(ac)
    }
}

/// Runs every `(task, seed)` job with the policy's mean actions, `setup.batch` environments at a
/// time; `progress` is called with the number of episodes finished so far. Results keep the
/// jobs' order. Each episode may run every pair's cycle time limit
/// (`env.switching.max_cycle_steps`).
pub fn evaluate<'a>(
    policy: impl Into<EvalPolicy<'a>>,
    setup: &EvalSetup,
    jobs: &[(Task, u64)],
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Vec<EpisodeEval>, NetError> {
    let policy = policy.into();
    let policies = policy.policies();
    let batch = setup.batch;
    let act_dim = policies[0].act_dim();
    let obs_dim = policies[0].obs_dim();
    if let Some(other) = policies
        .iter()
        .find(|p| p.act_dim() != act_dim || p.obs_dim() != obs_dim)
    {
        return Err(NetError::Config(format!(
            "the policies' shapes differ (teachers, or walk and stop): {obs_dim} observations -> {act_dim} actions and {} -> {}",
            other.obs_dim(),
            other.act_dim()
        )));
    }
    // What each policy sees: a VLA its image-and-instruction rows, the others the state.
    let views: Vec<Option<lhm_sim::vla::VlaView>> = policies
        .iter()
        .map(|ac| {
            ac.policy
                .encoder()
                .map(|e| crate::rollout::vla_view(e.config(), setup.language))
        })
        .collect();
    let mut out = Vec::with_capacity(jobs.len());
    for chunk in jobs.chunks(batch.max(1)) {
        let mut slots: Vec<Slot> = chunk
            .par_iter()
            .map(|(task, seed)| Slot {
                env: setup.env_for(task, *seed),
                seed: *seed,
                action: vec![0.0; act_dim],
                noise: action_noise_stream(&task.id, *seed),
                reach_step: None,
                result: None,
            })
            .collect();
        loop {
            let active: Vec<usize> = (0..slots.len())
                .filter(|&i| slots[i].result.is_none())
                .collect();
            if active.is_empty() {
                break;
            }
            // One batched forward pass per policy, over the environments it acts in now.
            for (p, ac) in policies.iter().enumerate() {
                let acting: Vec<usize> = active
                    .iter()
                    .copied()
                    .filter(|&i| policy.index_for(&slots[i].env) == p)
                    .collect();
                if acting.is_empty() {
                    continue;
                }
                let view = views[p].as_ref();
                let obs: Vec<f32> = acting
                    .par_iter()
                    .map(|&i| crate::rollout::observe(view, &slots[i].env))
                    .collect::<Vec<_>>()
                    .concat();
                let actions = ac.act_deterministic(&obs)?;
                for (row, &i) in actions.chunks_exact(act_dim).zip(&acting) {
                    let slot = &mut slots[i];
                    slot.action.copy_from_slice(row);
                    if setup.action_std > 0.0 {
                        add_noise(&mut slot.action, &mut slot.noise, setup.action_std);
                    }
                }
            }
            slots
                .par_iter_mut()
                .filter(|s| s.result.is_none())
                .for_each(|s| {
                    let action = std::mem::take(&mut s.action);
                    let r = s.env.step(&action);
                    s.action = action;
                    if s.env.reached && s.reach_step.is_none() {
                        s.reach_step = Some(s.env.steps());
                    }
                    if r.done || r.truncated || r.physics_invalid {
                        let steps = s.env.steps();
                        s.finish(r.fell, r.physics_invalid, steps);
                    }
                });
        }
        out.extend(slots.into_iter().filter_map(|s| s.result));
        progress(out.len());
    }
    Ok(out)
}

/// Adds `std` times standard normal draws from `rng` to every component of `action`.
fn add_noise(action: &mut [f32], rng: &mut SplitMix64, std: f32) {
    let mut draws = vec![0.0f32; action.len()];
    rng.fill_normal(&mut draws);
    for (a, n) in action.iter_mut().zip(draws) {
        *a += std * n;
    }
}

/// Mean and sample standard deviation over seeds (std 0 with one seed).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MeanStd {
    pub mean: f64,
    pub std: f64,
}

impl MeanStd {
    fn of(xs: &[f64]) -> Self {
        let n = xs.len() as f64;
        if xs.is_empty() {
            return Self {
                mean: f64::NAN,
                std: f64::NAN,
            };
        }
        let mean = xs.iter().sum::<f64>() / n;
        let std = if xs.len() > 1 {
            (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
        } else {
            0.0
        };
        Self { mean, std }
    }
}

/// The paper's table row for one policy on one split: per cycle k (1-based index k-1), the
/// fraction of episodes with at least k pairs whose k-th cycle succeeded and their mean Dist k;
/// Success All; the fall rate. Each is computed per seed, then mean ± std over seeds.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EvalTable {
    pub episodes: usize,
    pub seeds: Vec<u64>,
    pub success: Vec<MeanStd>,
    pub dist: Vec<MeanStd>,
    pub success_all: MeanStd,
    pub fall_rate: MeanStd,
    /// Control steps an episode ran (to its fall, its end, or the step cap): how long the
    /// character stayed up.
    pub steps: MeanStd,
    /// Fraction of episodes whose root came within the reach distance of its object.
    pub reach_rate: MeanStd,
}

pub fn summarize(episodes: &[EpisodeEval]) -> EvalTable {
    let mut seeds: Vec<u64> = episodes.iter().map(|e| e.seed).collect();
    seeds.sort_unstable();
    seeds.dedup();
    let max_pairs = episodes.iter().map(|e| e.success.len()).max().unwrap_or(0);
    let per_seed = |f: &dyn Fn(&[&EpisodeEval]) -> Option<f64>| -> MeanStd {
        let values: Vec<f64> = seeds
            .iter()
            .filter_map(|s| {
                let of_seed: Vec<&EpisodeEval> = episodes.iter().filter(|e| e.seed == *s).collect();
                f(&of_seed)
            })
            .collect();
        MeanStd::of(&values)
    };
    let mean = |xs: Vec<f64>| (!xs.is_empty()).then(|| xs.iter().sum::<f64>() / xs.len() as f64);
    let success = (0..max_pairs)
        .map(|k| {
            per_seed(&|es| {
                mean(
                    es.iter()
                        .filter_map(|e| e.success.get(k).map(|&s| f64::from(u8::from(s))))
                        .collect(),
                )
            })
        })
        .collect();
    let dist = (0..max_pairs)
        .map(|k| {
            per_seed(&|es| {
                mean(
                    es.iter()
                        .filter_map(|e| e.dist.get(k).map(|&d| f64::from(d)))
                        .collect(),
                )
            })
        })
        .collect();
    EvalTable {
        episodes: episodes.len(),
        success,
        dist,
        success_all: per_seed(&|es| {
            mean(
                es.iter()
                    .map(|e| f64::from(u8::from(e.success_all())))
                    .collect(),
            )
        }),
        fall_rate: per_seed(&|es| mean(es.iter().map(|e| f64::from(u8::from(e.fell))).collect())),
        steps: per_seed(&|es| mean(es.iter().map(|e| f64::from(e.steps)).collect())),
        reach_rate: per_seed(&|es| {
            mean(
                es.iter()
                    .map(|e| f64::from(u8::from(e.reach_step.is_some())))
                    .collect(),
            )
        }),
        seeds,
    }
}

impl EvalTable {
    /// Flat keys for `--json`: `success_k`, `dist_k` (k from 1), `success_all`, `fall_rate`, as
    /// fractions and metres, `mean_steps` (control steps per episode) and `reach_rate`, means
    /// over seeds, each with a `_std` twin.
    pub fn flat(&self) -> std::collections::BTreeMap<String, f64> {
        let mut out = std::collections::BTreeMap::new();
        let mut put = |key: String, v: MeanStd| {
            out.insert(format!("{key}_std"), v.std);
            out.insert(key, v.mean);
        };
        for (k, v) in self.success.iter().enumerate() {
            put(format!("success_{}", k + 1), *v);
        }
        for (k, v) in self.dist.iter().enumerate() {
            put(format!("dist_{}", k + 1), *v);
        }
        put("success_all".into(), self.success_all);
        put("fall_rate".into(), self.fall_rate);
        put("mean_steps".into(), self.steps);
        put("reach_rate".into(), self.reach_rate);
        out
    }

    /// The table in the paper's layout (success in %, Dist in m), one row named `method`.
    pub fn markdown(&self, method: &str) -> String {
        let k = self.success.len();
        let mut head = vec!["Method".to_string()];
        head.extend((1..=k).map(|i| format!("Success {i} (%)")));
        head.push("Success All (%)".into());
        head.extend((1..=k).map(|i| format!("Dist {i} (m)")));
        head.push("Falls (%)".into());
        let pct = |v: &MeanStd| format!("{:.1} ± {:.1}", 100.0 * v.mean, 100.0 * v.std);
        let m = |v: &MeanStd| format!("{:.3} ± {:.3}", v.mean, v.std);
        let mut row = vec![method.to_string()];
        row.extend(self.success.iter().map(pct));
        row.push(pct(&self.success_all));
        row.extend(self.dist.iter().map(m));
        row.push(pct(&self.fall_rate));
        format!(
            "| {} |\n|{}\n| {} |\n",
            head.join(" | "),
            "---|".repeat(head.len()),
            row.join(" | ")
        )
    }
}

/// One line per episode: `task_id,seed,steps,fell,physics_invalid,reach_step,success_1..K,
/// dist_1..K` (empty fields where a task has fewer pairs or the object was never reached), with a
/// header.
pub fn episodes_csv(episodes: &[EpisodeEval]) -> String {
    let k = episodes.iter().map(|e| e.success.len()).max().unwrap_or(0);
    let mut out = String::from("task_id,seed,steps,fell,physics_invalid,reach_step");
    for i in 1..=k {
        out.push_str(&format!(",success_{i}"));
    }
    for i in 1..=k {
        out.push_str(&format!(",dist_{i}"));
    }
    out.push('\n');
    for e in episodes {
        out.push_str(&format!(
            "{},{},{},{},{},{}",
            e.task_id,
            e.seed,
            e.steps,
            u8::from(e.fell),
            u8::from(e.physics_invalid),
            e.reach_step.map(|k| k.to_string()).unwrap_or_default()
        ));
        for i in 0..k {
            out.push(',');
            if let Some(s) = e.success.get(i) {
                out.push_str(if *s { "1" } else { "0" });
            }
        }
        for i in 0..k {
            out.push(',');
            if let Some(d) = e.dist.get(i) {
                out.push_str(&format!("{d:.4}"));
            }
        }
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// No gait, no step cap, instructions heard: the setup most tests evaluate under.
    fn plain_setup<'a>(
        model: &'a CharacterModel,
        bench: &'a lhm_scenes::Benchmark,
        sim: &'a SimConfig,
        env: &'a EnvConfig,
        batch: usize,
    ) -> EvalSetup<'a> {
        EvalSetup {
            model,
            catalogue: &bench.catalogue,
            sim,
            env,
            batch,
            language: true,
            gait: None,
            max_steps: None,
            action_std: 0.0,
        }
    }

    /// A policy with a small hidden layer and its initial weights, for `env`'s observations.
    fn untrained_policy(model: &CharacterModel, env: &EnvConfig) -> ActorCritic {
        ActorCritic::new(
            TaskEnv::obs_dim(model, env),
            model.dofs.len(),
            &lhm_nets::ActorCriticConfig::with_hidden(&[16]),
        )
        .unwrap()
    }

    /// Seeds 0 and 1 of the first two unseen tasks, in that order.
    fn two_seeds_of_two_unseen_tasks(bench: &lhm_scenes::Benchmark) -> Vec<(Task, u64)> {
        bench.tasks(lhm_scenes::Split::Unseen)[..2]
            .iter()
            .flat_map(|t| [(t.clone(), 0), (t.clone(), 1)])
            .collect()
    }

    fn episode(seed: u64, success: &[bool], dist: &[f32], fell: bool) -> EpisodeEval {
        EpisodeEval {
            task_id: format!("t{seed}"),
            seed,
            success: success.to_vec(),
            dist: dist.to_vec(),
            fell,
            physics_invalid: false,
            steps: 10,
            reach_step: (!fell).then_some(7),
        }
    }

    #[test]
    fn table_is_per_seed_then_mean_and_std_over_seeds() {
        let eps = [
            // Seed 0: cycle 1 succeeds in both tasks, cycle 2 in one.
            episode(0, &[true, true], &[0.1, 0.1], false),
            episode(0, &[true, false], &[0.1, 0.5], true),
            // Seed 1: nothing succeeds.
            episode(1, &[false, false], &[1.0, 2.0], true),
            episode(1, &[false, false], &[1.0, 2.0], true),
        ];
        let t = summarize(&eps);
        assert_eq!(t.seeds, vec![0, 1]);
        assert!((t.success[0].mean - 0.5).abs() < 1e-12);
        assert!((t.success[0].std - (0.5f64).sqrt()).abs() < 1e-12);
        assert!((t.success[1].mean - 0.25).abs() < 1e-12);
        assert!((t.success_all.mean - 0.25).abs() < 1e-12);
        assert!((t.dist[1].mean - (0.3 + 2.0) / 2.0).abs() < 1e-6);
        assert!((t.fall_rate.mean - 0.75).abs() < 1e-12);
        assert_eq!((t.steps.mean, t.steps.std), (10.0, 0.0));
        // Seed 0 reached in one of two episodes, seed 1 in none.
        assert!((t.reach_rate.mean - 0.25).abs() < 1e-12);
        let flat = t.flat();
        for key in [
            "success_1",
            "success_2",
            "success_all",
            "dist_1",
            "dist_2",
            "mean_steps",
            "reach_rate",
        ] {
            assert!(flat.contains_key(key), "{key}");
        }
        let md = t.markdown("T1");
        assert!(
            md.contains("| T1 | 50.0 ± 70.7 | 25.0 ± 35.4 | 25.0 ± 35.4 |"),
            "{md}"
        );
    }

    #[test]
    fn tasks_with_fewer_pairs_do_not_count_towards_later_cycles() {
        let eps = [
            episode(0, &[true], &[0.1], false),
            episode(0, &[true, true, false], &[0.1, 0.1, 0.9], false),
        ];
        let t = summarize(&eps);
        assert_eq!(t.success.len(), 3);
        assert_eq!(t.success[0].mean, 1.0);
        assert_eq!(t.success[2].mean, 0.0);
        assert_eq!(t.success_all.mean, 0.5);
        let csv = episodes_csv(&eps);
        assert!(csv.starts_with(
            "task_id,seed,steps,fell,physics_invalid,reach_step,success_1,success_2,success_3,dist_1"
        ));
        assert!(csv.contains("t0,0,10,0,0,7,1,,,0.1000,,\n"), "{csv}");
    }

    #[test]
    fn an_untrained_policy_is_scored_on_every_pair_deterministically_in_job_order() {
        let bench = lhm_scenes::Benchmark::embedded().unwrap();
        let model = CharacterModel::amp_humanoid();
        let mut env = EnvConfig::default();
        env.switching.max_cycle_steps = 8;
        let sim = SimConfig::default();
        let ac = untrained_policy(&model, &env);
        let jobs = two_seeds_of_two_unseen_tasks(&bench);
        let seen = std::sync::atomic::AtomicUsize::new(0);
        let run = || {
            let setup = plain_setup(&model, &bench, &sim, &env, 3);
            evaluate(&ac, &setup, &jobs, &|n| {
                seen.store(n, std::sync::atomic::Ordering::Relaxed)
            })
            .unwrap()
        };
        let first = run();
        assert_eq!(seen.load(std::sync::atomic::Ordering::Relaxed), jobs.len());
        assert_eq!(first.len(), jobs.len());
        for (e, (task, seed)) in first.iter().zip(&jobs) {
            assert_eq!((&e.task_id, e.seed), (&task.id, *seed));
            assert_eq!(e.success.len(), task.sequence.len());
            assert_eq!(e.dist.len(), task.sequence.len());
            // Nothing was carried: every object is still where it started, off its goal.
            assert!(e.success.iter().all(|s| !s), "{e:?}");
            assert!(e.dist.iter().all(|d| *d > 0.2), "{e:?}");
            // Each cycle's time limit is 8 steps: the episode ends by then (or by a fall).
            assert!(e.steps <= 2 * 8 + 1 || e.fell, "{e:?}");
        }
        assert_eq!(run(), first, "deterministic");
    }

    #[test]
    fn a_joined_walk_and_stop_switches_policies_where_the_gait_stops() {
        use lhm_sim::env::GaitConfig;
        use lhm_sim::motion::demo::AmpWindow;
        let bench = lhm_scenes::Benchmark::embedded().unwrap();
        let model = CharacterModel::amp_humanoid();
        let sim = SimConfig::default();
        let window = AmpWindow::of(&EnvConfig::default(), &sim);
        let demo = lhm_sim::gait::synthetic_cycle_demo(&model, window).unwrap();
        let reference = std::sync::Arc::new(
            lhm_sim::gait::GaitReference::new(&model, &demo, 0, 1.0 / sim.control_hz).unwrap(),
        );
        let config = |stop_distance| EnvConfig {
            gait: Some(GaitConfig {
                stop_distance,
                ..GaitConfig::default()
            }),
            ..EnvConfig::default()
        };
        let (never, at_once) = (config(0.0), config(100.0));
        let net = |seed| {
            let mut c = lhm_nets::ActorCriticConfig::with_hidden(&[16]);
            c.init_seed = seed;
            ActorCritic::new(TaskEnv::obs_dim(&model, &never), model.dofs.len(), &c).unwrap()
        };
        let (a, b) = (net(1), net(2));
        let jobs: Vec<(Task, u64)> = bench.tasks(lhm_scenes::Split::Unseen)[..3]
            .iter()
            .filter_map(|t| t.single_pair(0).map(|t| (t, 0)))
            .collect();
        let setup = |env| EvalSetup {
            gait: Some(GaitStart {
                demo: &demo,
                reference: reference.clone(),
                rest: false,
            }),
            max_steps: Some(20),
            ..plain_setup(&model, &bench, &sim, env, 2)
        };
        let run = |p: EvalPolicy, env| evaluate(p, &setup(env), &jobs, &|_| {}).unwrap();
        let joined = EvalPolicy::Joined { walk: &a, stop: &b };
        // A base that never stops: the walking policy throughout.
        assert_eq!(run(joined, &never), run(EvalPolicy::One(&a), &never));
        // One that stops at once: the stopping policy from the first step after the stop on.
        let mut env = setup(&at_once).env_for(&jobs[0].0, 0);
        assert!(!env.gait_stopped(), "walking until its first step");
        assert_eq!(joined.index_for(&env), 0);
        env.step(&vec![0.0; model.dofs.len()]);
        assert!(env.gait_stopped());
        assert_eq!(joined.index_for(&env), 1);
        // The same net on both sides scores exactly as that net alone.
        let same = EvalPolicy::Joined { walk: &b, stop: &b };
        assert_eq!(run(same, &at_once), run(EvalPolicy::One(&b), &at_once));
        // A stopping policy of another shape is refused.
        let small = ActorCritic::new(
            7,
            model.dofs.len(),
            &lhm_nets::ActorCriticConfig::with_hidden(&[16]),
        )
        .unwrap();
        let odd = EvalPolicy::Joined {
            walk: &a,
            stop: &small,
        };
        assert!(evaluate(odd, &setup(&at_once), &jobs, &|_| {}).is_err());
    }

    #[test]
    fn teachers_switch_at_the_first_handoff_and_batch_like_one_policy() {
        let bench = lhm_scenes::Benchmark::embedded().unwrap();
        let model = CharacterModel::amp_humanoid();
        let mut env = EnvConfig::default();
        env.switching.max_cycle_steps = 8;
        let sim = SimConfig::default();
        let net = |seed| {
            let mut c = lhm_nets::ActorCriticConfig::with_hidden(&[16]);
            c.init_seed = seed;
            ActorCritic::new(TaskEnv::obs_dim(&model, &env), model.dofs.len(), &c).unwrap()
        };
        let (a, b) = (net(1), net(2));
        let two_pairs: Vec<(Task, u64)> = bench.tasks(lhm_scenes::Split::Unseen)[..3]
            .iter()
            .map(|t| (t.clone(), 0))
            .collect();
        let first_pairs: Vec<(Task, u64)> = two_pairs
            .iter()
            .filter_map(|(t, s)| t.single_pair(0).map(|t| (t, *s)))
            .collect();
        let setup = plain_setup(&model, &bench, &sim, &env, 2);
        let run = |p: EvalPolicy, jobs: &[(Task, u64)]| evaluate(p, &setup, jobs, &|_| {}).unwrap();
        let teachers = EvalPolicy::Teachers {
            first: &a,
            later: &b,
        };
        assert_eq!(teachers.index_for_cycle(0), 0);
        assert_eq!(teachers.index_for_cycle(1), 1);
        assert_eq!(teachers.index_for_cycle(4), 1);
        // On first pairs alone Teacher 2 never acts.
        assert_eq!(
            run(teachers, &first_pairs),
            run(EvalPolicy::One(&a), &first_pairs)
        );
        // The same net as both teachers scores exactly as that net alone, split batches and all.
        let same = EvalPolicy::Teachers {
            first: &a,
            later: &a,
        };
        assert_eq!(run(same, &two_pairs), run(EvalPolicy::One(&a), &two_pairs));
        // Teachers of different shapes are refused.
        let small = ActorCritic::new(
            7,
            model.dofs.len(),
            &lhm_nets::ActorCriticConfig::with_hidden(&[16]),
        )
        .unwrap();
        let odd = EvalPolicy::Teachers {
            first: &a,
            later: &small,
        };
        assert!(evaluate(odd, &setup, &two_pairs, &|_| {}).is_err());
    }

    #[test]
    fn seed_zero_is_the_task_and_other_seeds_turn_the_start_within_the_jitter() {
        let bench = lhm_scenes::Benchmark::embedded().unwrap();
        let task = bench.tasks(lhm_scenes::Split::Unseen)[0].clone();
        assert_eq!(seeded_task(&task, 0), task);
        let a = seeded_task(&task, 1);
        let b = seeded_task(&task, 2);
        assert_ne!(a.start.yaw, b.start.yaw);
        for t in [&a, &b] {
            assert!((t.start.yaw - task.start.yaw).abs() <= START_YAW_JITTER);
            assert_eq!(t.start.pos, task.start.pos);
        }
        assert_eq!(seeded_task(&task, 1), a, "deterministic");
    }

    #[test]
    fn mean_steps_is_per_seed_then_over_seeds() {
        let mut eps = [
            episode(0, &[false], &[1.0], true),
            episode(0, &[false], &[1.0], false),
            episode(1, &[false], &[1.0], true),
        ];
        eps[0].steps = 40;
        eps[1].steps = 300;
        eps[2].steps = 90;
        let t = summarize(&eps);
        // Seed 0: (40 + 300) / 2 = 170; seed 1: 90.
        assert!((t.steps.mean - 130.0).abs() < 1e-9, "{:?}", t.steps);
        assert!(
            (t.steps.std - 40.0 * 2f64.sqrt()).abs() < 1e-9,
            "{:?}",
            t.steps
        );
        assert_eq!(t.flat()["mean_steps"], t.steps.mean);
    }

    #[test]
    fn gait_starts_at_the_first_step_for_seed_zero_and_spread_over_the_cycle_for_others() {
        assert_eq!(gait_start_step("unseen-001", 0, 40), 0);
        assert_eq!(gait_start_step("unseen-001", 3, 0), 0);
        let steps: Vec<usize> = (1..200)
            .map(|s| gait_start_step("unseen-001", s, 40))
            .collect();
        assert!(steps.iter().all(|&s| s < 40));
        let mut distinct = steps.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert!(distinct.len() > 30, "{distinct:?}");
        // Deterministic, and independent across tasks.
        assert_eq!(gait_start_step("unseen-001", 7, 40), steps[6]);
        let other: Vec<usize> = (1..200)
            .map(|s| gait_start_step("unseen-002", s, 40))
            .collect();
        assert_ne!(steps, other);
    }

    #[test]
    fn max_steps_caps_every_episode_below_the_cycle_limit() {
        let bench = lhm_scenes::Benchmark::embedded().unwrap();
        let model = CharacterModel::amp_humanoid();
        let env = EnvConfig::default();
        let sim = SimConfig::default();
        let ac = untrained_policy(&model, &env);
        let jobs: Vec<(Task, u64)> = bench.tasks(lhm_scenes::Split::Unseen)[..2]
            .iter()
            .map(|t| (t.clone(), 0))
            .collect();
        let setup = EvalSetup {
            max_steps: Some(5),
            ..plain_setup(&model, &bench, &sim, &env, 2)
        };
        assert_eq!(setup.env_for(&jobs[0].0, 0).config.max_episode_steps, 5);
        for e in evaluate(&ac, &setup, &jobs, &|_| {}).unwrap() {
            // Nothing falls within 5 steps of a standing start: the cap ends the episode.
            assert_eq!((e.steps, e.fell), (5, false), "{e:?}");
        }
        // A cap above the cycles' limit leaves the limit.
        let loose = EvalSetup {
            max_steps: Some(100_000),
            ..setup
        };
        let pairs = jobs[0].0.sequence.len() as u32;
        let limit = pairs * env.switching.max_cycle_steps + EPISODE_SLACK_STEPS;
        assert_eq!(loose.env_for(&jobs[0].0, 0).config.max_episode_steps, limit);
    }

    #[test]
    fn action_noise_moves_the_episodes_the_same_way_in_any_batch() {
        let bench = lhm_scenes::Benchmark::embedded().unwrap();
        let model = CharacterModel::amp_humanoid();
        let mut env = EnvConfig::default();
        env.switching.max_cycle_steps = 30;
        let sim = SimConfig::default();
        let ac = untrained_policy(&model, &env);
        let jobs = two_seeds_of_two_unseen_tasks(&bench);
        let run = |batch, action_std| {
            let setup = EvalSetup {
                action_std,
                ..plain_setup(&model, &bench, &sim, &env, batch)
            };
            evaluate(&ac, &setup, &jobs, &|_| {}).unwrap()
        };
        let mean = run(4, 0.0);
        let noisy = run(4, 0.5);
        // Every episode's own stream: one environment at a time or all four, the same episodes.
        assert_eq!(run(1, 0.5), noisy);
        // The noise moved the character: the episodes differ from the mean actions' ones.
        for (m, n) in mean.iter().zip(&noisy) {
            assert_eq!((&m.task_id, m.seed), (&n.task_id, n.seed));
            assert!(m.steps != n.steps || m.dist != n.dist, "{m:?} {n:?}");
        }
    }
}
