//! `lhm-dagger-server --connect tcp/LEARNER:7447 --run-id RUN`: serves `lhm/<run>/dagger/label`.

use anyhow::{Context, Result};
use clap::Parser;
use lhm_cluster::{shutdown, Endpoints};
use lhm_protos::keys;

#[derive(Parser)]
#[command(name = "lhm-dagger-server", about = "DAgger teacher-label queryable")]
struct Args {
    /// The learner's (or a router's) endpoint.
    #[arg(long, required = true)]
    connect: Vec<String>,
    /// The student run whose teachers label its states (`lhm train --stage student`'s default).
    #[arg(long, default_value = "student")]
    run_id: String,
    /// A Zenoh JSON5 configuration (TLS, authentication); explicit endpoints override its own.
    #[arg(long)]
    zenoh_config: Option<std::path::PathBuf>,
}

fn main() -> Result<()> {
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
    let args = Args::parse();
    shutdown::install();
    keys::check_chunk("run id", &args.run_id)?;
    let endpoints = Endpoints {
        listen: vec![],
        connect: args.connect,
        zenoh_config: args.zenoh_config,
    };
    lhm_dagger_server::serve(&endpoints, &args.run_id).context("dagger-server")?;
    Ok(())
}
