//! `PolicyWeights` ↔ a runnable policy. The safetensors bytes hold `policy.*` and `value.*`; the
//! JSON holds the run spec and the exact (f64) observation normaliser, so an actor normalises
//! exactly as the learner does; the proto `Normalizer` carries the same statistics as f32 for
//! readers in other languages.

use lhm_nets::{ActorCritic, RunningMeanStd};
use lhm_protos::{Normalizer, PolicyWeights, Role, WireMessage};
use serde::{Deserialize, Serialize};

use crate::{ClusterError, ClusterResult, RunSpec};

#[derive(Serialize, Deserialize)]
struct PolicyJson {
    spec: RunSpec,
    obs_norm: Option<RunningMeanStd>,
    /// Absent in messages from before value normalisation.
    #[serde(default)]
    value_norm: Option<RunningMeanStd>,
}

/// A decoded weights message: version, the run spec and a ready actor-critic.
#[derive(Debug, Clone)]
pub struct ReceivedPolicy {
    pub run_id: String,
    pub role: Role,
    pub version: u64,
    pub spec: RunSpec,
    pub actor_critic: ActorCritic,
}

fn normalizer(norm: &RunningMeanStd) -> Normalizer {
    Normalizer {
        count: norm.count(),
        mean: norm.mean().iter().map(|&x| x as f32).collect(),
        var: norm.var().iter().map(|&x| x as f32).collect(),
        epsilon: norm.epsilon,
        clip: norm.clip,
    }
}

/// Builds the weights message of `ac` at `version`.
pub fn encode_policy(
    run_id: &str,
    role: Role,
    version: u64,
    spec: &RunSpec,
    ac: &ActorCritic,
) -> ClusterResult<PolicyWeights> {
    let json = serde_json::to_string(&PolicyJson {
        spec: spec.clone(),
        obs_norm: ac.obs_norm.clone(),
        value_norm: ac.value_norm.clone(),
    })
    .map_err(|e| ClusterError::Weights(format!("cannot serialise the run spec: {e}")))?;
    Ok(PolicyWeights {
        run_id: run_id.to_owned(),
        role: role as i32,
        version,
        safetensors: ac.weights_safetensors()?,
        obs_normalizer: ac.obs_norm.as_ref().map(normalizer),
        amp_normalizer: None,
        config_json: json,
        ..PolicyWeights::versioned()
    })
}

/// Decodes and checks a weights message and builds its actor-critic.
pub fn decode_policy(bytes: &[u8]) -> ClusterResult<ReceivedPolicy> {
    let msg = PolicyWeights::decode_checked(bytes)?;
    let json: PolicyJson = serde_json::from_str(&msg.config_json)
        .map_err(|e| ClusterError::Weights(format!("config_json: {e}")))?;
    let spec = json.spec;
    let mut ac = ActorCritic::new(spec.obs_dim, spec.act_dim, &spec.actor_critic)?;
    ac.load_weights_safetensors(&msg.safetensors)?;
    match (&ac.obs_norm, &json.obs_norm) {
        (None, None) => {}
        (Some(own), Some(norm)) if norm.dim() == own.dim() => ac.obs_norm = Some(norm.clone()),
        _ => {
            return Err(ClusterError::Weights(
                "config_json: observation normaliser missing or of the wrong width".into(),
            ))
        }
    }
    match (&ac.value_norm, &json.value_norm) {
        (None, None) => {}
        (Some(_), Some(norm)) if norm.dim() == 1 => ac.value_norm = Some(norm.clone()),
        _ => {
            return Err(ClusterError::Weights(
                "config_json: value normaliser missing or not of width 1".into(),
            ))
        }
    }
    Ok(ReceivedPolicy {
        run_id: msg.run_id,
        role: Role::try_from(msg.role).unwrap_or(Role::Unspecified),
        version: msg.version,
        spec,
        actor_critic: ac,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use lhm_nets::ActorCriticConfig;
    use lhm_protos::prost::Message;

    fn spec() -> RunSpec {
        RunSpec {
            obs_dim: 4,
            act_dim: 2,
            amp_dim: 0,
            actor_critic: ActorCriticConfig::with_hidden(&[8]),
            env: Default::default(),
            sim: Default::default(),
            tasks: crate::TaskSet::TrainSingleObject,
            chunk_steps: 16,
            record_every_episodes: 0,
            chunk_sets_per_version: 0,
            teacher_mix: 0.0,
        }
    }

    #[test]
    fn weights_round_trip_with_their_normaliser() {
        let mut s = spec();
        s.actor_critic.normalize_value = true;
        let mut ac = ActorCritic::new(4, 2, &s.actor_critic).unwrap();
        if let Some(norm) = ac.obs_norm.as_mut() {
            norm.update(&[1.0, 2.0, 3.0, 4.0, -1.0, 0.5, 0.25, 8.0])
                .unwrap();
        }
        if let Some(norm) = ac.value_norm.as_mut() {
            norm.update(&[10.0, 30.0]).unwrap();
        }
        let msg = encode_policy("run", Role::Teacher1, 7, &s, &ac).unwrap();
        let got = decode_policy(&msg.encode_checked().unwrap()).unwrap();
        assert_eq!(got.version, 7);
        assert_eq!(got.role, Role::Teacher1);
        assert_eq!(got.spec, s);
        assert_eq!(got.actor_critic.obs_norm, ac.obs_norm);
        assert_eq!(got.actor_critic.value_norm, ac.value_norm);
        let obs = [0.3, -0.1, 2.0, 5.0];
        assert_eq!(
            got.actor_critic.values(&obs).unwrap(),
            ac.values(&obs).unwrap()
        );
        assert_eq!(
            got.actor_critic.act_deterministic(&obs).unwrap(),
            ac.act_deterministic(&obs).unwrap()
        );
    }

    #[test]
    fn broken_weights_are_errors() {
        let s = spec();
        let ac = ActorCritic::new(4, 2, &s.actor_critic).unwrap();
        let mut msg = encode_policy("run", Role::Teacher1, 1, &s, &ac).unwrap();
        msg.config_json = "{".into();
        let err = decode_policy(&msg.encode_to_vec()).unwrap_err();
        assert!(err.to_string().contains("config_json"), "{err}");
        let mut msg = encode_policy("run", Role::Teacher1, 1, &s, &ac).unwrap();
        msg.safetensors.truncate(10);
        assert!(decode_policy(&msg.encode_to_vec()).is_err());
    }
}
