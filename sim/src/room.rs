//! A benchmark task's room in rapier: walls, static obstacles (fixed boxes or cylinders with their
//! catalogue sizes), and the movable objects as dynamic bodies with their mass, resting where the
//! task puts them. Grasping is by contact only, so objects get real friction and no attachment.
//!
//! The geometry itself (wall boxes, solids, poses) is exposed as plain data so that other views of
//! the room (e.g. the MCAP recorder) draw exactly what the physics simulates.

use lhm_scenes::{Catalogue, MovableObject, Obstacle, Shape, Task};
use rapier3d::prelude::*;

pub const WALL_HEIGHT: f32 = 2.5;
pub const WALL_THICKNESS: f32 = 0.1;
/// Friction of furniture and objects (wood/plastic on rubber-like hands and feet).
pub const OBJECT_FRICTION: f32 = 0.9;
/// Soft-CCD prediction distance of movable objects, metres.
const OBJECT_SOFT_CCD: f32 = 0.2;

/// Handles of what a room added to the world.
#[derive(Clone, Debug, Default)]
pub struct Room {
    /// The fixed body carrying the four walls.
    pub walls: Option<RigidBodyHandle>,
    pub obstacles: Vec<RigidBodyHandle>,
    /// In task order (`task.objects`).
    pub objects: Vec<RigidBodyHandle>,
    /// Colour of each object (`objects` order) in rendered images: [`object_colour`].
    pub object_colours: Vec<[f32; 3]>,
    /// Shapes only to be looked at (e.g. the box of a motion clip played back): kinematic, they
    /// collide with nothing and are moved by hand ([`crate::World::add_prop_box`]).
    pub props: Vec<RigidBodyHandle>,
}

/// The collision solid of an obstacle or object, in its body's frame (centred on the body).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Solid {
    Cuboid {
        half: Vector,
    },
    /// Axis along the body's z (vertical when the body is upright).
    Cylinder {
        half_height: f32,
        radius: f32,
    },
}

/// The solid of a catalogue shape with bounding-box `size` [length, width, height]: cylinders take
/// the larger footprint side as their diameter.
pub fn solid(shape: Shape, size: [f64; 3]) -> Solid {
    let [l, w, h] = size.map(|x| x as f32);
    match shape {
        Shape::Box => Solid::Cuboid {
            half: Vector::new(l / 2.0, w / 2.0, h / 2.0),
        },
        Shape::Cylinder => Solid::Cylinder {
            half_height: h / 2.0,
            radius: l.max(w) / 2.0,
        },
    }
}

/// The catalogue shape of `kind`. Unknown kinds were rejected when the task was loaded, so a
/// missing type falls back to a box of the stored size.
pub fn shape_of(catalogue: &Catalogue, kind: &str) -> Shape {
    catalogue.get(kind).map_or(Shape::Box, |t| t.shape)
}

/// The four walls as (centre, half extents), world frame: just outside the `room_size` floor
/// [x extent, y extent], the north/south walls spanning the corners.
pub fn wall_boxes(room_size: [f64; 2]) -> [(Vector, Vector); 4] {
    let [w, d] = room_size.map(|x| x as f32);
    let t = WALL_THICKNESS / 2.0;
    [
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
    ]
}

/// Pose of a static obstacle's body: standing on the floor (centre at half its height), turned by
/// its yaw.
pub fn obstacle_pose(o: &Obstacle) -> Pose {
    Pose::from_parts(
        Vector::new(o.pos[0] as f32, o.pos[1] as f32, (o.size[2] / 2.0) as f32),
        yaw_rotation(o.yaw),
    )
}

/// Pose of a movable object's body at the start of the task.
pub fn object_start_pose(o: &MovableObject) -> Pose {
    Pose::from_parts(
        Vector::new(o.pos[0] as f32, o.pos[1] as f32, o.pos[2] as f32),
        yaw_rotation(o.yaw),
    )
}

fn yaw_rotation(yaw: f64) -> Rotation {
    Rotation::from_rotation_z(yaw as f32)
}

fn collider_for(shape: Shape, size: [f64; 3]) -> ColliderBuilder {
    match solid(shape, size) {
        Solid::Cuboid { half } => ColliderBuilder::cuboid(half.x, half.y, half.z),
        // Cylinders are along y in parry; rotate so the axis is vertical.
        Solid::Cylinder {
            half_height,
            radius,
        } => ColliderBuilder::cylinder(half_height, radius).rotation(Vector::new(
            std::f32::consts::FRAC_PI_2,
            0.0,
            0.0,
        )),
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
    let walls = bodies.insert(RigidBodyBuilder::fixed().build());
    room.walls = Some(walls);
    for (pos, half) in wall_boxes(task.room_size) {
        colliders.insert_with_parent(
            ColliderBuilder::cuboid(half.x, half.y, half.z)
                .translation(pos)
                .build(),
            walls,
            bodies,
        );
    }
    for o in &task.obstacles {
        let h = bodies.insert(RigidBodyBuilder::fixed().pose(obstacle_pose(o)).build());
        colliders.insert_with_parent(
            collider_for(shape_of(catalogue, &o.kind), o.size)
                .friction(OBJECT_FRICTION)
                .build(),
            h,
            bodies,
        );
        room.obstacles.push(h);
    }
    for o in &task.objects {
        let h = bodies.insert(
            RigidBodyBuilder::dynamic()
                .pose(object_start_pose(o))
                // Objects are small and may be dropped; CCD keeps them from tunnelling, and a
                // velocity-scaled contact prediction (soft CCD) lets a box falling ~9 cm per
                // 1/60 s pipeline step meet the floor before it sinks in. The character's links
                // keep CCD off: on multibody links it tore joints apart.
                .ccd_enabled(true)
                .soft_ccd_prediction(OBJECT_SOFT_CCD)
                .build(),
        );
        colliders.insert_with_parent(
            collider_for(shape_of(catalogue, &o.kind), o.size)
                .mass(o.mass as f32)
                .friction(OBJECT_FRICTION)
                .build(),
            h,
            bodies,
        );
        room.objects.push(h);
        room.object_colours.push(object_colour(catalogue, &o.kind));
    }
    room
}

/// An object's colour in rendered images: one hue per catalogue category, shaded a little per
/// kind. Objects of one category (a pot and a kettle) look nearly alike, so in the egocentric
/// view only the instruction tells them apart — the setting of the paper's language ablation.
pub fn object_colour(catalogue: &Catalogue, kind: &str) -> [f32; 3] {
    let category = catalogue.get(kind).map_or("", |t| t.category.as_str());
    let base = match category {
        "electronics" => [0.30, 0.32, 0.36],
        "container" => [0.20, 0.55, 0.35],
        "kitchenware" => [0.75, 0.72, 0.68],
        "appliance" => [0.80, 0.76, 0.70],
        "textile" => [0.85, 0.80, 0.55],
        "furniture" => [0.55, 0.38, 0.22],
        "luggage" => [0.25, 0.30, 0.55],
        "tool" => [0.80, 0.20, 0.15],
        "lighting" => [0.95, 0.85, 0.40],
        "decor" => [0.30, 0.60, 0.20],
        _ => [0.90, 0.45, 0.15],
    };
    // FNV-1a of the kind: a fixed, small (±6 %) brightness change per kind.
    let hash = kind.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ b as u64).wrapping_mul(0x100_0000_01b3)
    });
    let shade = 0.94 + 0.12 * ((hash % 1000) as f32 / 1000.0);
    base.map(|c| (c * shade).min(1.0))
}
