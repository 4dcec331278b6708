//! `examples/python` reads what the Rust side publishes: a numpy run of a `PolicyWeights`
//! message recomputes the log-probabilities and values an actor wrote into a `TrajectoryChunk`.
//! Runs where a Python with numpy is found (`$LHM_PYTHON`, else `python3`;
//! `scripts/install-python-examples` makes one); prints SKIP and passes elsewhere.

use std::path::{Path, PathBuf};
use std::process::Command;

use lhm_cluster::{encode_policy, RunSpec, TaskSet};
use lhm_nets::{Activation, ActorCritic, ActorCriticConfig, LogStd, SplitMix64};
use lhm_protos::{EpisodeStats, Role, TrajectoryChunk, WireMessage};

fn python() -> Option<String> {
    let candidates = [
        std::env::var("LHM_PYTHON").ok(),
        std::env::var("HOME")
            .ok()
            .map(|h| format!("{h}/.cache/lhm/python/bin/python")),
        Some("python3".to_owned()),
    ];
    candidates.into_iter().flatten().find(|p| {
        Command::new(p)
            .args(["-c", "import numpy"])
            .output()
            .is_ok_and(|o| o.status.success())
    })
}

fn examples_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/python")
}

fn rows(rng: &mut SplitMix64, n: usize, scale: f32, shift: f32) -> Vec<f32> {
    (0..n)
        .map(|_| shift + scale * (2.0 * rng.next_f64() as f32 - 1.0))
        .collect()
}

/// A small actor-critic with every option the wire must carry: ELU and ReLU layers, a learned
/// log-std, non-trivial observation and value normalisers.
fn network(obs_dim: usize, act_dim: usize) -> (ActorCriticConfig, ActorCritic) {
    let mut config = ActorCriticConfig::with_hidden(&[8, 5]);
    config.policy.log_std = LogStd::Learned(-1.2);
    config.value.activation = Activation::Relu;
    config.normalize_value = true;
    config.init_seed = 7;
    let mut ac = ActorCritic::new(obs_dim, act_dim, &config).unwrap();
    let mut rng = SplitMix64::new(3);
    let seen = rows(&mut rng, 50 * obs_dim, 3.0, 1.5);
    ac.obs_norm.as_mut().unwrap().update(&seen).unwrap();
    let returns = rows(&mut rng, 40, 10.0, 4.0);
    ac.value_norm.as_mut().unwrap().update(&returns).unwrap();
    (config, ac)
}

#[test]
fn python_recomputes_the_chunks_log_probs_and_values_from_the_published_weights() {
    let Some(py) = python() else {
        eprintln!(
            "SKIP: no Python with numpy (set LHM_PYTHON or run scripts/install-python-examples)"
        );
        return;
    };
    let (obs_dim, act_dim, n) = (6usize, 3usize, 9usize);
    let (config, ac) = network(obs_dim, act_dim);
    let spec = RunSpec {
        obs_dim,
        act_dim,
        amp_dim: 0,
        actor_critic: config,
        env: Default::default(),
        sim: Default::default(),
        tasks: TaskSet::TrainSingleObject,
        chunk_steps: n as u32,
        record_every_episodes: 0,
        chunk_sets_per_version: 0,
        teacher_mix: 0.0,
    };
    let weights = encode_policy("py-check", Role::Teacher1, 42, &spec, &ac)
        .unwrap()
        .encode_checked()
        .unwrap();
    let mut rng = SplitMix64::new(11);
    // Observations well outside the normaliser's range, so its clip matters too.
    let observations = rows(&mut rng, n * obs_dim, 12.0, 0.0);
    let out = ac.act(&observations, &mut rng).unwrap();
    let chunk = TrajectoryChunk {
        run_id: "py-check".into(),
        actor_id: "a0".into(),
        role: Role::Teacher1.into(),
        policy_version: 42,
        num_steps: n as u32,
        obs_dim: obs_dim as u32,
        act_dim: act_dim as u32,
        observations: observations.clone(),
        actions: out.actions.clone(),
        log_probs: out.log_probs.clone(),
        values: out.values.clone(),
        rewards: (0..n).map(|i| i as f32 * 0.5).collect(),
        dones: vec![false; n],
        truncated: vec![false; n],
        truncation_values: vec![0.0; n],
        episodes: vec![EpisodeStats {
            episode_return: 3.0,
            length: 40,
            ..Default::default()
        }],
        ..TrajectoryChunk::versioned()
    }
    .encode_checked()
    .unwrap();
    let dir = std::env::temp_dir().join(format!("lhm-py-examples-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("policy.bin"), &weights).unwrap();
    std::fs::write(dir.join("chunk-0.bin"), &chunk).unwrap();

    let run = Command::new(&py)
        .arg(examples_dir().join("check_policy.py"))
        .arg("--weights")
        .arg(dir.join("policy.bin"))
        .arg("--chunk")
        .arg(dir.join("chunk-0.bin"))
        .output()
        .expect("running check_policy.py");
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        run.status.success(),
        "check_policy.py failed:\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(report["version"], 42);
    let c = &report["chunks"][0];
    assert_eq!(c["num_steps"], n as u64);
    assert_eq!(c["episodes"], 1);
    assert!(
        (c["reward_sum"].as_f64().unwrap() - 18.0).abs() < 1e-6,
        "{c}"
    );
    let lp = c["max_abs_log_prob_error"].as_f64().unwrap();
    let v = c["max_abs_value_error"].as_f64().unwrap();
    assert!(lp < 1e-3, "log-prob differs by {lp}: {c}");
    assert!(v < 1e-3, "value differs by {v}: {c}");
    let mean: Vec<f64> = c["mean_action_of_first_obs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let rust = ac.act_deterministic(&observations[..obs_dim]).unwrap();
    for (p, r) in mean.iter().zip(&rust) {
        assert!((p - *r as f64).abs() < 1e-4, "mean action {p} vs {r}");
    }
}
