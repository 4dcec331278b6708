//! Benchmark rooms in rapier: objects rest where tasks put them, nothing passes through furniture.

use lhm_scenes::{Benchmark, RoomType, Split, Support, Task};
use lhm_sim::{CharacterModel, SimConfig, World};

fn bench() -> Benchmark {
    Benchmark::embedded().expect("benchmark")
}

fn zero(model: &CharacterModel) -> Vec<f32> {
    vec![0.0; model.dofs.len()]
}

#[test]
fn objects_rest_where_every_room_type_puts_them() {
    let b = bench();
    let model = CharacterModel::amp_humanoid();
    // Two tasks per room type, including ones with objects on support surfaces.
    let mut tasks: Vec<&Task> = Vec::new();
    for room in RoomType::ALL {
        tasks.extend(
            b.tasks(Split::Train)
                .iter()
                .filter(|t| t.room == room)
                .take(2),
        );
    }
    tasks.extend(
        b.tasks(Split::Train)
            .iter()
            .filter(|t| t.objects.iter().any(|o| o.on != Support::Floor))
            .take(2),
    );
    for task in tasks {
        let mut w = World::with_task(&model, SimConfig::default(), task, &b.catalogue);
        for _ in 0..30 {
            assert!(w.step(&zero(&model)), "{}: physics guard tripped", task.id);
        }
        for (i, o) in task.objects.iter().enumerate() {
            let p = w.object_pose(i).expect("object").translation;
            let moved = ((p.x - o.pos[0] as f32).powi(2) + (p.y - o.pos[1] as f32).powi(2)).sqrt();
            let sank = o.pos[2] as f32 - p.z;
            // (The falling character may knock an object over, so only sinking is checked.)
            assert!(
                sank < 0.03,
                "{} {} ({:?}) sank {sank} m (moved {moved} m): through its support?",
                task.id,
                o.id,
                o.on
            );
        }
    }
}

#[test]
fn a_dropped_object_comes_to_rest_on_the_floor() {
    let b = bench();
    let model = CharacterModel::amp_humanoid();
    let mut task = b
        .tasks(Split::Train)
        .iter()
        .find(|t| t.objects[0].on == Support::Floor)
        .expect("floor object")
        .clone();
    let half_height = task.objects[0].size[2] / 2.0;
    task.objects[0].pos[2] = 1.5;
    let mut w = World::with_task(&model, SimConfig::default(), &task, &b.catalogue);
    let mut lowest = f32::MAX;
    for _ in 0..90 {
        assert!(w.step(&zero(&model)));
        lowest = lowest.min(w.object_pose(0).expect("object").translation.z);
    }
    let h = w.room.objects[0];
    let body = &w.state.bodies[h];
    let z = body.position().translation.z;
    assert!(
        body.linvel().length() < 0.05,
        "still moving at {} m/s",
        body.linvel().length()
    );
    // Resting on the floor on some face: its centre is between its smallest half-extent and its
    // height, and it never went through the floor.
    let size = task.objects[0].size;
    let min_half = (size[0].min(size[1]).min(size[2]) / 2.0) as f32;
    assert!(
        z > min_half - 0.01 && z < (half_height * 2.0) as f32 + 0.01,
        "rests at z={z}"
    );
    assert!(lowest > min_half - 0.02, "went down to {lowest}");
}

#[test]
fn a_character_dropped_on_a_table_never_passes_through_it() {
    let b = bench();
    let model = CharacterModel::amp_humanoid();
    let (task, table) = b
        .tasks(Split::Train)
        .iter()
        .find_map(|t| {
            t.obstacles
                .iter()
                .find(|o| {
                    o.kind == "kitchen_island"
                        || o.kind == "dining_table"
                        || o.kind == "packing_table"
                })
                .map(|o| (t, o))
        })
        .expect("a task with a big table");
    let mut task = task.clone();
    task.start.pos = table.pos;
    let top = table.size[2] as f32;
    let cfg = SimConfig {
        spawn_height: top + 1.2,
        ..SimConfig::default()
    };
    let mut w = World::with_task(&model, cfg, &task, &b.catalogue);
    let footprint =
        lhm_scenes::geometry::Rect::new(table.pos, [table.size[0], table.size[1]], table.yaw);
    let mut landed_on_top = false;
    for step in 0..60 {
        assert!(w.step(&zero(&model)));
        for i in 0..model.bodies.len() {
            let p = w.body_pose(i).translation;
            // Inside the table's outline (away from its edges) a body's centre is above the top.
            if footprint.contains_point([f64::from(p.x), f64::from(p.y)], 0.1) {
                assert!(
                    p.z > top,
                    "step {step}: {} inside the table at z={}",
                    model.bodies[i].name,
                    p.z
                );
                landed_on_top = true;
            }
        }
    }
    assert!(landed_on_top, "the character landed on the table");
}
