//! `runs/<run>/metrics.csv`: one row per iteration, appended and flushed as it is made, so a killed
//! learner loses no row it wrote and a resumed one continues the same file (`lhm plot` reads it).

use std::fs::{File, OpenOptions};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

/// The columns, in order. Missing values are written as empty fields.
pub const COLUMNS: &[&str] = &[
    "iteration",
    "samples",
    "wall_s",
    "samples_per_s",
    "update_s",
    "episodes",
    "mean_return",
    "mean_episode_length",
    "success_rate",
    "fall_fraction",
    "task_start_fall_fraction",
    "reach_rate",
    "disc_accuracy",
    "style_reward",
    "task_reward",
    "policy_loss",
    "value_loss",
    "approx_kl",
    "lr",
    "clip_fraction",
    "stale_chunks",
    "accepted_chunks",
    "reward_locomotion",
    "reward_facing",
    "reward_hands",
    "reward_lift",
    "reward_carry",
    "reward_place",
    "reward_power",
    "reward_release_retreat",
    "reward_success",
    "reward_alive",
    "reward_imitation",
    // The student's DAgger rounds (empty for the teachers).
    "teacher_mix",
    "student_loss_before",
    "student_loss",
    "dagger_rows",
    "dagger_rounds",
    // The Hierarchical RL baseline's skill completions (0 without the skill machine).
    "reward_skill",
    "reward_assist",
    // The upright assist's strength (sim.assist; empty when the run has none).
    "assist_strength",
    // Reach over every finished episode, demo and gait starts included (`reach_rate` counts task
    // starts only; with [env.gait] every episode starts in the gait).
    "reach_rate_all",
    // The discriminator's update, each side apart (`disc_accuracy` is their mean), and its
    // losses before the weights (gradient penalty unscaled).
    "disc_demo_accuracy",
    "disc_agent_accuracy",
    "disc_demo_logit",
    "disc_agent_logit",
    "disc_bce_loss",
    "disc_grad_penalty",
    // The discriminator's learning rate in the update (steered under `[amp.accuracy_target]`).
    "disc_lr",
    // The style reward's (judged steps) and the task reward's standard deviation per step over
    // the batch: how much of the reward's step-to-step variation the discriminator makes.
    "style_reward_std",
    "task_reward_std",
];

pub struct MetricsCsv {
    path: PathBuf,
    file: File,
}

impl MetricsCsv {
    /// Opens `path` for appending. A file whose header is a prefix of [`COLUMNS`] (written before
    /// columns were added at the end) is brought to the new layout in place, its rows padded with
    /// empty fields (written to a temporary file and renamed, so a crash leaves one or the other);
    /// any other header (an older layout) is kept as `<path>.old` (never overwritten: `.old.2`,
    /// … ) and a new file started.
    pub fn open(path: &Path) -> std::io::Result<Self> {
        let header = COLUMNS.join(",");
        if let Ok(f) = File::open(path) {
            let mut first = String::new();
            BufReader::new(f).read_line(&mut first)?;
            let old = first.trim_end();
            let old_columns: Vec<&str> = old.split(',').collect();
            let is_prefix = !old.is_empty()
                && old_columns.len() < COLUMNS.len()
                && COLUMNS[..old_columns.len()] == old_columns[..];
            if is_prefix {
                let text = std::fs::read_to_string(path)?;
                let mut out = format!("{header}\n");
                for line in text.lines().skip(1).filter(|l| !l.is_empty()) {
                    let fields = line.split(',').count();
                    out.push_str(line);
                    out.push_str(&",".repeat(COLUMNS.len().saturating_sub(fields)));
                    out.push('\n');
                }
                let tmp = path.with_extension("csv.tmp");
                std::fs::write(&tmp, out)?;
                std::fs::rename(&tmp, path)?;
            } else if !old.is_empty() && old != header {
                let keep = (1u32..)
                    .map(|k| {
                        let suffix = if k == 1 {
                            "old".into()
                        } else {
                            format!("old.{k}")
                        };
                        path.with_extension(format!("csv.{suffix}"))
                    })
                    .find(|p| !p.exists())
                    .unwrap_or_else(|| path.with_extension("csv.old"));
                std::fs::rename(path, keep)?;
            }
        }
        let mut file = OpenOptions::new().create(true).append(true).open(path)?;
        if file.metadata()?.len() == 0 {
            writeln!(file, "{header}")?;
            file.flush()?;
        }
        Ok(Self {
            path: path.to_owned(),
            file,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends one row: `values` by column name; absent or non-finite values are empty fields.
    pub fn append(&mut self, values: &[(&str, f64)]) -> std::io::Result<()> {
        let row: Vec<String> = COLUMNS
            .iter()
            .map(|c| {
                values
                    .iter()
                    .find(|(k, _)| k == c)
                    .filter(|(_, v)| v.is_finite())
                    .map_or(String::new(), |(_, v)| format!("{v}"))
            })
            .collect();
        writeln!(self.file, "{}", row.join(","))?;
        self.file.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_missing_the_last_columns_is_padded_in_place() {
        let dir = std::env::temp_dir().join(format!("lhm-metrics-pad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("metrics.csv");
        let old = &COLUMNS[..COLUMNS.len() - 3];
        std::fs::write(&path, format!("{}\n1,2\n", old.join(","))).unwrap();
        let mut csv = MetricsCsv::open(&path).unwrap();
        csv.append(&[("iteration", 2.0)]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], COLUMNS.join(","));
        assert_eq!(lines[1].split(',').count(), COLUMNS.len());
        assert!(lines[1].starts_with("1,2,"));
        assert!(lines[2].starts_with("2,"));
        assert!(!path.with_extension("csv.old").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn rows_append_across_reopens_and_an_old_layout_is_kept_aside() {
        let dir = std::env::temp_dir().join(format!("lhm-metrics-csv-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("metrics.csv");
        std::fs::write(&path, "iteration,old_column\n1,2\n").unwrap();
        let mut m = MetricsCsv::open(&path).unwrap();
        m.append(&[
            ("iteration", 1.0),
            ("mean_return", 2.5),
            ("reach_rate", f64::NAN),
        ])
        .unwrap();
        drop(m);
        let mut m = MetricsCsv::open(&path).unwrap();
        m.append(&[("iteration", 2.0)]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3, "{text}");
        assert_eq!(lines[0], COLUMNS.join(","));
        let row: Vec<&str> = lines[1].split(',').collect();
        assert_eq!(row.len(), COLUMNS.len());
        assert_eq!(row[0], "1");
        assert_eq!(row[6], "2.5");
        assert_eq!(row[10], "", "NaN is an empty field");
        assert!(lines[2].starts_with("2,"));
        let old = std::fs::read_to_string(dir.join("metrics.csv.old")).unwrap();
        assert!(old.contains("old_column"), "the old file is kept");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
