//! Deterministic generation of the benchmark from the catalogue: `lhm scenes generate`.
//!
//! Each task is drawn by rejection sampling from its own random stream (seed, split, index,
//! attempt), rounded to millimetres, and kept only if the validator accepts it, so every generated
//! file validates by construction. Unseen tasks are also rejected when their layout, object choice
//! or an instruction occurs in train.

use crate::catalogue::Catalogue;
use crate::geometry::{dist, room_rect, Rect};
use crate::language::{describe_goal, instruction, Phrasing};
use crate::model::{
    MovableObject, ObjectType, Obstacle, Placement, PlacementStep, RoomType, Split, SplitFile,
    StartPose, Support, Task, Wall, TASK_FILE_SCHEMA,
};
use crate::rng::{hash_str, SplitMix64};
use crate::routes::{footprint, obstacle_rect, Clearance};
use crate::validate::{layout_signature, object_choice, validate_task, MAX_RADIUS};
use std::collections::HashSet;
use std::f64::consts::{FRAC_PI_2, PI};

#[derive(Clone, Debug)]
pub struct GenerateConfig {
    pub seed: u64,
    pub train: usize,
    pub unseen: usize,
    /// Extension tasks per sequence length (spread over the four room types).
    pub extension_per_length: usize,
    pub extension_lengths: Vec<usize>,
    pub max_attempts: u32,
}

impl Default for GenerateConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            train: 350,
            unseen: 66,
            extension_per_length: 24,
            extension_lengths: vec![3, 4, 5],
            max_attempts: 5000,
        }
    }
}

#[derive(Debug, thiserror::Error)]
#[error("could not generate {split} task #{index} in {attempts} attempts (last rejection: {last})")]
pub struct GenerateError {
    pub split: Split,
    pub index: usize,
    pub attempts: u32,
    pub last: String,
}

/// Generates all three splits. `progress(split, done, total)` is called after each task.
pub fn generate(
    cat: &Catalogue,
    cfg: &GenerateConfig,
    mut progress: impl FnMut(Split, usize, usize),
) -> Result<Vec<SplitFile>, GenerateError> {
    let clearance = Clearance::default();
    let mut out = Vec::new();
    let mut train_layouts = HashSet::new();
    let mut train_choices = HashSet::new();
    let mut train_instructions = HashSet::new();
    for split in Split::ALL {
        let jobs: Vec<(String, RoomType, usize)> = match split {
            Split::Train => (0..cfg.train)
                .map(|i| (format!("train-{:04}", i + 1), RoomType::ALL[i % 4], 2))
                .collect(),
            Split::Unseen => (0..cfg.unseen)
                .map(|i| (format!("unseen-{:03}", i + 1), RoomType::ALL[i % 4], 2))
                .collect(),
            Split::Extension => cfg
                .extension_lengths
                .iter()
                .flat_map(|&n| {
                    (0..cfg.extension_per_length).map(move |i| {
                        (
                            format!("extension-{n}obj-{:02}", i + 1),
                            RoomType::ALL[i % 4],
                            n,
                        )
                    })
                })
                .collect(),
        };
        let mut tasks = Vec::with_capacity(jobs.len());
        for (index, (id, room, n_objects)) in jobs.iter().enumerate() {
            let mut last = String::from("none");
            let mut found = None;
            for attempt in 0..cfg.max_attempts {
                let rng = SplitMix64::from_parts(&[
                    cfg.seed,
                    hash_str(split.as_str()),
                    index as u64,
                    u64::from(attempt),
                ]);
                let mut s = Sampler { cat, rng, split };
                let Some(task) = s.task(id, *room, *n_objects) else {
                    last = "sampling failed".into();
                    continue;
                };
                if let Some(p) = validate_task(&task, split, cat, &clearance)
                    .into_iter()
                    .next()
                {
                    last = p;
                    continue;
                }
                if split == Split::Unseen {
                    if train_layouts.contains(&layout_signature(&task)) {
                        last = "layout occurs in train".into();
                        continue;
                    }
                    if train_choices.contains(&object_choice(&task)) {
                        last = "object choice occurs in train".into();
                        continue;
                    }
                    if task
                        .sequence
                        .iter()
                        .any(|st| train_instructions.contains(&st.instruction))
                    {
                        last = "instruction occurs in train".into();
                        continue;
                    }
                }
                found = Some(task);
                break;
            }
            let task = found.ok_or(GenerateError {
                split,
                index,
                attempts: cfg.max_attempts,
                last,
            })?;
            if split == Split::Train {
                train_layouts.insert(layout_signature(&task));
                train_choices.insert(object_choice(&task));
                train_instructions.extend(task.sequence.iter().map(|s| s.instruction.clone()));
            }
            tasks.push(task);
            progress(split, tasks.len(), jobs.len());
        }
        out.push(SplitFile {
            schema: TASK_FILE_SCHEMA,
            split,
            tasks,
        });
    }
    Ok(out)
}

/// Renders a split file as the committed TOML, with a header saying where it comes from.
pub fn to_toml(file: &SplitFile) -> Result<String, toml::ser::Error> {
    let body = toml::to_string(file)?;
    Ok(format!(
        "# LHM benchmark, {} split: {} tasks. Generated by `lhm scenes generate` from catalogue.toml;\n\
         # regenerate rather than edit by hand (`lhm scenes validate` checks hand edits).\n\
         # Metres, z up, room floor centred on the origin; yaw in radians about +z.\n\n{body}",
        file.split,
        file.tasks.len()
    ))
}

fn mm(x: f64) -> f64 {
    let r = (x * 1000.0).round() / 1000.0;
    if r == 0.0 {
        0.0
    } else {
        r
    }
}

fn wrap_angle(a: f64) -> f64 {
    let mut a = a % (2.0 * PI);
    if a > PI {
        a -= 2.0 * PI;
    } else if a <= -PI {
        a += 2.0 * PI;
    }
    a
}

struct Sampler<'a> {
    cat: &'a Catalogue,
    rng: SplitMix64,
    split: Split,
}

/// A sampled resting pose: position of the root, yaw, and support.
type Pose = ([f64; 3], f64, Support);

impl Sampler<'_> {
    fn task(&mut self, id: &str, room: RoomType, n_objects: usize) -> Option<Task> {
        let spec = self.cat.room(room).clone();
        let w = (self.rng.range(spec.width[0], spec.width[1]) * 10.0).round() / 10.0;
        let d = (self.rng.range(spec.depth[0], spec.depth[1]) * 10.0).round() / 10.0;
        let centroid = match self.split {
            Split::Unseen => {
                let a = self.rng.range(-PI, PI);
                let r = self.rng.range(0.2, 0.495);
                [mm(r * a.cos()), mm(r * a.sin())]
            }
            Split::Train | Split::Extension => [0.0, 0.0],
        };
        let mut task = Task {
            id: id.to_string(),
            room,
            room_size: [w, d],
            centroid,
            window_wall: *self.rng.pick(&Wall::ALL),
            start: StartPose {
                pos: [0.0, 0.0],
                yaw: 0.0,
            },
            obstacles: Vec::new(),
            objects: Vec::new(),
            sequence: Vec::new(),
        };
        let n_obs = self.rng.int_inclusive(spec.obstacles[0], spec.obstacles[1]) as usize;
        self.furnish(&mut task, n_obs)?;
        self.place_objects(&mut task, n_objects)?;
        self.place_start(&mut task)?;
        self.describe(&mut task);
        Some(task)
    }

    fn furnish(&mut self, task: &mut Task, n: usize) -> Option<()> {
        let pool: Vec<&ObjectType> = self
            .cat
            .statics()
            .filter(|t| t.rooms.contains(&task.room))
            .collect();
        let mut kinds: Vec<&ObjectType> = Vec::new();
        while kinds.len() < n {
            let t = *self.rng.pick(&pool);
            // Rooms have one piano, one bed, one wardrobe; small pieces (chairs, drums, side
            // tables) may come in pairs.
            let same = kinds.iter().filter(|k| k.name == t.name).count();
            let small = t.size[0] * t.size[1] < 0.5;
            let beds = kinds.iter().filter(|k| k.category == "bed").count();
            if same >= if small { 2 } else { 1 } || (t.category == "bed" && beds > 0) {
                continue;
            }
            kinds.push(t);
        }
        // Big pieces first: they are the hardest to fit.
        kinds.sort_by(|a, b| (b.size[0] * b.size[1]).total_cmp(&(a.size[0] * a.size[1])));
        let room = room_rect(task.room_size);
        let (hw, hd) = (task.room_size[0] / 2.0, task.room_size[1] / 2.0);
        let free_radius = if task.room == RoomType::Warehouse {
            3.8
        } else {
            hw.min(hd) - 0.3
        };
        for (i, t) in kinds.into_iter().enumerate() {
            let [l, dep, _] = t.size;
            let mut placed = None;
            for _ in 0..60 {
                let (pos, yaw) = match t.placement {
                    Some(Placement::Wall) => {
                        let wall = *self.rng.pick(&Wall::ALL);
                        let along = match wall {
                            Wall::North | Wall::South => hw - l / 2.0 - 0.02,
                            Wall::East | Wall::West => hd - l / 2.0 - 0.02,
                        };
                        if along <= 0.0 {
                            continue;
                        }
                        let u = self.rng.range(-along, along);
                        match wall {
                            Wall::North => ([u, hd - dep / 2.0 - 0.02], PI),
                            Wall::South => ([u, -hd + dep / 2.0 + 0.02], 0.0),
                            Wall::East => ([hw - dep / 2.0 - 0.02, u], FRAC_PI_2),
                            Wall::West => ([-hw + dep / 2.0 + 0.02, u], -FRAC_PI_2),
                        }
                    }
                    _ => {
                        let a = self.rng.range(-PI, PI);
                        let r = free_radius * self.rng.unit().sqrt();
                        let jitter = if self.rng.chance(0.5) {
                            self.rng.range(-0.35, 0.35)
                        } else {
                            0.0
                        };
                        let yaw = self.rng.index(4) as f64 * FRAC_PI_2 + jitter;
                        (
                            [
                                task.centroid[0] + r * a.cos(),
                                task.centroid[1] + r * a.sin(),
                            ],
                            wrap_angle(yaw),
                        )
                    }
                };
                let pos = [mm(pos[0]), mm(pos[1])];
                let yaw = mm(yaw);
                let rect = Rect::new(pos, [l, dep], yaw);
                if !room.contains_rect(&rect, 0.01) {
                    continue;
                }
                if task
                    .obstacles
                    .iter()
                    .any(|o| obstacle_rect(o).overlaps(&rect, 0.1))
                {
                    continue;
                }
                placed = Some((pos, yaw));
                break;
            }
            let (pos, yaw) = placed?;
            task.obstacles.push(Obstacle {
                id: format!("o{i}"),
                kind: t.name.clone(),
                pos,
                yaw,
                size: t.size,
            });
        }
        Some(())
    }

    /// Support surfaces whose top comes within the object radius of the centroid.
    fn surfaces(&self, task: &Task) -> Vec<String> {
        task.obstacles
            .iter()
            .filter(|o| self.cat.get(&o.kind).is_some_and(|t| t.support))
            .filter(|o| obstacle_rect(o).distance(task.centroid) < MAX_RADIUS - 0.1)
            .map(|o| o.id.clone())
            .collect()
    }

    /// A resting pose for `t` that avoids `occupied` footprints (with their supports).
    fn rest_pose(
        &mut self,
        task: &Task,
        t: &ObjectType,
        occupied: &[(Rect, Support)],
        on_surface_p: f64,
    ) -> Option<Pose> {
        let surfaces = self.surfaces(task);
        let room = room_rect(task.room_size);
        for _ in 0..80 {
            let (pos, yaw, on) =
                if t.on_surface && !surfaces.is_empty() && self.rng.chance(on_surface_p) {
                    let sid = self.rng.pick(&surfaces).clone();
                    let o = task.obstacle(&sid)?;
                    let top = obstacle_rect(o);
                    let quarter = self.rng.index(4);
                    let yaw = wrap_angle(o.yaw + quarter as f64 * FRAC_PI_2);
                    let (ol, ow) = if quarter % 2 == 0 {
                        (t.size[0], t.size[1])
                    } else {
                        (t.size[1], t.size[0])
                    };
                    let ax = top.half[0] - ol / 2.0 - 0.03;
                    let ay = top.half[1] - ow / 2.0 - 0.03;
                    if ax < 0.0 || ay < 0.0 {
                        continue;
                    }
                    // Toward the front edge (+y, away from the wall for wall furniture) so a person
                    // standing there can reach it.
                    let ly = ay * self.rng.range(0.3, 1.0);
                    let p = top.to_world([self.rng.range(-ax, ax), ly]);
                    (
                        [p[0], p[1], o.size[2] + t.size[2] / 2.0],
                        yaw,
                        Support::Surface(sid),
                    )
                } else {
                    let a = self.rng.range(-PI, PI);
                    let r = (MAX_RADIUS - 0.02) * self.rng.unit().sqrt();
                    let p = [
                        task.centroid[0] + r * a.cos(),
                        task.centroid[1] + r * a.sin(),
                    ];
                    (
                        [p[0], p[1], t.size[2] / 2.0],
                        self.rng.range(-PI, PI),
                        Support::Floor,
                    )
                };
            let pos = [mm(pos[0]), mm(pos[1]), mm(pos[2])];
            let yaw = mm(yaw);
            let fp = footprint(pos, yaw, t.size);
            if dist([pos[0], pos[1]], task.centroid) > MAX_RADIUS - 0.01 {
                continue;
            }
            if on == Support::Floor
                && (!room.contains_rect(&fp, 0.05)
                    || task
                        .obstacles
                        .iter()
                        .any(|o| obstacle_rect(o).overlaps(&fp, 0.15)))
            {
                continue;
            }
            if occupied
                .iter()
                .any(|(r, s)| *s == on && r.overlaps(&fp, 0.2))
            {
                continue;
            }
            return Some((pos, yaw, on));
        }
        None
    }

    fn place_objects(&mut self, task: &mut Task, n: usize) -> Option<()> {
        let mut pool: Vec<&ObjectType> = self
            .cat
            .movable()
            .filter(|t| t.rooms.contains(&task.room))
            .collect();
        if pool.len() < n {
            return None;
        }
        self.rng.shuffle(&mut pool);
        let kinds: Vec<&ObjectType> = pool.into_iter().take(n).collect();
        let mut occupied: Vec<(Rect, Support)> = Vec::new();
        for (i, t) in kinds.iter().enumerate() {
            let (pos, yaw, on) = self.rest_pose(task, t, &occupied, 0.35)?;
            occupied.push((footprint(pos, yaw, t.size), on.clone()));
            task.objects.push(MovableObject {
                id: format!("m{i}"),
                kind: t.name.clone(),
                pos,
                yaw,
                size: t.size,
                mass: t.mass,
                on,
            });
        }
        // Goals in sequence: object k's goal avoids objects still waiting and goals already used.
        for (k, t) in kinds.iter().enumerate() {
            let waiting: Vec<(Rect, Support)> = task.objects[k + 1..]
                .iter()
                .map(|o| (footprint(o.pos, o.yaw, o.size), o.on.clone()))
                .collect();
            let mut avoid = waiting;
            for s in &task.sequence {
                let o = task.object(&s.object)?;
                avoid.push((footprint(s.goal, s.goal_yaw, o.size), s.on.clone()));
            }
            let start = task.objects[k].pos;
            let mut goal = None;
            for _ in 0..20 {
                let g = self.rest_pose(task, t, &avoid, 0.5)?;
                if dist([g.0[0], g.0[1]], [start[0], start[1]]) >= 1.0 {
                    goal = Some(g);
                    break;
                }
            }
            let (pos, yaw, on) = goal?;
            task.sequence.push(PlacementStep {
                object: task.objects[k].id.clone(),
                goal: pos,
                goal_yaw: yaw,
                on,
                instruction: String::new(),
            });
        }
        Some(())
    }

    fn place_start(&mut self, task: &mut Task) -> Option<()> {
        let (hw, hd) = (task.room_size[0] / 2.0 - 0.5, task.room_size[1] / 2.0 - 0.5);
        for _ in 0..100 {
            let p = [mm(self.rng.range(-hw, hw)), mm(self.rng.range(-hd, hd))];
            let r = dist(p, task.centroid);
            if !(1.0..=3.0).contains(&r) {
                continue;
            }
            if task
                .obstacles
                .iter()
                .any(|o| obstacle_rect(o).distance(p) < 0.4)
            {
                continue;
            }
            if task
                .objects
                .iter()
                .any(|o| footprint(o.pos, o.yaw, o.size).distance(p) < 0.6)
            {
                continue;
            }
            task.start = StartPose {
                pos: p,
                yaw: mm(self.rng.range(-PI, PI)),
            };
            return Some(());
        }
        None
    }

    fn describe(&mut self, task: &mut Task) {
        let phrasing = if self.split == Split::Unseen {
            Phrasing::Unseen
        } else {
            Phrasing::Train
        };
        for k in 0..task.sequence.len() {
            let step = &task.sequence[k];
            let display = task
                .object(&step.object)
                .and_then(|o| self.cat.get(&o.kind))
                .map_or_else(|| step.object.clone(), |t| t.display.clone());
            let goal = describe_goal(&mut self.rng, task, self.cat, step.goal, &step.on);
            task.sequence[k].instruction = instruction(&mut self.rng, phrasing, &display, &goal);
        }
    }
}
