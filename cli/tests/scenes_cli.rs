//! `lhm scenes ...` end to end, as a user runs it.

use std::path::PathBuf;
use std::process::{Command, Output};

fn lhm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lhm"))
        .args(args)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .output()
        .expect("runs lhm")
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("lhm-cli-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp dir");
    dir.join(name)
}

#[test]
fn stats_json_reports_the_benchmark() {
    let out = lhm(&["scenes", "stats", "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let s: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json on stdout");
    assert_eq!(s["splits"]["train"]["tasks"], 350);
    assert_eq!(s["splits"]["unseen"]["tasks"], 66);
    assert_eq!(s["room_types"], 4);
    assert_eq!(s["object_types"], 79);
    assert_eq!(s["movable_object_types"], 25);
    assert!(s["obstacles_per_scene"]["min"].as_f64() >= Some(4.0));
    assert!(s["obstacles_per_scene"]["max"].as_f64() <= Some(10.0));
}

#[test]
fn validate_passes_every_split_and_rejects_unknown_ones() {
    let out = lhm(&["scenes", "validate"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("train: 350 tasks, 0 problems"), "{text}");
    for split in ["train", "unseen", "extension"] {
        assert!(lhm(&["scenes", "validate", "--split", split])
            .status
            .success());
    }
    let out = lhm(&["scenes", "validate", "--split", "holdout"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown split \"holdout\""));
}

#[test]
fn committed_files_match_generation() {
    let out = lhm(&["scenes", "generate", "--check"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn validate_names_the_broken_task_and_exits_non_zero() {
    let dir = tmp("broken-scenes");
    std::fs::create_dir_all(&dir).expect("dir");
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/data");
    for f in [
        "catalogue.toml",
        "train.toml",
        "unseen.toml",
        "extension.toml",
    ] {
        std::fs::copy(format!("{data}/{f}"), dir.join(f)).expect("copy");
    }
    // Lift the first unseen task's first object 1 m into the air.
    let path = dir.join("unseen.toml");
    let text = std::fs::read_to_string(&path).expect("read");
    let at = text.find("[[task.object]]").expect("an object");
    let pos = at + text[at..].find("pos = [").expect("pos");
    let end = pos + text[pos..].find(']').expect("]");
    let coords: Vec<f64> = text[pos + 7..end]
        .split(", ")
        .map(|x| x.parse().expect("number"))
        .collect();
    let lifted = format!("pos = [{}, {}, {}", coords[0], coords[1], coords[2] + 1.0);
    std::fs::write(&path, format!("{}{}{}", &text[..pos], lifted, &text[end..])).expect("write");
    let out = lhm(&[
        "scenes",
        "validate",
        "--scenes",
        dir.to_str().expect("utf8"),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("task unseen-001") && err.contains("object m0"),
        "{err}"
    );
}

#[test]
fn render_writes_a_png_and_unknown_tasks_fail() {
    let png = tmp("room.png");
    let out = lhm(&[
        "scenes",
        "render",
        "train-0001",
        "-o",
        png.to_str().expect("utf8"),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let bytes = std::fs::read(&png).expect("png written");
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert!(bytes.len() > 10_000, "a real picture, not an empty image");
    let out = lhm(&[
        "scenes",
        "render",
        "train-9999",
        "-o",
        png.to_str().expect("utf8"),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no task \"train-9999\""));
}
