//! The actor–learner service across real processes on loopback (DESIGN.md §3): the policy
//! version advances with two actors; a SIGKILLed actor costs nothing but its unfinished chunk;
//! a SIGKILLed learner resumes from its checkpoint and the running actors come back to it;
//! garbage on the trajectory key is rejected and counted; a SIGKILLed `lhm train` takes its actor
//! processes with it, its logs are plain text, and a second session appends to them; a learner
//! killed at any point of a checkpoint save resumes from a whole checkpoint.

use std::time::Duration;

use lhm_e2e::*;
use lhm_protos::{keys, prost::Message, Role, TrajectoryChunk, WireMessage};
use zenoh::Wait;

const LONG: Duration = Duration::from_secs(240);
const CHUNK_STEPS: u64 = 16;

#[test]
fn two_actors_advance_the_policy_version() {
    let dir = scratch_dir("two-actors");
    let config = write_config(&dir);
    let port = free_port();
    let mut learner = start_learner(&dir, &config, port, "learner.log");
    let _a = start_actor(&dir, port, "a0", 1);
    let _b = start_actor(&dir, port, "a1", 2);
    let s = wait_for(&dir, "3 iterations with both actors", LONG, |s| {
        u64_at(s, "/iteration") >= 3 && u64_at(s, "/actors_seen") >= 2
    });
    assert_eq!(u64_at(&s, "/intake/malformed"), 0);
    assert_eq!(u64_at(&s, "/intake/invalid"), 0);
    assert!(u64_at(&s, "/steps_used") >= 3 * 256, "{s:#}");
    // SIGTERM: the learner checkpoints and exits cleanly.
    learner.signal(libc::SIGTERM);
    let exit = learner
        .wait_exit(Duration::from_secs(60))
        .expect("learner exits");
    assert!(exit.success(), "learner exit {exit:?}");
    let meta: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.join("runs/e2e/checkpoint.json")).expect("checkpoint written"),
    )
    .unwrap();
    let final_iteration = u64_at(&status(&dir), "/iteration");
    assert_eq!(
        u64_at(&meta, "/payload/counters/iteration"),
        final_iteration,
        "the checkpoint on SIGTERM holds the last iteration"
    );
    assert!(dir.join("runs/e2e/run.mcap").is_file());
    // The checkpoint evaluates with the run's own config.toml (no --config), and --gifs films
    // the first episode.
    let out_dir = dir.join("eval");
    let eval = std::process::Command::new(lhm())
        .args([
            "eval",
            "--policy",
            &dir.join("runs/e2e/policy").display().to_string(),
        ])
        .args([
            "--split",
            "unseen",
            "--first-pair",
            "--limit",
            "1",
            "--seeds",
            "1",
        ])
        .args([
            "--json",
            "--gifs",
            "1",
            "-o",
            &out_dir.display().to_string(),
        ])
        .output()
        .expect("running lhm eval");
    let stderr = String::from_utf8_lossy(&eval.stderr);
    assert!(eval.status.success(), "{stderr}");
    assert!(stderr.contains("config.toml"), "{stderr}");
    let table: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
    assert_eq!(table["episodes"], 1, "{table}");
    let gif = std::fs::read(out_dir.join("unseen-001.p1-s0.gif")).expect("the GIF");
    assert!(gif.starts_with(b"GIF89a"), "not a GIF");
}

#[test]
fn a_killed_actor_costs_only_its_unfinished_chunk() {
    let dir = scratch_dir("kill-actor");
    let config = write_config(&dir);
    let port = free_port();
    let _learner = start_learner(&dir, &config, port, "learner.log");
    let mut victim = start_actor(&dir, port, "victim", 3);
    let _survivor = start_actor(&dir, port, "survivor", 4);
    let before = wait_for(&dir, "2 iterations", LONG, |s| {
        u64_at(s, "/iteration") >= 2 && alive(s).len() == 2
    });
    // Mid-chunk with near certainty: a chunk is 16 steps of 2 environments (~50 ms of work).
    std::thread::sleep(Duration::from_millis(137));
    victim.signal(libc::SIGKILL);
    victim.wait_exit(Duration::from_secs(10));
    let it0 = u64_at(&before, "/iteration");
    let after = wait_for(&dir, "training to go on with the survivor", LONG, |s| {
        u64_at(s, "/iteration") >= it0 + 3 && alive(s) == ["survivor"]
    });
    // Count check: every accepted chunk was whole, nothing was rejected, and updates used only
    // accepted steps.
    let accepted = u64_at(&after, "/intake/accepted");
    assert_eq!(
        u64_at(&after, "/intake/accepted_steps"),
        accepted * CHUNK_STEPS
    );
    assert_eq!(u64_at(&after, "/intake/malformed"), 0, "{after:#}");
    assert_eq!(u64_at(&after, "/intake/invalid"), 0, "{after:#}");
    assert_eq!(u64_at(&after, "/intake/wrong_version"), 0, "{after:#}");
    assert!(u64_at(&after, "/steps_used") <= u64_at(&after, "/intake/accepted_steps"));
}

#[test]
fn a_restarted_learner_resumes_and_running_actors_reconnect() {
    let dir = scratch_dir("restart-learner");
    let config = write_config(&dir);
    let port = free_port();
    let mut learner = start_learner(&dir, &config, port, "learner-1.log");
    let mut actor = start_actor(&dir, port, "steady", 5);
    wait_for(&dir, "a checkpoint (iteration 3)", LONG, |s| {
        u64_at(s, "/iteration") >= 3
    });
    learner.signal(libc::SIGKILL);
    learner.wait_exit(Duration::from_secs(10));
    let meta: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.join("runs/e2e/checkpoint.json")).expect("a checkpoint exists"),
    )
    .unwrap();
    let checkpointed = u64_at(&meta, "/payload/counters/iteration");
    assert!(
        checkpointed >= 2,
        "checkpoint every 2 iterations: {checkpointed}"
    );
    // The killed learner's recording has no summary and no end magic; `lhm recover` makes a
    // file the strict readers accept (the Python `mcap` reader too, where installed).
    let recovered = dir.join("recovered.mcap");
    let out = std::process::Command::new(lhm())
        .args([
            "recover",
            &dir.join("runs/e2e/run.mcap").display().to_string(),
        ])
        .args(["-o", &recovered.display().to_string()])
        .output()
        .expect("running lhm recover");
    let said = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{said}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let messages: u64 = said
        .split(": ")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("lhm recover said {said:?}"));
    assert!(messages > 0, "{said}");
    if let Some(py) = python_with("mcap") {
        let script = "import sys\nfrom mcap.reader import make_reader\n\
                      with open(sys.argv[1], 'rb') as f:\n    \
                      print(sum(1 for _ in make_reader(f).iter_messages()))\n";
        let read = std::process::Command::new(py)
            .args(["-c", script, &recovered.display().to_string()])
            .output()
            .expect("running python");
        assert!(
            read.status.success(),
            "{}",
            String::from_utf8_lossy(&read.stderr)
        );
        let n: u64 = String::from_utf8_lossy(&read.stdout)
            .trim()
            .parse()
            .unwrap();
        assert_eq!(n, messages, "the Python reader's count");
    } else {
        eprintln!(
            "SKIP the Python mcap reader: no Python with `mcap` (scripts/install-python-examples)"
        );
    }
    // The orphaned actor says its learner is gone and stops simulating (so it sends nothing)
    // within a bounded time: its CPU use over 3 s stays near nothing.
    let actor_log = dir.join("steady.log");
    wait_for_log(&actor_log, "gone for", Duration::from_secs(60));
    let before = cpu_ticks(actor.pid()).expect("the actor runs");
    std::thread::sleep(Duration::from_secs(3));
    let used = cpu_ticks(actor.pid()).expect("the actor runs") - before;
    assert!(
        used * 10 < 3 * ticks_per_second(),
        "a paused actor used {used} ticks of CPU in 3 s"
    );

    let _learner = start_learner(&dir, &config, port, "learner-2.log");
    let resumed = wait_for(&dir, "the restarted learner", LONG, |s| {
        s.pointer("/resumed_from_iteration")
            .is_some_and(|v| !v.is_null())
    });
    assert_eq!(u64_at(&resumed, "/resumed_from_iteration"), checkpointed);
    wait_for(
        &dir,
        "training to continue with the same actor",
        LONG,
        |s| u64_at(s, "/iteration") >= checkpointed + 2 && alive(s) == ["steady"],
    );
    assert!(actor.is_running(), "the actor was never restarted");
    wait_for_log(&actor_log, "resumes", Duration::from_secs(10));
}

#[test]
fn a_waiting_actor_says_so_once_not_three_lines_every_half_second() {
    let dir = scratch_dir("waiting-actor");
    let port = free_port();
    let log = dir.join("waiting.log");
    let file = std::fs::File::create(&log).expect("log file");
    // The binaries' own default log filter (no RUST_LOG), as a user starting an actor sees it.
    let child = std::process::Command::new(lhm())
        .args([
            "actor",
            "--connect",
            &format!("tcp/127.0.0.1:{port}"),
            "--run-id",
            "e2e",
            "--envs",
            "1",
        ])
        .env_remove("RUST_LOG")
        .stdin(std::process::Stdio::null())
        .stdout(file.try_clone().expect("log file"))
        .stderr(file)
        .spawn()
        .expect("starting an actor");
    let mut actor = Proc {
        child,
        name: "waiting".into(),
    };
    std::thread::sleep(Duration::from_secs(4));
    actor.signal(libc::SIGTERM);
    actor.wait_exit(Duration::from_secs(10));
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    let lines = text.lines().count();
    // Eight connection attempts in 4 s: before, 3 lines each.
    assert!(lines <= 3, "{lines} lines in 4 s of waiting:\n{text}");
    assert!(text.contains("waiting for"), "{text}");
    assert!(!text.contains("orchestrator"), "{text}");
}

fn chunk(version: u64) -> TrajectoryChunk {
    let n = 2u32;
    TrajectoryChunk {
        run_id: "e2e".into(),
        actor_id: "intruder".into(),
        role: Role::Teacher1 as i32,
        policy_version: version,
        num_steps: n,
        obs_dim: 3,
        act_dim: 1,
        observations: vec![0.0; 6],
        actions: vec![0.0; 2],
        log_probs: vec![0.0; 2],
        values: vec![0.0; 2],
        rewards: vec![0.0; 2],
        dones: vec![false; 2],
        truncated: vec![false; 2],
        truncation_values: vec![0.0; 2],
        ..TrajectoryChunk::versioned()
    }
}

#[test]
fn malformed_and_wrong_version_messages_are_rejected_and_counted() {
    let dir = scratch_dir("garbage");
    let config = write_config(&dir);
    let port = free_port();
    let mut learner = start_learner(&dir, &config, port, "learner.log");
    wait_for(&dir, "the learner", LONG, |s| !s.is_null());

    let mut zconfig = zenoh::Config::default();
    for (k, v) in [
        ("mode", "\"client\"".to_string()),
        ("scouting/multicast/enabled", "false".into()),
        ("connect/endpoints", format!("[\"tcp/127.0.0.1:{port}\"]")),
    ] {
        zconfig.insert_json5(k, &v).unwrap();
    }
    let session = zenoh::open(zconfig).wait().expect("connect to the learner");
    let key = keys::trajectory("e2e", Role::Teacher1, "intruder");
    let put = |bytes: Vec<u8>| {
        session
            .put(&key, bytes)
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .wait()
            .unwrap()
    };
    // Not protobuf at all; truncated protobuf.
    put(vec![0xff; 64]);
    put(chunk(0).encode_checked().unwrap()[..9].to_vec());
    // Another schema version.
    let mut future = chunk(0);
    future.schema_version = 99;
    put(future.encode_to_vec());
    // Shapes that do not add up; NaN rewards.
    let mut ragged = chunk(0);
    ragged.rewards.pop();
    put(ragged.encode_to_vec());
    let mut nan = chunk(0);
    nan.rewards[0] = f32::NAN;
    put(nan.encode_to_vec());
    // Well-formed, but not this run's network.
    put(chunk(0).encode_to_vec());

    let s = wait_for(
        &dir,
        "every message counted",
        Duration::from_secs(60),
        |s| {
            u64_at(s, "/intake/malformed")
                + u64_at(s, "/intake/wrong_version")
                + u64_at(s, "/intake/invalid")
                + u64_at(s, "/intake/mismatched")
                >= 6
        },
    );
    assert_eq!(u64_at(&s, "/intake/wrong_version"), 1, "{s:#}");
    assert_eq!(u64_at(&s, "/intake/invalid"), 2, "{s:#}");
    assert_eq!(u64_at(&s, "/intake/mismatched"), 1, "{s:#}");
    assert_eq!(u64_at(&s, "/intake/malformed"), 2, "{s:#}");
    assert_eq!(u64_at(&s, "/intake/accepted"), 0);
    assert!(learner.is_running(), "the learner survived");
}

#[test]
fn a_killed_lhm_train_takes_its_actor_processes_with_it() {
    let dir = scratch_dir("kill-train");
    let config = write_config(&dir);
    let mut train = start_train(&dir, &config, 2);
    wait_for(&dir, "an iteration with both actors", LONG, |s| {
        u64_at(s, "/iteration") >= 1 && alive(s).len() >= 2
    });
    let actors = children_of(train.pid());
    assert_eq!(actors.len(), 2, "actor processes of lhm train: {actors:?}");
    // `--scenes` reached the actors (which then trained from those files) and the run's config.
    let scenes = dir.join("scenes").display().to_string();
    for &pid in &actors {
        let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
        let cmdline = String::from_utf8_lossy(&cmdline).replace('\0', " ");
        assert!(cmdline.contains(&format!("--scenes {scenes}")), "{cmdline}");
    }
    let run_config = std::fs::read_to_string(dir.join("runs/e2e/config.toml")).unwrap_or_default();
    assert!(run_config.contains(&scenes), "{run_config}");
    // Logs written to files are plain text: a progress line per iteration, no colour codes.
    let read = |p: &std::path::Path| std::fs::read_to_string(p).unwrap_or_default();
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    while !read(&dir.join("train.log")).contains("iteration 1 |") {
        assert!(
            std::time::Instant::now() < deadline,
            "no plain progress line in train.log: {}",
            read(&dir.join("train.log"))
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let run_dir = dir.join("runs").join("e2e");
    for log in [dir.join("train.log"), run_dir.join("actor-0.log")] {
        let text = read(&log);
        assert!(!text.is_empty(), "{} is empty", log.display());
        assert!(
            !text.contains('\x1b'),
            "colour codes in {}: {text}",
            log.display()
        );
    }
    train.signal(libc::SIGKILL);
    train
        .wait_exit(Duration::from_secs(10))
        .expect("lhm train dies");
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    while actors.iter().any(|&pid| !exited(pid)) {
        assert!(
            std::time::Instant::now() < deadline,
            "actors {actors:?} outlived their lhm train: {:?}",
            actors.iter().map(|&p| proc_state(p)).collect::<Vec<_>>()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    // Started again on the same run, the actors append to their logs instead of truncating them.
    let started = |text: &str| text.matches("actor local-0 waiting for").count();
    assert_eq!(started(&read(&run_dir.join("actor-0.log"))), 1);
    let mut again = start_train(&dir, &config, 2);
    let deadline = std::time::Instant::now() + LONG;
    while started(&read(&run_dir.join("actor-0.log"))) < 2 {
        assert!(
            std::time::Instant::now() < deadline,
            "the second session's actor never logged: {}",
            read(&run_dir.join("actor-0.log"))
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    again.signal(libc::SIGTERM);
    again.wait_exit(Duration::from_secs(60));
}

/// Fault injection, not timing luck: the learner aborts at each point of its second checkpoint
/// save in turn (`LHM_CHECKPOINT_FAULT`), and a learner started on the same run must resume
/// from the last committed checkpoint (iteration 2 until the manifest's rename, 4 after it) and
/// leave no temporary or orphaned tensor files behind once it has saved again.
#[test]
fn a_learner_killed_at_any_point_of_a_save_resumes_from_a_whole_checkpoint() {
    for (point, committed) in [
        ("weights-written", 2),
        ("weights-renamed", 2),
        ("meta-written", 2),
        ("meta-renamed", 4),
    ] {
        let dir = scratch_dir(&format!("fault-{point}"));
        let config = write_config(&dir);
        let port = free_port();
        // Saves 1 and 2 are iteration 2's checkpoint and policy; save 3 is iteration 4's
        // checkpoint.
        let fault = format!("{point}:3");
        let mut learner = start_learner_with_env(
            &dir,
            &config,
            port,
            "learner.log",
            &[("LHM_CHECKPOINT_FAULT", &fault)],
        );
        let _actor = start_actor(&dir, port, "a0", 1);
        let exit = learner
            .wait_exit(LONG)
            .unwrap_or_else(|| panic!("{point}: the learner never reached its fault"));
        assert!(!exit.success(), "{point}: {exit:?}");
        let log = std::fs::read_to_string(dir.join("learner.log")).unwrap_or_default();
        assert!(
            log.contains(&format!("aborting at {point}")),
            "{point}: {log}"
        );

        let mut again = start_learner(&dir, &config, port, "learner-2.log");
        let resumed = wait_for(&dir, "the restarted learner", LONG, |s| {
            s.pointer("/resumed_from_iteration")
                .and_then(|v| v.as_u64())
                .is_some()
        });
        assert_eq!(
            u64_at(&resumed, "/resumed_from_iteration"),
            committed,
            "{point}"
        );
        wait_for(&dir, "the next checkpoint", LONG, |s| {
            u64_at(s, "/iteration") >= committed + 2
        });
        again.signal(libc::SIGTERM);
        again.wait_exit(Duration::from_secs(60));
        let run = dir.join("runs/e2e");
        let names: Vec<String> = std::fs::read_dir(&run)
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert!(
            !names.iter().any(|n| n.contains(".tmp-")),
            "{point}: temporary files left: {names:?}"
        );
        for stem in ["checkpoint", "policy"] {
            let tensors = names
                .iter()
                .filter(|n| n.starts_with(&format!("{stem}.")) && n.ends_with(".safetensors"))
                .count();
            assert!(
                (1..=2).contains(&tensors),
                "{point}: {tensors} tensor files of {stem}: {names:?}"
            );
        }
    }
}
