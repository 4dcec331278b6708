//! The benchmark's rules, checked on loaded tasks: geometry (inside the room, no overlaps, objects
//! and goals in free space or on a surface), the radii and counts of the paper's benchmark,
//! reachability in sequence, and the unseen split's separation from train.

use crate::catalogue::Catalogue;
use crate::geometry::{dist, room_rect, Rect};
use crate::load::Benchmark;
use crate::model::{Split, Support, Task};
use crate::routes::{footprint, obstacle_rect, plan_task, Clearance};
use std::collections::{BTreeSet, HashSet};
use std::fmt;

/// Initial and goal positions lie within this radius of the task's centroid (paper Sec. 4.1).
pub const MAX_RADIUS: f64 = 1.5;
/// Unseen scene-centroid shifts are at most this far from the room centre.
pub const MAX_CENTROID_SHIFT: f64 = 0.5;
/// Static obstacles per scene.
pub const OBSTACLES_PER_SCENE: [usize; 2] = [4, 10];
/// An object resting on a surface keeps this margin from the surface's edges.
pub const SURFACE_MARGIN: f64 = 0.02;
/// Tolerance for heights computed from rounded file values.
const Z_TOL: f64 = 2e-3;

#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    pub task: String,
    pub reason: String,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "task {}: {}", self.task, self.reason)
    }
}

/// Objects per task for a split: two for train and unseen, 3..=5 for the extension.
pub fn objects_per_task(split: Split) -> [usize; 2] {
    match split {
        Split::Train | Split::Unseen => [2, 2],
        Split::Extension => [3, 5],
    }
}

/// Every problem of one task (empty when valid).
pub fn validate_task(task: &Task, split: Split, cat: &Catalogue, c: &Clearance) -> Vec<String> {
    let mut p = Vec::new();
    let spec = cat.room(task.room);
    let in_range = |v: f64, r: [f64; 2]| v >= r[0] - 1e-6 && v <= r[1] + 1e-6;
    if !in_range(task.room_size[0], spec.width) || !in_range(task.room_size[1], spec.depth) {
        p.push(format!(
            "room_size {:?} outside the {} range {:?} x {:?}",
            task.room_size, task.room, spec.width, spec.depth
        ));
    }
    let n_obs = task.obstacles.len();
    let [lo, hi] = spec.obstacles;
    if n_obs < OBSTACLES_PER_SCENE[0].max(lo as usize)
        || n_obs > OBSTACLES_PER_SCENE[1].min(hi as usize)
    {
        p.push(format!(
            "{n_obs} obstacles, a {} has {lo}..={hi}",
            task.room
        ));
    }
    let [min_obj, max_obj] = objects_per_task(split);
    if task.objects.len() < min_obj || task.objects.len() > max_obj {
        p.push(format!(
            "{} objects, the {split} split has {min_obj}..={max_obj}",
            task.objects.len()
        ));
    }
    if dist(task.centroid, [0.0, 0.0]) > MAX_CENTROID_SHIFT + 1e-6 {
        p.push(format!(
            "centroid {:?} shifted more than {MAX_CENTROID_SHIFT} m",
            task.centroid
        ));
    }
    let room = room_rect(task.room_size);
    let obstacles: Vec<Rect> = task.obstacles.iter().map(obstacle_rect).collect();
    for (i, r) in obstacles.iter().enumerate() {
        let id = &task.obstacles[i].id;
        if !room.contains_rect(r, 0.0) {
            p.push(format!("obstacle {id} sticks out of the room"));
        }
        for (j, s) in obstacles.iter().enumerate().skip(i + 1) {
            if r.overlaps(s, 0.0) {
                p.push(format!(
                    "obstacles {id} and {} overlap",
                    task.obstacles[j].id
                ));
            }
        }
    }
    // Resting checks shared by initial poses and goals: returns the problem, if any.
    let rests =
        |what: &str, pos: [f64; 3], yaw: f64, size: [f64; 3], on: &Support| -> Option<String> {
            let fp = footprint(pos, yaw, size);
            match on {
                Support::Floor => {
                    if (pos[2] - size[2] / 2.0).abs() > Z_TOL {
                        return Some(format!(
                            "{what} is on the floor but its centre is at z={}",
                            pos[2]
                        ));
                    }
                    if !room.contains_rect(&fp, 0.0) {
                        return Some(format!("{what} sticks out of the room"));
                    }
                    if let Some(k) = obstacles.iter().position(|o| o.overlaps(&fp, 0.0)) {
                        return Some(format!("{what} overlaps obstacle {}", task.obstacles[k].id));
                    }
                }
                Support::Surface(id) => {
                    let o = task.obstacle(id)?; // the loader guarantees the reference
                    let top = obstacle_rect(o);
                    if !top.contains_rect(&fp, SURFACE_MARGIN) {
                        return Some(format!("{what} does not fit on {id} ({})", o.kind));
                    }
                    if (pos[2] - (o.size[2] + size[2] / 2.0)).abs() > Z_TOL {
                        return Some(format!(
                            "{what} is not resting on top of {id} (z={})",
                            pos[2]
                        ));
                    }
                }
            }
            if dist([pos[0], pos[1]], task.centroid) > MAX_RADIUS + 1e-6 {
                return Some(format!(
                    "{what} is more than {MAX_RADIUS} m from the centroid"
                ));
            }
            None
        };
    for o in &task.objects {
        p.extend(rests(
            &format!("object {}", o.id),
            o.pos,
            o.yaw,
            o.size,
            &o.on,
        ));
    }
    for (i, a) in task.objects.iter().enumerate() {
        for b in &task.objects[i + 1..] {
            if footprint(a.pos, a.yaw, a.size).overlaps(&footprint(b.pos, b.yaw, b.size), 0.0)
                && a.on == b.on
            {
                p.push(format!("objects {} and {} overlap", a.id, b.id));
            }
        }
    }
    // Goals must be free at the time of their step: objects still to move are at their initial
    // poses, objects already moved are at their goals.
    let mut placed: Vec<(String, Rect, Support)> = Vec::new();
    for (k, s) in task.sequence.iter().enumerate() {
        let Some(obj) = task.object(&s.object) else {
            continue;
        };
        let what = format!("goal of step {k} ({})", obj.id);
        p.extend(rests(&what, s.goal, s.goal_yaw, obj.size, &s.on));
        let g = footprint(s.goal, s.goal_yaw, obj.size);
        let waiting = task.sequence[k + 1..]
            .iter()
            .filter_map(|w| task.object(&w.object));
        for w in waiting {
            if w.on == s.on && footprint(w.pos, w.yaw, w.size).overlaps(&g, 0.0) {
                p.push(format!(
                    "{what} is occupied by object {} waiting there",
                    w.id
                ));
            }
        }
        for (id, r, on) in &placed {
            if *on == s.on && r.overlaps(&g, 0.0) {
                p.push(format!("{what} overlaps object {id} placed before it"));
            }
        }
        placed.push((obj.id.clone(), g, s.on.clone()));
        let display = cat
            .get(&obj.kind)
            .map_or(obj.kind.as_str(), |t| t.display.as_str());
        if !s
            .instruction
            .to_lowercase()
            .contains(&display.to_lowercase())
        {
            p.push(format!(
                "instruction of step {k} does not name the {display}"
            ));
        }
    }
    if p.is_empty() {
        if let Err(e) = plan_task(task, c) {
            p.push(format!("unreachable: {e}"));
        }
    }
    p
}

/// Ordered object kinds of a task, e.g. ["laptop", "pot"].
pub fn object_choice(task: &Task) -> Vec<String> {
    task.sequence
        .iter()
        .filter_map(|s| task.object(&s.object).map(|o| o.kind.clone()))
        .collect()
}

/// A layout's identity: room type and the multiset of its furniture.
pub fn layout_signature(task: &Task) -> (String, Vec<String>) {
    let mut kinds: Vec<String> = task.obstacles.iter().map(|o| o.kind.clone()).collect();
    kinds.sort();
    (task.room.to_string(), kinds)
}

/// Problems across splits: unique ids, and unseen tasks whose layout, object choice or an
/// instruction also occurs in train.
pub fn validate_cross_split(b: &Benchmark) -> Vec<Problem> {
    let mut p = Vec::new();
    let mut ids = HashSet::new();
    for (split, t) in b.all_tasks() {
        if !ids.insert(t.id.as_str()) {
            p.push(Problem {
                task: t.id.clone(),
                reason: format!("id repeated (in {split})"),
            });
        }
    }
    let train = b.tasks(Split::Train);
    let layouts: HashSet<_> = train.iter().map(layout_signature).collect();
    let choices: HashSet<_> = train.iter().map(object_choice).collect();
    let instructions: BTreeSet<&str> = train
        .iter()
        .flat_map(|t| t.sequence.iter().map(|s| s.instruction.as_str()))
        .collect();
    for t in b.tasks(Split::Unseen) {
        let mut bad = |reason: String| {
            p.push(Problem {
                task: t.id.clone(),
                reason,
            })
        };
        if layouts.contains(&layout_signature(t)) {
            bad("its layout (room type and furniture) also occurs in train".into());
        }
        if choices.contains(&object_choice(t)) {
            bad(format!(
                "its object choice {:?} also occurs in train",
                object_choice(t)
            ));
        }
        for s in &t.sequence {
            if instructions.contains(s.instruction.as_str()) {
                bad(format!(
                    "instruction {:?} also occurs in train",
                    s.instruction
                ));
            }
        }
    }
    p
}

/// Validates the given splits (all when `only` is None) plus the cross-split rules.
pub fn validate_benchmark(b: &Benchmark, only: Option<Split>, c: &Clearance) -> Vec<Problem> {
    let mut problems = Vec::new();
    for (split, task) in b.all_tasks() {
        if only.is_some_and(|s| s != split) {
            continue;
        }
        for reason in validate_task(task, split, &b.catalogue, c) {
            problems.push(Problem {
                task: task.id.clone(),
                reason,
            });
        }
    }
    problems.extend(validate_cross_split(b));
    problems
}
