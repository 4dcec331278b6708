//! `lhm pipeline`: the paper's stages in order — `t1` → `t1-rr` → `t2` → `student` → eval — or a
//! baseline's (`e2e`; `t1` → `curriculum`), each a run of the same local actor–learner cluster as
//! `lhm train` (`Stage` presets its configuration), in
//! `<runs dir>/<pipeline>/<stage>/`. A stage whose status says it reached its budget is skipped
//! and an unfinished one resumes from its checkpoint, so running the command again continues
//! the pipeline wherever it stopped (Ctrl-C, SIGKILL, power loss).

use crate::cluster_cmd::{demo_for, train_locally, LocalCluster};
use anyhow::{bail, Context, Result};
use clap::Args;
use lhm_cluster::shutdown;
use lhm_learner::service::stage::Stage;
use lhm_learner::service::TrainConfig;
use serde::Deserialize;
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct PipelineArgs {
    /// The pipeline (TOML; see configs/pipeline-smoke.toml). Default: the laptop pipeline built
    /// in (`PipelineConfig::default`).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Directory of runs: the pipeline lives in RUNS_DIR/<name>/ (default `runs`).
    #[arg(long, default_value = "runs")]
    runs_dir: PathBuf,
    /// Actor processes per stage (default: the config's, else one per CPU core).
    #[arg(long)]
    actors: Option<usize>,
    /// Where `scripts/install-motions` put the clips (default: $LHM_MOTION_DIR or ~/.cache/lhm/motions).
    #[arg(long)]
    motion_dir: Option<PathBuf>,
    /// A training configuration laid over every stage's own, key by key (e.g. smaller networks
    /// for a quick look at a method's pipeline).
    #[arg(long)]
    overlay: Option<PathBuf>,
    /// Multiply every stage's iteration budget by this (each stays at least 1): the same pipeline
    /// at another budget, in the same proportions.
    #[arg(long, value_parser = positive_scale)]
    budget_scale: Option<f64>,
    #[command(flatten)]
    scenes: crate::scenes_cmd::Source,
}

fn positive_scale(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        _ => Err(format!("{text:?} is not a positive number")),
    }
}

/// One training stage of the pipeline.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageConfig {
    /// `t1`, `t1-rr`, `t2`, `student`, `vla`, or the baselines' `e2e`, `curriculum` and
    /// `hierarchical`.
    pub stage: String,
    /// The stage's training configuration (a `lhm train --config` file, relative to the
    /// pipeline file); absent: the built-in default.
    #[serde(default)]
    pub config: Option<PathBuf>,
    /// The stage's budget: iterations in all (PPO updates; the student's DAgger rounds).
    pub iterations: u64,
}

/// The evaluation at the end: the last Teacher 1 policy on each split's first pairs.
#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EvalConfig {
    pub splits: Vec<String>,
    pub seeds: u64,
    /// Only the first N tasks of each split (absent: all).
    pub limit: Option<usize>,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            splits: vec!["train".into(), "unseen".into()],
            seeds: 1,
            limit: None,
        }
    }
}

#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PipelineConfig {
    /// The pipeline's directory name under the runs directory.
    pub name: String,
    /// How `lhm tables` names the method (default: the name).
    pub label: Option<String>,
    pub actors: Option<usize>,
    /// Environments per actor process.
    pub envs: usize,
    /// The stages, in order.
    #[serde(rename = "stage")]
    pub stages: Vec<StageConfig>,
    pub eval: EvalConfig,
}

impl Default for PipelineConfig {
    /// The laptop pipeline: ~1 h of Teacher 1 and ~15-25 min each of fine-tuning, Teacher 2 and
    /// the student on 2 cores (measured at a third of these budgets, configs/pipeline-hour.toml:
    /// ~1,500, ~1,400, ~800 and ~1,200 samples/s; RESULTS.md).
    fn default() -> Self {
        let stage = |stage: &str, iterations| StageConfig {
            stage: stage.into(),
            config: None,
            iterations,
        };
        Self {
            name: "pipeline".into(),
            label: None,
            actors: None,
            envs: 16,
            stages: vec![
                stage("t1", 1200),
                stage("t1-rr", 300),
                stage("t2", 300),
                stage("student", 300),
            ],
            eval: EvalConfig::default(),
        }
    }
}

impl PipelineConfig {
    pub fn from_toml_file(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let mut config: Self =
            toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        let base = path.parent().unwrap_or(Path::new("."));
        for s in &mut config.stages {
            if let Some(c) = &mut s.config {
                if c.is_relative() {
                    *c = base.join(&*c);
                }
            }
        }
        config
            .check()
            .with_context(|| format!("in {}", path.display()))?;
        Ok(config)
    }

    /// The stages in an order that can run: each known, each budget positive, `t1-rr` after a
    /// `t1`, `t2` and `curriculum` after a Teacher 1 stage and no Teacher 1 stage after `t2`,
    /// `student` after `t2`, `e2e` alone, each stage at most once.
    pub fn check(&self) -> Result<Vec<Stage>> {
        lhm_protos::keys::check_chunk("pipeline name", &self.name)?;
        if self.envs == 0 {
            bail!("envs must be at least 1");
        }
        if self.actors == Some(0) {
            bail!("actors must be at least 1");
        }
        if self.stages.is_empty() {
            bail!("no [[stage]]: list t1, t1-rr, t2, student in order (or a baseline's stages)");
        }
        let mut seen: Vec<Stage> = Vec::new();
        for (i, s) in self.stages.iter().enumerate() {
            let stage = Stage::parse(&s.stage).with_context(|| format!("stage {}", i + 1))?;
            if s.iterations == 0 {
                bail!(
                    "stage {} ({}): iterations must be at least 1",
                    i + 1,
                    s.stage
                );
            }
            if seen.contains(&stage) {
                bail!("stage {} ({}) is listed twice", i + 1, s.stage);
            }
            if seen.contains(&Stage::T2) && matches!(stage, Stage::T1 | Stage::T1Rr) {
                // The student and the "T" rows pair the last Teacher 1 with t2, which must have
                // started from that very Teacher 1's terminal states.
                bail!(
                    "stage {} ({}) needs to come before t2 (t2 starts from the last Teacher 1's \
                     terminal states)",
                    i + 1,
                    s.stage
                );
            }
            let needs = match stage {
                Stage::T1 => None,
                Stage::T1Rr => (!seen.contains(&Stage::T1)).then_some("a t1 stage before it"),
                Stage::T2 => (!seen.iter().any(|s| matches!(s, Stage::T1 | Stage::T1Rr)))
                    .then_some("a Teacher 1 stage (t1 or t1-rr) before it"),
                Stage::Student => (!seen.contains(&Stage::T2))
                    .then_some("a t2 stage (and a Teacher 1 stage) before it"),
                // Distilled from the deployable policy: the student, or a baseline's one policy.
                Stage::Vla => (!seen.iter().any(|s| {
                    matches!(
                        s,
                        Stage::Student | Stage::E2e | Stage::Curriculum | Stage::Hierarchical
                    )
                }))
                .then_some(
                    "a student (or e2e, curriculum, hierarchical) stage before it: the VLA is \
                     distilled from it",
                ),
                Stage::E2e | Stage::Hierarchical => (!seen.is_empty())
                    .then_some("to be the only stage (it trains one policy from scratch)"),
                Stage::Curriculum => (!seen.iter().any(|s| matches!(s, Stage::T1 | Stage::T1Rr)))
                    .then_some("a Teacher 1 stage (t1 or t1-rr) before it"),
            };
            if let Some(what) = needs {
                bail!("stage {} ({}) needs {what}", i + 1, s.stage);
            }
            seen.push(stage);
        }
        if self.eval.seeds == 0 {
            bail!("eval.seeds must be at least 1");
        }
        Ok(seen)
    }
}

/// The iteration a run's `status.json` reports (0 when the run has not written one yet).
fn iterations_done(run_dir: &Path) -> Result<u64> {
    let path = run_dir.join("status.json");
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
    };
    let json: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    Ok(json.get("iteration").and_then(|v| v.as_u64()).unwrap_or(0))
}

/// What `<runs dir>/<pipeline>/pipeline.json` records of the pipeline that made the directory,
/// for `lhm tables`: its method label, stages and budgets.
#[derive(Debug, Clone, serde::Serialize, Deserialize)]
pub struct Manifest {
    pub name: String,
    pub label: String,
    /// (stage, iteration budget) in order, after `--budget-scale`.
    pub stages: Vec<(String, u64)>,
    pub budget_scale: Option<f64>,
    pub overlay: Option<PathBuf>,
}

pub const MANIFEST_FILE: &str = "pipeline.json";

/// A stage budget under `--budget-scale` (at least 1).
fn scaled(iterations: u64, scale: Option<f64>) -> u64 {
    match scale {
        Some(scale) => ((iterations as f64 * scale).round() as u64).max(1),
        None => iterations,
    }
}

fn write_manifest(root: &Path, config: &PipelineConfig, args: &PipelineArgs) -> Result<()> {
    let manifest = Manifest {
        name: config.name.clone(),
        label: config.label.clone().unwrap_or_else(|| config.name.clone()),
        stages: config
            .stages
            .iter()
            .map(|s| (s.stage.clone(), scaled(s.iterations, args.budget_scale)))
            .collect(),
        budget_scale: args.budget_scale,
        overlay: args.overlay.clone(),
    };
    let path = root.join(MANIFEST_FILE);
    let tmp = root.join(format!("{MANIFEST_FILE}.tmp"));
    std::fs::write(&tmp, serde_json::to_vec_pretty(&manifest)?)
        .and_then(|()| std::fs::rename(&tmp, &path))
        .with_context(|| format!("writing {}", path.display()))
}

/// Exit status of a pipeline stopped by SIGINT/SIGTERM before it finished (128 + SIGINT, as a
/// shell reports Ctrl-C), so scripts can tell it from a finished one.
pub const STOPPED_EXIT: u8 = 130;

/// Runs (or continues) the pipeline; `Ok(false)` when a stop request cut it short.
pub fn run(args: PipelineArgs) -> Result<bool> {
    shutdown::install();
    let config = match &args.config {
        Some(path) => PipelineConfig::from_toml_file(path)?,
        None => PipelineConfig::default(),
    };
    let stages = config.check()?;
    let root = args.runs_dir.join(&config.name);
    std::fs::create_dir_all(&root).with_context(|| format!("creating {}", root.display()))?;
    write_manifest(&root, &config, &args)?;
    let local = LocalCluster {
        actors: args.actors.or(config.actors),
        envs: config.envs,
        port: 0,
        zenoh_config: None,
    };
    let started = std::time::Instant::now();
    // The Teacher 1 policy later stages start from: t1's, then t1-rr's once that has run.
    let mut teacher1: Option<PathBuf> = None;
    let mut teacher2: Option<PathBuf> = None;
    let mut student: Option<PathBuf> = None;
    let mut vla: Option<PathBuf> = None;
    // A baseline's one policy for every cycle (e2e, curriculum, hierarchical).
    let mut single: Option<PathBuf> = None;
    let mut upstream_trained = false;
    for (spec, stage) in config.stages.iter().zip(&stages) {
        let files: Vec<&Path> = spec
            .config
            .iter()
            .chain(&args.overlay)
            .map(|p| p.as_path())
            .collect();
        let mut train = if files.is_empty() {
            TrainConfig::default()
        } else {
            TrainConfig::from_toml_files(&files)?
        };
        let budget = scaled(spec.iterations, args.budget_scale);
        train.run_id = stage.name().into();
        train.runs_dir = root.clone();
        train.max_iterations = Some(budget);
        if args.scenes.scenes.is_some() {
            train.scenes.clone_from(&args.scenes.scenes);
        }
        let labeller2 = if *stage == Stage::Student {
            teacher2.as_deref()
        } else {
            None
        };
        // The VLA's labeller is the unified student (a baseline's: its one policy).
        let labeller1 = if *stage == Stage::Vla {
            student.as_deref().or(single.as_deref())
        } else {
            teacher1.as_deref()
        };
        stage.apply(&mut train, labeller1, labeller2)?;
        train.check()?;
        let dir = train.run_dir();
        let done = iterations_done(&dir)?;
        if done > 0 && upstream_trained {
            // Its start (an earlier stage's policy) changed in this session; it is not redone.
            println!(
                "stage {}: warning: made from an earlier stage's policy before that stage trained \
                 further; delete {} to redo it from the new one",
                stage.name(),
                dir.display()
            );
        }
        if done >= budget {
            println!(
                "stage {}: finished ({done} of {budget} iterations) in {}",
                stage.name(),
                dir.display()
            );
        } else {
            println!(
                "stage {}: {} to iteration {budget} in {}",
                stage.name(),
                if done > 0 { "resuming" } else { "training" },
                dir.display()
            );
            upstream_trained = true;
            let demo = demo_for(args.motion_dir.clone(), &train)?;
            train_locally(train, demo, &local)
                .with_context(|| format!("stage {}", stage.name()))?;
            if shutdown::requested() {
                println!(
                    "pipeline {} stopped in stage {}; run the same command again to continue",
                    config.name,
                    stage.name()
                );
                return Ok(false);
            }
            let reached = iterations_done(&dir)?;
            if reached < budget {
                bail!(
                    "stage {} stopped at iteration {reached} of {budget} without being asked to",
                    stage.name()
                );
            }
        }
        crate::plot_cmd::plot_run(&dir)
            .with_context(|| format!("stage {}: curves", stage.name()))?;
        let policy = Some(dir.join("policy"));
        match stage {
            Stage::T1 | Stage::T1Rr => teacher1 = policy,
            Stage::T2 => teacher2 = policy,
            Stage::Student => student = policy,
            Stage::Vla => vla = policy,
            Stage::E2e | Stage::Curriculum | Stage::Hierarchical => single = policy,
        }
    }
    let policies = Policies {
        teacher1: teacher1.as_deref(),
        teacher2: teacher2.as_deref(),
        student: student.as_deref(),
        vla: vla.as_deref(),
        single: single.as_deref(),
    };
    evaluate(&config, &root, &policies, &args.scenes)?;
    if shutdown::requested() {
        println!(
            "pipeline {} stopped in eval; run the same command again to continue",
            config.name
        );
        return Ok(false);
    }
    if !config.eval.splits.is_empty() {
        let summary = eval_summary(&config, &root, &policies)?;
        let path = root.join("eval").join("summary.md");
        std::fs::write(&path, &summary).with_context(|| format!("writing {}", path.display()))?;
        println!("\n{summary}");
    }
    println!(
        "pipeline {}: every stage finished ({:.0} s this session); runs in {}",
        config.name,
        started.elapsed().as_secs_f64(),
        root.display()
    );
    Ok(true)
}

/// Every evaluation of the pipeline in one Markdown table per split (the paper's columns for two
/// objects; a first-pair row has no second cycle), from the `table.json` files `evaluate` wrote.
fn eval_summary(config: &PipelineConfig, root: &Path, policies: &Policies<'_>) -> Result<String> {
    let mut out = String::new();
    for split in &config.eval.splits {
        out.push_str(&format!(
            "### {} on `{split}` ({} seed{} per task)\n\n| Row | Success 1 (%) | Success 2 (%) | \
             Success All (%) | Dist 1 (m) | Dist 2 (m) | Falls (%) | Tasks |\n|---|---|---|---|---|---|---|---|\n",
            config.name,
            config.eval.seeds,
            if config.eval.seeds == 1 { "" } else { "s" }
        ));
        for row in policies.rows() {
            let path = root
                .join("eval")
                .join(split)
                .join(row.name)
                .join("table.json");
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("reading {}", path.display()))?;
            let t: serde_json::Value = serde_json::from_str(&text)
                .with_context(|| format!("parsing {}", path.display()))?;
            let cell = |key: &str, scale: f64, digits: usize| match (
                t.get(key).and_then(|v| v.as_f64()),
                t.get(format!("{key}_std")).and_then(|v| v.as_f64()),
            ) {
                (Some(m), Some(s)) => {
                    format!("{:.digits$} ± {:.digits$}", m * scale, s * scale)
                }
                _ => "—".into(),
            };
            out.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
                row.name,
                cell("success_1", 100.0, 1),
                cell("success_2", 100.0, 1),
                cell("success_all", 100.0, 1),
                cell("dist_1", 1.0, 2),
                cell("dist_2", 1.0, 2),
                cell("fall_rate", 100.0, 1),
                t.get("tasks").and_then(|v| v.as_u64()).unwrap_or(0)
            ));
        }
        out.push('\n');
    }
    Ok(out)
}

/// The policies the pipeline's stages left.
pub(crate) struct Policies<'a> {
    pub teacher1: Option<&'a Path>,
    pub teacher2: Option<&'a Path>,
    pub student: Option<&'a Path>,
    pub vla: Option<&'a Path>,
    pub single: Option<&'a Path>,
}

/// One evaluation of a pipeline: its directory name under `eval/<split>/`, the policy, the
/// Teacher 1 that plays first cycles (the "T" rows), whether only first pairs are played.
pub(crate) struct EvalRow<'a> {
    pub name: &'static str,
    pub policy: &'a Path,
    pub teacher1: Option<&'a Path>,
    pub first_pair: bool,
    /// A VLA row with its instructions blanked (the language ablation).
    pub no_language: bool,
}

impl<'a> Policies<'a> {
    /// The rows of the pipeline's evaluation: the last Teacher 1 on first pairs, the teachers
    /// through the switch, the student, a baseline's one policy — whichever the stages left.
    pub fn rows(&self) -> Vec<EvalRow<'a>> {
        let mut rows = Vec::new();
        if let Some(t1) = self.teacher1 {
            rows.push(EvalRow {
                name: "t1-first-pair",
                policy: t1,
                teacher1: None,
                first_pair: true,
                no_language: false,
            });
            if let Some(t2) = self.teacher2 {
                rows.push(EvalRow {
                    name: "teachers",
                    policy: t2,
                    teacher1: Some(t1),
                    first_pair: false,
                    no_language: false,
                });
            }
        }
        if let Some(s) = self.student {
            rows.push(EvalRow {
                name: "student",
                policy: s,
                teacher1: None,
                first_pair: false,
                no_language: false,
            });
        }
        if let Some(v) = self.vla {
            for no_language in [false, true] {
                rows.push(EvalRow {
                    name: if no_language {
                        "vla-no-language"
                    } else {
                        "vla"
                    },
                    policy: v,
                    teacher1: None,
                    first_pair: false,
                    no_language,
                });
            }
        }
        if let Some(p) = self.single {
            rows.push(EvalRow {
                name: "policy",
                policy: p,
                teacher1: None,
                first_pair: false,
                no_language: false,
            });
        }
        rows
    }
}

/// `lhm eval` on each split for each of [`Policies::rows`] into `<pipeline>/eval/<split>/<row>/`:
/// Teacher 1 on first pairs (`t1-first-pair`), the paper's "T" row (Teacher 1 on the first
/// cycle, Teacher 2 on the later ones: `teachers`), its "S" row (the student through every
/// cycle: `student`), a baseline's one policy (`policy`). An evaluation whose table is already
/// there is skipped.
fn evaluate(
    config: &PipelineConfig,
    root: &Path,
    policies: &Policies<'_>,
    scenes: &crate::scenes_cmd::Source,
) -> Result<()> {
    let bench = scenes.load()?;
    for split in &config.eval.splits {
        for row in policies.rows() {
            let out = root.join("eval").join(split).join(row.name);
            let tasks = crate::eval_cmd::split_tasks(&bench, split)?.len();
            let tasks = config.eval.limit.map_or(tasks, |n| tasks.min(n));
            // Reused only when it evaluated these very policies: a stage trained further since
            // (a larger budget) is evaluated again.
            if crate::eval_cmd::table_is_current(
                &out,
                row.policy,
                row.teacher1,
                config.eval.seeds,
                Some(tasks),
            ) {
                println!(
                    "eval {split} {}: finished, table in {}",
                    row.name,
                    out.display()
                );
                continue;
            }
            if shutdown::requested() {
                return Ok(());
            }
            println!("eval {split} {}: {}", row.name, row.policy.display());
            crate::eval_cmd::run(crate::eval_cmd::EvalArgs {
                policy: row.policy.to_path_buf(),
                split: split.clone(),
                seeds: config.eval.seeds,
                first_pair: row.first_pair,
                teacher1: row.teacher1.map(Path::to_path_buf),
                stop_policy: None,
                limit: config.eval.limit,
                config: None,
                json: false,
                output: Some(out),
                batch: 64,
                gifs: 0,
                max_steps: None,
                action_std: 0.0,
                no_language: row.no_language,
                from_rest: false,
                scenes: scenes.clone(),
            })
            .with_context(|| format!("eval {split} {}", row.name))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Vec<Stage>> {
        let c: PipelineConfig = toml::from_str(text)?;
        c.check()
    }

    #[test]
    fn the_default_pipeline_and_a_smoke_file_are_valid() {
        assert_eq!(
            PipelineConfig::default().check().unwrap(),
            vec![Stage::T1, Stage::T1Rr, Stage::T2, Stage::Student]
        );
        let smoke = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/pipeline-smoke.toml");
        let c = PipelineConfig::from_toml_file(&smoke).unwrap();
        assert_eq!(c.stages.len(), 5);
        assert!(c
            .stages
            .iter()
            .all(|s| s.config.as_ref().is_some_and(|p| p.is_file())));
        // Every method of the tables, each a valid pipeline.
        let methods = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/methods");
        for (method, stages) in [
            (
                "lhm",
                &[Stage::T1, Stage::T1Rr, Stage::T2, Stage::Student][..],
            ),
            ("no-rr", &[Stage::T1, Stage::T2, Stage::Student][..]),
            (
                "no-amp",
                &[Stage::T1, Stage::T1Rr, Stage::T2, Stage::Student][..],
            ),
            ("e2e-rl", &[Stage::E2e][..]),
            ("curriculum-rl", &[Stage::T1, Stage::Curriculum][..]),
            ("hierarchical-rl", &[Stage::Hierarchical][..]),
        ] {
            let c =
                PipelineConfig::from_toml_file(&methods.join(format!("{method}.toml"))).unwrap();
            // Every method ends with its VLA (Table 3).
            let mut with_vla = stages.to_vec();
            with_vla.push(Stage::Vla);
            assert_eq!(c.check().unwrap(), with_vla, "{method}");
            assert_eq!(c.name, method);
            // The same budget for every method, as the paper insists (the VLA's 150 apart).
            assert_eq!(
                c.stages
                    .iter()
                    .filter(|s| s.stage != "vla")
                    .map(|s| s.iterations)
                    .sum::<u64>(),
                1000,
                "{method}"
            );
        }
        let hour = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/pipeline-hour.toml");
        let c = PipelineConfig::from_toml_file(&hour).unwrap();
        assert_eq!(
            c.check().unwrap(),
            vec![Stage::T1, Stage::T1Rr, Stage::T2, Stage::Student]
        );
    }

    #[test]
    fn stages_out_of_order_or_unknown_are_refused_by_name() {
        let err = |t: &str| format!("{:#}", parse(t).unwrap_err());
        let e = err("[[stage]]\nstage = \"t1-rr\"\niterations = 1\n");
        assert!(e.contains("needs a t1 stage"), "{e}");
        let e = err("[[stage]]\nstage = \"t2\"\niterations = 1\n");
        assert!(e.contains("Teacher 1 stage"), "{e}");
        let e = err("[[stage]]\nstage = \"t1\"\niterations = 0\n");
        assert!(e.contains("at least 1"), "{e}");
        let e = err("[[stage]]\nstage = \"t1\"\niterations = 1\n[[stage]]\nstage = \"t1\"\niterations = 1\n");
        assert!(e.contains("twice"), "{e}");
        let e = err("[[stage]]\nstage = \"t1\"\niterations = 1\n[[stage]]\nstage = \"student\"\niterations = 1\n");
        assert!(e.contains("needs a t2 stage"), "{e}");
        let e = err("[[stage]]\nstage = \"t1\"\niterations = 1\n[[stage]]\nstage = \"e2e\"\niterations = 1\n");
        assert!(e.contains("only stage"), "{e}");
        let e = err("[[stage]]\nstage = \"t1\"\niterations = 1\n[[stage]]\nstage = \"t2\"\niterations = 1\n[[stage]]\nstage = \"t1-rr\"\niterations = 1\n");
        assert!(e.contains("before t2"), "{e}");
        let e = err("[[stage]]\nstage = \"curriculum\"\niterations = 1\n");
        assert!(e.contains("Teacher 1 stage"), "{e}");
        assert!(toml::from_str::<PipelineConfig>("stages = 3").is_err());
        // t1 then t2 (no fine-tuning) is a valid pipeline.
        assert_eq!(
            parse("[[stage]]\nstage = \"t1\"\niterations = 1\n[[stage]]\nstage = \"t2\"\niterations = 1\n")
                .unwrap(),
            vec![Stage::T1, Stage::T2]
        );
    }
}
