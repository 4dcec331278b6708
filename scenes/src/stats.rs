//! Benchmark statistics (`lhm scenes stats`): what the paper's Sec. 4.1 reports, measured on the
//! files as they are.

use crate::geometry::dist;
use crate::load::Benchmark;
use crate::model::{Split, Support};
use crate::validate::{layout_signature, object_choice};
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet, HashSet};

#[derive(Serialize, Clone, Debug, PartialEq)]
pub struct Summary {
    pub min: f64,
    pub median: f64,
    pub max: f64,
    pub mean: f64,
}

impl Summary {
    pub fn of(values: &[f64]) -> Option<Summary> {
        if values.is_empty() {
            return None;
        }
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let median = if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        };
        let round = |x: f64| (x * 1000.0).round() / 1000.0;
        Some(Summary {
            min: round(v[0]),
            median: round(median),
            max: round(v[n - 1]),
            mean: round(v.iter().sum::<f64>() / n as f64),
        })
    }
}

#[derive(Serialize, Clone, Debug)]
pub struct SplitStats {
    pub tasks: usize,
    pub tasks_by_room: BTreeMap<String, usize>,
    /// Object count -> tasks with that many objects.
    pub tasks_by_objects: BTreeMap<String, usize>,
    pub obstacles_per_scene: Option<Summary>,
    pub initial_radius_m: Option<Summary>,
    pub goal_radius_m: Option<Summary>,
    pub carry_distance_m: Option<Summary>,
    pub centroid_shift_m: Option<Summary>,
    pub objects_starting_on_surfaces: usize,
    pub goals_on_surfaces: usize,
    pub goals_on_floor: usize,
    pub distinct_object_choices: usize,
    pub distinct_instructions: usize,
}

#[derive(Serialize, Clone, Debug)]
pub struct InstructionOverlap {
    pub train_vocabulary: usize,
    pub unseen_vocabulary: usize,
    pub shared_words: usize,
    /// Fraction of the unseen vocabulary that also occurs in train instructions.
    pub unseen_words_in_train: f64,
    /// Unseen instructions that occur verbatim in train (0 by construction).
    pub unseen_instructions_in_train: usize,
    pub unseen_only_words: Vec<String>,
}

#[derive(Serialize, Clone, Debug)]
pub struct Stats {
    pub splits: BTreeMap<String, SplitStats>,
    pub room_types: usize,
    pub object_types: usize,
    pub movable_object_types: usize,
    pub static_object_types: usize,
    pub support_object_types: usize,
    /// Over every task of every split.
    pub obstacles_per_scene: Summary,
    pub instructions: InstructionOverlap,
    pub unseen_object_choices_in_train: usize,
    pub unseen_layouts_in_train: usize,
}

fn words(s: &str) -> impl Iterator<Item = String> + '_ {
    s.split(|c: char| !c.is_alphanumeric())
        .filter(|w| !w.is_empty())
        .map(str::to_lowercase)
}

pub fn compute(b: &Benchmark) -> Stats {
    let mut splits = BTreeMap::new();
    let mut all_obstacles = Vec::new();
    for split in Split::ALL {
        let tasks = b.tasks(split);
        let mut by_room = BTreeMap::new();
        let mut by_objects = BTreeMap::new();
        let (mut obst, mut init_r, mut goal_r, mut carry, mut shift) =
            (vec![], vec![], vec![], vec![], vec![]);
        let (mut start_surf, mut goal_surf, mut goal_floor) = (0, 0, 0);
        let mut choices = HashSet::new();
        let mut instructions = HashSet::new();
        for t in tasks {
            *by_room.entry(t.room.to_string()).or_insert(0) += 1;
            *by_objects.entry(t.objects.len().to_string()).or_insert(0) += 1;
            obst.push(t.obstacles.len() as f64);
            shift.push(dist(t.centroid, [0.0, 0.0]));
            choices.insert(object_choice(t));
            for o in &t.objects {
                init_r.push(dist([o.pos[0], o.pos[1]], t.centroid));
                start_surf += usize::from(o.on != Support::Floor);
            }
            for s in &t.sequence {
                goal_r.push(dist([s.goal[0], s.goal[1]], t.centroid));
                if let Some(o) = t.object(&s.object) {
                    carry.push(dist([s.goal[0], s.goal[1]], [o.pos[0], o.pos[1]]));
                }
                if s.on == Support::Floor {
                    goal_floor += 1;
                } else {
                    goal_surf += 1;
                }
                instructions.insert(s.instruction.clone());
            }
        }
        all_obstacles.extend(obst.iter().copied());
        splits.insert(
            split.to_string(),
            SplitStats {
                tasks: tasks.len(),
                tasks_by_room: by_room,
                tasks_by_objects: by_objects,
                obstacles_per_scene: Summary::of(&obst),
                initial_radius_m: Summary::of(&init_r),
                goal_radius_m: Summary::of(&goal_r),
                carry_distance_m: Summary::of(&carry),
                centroid_shift_m: Summary::of(&shift),
                objects_starting_on_surfaces: start_surf,
                goals_on_surfaces: goal_surf,
                goals_on_floor: goal_floor,
                distinct_object_choices: choices.len(),
                distinct_instructions: instructions.len(),
            },
        );
    }
    let vocab = |split: Split| -> BTreeSet<String> {
        b.tasks(split)
            .iter()
            .flat_map(|t| {
                t.sequence
                    .iter()
                    .flat_map(|s| words(&s.instruction).collect::<Vec<_>>())
            })
            .collect()
    };
    let (train_v, unseen_v) = (vocab(Split::Train), vocab(Split::Unseen));
    let shared = train_v.intersection(&unseen_v).count();
    let train_instr: HashSet<&str> = b
        .tasks(Split::Train)
        .iter()
        .flat_map(|t| t.sequence.iter().map(|s| s.instruction.as_str()))
        .collect();
    let train_layouts: HashSet<_> = b.tasks(Split::Train).iter().map(layout_signature).collect();
    let train_choices: HashSet<_> = b.tasks(Split::Train).iter().map(object_choice).collect();
    let unseen = b.tasks(Split::Unseen);
    let cat = &b.catalogue;
    Stats {
        splits,
        room_types: cat.rooms.len(),
        object_types: cat.objects.len(),
        movable_object_types: cat.movable().count(),
        static_object_types: cat.statics().count(),
        support_object_types: cat.statics().filter(|t| t.support).count(),
        obstacles_per_scene: Summary::of(&all_obstacles).unwrap_or(Summary {
            min: 0.0,
            median: 0.0,
            max: 0.0,
            mean: 0.0,
        }),
        instructions: InstructionOverlap {
            train_vocabulary: train_v.len(),
            unseen_vocabulary: unseen_v.len(),
            shared_words: shared,
            unseen_words_in_train: if unseen_v.is_empty() {
                0.0
            } else {
                (shared as f64 / unseen_v.len() as f64 * 1000.0).round() / 1000.0
            },
            unseen_instructions_in_train: unseen
                .iter()
                .flat_map(|t| &t.sequence)
                .filter(|s| train_instr.contains(s.instruction.as_str()))
                .count(),
            unseen_only_words: unseen_v.difference(&train_v).cloned().collect(),
        },
        unseen_object_choices_in_train: unseen
            .iter()
            .filter(|t| train_choices.contains(&object_choice(t)))
            .count(),
        unseen_layouts_in_train: unseen
            .iter()
            .filter(|t| train_layouts.contains(&layout_signature(t)))
            .count(),
    }
}

fn fmt_summary(s: &Option<Summary>) -> String {
    s.as_ref().map_or_else(
        || "-".into(),
        |s| format!("{} / {} / {}", s.min, s.median, s.max),
    )
}

/// The human-readable report.
pub fn to_text(s: &Stats) -> String {
    let mut out = String::new();
    out += &format!(
        "object types: {} ({} movable targets, {} static, {} support surfaces); room types: {}\n",
        s.object_types,
        s.movable_object_types,
        s.static_object_types,
        s.support_object_types,
        s.room_types
    );
    out += &format!(
        "obstacles per scene (all splits) min/median/max: {} / {} / {}\n\n",
        s.obstacles_per_scene.min, s.obstacles_per_scene.median, s.obstacles_per_scene.max
    );
    for (name, sp) in &s.splits {
        out += &format!("[{name}] {} tasks\n", sp.tasks);
        let rooms: Vec<String> = sp
            .tasks_by_room
            .iter()
            .map(|(r, n)| format!("{r} {n}"))
            .collect();
        out += &format!("  per room type: {}\n", rooms.join(", "));
        let objs: Vec<String> = sp
            .tasks_by_objects
            .iter()
            .map(|(k, n)| format!("{k} objects: {n}"))
            .collect();
        out += &format!("  tasks by object count: {}\n", objs.join(", "));
        out += &format!(
            "  obstacles per scene min/median/max: {}\n",
            fmt_summary(&sp.obstacles_per_scene)
        );
        out += &format!(
            "  initial radius (m) min/median/max:  {}\n",
            fmt_summary(&sp.initial_radius_m)
        );
        out += &format!(
            "  goal radius (m) min/median/max:     {}\n",
            fmt_summary(&sp.goal_radius_m)
        );
        out += &format!(
            "  carry distance (m) min/median/max:  {}\n",
            fmt_summary(&sp.carry_distance_m)
        );
        out += &format!(
            "  centroid shift (m) min/median/max:  {}\n",
            fmt_summary(&sp.centroid_shift_m)
        );
        out += &format!(
            "  objects starting on surfaces: {}; goals on surfaces/floor: {}/{}; distinct object choices: {}; distinct instructions: {}\n\n",
            sp.objects_starting_on_surfaces, sp.goals_on_surfaces, sp.goals_on_floor, sp.distinct_object_choices, sp.distinct_instructions
        );
    }
    let i = &s.instructions;
    out += &format!(
        "instructions: train vocabulary {}, unseen vocabulary {}, shared {} ({:.1}% of unseen words occur in train); unseen instructions found verbatim in train: {}\n",
        i.train_vocabulary, i.unseen_vocabulary, i.shared_words, i.unseen_words_in_train * 100.0, i.unseen_instructions_in_train
    );
    out += &format!(
        "unseen tasks whose object choice occurs in train: {}; whose layout occurs in train: {}\n",
        s.unseen_object_choices_in_train, s.unseen_layouts_in_train
    );
    out
}
