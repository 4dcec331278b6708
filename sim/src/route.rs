//! The way the gait's base walks to the first object (`[env.gait] route_lookahead`): a planned
//! route around the room's other objects and furniture ([`lhm_scenes::routes`]) that the base
//! steers along, a point `lookahead` metres ahead at a time, instead of straight at the object.

use lhm_scenes::routes::{plan_first_walk, Clearance};
use lhm_scenes::Task;

/// The planning grid's cell (m): a tenth of the benchmark validator's resolution is plenty for
/// a point the base aims at a metre ahead, and keeps the plan to ~1 ms a room.
const CELL: f64 = 0.1;

/// The route from `task`'s start to a spot beside its first object keeping `clearance` metres
/// from every wall, furniture and object; where none keeps that much, the validator's walking
/// clearance (the benchmark guarantees that route exists in the task's own room); `None` where
/// neither plans (the start itself blocked): the base then steers straight at the object.
pub fn first_walk(task: &Task, clearance: f32) -> Option<Vec<[f32; 2]>> {
    let validator = Clearance::default();
    let wide = Clearance {
        walk: f64::from(clearance),
        cell: CELL,
        ..validator
    };
    let narrow = Clearance {
        cell: CELL,
        ..validator
    };
    plan_first_walk(task, &wide)
        .or_else(|_| plan_first_walk(task, &narrow))
        .ok()
        .map(|path| path.iter().map(|p| [p[0] as f32, p[1] as f32]).collect())
}

fn dist(a: [f32; 2], b: [f32; 2]) -> f32 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// The point `ahead` metres along `route` past its point nearest `at`; `object` once the rest
/// of the route is shorter (the last approach aims at the object itself).
pub fn lookahead(route: &[[f32; 2]], object: [f32; 2], at: [f32; 2], ahead: f32) -> [f32; 2] {
    let Some(nearest) = (0..route.len()).min_by(|&i, &j| {
        dist(route[i], at)
            .partial_cmp(&dist(route[j], at))
            .unwrap_or(std::cmp::Ordering::Equal)
    }) else {
        return object;
    };
    let mut left = ahead;
    for pair in route[nearest..].windows(2) {
        let step = dist(pair[0], pair[1]);
        if step >= left {
            let t = left / step.max(1e-6);
            return [
                pair[0][0] + t * (pair[1][0] - pair[0][0]),
                pair[0][1] + t * (pair[1][1] - pair[0][1]),
            ];
        }
        left -= step;
    }
    object
}

/// The point `distance` metres before `object` along the way: the straight last stretch from the
/// route's end to the object, then the route backward; `None` where the whole way is shorter.
pub fn point_before(route: &[[f32; 2]], object: [f32; 2], distance: f32) -> Option<[f32; 2]> {
    let last = *route.last()?;
    let mut left = distance;
    let mut stretch = vec![[object, last]];
    stretch.extend(route.windows(2).rev().map(|p| [p[1], p[0]]));
    for [from, to] in stretch {
        let step = dist(from, to);
        if step >= left {
            let t = left / step.max(1e-6);
            return Some([
                from[0] + t * (to[0] - from[0]),
                from[1] + t * (to[1] - from[1]),
            ]);
        }
        left -= step;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An L: east 2 m, then north 2 m; the object 0.5 m further north.
    fn ell() -> Vec<[f32; 2]> {
        let mut r: Vec<[f32; 2]> = (0..=20).map(|i| [i as f32 * 0.1, 0.0]).collect();
        r.extend((1..=20).map(|i| [2.0, i as f32 * 0.1]));
        r
    }

    #[test]
    fn lookahead_follows_the_route_from_the_nearest_point_then_aims_at_the_object() {
        let (r, object) = (ell(), [2.0, 2.5]);
        // Beside the first leg, 1 m ahead of the nearest point (0.5, 0).
        let p = lookahead(&r, object, [0.5, 0.3], 1.0);
        assert!(dist(p, [1.5, 0.0]) < 1e-4, "{p:?}");
        // Round the corner: 0.5 m east then 0.5 m north.
        let p = lookahead(&r, object, [1.5, -0.1], 1.0);
        assert!(dist(p, [2.0, 0.5]) < 1e-4, "{p:?}");
        // Near the end: the object.
        assert_eq!(lookahead(&r, object, [2.0, 1.6], 1.0), object);
        assert_eq!(lookahead(&[], object, [0.0, 0.0], 1.0), object);
    }

    #[test]
    fn point_before_measures_along_the_way_from_the_object() {
        let (r, object) = (ell(), [2.0, 2.5]);
        let p = point_before(&r, object, 0.3).unwrap();
        assert!(dist(p, [2.0, 2.2]) < 1e-4, "{p:?}");
        // 0.5 to the route's end, 2 m down the second leg, 0.5 m back along the first.
        let p = point_before(&r, object, 3.0).unwrap();
        assert!(dist(p, [1.5, 0.0]) < 1e-4, "{p:?}");
        assert!(point_before(&r, object, 4.6).is_none());
    }
}
