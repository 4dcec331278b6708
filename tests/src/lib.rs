//! Helpers for the end-to-end tests: start `lhm` processes on loopback, read the learner's
//! `status.json`, wait for conditions, and never leave a process behind.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The `lhm` binary next to the test executable (`cargo test --workspace` builds it).
pub fn lhm() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test> → target/<profile>/lhm
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("target directory");
    let bin = dir.join("lhm");
    assert!(
        bin.is_file(),
        "{} not found: run the tests with `cargo test --workspace` so the lhm binary is built",
        bin.display()
    );
    bin
}

pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free loopback port")
        .port()
}

/// A fresh directory for one test's runs.
pub fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("lhm-e2e-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// A small, fast run: 64-64 networks, 256-step batches of 16-step chunks, a checkpoint every 2
/// iterations.
pub fn write_config(dir: &Path) -> PathBuf {
    let path = dir.join("train.toml");
    std::fs::write(
        &path,
        r#"run_id = "e2e"
batch_steps = 256
chunk_steps = 16
checkpoint_every = 2
record_every_episodes = 4

[network.policy.mlp]
hidden = [64, 64]

[network.value]
hidden = [64, 64]

[ppo]
epochs = 2
minibatch_size = 128
"#,
    )
    .expect("writing the config");
    path
}

/// A child process killed (SIGKILL) when dropped, so a failing test leaves nothing running.
pub struct Proc {
    pub child: Child,
    pub name: String,
}

impl Proc {
    pub fn pid(&self) -> i32 {
        self.child.id() as i32
    }

    pub fn signal(&self, sig: i32) {
        // SAFETY: kill(2) on our own child.
        unsafe {
            libc::kill(self.pid(), sig);
        }
    }

    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// Waits for the process to exit; its exit status, or `None` on timeout.
    pub fn wait_exit(&mut self, timeout: Duration) -> Option<std::process::ExitStatus> {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if let Ok(Some(status)) = self.child.try_wait() {
                return Some(status);
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        None
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn spawn(name: &str, args: &[String], log: &Path) -> Proc {
    spawn_with_env(name, args, log, &[])
}

fn spawn_with_env(name: &str, args: &[String], log: &Path, env: &[(&str, &str)]) -> Proc {
    let file = std::fs::File::create(log).expect("log file");
    let err = file.try_clone().expect("log file");
    let child = Command::new(lhm())
        .args(args)
        .env("RUST_LOG", "info")
        .envs(env.iter().copied())
        .stdin(Stdio::null())
        .stdout(file)
        .stderr(err)
        .spawn()
        .unwrap_or_else(|e| panic!("starting {name}: {e}"));
    Proc {
        child,
        name: name.to_owned(),
    }
}

pub fn start_learner(dir: &Path, config: &Path, port: u16, log_name: &str) -> Proc {
    start_learner_with_env(dir, config, port, log_name, &[])
}

/// [`start_learner`] with extra environment variables (e.g. `LHM_CHECKPOINT_FAULT`).
pub fn start_learner_with_env(
    dir: &Path,
    config: &Path,
    port: u16,
    log_name: &str,
    env: &[(&str, &str)],
) -> Proc {
    let args: Vec<String> = [
        "learner",
        "--listen",
        &format!("tcp/127.0.0.1:{port}"),
        "--config",
        &config.display().to_string(),
        "--runs-dir",
        &dir.join("runs").display().to_string(),
        "--no-amp",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    spawn_with_env("learner", &args, &dir.join(log_name), env)
}

pub fn start_actor(dir: &Path, port: u16, id: &str, seed: u64) -> Proc {
    let args: Vec<String> = [
        "actor",
        "--connect",
        &format!("tcp/127.0.0.1:{port}"),
        "--run-id",
        "e2e",
        "--envs",
        "2",
        "--seed",
        &seed.to_string(),
        "--actor-id",
        id,
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    spawn(id, &args, &dir.join(format!("{id}.log")))
}

/// A copy of the repository's scene files in `dir/scenes` (for `--scenes`).
pub fn copy_scenes(dir: &Path) -> PathBuf {
    let from = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/data");
    let to = dir.join("scenes");
    std::fs::create_dir_all(&to).expect("scenes dir");
    for entry in std::fs::read_dir(&from).expect("scenes/data") {
        let entry = entry.expect("scenes/data entry");
        std::fs::copy(entry.path(), to.join(entry.file_name())).expect("copying a scene file");
    }
    to
}

/// `lhm train` on loopback with `--no-amp`, `actors` actor processes of 2 environments each,
/// reading the tasks from a copy of the scene files (`--scenes`, passed on to its actors).
pub fn start_train(dir: &Path, config: &Path, actors: usize) -> Proc {
    let scenes = copy_scenes(dir);
    let args: Vec<String> = [
        "train",
        "--config",
        &config.display().to_string(),
        "--runs-dir",
        &dir.join("runs").display().to_string(),
        "--no-amp",
        "--actors",
        &actors.to_string(),
        "--envs",
        "2",
        "--scenes",
        &scenes.display().to_string(),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    spawn("train", &args, &dir.join("train.log"))
}

/// Pids of the live (not zombie) processes whose parent is `parent`, read from /proc.
pub fn children_of(parent: i32) -> Vec<i32> {
    let mut out = Vec::new();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return out;
    };
    for e in entries.flatten() {
        let Some(pid) = e.file_name().to_str().and_then(|n| n.parse::<i32>().ok()) else {
            continue;
        };
        if let Some((state, ppid)) = proc_state(pid) {
            if ppid == parent && state != 'Z' {
                out.push(pid);
            }
        }
    }
    out
}

/// (state letter, parent pid) of a process from /proc/PID/stat; `None` once it is gone.
pub fn proc_state(pid: i32) -> Option<(char, i32)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // "pid (comm) S ppid ...": comm may hold spaces, so parse after its closing parenthesis.
    let rest = &stat[stat.rfind(')')? + 2..];
    let mut fields = rest.split_whitespace();
    let state = fields.next()?.chars().next()?;
    let ppid = fields.next()?.parse().ok()?;
    Some((state, ppid))
}

/// CPU time (user + system, clock ticks) a process has used, from /proc/PID/stat.
pub fn cpu_ticks(pid: i32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let rest = &stat[stat.rfind(')')? + 2..];
    // After the comm: state(0) ppid(1) ... utime(11) stime(12).
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: u64 = fields.get(11)?.parse().ok()?;
    let stime: u64 = fields.get(12)?.parse().ok()?;
    Some(utime + stime)
}

/// Clock ticks per second (the unit of [`cpu_ticks`]).
pub fn ticks_per_second() -> u64 {
    // SAFETY: sysconf has no preconditions.
    let t = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if t > 0 {
        t as u64
    } else {
        100
    }
}

/// Polls a log file until it contains `needle`; panics with the log on timeout.
pub fn wait_for_log(path: &Path, needle: &str, timeout: Duration) -> String {
    let deadline = Instant::now() + timeout;
    loop {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        if text.contains(needle) {
            return text;
        }
        if Instant::now() >= deadline {
            panic!(
                "{} never said {needle:?} within {timeout:?}:\n{text}",
                path.display()
            );
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// A Python that can import `module` (`$LHM_PYTHON`, `~/.cache/lhm/python`, or `python3`).
pub fn python_with(module: &str) -> Option<String> {
    let candidates = [
        std::env::var("LHM_PYTHON").ok(),
        std::env::var("HOME")
            .ok()
            .map(|h| format!("{h}/.cache/lhm/python/bin/python")),
        Some("python3".to_owned()),
    ];
    candidates.into_iter().flatten().find(|p| {
        Command::new(p)
            .args(["-c", &format!("import {module}")])
            .output()
            .is_ok_and(|o| o.status.success())
    })
}

/// Gone, or a zombie waiting for whoever reaps orphans.
pub fn exited(pid: i32) -> bool {
    proc_state(pid).is_none_or(|(state, _)| state == 'Z')
}

/// The learner's `status.json` (`Null` until it exists and parses).
pub fn status(dir: &Path) -> serde_json::Value {
    std::fs::read(dir.join("runs/e2e/status.json"))
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .unwrap_or(serde_json::Value::Null)
}

pub fn u64_at(v: &serde_json::Value, pointer: &str) -> u64 {
    v.pointer(pointer).and_then(|x| x.as_u64()).unwrap_or(0)
}

pub fn alive(v: &serde_json::Value) -> Vec<String> {
    v.pointer("/actors_alive")
        .and_then(|a| a.as_array())
        .map(|a| {
            a.iter()
                .filter_map(|x| x.as_str().map(str::to_owned))
                .collect()
        })
        .unwrap_or_default()
}

/// Polls `status.json` until `cond` holds; panics with the last status and the logs on timeout.
pub fn wait_for(
    dir: &Path,
    what: &str,
    timeout: Duration,
    mut cond: impl FnMut(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let deadline = Instant::now() + timeout;
    loop {
        let s = status(dir);
        if cond(&s) {
            return s;
        }
        if Instant::now() > deadline {
            let mut logs = String::new();
            if let Ok(entries) = std::fs::read_dir(dir) {
                for e in entries.flatten() {
                    if e.path().extension().is_some_and(|x| x == "log") {
                        let text = std::fs::read_to_string(e.path()).unwrap_or_default();
                        let tail: Vec<&str> = text.lines().rev().take(15).collect();
                        logs.push_str(&format!(
                            "\n--- {} ---\n{}",
                            e.path().display(),
                            tail.into_iter().rev().collect::<Vec<_>>().join("\n")
                        ));
                    }
                }
            }
            panic!("timed out waiting for {what}; last status: {s:#}{logs}");
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// `lhm pipeline --config CONFIG --runs-dir DIR/runs` with 2 actor processes, logging to
/// `DIR/<log_name>`.
pub fn start_pipeline(dir: &Path, config: &Path, log_name: &str) -> Proc {
    let args: Vec<String> = [
        "pipeline",
        "--config",
        &config.display().to_string(),
        "--runs-dir",
        &dir.join("runs").display().to_string(),
        "--actors",
        "2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    spawn("pipeline", &args, &dir.join(log_name))
}
