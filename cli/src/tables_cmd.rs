//! `lhm tables`: the paper's Tables 1 (350 training tasks), 2 (66 unseen tasks), 3 (each method's
//! VLA, distilled from its deployable policy, on the unseen tasks; with its language ablation) and
//! 4 (five-object sequences) from the method pipelines in one runs directory (`lhm pipeline --config
//! configs/methods/<method>.toml --runs-dir DIR`), each policy run by `lhm eval` on every task
//! and seed (or reused from an earlier identical evaluation), mean ± std over seeds, in Markdown
//! and CSV, with the paper's own figures beside ours.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;

use crate::pipeline_cmd::{EvalRow, Manifest, Policies, MANIFEST_FILE};

#[derive(Args)]
pub struct TablesArgs {
    /// The runs directory: one pipeline per method, each with its `pipeline.json`.
    #[arg(long)]
    runs: PathBuf,
    /// Seeds per task (seed 0 is each task as specified; later seeds turn the start heading).
    #[arg(long, default_value_t = 3)]
    seeds: u64,
    /// Only the first N tasks of each split (a quick look; the tables say so).
    #[arg(long)]
    limit: Option<usize>,
    /// Where the tables go (`table1-train.md`, `.csv`, and the same for table2-unseen, table3-vla,
    /// table4-ext5).
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    scenes: crate::scenes_cmd::Source,
}

/// One of the paper's tables: the split it is measured on, its cycles, and the paper's rows
/// (method, Success 1..K and Success All in %, then Dist 1..K in m where the paper gives them).
struct TableSpec {
    file: &'static str,
    title: &'static str,
    split: &'static str,
    cycles: usize,
    with_dist: bool,
    /// The methods' VLA rows (a `vla` stage's policy, with and without language) instead of
    /// their state-based ones.
    vla: bool,
    paper: &'static [(&'static str, &'static [f64])],
}

/// The paper's figures (../shared/paper, Tables 1-4), shown beside ours for reference.
const TABLES: &[TableSpec] = &[
    TableSpec {
        file: "table1-train",
        title: "Table 1: the 350 training tasks",
        split: "train",
        cycles: 2,
        with_dist: true,
        vla: false,
        paper: &[
            ("End-to-End RL", &[2.3, 0.0, 0.0, 2.05, 1.97]),
            ("Curriculum RL", &[88.3, 48.5, 47.2, 0.26, 1.01]),
            ("Hierarchical RL", &[37.5, 25.0, 20.8, 0.78, 1.13]),
            ("HumanVLA", &[42.3, 36.7, 29.9, 0.65, 0.97]),
            ("InterMimic", &[20.6, 9.8, 7.5, 1.32, 1.82]),
            ("TokenHSI", &[40.5, 31.5, 27.6, 0.58, 1.07]),
            ("LHM w/o RR", &[81.1, 60.5, 56.2, 0.52, 0.59]),
            ("LHM w/o AMP", &[32.9, 14.8, 10.4, 1.09, 1.64]),
            ("LHM-S", &[87.4, 72.6, 71.1, 0.28, 0.50]),
            ("LHM-T", &[88.8, 72.9, 72.4, 0.25, 0.48]),
        ],
    },
    TableSpec {
        file: "table2-unseen",
        title: "Table 2: the 66 unseen tasks",
        split: "unseen",
        cycles: 2,
        with_dist: true,
        vla: false,
        paper: &[
            ("End-to-End RL", &[1.4, 0.0, 0.0, 2.37, 2.28]),
            ("Curriculum RL", &[75.5, 40.4, 39.5, 0.36, 1.11]),
            ("Hierarchical RL", &[31.6, 21.8, 17.3, 0.97, 1.39]),
            ("HumanVLA", &[36.3, 31.3, 25.1, 0.72, 1.16]),
            ("InterMimic", &[17.2, 8.2, 5.9, 1.47, 2.03]),
            ("TokenHSI", &[33.9, 26.1, 22.9, 0.67, 1.21]),
            ("LHM w/o RR", &[69.2, 52.4, 48.6, 0.62, 0.60]),
            ("LHM w/o AMP", &[27.2, 12.9, 9.0, 1.27, 1.86]),
            ("LHM-S", &[80.8, 64.9, 61.6, 0.37, 0.54]),
            ("LHM-T", &[81.6, 65.1, 63.2, 0.35, 0.50]),
        ],
    },
    TableSpec {
        file: "table3-vla",
        title:
            "Table 3: each method's VLA (egocentric RGB, proprioception, instruction) on the 66 \
                unseen tasks",
        split: "unseen",
        cycles: 2,
        with_dist: true,
        vla: true,
        paper: &[
            ("End-to-End RL", &[1.3, 0.0, 0.0, 2.50, 2.49]),
            ("Curriculum RL", &[71.5, 41.1, 40.7, 0.37, 1.18]),
            ("Hierarchical RL", &[29.3, 20.7, 16.5, 1.04, 1.45]),
            ("HumanVLA", &[34.2, 29.8, 23.5, 0.70, 1.26]),
            ("InterMimic", &[16.3, 8.4, 6.2, 1.64, 2.22]),
            ("TokenHSI", &[32.0, 27.0, 23.7, 0.72, 1.31]),
            ("LHM w/o RR", &[66.7, 52.2, 48.7, 0.60, 0.68]),
            ("LHM w/o AMP", &[25.3, 14.5, 10.6, 1.39, 1.91]),
            ("LHM-S", &[76.5, 65.4, 63.7, 0.42, 0.56]),
        ],
    },
    TableSpec {
        file: "table4-ext5",
        title: "Table 4: five-object sequences (trained on two objects)",
        split: "ext5",
        cycles: 5,
        with_dist: false,
        vla: false,
        paper: &[
            ("End-to-End RL", &[2.4, 0.0, 0.0, 0.0, 0.0, 0.0]),
            ("Curriculum RL", &[90.4, 51.8, 34.3, 22.3, 6.7, 1.7]),
            ("Hierarchical RL", &[38.6, 27.3, 16.6, 3.8, 0.0, 0.0]),
            ("HumanVLA", &[45.8, 40.5, 21.7, 5.6, 1.2, 0.1]),
            ("InterMimic", &[21.3, 10.2, 2.5, 0.4, 0.0, 0.0]),
            ("TokenHSI", &[41.7, 32.7, 18.9, 4.9, 1.1, 0.1]),
            ("LHM w/o RR", &[82.1, 60.0, 21.6, 4.1, 0.9, 0.0]),
            ("LHM w/o AMP", &[33.6, 14.3, 2.0, 0.9, 0.0, 0.0]),
            ("LHM-S", &[90.8, 76.1, 61.0, 38.5, 20.9, 18.1]),
        ],
    },
];

/// One of our rows: a method's policy (or teacher pair) and where its evaluations go.
struct OurRow {
    name: String,
    /// What produced it: the pipeline's stages and budgets.
    provenance: String,
    /// The paper row it is compared with.
    paper_name: String,
    method_dir: PathBuf,
    row_dir: &'static str,
    policy: PathBuf,
    teacher1: Option<PathBuf>,
}

/// A stage's policy stem if the stage left one.
fn stage_policy(method_dir: &Path, stage: &str) -> Option<PathBuf> {
    let stem = method_dir.join(stage).join("policy");
    stem.with_extension("json").is_file().then_some(stem)
}

/// Every method pipeline under `runs` (directories with a `pipeline.json`), sorted by name.
fn methods(runs: &Path) -> Result<Vec<(PathBuf, Manifest)>> {
    let entries = std::fs::read_dir(runs).with_context(|| format!("reading {}", runs.display()))?;
    let mut out = Vec::new();
    for entry in entries {
        let dir = entry
            .with_context(|| format!("reading {}", runs.display()))?
            .path();
        let path = dir.join(MANIFEST_FILE);
        if !path.is_file() {
            continue;
        }
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        let manifest: Manifest =
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        out.push((dir, manifest));
    }
    out.sort_by(|a, b| a.1.name.cmp(&b.1.name));
    Ok(out)
}

/// Our rows of a method: its teachers ("-T"), its student ("-S"), or a baseline's one policy;
/// with `vla`, its VLA with and without language instead (Table 3).
fn rows_of(dir: &Path, manifest: &Manifest, vla: bool) -> Vec<OurRow> {
    let teacher1 = stage_policy(dir, "t1-rr").or_else(|| stage_policy(dir, "t1"));
    let teacher2 = stage_policy(dir, "t2");
    let student = stage_policy(dir, "student");
    let single = stage_policy(dir, "curriculum")
        .or_else(|| stage_policy(dir, "e2e"))
        .or_else(|| stage_policy(dir, "hierarchical"));
    let vla_policy = stage_policy(dir, "vla");
    let policies = if vla {
        Policies {
            teacher1: None,
            teacher2: None,
            student: None,
            vla: vla_policy.as_deref(),
            single: None,
        }
    } else {
        Policies {
            teacher1: teacher1.as_deref(),
            teacher2: teacher2.as_deref(),
            student: student.as_deref(),
            vla: None,
            single: single.as_deref(),
        }
    };
    let label = &manifest.label;
    let stages: Vec<String> = manifest
        .stages
        .iter()
        .map(|(stage, n)| format!("{stage} {n}"))
        .collect();
    let provenance = format!(
        "pipeline `{}` ({} iterations{})",
        manifest.name,
        stages.join(", "),
        manifest
            .overlay
            .as_ref()
            .map(|o| format!(", overlay {}", o.display()))
            .unwrap_or_default()
    );
    policies
        .rows()
        .into_iter()
        .filter(|r| !r.first_pair)
        .map(|r: EvalRow<'_>| {
            // The paper's VLA rows are named by the policy they were distilled from.
            let vla_name = |suffix: &str| {
                if label == "LHM" {
                    (format!("{label}-S (VLA{suffix})"), "LHM-S".to_string())
                } else {
                    (format!("{label} (VLA{suffix})"), label.clone())
                }
            };
            let (name, paper_name) = match r.name {
                "vla" => vla_name(""),
                // The paper gives no figure for the ablation ("near zero").
                "vla-no-language" => (vla_name(", no language").0, String::new()),
                "teachers" => (format!("{label}-T"), format!("{label}-T")),
                // The paper's ablation rows are deployable policies: compared with our student.
                "student" if label == "LHM" => (format!("{label}-S"), format!("{label}-S")),
                "student" => (format!("{label}-S"), label.clone()),
                _ => (label.clone(), label.clone()),
            };
            OurRow {
                provenance: provenance.clone(),
                name,
                paper_name,
                method_dir: dir.to_path_buf(),
                row_dir: r.name,
                policy: r.policy.to_path_buf(),
                teacher1: r.teacher1.map(Path::to_path_buf),
            }
        })
        .collect()
}

/// The row's evaluation on `split`: reused when an earlier one had the same seeds and tasks,
/// else run now.
fn evaluation(
    row: &OurRow,
    split: &str,
    tasks: usize,
    args: &TablesArgs,
) -> Result<serde_json::Value> {
    let out = row.method_dir.join("eval").join(split).join(row.row_dir);
    let path = out.join("table.json");
    let read = || -> Option<serde_json::Value> {
        serde_json::from_slice(&std::fs::read(&path).ok()?).ok()
    };
    // Reused only when it evaluated these very policies (their saved iterations), seeds and tasks.
    if crate::eval_cmd::table_is_current(
        &out,
        &row.policy,
        row.teacher1.as_deref(),
        args.seeds,
        Some(tasks),
    ) {
        if let Some(table) = read() {
            println!("{} on {split}: reusing {}", row.name, path.display());
            return Ok(table);
        }
    }
    println!(
        "{} on {split}: evaluating {}",
        row.name,
        row.policy.display()
    );
    crate::eval_cmd::run(crate::eval_cmd::EvalArgs {
        policy: row.policy.clone(),
        split: split.into(),
        seeds: args.seeds,
        first_pair: false,
        teacher1: row.teacher1.clone(),
        stop_policy: None,
        limit: args.limit,
        config: None,
        json: false,
        output: Some(out),
        batch: 64,
        gifs: 0,
        max_steps: None,
        action_std: 0.0,
        no_language: false,
        from_rest: false,
        scenes: args.scenes.clone(),
    })
    .with_context(|| format!("{} on {split}", row.name))?;
    read().with_context(|| format!("{} was not written", path.display()))
}

fn pct(table: &serde_json::Value, key: &str) -> (String, String) {
    let get = |k: &str| table.get(k).and_then(|v| v.as_f64());
    match (get(key), get(&format!("{key}_std"))) {
        (Some(m), Some(s)) => (
            format!("{:.1} ± {:.1}", 100.0 * m, 100.0 * s),
            format!("{},{}", 100.0 * m, 100.0 * s),
        ),
        _ => ("—".into(), ",".into()),
    }
}

fn metres(table: &serde_json::Value, key: &str) -> (String, String) {
    let get = |k: &str| table.get(k).and_then(|v| v.as_f64());
    match (get(key), get(&format!("{key}_std"))) {
        (Some(m), Some(s)) => (format!("{m:.2} ± {s:.2}"), format!("{m},{s}")),
        _ => ("—".into(), ",".into()),
    }
}

/// The paper's figures of `name` as one cell ("88.8 / 72.9 / … / 0.25 / 0.48"), or "—".
fn paper_cell(spec: &TableSpec, name: &str) -> String {
    // Success 1..K and Success All in %, then the distances in m.
    let successes = spec.cycles + 1;
    spec.paper
        .iter()
        .find(|(n, _)| *n == name)
        .map_or("—".into(), |(_, v)| {
            v.iter()
                .enumerate()
                .map(|(i, x)| {
                    if i < successes {
                        format!("{x:.1}")
                    } else {
                        format!("{x:.2}")
                    }
                })
                .collect::<Vec<_>>()
                .join(" / ")
        })
}

pub fn run(args: TablesArgs) -> Result<()> {
    if args.seeds == 0 {
        bail!("--seeds must be at least 1");
    }
    let methods = methods(&args.runs)?;
    if methods.is_empty() {
        bail!(
            "{}: no method pipelines (directories with {MANIFEST_FILE}); run `lhm pipeline \
             --config configs/methods/<method>.toml --runs-dir {}` first",
            args.runs.display(),
            args.runs.display()
        );
    }
    let rows: Vec<OurRow> = methods
        .iter()
        .flat_map(|(d, m)| rows_of(d, m, false))
        .collect();
    let vla_rows: Vec<OurRow> = methods
        .iter()
        .flat_map(|(d, m)| rows_of(d, m, true))
        .collect();
    if rows.is_empty() {
        bail!(
            "{}: the method pipelines have no finished policy yet",
            args.runs.display()
        );
    }
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("creating {}", args.output.display()))?;
    let bench = args.scenes.load()?;
    for spec in TABLES {
        let rows = if spec.vla { &vla_rows } else { &rows };
        let mut tasks = crate::eval_cmd::split_tasks(&bench, spec.split)?.len();
        if let Some(n) = args.limit {
            tasks = tasks.min(n);
        }
        let k = spec.cycles;
        let mut head = vec!["Method".to_string()];
        head.extend((1..=k).map(|i| format!("Success {i} (%)")));
        head.push("Success All (%)".into());
        if spec.with_dist {
            head.extend((1..=k).map(|i| format!("Dist {i} (m)")));
        }
        head.push("Falls (%)".into());
        head.push(if spec.with_dist {
            "Paper: Success 1 / 2 / All (%), Dist 1 / 2 (m)".to_string()
        } else {
            format!("Paper: Success 1-{k} / All (%)")
        });
        let mut csv_head = vec!["method".to_string()];
        let mut keys: Vec<String> = (1..=k).map(|i| format!("success_{i}")).collect();
        keys.push("success_all".into());
        if spec.with_dist {
            keys.extend((1..=k).map(|i| format!("dist_{i}")));
        }
        keys.push("fall_rate".into());
        for key in &keys {
            let unit = if key.starts_with("dist") { "m" } else { "pct" };
            csv_head.push(format!("{key}_{unit}"));
            csv_head.push(format!("{key}_{unit}_std"));
        }
        csv_head.extend(["paper".into(), "policy".into()]);
        let mut md =
            format!(
            "## {}\n\n`lhm tables --runs {} --seeds {}{}`: {} tasks of `{}` × {} seeds per row, \
             deterministic actions; mean ± std over seeds.\n\n| {} |\n|{}\n",
            spec.title,
            args.runs.display(),
            args.seeds,
            args.limit.map(|n| format!(" --limit {n}")).unwrap_or_default(),
            tasks,
            spec.split,
            args.seeds,
            head.join(" | "),
            "---|".repeat(head.len())
        );
        let mut csv = format!("{}\n", csv_head.join(","));
        let mut ours: Vec<&str> = Vec::new();
        let mut made_by = String::new();
        if rows.is_empty() {
            md.push_str("| (no method pipeline has a `vla` stage yet) |\n");
        }
        for row in rows {
            made_by.push_str(&format!(
                "- {}: `{}` (saved at iteration {}){}, {}\n",
                row.name,
                row.policy.display(),
                crate::eval_cmd::policy_iteration(&row.policy)
                    .map_or("?".into(), |i| i.to_string()),
                row.teacher1
                    .as_ref()
                    .map(|t| format!(" after `{}` on each first cycle", t.display()))
                    .unwrap_or_default(),
                row.provenance
            ));
            let table = evaluation(row, spec.split, tasks, &args)?;
            let mut cells = vec![row.name.clone()];
            let mut fields = vec![row.name.clone()];
            for key in &keys {
                let (cell, field) = if key.starts_with("dist") {
                    metres(&table, key)
                } else {
                    pct(&table, key)
                };
                cells.push(cell);
                fields.push(field);
            }
            let paper = paper_cell(spec, &row.paper_name);
            cells.push(paper.clone());
            fields.push(format!("\"{paper}\""));
            fields.push(format!("\"{}\"", row.policy.display()));
            md.push_str(&format!("| {} |\n", cells.join(" | ")));
            csv.push_str(&format!("{}\n", fields.join(",")));
            ours.push(&row.paper_name);
        }
        // The paper's other rows, for reference: methods not run here.
        let mut missing = Vec::new();
        for (name, _) in spec.paper {
            if !ours.contains(name) {
                let mut cells = vec![format!("{name} (not run here)")];
                cells.extend(std::iter::repeat_n("—".to_string(), keys.len()));
                cells.push(paper_cell(spec, name));
                md.push_str(&format!("| {} |\n", cells.join(" | ")));
                missing.push(*name);
            }
        }
        md.push_str(&format!("\nRows:\n{made_by}"));
        if !missing.is_empty() {
            md.push_str(&format!("\nNot run here: {}.\n", missing.join(", ")));
        }
        for (ext, text) in [("md", md), ("csv", csv)] {
            let path = args.output.join(format!("{}.{ext}", spec.file));
            std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}
