//! Policy weights as in-memory safetensors (the learner's broadcast): exact round trip, and
//! truncated, foreign or mis-shaped bytes are refused without touching the network.

use lhm_nets::{ActorCritic, ActorCriticConfig};

fn net(seed: u64) -> ActorCritic {
    let mut config = ActorCriticConfig::with_hidden(&[16, 8]);
    config.init_seed = seed;
    ActorCritic::new(5, 3, &config).unwrap()
}

fn params(ac: &ActorCritic) -> Vec<Vec<f32>> {
    ac.named_vars()
        .iter()
        .map(|(_, v)| v.as_tensor().flatten_all().unwrap().to_vec1().unwrap())
        .collect()
}

#[test]
fn weights_round_trip_exactly() {
    let source = net(1);
    let target = net(2);
    assert_ne!(params(&source), params(&target));
    target
        .load_weights_safetensors(&source.weights_safetensors().unwrap())
        .unwrap();
    assert_eq!(params(&source), params(&target));
    let obs = [0.1, -0.2, 0.3, 0.4, -0.5];
    assert_eq!(
        source.act_deterministic(&obs).unwrap(),
        target.act_deterministic(&obs).unwrap()
    );
}

#[test]
fn bad_weights_are_refused_and_leave_the_network_alone() {
    let source = net(1);
    let target = net(2);
    let before = params(&target);
    let bytes = source.weights_safetensors().unwrap();
    for cut in [0, 7, bytes.len() / 2, bytes.len() - 1] {
        let err = target.load_weights_safetensors(&bytes[..cut]).unwrap_err();
        assert!(err.to_string().contains("policy weights"), "{err}");
    }
    // Same names, other shapes.
    let wider = ActorCritic::new(6, 3, &ActorCriticConfig::with_hidden(&[16, 8])).unwrap();
    let err = target
        .load_weights_safetensors(&wider.weights_safetensors().unwrap())
        .unwrap_err();
    assert!(err.to_string().contains("expected F32"), "{err}");
    assert_eq!(params(&target), before);
}
