//! A benchmark task's room in rapier: walls, static obstacles (fixed boxes or cylinders with their
//! catalogue sizes), and the movable objects as dynamic bodies with their mass, resting where the
//! task puts them. Grasping is by contact only, so objects get real friction and no attachment.

use lhm_scenes::{Catalogue, Shape, Task};
use rapier3d::prelude::*;

pub const WALL_HEIGHT: f32 = 2.5;
pub const WALL_THICKNESS: f32 = 0.1;
/// Friction of furniture and objects (wood/plastic on rubber-like hands and feet).
pub const OBJECT_FRICTION: f32 = 0.9;

/// Handles of what a room added to the world.
#[derive(Clone, Debug, Default)]
pub struct Room {
    /// The fixed body carrying the four walls.
    pub walls: Option<RigidBodyHandle>,
    pub obstacles: Vec<RigidBodyHandle>,
    /// In task order (`task.objects`).
    pub objects: Vec<RigidBodyHandle>,
}

fn yaw_rotation(yaw: f64) -> Rotation {
    Rotation::from_rotation_z(yaw as f32)
}

fn collider_for(shape: Shape, size: [f64; 3]) -> ColliderBuilder {
    let [l, w, h] = size.map(|x| x as f32);
    match shape {
        Shape::Box => ColliderBuilder::cuboid(l / 2.0, w / 2.0, h / 2.0),
        // Cylinders are along y in parry; rotate so the axis is vertical.
        Shape::Cylinder => ColliderBuilder::cylinder(h / 2.0, l.max(w) / 2.0)
            .rotation(Vector::new(std::f32::consts::FRAC_PI_2, 0.0, 0.0)),
    }
}

/// Adds the task's walls, obstacles and objects. Unknown catalogue kinds were rejected when the
/// task was loaded, so a missing type here falls back to a box of the stored size.
pub fn build_room(
    task: &Task,
    catalogue: &Catalogue,
    bodies: &mut RigidBodySet,
    colliders: &mut ColliderSet,
) -> Room {
    let mut room = Room::default();
    let [w, d] = task.room_size.map(|x| x as f32);
    let walls = bodies.insert(RigidBodyBuilder::fixed().build());
    room.walls = Some(walls);
    let t = WALL_THICKNESS / 2.0;
    for (pos, half) in [
        (
            Vector::new(0.0, d / 2.0 + t, WALL_HEIGHT / 2.0),
            Vector::new(w / 2.0 + 2.0 * t, t, WALL_HEIGHT / 2.0),
        ),
        (
            Vector::new(0.0, -d / 2.0 - t, WALL_HEIGHT / 2.0),
            Vector::new(w / 2.0 + 2.0 * t, t, WALL_HEIGHT / 2.0),
        ),
        (
            Vector::new(w / 2.0 + t, 0.0, WALL_HEIGHT / 2.0),
            Vector::new(t, d / 2.0, WALL_HEIGHT / 2.0),
        ),
        (
            Vector::new(-w / 2.0 - t, 0.0, WALL_HEIGHT / 2.0),
            Vector::new(t, d / 2.0, WALL_HEIGHT / 2.0),
        ),
    ] {
        colliders.insert_with_parent(
            ColliderBuilder::cuboid(half.x, half.y, half.z)
                .translation(pos)
                .build(),
            walls,
            bodies,
        );
    }
    for o in &task.obstacles {
        let shape = catalogue.get(&o.kind).map_or(Shape::Box, |t| t.shape);
        let pos = Vector::new(o.pos[0] as f32, o.pos[1] as f32, (o.size[2] / 2.0) as f32);
        let h = bodies.insert(
            RigidBodyBuilder::fixed()
                .pose(Pose::from_parts(pos, yaw_rotation(o.yaw)))
                .build(),
        );
        colliders.insert_with_parent(
            collider_for(shape, o.size)
                .friction(OBJECT_FRICTION)
                .build(),
            h,
            bodies,
        );
        room.obstacles.push(h);
    }
    for o in &task.objects {
        let shape = catalogue.get(&o.kind).map_or(Shape::Box, |t| t.shape);
        let pos = Vector::new(o.pos[0] as f32, o.pos[1] as f32, o.pos[2] as f32);
        let h = bodies.insert(
            RigidBodyBuilder::dynamic()
                .pose(Pose::from_parts(pos, yaw_rotation(o.yaw)))
                // Objects are small and may be dropped; CCD keeps them out of the floor (the
                // character's links keep it off: on multibody links it tore joints apart).
                .ccd_enabled(true)
                .build(),
        );
        colliders.insert_with_parent(
            collider_for(shape, o.size)
                .mass(o.mass as f32)
                .friction(OBJECT_FRICTION)
                .build(),
            h,
            bodies,
        );
        room.objects.push(h);
    }
    room
}
