//! Generalised advantage estimation (Schulman et al. 2016) over [T, N] rollouts stored time-major
//! (index t * N + n).
//!
//! Two ways an episode can end are kept apart:
//! - `done` (terminal state, e.g. a fall): the future is worth nothing, no bootstrap;
//! - `truncated` (time limit, cycle handoff): the future is cut off only by bookkeeping, so the
//!   step bootstraps from V(final observation), given per step in `truncation_values` (the next
//!   row of the buffer already belongs to the next episode, so it cannot be used).
//!
//! In both cases the advantage does not carry across the episode boundary. A step that is both
//! is treated as terminal.

use crate::error::{check_len, LearnerResult};

#[derive(Debug, Clone, Copy)]
pub struct GaeParams {
    pub gamma: f32,
    pub lambda: f32,
}

/// One rollout's per-step data, all [T, N] time-major except `last_values` [N], the value of the
/// observation after the last step (bootstrap for episodes still running).
#[derive(Debug, Clone, Copy)]
pub struct GaeInput<'a> {
    pub steps: usize,
    pub envs: usize,
    pub rewards: &'a [f32],
    pub values: &'a [f32],
    pub dones: &'a [bool],
    pub truncated: &'a [bool],
    /// V(final observation) where `truncated`; ignored elsewhere.
    pub truncation_values: &'a [f32],
    pub last_values: &'a [f32],
}

#[derive(Debug, Clone, PartialEq)]
pub struct GaeOutput {
    pub advantages: Vec<f32>,
    /// Value targets: advantages + values.
    pub returns: Vec<f32>,
}

pub fn compute_gae(input: &GaeInput, params: GaeParams) -> LearnerResult<GaeOutput> {
    let GaeInput { steps, envs, .. } = *input;
    let total = steps * envs;
    check_len("rewards", input.rewards.len(), total)?;
    check_len("values", input.values.len(), total)?;
    check_len("dones", input.dones.len(), total)?;
    check_len("truncated", input.truncated.len(), total)?;
    check_len("truncation_values", input.truncation_values.len(), total)?;
    check_len("last_values", input.last_values.len(), envs)?;
    let GaeParams { gamma, lambda } = params;

    let mut advantages = vec![0f32; total];
    let mut running = vec![0f32; envs];
    for t in (0..steps).rev() {
        for (n, running) in running.iter_mut().enumerate() {
            let i = t * envs + n;
            let next_value = if t + 1 == steps {
                input.last_values[n]
            } else {
                input.values[i + envs]
            };
            let (bootstrap, continues) = if input.dones[i] {
                (0.0, false)
            } else if input.truncated[i] {
                (input.truncation_values[i], false)
            } else {
                (next_value, true)
            };
            let delta = input.rewards[i] + gamma * bootstrap - input.values[i];
            *running = if continues {
                delta + gamma * lambda * *running
            } else {
                delta
            };
            advantages[i] = *running;
        }
    }
    let returns = advantages
        .iter()
        .zip(input.values)
        .map(|(a, v)| a + v)
        .collect();
    Ok(GaeOutput {
        advantages,
        returns,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &[f32], b: &[f32]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5)
    }

    /// T = 3, N = 2. Env 0: terminal at t = 1 (no bootstrap), new episode at t = 2.
    /// Env 1: time limit at t = 0 (bootstrap from its final observation, value 10), then runs on.
    #[test]
    fn terminal_and_truncated_steps_are_handled_differently() {
        let input = GaeInput {
            steps: 3,
            envs: 2,
            rewards: &[1.0, 2.0, 1.0, 0.0, 1.0, 1.0],
            values: &[0.5, 3.0, 0.5, 1.0, 2.0, 1.5],
            dones: &[false, false, true, false, false, false],
            truncated: &[false, true, false, false, false, false],
            truncation_values: &[0.0, 10.0, 0.0, 0.0, 0.0, 0.0],
            last_values: &[4.0, 2.0],
        };
        let (g, l) = (0.9f32, 0.8f32);
        let out = compute_gae(
            &input,
            GaeParams {
                gamma: g,
                lambda: l,
            },
        )
        .unwrap();
        // Env 0, by hand:
        // t=2: δ = 1 + 0.9·4 - 2 = 2.6, A = 2.6 (last step bootstraps from last_values)
        // t=1: terminal: δ = 1 - 0.5 = 0.5, A = 0.5 (the episode of t=2 is not added)
        // t=0: δ = 1 + 0.9·0.5 - 0.5 = 0.95, A = 0.95 + 0.72·0.5 = 1.31
        // Env 1:
        // t=2: δ = 1 + 0.9·2 - 1.5 = 1.3, A = 1.3
        // t=1: δ = 0 + 0.9·1.5 - 1 = 0.35, A = 0.35 + 0.72·1.3 = 1.286
        // t=0: truncated: δ = 2 + 0.9·10 - 3 = 8, A = 8 (bootstrap from the final obs, not values[t+1])
        let expected_adv = [1.31, 8.0, 0.5, 1.286, 2.6, 1.3];
        assert!(
            close(&out.advantages, &expected_adv),
            "{:?}",
            out.advantages
        );
        let expected_ret: Vec<f32> = expected_adv
            .iter()
            .zip(input.values)
            .map(|(a, v)| a + v)
            .collect();
        assert!(close(&out.returns, &expected_ret));
    }

    #[test]
    fn truncation_bootstraps_but_terminal_does_not() {
        // Single step, single env, reward 1, V = 0, final-observation value 5.
        let run = |done: bool, truncated: bool| {
            let input = GaeInput {
                steps: 1,
                envs: 1,
                rewards: &[1.0],
                values: &[0.0],
                dones: &[done],
                truncated: &[truncated],
                truncation_values: &[5.0],
                last_values: &[100.0],
            };
            compute_gae(
                &input,
                GaeParams {
                    gamma: 0.5,
                    lambda: 0.95,
                },
            )
            .unwrap()
            .advantages[0]
        };
        assert_eq!(run(true, false), 1.0);
        assert_eq!(run(false, true), 3.5);
        assert_eq!(run(true, true), 1.0);
        assert_eq!(run(false, false), 51.0);
    }

    #[test]
    fn wrong_lengths_are_errors() {
        let input = GaeInput {
            steps: 2,
            envs: 1,
            rewards: &[1.0],
            values: &[0.0, 0.0],
            dones: &[false, false],
            truncated: &[false, false],
            truncation_values: &[0.0, 0.0],
            last_values: &[0.0],
        };
        assert!(compute_gae(
            &input,
            GaeParams {
                gamma: 0.9,
                lambda: 0.9
            }
        )
        .is_err());
    }
}
