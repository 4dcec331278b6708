//! `lhm-dagger-server --connect tcp/LEARNER:7447 --run-id RUN`: serves `lhm/<run>/dagger/label`.

use std::time::Duration;

use anyhow::{Context, Result};
use clap::Parser;
use lhm_cluster::{session::open_session_retrying, shutdown, Endpoints, NodeMode};
use lhm_dagger_server::{answer, SharedTeachers};
use lhm_protos::{keys, Role, WireMessage};
use zenoh::Wait;

#[derive(Parser)]
#[command(name = "lhm-dagger-server", about = "DAgger teacher-label queryable")]
struct Args {
    /// The learner's (or a router's) endpoint.
    #[arg(long, required = true)]
    connect: Vec<String>,
    /// The run whose teachers label the student's states.
    #[arg(long, default_value = "teacher1")]
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
    let session = match open_session_retrying(
        NodeMode::Client,
        &endpoints,
        Duration::from_millis(500),
        || !shutdown::requested(),
    ) {
        Ok(s) => s,
        // SIGTERM/Ctrl-C while still waiting for the learner: a clean stop, as the actor's.
        Err(e @ lhm_cluster::ClusterError::Stopped(_)) => {
            tracing::info!("{e}");
            return Ok(());
        }
        Err(e) => return Err(e.into()),
    };
    let teachers = SharedTeachers::default();
    let mut subscribers = Vec::new();
    for role in [Role::Teacher1, Role::Teacher2] {
        let t = teachers.clone();
        let key = keys::policy(&args.run_id, role);
        subscribers.push(
            session
                .declare_subscriber(&key)
                .callback(move |sample| {
                    let bytes = sample.payload().to_bytes();
                    match t.lock().map(|mut t| t.update(&bytes)) {
                        Ok(Ok(role)) => tracing::debug!("new {} weights", keys::role_chunk(role)),
                        Ok(Err(e)) => tracing::warn!("ignoring weights: {e}"),
                        Err(_) => {}
                    }
                })
                .wait()
                .map_err(|e| anyhow::anyhow!("subscribing to {key}: {e}"))?,
        );
        // The latest weights now, rather than at the learner's next update.
        if let Ok(replies) = session.get(&key).timeout(Duration::from_secs(2)).wait() {
            while let Ok(reply) = replies.recv() {
                if let (Ok(sample), Ok(mut t)) = (reply.result(), teachers.lock()) {
                    let _ = t.update(&sample.payload().to_bytes());
                }
            }
        }
    }
    let t = teachers.clone();
    let label_key = keys::dagger_label(&args.run_id);
    let _queryable = session
        .declare_queryable(&label_key)
        .callback(move |query| {
            let bytes = query
                .payload()
                .map(|p| p.to_bytes().to_vec())
                .unwrap_or_default();
            let snapshot = t.lock().map(|t| t.clone()).unwrap_or_default();
            let reply = answer(&bytes, &snapshot);
            match reply.encode_checked() {
                Ok(bytes) => {
                    // A reply travels with the query's QoS: students query with Block and a high
                    // priority so labels are never dropped.
                    if let Err(e) = query.reply(query.key_expr().clone(), bytes).wait() {
                        tracing::warn!("replying to a label query: {e}");
                    }
                }
                Err(e) => tracing::warn!("label reply does not encode: {e}"),
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("declaring {label_key}: {e}"))?;
    let _token = session
        .liveliness()
        .declare_token(keys::status(&args.run_id, "dagger-server"))
        .wait()
        .map_err(|e| anyhow::anyhow!("liveliness: {e}"))?;
    tracing::info!("dagger-server answering {label_key}");
    while !shutdown::requested() {
        std::thread::sleep(Duration::from_millis(100));
    }
    drop(subscribers);
    session
        .close()
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))
        .context("closing")?;
    Ok(())
}
