//! `lhm`: the project's command line. Subcommands are thin: parsing and printing here, the work in
//! the library crates.

mod bench_cmd;
mod cluster_bench;
mod cluster_cmd;
mod demo;
mod eval_cmd;
mod motion_cmd;
mod pipeline_cmd;
mod plot_cmd;
mod record_cmd;
mod render_cmd;
mod scenes_cmd;
mod tables_cmd;
mod train_bench;
mod vla_bench;
mod vla_probe_cmd;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "lhm",
    version,
    about = "Long-horizon, reset-free humanoid object transport"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Train Teacher 1 on this machine: the learner on loopback and one actor process per core.
    Train(cluster_cmd::TrainArgs),
    /// The paper's stages in order on this machine — t1, t1-rr (release-and-retreat), t2 — then
    /// eval; re-running continues where it stopped.
    Pipeline(pipeline_cmd::PipelineArgs),
    /// The learner service alone (actors connect to it with `lhm actor --connect`).
    Learner(cluster_cmd::LearnerArgs),
    /// One actor process: simulates episodes and streams trajectories to a learner.
    Actor(cluster_cmd::ActorArgs),
    /// The teacher-label service of a student run: labels student states with Teacher 1 (first
    /// cycle) or Teacher 2 (later cycles).
    DaggerServer(cluster_cmd::DaggerServerArgs),
    /// The benchmark: generate, validate, summarise and draw its tasks.
    Scenes(scenes_cmd::ScenesArgs),
    /// Record one episode of a trained policy as MCAP (opens in Foxglove).
    Record(record_cmd::RecordArgs),
    /// Throughput benchmarks (results go in BENCHMARKS.md).
    Bench(bench_cmd::BenchArgs),
    /// Reference motion clips for AMP.
    Motion(motion_cmd::MotionArgs),
    /// Animated GIF of the character in a benchmark room under a simple policy.
    RenderRollout(render_cmd::RenderRolloutArgs),
    /// Training curves of a run (RUN_DIR/metrics.csv) as one PNG.
    Plot(plot_cmd::PlotArgs),
    /// Score a policy on a benchmark split: Success k, Dist k, Success All, falls (paper Sec. 4.1).
    Eval(eval_cmd::EvalArgs),
    /// The paper's Tables 1, 2 and 4 from the method pipelines in a runs directory
    /// (configs/methods/*.toml), with the paper's figures beside ours.
    Tables(tables_cmd::TablesArgs),
    /// Make a recording cut short by a crash (SIGKILL, power loss) readable again: copies every
    /// complete record into a new, properly finished MCAP file.
    Recover(record_cmd::RecoverArgs),
    /// How closely a VLA policy reproduces the policy it was distilled from, with and without
    /// its instructions, along its own rollouts on each split.
    VlaProbe(vla_probe_cmd::VlaProbeArgs),
}

/// candle allocates a fresh buffer per tensor op and glibc serves large ones with mmap, so every
/// learner step pays page faults (measured: 2.75M minor faults and ~20% of a PPO step). Raising
/// the mmap and trim thresholds keeps those buffers in the heap.
fn tune_allocator() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator parameters; it is called before any other thread
    // exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
    }
}

/// The error and its causes on one line, each cause once: library errors that already quote
/// their source in their message (thiserror's `"{path}: {source}"`) also return it as the source,
/// and anyhow's `{:#}` printed such an OS error twice.
fn error_chain(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

fn main() -> ExitCode {
    tune_allocator();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| lhm_cluster::session::DEFAULT_LOG_FILTER.into()),
        )
        .with_writer(std::io::stderr)
        // Colour codes only on a terminal: logs redirected to files, containers and CI stay
        // plain text.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Train(args) => cluster_cmd::train(args).map(|()| ExitCode::SUCCESS),
        Command::Pipeline(args) => pipeline_cmd::run(args).map(|finished| {
            if finished {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(pipeline_cmd::STOPPED_EXIT)
            }
        }),
        Command::Learner(args) => cluster_cmd::learner(args).map(|()| ExitCode::SUCCESS),
        Command::Actor(args) => cluster_cmd::actor(args).map(|()| ExitCode::SUCCESS),
        Command::DaggerServer(args) => cluster_cmd::dagger_server(args).map(|()| ExitCode::SUCCESS),
        Command::Record(args) => record_cmd::run(args).map(|()| ExitCode::SUCCESS),
        Command::Eval(args) => eval_cmd::run(args).map(|()| ExitCode::SUCCESS),
        Command::Tables(args) => tables_cmd::run(args).map(|()| ExitCode::SUCCESS),
        Command::Recover(args) => record_cmd::recover(args).map(|()| ExitCode::SUCCESS),
        Command::VlaProbe(args) => vla_probe_cmd::run(args).map(|()| ExitCode::SUCCESS),
        Command::Scenes(args) => scenes_cmd::run(args),
        Command::Bench(args) => bench_cmd::run(args).map(|()| ExitCode::SUCCESS),
        Command::Motion(args) => motion_cmd::run(args).map(|()| ExitCode::SUCCESS),
        Command::RenderRollout(args) => render_cmd::run(args).map(|()| ExitCode::SUCCESS),
        Command::Plot(args) => plot_cmd::run(args).map(|()| ExitCode::SUCCESS),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {}", error_chain(&e));
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An error that quotes its source in its message and returns it as its source too.
    #[derive(Debug)]
    struct Quoting {
        path: String,
        source: std::io::Error,
    }

    impl std::fmt::Display for Quoting {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            write!(f, "{}: cannot read: {}", self.path, self.source)
        }
    }

    impl std::error::Error for Quoting {
        fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
            Some(&self.source)
        }
    }

    #[test]
    fn every_argument_has_help_text() {
        use clap::CommandFactory;
        fn walk(cmd: &clap::Command, path: &str, missing: &mut Vec<String>) {
            for a in cmd.get_arguments() {
                let id = a.get_id().as_str();
                if id == "help" || id == "version" || a.is_hide_set() {
                    continue;
                }
                if a.get_help().is_none() && a.get_long_help().is_none() {
                    missing.push(format!("{path} {id}"));
                }
            }
            for sub in cmd.get_subcommands() {
                walk(sub, &format!("{path} {}", sub.get_name()), missing);
            }
        }
        let mut missing = Vec::new();
        walk(&Cli::command(), "lhm", &mut missing);
        assert!(missing.is_empty(), "arguments without help: {missing:#?}");
    }

    #[test]
    fn an_os_error_is_printed_once() {
        let os = std::io::Error::from_raw_os_error(2);
        let e = anyhow::Error::new(Quoting {
            path: "/x/catalogue.toml".into(),
            source: os,
        })
        .context("--scenes /x");
        let line = error_chain(&e);
        assert_eq!(line.matches("os error 2").count(), 1, "{line}");
        assert!(
            line.starts_with("--scenes /x: /x/catalogue.toml: cannot read"),
            "{line}"
        );
    }
}
