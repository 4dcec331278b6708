//! Every method of `configs/methods/` trains through `lhm pipeline` at a tiny budget (each stage
//! scaled down to an iteration or two, small networks from the smoke VLA overlay), and `lhm tables`
//! writes the paper's Tables 1-4 (Table 3: each method's VLA, with and without language) with a row
//! for each of our methods, every column, and the paper's figures beside them; a second
//! `lhm tables` reuses every evaluation.

use std::path::Path;
use std::process::Command;

use lhm_e2e::{lhm, scratch_dir};

const METHODS: &[&str] = &[
    "lhm",
    "no-rr",
    "no-amp",
    "e2e-rl",
    "curriculum-rl",
    "hierarchical-rl",
];

fn run(args: &[&str]) -> String {
    let out = Command::new(lhm())
        .args(args)
        .output()
        .expect("running lhm");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "lhm {args:?}:\n{text}");
    text
}

#[test]
fn every_method_trains_and_the_tables_have_every_row_and_column() {
    let dir = scratch_dir("tables");
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let runs = dir.join("runs");
    let runs_arg = runs.display().to_string();
    // The smoke stage's sizes, and a tiny VLA encoder (16 x 16 images) for the vla stages; the
    // other stages drop the VLA section (Stage::apply).
    let overlay = repo.join("configs/smoke-vla.toml").display().to_string();
    for method in METHODS {
        let config = repo.join(format!("configs/methods/{method}.toml"));
        let log = run(&[
            "pipeline",
            "--config",
            &config.display().to_string(),
            "--runs-dir",
            &runs_arg,
            "--overlay",
            &overlay,
            "--budget-scale",
            "0.002",
            "--actors",
            "1",
        ]);
        assert!(log.contains("every stage finished"), "{method}: {log}");
        assert!(runs.join(method).join("pipeline.json").is_file());
    }
    let tables = dir.join("tables");
    let tables_arg = tables.display().to_string();
    let args = [
        "tables",
        "--runs",
        &runs_arg,
        "--seeds",
        "1",
        "--limit",
        "1",
        "-o",
        &tables_arg,
    ];
    run(&args);
    let rows = [
        "LHM-T",
        "LHM-S",
        "LHM w/o RR-S",
        "LHM w/o AMP-S",
        "End-to-End RL",
        "Curriculum RL",
        "Hierarchical RL",
    ];
    // Table 3: every method's VLA, with and without its instructions.
    let vla_rows: Vec<String> = [
        "LHM-S",
        "LHM w/o RR",
        "LHM w/o AMP",
        "End-to-End RL",
        "Curriculum RL",
        "Hierarchical RL",
    ]
    .iter()
    .flat_map(|m| [format!("{m} (VLA)"), format!("{m} (VLA, no language)")])
    .collect();
    for (file, columns) in [
        (
            "table1-train",
            &[
                "Success 1 (%)",
                "Success 2 (%)",
                "Success All (%)",
                "Dist 1 (m)",
                "Dist 2 (m)",
            ][..],
        ),
        (
            "table2-unseen",
            &[
                "Success 1 (%)",
                "Success 2 (%)",
                "Success All (%)",
                "Dist 1 (m)",
                "Dist 2 (m)",
            ][..],
        ),
        (
            "table3-vla",
            &[
                "Success 1 (%)",
                "Success 2 (%)",
                "Success All (%)",
                "Dist 1 (m)",
                "Dist 2 (m)",
            ][..],
        ),
        (
            "table4-ext5",
            &[
                "Success 1 (%)",
                "Success 3 (%)",
                "Success 5 (%)",
                "Success All (%)",
            ][..],
        ),
    ] {
        let md = std::fs::read_to_string(tables.join(format!("{file}.md"))).expect(file);
        let header = md
            .lines()
            .find(|l| l.starts_with("| Method"))
            .unwrap_or_default();
        for column in columns {
            assert!(header.contains(column), "{file}: no {column}: {header}");
        }
        let (expected, ours): (Vec<&str>, usize) = if file == "table3-vla" {
            (vla_rows.iter().map(String::as_str).collect(), 12)
        } else {
            (rows.to_vec(), 9)
        };
        for row in expected {
            let line = md
                .lines()
                .find(|l| l.starts_with(&format!("| {row} |")))
                .unwrap_or_else(|| panic!("{file}: no row {row}\n{md}"));
            // Measured cells (mean ± std), not placeholders.
            assert!(line.matches(" ± ").count() >= columns.len(), "{line}");
        }
        // The paper's figures beside ours, and its rows we do not run.
        assert!(md.contains("TokenHSI (not run here)"), "{md}");
        assert!(!md.contains("Hierarchical RL (not run here)"), "{md}");
        if file == "table1-train" {
            assert!(md.contains("88.8 / 72.9 / 72.4 / 0.25 / 0.48"), "{md}");
        }
        if file == "table4-ext5" {
            assert!(
                md.contains("90.8 / 76.1 / 61.0 / 38.5 / 20.9 / 18.1"),
                "{md}"
            );
        }
        let csv = std::fs::read_to_string(tables.join(format!("{file}.csv"))).expect(file);
        assert_eq!(
            csv.lines().count(),
            1 + ours,
            "{file}: {ours} rows of ours\n{csv}"
        );
        if file == "table3-vla" {
            assert!(md.contains("76.5 / 65.4 / 63.7 / 0.42 / 0.56"), "{md}");
        }
    }
    // Every evaluation is reused the second time.
    let again = run(&args);
    assert!(!again.contains("evaluating"), "{again}");
    assert_eq!(again.matches("reusing").count(), 9 * 3 + 12, "{again}");
    let _ = std::fs::remove_dir_all(&dir);
}
