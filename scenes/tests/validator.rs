//! The validator and the route planner on hand-built and hand-broken tasks.

use lhm_scenes::routes::{plan_first_walk, plan_task, Clearance, LegKind};
use lhm_scenes::validate::validate_task;
use lhm_scenes::{
    Benchmark, MovableObject, Obstacle, PlacementStep, RoomType, Split, StartPose, Support, Task,
    Wall,
};

/// A 6 x 4 m room split by a barrier at x = 0 with an opening of `gap` metres in its middle
/// (gap 0: closed). A storage box (0.6 x 0.4 m, needs a 0.7 m corridor to carry) waits at
/// `object`, to be carried to (2, 0).
fn corridor(gap: f64, object: [f64; 2]) -> Task {
    let half = (4.0 - gap) / 2.0;
    let wall = |id: &str, y: f64| Obstacle {
        id: id.into(),
        kind: "kitchen_counter".into(),
        pos: [0.0, y],
        yaw: 0.0,
        size: [0.4, half, 0.9],
    };
    Task {
        id: "corridor".into(),
        room: RoomType::Kitchen,
        room_size: [6.0, 4.0],
        centroid: [0.0, 0.0],
        window_wall: Wall::North,
        start: StartPose {
            pos: [-2.5, 0.0],
            yaw: 0.0,
        },
        obstacles: vec![wall("o0", -2.0 + half / 2.0), wall("o1", 2.0 - half / 2.0)],
        objects: vec![MovableObject {
            id: "m0".into(),
            kind: "storage_box".into(),
            pos: [object[0], object[1], 0.175],
            yaw: 0.0,
            size: [0.6, 0.4, 0.35],
            mass: 4.0,
            on: Support::Floor,
        }],
        sequence: vec![PlacementStep {
            object: "m0".into(),
            goal: [2.0, 0.0, 0.175],
            goal_yaw: 0.0,
            on: Support::Floor,
            instruction: "carry the storage box".into(),
        }],
    }
}

#[test]
fn routes_need_a_corridor_wide_enough_to_carry() {
    let c = Clearance::default();
    let legs =
        plan_task(&corridor(1.0, [-1.5, 1.0]), &c).expect("a 1 m opening lets the box through");
    assert_eq!(
        legs.iter().map(|l| l.kind).collect::<Vec<_>>(),
        vec![LegKind::Walk, LegKind::Carry]
    );
    let carry = &legs[1].path;
    assert!(carry.first().expect("start")[0] < 0.0 && carry.last().expect("end")[0] > 1.0);

    // 0.6 m: a person walks through, a person carrying the box does not.
    let e = plan_task(&corridor(0.6, [-1.5, 1.0]), &c).expect_err("too narrow to carry");
    assert_eq!(e.kind, LegKind::Carry);
    // With the box already on the goal's side, only the walk crosses the opening: fine.
    let legs = plan_task(&corridor(0.6, [1.5, 1.0]), &c).expect("walking through 0.6 m works");
    let walk = &legs[0].path;
    assert!(
        walk[0][0] < 0.0 && walk[walk.len() - 1][0] > 0.0,
        "the walk crosses the barrier"
    );
    // Closed barrier with the box on the far side: cannot even walk to it.
    let e = plan_task(&corridor(0.0, [1.5, 1.0]), &c).expect_err("closed");
    assert_eq!(e.kind, LegKind::Walk);
}

#[test]
fn the_first_walk_alone_is_plan_tasks_first_leg_and_needs_no_carry_route() {
    let c = Clearance::default();
    let task = corridor(0.6, [1.5, 1.0]);
    let legs = plan_task(&task, &c).expect("walking through 0.6 m works");
    let walk = plan_first_walk(&task, &c).expect("walk");
    let grid = &legs[0].path;
    let length = |p: &[[f64; 2]]| -> f64 {
        p.windows(2)
            .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
            .sum()
    };
    // The same ends, pulled straight: no longer, and through the opening (|y| < 0.3 at x = 0).
    assert_eq!(walk.first(), grid.first());
    assert_eq!(walk.last(), grid.last());
    assert!(length(&walk) <= length(grid) + 1e-9);
    let crossing = walk
        .windows(2)
        .find(|w| w[0][0] <= 0.0 && w[1][0] >= 0.0)
        .expect("crosses x = 0");
    let t = -crossing[0][0] / (crossing[1][0] - crossing[0][0]);
    let y = crossing[0][1] + t * (crossing[1][1] - crossing[0][1]);
    assert!(y.abs() < 0.3 - c.walk + 0.05, "crosses at y = {y}");
    // Too narrow to carry the box out, but the walk to it exists.
    let task = corridor(0.6, [-1.5, 1.0]);
    assert!(plan_task(&task, &c).is_err());
    let walk = plan_first_walk(&task, &c).expect("the walk needs no carry route");
    assert!(
        walk.last().expect("end")[0] < 0.0,
        "stays on the start's side"
    );
    // A clearance wider than the opening closes the walk through it.
    let wide = Clearance { walk: 0.35, ..c };
    let e = plan_first_walk(&corridor(0.6, [1.5, 1.0]), &wide).expect_err("0.7 m needed");
    assert_eq!(e.kind, LegKind::Walk);
}

fn two_floor_objects() -> (Benchmark, Task) {
    let b = Benchmark::embedded().expect("loads");
    let t = b
        .tasks(Split::Train)
        .iter()
        .find(|t| {
            t.objects.iter().all(|o| o.on == Support::Floor)
                && t.sequence.iter().all(|s| s.on == Support::Floor)
                && t.obstacles.len() == 4
        })
        .expect("a task with both objects and goals on the floor and 4 obstacles")
        .clone();
    (b, t)
}

fn problems(b: &Benchmark, t: &Task) -> Vec<String> {
    validate_task(t, Split::Train, &b.catalogue, &Clearance::default())
}

fn assert_problem(b: &Benchmark, t: &Task, needle: &str) {
    let p = problems(b, t);
    assert!(
        p.iter().any(|x| x.contains(needle)),
        "expected {needle:?} in {p:?}"
    );
}

#[test]
fn valid_task_has_no_problem() {
    let (b, t) = two_floor_objects();
    assert_eq!(problems(&b, &t), Vec::<String>::new());
}

#[test]
fn broken_tasks_are_caught() {
    let (b, base) = two_floor_objects();

    let mut t = base.clone();
    let waiting = t.objects[1].pos;
    t.sequence[0].goal = waiting;
    t.sequence[0].goal[2] = t.objects[0].size[2] / 2.0;
    t.sequence[0].goal_yaw = t.objects[1].yaw;
    assert_problem(&b, &t, "occupied by object m1");

    let mut t = base.clone();
    t.objects[0].pos = [t.centroid[0] + 1.9, t.centroid[1], t.objects[0].pos[2]];
    assert_problem(&b, &t, "more than 1.5 m from the centroid");

    let mut t = base.clone();
    t.objects[1].pos[2] += 0.3;
    assert_problem(&b, &t, "centre is at z");

    let mut t = base.clone();
    t.start.pos = t.obstacles[0].pos;
    assert_problem(&b, &t, "unreachable");

    let mut t = base.clone();
    t.obstacles[1].pos = t.obstacles[0].pos;
    assert_problem(&b, &t, "overlap");

    let mut t = base.clone();
    t.obstacles.pop();
    assert_problem(&b, &t, "3 obstacles");

    let mut t = base;
    let support = b
        .catalogue
        .statics()
        .find(|s| s.support && s.rooms.contains(&t.room))
        .expect("a support type")
        .name
        .clone();
    t.obstacles[0].kind = support.clone();
    t.obstacles[0].size = b.catalogue.get(&support).expect("type").size;
    t.sequence[0].on = Support::Surface("o0".into());
    assert_problem(&b, &t, "does not fit on o0");
}
