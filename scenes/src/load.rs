//! Loading the benchmark: the catalogue and the three split files, from a directory or from the
//! copy embedded in the binary (so `lhm` works from anywhere, including a container with nothing
//! but the binary). Every problem is reported with the file, the task and the field.

use crate::catalogue::Catalogue;
use crate::error::SceneError;
use crate::model::{Split, SplitFile, Support, Task, TASK_FILE_SCHEMA};
use crate::toml_util::{deserialize_at, parse_table};
use std::collections::{BTreeMap, HashSet};
use std::path::Path;

pub const CATALOGUE_FILE: &str = "catalogue.toml";

/// The committed data files, embedded at build time.
const EMBEDDED: [(&str, &str); 4] = [
    (CATALOGUE_FILE, include_str!("../data/catalogue.toml")),
    ("train.toml", include_str!("../data/train.toml")),
    ("unseen.toml", include_str!("../data/unseen.toml")),
    ("extension.toml", include_str!("../data/extension.toml")),
];

/// Display prefix for embedded files, so errors point at the file in the repository.
const EMBEDDED_DIR: &str = "scenes/data";

#[derive(Clone, Debug)]
pub struct Benchmark {
    pub catalogue: Catalogue,
    pub splits: BTreeMap<Split, SplitFile>,
}

impl Benchmark {
    /// The benchmark as committed in `scenes/data/`, embedded in the binary.
    pub fn embedded() -> Result<Self, SceneError> {
        let files: BTreeMap<&str, &str> = EMBEDDED.into_iter().collect();
        Self::from_texts(EMBEDDED_DIR, |name| Ok(files[name].to_string()))
    }

    /// Loads `catalogue.toml`, `train.toml`, `unseen.toml` and `extension.toml` from `dir`.
    pub fn load_dir(dir: &Path) -> Result<Self, SceneError> {
        Self::from_texts(&dir.display().to_string(), |name| {
            let path = dir.join(name);
            std::fs::read_to_string(&path).map_err(|source| SceneError::Io {
                file: path.display().to_string(),
                source,
            })
        })
    }

    fn from_texts(
        dir: &str,
        read: impl Fn(&str) -> Result<String, SceneError>,
    ) -> Result<Self, SceneError> {
        let catalogue =
            Catalogue::parse(&read(CATALOGUE_FILE)?, &format!("{dir}/{CATALOGUE_FILE}"))?;
        let mut splits = BTreeMap::new();
        for split in Split::ALL {
            let name = split.file_name();
            let file = parse_split(&read(&name)?, &format!("{dir}/{name}"), &catalogue)?;
            if file.split != split {
                return Err(SceneError::field(
                    &format!("{dir}/{name}"),
                    None,
                    "split",
                    format!(
                        "says {:?}, expected {:?}",
                        file.split.as_str(),
                        split.as_str()
                    ),
                ));
            }
            splits.insert(split, file);
        }
        Ok(Self { catalogue, splits })
    }

    pub fn tasks(&self, split: Split) -> &[Task] {
        self.splits.get(&split).map_or(&[], |f| f.tasks.as_slice())
    }

    pub fn all_tasks(&self) -> impl Iterator<Item = (Split, &Task)> {
        self.splits
            .iter()
            .flat_map(|(s, f)| f.tasks.iter().map(move |t| (*s, t)))
    }

    /// A task by id: a benchmark task, or one of its single-object tasks (`<id>.p<k>`, see
    /// [`Task::single_pair`]).
    pub fn task(&self, id: &str) -> Option<(Split, Task)> {
        if let Some(found) = self.all_tasks().find(|(_, t)| t.id == id) {
            return Some((found.0, found.1.clone()));
        }
        let (parent, k) = id.rsplit_once(".p")?;
        let k: usize = k.parse().ok()?;
        let (split, task) = self.all_tasks().find(|(_, t)| t.id == parent)?;
        Some((split, task.single_pair(k.checked_sub(1)?)?))
    }

    /// Teacher 1's pretraining set: every task of `split` cut into one task per (object, goal)
    /// pair (350 two-object training tasks → 700 single-object tasks).
    pub fn single_object_tasks(&self, split: Split) -> Vec<Task> {
        self.tasks(split)
            .iter()
            .flat_map(|t| (0..t.sequence.len()).filter_map(move |k| t.single_pair(k)))
            .collect()
    }
}

/// Parses one split file and checks it against the catalogue.
pub fn parse_split(text: &str, file: &str, catalogue: &Catalogue) -> Result<SplitFile, SceneError> {
    let mut table = parse_table(text, file)?;
    let tasks = match table.remove("task") {
        Some(toml::Value::Array(a)) => a,
        Some(_) => {
            return Err(SceneError::field(
                file,
                None,
                "task",
                "must be an array of tables",
            ))
        }
        None => Vec::new(),
    };
    match table.get("schema").and_then(toml::Value::as_integer) {
        Some(v) if v == i64::from(TASK_FILE_SCHEMA) => {}
        Some(v) => {
            return Err(SceneError::field(
                file,
                None,
                "schema",
                format!("version {v} is not supported (this build reads {TASK_FILE_SCHEMA})"),
            ))
        }
        None => return Err(SceneError::field(file, None, "schema", "missing")),
    }
    table.insert("task".into(), toml::Value::Array(Vec::new()));
    let mut split: SplitFile = deserialize_at(toml::Value::Table(table), file, None)?;
    let mut ids = HashSet::new();
    for (i, value) in tasks.into_iter().enumerate() {
        let name = value
            .get("id")
            .and_then(toml::Value::as_str)
            .map_or_else(|| format!("#{i} (no id)"), str::to_string);
        let task: Task = deserialize_at(value, file, Some(&name))?;
        if !ids.insert(task.id.clone()) {
            return Err(SceneError::field(
                file,
                Some(&name),
                "id",
                "duplicate task id",
            ));
        }
        check_task(&task, catalogue)
            .map_err(|(field, msg)| SceneError::field(file, Some(&task.id), field, msg))?;
        split.tasks.push(task);
    }
    Ok(split)
}

type Inconsistency = (String, String);

/// Consistency of one task with the catalogue and with itself (references, sizes, counts).
/// Geometry (overlaps, reachability) is the validator's job.
fn check_task(task: &Task, cat: &Catalogue) -> Result<(), Inconsistency> {
    let fail = |field: String, msg: String| Err((field, msg));
    if task.id.is_empty() {
        return fail("id".into(), "empty".into());
    }
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if !finite(&task.room_size) || task.room_size.iter().any(|s| *s <= 0.0) {
        return fail("room_size".into(), "must be positive".into());
    }
    if !finite(&task.centroid) {
        return fail("centroid".into(), "not finite".into());
    }
    if !finite(&task.start.pos) || !task.start.yaw.is_finite() {
        return fail("start".into(), "not finite".into());
    }
    let same = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6);
    let mut ids = HashSet::new();
    for (i, o) in task.obstacles.iter().enumerate() {
        let at = |f: &str| format!("obstacle[{i}].{f}");
        if !ids.insert(o.id.as_str()) {
            return fail(at("id"), format!("duplicate id {:?}", o.id));
        }
        let Some(t) = cat.get(&o.kind) else {
            return fail(at("kind"), format!("{:?} is not in the catalogue", o.kind));
        };
        if t.movable {
            return fail(
                at("kind"),
                format!("{:?} is movable, not an obstacle", o.kind),
            );
        }
        if !t.rooms.contains(&task.room) {
            return fail(
                at("kind"),
                format!("{:?} does not belong in a {}", o.kind, task.room),
            );
        }
        if !same(&o.size, &t.size) {
            return fail(
                at("size"),
                format!("{:?} differs from the catalogue {:?}", o.size, t.size),
            );
        }
        if !finite(&o.pos) || !o.yaw.is_finite() {
            return fail(at("pos"), "not finite".into());
        }
    }
    let check_support = |on: &Support, field: String| -> Result<(), Inconsistency> {
        if let Support::Surface(id) = on {
            match task.obstacle(id).and_then(|o| cat.get(&o.kind)) {
                None => return fail(field, format!("no obstacle {id:?} to rest on")),
                Some(t) if !t.support => {
                    return fail(
                        field,
                        format!("{id:?} ({}) is not a support surface", t.name),
                    )
                }
                Some(_) => {}
            }
        }
        Ok(())
    };
    let mut kinds = HashSet::new();
    for (i, o) in task.objects.iter().enumerate() {
        let at = |f: &str| format!("object[{i}].{f}");
        if !ids.insert(o.id.as_str()) {
            return fail(at("id"), format!("duplicate id {:?}", o.id));
        }
        let Some(t) = cat.get(&o.kind) else {
            return fail(at("kind"), format!("{:?} is not in the catalogue", o.kind));
        };
        if !t.movable {
            return fail(at("kind"), format!("{:?} is not a movable object", o.kind));
        }
        if !t.rooms.contains(&task.room) {
            return fail(
                at("kind"),
                format!("{:?} does not belong in a {}", o.kind, task.room),
            );
        }
        if !kinds.insert(o.kind.as_str()) {
            return fail(
                at("kind"),
                format!("two {:?}: instructions would be ambiguous", o.kind),
            );
        }
        if !same(&o.size, &t.size) {
            return fail(
                at("size"),
                format!("{:?} differs from the catalogue {:?}", o.size, t.size),
            );
        }
        if (o.mass - t.mass).abs() > 1e-6 {
            return fail(
                at("mass"),
                format!("{} differs from the catalogue {}", o.mass, t.mass),
            );
        }
        if !finite(&o.pos) || !o.yaw.is_finite() {
            return fail(at("pos"), "not finite".into());
        }
        if matches!(o.on, Support::Surface(_)) && !t.on_surface {
            return fail(
                at("on"),
                format!("a {} does not go on a surface", t.display),
            );
        }
        check_support(&o.on, at("on"))?;
    }
    if task.sequence.is_empty() {
        return fail("step".into(), "no (object, goal) pairs".into());
    }
    let mut moved = HashSet::new();
    for (k, s) in task.sequence.iter().enumerate() {
        let at = |f: &str| format!("step[{k}].{f}");
        let Some(o) = task.object(&s.object) else {
            return fail(at("object"), format!("no object {:?}", s.object));
        };
        if !moved.insert(s.object.as_str()) {
            return fail(at("object"), format!("{:?} is moved twice", s.object));
        }
        if !finite(&s.goal) || !s.goal_yaw.is_finite() {
            return fail(at("goal"), "not finite".into());
        }
        if s.instruction.trim().is_empty() {
            return fail(at("instruction"), "empty".into());
        }
        let surface_ok = cat.get(&o.kind).is_some_and(|t| t.on_surface);
        if matches!(s.on, Support::Surface(_)) && !surface_ok {
            return fail(at("on"), format!("a {} does not go on a surface", o.kind));
        }
        check_support(&s.on, at("on"))?;
    }
    if moved.len() != task.objects.len() {
        return fail(
            "step".into(),
            "every movable object must be moved exactly once".into(),
        );
    }
    Ok(())
}
