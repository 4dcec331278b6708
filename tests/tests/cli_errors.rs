//! Bad command-line input gets a clear error and a failing exit status, never a silent
//! substitute (a 0 count used to become 1) or a library's debug dump (an endpoint typo printed
//! Zenoh's internal `Json5Err { … }` with source paths).

use std::process::Command;

use lhm_e2e::lhm;

/// Runs `lhm args…`; (success, stderr).
fn run(args: &[&str]) -> (bool, String) {
    let dir = std::env::temp_dir().join(format!("lhm-cli-errors-{}", std::process::id()));
    let out = Command::new(lhm())
        .args(args)
        .args(["--runs-dir", &dir.display().to_string()])
        .output()
        .expect("running lhm");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn zero_counts_and_malformed_endpoints_are_refused_clearly() {
    for (args, expected) in [
        (vec!["train", "--no-amp", "--actors", "0"], "--actors"),
        (vec!["train", "--no-amp", "--envs", "0"], "--envs"),
        (
            vec!["train", "--no-amp", "--batch-steps", "0"],
            "batch_steps",
        ),
        (
            vec!["learner", "--no-amp", "--listen", "foo"],
            "not an endpoint",
        ),
    ] {
        let (ok, stderr) = run(&args);
        assert!(!ok, "{args:?} succeeded");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(
            !stderr.contains("Json5Err") && !stderr.contains(".cargo/registry"),
            "{args:?} printed a debug value: {stderr}"
        );
    }
    // `lhm actor` has no --runs-dir: checked on its own.
    let out = Command::new(lhm())
        .args(["actor", "--connect", "foo", "--envs", "2"])
        .output()
        .expect("running lhm");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("not an endpoint"),
        "{stderr}"
    );
    let out = Command::new(lhm())
        .args(["actor", "--connect", "tcp/127.0.0.1:1", "--envs", "0"])
        .output()
        .expect("running lhm");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("at least 1"),
        "{stderr}"
    );
}

/// `--scenes DIR` on the commands that take a task: a directory that is not a benchmark is a
/// clear error naming it; the repository's own scene files work as the built-in copy does.
#[test]
fn scenes_dir_is_read_or_refused_by_name() {
    let dir = std::env::temp_dir().join(format!("lhm-scenes-arg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("t.png");
    let png = png.display().to_string();
    let missing = dir.join("no-such-scenes").display().to_string();
    let policy = dir.join("no-policy").display().to_string();
    for args in [
        vec![
            "render-rollout",
            "train-0001",
            "-o",
            &png,
            "--scenes",
            &missing,
        ],
        vec!["eval", "--policy", &policy, "--scenes", &missing],
        vec![
            "record",
            "train-0001",
            "--policy",
            &policy,
            "-o",
            &png,
            "--scenes",
            &missing,
        ],
    ] {
        let out = Command::new(lhm())
            .args(&args)
            .output()
            .expect("running lhm");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(stderr.contains("no-such-scenes"), "{args:?}: {stderr}");
    }
    let out = Command::new(lhm())
        .args(["eval", "--policy", &policy, "--gifs", "2"])
        .output()
        .expect("running lhm");
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("--gifs needs --output"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/data");
    let out = Command::new(lhm())
        .args([
            "render-rollout",
            "train-0001",
            "--seconds",
            "0.1",
            "-o",
            &png,
        ])
        .args(["--scenes", data])
        .output()
        .expect("running lhm");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(std::fs::metadata(&png).is_ok_and(|m| m.len() > 0));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_stages_pipelines_and_demo_starts_are_refused_by_name() {
    // Stages that need teachers, t1 given a Teacher 1, a Teacher 2 outside the student stage.
    for (args, expected) in [
        (vec!["train", "--no-amp", "--stage", "t1-rr"], "--init-from"),
        (vec!["train", "--no-amp", "--stage", "t2"], "--teacher1"),
        (
            vec!["train", "--no-amp", "--stage", "student"],
            "--teacher1",
        ),
        (
            vec!["train", "--stage", "student", "--teacher1", "x/policy"],
            "--teacher2",
        ),
        (
            vec!["train", "--no-amp", "--teacher2", "x/policy"],
            "--stage student",
        ),
        (
            vec![
                "train",
                "--no-amp",
                "--stage",
                "t1",
                "--teacher1",
                "x/policy",
            ],
            "from scratch",
        ),
    ] {
        let (ok, stderr) = run(&args);
        assert!(!ok, "{args:?} succeeded");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
    let dir = std::env::temp_dir().join(format!("lhm-cli-pipeline-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[[stage]]\nstage = \"t2\"\niterations = 5\n").unwrap();
    let (ok, stderr) = run(&["pipeline", "--config", &bad.display().to_string()]);
    assert!(!ok);
    assert!(
        stderr.contains("bad.toml") && stderr.contains("Teacher 1 stage"),
        "{stderr}"
    );
    // render-rollout: a malformed demo-start time is refused before anything loads.
    let out = Command::new(lhm())
        .args(["render-rollout", "train-0001", "--demo-start", "walk@soon"])
        .args(["-o", &dir.join("x.gif").display().to_string()])
        .output()
        .expect("running lhm");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("not a time in seconds"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn eval_scores_the_zero_action_under_a_step_cap_and_refuses_bad_caps() {
    let out = Command::new(lhm())
        .args([
            "eval",
            "--policy",
            "zero",
            "--split",
            "unseen",
            "--limit",
            "2",
            "--seeds",
            "2",
            "--first-pair",
            "--max-steps",
            "5",
            "--json",
        ])
        .output()
        .expect("running lhm");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("eval --json");
    // Standing still for 5 steps: every episode runs to the cap and none falls.
    assert_eq!(json["mean_steps"], 5.0, "{json}");
    assert_eq!(json["fall_rate"], 0.0, "{json}");
    assert_eq!(json["max_steps"], 5, "{json}");
    assert_eq!(json["episodes"], 4, "{json}");
    for (args, expected) in [
        (vec!["--max-steps", "0"], "--max-steps"),
        (vec!["--teacher1", "zero"], "--teacher1"),
        // The built-in default has no gait to start at rest.
        (vec!["--from-rest"], "[env.gait]"),
    ] {
        let out = Command::new(lhm())
            .args(["eval", "--policy", "zero", "--limit", "1"])
            .args(&args)
            .output()
            .expect("running lhm");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
}

/// `render-rollout --eval-seed S` starts as `lhm eval`'s seed S: seed 0 is the task as
/// specified (the same still as no seed), a later seed turns the start heading (another still).
#[test]
fn render_rollout_starts_as_the_eval_seed_does() {
    let dir = std::env::temp_dir().join(format!("lhm-eval-seed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let still = |name: &str, seed: Option<&str>| {
        let png = dir.join(name);
        let mut cmd = Command::new(lhm());
        cmd.args(["render-rollout", "train-0001", "--seconds", "0.1", "-o"])
            .arg(&png);
        if let Some(s) = seed {
            cmd.args(["--eval-seed", s]);
        }
        let out = cmd.output().expect("running lhm");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        std::fs::read(&png).unwrap()
    };
    let plain = still("plain.png", None);
    assert_eq!(
        still("seed0.png", Some("0")),
        plain,
        "seed 0 is the task as specified"
    );
    assert_ne!(
        still("seed3.png", Some("3")),
        plain,
        "seed 3 turns the start heading"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
