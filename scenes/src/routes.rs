//! Reachability: does a person get from the start to each object and carry it to its goal, in
//! sequence? A grid planner (Dijkstra, 8-connected) over a clearance field of the room.
//!
//! Clearances model a person as a disc: walking needs `walk` metres to any obstacle, carrying an
//! object needs the larger of `carry_min` and half the object's larger horizontal side plus
//! `carry_margin` (the object is held in front of the body and sweeps that much). Picking up and
//! putting down happen from a spot within `reach` of the object's footprint with walking
//! clearance; within `step_back` of those spots the carrier may still be in a narrow place (in
//! front of a table, say), so only walking clearance is needed there.

use crate::geometry::{dist, Rect};
use crate::model::{Support, Task};
use std::cmp::Ordering;
use std::collections::BinaryHeap;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clearance {
    pub walk: f64,
    pub carry_min: f64,
    pub carry_margin: f64,
    pub reach: f64,
    pub step_back: f64,
    /// Grid cell size, metres.
    pub cell: f64,
}

impl Default for Clearance {
    fn default() -> Self {
        Self {
            walk: 0.25,
            carry_min: 0.30,
            carry_margin: 0.05,
            reach: 0.50,
            step_back: 0.50,
            cell: 0.05,
        }
    }
}

impl Clearance {
    pub fn carry(&self, object_size: [f64; 3]) -> f64 {
        self.carry_min
            .max(0.5 * object_size[0].max(object_size[1]) + self.carry_margin)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LegKind {
    /// Empty-handed, to the pick-up spot of an object.
    Walk,
    /// Holding the object, to the put-down spot of its goal.
    Carry,
}

#[derive(Clone, Debug)]
pub struct Leg {
    pub step: usize,
    pub kind: LegKind,
    /// Waypoints in metres, from the leg's start to its end.
    pub path: Vec<[f64; 2]>,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("step {step} ({object}): no {kind:?} route: {reason}")]
pub struct RouteError {
    pub step: usize,
    pub object: String,
    pub kind: LegKind,
    pub reason: String,
}

/// Distance from each cell centre to the nearest wall or blocker.
#[derive(Clone)]
struct ClearanceField {
    origin: [f64; 2],
    cell: f64,
    nx: usize,
    ny: usize,
    dist: Vec<f32>,
}

impl ClearanceField {
    fn new(room_size: [f64; 2], cell: f64) -> Self {
        let nx = (room_size[0] / cell).floor().max(1.0) as usize;
        let ny = (room_size[1] / cell).floor().max(1.0) as usize;
        let origin = [-room_size[0] / 2.0, -room_size[1] / 2.0];
        let mut f = Self {
            origin,
            cell,
            nx,
            ny,
            dist: vec![0.0; nx * ny],
        };
        let (hx, hy) = (room_size[0] / 2.0, room_size[1] / 2.0);
        for j in 0..ny {
            for i in 0..nx {
                let [x, y] = f.centre(i, j);
                f.dist[j * nx + i] = (hx - x.abs()).min(hy - y.abs()) as f32;
            }
        }
        f
    }

    fn centre(&self, i: usize, j: usize) -> [f64; 2] {
        [
            self.origin[0] + (i as f64 + 0.5) * self.cell,
            self.origin[1] + (j as f64 + 0.5) * self.cell,
        ]
    }

    fn cell_of(&self, p: [f64; 2]) -> Option<(usize, usize)> {
        let i = ((p[0] - self.origin[0]) / self.cell).floor();
        let j = ((p[1] - self.origin[1]) / self.cell).floor();
        (i >= 0.0 && j >= 0.0 && (i as usize) < self.nx && (j as usize) < self.ny)
            .then_some((i as usize, j as usize))
    }

    fn block(&mut self, r: &Rect) {
        // Only cells near the rectangle can get closer than the wall distance they already hold.
        let reach = r.half[0].hypot(r.half[1]) + 1.0;
        let (i0, j0) = self.cell_of_clamped([r.centre[0] - reach, r.centre[1] - reach]);
        let (i1, j1) = self.cell_of_clamped([r.centre[0] + reach, r.centre[1] + reach]);
        for j in j0..=j1 {
            for i in i0..=i1 {
                let d = r.distance(self.centre(i, j)) as f32;
                let slot = &mut self.dist[j * self.nx + i];
                *slot = slot.min(d);
            }
        }
        // Cells further out are at least 1 m from the rectangle; every clearance queried is well
        // under 1 m, so leaving them at their previous value changes no answer.
    }

    fn cell_of_clamped(&self, p: [f64; 2]) -> (usize, usize) {
        let i = ((p[0] - self.origin[0]) / self.cell)
            .floor()
            .clamp(0.0, (self.nx - 1) as f64);
        let j = ((p[1] - self.origin[1]) / self.cell)
            .floor()
            .clamp(0.0, (self.ny - 1) as f64);
        (i as usize, j as usize)
    }

    /// Shortest path from `start` through `passable` cells to any cell satisfying `target`;
    /// both predicates get the cell centre and its clearance.
    fn plan(
        &self,
        start: [f64; 2],
        passable: impl Fn([f64; 2], f64) -> bool,
        target: impl Fn([f64; 2], f64) -> bool,
    ) -> Result<Vec<[f64; 2]>, String> {
        let (si, sj) = self
            .cell_of(start)
            .ok_or_else(|| format!("start {start:?} is outside the room"))?;
        let start_idx = sj * self.nx + si;
        if !passable(self.centre(si, sj), f64::from(self.dist[start_idx])) {
            return Err(format!(
                "start ({:.2}, {:.2}) is blocked ({:.2} m clearance)",
                start[0], start[1], self.dist[start_idx]
            ));
        }
        let mut cost = vec![f64::INFINITY; self.nx * self.ny];
        let mut prev = vec![usize::MAX; self.nx * self.ny];
        let mut heap = BinaryHeap::new();
        cost[start_idx] = 0.0;
        heap.push(Node {
            cost: 0.0,
            idx: start_idx,
        });
        const STEPS: [(i64, i64, f64); 8] = [
            (1, 0, 1.0),
            (-1, 0, 1.0),
            (0, 1, 1.0),
            (0, -1, 1.0),
            (1, 1, std::f64::consts::SQRT_2),
            (1, -1, std::f64::consts::SQRT_2),
            (-1, 1, std::f64::consts::SQRT_2),
            (-1, -1, std::f64::consts::SQRT_2),
        ];
        while let Some(Node { cost: c, idx }) = heap.pop() {
            if c > cost[idx] {
                continue;
            }
            let (i, j) = (idx % self.nx, idx / self.nx);
            if target(self.centre(i, j), f64::from(self.dist[idx])) {
                let mut path = vec![self.centre(i, j)];
                let mut k = idx;
                while prev[k] != usize::MAX {
                    k = prev[k];
                    path.push(self.centre(k % self.nx, k / self.nx));
                }
                path.reverse();
                path[0] = start;
                return Ok(simplify(path));
            }
            for (di, dj, w) in STEPS {
                let (ni, nj) = (i as i64 + di, j as i64 + dj);
                if ni < 0 || nj < 0 || ni >= self.nx as i64 || nj >= self.ny as i64 {
                    continue;
                }
                let n = nj as usize * self.nx + ni as usize;
                if !passable(
                    self.centre(ni as usize, nj as usize),
                    f64::from(self.dist[n]),
                ) {
                    continue;
                }
                let nc = c + w * self.cell;
                if nc < cost[n] {
                    cost[n] = nc;
                    prev[n] = idx;
                    heap.push(Node { cost: nc, idx: n });
                }
            }
        }
        Err("no path with enough clearance".into())
    }
}

impl ClearanceField {
    /// Whether every point of the segment `a`-`b` (sampled every half cell) has `clear` metres.
    fn clear_between(&self, a: [f64; 2], b: [f64; 2], clear: f64) -> bool {
        let n = (dist(a, b) / (self.cell / 2.0)).ceil().max(1.0) as usize;
        (0..=n).all(|k| {
            let t = k as f64 / n as f64;
            let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
            self.cell_of(p)
                .is_some_and(|(i, j)| f64::from(self.dist[j * self.nx + i]) >= clear)
        })
    }

    /// `path` pulled straight: from each kept waypoint, on to the farthest later one in sight
    /// with `clear` metres all the way — the grid's 45° zig-zags become the straight lines a
    /// walker takes.
    fn straighten(&self, path: &[[f64; 2]], clear: f64) -> Vec<[f64; 2]> {
        let Some(&first) = path.first() else {
            return Vec::new();
        };
        let mut out = vec![first];
        let mut i = 0;
        while i + 1 < path.len() {
            let mut j = path.len() - 1;
            while j > i + 1 && !self.clear_between(path[i], path[j], clear) {
                j -= 1;
            }
            out.push(path[j]);
            i = j;
        }
        out
    }
}

/// Drops collinear grid waypoints so paths are short to store and draw.
fn simplify(path: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    let mut out: Vec<[f64; 2]> = Vec::with_capacity(path.len());
    for p in path {
        if out.len() >= 2 {
            let a = out[out.len() - 2];
            let b = out[out.len() - 1];
            let cross = (b[0] - a[0]) * (p[1] - b[1]) - (b[1] - a[1]) * (p[0] - b[0]);
            if cross.abs() < 1e-9 {
                out.pop();
            }
        }
        out.push(p);
    }
    out
}

#[derive(PartialEq)]
struct Node {
    cost: f64,
    idx: usize,
}
impl Eq for Node {}
impl Ord for Node {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .cost
            .total_cmp(&self.cost)
            .then(other.idx.cmp(&self.idx))
    }
}
impl PartialOrd for Node {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

pub fn obstacle_rect(o: &crate::model::Obstacle) -> Rect {
    Rect::new(o.pos, [o.size[0], o.size[1]], o.yaw)
}

pub fn footprint(pos: [f64; 3], yaw: f64, size: [f64; 3]) -> Rect {
    Rect::new([pos[0], pos[1]], [size[0], size[1]], yaw)
}

/// The walk leg of `task`'s first step alone ([`plan_task`]'s first leg without planning the
/// rest, whose carry legs a larger walking clearance may close): from the start to a pick-up
/// spot of the first object, every object on the floor blocking the way, pulled straight
/// (waypoints only where the way must turn, with the clearance kept between them).
pub fn plan_first_walk(task: &Task, c: &Clearance) -> Result<Vec<[f64; 2]>, RouteError> {
    let err = |object: &str, reason: String| RouteError {
        step: 0,
        object: object.into(),
        kind: LegKind::Walk,
        reason,
    };
    let Some(step) = task.sequence.first() else {
        return Err(err("", "the task has no steps".into()));
    };
    let Some(obj) = task.object_index(&step.object).map(|i| &task.objects[i]) else {
        return Err(err(&step.object, "unknown object".into()));
    };
    let mut field = ClearanceField::new(task.room_size, c.cell);
    for o in &task.obstacles {
        field.block(&obstacle_rect(o));
    }
    for o in task.objects.iter().filter(|o| o.on == Support::Floor) {
        field.block(&footprint(o.pos, o.yaw, o.size));
    }
    let pick = footprint(obj.pos, obj.yaw, obj.size);
    let path = field
        .plan(
            task.start.pos,
            |_, d| d >= c.walk,
            |p, d| d >= c.walk && pick.distance(p) <= c.reach,
        )
        .map_err(|r| err(&obj.id, r))?;
    Ok(field.straighten(&path, c.walk))
}

/// Plans the walk and carry legs of every step of `task`, in order. Objects not being carried
/// block the way where they are at that moment (placed ones at their goals). Objects on a surface
/// are inside their support's footprint and add nothing.
pub fn plan_task(task: &Task, c: &Clearance) -> Result<Vec<Leg>, RouteError> {
    let mut fixed = ClearanceField::new(task.room_size, c.cell);
    for o in &task.obstacles {
        fixed.block(&obstacle_rect(o));
    }
    // Current footprint of every object, updated as they are placed.
    let mut at: Vec<Rect> = task
        .objects
        .iter()
        .map(|o| footprint(o.pos, o.yaw, o.size))
        .collect();
    let on_floor: Vec<bool> = task
        .objects
        .iter()
        .map(|o| o.on == Support::Floor)
        .collect();
    let mut on_floor_now = on_floor.clone();
    let mut here = task.start.pos;
    let mut legs = Vec::new();
    for (k, step) in task.sequence.iter().enumerate() {
        let Some(obj_idx) = task.object_index(&step.object) else {
            return Err(RouteError {
                step: k,
                object: step.object.clone(),
                kind: LegKind::Walk,
                reason: "unknown object".into(),
            });
        };
        let obj = &task.objects[obj_idx];
        let carry = c.carry(obj.size);
        let err = |kind, reason| RouteError {
            step: k,
            object: obj.id.clone(),
            kind,
            reason,
        };

        let mut walk_field = fixed.clone();
        for (j, r) in at.iter().enumerate() {
            if on_floor_now[j] {
                walk_field.block(r);
            }
        }
        let pick = at[obj_idx];
        let walk = walk_field
            .plan(
                here,
                |_, d| d >= c.walk,
                |p, d| d >= c.walk && pick.distance(p) <= c.reach,
            )
            .map_err(|r| err(LegKind::Walk, r))?;
        let pick_spot = *walk.last().unwrap_or(&here);
        legs.push(Leg {
            step: k,
            kind: LegKind::Walk,
            path: walk,
        });

        let mut carry_field = fixed.clone();
        for (j, r) in at.iter().enumerate() {
            if on_floor_now[j] && j != obj_idx {
                carry_field.block(r);
            }
        }
        let goal = footprint(step.goal, step.goal_yaw, obj.size);
        let near_ends = |p: [f64; 2]| {
            dist(p, pick_spot) <= c.step_back || goal.distance(p) <= c.reach + c.step_back
        };
        let path = carry_field
            .plan(
                pick_spot,
                |p, d| d >= carry || (d >= c.walk && near_ends(p)),
                |p, d| d >= c.walk && goal.distance(p) <= c.reach,
            )
            .map_err(|r| err(LegKind::Carry, r))?;
        here = *path.last().unwrap_or(&pick_spot);
        legs.push(Leg {
            step: k,
            kind: LegKind::Carry,
            path,
        });
        at[obj_idx] = goal;
        on_floor_now[obj_idx] = step.on == Support::Floor;
    }
    Ok(legs)
}
