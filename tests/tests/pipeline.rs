//! `lhm pipeline` end to end on loopback with the repository's smoke configuration: every stage
//! (t1, t1-rr, t2, the DAgger student with its dagger-server) runs in order, a SIGKILL inside a
//! stage (t1-rr, then the student) loses nothing finished, and running the same command again
//! completes the pipeline without redoing a finished stage.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use lhm_e2e::{scratch_dir, start_pipeline};

fn stage_status(root: &Path, stage: &str) -> serde_json::Value {
    std::fs::read(root.join(stage).join("status.json"))
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .unwrap_or(serde_json::Value::Null)
}

fn iteration(root: &Path, stage: &str) -> u64 {
    stage_status(root, stage)
        .pointer("/iteration")
        .and_then(|v| v.as_u64())
        .unwrap_or(0)
}

fn rows(path: &Path) -> usize {
    std::fs::read_to_string(path)
        .map(|t| t.lines().count().saturating_sub(1))
        .unwrap_or(0)
}

fn logs(dir: &Path) -> String {
    ["first.log", "second.log", "third.log"]
        .iter()
        .map(|n| {
            format!(
                "--- {n}\n{}",
                std::fs::read_to_string(dir.join(n)).unwrap_or_default()
            )
        })
        .collect()
}

#[test]
fn a_pipeline_killed_in_a_stage_finishes_when_run_again_without_redoing_finished_stages() {
    let dir = scratch_dir("pipeline");
    let config: PathBuf =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/pipeline-smoke.toml");
    let root = dir.join("runs/smoke");

    // Kill the first run once the second stage (t1-rr) has made an iteration.
    let mut first = start_pipeline(&dir, &config, "first.log");
    let deadline = Instant::now() + Duration::from_secs(240);
    while iteration(&root, "t1-rr") < 1 {
        assert!(
            first.is_running(),
            "the pipeline ended before t1-rr ran\n{}",
            logs(&dir)
        );
        assert!(
            Instant::now() < deadline,
            "t1-rr never started\n{}",
            logs(&dir)
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    first.signal(libc::SIGKILL);
    first.wait_exit(Duration::from_secs(10));
    assert_eq!(iteration(&root, "t1"), 4, "t1 finished its budget");
    let t1_rows = rows(&root.join("t1/metrics.csv"));
    assert_eq!(t1_rows, 4);
    assert!(iteration(&root, "t1-rr") < 6, "killed inside t1-rr");

    // The same command again: t1 skipped, t1-rr resumed, t2 runs; killed again inside the
    // student's stage once it has aggregated a round.
    let mut second = start_pipeline(&dir, &config, "second.log");
    let deadline = Instant::now() + Duration::from_secs(300);
    while iteration(&root, "student") < 1 {
        assert!(
            second.is_running(),
            "the second run ended before the student trained\n{}",
            logs(&dir)
        );
        assert!(
            Instant::now() < deadline,
            "the student never trained\n{}",
            logs(&dir)
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    second.signal(libc::SIGKILL);
    second.wait_exit(Duration::from_secs(10));
    assert!(iteration(&root, "student") < 6, "killed inside the student");

    // Once more: the student resumes with its dataset, eval runs.
    let mut third = start_pipeline(&dir, &config, "third.log");
    let status = third.wait_exit(Duration::from_secs(300));
    assert!(
        status.is_some_and(|s| s.success()),
        "third run: {status:?}\n{}",
        logs(&dir)
    );
    let third_log = std::fs::read_to_string(dir.join("third.log")).unwrap_or_default();
    assert!(
        third_log.contains("stage t2: finished (3 of 3 iterations)")
            && third_log.contains("stage student: resuming to iteration 6"),
        "{third_log}"
    );
    let log = std::fs::read_to_string(dir.join("second.log")).unwrap_or_default() + &third_log;
    assert!(
        log.contains("stage t1: finished (4 of 4 iterations)"),
        "{log}"
    );
    assert!(
        log.contains("stage t1-rr: resuming to iteration 6"),
        "{log}"
    );
    assert_eq!(
        rows(&root.join("t1/metrics.csv")),
        t1_rows,
        "t1 was not trained again"
    );
    for (stage, budget) in [
        ("t1", 4),
        ("t1-rr", 6),
        ("t2", 3),
        ("student", 6),
        ("vla", 3),
    ] {
        assert_eq!(iteration(&root, stage), budget, "{stage}\n{log}");
        assert!(
            root.join(stage).join("policy.json").is_file(),
            "{stage} checkpoint"
        );
        assert!(
            root.join(stage).join("curves.png").is_file(),
            "{stage} curves"
        );
    }
    // Each stage was configured as its stage says.
    let config_of = |stage: &str| {
        std::fs::read_to_string(root.join(stage).join("config.toml")).unwrap_or_default()
    };
    let rr = config_of("t1-rr");
    assert!(rr.contains("release_retreat = 0.5"), "{rr}");
    assert!(rr.contains("t1/policy"), "t1-rr starts from t1: {rr}");
    let t2 = config_of("t2");
    assert!(t2.contains("role = \"teacher2\""), "{t2}");
    assert!(t2.contains("t1-rr/policy"), "t2's Teacher 1 is t1-rr: {t2}");
    let student = config_of("student");
    assert!(student.contains("role = \"student\""), "{student}");
    assert!(
        student.contains("t1-rr/policy") && student.contains("t2/policy"),
        "the student's labellers are t1-rr and t2: {student}"
    );
    // The VLA is distilled from the student, which labels every cycle; its dataset holds VLA
    // rows (proprioception, 16 word ids, a 16 x 16 image), not the state.
    let vla = config_of("vla");
    assert!(vla.contains("role = \"vla\""), "{vla}");
    assert_eq!(vla.matches("student/policy").count(), 2, "{vla}");
    let vla_index: serde_json::Value = serde_json::from_slice(
        &std::fs::read(root.join("vla/dagger/index.json")).expect("VLA dataset index"),
    )
    .expect("json");
    assert_eq!(
        vla_index.get("obs_dim").and_then(|v| v.as_u64()),
        Some(226 + 16 + 3 * 16 * 16),
        "{vla_index}"
    );
    // The student learned from the dagger-server's labels, across the kill: the aggregated
    // dataset grew every round (rounds made before the kill kept), most rounds' regression
    // lowered its loss on the dataset, and the last round ends at under half where the first began.
    let index: serde_json::Value = serde_json::from_slice(
        &std::fs::read(root.join("student/dagger/index.json")).expect("DAgger dataset index"),
    )
    .expect("json");
    let shards = index
        .get("shards")
        .and_then(|v| v.as_array())
        .map_or(0, Vec::len);
    assert!(shards >= 6, "{index}");
    let metrics = std::fs::read_to_string(root.join("student/metrics.csv")).unwrap_or_default();
    let header: Vec<&str> = metrics
        .lines()
        .next()
        .unwrap_or_default()
        .split(',')
        .collect();
    let column = |name: &str| -> Vec<f64> {
        let i = header.iter().position(|h| *h == name).expect(name);
        metrics
            .lines()
            .skip(1)
            .map(|l| {
                l.split(',')
                    .nth(i)
                    .and_then(|v| v.parse().ok())
                    .expect(name)
            })
            .collect()
    };
    let (dataset_rows, before, after) = (
        column("dagger_rows"),
        column("student_loss_before"),
        column("student_loss"),
    );
    assert!(dataset_rows.len() >= 6, "{metrics}");
    assert!(dataset_rows.windows(2).all(|w| w[1] > w[0]), "{metrics}");
    // A round's few sampled minibatches may overshoot a little (losses of ~1e-4 here); over
    // the rounds the loss falls.
    let lowered = before.iter().zip(&after).filter(|(b, a)| a < b).count();
    assert!(2 * lowered >= before.len(), "{metrics}");
    assert!(after[after.len() - 1] < 0.5 * before[0], "{metrics}");
    // Eval tables on both splits with the paper's keys: Teacher 1 on first pairs, and the
    // teachers through the switch on both pairs.
    for split in ["train", "unseen"] {
        for (row, keys) in [
            (
                "t1-first-pair",
                &["success_1", "dist_1", "success_all", "fall_rate"][..],
            ),
            (
                "teachers",
                &["success_1", "success_2", "dist_1", "dist_2", "success_all"][..],
            ),
            (
                "student",
                &["success_1", "success_2", "dist_1", "dist_2", "success_all"][..],
            ),
        ] {
            let path = root.join("eval").join(split).join(row).join("table.json");
            let table: serde_json::Value =
                serde_json::from_slice(&std::fs::read(&path).expect("eval table")).expect("json");
            for key in keys {
                assert!(
                    table.get(*key).is_some(),
                    "{split} {row}: no {key} in {table}"
                );
            }
            assert_eq!(table.get("tasks").and_then(|v| v.as_u64()), Some(2));
        }
        let md = std::fs::read_to_string(root.join("eval").join(split).join("teachers/table.md"))
            .unwrap_or_default();
        assert!(
            md.contains("t1-rr/policy then") && md.contains("t2/policy (T)"),
            "{md}"
        );
    }

    // The pipeline ends with every evaluation in one table per split.
    let summary = std::fs::read_to_string(root.join("eval/summary.md")).unwrap_or_default();
    for row in [
        "| t1-first-pair |",
        "| teachers |",
        "| student |",
        "| vla |",
        "| vla-no-language |",
    ] {
        assert_eq!(summary.matches(row).count(), 2, "{row}: {summary}");
    }
    // A fourth run has nothing left to do.
    let mut fourth = start_pipeline(&dir, &config, "fourth.log");
    let status = fourth.wait_exit(Duration::from_secs(60));
    assert!(
        status.is_some_and(|s| s.success()),
        "fourth run: {status:?}"
    );
    let log = std::fs::read_to_string(dir.join("fourth.log")).unwrap_or_default();
    assert!(
        !log.contains("training to") && !log.contains("resuming"),
        "{log}"
    );
    assert!(log.contains("every stage finished"), "{log}");
    let _ = std::fs::remove_dir_all(&dir);
}
