//! The run spec: everything an actor needs to produce useful experience, sent by the learner
//! inside every weights message. Actors therefore hold no configuration of their own beyond where
//! to connect, which run and which role — they are stateless and interchangeable.

use lhm_nets::ActorCriticConfig;
use lhm_scenes::{Benchmark, Split, Task};
use lhm_sim::env::EnvConfig;
use lhm_sim::SimConfig;
use serde::{Deserialize, Serialize};

/// Which benchmark tasks actors draw their episodes from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TaskSet {
    /// Teacher 1's pretraining set: the training tasks cut into single-object tasks (700).
    TrainSingleObject,
    /// Every task of a split, all pairs in one reset-free episode.
    Split(Split),
    /// Listed task ids (benchmark or single-object `<id>.p<k>` ids).
    Ids(Vec<String>),
}

impl TaskSet {
    /// The tasks, or the first id that does not exist.
    pub fn resolve(&self, bench: &Benchmark) -> Result<Vec<Task>, String> {
        let tasks = match self {
            Self::TrainSingleObject => bench.single_object_tasks(Split::Train),
            Self::Split(split) => bench.tasks(*split).to_vec(),
            Self::Ids(ids) => ids
                .iter()
                .map(|id| {
                    bench
                        .task(id)
                        .map(|(_, t)| t)
                        .ok_or_else(|| format!("no task {id:?} in the benchmark"))
                })
                .collect::<Result<_, _>>()?,
        };
        if tasks.is_empty() {
            return Err("the task set is empty".into());
        }
        Ok(tasks)
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    pub obs_dim: usize,
    pub act_dim: usize,
    /// AMP features per step (0: trained without AMP, actors send none).
    pub amp_dim: usize,
    pub actor_critic: ActorCriticConfig,
    pub env: EnvConfig,
    pub sim: SimConfig,
    pub tasks: TaskSet,
    /// Steps per trajectory chunk (per environment).
    pub chunk_steps: u32,
    /// Each actor sends the poses of one in this many finished episodes for recording (0: none).
    pub record_every_episodes: u32,
    /// Each actor sends this many sets of chunks (one chunk per environment) per policy version,
    /// then waits for the next weights (a bounded time), so collection and learning take turns
    /// on shared cores and no chunk goes stale; 0: actors run free.
    #[serde(default)]
    pub chunk_sets_per_version: u32,
    /// DAgger's β for a student rollout: the probability that a step executes the teachers'
    /// action instead of the student's (the label is sent either way). The learner lowers it
    /// round by round; other roles ignore it.
    #[serde(default)]
    pub teacher_mix: f32,
}
