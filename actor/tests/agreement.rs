//! The VLA agreement probe: its figures are the mean squared action differences it says they are,
//! measured on the VLA's own rollout, and the instruction's share is measured, not assumed.

use lhm_actor::agreement::vla_agreement;
use lhm_actor::eval::EvalSetup;
use lhm_actor::rollout::vla_view;
use lhm_nets::{ActorCritic, ActorCriticConfig, VlaEncoderConfig};
use lhm_scenes::{Benchmark, Split};
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::vla::Vocabulary;
use lhm_sim::{CharacterModel, SimConfig};

#[test]
fn the_probe_measures_the_vla_against_its_labeller_with_and_without_words() {
    let bench = Benchmark::embedded().unwrap();
    let model = CharacterModel::amp_humanoid();
    let env = EnvConfig::default();
    let sim = SimConfig::default();
    let tasks = &bench.tasks(Split::Train)[..1];
    let encoder = VlaEncoderConfig {
        proprio_dim: lhm_sim::obs::proprioception_dim(&model),
        max_tokens: 8,
        image_size: 8,
        vocabulary: Vocabulary::from_instructions(
            tasks[0].sequence.iter().map(|s| s.instruction.as_str()),
        )
        .words,
        conv_channels: vec![4],
        image_features: 6,
        word_dim: 5,
        text_features: 7,
    };
    let mut config = ActorCriticConfig::with_hidden(&[16]);
    config.policy.vla = Some(encoder.clone());
    let act_dim = model.dofs.len();
    let vla = ActorCritic::new(encoder.obs_dim(), act_dim, &config).unwrap();
    let labeller = ActorCritic::new(
        TaskEnv::obs_dim(&model, &env),
        act_dim,
        &ActorCriticConfig::with_hidden(&[16]),
    )
    .unwrap();
    let setup = EvalSetup {
        model: &model,
        catalogue: &bench.catalogue,
        sim: &sim,
        env: &env,
        batch: 1,
        language: true,
        gait: None,
        max_steps: None,
        action_std: 0.0,
    };
    // One step, by hand: the same environment, the same three actions.
    let one = vla_agreement(&vla, &labeller, &setup, tasks, 1).unwrap();
    let probe_env = setup.env_for(&tasks[0], 0);
    let with = vla
        .act_deterministic(&vla_view(&encoder, true).observation(&probe_env))
        .unwrap();
    let without = vla
        .act_deterministic(&vla_view(&encoder, false).observation(&probe_env))
        .unwrap();
    let label = labeller
        .act_deterministic(&probe_env.observation())
        .unwrap();
    let mse = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| f64::from(x - y).powi(2))
            .sum::<f64>()
            / act_dim as f64
    };
    assert_eq!((one.episodes, one.steps), (1, 1));
    assert!((one.mse_language - mse(&with, &label)).abs() < 1e-12);
    assert!((one.mse_no_language - mse(&without, &label)).abs() < 1e-12);
    assert!((one.mse_language_vs_blank - mse(&with, &without)).abs() < 1e-12);
    assert!(
        one.labeller_variance.abs() < 1e-12,
        "one step has no spread"
    );
    // Along a rollout: the words move an untrained VLA's actions, and the labeller's actions vary.
    let many = vla_agreement(&vla, &labeller, &setup, tasks, 20).unwrap();
    assert_eq!(many.steps, 20);
    assert!(many.mse_language_vs_blank > 0.0, "{many:?}");
    assert!(many.labeller_variance > 0.0, "{many:?}");
    assert!(many.explained_language().is_finite());
    // A state policy is not a VLA.
    assert!(vla_agreement(&labeller, &labeller, &setup, tasks, 1).is_err());
}
