//! The learner service: listens, takes trajectory chunks from whoever is alive, runs an update on
//! each batch — PPO (+AMP) for the teachers, DAgger aggregation and regression for the student
//! ([`optimise`]) — publishes weights (never dropped), answers `latest` queries, serves the frozen
//! teachers a stage needs, checkpoints every N iterations and on SIGTERM, and resumes from its
//! checkpoint.

pub mod batch;
pub mod intake;
pub mod metrics_csv;
pub mod optimise;
pub mod run_config;
pub mod stage;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use lhm_cluster::{encode_policy, shutdown, Endpoints, NodeMode, RunSpec, TaskSet};
use lhm_nets::ActorCriticConfig;
use lhm_protos::{keys, EpisodeFrames, Metrics, Role, TrajectoryChunk, WireMessage};
use lhm_record::{EpisodeScene, McapRecorder};
use lhm_scenes::Benchmark;
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::{CharacterModel, SimConfig};
use serde::{Deserialize, Serialize};
use zenoh::qos::{CongestionControl, Priority};
use zenoh::sample::SampleKind;
use zenoh::Wait;

use crate::amp::AmpConfig;
use crate::ppo::PpoConfig;
use crate::state::{AmpSetup, Learner, LearnerConfig};
use batch::EpisodeSummary;
use intake::{admit, Intake, IntakeCounters};
use optimise::Optimiser;
use run_config::{keep_earlier_config, refuse_another_role};

/// Everything a training run is, as one TOML file (every field has a default).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    pub run_id: String,
    /// `teacher1`, `teacher2`, `student`.
    pub role: String,
    /// Teacher 2's runs: the Teacher 1 policy checkpoint (a stem such as
    /// `runs/p/t1-rr/policy`, with or without `.json`) that plays each episode's first pair.
    /// The learner loads it and serves it to the actors on the run's `teacher1` policy key.
    pub teacher1: Option<PathBuf>,
    /// The student's runs: Teacher 2's policy checkpoint. A student run serves both teachers on
    /// the run's `teacher1`/`teacher2` policy keys, where the dagger-server takes them.
    pub teacher2: Option<PathBuf>,
    /// The student's DAgger settings (β and its decay, the dataset bound, the regression).
    pub dagger: crate::dagger::DaggerConfig,
    /// Fine-tuning (release-and-retreat after pretraining, Teacher 2 from Teacher 1): a new run
    /// starts from this checkpoint's policy, value function and normalisers (same network
    /// layout required) instead of random weights; optimiser and discriminator start fresh. A
    /// run that already has its own checkpoint resumes from that and ignores this.
    pub init_from: Option<PathBuf>,
    /// The benchmark's task files from this directory instead of the copy built in (`--scenes`);
    /// `lhm train` gives it to its actors too (remote actors take their own `--scenes`).
    pub scenes: Option<PathBuf>,
    /// Runs live in `<runs_dir>/<run_id>/` (checkpoint, status.json, run.mcap).
    pub runs_dir: PathBuf,
    /// Transitions per PPO update.
    pub batch_steps: usize,
    /// Chunks made with a policy more than this many versions old are dropped.
    pub max_policy_lag: u64,
    /// Checkpoint every this many iterations (and on SIGTERM / at the end).
    pub checkpoint_every: u64,
    /// Stop after this many iterations in total (`None`: until stopped).
    pub max_iterations: Option<u64>,
    pub network: ActorCriticConfig,
    pub ppo: PpoConfig,
    /// `false`: PPO on the task reward only (no discriminator, no motion clips needed).
    pub amp_enabled: bool,
    pub amp: AmpConfig,
    pub env: EnvConfig,
    pub sim: SimConfig,
    pub tasks: TaskSet,
    pub chunk_steps: u32,
    pub record_every_episodes: u32,
    /// See `RunSpec::chunk_sets_per_version` (0: actors run free). `lhm train` sets it from
    /// its actor and environment counts so that one version's sets make one batch.
    pub chunk_sets_per_version: u32,
    /// `[[stages]]`: a schedule over the learner's iterations ([`RunStage`]). Empty (the
    /// default): the settings above throughout.
    pub stages: Vec<RunStage>,
}

/// One stage of a run's schedule (`[[stages]]`): settings that hold while the learner's iteration
/// is below `until_iteration` (the first such stage holds); past the last stage the run's own.
/// A run from scratch can so learn in the order the fine-tune line of RESULTS.md did through
/// `--init-from` runs — a walk from rest without the discriminator at more noise first, then
/// the stop, the long walks and the discriminator — in one run. The actors follow: the stage's
/// environment and noise travel in the run spec with the weights of each version.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunStage {
    pub until_iteration: u64,
    /// `false`: PPO on the task reward alone while the stage holds (no style reward, no
    /// discriminator update); `true`: AMP on. The discriminator, its features and demo exist for
    /// the whole run when any part of it uses AMP (it starts learning where AMP is first on).
    pub amp_enabled: Option<bool>,
    /// The policy's fixed log standard deviation while the stage holds (the run's
    /// `[network.policy] log_std` must be fixed too).
    pub log_std: Option<f32>,
    /// Keys laid over the run's `[env]` while the stage holds, key by key
    /// (`[stages.env.gait] rest_start_fraction = 1.0`); the observation and AMP feature widths
    /// must stay the run's.
    pub env: toml::Table,
}

/// What a run's schedule sets at one iteration ([`TrainConfig::stage_at`]).
#[derive(Debug, Clone, PartialEq)]
pub struct StageSettings {
    /// The stage in `stages` that holds; `None` past the last (the run's own settings).
    pub index: Option<usize>,
    /// Whether the style reward counts and the discriminator learns.
    pub amp_active: bool,
    /// The policy's fixed log standard deviation, one for every dimension or one each (`None`: a
    /// learned one, left alone).
    pub log_std: Option<lhm_nets::LogStd>,
    /// What the actors receive with the weights: the stage's environment and noise.
    pub spec: RunSpec,
}

impl Default for TrainConfig {
    fn default() -> Self {
        // CPU-sized defaults (the laptop path): 512-256 networks, 4096-step batches.
        let defaults = PpoConfig::default();
        let ppo = PpoConfig {
            minibatch_size: 1024,
            epochs: 4,
            adam: lhm_nets::AdamConfig {
                lr: 5e-5,
                ..defaults.adam.clone()
            },
            // No value clip on unnormalised returns (a 0.2 clip on returns of tens froze the
            // critic); IsaacGymEnvs HumanoidAMP has clip_value False.
            value_clip: None,
            value_coef: 1.0,
            // rl_games' KL-adaptive rate: at sigma = e^-4.5 a fixed 5e-5 moved the policy by an
            // approx KL of ~0.06 per update (clip fraction 0.35-0.5); the narrower the Gaussian,
            // the larger the KL of the same mean shift (RESULTS.md, ninth session).
            kl_target: Some(0.01),
            ..defaults
        };
        let amp_defaults = AmpConfig::default();
        let amp = AmpConfig {
            disc: lhm_nets::MlpConfig::cpu_preset(),
            // 1e-5, not IsaacGymEnvs' 5e-5: our discriminator sees a 4k-step batch per update
            // (theirs 65k) and at 5e-5 it won (accuracy 0.98, style 0.1) within 300k samples.
            adam: lhm_nets::AdamConfig {
                lr: 1e-5,
                ..amp_defaults.adam.clone()
            },
            minibatch_size: 1024,
            // A fifth of each rollout's rows in 10k: the ~12 past updates the 50k buffer of every
            // row spanned (thirty-eighth session), in 8.4 MB of 2 x 105 features instead of 42 MB,
            // so a checkpoint (~10 MB without it) stays under the 20 MB that may be committed.
            replay_capacity: 10_000,
            replay_keep_fraction: 0.2,
            ..amp_defaults
        };
        Self {
            run_id: "teacher1".into(),
            role: "teacher1".into(),
            teacher1: None,
            teacher2: None,
            dagger: crate::dagger::DaggerConfig::default(),
            init_from: None,
            scenes: None,
            runs_dir: PathBuf::from("runs"),
            batch_steps: 4096,
            // Two free-running actors on 2 cores made half the chunks one version stale at lag 1;
            // PPO's ratio is taken against the behaviour policy's recorded log-probs, so data
            // up to 3 versions old is still usable (as Sample Factory's APPO uses lagged data).
            max_policy_lag: 3,
            checkpoint_every: 10,
            max_iterations: None,
            network: {
                let mut network = ActorCriticConfig {
                    // IsaacGymEnvs HumanoidAMP: normalize_value True. Returns run from ~3 (a
                    // fall in the first second) to tens; a critic regressing them raw at lr 5e-5
                    // lagged.
                    normalize_value: true,
                    ..ActorCriticConfig::with_hidden(&[512, 256])
                };
                // Exploration noise e^-4.5 = 0.011 instead of the anchors' e^-2.9 = 0.055: at
                // 0.055 the noise alone topples the neutral pose in ~45 steps (MuJoCo too), and
                // on a CPU budget the policy never got past that; at e^-3.5 task-start episodes
                // still ended in a fall 9 times in 10 after 4.5 M samples, at e^-4.5 almost never
                // after 0.3 M (RESULTS.md, third, sixth and ninth sessions).
                network.policy.log_std = lhm_nets::LogStd::Fixed(-4.5);
                network
            },
            ppo,
            amp_enabled: true,
            amp,
            env: EnvConfig {
                // Reference-state initialisation for half the episodes (AMP/ASE/TokenHSI use
                // such a hybrid of demo and default starts).
                demo_start_probability: 0.5,
                ..EnvConfig::default()
            },
            sim: SimConfig::default(),
            tasks: TaskSet::TrainSingleObject,
            chunk_steps: 32,
            record_every_episodes: 20,
            chunk_sets_per_version: 0,
            stages: Vec::new(),
        }
    }
}

impl TrainConfig {
    pub fn role(&self) -> Result<Role, ServiceError> {
        keys::parse_role(&self.role).ok_or_else(|| {
            ServiceError::Config(format!(
                "role {:?} is not one of teacher1, teacher2, student, vla",
                self.role
            ))
        })
    }

    pub fn run_dir(&self) -> PathBuf {
        self.runs_dir.join(&self.run_id)
    }

    /// What actors receive with the weights.
    pub fn run_spec(&self) -> RunSpec {
        let model = CharacterModel::amp_humanoid();
        RunSpec {
            // The VLA reads its own rows (image, instruction, proprioception).
            obs_dim: self
                .network
                .policy
                .vla
                .as_ref()
                .map_or(TaskEnv::obs_dim(&model, &self.env), |v| v.obs_dim()),
            act_dim: model.dofs.len(),
            amp_dim: if self.amp_present() {
                TaskEnv::amp_dim(&model, &self.env)
            } else {
                0
            },
            actor_critic: self.network.clone(),
            // Demo starts need the clips AMP uses: without AMP there are none to start from.
            env: EnvConfig {
                demo_start_probability: if self.amp_present() {
                    self.env.demo_start_probability
                } else {
                    0.0
                },
                ..self.env.clone()
            },
            sim: self.sim.clone(),
            tasks: self.tasks.clone(),
            chunk_steps: self.chunk_steps,
            record_every_episodes: self.record_every_episodes,
            chunk_sets_per_version: self.chunk_sets_per_version,
            teacher_mix: 0.0,
        }
    }

    /// Whether any part of the run uses AMP (its own settings or a stage's): the discriminator,
    /// the actors' AMP features and the demo exist for the whole run then.
    pub fn amp_present(&self) -> bool {
        self.amp_enabled || self.stages.iter().any(|s| s.amp_enabled == Some(true))
    }

    /// The stage of `stages` that holds at learner iteration `iteration` (`None`: past them all).
    pub fn stage_index(&self, iteration: u64) -> Option<usize> {
        self.stages
            .iter()
            .position(|s| iteration < s.until_iteration)
    }

    /// The schedule's settings at learner iteration `iteration` (policy version): the first
    /// stage whose `until_iteration` lies above it laid over the run's own, or the run's own.
    /// Errors name the stage and the field (`check` has tried every stage already).
    pub fn stage_at(&self, iteration: u64) -> Result<StageSettings, ServiceError> {
        let index = self.stage_index(iteration);
        let own_log_std = match &self.network.policy.log_std {
            lhm_nets::LogStd::Learned(_) => None,
            fixed => Some(fixed.clone()),
        };
        let mut spec = self.run_spec();
        let Some(i) = index else {
            return Ok(StageSettings {
                index,
                amp_active: self.amp_enabled,
                log_std: own_log_std,
                spec,
            });
        };
        let stage = &self.stages[i];
        let at = format!("stages[{i}]");
        let log_std = match (stage.log_std, own_log_std) {
            (None, own) => own,
            (Some(v), Some(_)) if v.is_finite() => Some(lhm_nets::LogStd::Fixed(v)),
            (Some(v), Some(_)) => {
                return Err(ServiceError::Config(format!(
                    "{at}.log_std must be a finite number, got {v}"
                )))
            }
            (Some(_), None) => {
                return Err(ServiceError::Config(format!(
                    "{at}.log_std: the run's [network.policy] log_std is learned; a stage can \
                     only set a fixed one"
                )))
            }
        };
        if let Some(v) = &log_std {
            spec.actor_critic.policy.log_std = v.clone();
        }
        if !stage.env.is_empty() {
            let mut env = toml::Table::try_from(&self.env)
                .map_err(|e| ServiceError::Config(format!("the run's [env]: {e}")))?;
            let schema = overlay_schema()?;
            let env_schema = schema.get("env").and_then(toml::Value::as_table);
            overlay(&mut env, stage.env.clone(), env_schema);
            let staged: EnvConfig = serde_path_to_error::deserialize(toml::Value::Table(env))
                .map_err(|e| {
                    ServiceError::Config(format!("{at}.env: field `{}`: {}", e.path(), e.inner()))
                })?;
            let model = CharacterModel::amp_humanoid();
            for (what, own, theirs) in [
                (
                    "observations",
                    TaskEnv::obs_dim(&model, &self.env),
                    TaskEnv::obs_dim(&model, &staged),
                ),
                (
                    "AMP features",
                    TaskEnv::amp_dim(&model, &self.env),
                    TaskEnv::amp_dim(&model, &staged),
                ),
            ] {
                if own != theirs {
                    return Err(ServiceError::Config(format!(
                        "{at}.env gives {theirs} {what} per step where the run's [env] gives \
                         {own}: a stage cannot change the networks' widths"
                    )));
                }
            }
            spec.env = EnvConfig {
                demo_start_probability: spec.env.demo_start_probability,
                ..staged
            };
        }
        Ok(StageSettings {
            index,
            amp_active: stage.amp_enabled.unwrap_or(self.amp_enabled),
            log_std,
            spec,
        })
    }

    /// Every environment the run will play, each named as an error about it names it: the run's
    /// own (`env`), then each stage's as it stands at the stage's last iteration (`stages[i].env`:
    /// the stage's table laid over the run's). What a check of the run's environments walks,
    /// here and where `lhm train` builds each one's gait cycle before it starts.
    pub fn named_envs(&self) -> Result<Vec<(String, EnvConfig)>, ServiceError> {
        let mut envs = vec![("env".to_string(), self.env.clone())];
        for (i, stage) in self.stages.iter().enumerate() {
            let settings = self.stage_at(stage.until_iteration.saturating_sub(1))?;
            envs.push((format!("stages[{i}].env"), settings.spec.env));
        }
        Ok(envs)
    }

    /// Counts that must be positive (a 0 was silently treated as 1 before).
    pub fn check(&self) -> Result<(), ServiceError> {
        for (name, value) in [
            ("batch_steps", self.batch_steps),
            ("chunk_steps", self.chunk_steps as usize),
            ("ppo.epochs", self.ppo.epochs),
            ("ppo.minibatch_size", self.ppo.minibatch_size),
        ] {
            if value == 0 {
                return Err(ServiceError::Config(format!(
                    "{name} must be at least 1, got 0"
                )));
            }
        }
        self.amp
            .demo_weights
            .check()
            .map_err(|e| ServiceError::Config(format!("amp.demo_weights: {e}")))?;
        let mut until = 0;
        for (i, stage) in self.stages.iter().enumerate() {
            if stage.until_iteration <= until {
                return Err(ServiceError::Config(format!(
                    "stages[{i}].until_iteration must be above the stage before's ({until}), got {}",
                    stage.until_iteration
                )));
            }
            until = stage.until_iteration;
        }
        for (at, env) in self.named_envs()? {
            check_env(&at, &env)?;
        }
        if self.role == "vla" {
            let vla = self.network.policy.vla.as_ref().ok_or_else(|| {
                ServiceError::Config(
                    "a vla run needs the VLA encoder: [network.policy.vla] (the stage preset \
                     sets it)"
                        .into(),
                )
            })?;
            vla.check().map_err(ServiceError::Config)?;
        } else if self.network.policy.vla.is_some() {
            return Err(ServiceError::Config(format!(
                "[network.policy.vla] is for role vla (the VLA stage); this run's role is {}",
                self.role
            )));
        }
        if self.role == "student" || self.role == "vla" {
            if self.amp_present() {
                return Err(ServiceError::Config(
                    "a student run learns by regression onto its teachers' actions: set \
                     amp_enabled = false (the stage preset does)"
                        .into(),
                ));
            }
            self.dagger.check().map_err(ServiceError::Config)?;
        }
        Ok(())
    }

    /// Writes the whole configuration (defaults filled in) to `<run dir>/config.toml`, replacing
    /// the file by one rename, so a run directory says how its policy was trained: `lhm eval`
    /// and `lhm render-rollout` read it beside the checkpoint.
    pub fn write_run_config(&self, run_dir: &Path) -> Result<PathBuf, ServiceError> {
        let path = run_dir.join(RUN_CONFIG_FILE);
        let text = toml::to_string(self)
            .map_err(|e| ServiceError::Config(format!("cannot write the run's config: {e}")))?;
        let tmp = run_dir.join(format!(".tmp-{RUN_CONFIG_FILE}"));
        let io = |source| ServiceError::Io {
            path: path.clone(),
            source,
        };
        std::fs::write(&tmp, text).map_err(io)?;
        std::fs::rename(&tmp, &path).map_err(io)?;
        Ok(path)
    }

    pub fn learner_config(&self) -> LearnerConfig {
        let spec = self.run_spec();
        LearnerConfig {
            obs_dim: spec.obs_dim,
            act_dim: spec.act_dim,
            actor_critic: self.network.clone(),
            ppo: self.ppo.clone(),
            amp: self.amp_present().then(|| AmpSetup {
                config: self.amp.clone(),
                feature_dim: spec.amp_dim,
            }),
        }
    }

    /// Reads a TOML file; errors name the file and the field. The file's tables are laid over
    /// this run's defaults key by key, so `[ppo] epochs = 2` changes the epochs and keeps the
    /// rest of the run's PPO settings (deserialising a partial `[ppo]` on its own would fill the
    /// gaps from `PpoConfig::default()`, whose values are not the run's).
    pub fn from_toml_file(path: &Path) -> Result<Self, ServiceError> {
        Self::from_toml_files(&[path])
    }

    /// [`Self::from_toml_file`] with several files laid over the defaults in order, each key by
    /// key over the ones before (e.g. a stage's configuration, then a pipeline-wide overlay).
    /// Errors name the file that was read last when the merged fields do not deserialise.
    pub fn from_toml_files(paths: &[&Path]) -> Result<Self, ServiceError> {
        let mut sources = Vec::with_capacity(paths.len());
        for path in paths {
            let text = std::fs::read_to_string(path)
                .map_err(|e| ServiceError::Config(format!("{}: {e}", path.display())))?;
            sources.push((path.display().to_string(), text));
        }
        Self::from_toml_sources(&sources)
    }

    /// [`Self::from_toml_files`] on TOML texts already read, each with the name its errors give
    /// (e.g. a configuration built into the binary).
    pub fn from_toml_sources(sources: &[(String, String)]) -> Result<Self, ServiceError> {
        let mut merged = toml::Table::try_from(Self::default())
            .map_err(|e| ServiceError::Config(format!("the built-in defaults: {e}")))?;
        let schema = overlay_schema()?;
        for (name, text) in sources {
            let user: toml::Table = text
                .parse()
                .map_err(|e| ServiceError::Config(format!("{name}: {e}")))?;
            overlay(&mut merged, user, Some(&schema));
        }
        let named: Vec<&str> = sources.iter().map(|(name, _)| name.as_str()).collect();
        serde_path_to_error::deserialize(toml::Value::Table(merged)).map_err(|e| {
            ServiceError::Config(format!(
                "{}: field `{}`: {}",
                named.join(" + "),
                e.path(),
                e.inner()
            ))
        })
    }
}

/// The run's configuration in its directory (see [`TrainConfig::write_run_config`]).
pub const RUN_CONFIG_FILE: &str = "config.toml";

/// The shape an overlay follows: the built-in defaults with every optional sub-configuration
/// (`[env.gait]`, `[env.skills]`, `[amp.accuracy_target]`) present at its own defaults, so that
/// a table a file writes has its default beside it even where the run's default leaves it out.
fn overlay_schema() -> Result<toml::Table, ServiceError> {
    let mut full = TrainConfig::default();
    full.env.gait.get_or_insert_with(Default::default);
    full.env.skills.get_or_insert_with(Default::default);
    full.amp
        .accuracy_target
        .get_or_insert_with(Default::default);
    toml::Table::try_from(full)
        .map_err(|e| ServiceError::Config(format!("the built-in defaults: {e}")))
}

/// Lays `top` over `base`: tables merge key by key, any other value replaces. Where `schema`
/// (the defaults at the same place, [`overlay_schema`]) says the field is an enum — its default
/// is a string (a unit variant) or a one-key table (a variant with data) — a one-key table over
/// a one-key table with another key replaces it: the enum switches variant
/// (`log_std = { learned = -1.0 }` over `{ fixed = -4.5 }`), which merged would name both.
/// Everything else merges, however few keys either side has: structs (`[env.gait.stop]
/// seconds` in one file, `feedback` in the next) and name-keyed maps (`residual_joints`, whose
/// default is empty). A test keeps every one-key table of the schema an enum.
fn overlay(base: &mut toml::Table, top: toml::Table, schema: Option<&toml::Table>) {
    for (key, value) in top {
        let field = schema.and_then(|s| s.get(&key));
        let enum_field = match field {
            Some(toml::Value::String(_)) => true,
            Some(toml::Value::Table(d)) => d.len() == 1,
            _ => false,
        };
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(t))
                if !(enum_field
                    && b.len() == 1
                    && t.len() == 1
                    && b.keys().next() != t.keys().next()) =>
            {
                overlay(b, t, field.and_then(toml::Value::as_table))
            }
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    #[error("config: {0}")]
    Config(String),
    #[error(transparent)]
    Cluster(#[from] lhm_cluster::ClusterError),
    #[error(transparent)]
    Learner(#[from] crate::LearnerError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

fn zerr(e: impl std::fmt::Display) -> ServiceError {
    ServiceError::Cluster(lhm_cluster::ClusterError::zenoh(e))
}

/// Demo AMP features (rows of the discriminator's width) for the discriminator's "real" side.
pub trait DemoSource: Send {
    fn sample(&mut self, rows: usize) -> Vec<f32>;
}

/// One finished iteration, for progress bars and logs.
#[derive(Debug, Clone, Serialize)]
pub struct IterationReport {
    pub iteration: u64,
    pub samples: u64,
    pub samples_per_s: f64,
    pub mean_return: f64,
    pub success_rate: f64,
    pub episodes: u64,
    pub actors_alive: usize,
    pub update_s: f64,
    /// Discriminator accuracy on this iteration's agent and demo rows (None without AMP).
    pub disc_accuracy: Option<f64>,
    /// Mean style and task reward per step of this iteration's batch.
    pub style_reward: f64,
    pub task_reward: f64,
    pub fall_fraction: f64,
    /// Over episodes from task starts.
    pub reach_rate: f64,
    /// Over every finished episode, demo and gait starts too (with `[env.gait]` every episode
    /// starts in the gait, so `reach_rate` has none to count).
    pub reach_rate_all: f64,
}

/// What `status.json` holds after every iteration (tests and people read it).
#[derive(Debug, Clone, Serialize)]
pub struct LearnerStatus {
    pub run_id: String,
    pub iteration: u64,
    pub policy_version: u64,
    pub samples: u64,
    /// Transitions that went into updates (equals the accepted chunks' steps consumed).
    pub steps_used: u64,
    pub intake: IntakeCounters,
    /// Live processes that have sent trajectories (actors).
    pub actors_alive: Vec<String>,
    /// Every live process of the run (actors, dagger-server, …), by liveliness token.
    pub processes_alive: Vec<String>,
    /// Distinct actors that have sent trajectories since this learner started.
    pub actors_seen: usize,
    pub resumed_from_iteration: Option<u64>,
    pub last: Option<IterationReport>,
    pub episodes: Option<EpisodeSummary>,
}

/// What the learner knows about the run besides its networks: the intake, who is alive, what the
/// last batch held. `status.json` is written from it.
#[derive(Default)]
struct Book {
    counters: IntakeCounters,
    /// Live processes, by liveliness token.
    alive: BTreeSet<String>,
    /// Processes that have sent trajectories (actors).
    seen: BTreeSet<String>,
    steps_used: u64,
    last: Option<IterationReport>,
    episodes: Option<EpisodeSummary>,
}

impl Book {
    /// Takes one liveliness change of the run's processes; whether a process joined.
    fn liveliness(&mut self, run_id: &str, sample: &zenoh::sample::Sample) -> bool {
        let key = sample.key_expr().as_str();
        let Some(process) = keys::process_of_status_key(run_id, key) else {
            return false;
        };
        if process == "learner" {
            return false;
        }
        match sample.kind() {
            SampleKind::Put => {
                if self.alive.insert(process.to_owned()) {
                    tracing::info!("{process} joined ({} alive)", self.alive.len());
                }
                true
            }
            SampleKind::Delete => {
                if self.alive.remove(process) {
                    tracing::info!("{process} left ({} alive)", self.alive.len());
                }
                false
            }
        }
    }

    fn actors_alive(&self) -> Vec<String> {
        self.alive.intersection(&self.seen).cloned().collect()
    }

    fn status(
        &self,
        config: &TrainConfig,
        learner: &Learner,
        resumed: Option<u64>,
    ) -> LearnerStatus {
        LearnerStatus {
            run_id: config.run_id.clone(),
            iteration: learner.counters.iteration,
            policy_version: learner.counters.iteration,
            samples: learner.counters.samples,
            steps_used: self.steps_used,
            intake: self.counters.clone(),
            actors_alive: self.actors_alive(),
            processes_alive: self.alive.iter().cloned().collect(),
            actors_seen: self.seen.len(),
            resumed_from_iteration: resumed,
            last: self.last.clone(),
            episodes: self.episodes.clone(),
        }
    }
}

fn write_json_atomic(path: &Path, value: &impl Serialize) -> Result<(), ServiceError> {
    let io = |source| ServiceError::Io {
        path: path.to_owned(),
        source,
    };
    let tmp = path.with_extension("json.tmp");
    let text = serde_json::to_vec_pretty(value).unwrap_or_default();
    std::fs::write(&tmp, text).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

/// Copies the policy, value function and normalisers of the checkpoint at `path` into a fresh
/// learner; a different network layout is an error naming the file and the tensor.
fn init_actor_critic(learner: &mut Learner, path: &Path) -> Result<(), ServiceError> {
    let stem = lhm_nets::checkpoint::stem_of(path);
    let source = Learner::load(&stem, None)?;
    let mismatch = |what: String| {
        ServiceError::Config(format!(
            "{}: cannot start from this checkpoint: {what}",
            stem.display()
        ))
    };
    let from: std::collections::HashMap<String, candle_core::Var> =
        source.actor_critic.named_vars().into_iter().collect();
    for (name, var) in learner.actor_critic.named_vars() {
        let src = from
            .get(&name)
            .ok_or_else(|| mismatch(format!("it has no tensor `{name}`")))?;
        if src.dims() != var.dims() {
            return Err(mismatch(format!(
                "`{name}` is {:?}, this run's is {:?}",
                src.dims(),
                var.dims()
            )));
        }
        var.set(src.as_tensor())
            .map_err(|e| mismatch(format!("`{name}`: {e}")))?;
    }
    let ac = &mut learner.actor_critic;
    let width =
        |n: &Option<lhm_nets::RunningMeanStd>| n.as_ref().map(lhm_nets::RunningMeanStd::dim);
    if width(&ac.obs_norm) != width(&source.actor_critic.obs_norm)
        || width(&ac.value_norm) != width(&source.actor_critic.value_norm)
    {
        return Err(mismatch("its normalisers differ from this run's".into()));
    }
    ac.obs_norm = source.actor_critic.obs_norm.clone();
    ac.value_norm = source.actor_critic.value_norm.clone();
    tracing::info!(
        "starting from {} (iteration {})",
        stem.display(),
        source.counters.iteration
    );
    Ok(())
}

/// The frozen teachers a run serves on its policy keys: Teacher 2's run, the Teacher 1 that
/// plays each episode's first pair; the student's run, both teachers (the dagger-server labels
/// with them). A run without the teachers its role needs, or with one that does not fit this
/// run's observations and actions, is an error naming the file.
fn load_teachers(config: &TrainConfig, role: Role) -> Result<Vec<(Role, Learner)>, ServiceError> {
    let needed: &[(Role, &Option<PathBuf>, &str)] = match role {
        Role::Teacher2 => &[(Role::Teacher1, &config.teacher1, "teacher1")],
        // The VLA's labeller is the unified student, serving every cycle: it stands on both
        // teachers' keys (`Stage::Vla` sets both to it).
        Role::Student | Role::Vla => &[
            (Role::Teacher1, &config.teacher1, "teacher1"),
            (Role::Teacher2, &config.teacher2, "teacher2"),
        ],
        _ => &[],
    };
    let spec = config.run_spec();
    // Teachers (and the VLA's labeller) read the state observation, whatever this run's policy
    // reads.
    let state_obs_dim = TaskEnv::obs_dim(&CharacterModel::amp_humanoid(), &config.env);
    let mut teachers = Vec::new();
    for (teacher, path, field) in needed {
        let Some(path) = path else {
            return Err(ServiceError::Config(format!(
                "a {} run needs {}'s policy: `{field} = \"runs/<run>/policy\"` in the config, \
                 or --{field}",
                config.role,
                lhm_protos::keys::role_chunk(*teacher)
            )));
        };
        let stem = lhm_nets::checkpoint::stem_of(path);
        let t = Learner::load(&stem, None)?;
        let (obs, act) = (t.actor_critic.obs_dim(), t.actor_critic.act_dim());
        if (obs, act) != (state_obs_dim, spec.act_dim) {
            return Err(ServiceError::Config(format!(
                "{}: {field} takes {obs} observations and gives {act} actions; this run's \
                 environment has {state_obs_dim} and {}",
                stem.display(),
                spec.act_dim
            )));
        }
        tracing::info!(
            "{field}: {} (iteration {})",
            stem.display(),
            t.counters.iteration
        );
        teachers.push((*teacher, t));
    }
    Ok(teachers)
}

/// A frozen teacher on its policy key: the queryable that answers for it, and the message to put
/// again whenever a process (re)joins (a dagger-server that missed both would label nothing).
struct ServedTeacher {
    _queryable: zenoh::query::Queryable<()>,
    key: String,
    bytes: Vec<u8>,
}

/// Answers queries on the run's `role` policy key with the frozen `teacher`'s weights, and puts
/// them once for subscribers already listening.
fn serve_teacher(
    session: &zenoh::Session,
    config: &TrainConfig,
    spec: &RunSpec,
    role: Role,
    teacher: &Learner,
) -> Result<ServedTeacher, ServiceError> {
    // The teacher's own network settings (its sizes or noise may differ from this run's).
    let teacher_spec = RunSpec {
        obs_dim: teacher.actor_critic.obs_dim(),
        actor_critic: teacher.actor_critic.config.clone(),
        ..spec.clone()
    };
    let bytes = encode_policy(
        &config.run_id,
        role,
        teacher.counters.iteration,
        &teacher_spec,
        &teacher.actor_critic,
    )?
    .encode_checked()
    .map_err(lhm_cluster::ClusterError::from)?;
    let key = keys::policy(&config.run_id, role);
    session.put(&key, bytes.clone()).wait().map_err(zerr)?;
    let answer = bytes.clone();
    let queryable = session
        .declare_queryable(&key)
        .callback(move |query| {
            if let Err(e) = query.reply(query.key_expr().clone(), answer.clone()).wait() {
                tracing::warn!("answering a teacher weights query: {e}");
            }
        })
        .wait()
        .map_err(zerr)?;
    Ok(ServedTeacher {
        _queryable: queryable,
        key,
        bytes,
    })
}

/// The environment's own settings that its types do not bound (`at`: where they came from).
fn check_env(at: &str, env: &EnvConfig) -> Result<(), ServiceError> {
    let Some(g) = env.gait.as_ref() else {
        return Ok(());
    };
    let at = format!("{at}.gait");
    // Names and values of residual_joints and angle_offsets, so a stage's typo stops the run at
    // its start rather than its actors when the stage comes.
    g.check(&CharacterModel::amp_humanoid())
        .map_err(|e| ServiceError::Config(format!("{at}: {e}")))?;
    for (name, f) in [
        ("near_start_fraction", g.near_start_fraction),
        ("rest_start_fraction", g.rest_start_fraction),
    ] {
        check_fraction(&at, name, f)?;
    }
    for (name, x) in [
        ("start_distance_max", g.start_distance_max),
        ("bout_distance", g.bout_distance),
        ("bout_min_left", g.bout_min_left),
        ("pause_seconds", g.pause_seconds),
    ] {
        check_non_negative(&at, name, x)?;
    }
    Ok(())
}

/// `{at}.{name}` refused unless it lies in [0, 1].
fn check_fraction(at: &str, name: &str, f: f32) -> Result<(), ServiceError> {
    if (0.0..=1.0).contains(&f) {
        Ok(())
    } else {
        Err(ServiceError::Config(format!(
            "{at}.{name} must be between 0 and 1, got {f}"
        )))
    }
}

/// `{at}.{name}` refused unless it is a finite number >= 0.
fn check_non_negative(at: &str, name: &str, x: f32) -> Result<(), ServiceError> {
    if x.is_finite() && x >= 0.0 {
        Ok(())
    } else {
        Err(ServiceError::Config(format!(
            "{at}.{name} must be a finite number >= 0, got {x}"
        )))
    }
}

/// The checkpoint stem of a run: `<run_dir>/checkpoint.{safetensors,json}`.
pub fn checkpoint_stem(run_dir: &Path) -> PathBuf {
    run_dir.join("checkpoint")
}

/// `run.mcap` for a new run; a resumed run records into `run.2.mcap`, `run.3.mcap`, … so that
/// nothing already recorded is overwritten.
pub fn recording_path(run_dir: &Path) -> PathBuf {
    let first = run_dir.join("run.mcap");
    if !first.exists() {
        return first;
    }
    (2u32..)
        .map(|k| run_dir.join(format!("run.{k}.mcap")))
        .find(|p| !p.exists())
        .unwrap_or(first)
}

/// The run's MCAP file: metrics, sampled episodes as Foxglove scenes, raw `lhm.v1` messages.
/// Recording is for people; a failure to write is logged and stops recording, never training.
struct RunRecording {
    recorder: Option<McapRecorder>,
    bench: Option<Benchmark>,
    model: CharacterModel,
}

impl RunRecording {
    fn open(path: PathBuf, scenes: Option<&Path>) -> Self {
        let recorder = McapRecorder::create(&path)
            .map_err(|e| tracing::warn!("not recording: {e}"))
            .ok();
        if recorder.is_some() {
            tracing::info!("recording to {}", path.display());
        }
        Self {
            recorder,
            bench: match scenes {
                Some(dir) => Benchmark::load_dir(dir),
                None => Benchmark::embedded(),
            }
            .map_err(|e| tracing::warn!("no scenes for recording: {e}"))
            .ok(),
            model: CharacterModel::amp_humanoid(),
        }
    }

    fn with(
        &mut self,
        what: &str,
        f: impl FnOnce(&mut McapRecorder) -> Result<(), lhm_record::RecordError>,
    ) {
        if let Some(r) = self.recorder.as_mut() {
            if let Err(e) = f(r) {
                tracing::warn!("recording {what} failed, recording stops: {e}");
                self.recorder = None;
            }
        }
    }

    fn episode(&mut self, bytes: &[u8]) {
        let frames = match EpisodeFrames::decode_checked(bytes) {
            Ok(f) => f,
            Err(e) => {
                tracing::warn!("ignoring a sampled episode: {e}");
                return;
            }
        };
        let Some(task) = self.bench.as_ref().and_then(|b| b.task(&frames.task_id)) else {
            tracing::warn!(
                "ignoring a sampled episode of unknown task {:?}",
                frames.task_id
            );
            return;
        };
        let Some(bench) = self.bench.as_ref() else {
            return;
        };
        let scene = EpisodeScene::new(&self.model, &task.1, &bench.catalogue);
        let now = lhm_cluster::clock::unix_ns();
        self.with("an episode", |r| {
            r.write_wire("/lhm/episode", now, &frames)?;
            r.write_episode(&frames, &scene, now)
        });
    }

    fn finish(self) {
        if let Some(r) = self.recorder {
            if let Err(e) = r.finish() {
                tracing::warn!("closing the recording: {e}");
            }
        }
    }
}

/// Called after every iteration.
pub type IterationHook<'a> = Box<dyn FnMut(&IterationReport) + 'a>;

/// Optional hooks into a learner run (recording, progress).
#[derive(Default)]
pub struct Hooks<'a> {
    pub on_iteration: Option<IterationHook<'a>>,
    /// Called once the session is up and listening (e.g. to start local actors).
    pub on_listening: Option<Box<dyn FnMut() + 'a>>,
}

/// Prepares the run directory (refusing one of another role, writing `config.toml`) and the
/// learner: resumed from its checkpoint if it has one (with the iteration it resumes from; a
/// changed configuration is named and the earlier one kept, [`keep_earlier_config`]), else
/// fresh or started from `init_from`.
fn open_learner(
    config: &TrainConfig,
    run_dir: &Path,
) -> Result<(Learner, Option<u64>), ServiceError> {
    std::fs::create_dir_all(run_dir).map_err(|source| ServiceError::Io {
        path: run_dir.to_owned(),
        source,
    })?;
    refuse_another_role(config, run_dir)?;
    let stem = checkpoint_stem(run_dir);
    let learner_config = config.learner_config();
    if stem.with_extension("json").is_file() {
        let l = Learner::load(&stem, Some(&learner_config))?;
        let it = l.counters.iteration;
        tracing::info!("resuming {} from iteration {it}", stem.display());
        if let Some(change) = keep_earlier_config(config, run_dir, it)? {
            tracing::warn!(
                "this run's configuration differs from the one {} was trained with up to \
                 iteration {it} in: {} (that one is kept as {})",
                run_dir.display(),
                change.keys.join(", "),
                change.kept_as.display()
            );
        }
        config.write_run_config(run_dir)?;
        Ok((l, Some(it)))
    } else {
        config.write_run_config(run_dir)?;
        let mut fresh = Learner::new(learner_config)?;
        if let Some(path) = &config.init_from {
            init_actor_critic(&mut fresh, path)?;
        }
        Ok((fresh, None))
    }
}

/// The schedule's settings at the learner's iteration, its policy's noise set to them; logged.
fn enter_stage(config: &TrainConfig, learner: &mut Learner) -> Result<StageSettings, ServiceError> {
    let it = learner.counters.iteration;
    let stage = config.stage_at(it)?;
    if let Some(v) = &stage.log_std {
        learner
            .actor_critic
            .set_fixed_log_std(v)
            .map_err(crate::LearnerError::from)?;
    }
    if !config.stages.is_empty() {
        let name = stage.index.map_or_else(
            || "the run's own settings".to_owned(),
            |i| format!("stages[{i}]"),
        );
        tracing::info!(
            "iteration {it}: {name} (AMP {}, log_std {:?})",
            if stage.amp_active { "on" } else { "off" },
            stage.log_std
        );
    }
    Ok(stage)
}

/// Runs the learner until `max_iterations` or a stop request; returns the final status.
pub fn run_learner(
    config: &TrainConfig,
    endpoints: &Endpoints,
    demo: Option<Box<dyn DemoSource>>,
    mut hooks: Hooks<'_>,
) -> Result<LearnerStatus, ServiceError> {
    let role = config.role()?;
    config.check()?;
    keys::check_chunk("run id", &config.run_id).map_err(lhm_cluster::ClusterError::from)?;
    let teachers = load_teachers(config, role)?;
    if config.amp_present() && demo.is_none() {
        return Err(ServiceError::Config(
            "AMP is on but no demo motion was given (install clips with scripts/install-motions, \
             or train without AMP)"
                .into(),
        ));
    }
    let run_dir = config.run_dir();
    let stem = checkpoint_stem(&run_dir);
    let (mut learner, resumed) = open_learner(config, &run_dir)?;
    let mut optimiser = match role {
        Role::Student | Role::Vla => Optimiser::dagger(&config.dagger, &learner, &run_dir)?,
        _ => Optimiser::PpoAmp { demo },
    };
    let mut stage = enter_stage(config, &mut learner)?;
    let mut spec = stage.spec.clone();
    spec.teacher_mix = optimiser.teacher_mix(learner.counters.iteration);

    let encode = |learner: &Learner, spec: &RunSpec| -> Result<Vec<u8>, ServiceError> {
        let msg = encode_policy(
            &config.run_id,
            role,
            learner.counters.iteration,
            spec,
            &learner.actor_critic,
        )?;
        Ok(msg
            .encode_checked()
            .map_err(lhm_cluster::ClusterError::from)?)
    };
    let links = LearnerLinks::open(config, role, endpoints, encode(&learner, &spec)?)?;
    let session = &links.session;
    let served_teachers = teachers
        .iter()
        .map(|(role, t)| serve_teacher(session, config, &spec, *role, t))
        .collect::<Result<Vec<_>, _>>()?;
    let mut recording = RunRecording::open(recording_path(&run_dir), config.scenes.as_deref());
    let mut metrics_csv = metrics_csv::MetricsCsv::open(&run_dir.join("metrics.csv"))
        .map_err(|e| tracing::warn!("no metrics.csv: {e}"))
        .ok();
    let run_started = Instant::now();
    links.publish_latest()?;
    tracing::info!(
        "learner {} ({}) listening on {:?}, policy version {}",
        config.run_id,
        config.role,
        endpoints.listen,
        learner.counters.iteration
    );
    if let Some(f) = hooks.on_listening.as_mut() {
        f();
    }

    let mut book = Book::default();
    let mut pending: Vec<TrajectoryChunk> = Vec::new();
    let mut pending_steps = 0usize;
    let mut iteration_started = Instant::now();
    let mut republish = false;
    let mut last_status = Instant::now();
    let mut last_republish = Instant::now();
    let status_path = run_dir.join("status.json");
    write_json_atomic(&status_path, &book.status(config, &learner, resumed))?;

    loop {
        if shutdown::requested()
            || config
                .max_iterations
                .is_some_and(|m| learner.counters.iteration >= m)
        {
            break;
        }
        while let Ok(Some(sample)) = links.alive_sub.try_recv() {
            // A (re)joining process may have missed the last broadcast (e.g. it outlived a
            // learner restart and holds a newer version than the checkpoint): send again.
            republish |= book.liveliness(&config.run_id, &sample);
        }
        if republish && last_republish.elapsed() >= Duration::from_millis(500) {
            links.publish_latest()?;
            for t in &served_teachers {
                session.put(&t.key, t.bytes.clone()).wait().map_err(zerr)?;
            }
            republish = false;
            last_republish = Instant::now();
        }
        while let Ok(Some(sample)) = links.episode_sub.try_recv() {
            recording.episode(&sample.payload().to_bytes());
        }
        if last_status.elapsed() >= Duration::from_secs(1) {
            // Between iterations too, so intake counters and who is alive are visible.
            write_json_atomic(&status_path, &book.status(config, &learner, resumed))?;
            last_status = Instant::now();
        }
        let Ok(Some(sample)) = links.traj_sub.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        let bytes = sample.payload().to_bytes();
        match admit(
            &bytes,
            &config.run_id,
            role,
            &spec,
            learner.counters.iteration,
            config.max_policy_lag,
            &mut book.counters,
        ) {
            Intake::Accepted(chunk) => {
                if !book.seen.contains(&chunk.actor_id) {
                    book.seen.insert(chunk.actor_id.clone());
                }
                pending_steps += chunk.num_steps as usize;
                pending.push(*chunk);
            }
            Intake::Stale { version, actor_id } => {
                book.seen.insert(actor_id);
                tracing::debug!("dropped a chunk of policy version {version}");
                if version > learner.counters.iteration {
                    // Made by weights this learner never published (it restarted from an older
                    // checkpoint): that actor needs the current ones.
                    republish = true;
                }
            }
            Intake::Rejected(why) => {
                tracing::warn!("rejected a message on the trajectory key: {why}")
            }
        }
        if pending_steps < config.batch_steps {
            continue;
        }
        // One update on everything pending.
        let collect_s = iteration_started.elapsed().as_secs_f64();
        let update_started = Instant::now();
        let chunks = std::mem::take(&mut pending);
        let n_steps = std::mem::take(&mut pending_steps);
        if let Some(first) = chunks.first() {
            // One raw chunk per iteration: enough to inspect what actors send, small enough to keep.
            recording.with("a trajectory chunk", |r| {
                r.write_wire("/lhm/trajectory", lhm_cluster::clock::unix_ns(), first)
            });
        }
        let update = optimiser.update(&mut learner, &chunks, stage.amp_active)?;
        learner.counters.iteration += 1;
        if config.stage_index(learner.counters.iteration) != stage.index {
            stage = enter_stage(config, &mut learner)?;
            spec = stage.spec.clone();
        }
        spec.teacher_mix = optimiser.teacher_mix(learner.counters.iteration);
        learner.counters.samples += n_steps as u64;
        book.steps_used += n_steps as u64;
        links.publish(encode(&learner, &spec)?)?;
        let it = learner.counters.iteration;
        // The last iteration of a budget is saved before status.json reports it: `lhm pipeline`
        // takes a stage whose status reached its budget as finished, checkpoint included.
        let last = config.max_iterations.is_some_and(|max| it >= max);
        if last || (config.checkpoint_every > 0 && it % config.checkpoint_every == 0) {
            learner.save(&stem)?;
            learner.save_policy(&run_dir.join("policy"))?;
        }
        let update_s = update_started.elapsed().as_secs_f64();
        let total_s = collect_s + update_s;
        let s = &update.summary;
        let report = IterationReport {
            iteration: it,
            samples: learner.counters.samples,
            samples_per_s: n_steps as f64 / total_s.max(1e-9),
            mean_return: s.mean_return,
            success_rate: s.success_rate,
            episodes: s.episodes,
            actors_alive: book.actors_alive().len(),
            update_s,
            disc_accuracy: update.disc_accuracy,
            style_reward: s.mean_style_reward,
            task_reward: s.mean_task_reward,
            fall_fraction: s.fall_fraction(),
            reach_rate: s.reach_rate(),
            reach_rate_all: s.reach_rate_all(),
        };
        if let Some(csv) = metrics_csv.as_mut() {
            let wall_s = run_started.elapsed().as_secs_f64();
            let assist = &config.sim.assist;
            let assist_strength = assist
                .is_active()
                .then(|| f64::from(assist.strength_at(report.iteration)));
            let extra = Extra {
                wall_s,
                assist_strength,
            };
            if let Err(e) = append_metrics_row(csv, &report, &update, &book.counters, extra) {
                tracing::warn!("writing {}: {e}; metrics.csv stops", csv.path().display());
                metrics_csv = None;
            }
        }
        let m = metrics_message(&config.run_id, &report, &update, &book);
        recording.with("metrics", |r| r.write_metrics(&m));
        if let Ok(bytes) = m.encode_checked() {
            let _ = session
                .put(keys::metrics(&config.run_id, "learner"), bytes)
                .congestion_control(CongestionControl::Drop)
                .priority(Priority::DataLow)
                .wait();
        }
        if let Some(f) = hooks.on_iteration.as_mut() {
            f(&report);
        }
        book.episodes = Some(s.clone());
        book.last = Some(report);
        write_json_atomic(&status_path, &book.status(config, &learner, resumed))?;
        iteration_started = Instant::now();
    }
    learner.save(&stem)?;
    learner.save_policy(&run_dir.join("policy"))?;
    tracing::info!(
        "learner stopped at iteration {}; checkpoint {}",
        learner.counters.iteration,
        stem.display()
    );
    let final_status = book.status(config, &learner, resumed);
    write_json_atomic(&status_path, &final_status)?;
    recording.finish();
    drop(served_teachers);
    links.close();
    Ok(final_status)
}

type SampleSubscriber =
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;

/// The learner's side of the Zenoh wiring: its session (a router actors connect to), the policy
/// key it publishes on and answers queries on with the latest weights, the trajectory and episode
/// subscriptions, and the liveliness of everyone in the run.
struct LearnerLinks {
    session: zenoh::Session,
    /// The newest encoded weights message: what queries are answered with and what is re-put.
    latest: Arc<Mutex<Vec<u8>>>,
    _queryable: zenoh::query::Queryable<()>,
    weights_pub: zenoh::pubsub::Publisher<'static>,
    traj_sub: SampleSubscriber,
    episode_sub: SampleSubscriber,
    alive_sub: SampleSubscriber,
    _token: zenoh::liveliness::LivelinessToken,
}

impl LearnerLinks {
    fn open(
        config: &TrainConfig,
        role: Role,
        endpoints: &Endpoints,
        weights: Vec<u8>,
    ) -> Result<Self, ServiceError> {
        let session = lhm_cluster::open_session(NodeMode::Router, endpoints)?;
        let policy_key = keys::policy(&config.run_id, role);
        let latest = Arc::new(Mutex::new(weights));
        let latest_for_queries = Arc::clone(&latest);
        let queryable = session
            .declare_queryable(&policy_key)
            .callback(move |query| {
                let bytes = latest_for_queries
                    .lock()
                    .map(|b| b.clone())
                    .unwrap_or_default();
                if let Err(e) = query.reply(query.key_expr().clone(), bytes).wait() {
                    tracing::warn!("answering a weights query: {e}");
                }
            })
            .wait()
            .map_err(zerr)?;
        // Weights are large and must never be dropped: Block, on their own (higher) priority.
        let weights_pub = session
            .declare_publisher(policy_key)
            .congestion_control(CongestionControl::Block)
            .priority(Priority::DataHigh)
            .wait()
            .map_err(zerr)?;
        let traj_sub = session
            .declare_subscriber(keys::trajectory_all(&config.run_id, role))
            .wait()
            .map_err(zerr)?;
        let episode_sub = session
            .declare_subscriber(keys::episode_all(&config.run_id, role))
            .wait()
            .map_err(zerr)?;
        let alive_sub = session
            .liveliness()
            .declare_subscriber(keys::status_all(&config.run_id))
            .history(true)
            .wait()
            .map_err(zerr)?;
        let token = session
            .liveliness()
            .declare_token(keys::status(&config.run_id, "learner"))
            .wait()
            .map_err(zerr)?;
        Ok(Self {
            session,
            latest,
            _queryable: queryable,
            weights_pub,
            traj_sub,
            episode_sub,
            alive_sub,
            _token: token,
        })
    }

    /// Makes `bytes` the latest weights and publishes them.
    fn publish(&self, bytes: Vec<u8>) -> Result<(), ServiceError> {
        if let Ok(mut l) = self.latest.lock() {
            l.clone_from(&bytes);
        }
        self.weights_pub.put(bytes).wait().map_err(zerr)
    }

    /// Publishes the latest weights again (for processes that may have missed them).
    fn publish_latest(&self) -> Result<(), ServiceError> {
        let bytes = self.latest.lock().map(|b| b.clone()).unwrap_or_default();
        self.weights_pub.put(bytes).wait().map_err(zerr)
    }

    fn close(self) {
        let _ = self.session.close().wait();
    }
}

/// The row's figures that are neither the report's nor the update's.
struct Extra {
    wall_s: f64,
    /// The upright assist's strength the actors train under (`None`: no assist).
    assist_strength: Option<f64>,
}

/// One row of `metrics.csv` for an iteration.
fn append_metrics_row(
    csv: &mut metrics_csv::MetricsCsv,
    report: &IterationReport,
    update: &optimise::Update,
    counters: &IntakeCounters,
    extra: Extra,
) -> std::io::Result<()> {
    let Extra {
        wall_s,
        assist_strength,
    } = extra;
    let s = &update.summary;
    let finished = |v: f64| if s.episodes > 0 { v } else { f64::NAN };
    let terms: Vec<(String, f64)> = s
        .reward_terms
        .iter()
        .map(|(k, v)| (format!("reward_{k}"), *v))
        .collect();
    let mut row = vec![
        ("iteration", report.iteration as f64),
        ("samples", report.samples as f64),
        ("wall_s", wall_s),
        ("samples_per_s", report.samples_per_s),
        ("update_s", report.update_s),
        ("episodes", s.episodes as f64),
        // Empty, not 0, in an iteration that finished no episode (long episodes end in bursts,
        // and zeros between the bursts would drag the plotted curve down).
        ("mean_return", finished(s.mean_return)),
        ("mean_episode_length", finished(s.mean_length)),
        ("success_rate", s.success_rate),
        ("fall_fraction", report.fall_fraction),
        ("task_start_fall_fraction", s.task_start_fall_fraction()),
        ("reach_rate", report.reach_rate),
        ("reach_rate_all", s.reach_rate_all()),
        ("disc_accuracy", report.disc_accuracy.unwrap_or(f64::NAN)),
        ("style_reward", s.mean_style_reward),
        ("task_reward", s.mean_task_reward),
    ];
    row.extend(update.metrics.iter().map(|m| (m.column, m.value)));
    row.extend([
        ("stale_chunks", counters.stale as f64),
        ("accepted_chunks", counters.accepted as f64),
    ]);
    row.extend(terms.iter().map(|(k, v)| (k.as_str(), *v)));
    row.push(("assist_strength", assist_strength.unwrap_or(f64::NAN)));
    row.extend([
        ("style_reward_std", s.style_reward_std),
        ("task_reward_std", s.task_reward_std),
    ]);
    csv.append(&row)
}

/// The iteration's metrics as recorded in `run.mcap` and put on the run's metrics key.
fn metrics_message(
    run_id: &str,
    report: &IterationReport,
    update: &optimise::Update,
    book: &Book,
) -> Metrics {
    let s = &update.summary;
    let mut m = Metrics {
        run_id: run_id.to_owned(),
        process: "learner".into(),
        unix_time_ms: lhm_cluster::clock::unix_ms(),
        iteration: report.iteration,
        ..Metrics::versioned()
    };
    let v = &mut m.values;
    v.insert("samples_per_s".into(), report.samples_per_s);
    v.insert("update_s".into(), report.update_s);
    v.insert("episodes".into(), s.episodes as f64);
    v.insert("mean_return".into(), s.mean_return);
    v.insert("success_rate".into(), s.success_rate);
    v.insert("falls".into(), s.falls as f64);
    v.insert("fall_fraction".into(), report.fall_fraction);
    for (name, mean) in &s.reward_terms {
        v.insert(format!("reward/{name}"), *mean);
    }
    v.insert("reach_rate".into(), report.reach_rate);
    v.insert("mean_task_reward".into(), s.mean_task_reward);
    v.insert("mean_style_reward".into(), s.mean_style_reward);
    for (key, value) in [
        ("amp/style_reward_std", s.style_reward_std),
        ("amp/task_reward_std", s.task_reward_std),
    ] {
        if value.is_finite() {
            v.insert(key.into(), value);
        }
    }
    for m in &update.metrics {
        v.insert(m.key.into(), m.value);
    }
    if let Some(a) = update.disc_accuracy {
        v.insert("amp/accuracy".into(), a);
    }
    v.insert("intake/accepted".into(), book.counters.accepted as f64);
    v.insert("intake/stale".into(), book.counters.stale as f64);
    v.insert("intake/rejected".into(), book.counters.rejected() as f64);
    v.insert("actors_alive".into(), book.actors_alive().len() as f64);
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<TrainConfig, ServiceError> {
        let path = std::env::temp_dir().join(format!(
            "lhm-train-config-{}-{}.toml",
            std::process::id(),
            text.len()
        ));
        std::fs::write(&path, text).unwrap();
        let out = TrainConfig::from_toml_file(&path);
        let _ = std::fs::remove_file(&path);
        out
    }

    #[test]
    fn toml_overrides_defaults_and_errors_name_the_field() {
        let c = parse("run_id = \"x\"\namp_enabled = false\n[ppo]\nepochs = 2\n").unwrap();
        assert_eq!(c.run_id, "x");
        assert_eq!(c.ppo.epochs, 2);
        assert_eq!(c.batch_steps, TrainConfig::default().batch_steps);
        // The rest of [ppo] keeps the run's defaults, not PpoConfig::default()'s.
        let d = TrainConfig::default();
        assert_eq!(c.ppo.value_clip, d.ppo.value_clip);
        assert_eq!(c.ppo.adam, d.ppo.adam);
        assert_eq!(c.ppo.minibatch_size, d.ppo.minibatch_size);
        let c2 = parse("[ppo.adam]\nlr = 1e-3\n[env]\nwalk_speed = 0.5\n").unwrap();
        assert_eq!(c2.ppo.adam.lr, 1e-3);
        assert_eq!(c2.ppo.adam.eps, d.ppo.adam.eps);
        assert_eq!(c2.ppo.epochs, d.ppo.epochs);
        assert_eq!(c2.env.demo_start_probability, d.env.demo_start_probability);
        let err = parse("[ppo.adam]\nlearning_rate = 1e-3\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("ppo.adam.learning_rate"), "{err}");
        // A misspelt reward weight is an error too, not a silently ignored key.
        let err = parse("[env.weights]\nlocomotoin = 1.0\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("locomotoin"), "{err}");
        assert!(c.learner_config().amp.is_none());
        assert_eq!(c.run_spec().amp_dim, 0);

        let err = parse("[ppo]\nepochs = \"six\"\n").unwrap_err().to_string();
        assert!(err.contains("ppo.epochs"), "{err}");
        let err = parse("bach_steps = 10\n").unwrap_err().to_string();
        assert!(err.contains("bach_steps"), "{err}");
        let err = parse("run_id = \n").unwrap_err().to_string();
        assert!(err.contains("lhm-train-config"), "{err}");
        assert!(parse("role = \"critic\"\n").unwrap().role().is_err());
    }

    /// The KL-adaptive rate is on by default; a file turns it off with 0 (TOML has no null).
    #[test]
    fn a_config_file_turns_the_default_kl_target_off_with_zero() {
        assert_eq!(TrainConfig::default().ppo.kl_target, Some(0.01));
        assert_eq!(
            parse("[ppo]\nkl_target = 0.0\n").unwrap().ppo.kl_target,
            Some(0.0)
        );
    }

    /// The config.toml a run writes reads back as the same configuration, options and
    /// non-default settings included.
    #[test]
    fn the_run_config_file_reads_back_as_the_run_config() {
        let mut c =
            parse("[env]\ndemo_start_toward_object = 0.75\n[ppo]\nkl_target = 0.02\n").unwrap();
        c.env.weights.locomotion = 0.5;
        c.amp.style_cap_floor = Some(0.4);
        let dir = std::env::temp_dir().join(format!("lhm-run-config-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = c.write_run_config(&dir).unwrap();
        let back = TrainConfig::from_toml_file(&path).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(back.env, c.env);
        assert_eq!(back.ppo.kl_target, Some(0.02));
        assert_eq!(
            toml::to_string(&back).unwrap(),
            toml::to_string(&c).unwrap()
        );
    }

    /// A teacher2 run names its Teacher 1 and a student run both teachers; one that does not fit
    /// the run's observations is refused naming the file; Teacher 1 runs need none.
    #[test]
    fn later_stages_need_fitting_teachers() {
        let mut config = TrainConfig {
            role: "teacher2".into(),
            ..TrainConfig::default()
        };
        let err = load_teachers(&config, Role::Teacher2).err().unwrap();
        assert!(err.to_string().contains("teacher1"), "{err}");
        assert!(load_teachers(&TrainConfig::default(), Role::Teacher1)
            .unwrap()
            .is_empty());

        let dir = std::env::temp_dir().join(format!("lhm-teacher1-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let spec = config.run_spec();
        let small = |obs_dim| LearnerConfig {
            obs_dim,
            act_dim: spec.act_dim,
            actor_critic: ActorCriticConfig::with_hidden(&[8]),
            ppo: PpoConfig::default(),
            amp: None,
        };
        Learner::new(small(spec.obs_dim - 1))
            .unwrap()
            .save_policy(&dir.join("wrong"))
            .unwrap();
        config.teacher1 = Some(dir.join("wrong.json"));
        let err = load_teachers(&config, Role::Teacher2).err().unwrap();
        assert!(
            err.to_string().contains("wrong") && err.to_string().contains("observations"),
            "{err}"
        );
        Learner::new(small(spec.obs_dim))
            .unwrap()
            .save_policy(&dir.join("right"))
            .unwrap();
        config.teacher1 = Some(dir.join("right"));
        let teachers = load_teachers(&config, Role::Teacher2).unwrap();
        assert_eq!(teachers.len(), 1);
        assert_eq!(teachers[0].0, Role::Teacher1);

        config.role = "student".into();
        let err = load_teachers(&config, Role::Student).err().unwrap();
        assert!(err.to_string().contains("teacher2"), "{err}");
        config.teacher2 = Some(dir.join("right"));
        let roles: Vec<Role> = load_teachers(&config, Role::Student)
            .unwrap()
            .into_iter()
            .map(|(r, _)| r)
            .collect();
        assert_eq!(roles, vec![Role::Teacher1, Role::Teacher2]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_negative_or_non_finite_bout_setting_is_refused_by_name() {
        let mut config = TrainConfig::default();
        for name in ["bout_distance", "bout_min_left", "pause_seconds"] {
            for (x, ok) in [
                (0.0, true),
                (2.0, true),
                (-0.5, false),
                (f32::NAN, false),
                (f32::INFINITY, false),
            ] {
                let mut g = lhm_sim::env::GaitConfig::default();
                match name {
                    "bout_distance" => g.bout_distance = x,
                    "bout_min_left" => g.bout_min_left = x,
                    _ => g.pause_seconds = x,
                }
                config.env.gait = Some(g);
                let result = config.check();
                assert_eq!(result.is_ok(), ok, "{name} {x}: {result:?}");
                if let Err(e) = result {
                    assert!(e.to_string().contains(&format!("env.gait.{name}")), "{e}");
                }
            }
        }
    }

    const STAGED: &str = r#"
run_id = "staged"
amp_enabled = true
[network.policy]
log_std = { fixed = -4.0 }
[env.gait]
stop_distance = 0.7
stop_on = "feet-down"
start_distance = 1.2
start_distance_max = 5.0
rest_start_fraction = 0.5

[[stages]]
until_iteration = 100
amp_enabled = false
log_std = -3.5
[stages.env.gait]
rest_start_fraction = 1.0
stop_on = "distance"

[[stages]]
until_iteration = 200
[stages.env.gait]
start_distance_max = 0.0
"#;

    #[test]
    fn stages_set_noise_amp_and_env_by_iteration_and_the_runs_own_follow() {
        use lhm_sim::env::StopOn;
        let config = parse(STAGED).unwrap();
        config.check().unwrap();
        let own = config.run_spec();
        assert!(own.amp_dim > 0);
        let gait = |s: &StageSettings| s.spec.env.gait.clone().unwrap();
        for it in [0, 99] {
            let s = config.stage_at(it).unwrap();
            assert_eq!(s.index, Some(0));
            assert!(!s.amp_active);
            assert_eq!(s.log_std, Some(lhm_nets::LogStd::Fixed(-3.5)));
            assert_eq!(
                s.spec.actor_critic.policy.log_std,
                lhm_nets::LogStd::Fixed(-3.5)
            );
            // The stage's keys, the run's others; the widths stay the run's.
            assert_eq!(gait(&s).rest_start_fraction, 1.0);
            assert_eq!(gait(&s).stop_on, StopOn::Distance);
            assert_eq!(gait(&s).stop_distance, 0.7);
            assert_eq!(gait(&s).start_distance_max, 5.0);
            assert_eq!((s.spec.obs_dim, s.spec.amp_dim), (own.obs_dim, own.amp_dim));
        }
        let s = config.stage_at(150).unwrap();
        assert_eq!(s.index, Some(1));
        assert!(s.amp_active);
        assert_eq!(s.log_std, Some(lhm_nets::LogStd::Fixed(-4.0)));
        assert_eq!(gait(&s).rest_start_fraction, 0.5);
        assert_eq!(gait(&s).stop_on, StopOn::FeetDown);
        assert_eq!(gait(&s).start_distance_max, 0.0);
        for it in [200, 1_000_000] {
            let s = config.stage_at(it).unwrap();
            assert_eq!(s.index, None);
            assert!(s.amp_active);
            assert_eq!(s.spec, own);
        }
        // The run directory's config.toml keeps the schedule.
        let dir = std::env::temp_dir().join(format!("lhm-staged-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = config.write_run_config(&dir).unwrap();
        assert_eq!(TrainConfig::from_toml_file(&path).unwrap(), config);
        let _ = std::fs::remove_dir_all(&dir);
        // A run whose AMP is on only in a stage still has the discriminator throughout.
        let late = parse(
            "amp_enabled = false\n[[stages]]\nuntil_iteration = 5\n\
             [[stages]]\nuntil_iteration = 9\namp_enabled = true\n",
        )
        .unwrap();
        assert!(late.amp_present() && late.learner_config().amp.is_some());
        assert!(!late.stage_at(0).unwrap().amp_active);
        assert!(late.stage_at(5).unwrap().amp_active);
        assert!(!late.stage_at(9).unwrap().amp_active);
        assert!(late.run_spec().amp_dim > 0);
    }

    #[test]
    fn stages_out_of_order_or_out_of_range_are_refused_by_name() {
        let head =
            "[network.policy]\nlog_std = { fixed = -4.0 }\n[env.gait]\nstop_distance = 0.7\n";
        for (stages, refused) in [
            (
                "[[stages]]\nuntil_iteration = 0\n",
                "stages[0].until_iteration",
            ),
            (
                "[[stages]]\nuntil_iteration = 20\n[[stages]]\nuntil_iteration = 20\n",
                "stages[1].until_iteration",
            ),
            (
                "[[stages]]\nuntil_iteration = 10\n[stages.env.gait]\nrest_start_fraction = 1.5\n",
                "stages[0].env.gait.rest_start_fraction",
            ),
            (
                "[[stages]]\nuntil_iteration = 10\n[[stages]]\nuntil_iteration = 20\n\
                 [stages.env.gait]\nstart_distance_max = -1.0\n",
                "stages[1].env.gait.start_distance_max",
            ),
            (
                "[[stages]]\nuntil_iteration = 10\n[stages.env]\nno_such_key = 1\n",
                "stages[0].env: field `no_such_key`",
            ),
            (
                "[[stages]]\nuntil_iteration = 10\n[stages.env]\nmap_cells = 3\n",
                "stages[0].env gives",
            ),
            (
                "[[stages]]\nuntil_iteration = 10\nlog_std = nan\n",
                "stages[0].log_std",
            ),
            (
                "[[stages]]\nuntil_iteration = 10\nno_such_key = 1\n",
                "no_such_key",
            ),
        ] {
            let result = parse(&format!("{head}{stages}")).and_then(|c| c.check());
            match result {
                Err(e) => assert!(e.to_string().contains(refused), "{refused}: {e}"),
                Ok(()) => panic!("{refused}: accepted"),
            }
        }
        let learned = parse(
            "[network.policy]\nlog_std = { learned = -1.0 }\n\n\
             [[stages]]\nuntil_iteration = 10\nlog_std = -3.5\n",
        )
        .unwrap();
        assert_eq!(
            learned.network.policy.log_std,
            lhm_nets::LogStd::Learned(-1.0)
        );
        let per_dim = parse("[network.policy]\nlog_std = { per_dim = [-4.5, -2.5] }\n").unwrap();
        assert_eq!(
            per_dim.network.policy.log_std,
            lhm_nets::LogStd::PerDim(vec![-4.5, -2.5])
        );
        let e = learned.check().unwrap_err().to_string();
        assert!(
            e.contains("stages[0].log_std") && e.contains("learned"),
            "{e}"
        );
    }

    #[test]
    fn a_stage_whose_gait_names_no_dof_or_a_non_finite_offset_is_refused_at_check() {
        let text = |offsets: &str| {
            format!(
                "[env.gait]\nangle_offsets = {{ right_knee = [0.1] }}\n\n\
                 [[stages]]\nuntil_iteration = 10\n\n\
                 [stages.env.gait]\nangle_offsets = {{ {offsets} }}\n"
            )
        };
        let load = |t: String| TrainConfig::from_toml_sources(&[("run.toml".to_owned(), t)]);
        load(text("left_knee = [0.2, 0.3]"))
            .expect("a stage with good offsets loads")
            .check()
            .expect("and checks");
        for (offsets, names) in [
            ("left_kne = [0.2]", "angle_offsets.left_kne"),
            ("left_knee = [nan]", "angle_offsets.left_knee"),
        ] {
            let result = load(text(offsets)).and_then(|c| c.check());
            let e = result.expect_err(offsets).to_string();
            assert!(e.contains("stages[0].env.gait") && e.contains(names), "{e}");
        }
        let mut config = TrainConfig::default();
        let mut gait = lhm_sim::env::GaitConfig::default();
        gait.residual_joints.insert("elbw".into(), 0.0);
        config.env.gait = Some(gait);
        let e = config
            .check()
            .expect_err("no DoF named like elbw")
            .to_string();
        assert!(
            e.contains("env.gait") && e.contains("residual_joints.elbw"),
            "{e}"
        );
    }

    #[test]
    fn named_envs_are_the_runs_then_each_stage_at_its_end_and_stages_out_of_order_are_refused() {
        let text = |second: u64| {
            format!(
                "[env]\nmax_episode_steps = 100\n\n\
                 [[stages]]\nuntil_iteration = 10\n\n\
                 [stages.env]\nmax_episode_steps = 200\n\n\
                 [[stages]]\nuntil_iteration = {second}\n\n\
                 [stages.env]\nwalk_speed = 0.5\n"
            )
        };
        let load = |t: String| TrainConfig::from_toml_sources(&[("run.toml".to_owned(), t)]);
        let config = load(text(20)).expect("two ordered stages load");
        let envs = config.named_envs().expect("every stage's settings resolve");
        let named: Vec<(&str, u32, f32)> = envs
            .iter()
            .map(|(at, env)| (at.as_str(), env.max_episode_steps, env.walk_speed))
            .collect();
        let speed = config.env.walk_speed;
        // Each stage lays over the run's own [env], not over the stage before.
        assert_eq!(
            named,
            [
                ("env", 100, speed),
                ("stages[0].env", 200, speed),
                ("stages[1].env", 100, 0.5)
            ]
        );
        config.check().expect("and checks");
        let e = load(text(10))
            .and_then(|c| c.check())
            .expect_err("a stage ending where the one before ends")
            .to_string();
        assert!(
            e.contains("stages[1].until_iteration must be above the stage before's (10)"),
            "{e}"
        );
    }

    #[test]
    fn a_start_fraction_outside_zero_to_one_is_refused_by_name() {
        let mut config = TrainConfig::default();
        let with = |name: &str, f: f32| {
            let mut g = lhm_sim::env::GaitConfig::default();
            match name {
                "near_start_fraction" => g.near_start_fraction = f,
                _ => g.rest_start_fraction = f,
            }
            Some(g)
        };
        for name in ["near_start_fraction", "rest_start_fraction"] {
            for (f, ok) in [
                (0.0, true),
                (0.5, true),
                (1.0, true),
                (1.5, false),
                (-0.1, false),
                (f32::NAN, false),
            ] {
                config.env.gait = with(name, f);
                let result = config.check();
                assert_eq!(result.is_ok(), ok, "{name} {f}: {result:?}");
                if let Err(e) = result {
                    assert!(e.to_string().contains(name), "{e}");
                }
            }
        }
    }

    #[test]
    fn name_keyed_tables_merge_across_files_while_a_one_key_enum_switches_variant() {
        let sources = |texts: &[&str]| -> Vec<(String, String)> {
            texts
                .iter()
                .enumerate()
                .map(|(i, t)| (format!("file{i}.toml"), t.to_string()))
                .collect()
        };
        let config = TrainConfig::from_toml_sources(&sources(&[
            "[env.gait]\nresidual_joints = { shoulder = 0.0 }\n\n\
             [env.gait.stop]\nseconds = 0.5\n\n\
             [amp.accuracy_target]\naccuracy = 0.7\n\n\
             [network.policy]\nlog_std = { fixed = -4.0 }\n",
            "[env.gait]\nresidual_joints = { elbow = 0.5 }\n\n\
             [env.gait.stop]\nfeedback = 0.25\n\n\
             [amp.accuracy_target]\nfactor = 1.1\n\n\
             [network.policy]\nlog_std = { learned = -1.0 }\n",
        ]))
        .unwrap();
        let gait = config.env.gait.as_ref().unwrap();
        let joints = &gait.residual_joints;
        assert_eq!(joints.get("shoulder"), Some(&0.0), "{joints:?}");
        assert_eq!(joints.get("elbow"), Some(&0.5), "{joints:?}");
        assert_eq!(joints.len(), 2, "{joints:?}");
        // One-key struct tables in two files (the run's default has no [env.gait] at all, so
        // each file's table has the one key it writes) merge as well.
        assert_eq!(gait.stop.seconds, 0.5, "{:?}", gait.stop);
        assert_eq!(gait.stop.feedback, 0.25, "{:?}", gait.stop);
        let target = config.amp.accuracy_target.unwrap();
        assert_eq!((target.accuracy, target.factor), (0.7, 1.1), "{target:?}");
        assert_eq!(
            config.network.policy.log_std,
            lhm_nets::LogStd::Learned(-1.0)
        );
    }

    /// The overlay replaces a one-key table where the schema's default is a one-key table; that
    /// is right only for enums. Every such table must refuse `{}` (an enum needs its variant; a
    /// struct with defaults or a map would take it): a one-field struct added to the config
    /// fails here, naming its path, instead of silently losing keys between files.
    #[test]
    fn every_one_key_table_in_the_overlay_schema_is_an_enum() {
        fn one_key_tables(table: &toml::Table, path: &str, out: &mut Vec<String>) {
            for (key, value) in table {
                let at = if path.is_empty() {
                    key.clone()
                } else {
                    format!("{path}.{key}")
                };
                if let toml::Value::Table(t) = value {
                    if t.len() == 1 {
                        out.push(at.clone());
                    }
                    one_key_tables(t, &at, out);
                }
            }
        }
        let schema = overlay_schema().unwrap();
        let mut paths = Vec::new();
        one_key_tables(&schema, "", &mut paths);
        assert!(
            paths.iter().any(|p| p == "network.policy.log_std"),
            "the schema should hold log_std's variant table: {paths:?}"
        );
        for path in &paths {
            let mut emptied = schema.clone();
            let mut at = &mut emptied;
            let keys: Vec<&str> = path.split('.').collect();
            for key in &keys[..keys.len() - 1] {
                at = at.get_mut(*key).unwrap().as_table_mut().unwrap();
            }
            at.insert(
                keys[keys.len() - 1].to_string(),
                toml::Value::Table(toml::Table::new()),
            );
            let read: Result<TrainConfig, _> = toml::Value::Table(emptied).try_into();
            assert!(
                read.is_err(),
                "{path} is a one-key table in the defaults that reads from {{}}: not an enum, \
                 so overlay() would replace it between files instead of merging"
            );
        }
    }

    #[test]
    fn demo_weights_read_key_by_key_and_bad_ones_are_refused_by_name() {
        let dir = std::env::temp_dir().join(format!("lhm-demo-weights-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("walks.toml");
        std::fs::write(&path, "[amp.demo_weights]\nomomo = 0.0\n").unwrap();
        let config = TrainConfig::from_toml_file(&path).unwrap();
        assert_eq!(
            config.amp.demo_weights,
            lhm_sim::motion::SourceWeights {
                deepmimic: 1.0,
                omomo: 0.0
            }
        );
        assert!(config.check().is_ok());
        std::fs::write(&path, "[amp.demo_weights]\nomomo = 0.0\ndeepmimic = 0.0\n").unwrap();
        let err = TrainConfig::from_toml_file(&path)
            .unwrap()
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains("amp.demo_weights"), "{err}");
        std::fs::write(&path, "[amp.demo_weights]\ncarry = 1.0\n").unwrap();
        let err = TrainConfig::from_toml_file(&path).unwrap_err().to_string();
        assert!(err.contains("walks.toml") && err.contains("carry"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A run directory made by another role is refused before anything in it changes.
    #[test]
    fn a_run_directory_of_another_role_is_refused() {
        let dir = std::env::temp_dir().join(format!("lhm-role-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let teacher = TrainConfig::default();
        teacher.write_run_config(&dir).unwrap();
        let before = std::fs::read_to_string(dir.join(RUN_CONFIG_FILE)).unwrap();
        refuse_another_role(&teacher, &dir).unwrap();
        let student = TrainConfig {
            role: "student".into(),
            ..TrainConfig::default()
        };
        let e = refuse_another_role(&student, &dir).unwrap_err().to_string();
        assert!(e.contains("teacher1 run") && e.contains("--run-id"), "{e}");
        assert_eq!(
            std::fs::read_to_string(dir.join(RUN_CONFIG_FILE)).unwrap(),
            before
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A resume under another schedule keeps the configuration that trained the iterations
    /// before it as `config.until-<iteration>.toml`; one that changes only session keys keeps
    /// nothing; a second resume at the same iteration leaves the kept file alone.
    #[test]
    fn a_resume_under_another_configuration_keeps_the_earlier_one() {
        let runs = std::env::temp_dir().join(format!("lhm-resume-config-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&runs);
        let first = TrainConfig {
            run_id: "r".into(),
            runs_dir: runs.clone(),
            network: ActorCriticConfig::with_hidden(&[8]),
            amp_enabled: false,
            ..TrainConfig::default()
        };
        let dir = first.run_dir();
        let (mut learner, resumed) = open_learner(&first, &dir).unwrap();
        assert_eq!(resumed, None);
        learner.counters.iteration = 7;
        learner.save(&checkpoint_stem(&dir)).unwrap();
        let kept = run_config::earlier_config_path(&dir, 7);

        let longer = TrainConfig {
            max_iterations: Some(20),
            ..first.clone()
        };
        assert_eq!(open_learner(&longer, &dir).unwrap().1, Some(7));
        assert!(!kept.exists(), "only a session key changed");
        let saved = std::fs::read_to_string(dir.join(RUN_CONFIG_FILE)).unwrap();

        let staged = TrainConfig {
            stages: vec![RunStage {
                until_iteration: 9,
                amp_enabled: Some(false),
                ..RunStage::default()
            }],
            ..first.clone()
        };
        let change = keep_earlier_config(&staged, &dir, 7).unwrap().unwrap();
        assert_eq!(change.keys, vec!["stages (0 entries → 1 entry)".to_owned()]);
        let _ = std::fs::remove_file(&kept);
        assert_eq!(open_learner(&staged, &dir).unwrap().1, Some(7));
        assert_eq!(std::fs::read_to_string(&kept).unwrap(), saved);
        assert_eq!(
            TrainConfig::from_toml_file(&dir.join(RUN_CONFIG_FILE)).unwrap(),
            staged
        );
        // Resumed again at 7 under a third configuration: the file of what trained 0..7 stays.
        let third = TrainConfig {
            batch_steps: first.batch_steps * 2,
            ..first.clone()
        };
        assert_eq!(open_learner(&third, &dir).unwrap().1, Some(7));
        assert_eq!(std::fs::read_to_string(&kept).unwrap(), saved);
        let _ = std::fs::remove_dir_all(&runs);
    }

    /// A fine-tuning run starts acting exactly as the checkpoint it starts from; a checkpoint of
    /// another layout is refused naming the tensor.
    #[test]
    fn init_from_copies_the_policy_and_refuses_another_layout() {
        let dir = std::env::temp_dir().join(format!("lhm-init-from-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let config = |hidden: &[usize], seed| LearnerConfig {
            obs_dim: 6,
            act_dim: 3,
            actor_critic: ActorCriticConfig {
                init_seed: seed,
                normalize_value: true,
                ..ActorCriticConfig::with_hidden(hidden)
            },
            ppo: PpoConfig::default(),
            amp: None,
        };
        let mut source = Learner::new(config(&[8], 1)).unwrap();
        let obs: Vec<f32> = (0..12).map(|i| (i as f32 * 0.7).sin()).collect();
        if let Some(norm) = &mut source.actor_critic.obs_norm {
            norm.update(&obs).unwrap();
        }
        source.save_policy(&dir.join("t1")).unwrap();
        let mut fresh = Learner::new(config(&[8], 2)).unwrap();
        assert_ne!(
            fresh.actor_critic.act_deterministic(&obs).unwrap(),
            source.actor_critic.act_deterministic(&obs).unwrap()
        );
        init_actor_critic(&mut fresh, &dir.join("t1.json")).unwrap();
        assert_eq!(
            fresh.actor_critic.act_deterministic(&obs).unwrap(),
            source.actor_critic.act_deterministic(&obs).unwrap()
        );
        assert_eq!(fresh.counters.iteration, 0, "a new run, not a resumed one");
        let mut other = Learner::new(config(&[4], 2)).unwrap();
        let err = init_actor_critic(&mut other, &dir.join("t1")).unwrap_err();
        assert!(
            err.to_string().contains("t1") && err.to_string().contains("policy.mean"),
            "{err}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
