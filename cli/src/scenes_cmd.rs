use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use lhm_scenes::generate::{generate, to_toml, GenerateConfig};
use lhm_scenes::render::render_task;
use lhm_scenes::routes::{plan_task, Clearance};
use lhm_scenes::validate::validate_benchmark;
use lhm_scenes::{stats, Benchmark, Catalogue, Split};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Args)]
pub struct ScenesArgs {
    #[command(subcommand)]
    command: ScenesCommand,
}

/// Where a command reads the benchmark's tasks: `--scenes DIR` (e.g. written by `lhm scenes
/// generate`) or the copy built into `lhm`.
#[derive(Args, Clone, Debug, Default)]
pub struct Source {
    /// Read the task files from this directory instead of the copy built into `lhm`.
    #[arg(long, value_name = "DIR")]
    pub scenes: Option<PathBuf>,
}

impl Source {
    pub fn load(&self) -> Result<Benchmark> {
        Ok(match &self.scenes {
            Some(dir) => {
                Benchmark::load_dir(dir).with_context(|| format!("--scenes {}", dir.display()))?
            }
            None => Benchmark::embedded()?,
        })
    }
}

#[derive(Subcommand)]
enum ScenesCommand {
    /// Generate train/unseen/extension task files from the catalogue, deterministically.
    Generate {
        /// Directory holding catalogue.toml; the split files are written beside it.
        #[arg(long, default_value = "scenes/data")]
        dir: PathBuf,
        /// Seed of the generator (the shipped files use the default).
        #[arg(long, default_value_t = GenerateConfig::default().seed)]
        seed: u64,
        /// Compare with the files in DIR instead of writing; exit non-zero if they differ.
        #[arg(long)]
        check: bool,
    },
    /// Check every task: geometry, counts, radii, reachable routes, unseen/train separation.
    Validate {
        /// Only this split (train, unseen, extension).
        #[arg(long)]
        split: Option<String>,
        #[command(flatten)]
        source: Source,
    },
    /// Benchmark statistics.
    Stats {
        /// Print the statistics as JSON.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        source: Source,
    },
    /// Top-down picture of one task with its planned routes.
    Render {
        /// Task id, e.g. train-0001.
        task: String,
        /// Output PNG file.
        #[arg(short, long, value_name = "PNG")]
        output: PathBuf,
        #[command(flatten)]
        source: Source,
    },
}

pub fn run(args: ScenesArgs) -> Result<ExitCode> {
    match args.command {
        ScenesCommand::Generate { dir, seed, check } => generate_cmd(&dir, seed, check),
        ScenesCommand::Validate { split, source } => {
            let only = match split.as_deref() {
                None => None,
                Some(s) => Some(Split::parse(s).with_context(|| {
                    format!("unknown split {s:?}: expected train, unseen or extension")
                })?),
            };
            validate_cmd(&source.load()?, only)
        }
        ScenesCommand::Stats { json, source } => {
            let s = stats::compute(&source.load()?);
            if json {
                println!("{}", serde_json::to_string_pretty(&s)?);
            } else {
                print!("{}", stats::to_text(&s));
            }
            Ok(ExitCode::SUCCESS)
        }
        ScenesCommand::Render {
            task,
            output,
            source,
        } => render_cmd(&source.load()?, &task, &output),
    }
}

fn generate_cmd(dir: &Path, seed: u64, check: bool) -> Result<ExitCode> {
    let cat_path = dir.join(lhm_scenes::load::CATALOGUE_FILE);
    let text = std::fs::read_to_string(&cat_path).with_context(|| {
        format!(
            "reading {} (run from the repository root or pass --dir)",
            cat_path.display()
        )
    })?;
    let catalogue = Catalogue::parse(&text, &cat_path.display().to_string())?;
    let cfg = GenerateConfig {
        seed,
        ..GenerateConfig::default()
    };
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} tasks ({elapsed})")
            .expect("static template")
            .progress_chars("=> "),
    );
    let files = generate(&catalogue, &cfg, |split, done, total| {
        bar.set_message(split.to_string());
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    let mut differ = Vec::new();
    for file in &files {
        let path = dir.join(file.split.file_name());
        let text = to_toml(file)?;
        if check {
            let current = std::fs::read_to_string(&path).unwrap_or_default();
            if current != text {
                differ.push(path.display().to_string());
            }
        } else {
            // Write to a temporary file then rename, so an interrupted run never leaves a
            // half-written split file behind.
            let tmp = path.with_extension("toml.tmp");
            std::fs::write(&tmp, &text).with_context(|| format!("writing {}", tmp.display()))?;
            std::fs::rename(&tmp, &path).with_context(|| format!("writing {}", path.display()))?;
            println!("wrote {} ({} tasks)", path.display(), file.tasks.len());
        }
    }
    if !differ.is_empty() {
        bail!(
            "generated tasks differ from the committed files: {}",
            differ.join(", ")
        );
    }
    if check {
        println!("committed task files match a fresh generation (seed {seed})");
    }
    Ok(ExitCode::SUCCESS)
}

fn validate_cmd(b: &Benchmark, only: Option<Split>) -> Result<ExitCode> {
    let problems = validate_benchmark(b, only, &Clearance::default());
    for split in Split::ALL
        .into_iter()
        .filter(|s| only.is_none_or(|o| o == *s))
    {
        let n = b.tasks(split).len();
        let bad = problems
            .iter()
            .filter(|p| b.tasks(split).iter().any(|t| t.id == p.task))
            .count();
        println!("{split:>10}: {n} tasks, {bad} problems");
    }
    for p in &problems {
        eprintln!("invalid: {p}");
    }
    Ok(if problems.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

fn render_cmd(b: &Benchmark, id: &str, output: &Path) -> Result<ExitCode> {
    let (_, task) = b
        .task(id)
        .with_context(|| format!("no task {id:?} (see `lhm scenes stats`)"))?;
    let legs = match plan_task(&task, &Clearance::default()) {
        Ok(legs) => Some(legs),
        Err(e) => {
            tracing::warn!("drawing {id} without routes: {e}");
            None
        }
    };
    let canvas = render_task(&task, &b.catalogue, legs.as_deref());
    let file =
        std::fs::File::create(output).with_context(|| format!("creating {}", output.display()))?;
    canvas
        .write_png(std::io::BufWriter::new(file))
        .with_context(|| format!("writing {}", output.display()))?;
    println!(
        "wrote {} ({}x{})",
        output.display(),
        canvas.width,
        canvas.height
    );
    Ok(ExitCode::SUCCESS)
}
