//! The predictive-sampling planner (`lhm_sim::plan`) on the environment itself, without clips:
//! it finds corrections that keep a pushed character up where the neutral pose falls, its plans
//! are reproducible from the seed, and bad settings are refused.

use lhm_scenes::Benchmark;
use lhm_sim::env::{EnvConfig, TaskEnv};
use lhm_sim::motion::retarget::KinematicPose;
use lhm_sim::plan::{down, Planner, PlannerConfig};
use lhm_sim::{CharacterModel, SimConfig};
use rapier3d::math::{Rotation, Vector};

/// Task train-0001 with its furniture removed and its objects far away: the character alone.
fn empty_env(model: &CharacterModel, bench: &Benchmark) -> TaskEnv {
    let (_, mut task) = bench.task("train-0001").unwrap();
    task.obstacles.clear();
    task.room_size = [60.0, 60.0];
    for o in &mut task.objects {
        o.pos[0] += 25.0;
    }
    TaskEnv::new(
        model,
        &task,
        &bench.catalogue,
        SimConfig::default(),
        EnvConfig::default(),
    )
}

/// Every body of the standing character moving at `v` m/s along its heading.
fn push(env: &mut TaskEnv, model: &CharacterModel, v: f32) {
    let mut states = env.world.body_states();
    let forward = states[0].rot * Vector::X;
    let dir = Vector::new(forward.x, forward.y, 0.0).normalize_or_zero();
    for b in &mut states {
        b.linvel = dir * v;
        b.angvel = Vector::ZERO;
    }
    let pose = KinematicPose {
        root_pos: states[0].pos,
        root_rot: states[0].rot,
        local_rots: vec![Rotation::IDENTITY; model.bodies.len()],
    };
    env.world.set_character_state(&pose, &states);
}

/// Control steps up (of `steps`) with `act` choosing each action.
fn steps_up(env: &mut TaskEnv, steps: usize, mut act: impl FnMut(&TaskEnv) -> Vec<f32>) -> usize {
    for t in 0..steps {
        let action = act(env);
        let r = env.step(&action);
        if down(env, &r, 0.7) {
            return t;
        }
    }
    steps
}

/// A planner small enough to step a few times in a test, on one thread.
fn small_config() -> PlannerConfig {
    PlannerConfig {
        samples: 4,
        horizon: 6,
        knot: 3,
        threads: 1,
        ..PlannerConfig::default()
    }
}

fn planner_config() -> PlannerConfig {
    PlannerConfig {
        samples: 16,
        horizon: 20,
        ..PlannerConfig::default()
    }
}

#[test]
fn the_planner_keeps_a_pushed_character_up_where_the_neutral_pose_falls() {
    let model = CharacterModel::amp_humanoid();
    let bench = Benchmark::embedded().unwrap();
    let steps = 120;
    let v = 0.6;

    let mut env = empty_env(&model, &bench);
    push(&mut env, &model, v);
    let zero = vec![0.0; model.dofs.len()];
    let neutral = steps_up(&mut env, steps, |_| zero.clone());
    assert!(neutral < steps, "the neutral pose stood a {v} m/s push");

    let mut env = empty_env(&model, &bench);
    push(&mut env, &model, v);
    let config = planner_config();
    let mut workers: Vec<TaskEnv> = (0..config.threads)
        .map(|_| empty_env(&model, &bench))
        .collect();
    let mut planner = Planner::new(config, model.dofs.len()).unwrap();
    let planned = steps_up(&mut env, steps, |env| planner.act(env, &mut workers));
    assert_eq!(
        planned, steps,
        "the planner fell after {planned} steps (neutral pose: {neutral})"
    );
}

#[test]
fn the_same_seed_plans_the_same_actions_and_one_sample_plays_the_nominal_plan() {
    let model = CharacterModel::amp_humanoid();
    let bench = Benchmark::embedded().unwrap();
    let first_actions = |config: PlannerConfig| {
        let env = empty_env(&model, &bench);
        let mut workers = vec![empty_env(&model, &bench)];
        let mut planner = Planner::new(config, model.dofs.len()).unwrap();
        let mut env = env;
        let mut out = Vec::new();
        for _ in 0..3 {
            let a = planner.act(&env, &mut workers);
            env.step(&a);
            out.push(a);
        }
        out
    };
    let config = small_config();
    let a = first_actions(config.clone());
    assert_eq!(a, first_actions(config.clone()));
    assert!(
        a.iter().flatten().any(|&x| x != 0.0),
        "sampling never moved the plan off zero"
    );
    let nominal_only = first_actions(PlannerConfig {
        samples: 1,
        ..config
    });
    assert!(nominal_only.iter().flatten().all(|&x| x == 0.0));
}

#[test]
fn bad_planner_settings_are_refused_by_name() {
    for (config, field) in [
        (
            PlannerConfig {
                samples: 0,
                ..PlannerConfig::default()
            },
            "samples",
        ),
        (
            PlannerConfig {
                horizon: 0,
                ..PlannerConfig::default()
            },
            "horizon",
        ),
        (
            PlannerConfig {
                sigma: f32::NAN,
                ..PlannerConfig::default()
            },
            "sigma",
        ),
    ] {
        let err = Planner::new(config, 28).unwrap_err();
        assert!(err.contains(field), "{err}");
    }
}

#[test]
fn the_posture_cost_is_nothing_standing_and_grows_once_the_character_has_fallen() {
    let model = CharacterModel::amp_humanoid();
    let bench = Benchmark::embedded().unwrap();
    let config = PlannerConfig {
        height_cost: 20.0,
        tilt_cost: 10.0,
        ..PlannerConfig::default()
    };
    let mut env = empty_env(&model, &bench);
    assert!(
        lhm_sim::plan::posture_cost(&env, &config) < 0.05,
        "standing start: {}",
        lhm_sim::plan::posture_cost(&env, &config)
    );
    push(&mut env, &model, 1.0);
    let zero = vec![0.0; model.dofs.len()];
    let up = steps_up(&mut env, 200, |_| zero.clone());
    assert!(up < 200, "a 1 m/s push did not topple the neutral pose");
    let fallen = lhm_sim::plan::posture_cost(&env, &config);
    assert!(fallen > 2.0, "fallen: {fallen}");
}

#[test]
fn a_planner_moves_only_the_dofs_it_plans() {
    let model = CharacterModel::amp_humanoid();
    let bench = Benchmark::embedded().unwrap();
    let d = model.dofs.len();
    let planned: Vec<bool> = (0..d).map(|i| i % 2 == 0).collect();
    let config = small_config();
    let mut planner = Planner::new(config.clone(), d)
        .unwrap()
        .with_planned(planned.clone())
        .unwrap();
    let mut env = empty_env(&model, &bench);
    let mut workers = vec![empty_env(&model, &bench)];
    let mut moved = vec![false; d];
    for _ in 0..3 {
        let a = planner.act(&env, &mut workers);
        for (m, x) in moved.iter_mut().zip(&a) {
            *m |= *x != 0.0;
        }
        env.step(&a);
    }
    for i in 0..d {
        if !planned[i] {
            assert!(!moved[i], "DoF {i} is not planned but moved");
        }
    }
    assert!(moved.iter().any(|&m| m), "nothing moved");
    assert!(Planner::new(config, d)
        .unwrap()
        .with_planned(vec![true; d - 1])
        .is_err());
}

#[test]
fn around_a_prior_one_sample_plays_the_prior_closed_loop_and_more_samples_correct_it() {
    let model = CharacterModel::amp_humanoid();
    let bench = Benchmark::embedded().unwrap();
    let d = model.dofs.len();
    // A closed-loop prior: every action depends on the observation it is given.
    let prior = |obs: &[f32]| -> Vec<f32> {
        (0..d)
            .map(|j| (0.3 * obs[j % obs.len()]).clamp(-0.5, 0.5))
            .collect()
    };
    let prior_ref: lhm_sim::plan::Prior = &prior;

    let mut played = empty_env(&model, &bench);
    let mut reference = empty_env(&model, &bench);
    let mut workers = vec![empty_env(&model, &bench)];
    let mut planner = Planner::new(
        PlannerConfig {
            samples: 1,
            ..small_config()
        },
        d,
    )
    .unwrap();
    for _ in 0..5 {
        let a = planner.act_around(&played, &mut workers, Some(prior_ref));
        let expected = prior(&reference.observation());
        assert_eq!(a, expected, "one sample must play the prior's own action");
        played.step(&a);
        reference.step(&expected);
    }

    // Around a prior that does nothing useful (it lets a 0.6 m/s push topple the character, as
    // the neutral pose does), the planner's corrections keep the character up.
    let steps = 120;
    let limp = |_: &[f32]| -> Vec<f32> { vec![0.0; d] };
    let mut env = empty_env(&model, &bench);
    push(&mut env, &model, 0.6);
    let alone = steps_up(&mut env, steps, |env| limp(&env.observation()));
    assert!(alone < steps, "the prior alone stood the push");
    let mut env = empty_env(&model, &bench);
    push(&mut env, &model, 0.6);
    let config = planner_config();
    let mut workers: Vec<TaskEnv> = (0..config.threads)
        .map(|_| empty_env(&model, &bench))
        .collect();
    let mut planner = Planner::new(config, d).unwrap();
    let limp_ref: lhm_sim::plan::Prior = &limp;
    let corrected = steps_up(&mut env, steps, |env| {
        let a = planner.act_around(env, &mut workers, Some(limp_ref));
        assert!(a.iter().all(|x| (-1.0..=1.0).contains(x)));
        a
    });
    assert_eq!(
        corrected, steps,
        "around the prior the planner fell after {corrected} steps (the prior alone: {alone})"
    );
}
