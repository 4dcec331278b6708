//! AMP on a toy system: the "motion feature" of a step is the policy's 2-D action itself, and the
//! demonstrations are draws from a fixed Gaussian. Trained on the style reward alone, the policy
//! should come to match the demo distribution, which shows up as the discriminator's accuracy on
//! fresh samples falling from near 1 towards 0.5.

use lhm_learner::{
    compute_gae, AmpConfig, AmpTrainer, GaeInput, GaeParams, PpoBatch, PpoConfig, PpoTrainer,
};
use lhm_nets::{ActorCritic, ActorCriticConfig, AdamConfig, LogStd, MlpConfig, SplitMix64};

const DEMO_MEAN: [f64; 2] = [0.6, -0.4];
const DEMO_STD: [f64; 2] = [0.15, 0.1];
const BATCH: usize = 512;
const ITERATIONS: usize = 100;
/// Discriminator-only iterations first, so "early" accuracy is that of a trained discriminator
/// against the untrained policy.
const DISC_WARMUP: usize = 5;

fn demo_rows(n: usize, rng: &mut SplitMix64) -> Vec<f32> {
    (0..n)
        .flat_map(|_| {
            let (a, b) = rng.normal_pair();
            [
                (DEMO_MEAN[0] + DEMO_STD[0] * a) as f32,
                (DEMO_MEAN[1] + DEMO_STD[1] * b) as f32,
            ]
        })
        .collect()
}

#[test]
fn amp_policy_comes_to_match_the_demo_distribution() {
    let mut ac_config = ActorCriticConfig::with_hidden(&[64, 64]);
    ac_config.policy.log_std = LogStd::Learned(-1.5);
    ac_config.normalize_obs = false;
    let mut ac = ActorCritic::new(1, 2, &ac_config).unwrap();
    let mut ppo = PpoTrainer::new(
        PpoConfig {
            adam: AdamConfig {
                lr: 1e-3,
                ..AdamConfig::default()
            },
            value_clip: None,
            value_coef: 0.5,
            bound_coef: 1.0,
            epochs: 5,
            minibatch_size: 256,
            ..PpoConfig::default()
        },
        &ac,
    )
    .unwrap();
    let mut amp = AmpTrainer::new(
        2,
        AmpConfig {
            disc: MlpConfig::with_hidden(&[64, 64]),
            adam: AdamConfig {
                lr: 1e-3,
                ..AdamConfig::default()
            },
            grad_penalty: 1.0,
            epochs: 2,
            minibatch_size: 256,
            replay_capacity: 4096,
            task_reward_weight: 0.0,
            style_reward_weight: 1.0,
            ..AmpConfig::default()
        },
    )
    .unwrap();
    let mut rng = SplitMix64::new(4);
    let obs = vec![0f32; BATCH];
    let mut accuracy = Vec::new();
    for iter in 0..ITERATIONS {
        let out = ac.act(&obs, &mut rng).unwrap();
        let demo = demo_rows(BATCH, &mut rng);
        // Accuracy of the current discriminator on fresh agent and demo samples.
        let (demo_acc, agent_acc) = amp.accuracy(&out.actions, &demo).unwrap();
        accuracy.push(0.5 * (demo_acc + agent_acc));
        let style = amp.style_rewards(&out.actions).unwrap();
        let rewards = amp.combine_rewards(&vec![0.0; BATCH], &style).unwrap();
        let stats = amp.update(&out.actions, &demo).unwrap();
        // Every step is a whole (terminal) episode: the advantage is r - V.
        let gae = compute_gae(
            &GaeInput {
                steps: 1,
                envs: BATCH,
                rewards: &rewards,
                values: &out.values,
                dones: &vec![true; BATCH],
                truncated: &vec![false; BATCH],
                truncation_values: &vec![0.0; BATCH],
                last_values: &vec![0.0; BATCH],
            },
            GaeParams {
                gamma: 0.99,
                lambda: 0.95,
            },
        )
        .unwrap();
        let batch = PpoBatch {
            obs: obs.clone(),
            actions: out.actions.clone(),
            old_log_probs: out.log_probs,
            old_values: out.values,
            advantages: gae.advantages,
            returns: gae.returns,
        };
        if iter >= DISC_WARMUP {
            ppo.update(&mut ac, &batch).unwrap();
        }
        if iter % 5 == 0 || iter == DISC_WARMUP || iter + 1 == ITERATIONS {
            let mean = ac.act_deterministic(&[0.0]).unwrap();
            let std: Vec<f32> = ac.policy.log_std().exp().unwrap().to_vec1().unwrap();
            println!(
                "iter {iter:>3}: disc accuracy {:.3} (demo {demo_acc:.3}, agent {agent_acc:.3})  mean style reward {:.3}  policy mean [{:+.3}, {:+.3}] std [{:.3}, {:.3}]  gp {:.4}",
                accuracy[iter],
                style.iter().sum::<f32>() / BATCH as f32,
                mean[0], mean[1], std[0], std[1], stats.grad_penalty
            );
        }
    }
    let early = accuracy[DISC_WARMUP];
    let late = accuracy[ITERATIONS - 10..].iter().sum::<f64>() / 10.0;
    println!(
        "accuracy trajectory: {:?}",
        accuracy
            .iter()
            .map(|a| format!("{a:.2}"))
            .collect::<Vec<_>>()
    );
    println!("discriminator accuracy: early (iter {DISC_WARMUP}, before the first policy update) {early:.3}, late (mean of last 10) {late:.3}");
    assert!(
        early > 0.9,
        "the discriminator should separate the untrained policy from the demos: {early:.3}"
    );
    assert!(
        late < 0.65,
        "the policy should come to match the demos: {late:.3}"
    );
    let mean = ac.act_deterministic(&[0.0]).unwrap();
    let err =
        ((mean[0] as f64 - DEMO_MEAN[0]).powi(2) + (mean[1] as f64 - DEMO_MEAN[1]).powi(2)).sqrt();
    println!("policy mean error vs demo mean: {err:.3}");
    assert!(
        err < 0.2,
        "policy mean {mean:?} should approach the demo mean {DEMO_MEAN:?}"
    );
}
