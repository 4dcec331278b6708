//! `lhm bench cluster`: what the distributed layer costs. Actors are real `lhm actor` processes
//! talking to an in-process router on loopback that answers their weights query and drains their
//! chunks, exactly as a learner would (without training, so the actors are all that is measured).
//!
//! - publishing overhead: env steps/s of one actor with and without encoding and putting chunks;
//! - scaling: aggregate env steps/s of two concurrent actor processes over one;
//! - weight broadcast: put → delivery latency of the default (1024-512) network's weights message
//!   between two Zenoh sessions over loopback TCP.

use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use lhm_cluster::{encode_policy, open_session, Endpoints, NodeMode};
use lhm_learner::service::TrainConfig;
use lhm_nets::{ActorCritic, ActorCriticConfig};
use lhm_protos::{keys, Role, WireMessage};
use serde::Serialize;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::Wait;

#[derive(Debug, Serialize)]
pub struct ClusterBench {
    pub envs_per_actor: usize,
    pub chunks_per_actor: u64,
    pub network_hidden: Vec<usize>,
    pub actor_env_steps_per_s_no_publish: f64,
    pub actor_env_steps_per_s_publish: f64,
    pub publish_overhead_percent: f64,
    pub one_actor_env_steps_per_s: f64,
    pub two_actors_env_steps_per_s: f64,
    pub scaling_two_vs_one: f64,
    pub weights_bytes: usize,
    pub weight_broadcast_ms_p50: f64,
    pub weight_broadcast_ms_p99: f64,
    pub weight_broadcast_samples: usize,
    pub chunks_received: u64,
}

const RUN: &str = "bench";

/// Runs `count` actor processes at once; returns each one's env steps/s.
fn run_actors(
    endpoint: &str,
    count: usize,
    envs: usize,
    chunks: u64,
    publish: bool,
) -> Result<Vec<f64>> {
    let exe = crate::cluster_cmd::this_executable()?;
    let mut children = Vec::new();
    for i in 0..count {
        let mut cmd = Command::new(&exe);
        cmd.args([
            "actor",
            "--connect",
            endpoint,
            "--run-id",
            RUN,
            "--summary-json",
        ])
        .args([
            "--envs",
            &envs.to_string(),
            "--max-chunks",
            &chunks.to_string(),
        ])
        .args([
            "--seed",
            &(i as u64 + 1).to_string(),
            "--actor-id",
            &format!("bench-{i}"),
        ])
        .env("RUST_LOG", "warn")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
        if !publish {
            cmd.arg("--no-publish");
        }
        children.push(cmd.spawn().context("starting an actor")?);
    }
    let mut rates = Vec::new();
    for child in children {
        let out = child.wait_with_output().context("waiting for an actor")?;
        if !out.status.success() {
            bail!("a benchmark actor failed ({})", out.status);
        }
        let text = String::from_utf8_lossy(&out.stdout);
        let line = text.lines().last().unwrap_or_default();
        let v: serde_json::Value =
            serde_json::from_str(line).with_context(|| format!("actor summary {line:?}"))?;
        rates.push(v["env_steps_per_s"].as_f64().unwrap_or(0.0));
    }
    Ok(rates)
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

pub fn run(envs: usize, chunks: u64, broadcasts: usize) -> Result<ClusterBench> {
    let port = std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let router = open_session(
        NodeMode::Router,
        &Endpoints {
            listen: vec![endpoint.clone()],
            ..Endpoints::default()
        },
    )?;
    // The actors' policy: the training default (CPU preset), as `lhm train` runs it.
    let config = TrainConfig {
        run_id: RUN.into(),
        ..TrainConfig::default()
    };
    let spec = config.run_spec();
    let ac = ActorCritic::new(spec.obs_dim, spec.act_dim, &spec.actor_critic)?;
    let weights = encode_policy(RUN, Role::Teacher1, 0, &spec, &ac)?.encode_checked()?;
    let _queryable = router
        .declare_queryable(keys::policy(RUN, Role::Teacher1))
        .callback(move |q| {
            let _ = q.reply(q.key_expr().clone(), weights.clone()).wait();
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let received = Arc::new(AtomicU64::new(0));
    let counter = Arc::clone(&received);
    let _drain = router
        .declare_subscriber(keys::trajectory_all(RUN, Role::Teacher1))
        .callback(move |_| {
            counter.fetch_add(1, Ordering::Relaxed);
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;

    let no_publish = run_actors(&endpoint, 1, envs, chunks, false)?[0];
    let publish = run_actors(&endpoint, 1, envs, chunks, true)?[0];
    let two: f64 = run_actors(&endpoint, 2, envs, chunks, true)?.iter().sum();

    // Weight broadcast of the default network, router → client over loopback TCP.
    let big = ActorCriticConfig::default();
    let big_ac = ActorCritic::new(spec.obs_dim, spec.act_dim, &big)?;
    let big_spec = lhm_cluster::RunSpec {
        actor_critic: big.clone(),
        ..spec.clone()
    };
    let big_weights =
        encode_policy(RUN, Role::Teacher1, 0, &big_spec, &big_ac)?.encode_checked()?;
    let client = open_session(
        NodeMode::Client,
        &Endpoints {
            connect: vec![endpoint.clone()],
            ..Endpoints::default()
        },
    )?;
    let key = keys::policy("bench-broadcast", Role::Teacher1);
    let (tx, rx) = mpsc::channel::<Instant>();
    let _sub = client
        .declare_subscriber(&key)
        .callback(move |_| {
            let _ = tx.send(Instant::now());
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let publisher = router
        .declare_publisher(&key)
        .congestion_control(CongestionControl::Block)
        .priority(Priority::DataHigh)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    std::thread::sleep(Duration::from_millis(500)); // let the subscription propagate
    let mut latencies = Vec::new();
    for _ in 0..broadcasts + 2 {
        let sent = Instant::now();
        publisher
            .put(big_weights.clone())
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let got = rx
            .recv_timeout(Duration::from_secs(10))
            .context("a weights broadcast never arrived")?;
        latencies.push(got.duration_since(sent).as_secs_f64() * 1e3);
        std::thread::sleep(Duration::from_millis(50));
    }
    // The first two warm the connection up.
    let mut latencies: Vec<f64> = latencies.split_off(2);
    latencies.sort_by(f64::total_cmp);
    Ok(ClusterBench {
        envs_per_actor: envs,
        chunks_per_actor: chunks,
        network_hidden: big.policy.mlp.hidden.clone(),
        actor_env_steps_per_s_no_publish: no_publish,
        actor_env_steps_per_s_publish: publish,
        publish_overhead_percent: 100.0 * (no_publish - publish) / no_publish,
        one_actor_env_steps_per_s: publish,
        two_actors_env_steps_per_s: two,
        scaling_two_vs_one: two / publish,
        weights_bytes: big_weights.len(),
        weight_broadcast_ms_p50: percentile(&latencies, 0.5),
        weight_broadcast_ms_p99: percentile(&latencies, 0.99),
        weight_broadcast_samples: latencies.len(),
        chunks_received: received.load(Ordering::Relaxed),
    })
}
