//! Natural-language instructions for placement steps ("put the laptop on the desk by the window").
//! The goal is described by its support and the nearest landmarks; the unseen split uses its own
//! sentence frames so its instructions never repeat train's.

use crate::catalogue::Catalogue;
use crate::geometry::dist;
use crate::model::{Support, Task, Wall};
use crate::rng::SplitMix64;
use crate::routes::obstacle_rect;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phrasing {
    Train,
    Unseen,
}

const TRAIN_FRAMES: [&str; 6] = [
    "put the {obj} {goal}",
    "move the {obj} {goal}",
    "carry the {obj} {goal}",
    "bring the {obj} {goal}",
    "take the {obj} and place it {goal}",
    "place the {obj} {goal}",
];

const UNSEEN_FRAMES: [&str; 5] = [
    "pick up the {obj} and set it down {goal}",
    "relocate the {obj} {goal}",
    "transfer the {obj} {goal}",
    "fetch the {obj} and leave it {goal}",
    "the {obj} belongs {goal}, carry it there",
];

/// Distance from a point to the window wall.
fn window_distance(task: &Task, p: [f64; 2]) -> f64 {
    let [hx, hy] = [task.room_size[0] / 2.0, task.room_size[1] / 2.0];
    match task.window_wall {
        Wall::North => hy - p[1],
        Wall::South => p[1] + hy,
        Wall::East => hx - p[0],
        Wall::West => p[0] + hx,
    }
}

/// Nearby obstacles by distance from `p`, excluding `skip` and kinds the room has twice (they
/// would not name one place): (display name, distance).
fn landmarks(task: &Task, cat: &Catalogue, p: [f64; 2], skip: Option<&str>) -> Vec<(String, f64)> {
    let unique = |kind: &str| task.obstacles.iter().filter(|o| o.kind == kind).count() == 1;
    let mut v: Vec<(String, f64)> = task
        .obstacles
        .iter()
        .filter(|o| Some(o.id.as_str()) != skip && unique(&o.kind))
        .map(|o| {
            let name = cat
                .get(&o.kind)
                .map_or(o.kind.clone(), |t| t.display.clone());
            (name, obstacle_rect(o).distance(p))
        })
        .collect();
    v.sort_by(|a, b| a.1.total_cmp(&b.1));
    v
}

/// Describes where the goal is: "on the desk by the window", "next to the sofa", ...
pub fn describe_goal(
    rng: &mut SplitMix64,
    task: &Task,
    cat: &Catalogue,
    goal: [f64; 3],
    on: &Support,
) -> String {
    let p = [goal[0], goal[1]];
    let near_window = window_distance(task, p) < 1.3;
    match on {
        Support::Surface(id) => {
            let Some(surface) = task.obstacle(id) else {
                return "on the surface".into();
            };
            let name = cat
                .get(&surface.kind)
                .map_or(surface.kind.as_str(), |t| t.display.as_str());
            let twin = task
                .obstacles
                .iter()
                .filter(|o| o.kind == surface.kind)
                .count()
                > 1;
            let others = landmarks(task, cat, p, Some(id));
            let qualifier = if near_window && (twin || rng.chance(0.5)) {
                " by the window".to_string()
            } else if let Some((n, _)) = others.first().filter(|(_, d)| *d < 1.5) {
                if twin || rng.chance(0.5) {
                    format!(" next to the {n}")
                } else {
                    String::new()
                }
            } else {
                String::new()
            };
            format!("on the {name}{qualifier}")
        }
        Support::Floor => {
            let marks = landmarks(task, cat, p, None);
            let floor = if rng.chance(0.3) { "on the floor " } else { "" };
            match (marks.first(), marks.get(1)) {
                (Some((a, da)), Some((b, db)))
                    if *da < 1.0 && *db < 1.2 && a != b && rng.chance(0.3) =>
                {
                    format!("{floor}between the {a} and the {b}")
                }
                (Some((a, da)), _) if *da < 0.9 => {
                    let rel = *rng.pick(&["next to", "beside", "in front of", "close to"]);
                    format!("{floor}{rel} the {a}")
                }
                _ if near_window => format!("{floor}by the window"),
                _ if dist(p, [0.0, 0.0]) < 0.8 => "in the middle of the room".to_string(),
                (Some((a, _)), _) => format!("{floor}near the {a}"),
                (None, _) => "in the middle of the room".to_string(),
            }
        }
    }
}

/// One instruction for moving `object_display` to the described goal.
pub fn instruction(
    rng: &mut SplitMix64,
    phrasing: Phrasing,
    object_display: &str,
    goal: &str,
) -> String {
    let frame = match phrasing {
        Phrasing::Train => *rng.pick(&TRAIN_FRAMES),
        Phrasing::Unseen => *rng.pick(&UNSEEN_FRAMES),
    };
    frame
        .replace("{obj}", object_display)
        .replace("{goal}", goal)
}
