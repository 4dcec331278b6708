//! Checkpoint/restore is exact: K updates, save, load into a fresh learner, update K+1; every
//! parameter, optimiser moment, RNG state, normaliser and the replay buffer must equal, bit for
//! bit, those of a run that did K+1 updates without interruption.

use std::path::PathBuf;

use lhm_learner::{
    AccuracyTarget, AmpConfig, AmpSetup, Learner, LearnerConfig, LearnerError, PpoBatch, PpoConfig,
};
use lhm_nets::checkpoint::CheckpointError;
use lhm_nets::{ActorCriticConfig, LogStd, MlpConfig, SplitMix64};

const OBS: usize = 5;
const ACT: usize = 3;
const FEAT: usize = 4;
const ROWS: usize = 96;

fn config() -> LearnerConfig {
    config_keeping(1.0)
}

/// [`config`] with the replay buffer keeping `keep` of each rollout's agent rows.
fn config_keeping(keep: f64) -> LearnerConfig {
    config_with(keep, None)
}

/// [`config_keeping`] with the discriminator's rate steered by `target`.
fn config_with(keep: f64, target: Option<AccuracyTarget>) -> LearnerConfig {
    let mut actor_critic = ActorCriticConfig::with_hidden(&[32, 32]);
    actor_critic.policy.log_std = LogStd::Learned(-1.0);
    // The value normaliser's statistics must survive the checkpoint too.
    actor_critic.normalize_value = true;
    LearnerConfig {
        obs_dim: OBS,
        act_dim: ACT,
        actor_critic,
        ppo: PpoConfig {
            epochs: 2,
            minibatch_size: 40,
            seed: 17,
            ..PpoConfig::default()
        },
        amp: Some(AmpSetup {
            feature_dim: FEAT,
            config: AmpConfig {
                disc: MlpConfig::with_hidden(&[16, 16]),
                minibatch_size: 40,
                epochs: 2,
                replay_capacity: 150,
                replay_keep_fraction: keep,
                seed: 23,
                accuracy_target: target,
                ..AmpConfig::default()
            },
        }),
    }
}

/// One training iteration on synthetic data drawn from `iteration` (actions from the policy).
fn train_step(learner: &mut Learner, iteration: u64) {
    let mut rng = ppo_step(learner, iteration);
    let agent: Vec<f32> = (0..ROWS * FEAT)
        .map(|_| rng.uniform(-1.0, 1.0) as f32)
        .collect();
    let demo: Vec<f32> = (0..ROWS * FEAT)
        .map(|_| rng.uniform(0.0, 2.0) as f32)
        .collect();
    learner.amp.as_mut().unwrap().update(&agent, &demo).unwrap();
    learner.counters.iteration += 1;
    learner.counters.samples += ROWS as u64;
}

/// The PPO half of [`train_step`]; returns the generator for the AMP half.
fn ppo_step(learner: &mut Learner, iteration: u64) -> SplitMix64 {
    let mut rng = SplitMix64::new(1000 + iteration);
    let obs: Vec<f32> = (0..ROWS * OBS)
        .map(|_| rng.uniform(-2.0, 3.0) as f32)
        .collect();
    let out = learner.actor_critic.act(&obs, &mut rng).unwrap();
    let advantages: Vec<f32> = (0..ROWS).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
    let returns: Vec<f32> = out
        .values
        .iter()
        .zip(&advantages)
        .map(|(v, a)| v + a)
        .collect();
    let batch = PpoBatch {
        obs,
        actions: out.actions,
        old_log_probs: out.log_probs,
        old_values: out.values,
        advantages,
        returns,
    };
    learner
        .ppo
        .update(&mut learner.actor_critic, &batch)
        .unwrap();
    rng
}

fn scratch(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("lhm-learner-resume-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn resumed_run_matches_uninterrupted_run_bit_for_bit() {
    resume_matches_uninterrupted(1.0, "exact");
}

#[test]
fn resumed_run_keeping_part_of_each_rollout_matches_bit_for_bit() {
    // The keep draws come from the discriminator's RNG, which the checkpoint carries; 0.6 of
    // 3 x 96 rows wraps the 150-row ring before the save.
    resume_matches_uninterrupted(0.6, "exact-keep");
}

#[test]
fn resumed_run_with_a_steered_discriminator_rate_matches_bit_for_bit() {
    // The rate is steered after each update and must come back from the checkpoint.
    let target = AccuracyTarget {
        accuracy: 0.51,
        factor: 2.0,
        min_lr_fraction: 1e-3,
    };
    // A fast configured rate, so the discriminator passes the target within the run.
    let config = || {
        let mut c = config_with(1.0, Some(target.clone()));
        if let Some(amp) = c.amp.as_mut() {
            amp.config.adam.lr = 3e-2;
        }
        c
    };
    let learner = resume_matches(config, "exact-steered");
    let amp = learner.amp.as_ref().unwrap();
    assert!(
        amp.adam.config.lr < amp.config.adam.lr,
        "the rate was steered: {}",
        amp.adam.config.lr
    );
}

fn resume_matches_uninterrupted(keep: f64, name: &str) {
    resume_matches(|| config_keeping(keep), name);
}

/// Runs K updates, saves, resumes and runs one more against K+1 straight; returns the straight
/// learner.
fn resume_matches(config: impl Fn() -> LearnerConfig, name: &str) -> Learner {
    const K: u64 = 3;
    let dir = scratch(name);
    let mut interrupted = Learner::new(config()).unwrap();
    for k in 0..K {
        train_step(&mut interrupted, k);
    }
    interrupted.save(&dir.join("k")).unwrap();
    drop(interrupted);
    let mut resumed = Learner::load(&dir.join("k"), Some(&config())).unwrap();
    assert_eq!(resumed.counters.iteration, K);
    train_step(&mut resumed, K);

    let mut straight = Learner::new(config()).unwrap();
    for k in 0..=K {
        train_step(&mut straight, k);
    }

    let a = resumed.named_tensors().unwrap();
    let b = straight.named_tensors().unwrap();
    assert_eq!(a.len(), b.len());
    let mut compared = 0usize;
    for ((na, ta), (nb, tb)) in a.iter().zip(&b) {
        assert_eq!(na, nb);
        let va: Vec<u32> = ta
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap()
            .iter()
            .map(|x| x.to_bits())
            .collect();
        let vb: Vec<u32> = tb
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap()
            .iter()
            .map(|x| x.to_bits())
            .collect();
        assert!(va == vb, "tensor {na} differs after resume");
        compared += va.len();
    }
    assert!(a.iter().any(|(n, _)| n == "amp.replay.features"));
    // Non-tensor state (RNGs, normalisers, step counts, ring head) through the saved files: the two
    // checkpoints must be byte-identical.
    resumed.save(&dir.join("resumed")).unwrap();
    straight.save(&dir.join("straight")).unwrap();
    let read = |name: &str| std::fs::read(dir.join(name)).unwrap();
    let tensors = |stem: &str| {
        std::fs::read(lhm_nets::checkpoint::committed_weights(&dir.join(stem)).unwrap()).unwrap()
    };
    assert!(
        tensors("resumed") == tensors("straight"),
        "safetensors files differ"
    );
    // The metadata names its own weights file; everything else must match.
    let json = |name: &str| {
        String::from_utf8(read(name))
            .unwrap()
            .replace(name.trim_end_matches(".json"), "STEM")
    };
    assert_eq!(json("resumed.json"), json("straight.json"));
    println!(
        "{} tensors, {compared} values identical after resume at update {}",
        a.len(),
        K + 1
    );
    let _ = std::fs::remove_dir_all(&dir);
    straight
}

#[test]
fn a_run_resumes_with_a_smaller_replay_buffer_holding_its_newest_rows() {
    let dir = scratch("shrink");
    let stem = dir.join("c");
    let mut learner = Learner::new(config()).unwrap();
    for k in 0..3 {
        train_step(&mut learner, k);
    }
    // 288 rows through a 150-row ring: full and wrapped.
    let stored = learner.amp.as_ref().unwrap().replay.clone();
    assert_eq!(stored.len(), 150);
    assert_ne!(stored.head(), 0);
    learner.save(&stem).unwrap();

    let mut smaller = config();
    let amp = &mut smaller.amp.as_mut().unwrap().config;
    amp.replay_capacity = 40;
    amp.replay_keep_fraction = 0.5;
    let resumed = Learner::load(&stem, Some(&smaller)).unwrap();
    let trainer = resumed.amp.as_ref().unwrap();
    assert_eq!(trainer.config.replay_capacity, 40);
    assert_eq!(trainer.config.replay_keep_fraction, 0.5);
    assert_eq!(
        resumed.config, smaller,
        "the requested replay settings apply"
    );
    // The newest 40 rows of the rollouts (the last rollout's last 40), oldest first.
    assert_eq!(trainer.replay.rows(), stored.clone().resized(40).rows());
    let mut rng = ppo_step(&mut Learner::new(config()).unwrap(), 2);
    let last: Vec<f32> = (0..ROWS * FEAT)
        .map(|_| rng.uniform(-1.0, 1.0) as f32)
        .collect();
    assert_eq!(trainer.replay.rows(), &last[(ROWS - 40) * FEAT..]);
    // The rest is the stored learner, and it trains on.
    assert_eq!(resumed.counters, learner.counters);
    let mut resumed = resumed;
    train_step(&mut resumed, 3);
    assert_eq!(resumed.amp.as_ref().unwrap().replay.len(), 40);

    // Any other AMP setting still has to match.
    let mut other = config();
    other.amp.as_mut().unwrap().config.logit_reg = 0.5;
    match Learner::load(&stem, Some(&other)) {
        Err(LearnerError::Checkpoint(CheckpointError::Mismatch { what, .. })) => {
            assert!(what.contains("amp"), "{what}")
        }
        other => panic!("expected a mismatch error, got {other:?}"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_policy_file_records_the_noise_its_stage_set_and_the_checkpoint_the_runs() {
    let mut config = config();
    config.actor_critic.policy.log_std = LogStd::Fixed(-4.0);
    let mut learner = Learner::new(config.clone()).unwrap();
    train_step(&mut learner, 0);
    // What a `[[stages]]` entry with `log_std = -3.5` does on entry.
    learner
        .actor_critic
        .set_fixed_log_std(&LogStd::Fixed(-3.5))
        .unwrap();
    let dir = scratch("stage-noise");
    learner.save(&dir.join("checkpoint")).unwrap();
    learner.save_policy(&dir.join("policy")).unwrap();
    let policy = Learner::load(&dir.join("policy"), None).unwrap();
    assert_eq!(
        policy.actor_critic.config.policy.log_std,
        LogStd::Fixed(-3.5)
    );
    let obs: Vec<f32> = (0..OBS).map(|i| i as f32 * 0.1).collect();
    let mean = policy.actor_critic.act_deterministic(&obs).unwrap();
    let draws = 4000;
    let many: Vec<f32> = obs.iter().cycle().take(draws * OBS).copied().collect();
    let acted = policy
        .actor_critic
        .act(&many, &mut SplitMix64::new(5))
        .unwrap();
    let var = acted
        .actions
        .chunks(ACT)
        .flat_map(|a| a.iter().zip(&mean).map(|(x, m)| ((x - m) as f64).powi(2)))
        .sum::<f64>()
        / (draws * ACT) as f64;
    let std = var.sqrt();
    assert!(
        (std / (-3.5f64).exp() - 1.0).abs() < 0.05,
        "sampled std {std}, want e^-3.5"
    );
    // The full checkpoint keeps the run's configuration, so the run resumes against it.
    let resumed = Learner::load(&dir.join("checkpoint"), Some(&config)).unwrap();
    assert_eq!(
        resumed.config.actor_critic.policy.log_std,
        LogStd::Fixed(-4.0)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn mismatched_or_corrupt_learner_checkpoints_are_refused_with_typed_errors() {
    let dir = scratch("refuse");
    let stem = dir.join("c");
    let mut learner = Learner::new(config()).unwrap();
    train_step(&mut learner, 0);
    learner.save(&stem).unwrap();

    let mut other = config();
    other.obs_dim = OBS + 1;
    match Learner::load(&stem, Some(&other)) {
        Err(LearnerError::Checkpoint(CheckpointError::Mismatch { what, .. })) => {
            assert!(what.contains("obs_dim"), "{what}")
        }
        other => panic!("expected a mismatch error, got {other:?}"),
    }

    let weights = lhm_nets::checkpoint::committed_weights(&stem).unwrap();
    let mut bytes = std::fs::read(&weights).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 1;
    std::fs::write(&weights, &bytes).unwrap();
    let err = Learner::load(&stem, None).unwrap_err();
    assert!(
        matches!(
            err,
            LearnerError::Checkpoint(CheckpointError::Checksum { .. })
        ),
        "{err}"
    );
    println!("corrupt checkpoint error: {err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_policy_alone_loads_and_acts_as_the_full_learner_without_its_amp_state() {
    let mut learner = Learner::new(config()).unwrap();
    for it in 0..3 {
        train_step(&mut learner, it);
    }
    let dir = scratch("policy-only");
    learner.save(&dir.join("checkpoint")).unwrap();
    learner.save_policy(&dir.join("policy")).unwrap();
    let policy = Learner::load(&dir.join("policy"), None).unwrap();
    assert!(policy.amp.is_none(), "no discriminator in the policy file");
    assert!(policy.config.amp.is_none());
    let obs: Vec<f32> = (0..4 * OBS).map(|i| (i as f32 * 0.37).sin()).collect();
    assert_eq!(
        policy.actor_critic.act_deterministic(&obs).unwrap(),
        learner.actor_critic.act_deterministic(&obs).unwrap()
    );
    let size = |stem: &str| {
        std::fs::metadata(lhm_nets::checkpoint::committed_weights(&dir.join(stem)).unwrap())
            .unwrap()
            .len()
    };
    assert!(
        size("policy") < size("checkpoint"),
        "the replay buffer and disc stay out"
    );
    // The weights alone: no Adam moments (which would triple it) beyond the safetensors header.
    let params: u64 = learner
        .actor_critic
        .named_vars()
        .iter()
        .map(|(_, v)| v.elem_count() as u64)
        .sum();
    assert!(
        size("policy") < 4 * params + 16 * 1024,
        "policy file {} bytes for {params} parameters",
        size("policy")
    );
    // Training from it starts a fresh optimiser and still steps.
    let mut from_policy = Learner::load(&dir.join("policy"), None).unwrap();
    let before = from_policy.actor_critic.act_deterministic(&obs).unwrap();
    ppo_step(&mut from_policy, 3);
    assert_ne!(
        from_policy.actor_critic.act_deterministic(&obs).unwrap(),
        before
    );
    let _ = std::fs::remove_dir_all(&dir);
}
