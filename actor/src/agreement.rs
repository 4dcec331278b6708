//! How closely a VLA policy reproduces the policy it was distilled from, along its own rollouts:
//! at every step of a VLA episode (deterministic actions, the instruction heard, exactly as
//! [`crate::eval`] runs it) the VLA's action with the instruction, its action with the
//! instruction blanked, and the labeller's action on the privileged state of that same step.
//! Task success says nothing while the labeller itself fails; this measures the distillation
//! and what language is worth to it, per split (the unseen split's instructions use sentence
//! frames never seen in training).

use crate::eval::EvalSetup;
use crate::rollout::vla_view;
use lhm_nets::{ActorCritic, NetError};
use lhm_scenes::Task;
use lhm_sim::vla::PAD;
use serde::Serialize;

/// Mean squared action differences over every step probed (per action dimension).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Agreement {
    pub episodes: usize,
    pub steps: u64,
    /// The VLA with the instruction against the labeller.
    pub mse_language: f64,
    /// The VLA with the instruction blanked against the labeller.
    pub mse_no_language: f64,
    /// The VLA with against without the instruction: how much the words move its action.
    pub mse_language_vs_blank: f64,
    /// Variance of the labeller's actions over the same steps (the MSE of always answering
    /// their mean): 1 − mse / this is the share of the labeller's action variance reproduced.
    pub labeller_variance: f64,
}

impl Agreement {
    /// 1 − mse_language / labeller_variance.
    pub fn explained_language(&self) -> f64 {
        1.0 - self.mse_language / self.labeller_variance
    }

    /// 1 − mse_no_language / labeller_variance.
    pub fn explained_no_language(&self) -> f64 {
        1.0 - self.mse_no_language / self.labeller_variance
    }
}

fn squared_distance(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum()
}

/// Rolls `vla` out on each task (seed 0) for at most `max_steps` control steps and compares, at
/// every step, its actions with and without the instruction to `labeller`'s on the privileged
/// observation. `vla` must have a VLA encoder and `labeller` must read `setup.env`'s state
/// observation.
pub fn vla_agreement(
    vla: &ActorCritic,
    labeller: &ActorCritic,
    setup: &EvalSetup,
    tasks: &[Task],
    max_steps: u32,
) -> Result<Agreement, NetError> {
    let Some(encoder) = vla.policy.encoder() else {
        return Err(NetError::Config(
            "the agreement probe needs a VLA policy (one with an image encoder)".into(),
        ));
    };
    let view = vla_view(encoder.config(), true);
    let tokens = view.layout.tokens_at()..view.layout.tokens_at() + view.layout.max_tokens;
    let act_dim = vla.act_dim();
    let mut sums = [0.0f64; 3];
    let (mut label_sum, mut label_sq) = (vec![0.0f64; act_dim], vec![0.0f64; act_dim]);
    let mut steps = 0u64;
    for task in tasks {
        let mut env = setup.env_for(task, 0);
        for _ in 0..max_steps {
            let heard = view.observation(&env);
            let mut blank = heard.clone();
            blank[tokens.clone()].fill(PAD as f32);
            let with = vla.act_deterministic(&heard)?;
            let without = vla.act_deterministic(&blank)?;
            let label = labeller.act_deterministic(&env.observation())?;
            sums[0] += squared_distance(&with, &label);
            sums[1] += squared_distance(&without, &label);
            sums[2] += squared_distance(&with, &without);
            for (k, v) in label.iter().enumerate() {
                label_sum[k] += f64::from(*v);
                label_sq[k] += f64::from(*v).powi(2);
            }
            steps += 1;
            let r = env.step(&with);
            if r.done || r.truncated || r.physics_invalid {
                break;
            }
        }
    }
    let n = steps.max(1) as f64;
    let per_value = n * act_dim as f64;
    let variance: f64 = label_sum
        .iter()
        .zip(&label_sq)
        .map(|(s, q)| q / n - (s / n).powi(2))
        .sum::<f64>()
        / act_dim as f64;
    Ok(Agreement {
        episodes: tasks.len(),
        steps,
        mse_language: sums[0] / per_value,
        mse_no_language: sums[1] / per_value,
        mse_language_vs_blank: sums[2] / per_value,
        labeller_variance: variance,
    })
}
