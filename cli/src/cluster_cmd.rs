//! `lhm train`, `lhm learner`, `lhm actor`: the distributed actor–learner run. `lhm train` is the
//! embedded default — the learner in this process on loopback and K actor processes it starts
//! itself — and gives the same run as the separate commands across machines.

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use lhm_actor::{run_actor, ActorConfig};
use lhm_cluster::{shutdown, Endpoints};
use lhm_learner::service::stage::Stage;
use lhm_learner::service::{run_learner, DemoSource, Hooks, IterationReport, TrainConfig};
use lhm_protos::keys;

#[derive(Args, Clone)]
pub struct LearnerOpts {
    /// Training configuration (TOML; every field optional, laid over the library's defaults);
    /// repeat it to lay several files over each other in order, key by key. Without it a plain
    /// `lhm train` runs the built-in Teacher 1 from scratch (`configs/teacher1.toml` then
    /// `configs/teacher1-schedule.toml`: the residual gait, its settings reached in stages, PPO +
    /// AMP in the last), and a `--stage` or `--teacher1` run the library's defaults.
    #[arg(long)]
    config: Vec<PathBuf>,
    /// Run id (overrides the config's).
    #[arg(long)]
    run_id: Option<String>,
    /// Directory of runs (overrides the config's; default `runs`).
    #[arg(long)]
    runs_dir: Option<PathBuf>,
    /// Stop after this many iterations (overrides the config's).
    #[arg(long)]
    max_iterations: Option<u64>,
    /// Transitions per update (overrides the config's).
    #[arg(long)]
    batch_steps: Option<usize>,
    /// Train with the task reward only (no AMP discriminator, no motion clips needed).
    #[arg(long)]
    no_amp: bool,
    /// Train Teacher 2 from this Teacher 1 policy's terminal states (a checkpoint stem such as
    /// runs/p/t1/policy): sets the role to teacher2 and, unless the config lists tasks, the task
    /// set to the two-object training tasks.
    #[arg(long)]
    teacher1: Option<PathBuf>,
    /// Teacher 2's policy for the student stage (with --stage student and --teacher1): the
    /// dagger-server labels first cycles with Teacher 1 and later cycles with it.
    #[arg(long)]
    teacher2: Option<PathBuf>,
    /// Start a new run from this checkpoint's policy, value function and normalisers (fine-tuning,
    /// e.g. release-and-retreat from runs/p/t1/policy); a run with its own checkpoint resumes
    /// from that instead.
    #[arg(long)]
    init_from: Option<PathBuf>,
    /// Run one stage of the paper's pipeline: `t1` (Teacher 1 pretraining), `t1-rr`
    /// (release-and-retreat fine-tuning; needs --init-from the t1 policy), `t2` (Teacher 2; needs
    /// --teacher1, and starts from that policy's weights unless --init-from says otherwise),
    /// `student` (DAgger distillation; needs --teacher1 and --teacher2), `vla` (the student
    /// distilled into an egocentric-RGB and language policy; needs --teacher1 the student's
    /// policy), or the baselines' `e2e`, `curriculum` and `hierarchical` (five skills switched
    /// by a privileged state machine).
    #[arg(long)]
    stage: Option<String>,
    /// Where `scripts/install-motions` put the clips (default: $LHM_MOTION_DIR or ~/.cache/lhm/motions).
    #[arg(long)]
    motion_dir: Option<PathBuf>,
    /// A Zenoh JSON5 configuration (TLS, authentication); explicit endpoints override its own.
    #[arg(long)]
    zenoh_config: Option<PathBuf>,
    #[command(flatten)]
    scenes: crate::scenes_cmd::Source,
}

/// `configs/teacher1.toml`, built in: Teacher 1's settings (the schedule's last stage).
pub(crate) const TEACHER1_TOML: &str = include_str!("../../configs/teacher1.toml");
/// `configs/teacher1-schedule.toml`, built in: the `[[stages]]` that reach those settings from
/// scratch.
pub(crate) const TEACHER1_SCHEDULE_TOML: &str =
    include_str!("../../configs/teacher1-schedule.toml");

/// The run a plain `lhm train` makes without `--config`: [`TEACHER1_TOML`] then
/// [`TEACHER1_SCHEDULE_TOML`] laid over `TrainConfig::default()`, as `--config
/// configs/teacher1.toml --config configs/teacher1-schedule.toml` is.
pub(crate) fn teacher1_config() -> Result<TrainConfig> {
    Ok(TrainConfig::from_toml_sources(&[
        (
            "configs/teacher1.toml (built in)".into(),
            TEACHER1_TOML.into(),
        ),
        (
            "configs/teacher1-schedule.toml (built in)".into(),
            TEACHER1_SCHEDULE_TOML.into(),
        ),
    ])?)
}

impl LearnerOpts {
    fn train_config(&self) -> Result<TrainConfig> {
        let plain_teacher1 =
            self.stage.is_none() && self.teacher1.is_none() && self.teacher2.is_none();
        let mut config = if !self.config.is_empty() {
            let paths: Vec<&std::path::Path> = self.config.iter().map(PathBuf::as_path).collect();
            TrainConfig::from_toml_files(&paths)?
        } else if plain_teacher1 {
            teacher1_config()?
        } else {
            // The pipeline's stages and Teacher 2 keep `TrainConfig::default()` (their actors do
            // not run the gait yet); a plain `lhm train` is Teacher 1 as it is trained today.
            TrainConfig::default()
        };
        if let Some(id) = &self.run_id {
            config.run_id = id.clone();
        }
        if let Some(dir) = &self.runs_dir {
            config.runs_dir = dir.clone();
        }
        if let Some(n) = self.max_iterations {
            config.max_iterations = Some(n);
        }
        if let Some(n) = self.batch_steps {
            config.batch_steps = n;
        }
        if self.no_amp {
            config.amp_enabled = false;
            for stage in &mut config.stages {
                stage.amp_enabled = None;
            }
        }
        if let Some(path) = &self.init_from {
            config.init_from = Some(path.clone());
        }
        if let Some(dir) = &self.scenes.scenes {
            config.scenes = Some(dir.clone());
        }
        if let Some(stage) = &self.stage {
            let stage_kind = Stage::parse(stage)?;
            // A stage's run is its own: without --run-id (or one in the config) it is named after
            // the stage, never the plain Teacher 1 run's default.
            if self.run_id.is_none() && config.run_id == TrainConfig::default().run_id {
                config.run_id = stage_kind.name().into();
            }
            stage_kind.apply(
                &mut config,
                self.teacher1.as_deref(),
                self.teacher2.as_deref(),
            )?;
        } else if self.teacher2.is_some() {
            bail!("--teacher2 is for the student stage: add --stage student");
        } else if let Some(path) = &self.teacher1 {
            config.teacher1 = Some(path.clone());
            config.role = "teacher2".into();
            if config.tasks == lhm_cluster::TaskSet::TrainSingleObject {
                config.tasks = lhm_cluster::TaskSet::Split(lhm_scenes::Split::Train);
            }
        }
        keys::check_chunk("run id", &config.run_id)?;
        config.check()?;
        Ok(config)
    }

    fn demo(&self, config: &TrainConfig) -> Result<Option<Box<dyn DemoSource>>> {
        demo_for(self.motion_dir.clone(), config)
    }
}

/// The discriminator's demo features for `config` (none without AMP; a gait run's cycles are
/// still built from the clips, to refuse a bad one at the start).
pub(crate) fn demo_for(
    motion_dir: Option<PathBuf>,
    config: &TrainConfig,
) -> Result<Option<Box<dyn DemoSource>>> {
    if !config.amp_present() {
        crate::demo::check_gait_run(motion_dir, config)?;
        return Ok(None);
    }
    crate::demo::load(motion_dir, config).map(Some)
}

/// How `lhm train` (and each stage of `lhm pipeline`) runs on this machine: the learner in this
/// process and `actors` actor processes on loopback.
#[derive(Clone, Debug)]
pub(crate) struct LocalCluster {
    pub actors: Option<usize>,
    pub envs: usize,
    pub port: u16,
    pub zenoh_config: Option<PathBuf>,
}

#[derive(Args)]
pub struct TrainArgs {
    #[command(flatten)]
    learner: LearnerOpts,
    /// Actor processes to start (default: one per CPU core).
    #[arg(long, value_parser = at_least_one)]
    actors: Option<usize>,
    /// Environments per actor process.
    #[arg(long, default_value_t = 16, value_parser = at_least_one)]
    envs: usize,
    /// Loopback port the learner listens on (0: any free port).
    #[arg(long, default_value_t = 0)]
    port: u16,
}

#[derive(Args)]
pub struct LearnerArgs {
    #[command(flatten)]
    learner: LearnerOpts,
    /// Endpoints to listen on (<protocol>/<address>, e.g. tcp/0.0.0.0:7447).
    #[arg(long, default_value = "tcp/0.0.0.0:7447", value_parser = endpoint)]
    listen: Vec<String>,
}

#[derive(Args)]
pub struct DaggerServerArgs {
    /// The learner's (or a router's) endpoint, e.g. tcp/10.0.0.5:7447.
    #[arg(long, required = true, value_parser = endpoint)]
    connect: Vec<String>,
    /// The student run whose teachers label its states (`lhm train --stage student`'s default).
    #[arg(long, default_value = "student")]
    run_id: String,
    /// A Zenoh JSON5 configuration (TLS, authentication); explicit endpoints override its own.
    #[arg(long)]
    zenoh_config: Option<PathBuf>,
}

#[derive(Args)]
pub struct ActorArgs {
    /// The learner's (or a router's) endpoint, e.g. tcp/10.0.0.5:7447.
    #[arg(long, required = true, value_parser = endpoint)]
    connect: Vec<String>,
    /// The learner's run id.
    #[arg(long, default_value = "teacher1")]
    run_id: String,
    /// teacher1, teacher2 or student.
    #[arg(long, default_value = "teacher1")]
    role: String,
    /// Environments stepped by this process.
    #[arg(long, default_value_t = 16, value_parser = at_least_one)]
    envs: usize,
    /// Seed of the task draws, starts and sampled actions.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Default: actor-<host>-<pid>.
    #[arg(long)]
    actor_id: Option<String>,
    /// Stop after sending this many chunks.
    #[arg(long)]
    max_chunks: Option<u64>,
    /// Simulate and build chunks without sending them (the benchmark's baseline).
    #[arg(long, hide = true)]
    no_publish: bool,
    /// Print the actor's summary as one JSON line on stdout when it stops.
    #[arg(long, hide = true)]
    summary_json: bool,
    /// A Zenoh JSON5 configuration (TLS, authentication); explicit endpoints override its own.
    #[arg(long)]
    zenoh_config: Option<PathBuf>,
    #[command(flatten)]
    scenes: crate::scenes_cmd::Source,
}

/// A count of processes or environments: 0 is an error, not silently 1.
fn at_least_one(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(0) => Err("must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(_) => Err(format!("{text:?} is not a whole number")),
    }
}

/// A Zenoh endpoint, `<protocol>/<address>` (checked here so that a typo gets a readable error
/// rather than Zenoh's internal one).
fn endpoint(text: &str) -> Result<String, String> {
    let valid = text.split_once('/').is_some_and(|(protocol, address)| {
        !protocol.is_empty()
            && protocol
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-')
            && !address.is_empty()
    });
    if valid {
        Ok(text.to_owned())
    } else {
        Err(format!(
            "{text:?} is not an endpoint: expected <protocol>/<address>, e.g. tcp/0.0.0.0:7447 or tcp/10.0.0.5:7447"
        ))
    }
}

fn progress_bar(max: Option<u64>) -> ProgressBar {
    let bar = match max {
        Some(n) => ProgressBar::new(n).with_style(
            ProgressStyle::with_template("{bar:30} it {pos}/{len} {msg} [{elapsed_precise}]")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        ),
        None => ProgressBar::new_spinner().with_style(
            ProgressStyle::with_template("{spinner} it {pos} {msg} [{elapsed_precise}]")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        ),
    };
    bar.enable_steady_tick(Duration::from_millis(250));
    bar.set_message("waiting for the first batch");
    bar
}

fn progress_message(r: &IterationReport) -> String {
    let success = if r.success_rate.is_finite() {
        format!("{:.1}%", 100.0 * r.success_rate)
    } else {
        "-".into()
    };
    let pct = |x: f64| {
        if x.is_finite() {
            format!("{:.0}%", 100.0 * x)
        } else {
            "-".into()
        }
    };
    let disc = r.disc_accuracy.map_or("-".into(), |a| format!("{a:.2}"));
    // Reach from task starts; a run whose episodes all start from clip frames (every gait run)
    // has none, so it shows the reach over all its episodes, marked as such.
    let reach = if r.reach_rate.is_finite() || !r.reach_rate_all.is_finite() {
        pct(r.reach_rate)
    } else {
        format!("{} (all starts)", pct(r.reach_rate_all))
    };
    format!(
        "| {:.0} samples/s | return {:.2} | success {success} | falls {} | reach {reach} | disc {disc} | style {:.3} | {} episodes | {} actors",
        r.samples_per_s,
        r.mean_return,
        pct(r.fall_fraction),
        r.style_reward,
        r.episodes,
        r.actors_alive
    )
}

fn run_with_progress(
    config: &TrainConfig,
    endpoints: &Endpoints,
    demo: Option<Box<dyn DemoSource>>,
    mut on_listening: impl FnMut(),
) -> Result<()> {
    let bar = progress_bar(config.max_iterations);
    let bar_for_hook = bar.clone();
    // Without a terminal (containers, CI, `2>log`) the bar draws nothing: plain lines instead,
    // one per 30 s at most.
    let plain = !std::io::IsTerminal::is_terminal(&std::io::stderr());
    let mut last_line: Option<std::time::Instant> = None;
    let hooks = Hooks {
        on_iteration: Some(Box::new(move |r: &IterationReport| {
            bar_for_hook.set_position(r.iteration);
            bar_for_hook.set_message(progress_message(r));
            if plain && last_line.is_none_or(|t| t.elapsed() >= Duration::from_secs(30)) {
                eprintln!("iteration {} {}", r.iteration, progress_message(r));
                last_line = Some(std::time::Instant::now());
            }
        })),
        on_listening: Some(Box::new(&mut on_listening)),
    };
    let status = run_learner(config, endpoints, demo, hooks);
    bar.finish();
    let status = status?;
    println!(
        "run {}: iteration {}, {} samples; checkpoint and status in {}",
        status.run_id,
        status.iteration,
        status.samples,
        config.run_dir().display()
    );
    Ok(())
}

pub fn train(args: TrainArgs) -> Result<()> {
    shutdown::install();
    let config = args.learner.train_config()?;
    let demo = args.learner.demo(&config)?;
    let local = LocalCluster {
        actors: args.actors,
        envs: args.envs,
        port: args.port,
        zenoh_config: args.learner.zenoh_config.clone(),
    };
    train_locally(config, demo, &local)
}

/// Runs `config` to its end (or SIGINT/SIGTERM) with the learner here and local actor processes.
pub(crate) fn train_locally(
    mut config: TrainConfig,
    demo: Option<Box<dyn DemoSource>>,
    args: &LocalCluster,
) -> Result<()> {
    let port = match args.port {
        0 => std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .context("finding a free loopback port")?
            .port(),
        p => p,
    };
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let endpoints = Endpoints {
        listen: vec![endpoint.clone()],
        connect: vec![],
        zenoh_config: args.zenoh_config.clone(),
    };
    let actors = args
        .actors
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, usize::from))
        .max(1);
    if config.chunk_sets_per_version == 0 {
        // The local actors share the learner's cores: each sends its share of one batch per
        // version and waits for the update (free-running, half the chunks went stale).
        let per_set = actors * args.envs * config.chunk_steps as usize;
        config.chunk_sets_per_version = config.batch_steps.div_ceil(per_set).max(1) as u32;
    }
    let exe = this_executable()?;
    let run_dir = config.run_dir();
    std::fs::create_dir_all(&run_dir).with_context(|| format!("creating {}", run_dir.display()))?;
    let mut children: Vec<Child> = Vec::new();
    let mut spawn_error: Option<anyhow::Error> = None;
    let role = config.role.clone();
    let run_id = config.run_id.clone();
    let scenes = config.scenes.clone();
    let result = run_with_progress(&config, &endpoints, demo, || {
        // The student's (and the VLA's) labels come from a dagger-server; the teachers' runs
        // need none.
        let mut processes: Vec<(String, Vec<String>)> = Vec::new();
        if role == "student" || role == "vla" {
            processes.push((
                "dagger-server".into(),
                ["dagger-server", "--connect", &endpoint, "--run-id", &run_id]
                    .map(String::from)
                    .to_vec(),
            ));
        }
        for i in 0..actors {
            let mut a: Vec<String> = ["actor", "--connect", &endpoint, "--run-id", &run_id]
                .map(String::from)
                .to_vec();
            a.extend([
                "--role".into(),
                role.clone(),
                "--envs".into(),
                args.envs.to_string(),
            ]);
            a.extend(["--seed".into(), (1000 + i as u64).to_string()]);
            a.extend(["--actor-id".into(), format!("local-{i}")]);
            processes.push((format!("actor-{i}"), a));
        }
        for (name, mut process_args) in processes {
            if let (true, Some(d)) = (name.starts_with("actor"), &scenes) {
                process_args.extend(["--scenes".into(), d.display().to_string()]);
            }
            let log = run_dir.join(format!("{name}.log"));
            match spawn_logged(&exe, &process_args, &log) {
                Ok(child) => children.push(child),
                Err(e) => {
                    spawn_error = Some(e.context(format!("starting the {name} process")));
                    shutdown::request();
                    break;
                }
            }
        }
    });
    stop_children(&mut children);
    if let Some(e) = spawn_error {
        return Err(e);
    }
    result
}

/// The running `lhm` to start actor and dagger-server processes from. On Linux that is
/// `/proc/self/exe`, the very file this process runs even after a rebuild replaced it on disk
/// (the path `current_exe` gives then ends in " (deleted)" and cannot be started; a pipeline's
/// later stages failed so), so every process of a run is the same build.
pub(crate) fn this_executable() -> Result<PathBuf> {
    let proc_exe = PathBuf::from("/proc/self/exe");
    if cfg!(target_os = "linux") && proc_exe.exists() {
        return Ok(proc_exe);
    }
    std::env::current_exe().context("locating the lhm executable")
}

/// Starts `exe args` with stdout and stderr appended to `log` (not truncated: a resumed run keeps
/// the logs of its earlier sessions), dying with this process.
fn spawn_logged(exe: &std::path::Path, args: &[String], log: &std::path::Path) -> Result<Child> {
    let file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)
        .with_context(|| format!("opening {}", log.display()))?;
    let err = file.try_clone()?;
    let mut cmd = Command::new(exe);
    die_with_parent(&mut cmd);
    Ok(cmd
        .args(args)
        .stdin(Stdio::null())
        .stdout(file)
        .stderr(err)
        .spawn()?)
}

/// The child gets SIGTERM (its clean stop) when this process dies, however it dies, SIGKILL
/// included: actors started by `lhm train` never outlive it (they were orphaned at full CPU).
/// Linux's parent-death signal fires when the spawning thread ends: actors are spawned from the
/// thread that runs the learner, which lives as long as the process.
fn die_with_parent(cmd: &mut Command) {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::process::CommandExt;
        let parent = std::process::id() as libc::pid_t;
        // SAFETY: the closure runs between fork and exec and calls only async-signal-safe
        // functions (prctl, getppid, raise); it allocates nothing.
        unsafe {
            cmd.pre_exec(move || {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                // The parent may have died before the prctl: nobody would signal then.
                if libc::getppid() != parent {
                    libc::raise(libc::SIGTERM);
                }
                Ok(())
            });
        }
    }
}

/// SIGTERM to every actor (they finish their step and leave without a partial chunk), then
/// SIGKILL whoever is still there after a grace period.
fn stop_children(children: &mut [Child]) {
    for child in children.iter() {
        // SAFETY: plain kill(2) on a child we spawned.
        unsafe {
            libc::kill(child.id() as libc::pid_t, libc::SIGTERM);
        }
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    for child in children.iter_mut() {
        loop {
            match child.try_wait() {
                Ok(Some(_)) => break,
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(50))
                }
                _ => {
                    let _ = child.kill();
                    let _ = child.wait();
                    break;
                }
            }
        }
    }
}

pub fn learner(args: LearnerArgs) -> Result<()> {
    shutdown::install();
    let config = args.learner.train_config()?;
    let demo = args.learner.demo(&config)?;
    let endpoints = Endpoints {
        listen: args.listen.clone(),
        connect: vec![],
        zenoh_config: args.learner.zenoh_config.clone(),
    };
    run_with_progress(&config, &endpoints, demo, || {})
}

/// `lhm dagger-server`: the teacher-label service of a student run (the same as the
/// `lhm-dagger-server` binary), here so that `lhm train --stage student` can start it.
pub fn dagger_server(args: DaggerServerArgs) -> Result<()> {
    shutdown::install();
    let endpoints = Endpoints {
        listen: vec![],
        connect: args.connect,
        zenoh_config: args.zenoh_config,
    };
    lhm_dagger_server::serve(&endpoints, &args.run_id).context("dagger-server")?;
    Ok(())
}

pub fn actor(args: ActorArgs) -> Result<()> {
    shutdown::install();
    let Some(role) = keys::parse_role(&args.role) else {
        bail!(
            "--role {:?} is not one of teacher1, teacher2, student, vla",
            args.role
        );
    };
    let config = ActorConfig {
        endpoints: Endpoints {
            listen: vec![],
            connect: args.connect,
            zenoh_config: args.zenoh_config,
        },
        run_id: args.run_id,
        role,
        actor_id: args.actor_id.unwrap_or_else(ActorConfig::default_actor_id),
        envs: args.envs,
        seed: args.seed,
        max_chunks: args.max_chunks,
        publish: !args.no_publish,
        scenes: args.scenes.scenes,
    };
    match run_actor(&config) {
        Ok(summary) => {
            tracing::info!("{summary:?}");
            if args.summary_json {
                println!(
                    "{}",
                    serde_json::json!({
                        "chunks_sent": summary.chunks_sent,
                        "env_steps": summary.env_steps,
                        "busy_s": summary.busy_s,
                        "env_steps_per_s": summary.env_steps as f64 / summary.busy_s.max(1e-9),
                    })
                );
            }
            Ok(())
        }
        Err(lhm_actor::service::ActorError::NoWeights) if shutdown::requested() => Ok(()),
        Err(lhm_actor::service::ActorError::Cluster(e @ lhm_cluster::ClusterError::Stopped(_))) => {
            tracing::info!("{e}");
            Ok(())
        }
        Err(e) => Err(e.into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(reach_rate: f64, reach_rate_all: f64) -> IterationReport {
        IterationReport {
            iteration: 3,
            samples: 100,
            samples_per_s: 50.0,
            mean_return: 1.0,
            success_rate: f64::NAN,
            episodes: 4,
            actors_alive: 2,
            update_s: 0.1,
            disc_accuracy: None,
            style_reward: 0.0,
            task_reward: 0.5,
            fall_fraction: 0.5,
            reach_rate,
            reach_rate_all,
        }
    }

    /// `LearnerOpts` as clap parses them from `args` (the program name first).
    fn learner_opts(args: &[&str]) -> LearnerOpts {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            opts: LearnerOpts,
        }
        <Cli as clap::Parser>::try_parse_from(args)
            .expect("flags")
            .opts
    }

    #[test]
    fn a_plain_train_runs_the_built_in_teacher1_and_a_stage_the_library_defaults() {
        let parse = learner_opts;
        let config = parse(&["lhm"])
            .train_config()
            .expect("the built-in configuration");
        let gait = config
            .env
            .gait
            .as_ref()
            .expect("the built-in Teacher 1 walks on the gait");
        assert_eq!(gait.stop_on, lhm_sim::env::StopOn::FeetDown);
        assert_eq!(gait.rest_start_fraction, 0.5);
        assert!(config.amp_enabled && !config.amp.discriminate_stand);
        // Laid over the defaults, not replacing them: what the file does not name is the
        // library's (a key the defaults do not know would have failed to parse).
        assert_eq!(config.ppo, TrainConfig::default().ppo);
        assert_eq!(config.run_id, TrainConfig::default().run_id);
        assert!(parse(&["lhm", "--stage", "t1"])
            .train_config()
            .expect("t1")
            .env
            .gait
            .is_none());
    }

    #[test]
    fn the_built_in_run_is_teacher1_reached_by_its_schedule_and_config_files_stack_in_order() {
        let parse = |args: &[&str]| learner_opts(args).train_config().expect("config");
        let configs = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs");
        let settings = format!("{configs}/teacher1.toml");
        let schedule = format!("{configs}/teacher1-schedule.toml");
        let built_in = parse(&["lhm"]);
        // The built-in run is the two files, in that order.
        assert_eq!(
            built_in,
            parse(&["lhm", "--config", &settings, "--config", &schedule])
        );
        // teacher1.toml alone (a fine-tune's base) has no schedule and the same settings.
        let alone = parse(&["lhm", "--config", &settings]);
        assert!(alone.stages.is_empty());
        assert_eq!(
            TrainConfig {
                stages: Vec::new(),
                ..built_in.clone()
            },
            alone
        );
        // From scratch: no AMP and σ e^−3.5, every start at rest, the stop at the distance; the
        // file's own settings (AMP, feet-down stop, half the starts walking) hold at the end.
        let first = built_in.stage_at(0).expect("stage at 0");
        assert_eq!(first.index, Some(0));
        assert!(!first.amp_active);
        assert_eq!(first.log_std, Some(lhm_nets::LogStd::Fixed(-3.5)));
        let gait = first.spec.env.gait.as_ref().expect("gait");
        assert_eq!(gait.rest_start_fraction, 1.0);
        assert_eq!(gait.stop_on, lhm_sim::env::StopOn::Distance);
        let last = built_in
            .stage_at(built_in.stages.last().expect("stages").until_iteration)
            .expect("past the schedule");
        assert_eq!(last.index, None);
        assert!(last.amp_active);
        assert_eq!(last.log_std, Some(lhm_nets::LogStd::Fixed(-4.5)));
        assert_eq!(built_in.amp.grad_penalty, 50.0);
        let target = built_in
            .amp
            .accuracy_target
            .as_ref()
            .expect("accuracy target");
        assert_eq!(target.accuracy, 0.8);
        // Stages 4 and 5 keep σ e^−4 (the line's walk-way-std40-long and feet-down runs).
        let before_amp = built_in.stage_at(12_899).expect("stage at 12,899");
        assert_eq!(before_amp.index, Some(4));
        assert_eq!(before_amp.log_std, Some(lhm_nets::LogStd::Fixed(-4.0)));
        let gait = last.spec.env.gait.as_ref().expect("gait");
        assert_eq!(gait.stop_on, lhm_sim::env::StopOn::FeetDown);
        assert_eq!(gait.rest_start_fraction, 0.5);
        // A later file is laid over an earlier one key by key.
        let dir = std::env::temp_dir().join(format!("lhm-config-stack-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let top = dir.join("top.toml");
        std::fs::write(&top, "[ppo.adam]\nlr = 1e-5\n").expect("write");
        let stacked = parse(&[
            "lhm",
            "--config",
            &settings,
            "--config",
            &top.to_string_lossy(),
        ]);
        std::fs::remove_dir_all(&dir).expect("clean up");
        assert_eq!(stacked.ppo.adam.lr, 1e-5);
        assert_eq!(
            TrainConfig {
                ppo: alone.ppo.clone(),
                ..stacked
            },
            alone
        );
    }

    #[test]
    fn the_progress_line_shows_reach_from_task_starts_or_else_over_all_starts() {
        assert!(progress_message(&report(0.25, 0.75)).contains("| reach 25% |"));
        // A gait run: no task starts, so the reach over all starts, labelled.
        assert!(progress_message(&report(f64::NAN, 0.75)).contains("| reach 75% (all starts) |"));
        // No episodes at all: nothing to show.
        assert!(progress_message(&report(f64::NAN, f64::NAN)).contains("| reach - |"));
    }
}
