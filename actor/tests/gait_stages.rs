//! A `[[stages]]` entry that changes the gait's `angle_offsets` reaches the actors through the
//! run spec of each version: the rollout walks the new cycle from then on instead of keeping the
//! one it started with, and a spec whose offsets cannot be built is refused with the old cycle
//! kept. Its own test binary: it points `LHM_MOTION_DIR` at a synthetic clip for the process.

use lhm_actor::Rollout;
use lhm_cluster::{RunSpec, TaskSet};
use lhm_nets::ActorCriticConfig;
use lhm_protos::Role;
use lhm_scenes::Benchmark;
use lhm_sim::env::{EnvConfig, GaitConfig, TaskEnv};
use lhm_sim::motion::deepmimic::JOINTS;
use lhm_sim::{CharacterModel, SimConfig};
use std::collections::BTreeMap;

/// Writes a one-second DeepMimic walk (root forward at 1 m/s, the thighs swinging ±0.3 rad in
/// opposition) as the only installed clip, `synthwalk`, and returns its directory.
fn install_synthetic_walk() -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("lhm-gait-stages-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("deepmimic")).expect("clip dir");
    std::fs::write(dir.join("MANIFEST"), "").expect("manifest");
    let frames: Vec<Vec<f64>> = (0..31)
        .map(|k| {
            let s = (std::f64::consts::TAU * f64::from(k) / 30.0).sin();
            let mut f = vec![
                1.0 / 30.0,
                f64::from(k) / 30.0,
                0.9,
                0.0,
                1.0,
                0.0,
                0.0,
                0.0,
            ];
            for (name, len) in JOINTS {
                let swing = match name {
                    "right_thigh" => 0.3 * s,
                    "left_thigh" => -0.3 * s,
                    _ => 0.0,
                };
                f.extend(if len == 4 {
                    // A turn about the joint's z axis (DeepMimic quaternions are w, x, y, z).
                    vec![(swing / 2.0).cos(), 0.0, 0.0, (swing / 2.0).sin()]
                } else {
                    vec![0.0]
                });
            }
            f
        })
        .collect();
    // Debug of nested f64 vectors is JSON (finite values only).
    let json = format!("{{\"Loop\": \"wrap\", \"Frames\": {frames:?}}}");
    std::fs::write(dir.join("deepmimic/synthwalk.txt"), json).expect("clip");
    dir
}

#[test]
fn a_spec_with_other_angle_offsets_rebuilds_the_cycle_and_a_bad_one_keeps_the_old() {
    let dir = install_synthetic_walk();
    std::env::set_var("LHM_MOTION_DIR", &dir);
    let bench = Benchmark::embedded().unwrap();
    let model = CharacterModel::amp_humanoid();
    let env = EnvConfig {
        max_episode_steps: 20,
        gait: Some(GaitConfig {
            clip: "synthwalk".into(),
            ..GaitConfig::default()
        }),
        ..EnvConfig::default()
    };
    let spec = RunSpec {
        obs_dim: TaskEnv::obs_dim(&model, &env),
        act_dim: model.dofs.len(),
        amp_dim: TaskEnv::amp_dim(&model, &env),
        actor_critic: ActorCriticConfig::with_hidden(&[16]),
        env,
        sim: SimConfig::default(),
        tasks: TaskSet::Ids(vec!["train-0001.p1".into()]),
        chunk_steps: 8,
        record_every_episodes: 0,
        chunk_sets_per_version: 0,
        teacher_mix: 0.0,
    };
    let rollout = Rollout::new(spec.clone(), &bench, "run", "a", Role::Teacher1, 1, 3);
    std::fs::remove_dir_all(&dir).ok();
    let mut rollout = rollout.expect("a gait rollout on the synthetic clip");
    let knee = model
        .dofs
        .iter()
        .position(|d| d.name == "right_knee")
        .expect("a right knee");
    let hip = model
        .dofs
        .iter()
        .position(|d| d.name == "left_hip_y")
        .expect("a left hip");
    let cycle = rollout.gait_cycle().expect("the run walks a cycle");
    let len = cycle.len();
    let before: Vec<Vec<f32>> = (0..len).map(|k| cycle.at(k).1.to_vec()).collect();

    // A stage's offsets: the knee bent 0.2 rad more throughout, the hip by a ramp over the cycle.
    let ramp: Vec<f32> = (0..len).map(|k| 0.01 * k as f32).collect();
    let mut staged = spec.clone();
    staged.env.gait.as_mut().unwrap().angle_offsets = BTreeMap::from([
        ("right_knee".into(), vec![0.2]),
        ("left_hip_y".into(), ramp),
    ]);
    rollout.set_spec(staged.clone()).expect("the staged spec");
    let cycle = rollout.gait_cycle().expect("still a cycle");
    for (k, old) in before.iter().enumerate() {
        let new = cycle.at(k).1;
        for (d, (&a, &b)) in old.iter().zip(new).enumerate() {
            let want = a + match d {
                _ if d == knee => 0.2,
                _ if d == hip => 0.01 * k as f32,
                _ => 0.0,
            };
            assert!(
                (b - want).abs() < 1e-6,
                "step {k}, DoF {}: {b} where {want} was asked for",
                model.dofs[d].name
            );
        }
    }
    // Episodes go on under the new cycle.
    let ac =
        lhm_nets::ActorCritic::new(staged.obs_dim, staged.act_dim, &staged.actor_critic).unwrap();
    for _ in 0..24 {
        rollout.step(&ac, 1).expect("a step on the staged cycle");
    }

    // Offsets naming no DoF: refused by name, the staged cycle and spec kept.
    let mut bad = staged.clone();
    bad.env.gait.as_mut().unwrap().angle_offsets =
        BTreeMap::from([("right_kne".into(), vec![0.2])]);
    let e = rollout.set_spec(bad).expect_err("no such DoF").to_string();
    assert!(e.contains("right_kne"), "{e}");
    assert_eq!(rollout.spec, staged);
    let knee_at_3 = rollout.gait_cycle().unwrap().at(3).1[knee];
    assert!(
        (knee_at_3 - (before[3][knee] + 0.2)).abs() < 1e-6,
        "{knee_at_3}"
    );

    // Back to no offsets: the clip's own angles again.
    rollout.set_spec(spec).expect("the run's own spec");
    let cycle = rollout.gait_cycle().unwrap();
    assert!((0..len).all(|k| cycle.at(k).1 == before[k].as_slice()));
}
