//! Zenoh sessions from explicit endpoints. Multicast scouting is off everywhere: it is unreliable
//! in containers and across hosts, so every process is told where to listen or connect.

use serde::{Deserialize, Serialize};
use zenoh::{Session, Wait};

use crate::{ClusterError, ClusterResult};

/// How a process joins the Zenoh network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NodeMode {
    /// Accepts connections and routes between its clients (the learner, or a dedicated router).
    Router,
    /// Connects to one router and keeps reconnecting to it (actors, the dagger-server).
    Client,
    /// Talks to the peers it connects to or accepts.
    Peer,
}

impl NodeMode {
    fn as_str(self) -> &'static str {
        match self {
            Self::Router => "router",
            Self::Client => "client",
            Self::Peer => "peer",
        }
    }
}

/// Endpoints like `tcp/127.0.0.1:7447`, plus an optional Zenoh JSON5 config file for the rest
/// (TLS, authentication, access control); explicit endpoints override the file's.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Endpoints {
    pub listen: Vec<String>,
    pub connect: Vec<String>,
    pub zenoh_config: Option<std::path::PathBuf>,
}

fn json_list(items: &[String]) -> String {
    serde_json::to_string(items).unwrap_or_else(|_| "[]".into())
}

/// Builds the Zenoh configuration of a process.
pub fn zenoh_config(mode: NodeMode, endpoints: &Endpoints) -> ClusterResult<zenoh::Config> {
    let mut config = match &endpoints.zenoh_config {
        Some(path) => zenoh::Config::from_file(path).map_err(|e| {
            ClusterError::Zenoh(format!("zenoh config file {}: {e}", path.display()))
        })?,
        None => zenoh::Config::default(),
    };
    let mut set = |key: &str, value: String| {
        config
            .insert_json5(key, &value)
            .map_err(|e| ClusterError::Zenoh(format!("setting {key} = {value}: {e}")))
    };
    set("mode", format!("\"{}\"", mode.as_str()))?;
    set("scouting/multicast/enabled", "false".into())?;
    if !endpoints.listen.is_empty() {
        set("listen/endpoints", json_list(&endpoints.listen))?;
    } else if mode != NodeMode::Router {
        set("listen/endpoints", "[]".into())?;
    }
    if !endpoints.connect.is_empty() {
        set("connect/endpoints", json_list(&endpoints.connect))?;
        // A client keeps retrying its router for ever, in the background: actors start before
        // the learner, and outlive its restarts.
        set(
            "connect/timeout_ms",
            "{ router: -1, peer: -1, client: 0 }".into(),
        )?;
        set(
            "connect/exit_on_failure",
            "{ router: false, peer: false, client: false }".into(),
        )?;
        set(
            "connect/retry",
            "{ period_init_ms: 250, period_max_ms: 1000, period_increase_factor: 2 }".into(),
        )?;
    }
    Ok(config)
}

/// Opens a session. A client whose router is not up yet fails here; callers retry (see
/// [`open_session_retrying`]).
pub fn open_session(mode: NodeMode, endpoints: &Endpoints) -> ClusterResult<Session> {
    open_with(zenoh_config(mode, endpoints)?, mode, endpoints)
}

fn open_with(
    config: zenoh::Config,
    mode: NodeMode,
    endpoints: &Endpoints,
) -> ClusterResult<Session> {
    zenoh::open(config).wait().map_err(|e| {
        ClusterError::zenoh(format!(
            "opening a {} session (listen {:?}, connect {:?}): {e}",
            mode.as_str(),
            endpoints.listen,
            endpoints.connect
        ))
    })
}

/// The log filter of the project's binaries when `RUST_LOG` is unset: our own INFO lines, zenoh's
/// warnings, but not the orchestrator's two warnings per failed connection attempt (a waiting
/// actor printed three lines every 0.5 s); [`open_session_retrying`] says once that it waits and
/// then every `WAIT_REPORT_EVERY`.
pub const DEFAULT_LOG_FILTER: &str = "info,zenoh=warn,zenoh::net::runtime::orchestrator=error";

/// How often a process still waiting for its peer says so.
pub const WAIT_REPORT_EVERY: std::time::Duration = std::time::Duration::from_secs(30);

/// Opens a session, retrying every `period` until it succeeds or `keep_trying` says stop. A bad
/// configuration is an error at once; only failing to connect is retried.
pub fn open_session_retrying(
    mode: NodeMode,
    endpoints: &Endpoints,
    period: std::time::Duration,
    mut keep_trying: impl FnMut() -> bool,
) -> ClusterResult<Session> {
    let config = zenoh_config(mode, endpoints)?;
    let started = std::time::Instant::now();
    let mut last_report: Option<std::time::Instant> = None;
    loop {
        match open_with(config.clone(), mode, endpoints) {
            Ok(s) => {
                if last_report.is_some() {
                    tracing::info!(
                        "connected to {:?} after {:.0} s",
                        endpoints.connect,
                        started.elapsed().as_secs_f64()
                    );
                }
                return Ok(s);
            }
            Err(e) => {
                if !keep_trying() {
                    return Err(if last_report.is_some() {
                        ClusterError::Stopped(format!("{:?}", endpoints.connect))
                    } else {
                        e
                    });
                }
                match last_report {
                    None => tracing::info!(
                        "waiting for {:?} (nothing answers there yet; retrying every {:.1} s)",
                        endpoints.connect,
                        period.as_secs_f64()
                    ),
                    Some(t) if t.elapsed() >= WAIT_REPORT_EVERY => tracing::info!(
                        "still waiting for {:?} ({:.0} s)",
                        endpoints.connect,
                        started.elapsed().as_secs_f64()
                    ),
                    Some(_) => {
                        std::thread::sleep(period);
                        continue;
                    }
                }
                last_report = Some(std::time::Instant::now());
                std::thread::sleep(period);
            }
        }
    }
}
