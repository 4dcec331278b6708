//! The run directory's `config.toml` as the record of how its checkpoint was trained: a run of
//! another role is refused, and a resume under a configuration that differs from the saved one
//! (a schedule, an environment key) says which keys changed and keeps the earlier file as
//! `config.until-<iteration>.toml`, so the record of how the first iterations were trained is
//! not overwritten by the one that trains the next.

use std::path::{Path, PathBuf};

use super::{ServiceError, TrainConfig, RUN_CONFIG_FILE};

/// Top-level keys that say where and how long a session runs, not what it trains: a resume that
/// changes only these is not a change of configuration.
const SESSION_KEYS: [&str; 5] = [
    "run_id",
    "runs_dir",
    "max_iterations",
    "checkpoint_every",
    "chunk_sets_per_version",
];

/// A run directory whose `config.toml` names another role (e.g. `lhm train --stage student` into
/// a Teacher 1 run's directory) is refused before anything in it is touched: resuming would train
/// one role's checkpoint as another's.
pub(super) fn refuse_another_role(
    config: &TrainConfig,
    run_dir: &Path,
) -> Result<(), ServiceError> {
    let path = run_dir.join(RUN_CONFIG_FILE);
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(());
    };
    let saved = text
        .parse::<toml::Table>()
        .ok()
        .and_then(|t| t.get("role").and_then(|r| r.as_str()).map(str::to_owned));
    match saved {
        Some(role) if role != config.role => Err(ServiceError::Config(format!(
            "{} holds a {role} run; this is a {} run: give it another --run-id",
            run_dir.display(),
            config.role
        ))),
        _ => Ok(()),
    }
}

/// The dotted keys whose values differ between a saved configuration and this run's (a key
/// only one side has counts; see [`diff_values`] for arrays), session keys left out; in key
/// order.
pub fn changed_keys(saved: &toml::Table, now: &toml::Table) -> Vec<String> {
    let without_session = |t: &toml::Table| -> toml::Table {
        t.iter()
            .filter(|(k, _)| !SESSION_KEYS.contains(&k.as_str()))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect()
    };
    let mut out = Vec::new();
    diff_tables("", &without_session(saved), &without_session(now), &mut out);
    out
}

fn diff_tables(prefix: &str, a: &toml::Table, b: &toml::Table, out: &mut Vec<String>) {
    let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    for key in keys {
        let path = if prefix.is_empty() {
            key.clone()
        } else {
            format!("{prefix}.{key}")
        };
        match (a.get(key), b.get(key)) {
            (Some(x), Some(y)) => diff_values(&path, x, y, out),
            (None, Some(_)) => out.push(format!("{path} (not in the saved config)")),
            (Some(_), None) => out.push(format!("{path} (only in the saved config)")),
            (None, None) => {}
        }
    }
}

/// How many differences inside an array of plain values (no tables in it) are listed one by
/// one; more are named once with their count, so a changed table of numbers (a gait's angle
/// offsets, hundreds of entries) is one line of the message, not hundreds.
const MAX_LISTED_IN_VALUES: usize = 3;

/// Tables key by key, arrays of one length entry by entry (`stages[1].log_std`; in an array of
/// plain values, up to [`MAX_LISTED_IN_VALUES`]), else whole.
fn diff_values(path: &str, a: &toml::Value, b: &toml::Value, out: &mut Vec<String>) {
    match (a, b) {
        _ if a == b => {}
        (toml::Value::Table(x), toml::Value::Table(y)) => diff_tables(path, x, y, out),
        (toml::Value::Array(x), toml::Value::Array(y)) if x.len() == y.len() => {
            let mut inside = Vec::new();
            for (i, (x, y)) in x.iter().zip(y).enumerate() {
                diff_values(&format!("{path}[{i}]"), x, y, &mut inside);
            }
            if inside.len() > MAX_LISTED_IN_VALUES && !holds_table(a) && !holds_table(b) {
                out.push(format!("{path} ({} values differ)", inside.len()));
            } else {
                out.extend(inside);
            }
        }
        _ => out.push(format!("{path} ({} → {})", short(a), short(b))),
    }
}

/// Whether a table lies anywhere inside `v` (its keys are worth naming one by one).
fn holds_table(v: &toml::Value) -> bool {
    match v {
        toml::Value::Table(_) => true,
        toml::Value::Array(a) => a.iter().any(holds_table),
        _ => false,
    }
}

/// A value as the message shows it: scalars in full (up to 40 characters), arrays and tables
/// by kind.
fn short(v: &toml::Value) -> String {
    match v {
        toml::Value::Array(a) if a.len() == 1 => "1 entry".into(),
        toml::Value::Array(a) => format!("{} entries", a.len()),
        toml::Value::Table(_) => "a table".into(),
        other => {
            let s = other.to_string();
            if s.chars().count() > 40 {
                format!("{}…", s.chars().take(40).collect::<String>())
            } else {
                s
            }
        }
    }
}

/// What [`keep_earlier_config`] found.
#[derive(Debug, PartialEq)]
pub struct ConfigChange {
    /// [`changed_keys`]; `["config.toml (unreadable: …)"]` when the saved file does not parse.
    pub keys: Vec<String>,
    /// Where the saved configuration now also lies.
    pub kept_as: PathBuf,
}

/// The file that keeps the configuration a run trained with up to `iteration`.
pub fn earlier_config_path(run_dir: &Path, iteration: u64) -> PathBuf {
    run_dir.join(format!("config.until-{iteration}.toml"))
}

/// Before a run resumed at `iteration` writes its configuration: when the saved `config.toml`
/// differs from `config` (see [`changed_keys`]), copies it to `config.until-<iteration>.toml`
/// (an existing such file is left as it is: it holds what trained those iterations, and a
/// second resume at the same iteration trained nothing under the file it would replace) and
/// says what changed. `None`: no saved file, or no change.
pub(super) fn keep_earlier_config(
    config: &TrainConfig,
    run_dir: &Path,
    iteration: u64,
) -> Result<Option<ConfigChange>, ServiceError> {
    let path = run_dir.join(RUN_CONFIG_FILE);
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(None);
    };
    // This run's configuration as its file would read back: a table made directly from the
    // struct holds its f32 fields widened (0.949999988…), the file the shortest text (0.95).
    let now: toml::Table = toml::to_string(config)
        .map_err(|e| ServiceError::Config(format!("cannot write the run's config: {e}")))?
        .parse()
        .map_err(|e| ServiceError::Config(format!("the run's config does not read back: {e}")))?;
    let keys = match text.parse::<toml::Table>() {
        Ok(saved) => changed_keys(&saved, &now),
        Err(e) => vec![format!(
            "{RUN_CONFIG_FILE} (unreadable: {})",
            e.to_string().lines().next().unwrap_or_default()
        )],
    };
    if keys.is_empty() {
        return Ok(None);
    }
    let kept_as = earlier_config_path(run_dir, iteration);
    if !kept_as.exists() {
        std::fs::copy(&path, &kept_as).map_err(|source| ServiceError::Io {
            path: kept_as.clone(),
            source,
        })?;
    }
    Ok(Some(ConfigChange { keys, kept_as }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &str) -> toml::Table {
        text.parse().unwrap()
    }

    #[test]
    fn changed_keys_name_each_differing_leaf_and_leave_session_keys_out() {
        let saved = table(
            "run_id = \"a\"\nmax_iterations = 10\nbatch_steps = 4096\n\
             [env.gait]\nstop_on = \"distance\"\nrest_start_fraction = 1.0\n\
             [[stages]]\nuntil_iteration = 5\n",
        );
        let same_but_session = table(
            "run_id = \"b\"\nmax_iterations = 99\nbatch_steps = 4096\n\
             [env.gait]\nstop_on = \"distance\"\nrest_start_fraction = 1.0\n\
             [[stages]]\nuntil_iteration = 5\n",
        );
        assert!(changed_keys(&saved, &same_but_session).is_empty());
        let other = table(
            "run_id = \"a\"\nbatch_steps = 4096\nchunk_steps = 8\n\
             [env.gait]\nstop_on = \"feet-down\"\nrest_start_fraction = 1.0\n",
        );
        assert_eq!(
            changed_keys(&saved, &other),
            vec![
                "chunk_steps (not in the saved config)".to_owned(),
                "env.gait.stop_on (\"distance\" → \"feet-down\")".to_owned(),
                "stages (only in the saved config)".to_owned(),
            ]
        );
        // Arrays of one length entry by entry, else whole.
        let one =
            table("[[stages]]\nuntil_iteration = 5\n[stages.env.gait]\nstop_on = \"distance\"\n");
        let later =
            table("[[stages]]\nuntil_iteration = 6\n[stages.env.gait]\nstop_on = \"distance\"\n");
        assert_eq!(
            changed_keys(&one, &later),
            vec!["stages[0].until_iteration (5 → 6)".to_owned()]
        );
        let two = table("[[stages]]\nuntil_iteration = 5\n[[stages]]\nuntil_iteration = 9\n");
        assert_eq!(
            changed_keys(&one, &two),
            vec!["stages (1 entry → 2 entries)".to_owned()]
        );
    }

    #[test]
    fn a_changed_table_of_numbers_is_named_once_with_its_count() {
        let saved = table(
            "[env.gait]\nangle_offsets = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]\n\
             [[stages]]\nuntil_iteration = 5\n\
             [stages.env.gait]\nangle_offsets = [[0.0, 0.0], [0.0, 0.0]]\n",
        );
        let now = table(
            "[env.gait]\nangle_offsets = [[0.1, 0.0, 0.2], [0.3, 0.4, 0.0]]\n\
             [[stages]]\nuntil_iteration = 6\n\
             [stages.env.gait]\nangle_offsets = [[0.0, 0.5], [0.0, 0.0]]\n",
        );
        // Four numbers differ in the first table: one line; one in the stage's: listed; the
        // stages (tables) key by key.
        assert_eq!(
            changed_keys(&saved, &now),
            vec![
                "env.gait.angle_offsets (4 values differ)".to_owned(),
                "stages[0].env.gait.angle_offsets[0][1] (0.0 → 0.5)".to_owned(),
                "stages[0].until_iteration (5 → 6)".to_owned(),
            ]
        );
        // Up to three are still listed one by one.
        let three = table("[env.gait]\nangle_offsets = [[0.1, 0.0, 0.2], [0.3, 0.0, 0.0]]\n");
        let zero = table("[env.gait]\nangle_offsets = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]\n");
        assert_eq!(changed_keys(&zero, &three).len(), 3);
    }
}
