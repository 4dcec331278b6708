//! What a recording draws: the room, the goals, the movable objects and the character, as Foxglove
//! scene entities. The shapes are built once per episode from what a receiver knows (the character
//! model, the task and the catalogue) with the same geometry the physics uses
//! (`lhm_sim::room`, the MJCF geoms), and posed per frame from an [`EpisodeFrames`].

use lhm_protos::foxglove::scene_entity_deletion::Type as DeletionType;
use lhm_protos::foxglove::{
    Color, CubePrimitive, CylinderPrimitive, FrameTransform, FrameTransforms, KeyValuePair, Pose,
    Quaternion, SceneEntity, SceneEntityDeletion, SceneUpdate, SpherePrimitive, Vector3,
};
use lhm_protos::prost_types::Timestamp;
use lhm_protos::EpisodeFrames;
use lhm_scenes::{Catalogue, Task};
use lhm_sim::mjcf::{CharacterModel, GeomShape};
use lhm_sim::room::{self, Solid};
use rapier3d::math::{Pose as SimPose, Rotation, Vector};

/// The fixed frame everything is drawn in (z up, metres, the room's floor centred on the origin).
pub const WORLD_FRAME: &str = "world";

/// The physics floor is an infinite half-space; we draw the room's footprint as a thin slab whose
/// top is at z = 0.
const FLOOR_THICKNESS: f32 = 0.02;

// The palette of `lhm_sim::render`, so stills and recordings look alike.
const CHARACTER: Color = rgba(0.35, 0.55, 0.85, 1.0);
const OBJECT: Color = rgba(0.90, 0.45, 0.15, 1.0);
const OBSTACLE: Color = rgba(0.62, 0.48, 0.36, 1.0);
// Walls are see-through so that an orbiting camera never loses the character behind one.
const WALL: Color = rgba(0.85, 0.85, 0.82, 0.3);
const FLOOR: Color = rgba(0.72, 0.70, 0.66, 1.0);
// A goal is a ghost of its object where it must end up.
const GOAL: Color = rgba(0.20, 0.75, 0.30, 0.35);

const fn rgba(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

/// One primitive in its owner's frame.
#[derive(Clone, Copy, Debug)]
enum Part {
    Sphere {
        centre: Vector,
        radius: f32,
    },
    Cuboid {
        centre: Vector,
        half: Vector,
    },
    /// Axis along the local z turned by `rotation`.
    Cylinder {
        centre: Vector,
        rotation: Rotation,
        half_height: f32,
        radius: f32,
    },
}

impl Part {
    fn of_solid(solid: Solid) -> Self {
        match solid {
            Solid::Cuboid { half } => Part::Cuboid {
                centre: Vector::ZERO,
                half,
            },
            Solid::Cylinder {
                half_height,
                radius,
            } => Part::Cylinder {
                centre: Vector::ZERO,
                rotation: Rotation::IDENTITY,
                half_height,
                radius,
            },
        }
    }

    /// An MJCF geom. Foxglove has no capsule primitive, so a capsule is a cylinder between its
    /// segment's ends plus a sphere on each end: the same solid the physics collides with.
    fn of_geom(shape: &GeomShape, pos: [f64; 3]) -> Vec<Self> {
        let v = |a: [f64; 3]| Vector::new(a[0] as f32, a[1] as f32, a[2] as f32);
        match shape {
            GeomShape::Sphere { radius } => vec![Part::Sphere {
                centre: v(pos),
                radius: *radius as f32,
            }],
            GeomShape::Box { half } => vec![Part::Cuboid {
                centre: v(pos),
                half: v(*half),
            }],
            GeomShape::Capsule { from, to, radius } => {
                let (from, to, radius) = (v(*from), v(*to), *radius as f32);
                let ends = [
                    Part::Sphere {
                        centre: from,
                        radius,
                    },
                    Part::Sphere { centre: to, radius },
                ];
                let axis = to - from;
                let length = axis.length();
                if length < 1e-6 {
                    // A zero-length capsule is a sphere.
                    return vec![ends[0]];
                }
                let mut parts = vec![Part::Cylinder {
                    centre: (from + to) * 0.5,
                    rotation: Rotation::from_rotation_arc(Vector::Z, axis / length),
                    half_height: length / 2.0,
                    radius,
                }];
                parts.extend(ends);
                parts
            }
        }
    }
}

/// A drawn thing: its entity id, metadata, colour and primitives in its own frame.
#[derive(Clone, Debug)]
struct Item {
    id: String,
    metadata: Vec<KeyValuePair>,
    color: Color,
    parts: Vec<Part>,
}

fn meta(pairs: &[(&str, &str)]) -> Vec<KeyValuePair> {
    pairs
        .iter()
        .map(|(key, value)| KeyValuePair {
            key: (*key).into(),
            value: (*value).into(),
        })
        .collect()
}

fn vector3(v: Vector) -> Vector3 {
    Vector3 {
        x: v.x.into(),
        y: v.y.into(),
        z: v.z.into(),
    }
}

fn quaternion(q: Rotation) -> Quaternion {
    Quaternion {
        x: q.x.into(),
        y: q.y.into(),
        z: q.z.into(),
        w: q.w.into(),
    }
}

fn fg_pose(position: Vector, orientation: Rotation) -> Option<Pose> {
    Some(Pose {
        position: Some(vector3(position)),
        orientation: Some(quaternion(orientation)),
    })
}

/// Nanoseconds since the epoch as a protobuf timestamp.
pub(crate) fn timestamp(ns: u64) -> Timestamp {
    Timestamp {
        // u64::MAX / 1e9 fits an i64 with room to spare.
        seconds: (ns / 1_000_000_000) as i64,
        nanos: (ns % 1_000_000_000) as i32,
    }
}

impl Item {
    /// The entity with the item's frame at `pose` in the world.
    fn entity(&self, pose: &SimPose, stamp: Timestamp) -> SceneEntity {
        let mut entity = SceneEntity {
            timestamp: Some(stamp),
            frame_id: WORLD_FRAME.into(),
            id: self.id.clone(),
            // Zero: shown until the next update replaces it (every frame does).
            lifetime: None,
            frame_locked: false,
            metadata: self.metadata.clone(),
            ..SceneEntity::default()
        };
        let color = Some(self.color);
        for part in &self.parts {
            match *part {
                Part::Sphere { centre, radius } => entity.spheres.push(SpherePrimitive {
                    pose: fg_pose(pose * centre, pose.rotation),
                    size: Some(vector3(Vector::splat(2.0 * radius))),
                    color,
                }),
                Part::Cuboid { centre, half } => entity.cubes.push(CubePrimitive {
                    pose: fg_pose(pose * centre, pose.rotation),
                    size: Some(vector3(half * 2.0)),
                    color,
                }),
                Part::Cylinder {
                    centre,
                    rotation,
                    half_height,
                    radius,
                } => entity.cylinders.push(CylinderPrimitive {
                    pose: fg_pose(pose * centre, pose.rotation * rotation),
                    size: Some(vector3(Vector::new(
                        2.0 * radius,
                        2.0 * radius,
                        2.0 * half_height,
                    ))),
                    bottom_scale: 1.0,
                    top_scale: 1.0,
                    color,
                }),
            }
        }
        entity
    }
}

/// Everything needed to draw the episodes of one task with one character: build it once, then
/// hand it to [`crate::McapRecorder::write_episode`] with each episode's frames.
#[derive(Clone, Debug)]
pub struct EpisodeScene {
    task_id: String,
    /// Floor, walls, obstacles and goal markers, at their fixed world poses.
    statics: Vec<(Item, SimPose)>,
    /// In task order, the order of `EpisodeFrames.object_*`.
    objects: Vec<Item>,
    /// In model order, the order of `EpisodeFrames.body_*`.
    bodies: Vec<Item>,
}

impl EpisodeScene {
    /// The scene of `task` with the character `model`; obstacle and object shapes come from the
    /// catalogue exactly as `lhm_sim::room` builds their colliders.
    pub fn new(model: &CharacterModel, task: &Task, catalogue: &Catalogue) -> Self {
        let mut statics = Vec::new();
        let [w, d] = task.room_size.map(|x| x as f32);
        statics.push((
            Item {
                id: "floor".into(),
                metadata: meta(&[("kind", "floor"), ("room", task.room.as_str())]),
                color: FLOOR,
                parts: vec![Part::Cuboid {
                    centre: Vector::new(0.0, 0.0, -FLOOR_THICKNESS / 2.0),
                    half: Vector::new(w / 2.0, d / 2.0, FLOOR_THICKNESS / 2.0),
                }],
            },
            SimPose::IDENTITY,
        ));
        statics.push((
            Item {
                id: "walls".into(),
                metadata: meta(&[("kind", "walls")]),
                color: WALL,
                parts: room::wall_boxes(task.room_size)
                    .into_iter()
                    .map(|(centre, half)| Part::Cuboid { centre, half })
                    .collect(),
            },
            SimPose::IDENTITY,
        ));
        for o in &task.obstacles {
            let shape = room::shape_of(catalogue, &o.kind);
            statics.push((
                Item {
                    id: format!("obstacle/{}", o.id),
                    metadata: meta(&[("kind", "obstacle"), ("id", &o.id), ("type", &o.kind)]),
                    color: OBSTACLE,
                    parts: vec![Part::of_solid(room::solid(shape, o.size))],
                },
                room::obstacle_pose(o),
            ));
        }
        for (k, step) in task.sequence.iter().enumerate() {
            // Loading rejects steps naming unknown objects; a goal we cannot size is not drawn.
            let Some(o) = task.object(&step.object) else {
                continue;
            };
            let shape = room::shape_of(catalogue, &o.kind);
            let pose = SimPose::from_parts(
                Vector::new(
                    step.goal[0] as f32,
                    step.goal[1] as f32,
                    step.goal[2] as f32,
                ),
                Rotation::from_rotation_z(step.goal_yaw as f32),
            );
            statics.push((
                Item {
                    id: format!("goal/{k}"),
                    metadata: meta(&[
                        ("kind", "goal"),
                        ("step", &k.to_string()),
                        ("object", &o.id),
                        ("instruction", &step.instruction),
                    ]),
                    color: GOAL,
                    parts: vec![Part::of_solid(room::solid(shape, o.size))],
                },
                pose,
            ));
        }
        let objects = task
            .objects
            .iter()
            .map(|o| Item {
                id: format!("object/{}", o.id),
                metadata: meta(&[
                    ("kind", "object"),
                    ("id", &o.id),
                    ("type", &o.kind),
                    ("mass_kg", &o.mass.to_string()),
                ]),
                color: OBJECT,
                parts: vec![Part::of_solid(room::solid(
                    room::shape_of(catalogue, &o.kind),
                    o.size,
                ))],
            })
            .collect();
        let bodies = model
            .bodies
            .iter()
            .map(|b| Item {
                id: format!("body/{}", b.name),
                metadata: meta(&[("kind", "body"), ("body", &b.name)]),
                color: CHARACTER,
                parts: b
                    .geoms
                    .iter()
                    .flat_map(|g| Part::of_geom(&g.shape, g.pos))
                    .collect(),
            })
            .collect();
        Self {
            task_id: task.id.clone(),
            statics,
            objects,
            bodies,
        }
    }

    /// The benchmark task this scene draws (`EpisodeFrames.task_id` must match it).
    pub fn task_id(&self) -> &str {
        &self.task_id
    }

    /// Character bodies (`EpisodeFrames.num_bodies` must match).
    pub fn num_bodies(&self) -> usize {
        self.bodies.len()
    }

    /// Movable objects (`EpisodeFrames.num_objects` must match).
    pub fn num_objects(&self) -> usize {
        self.objects.len()
    }

    /// Entities in every scene update: bodies, objects, and the room's floor, walls, obstacles and
    /// goal markers.
    pub fn num_entities(&self) -> usize {
        self.bodies.len() + self.objects.len() + self.statics.len()
    }

    /// Transform frame names, bodies (model order) then objects (task order): `body/<name>`,
    /// `object/<id>`, children of [`WORLD_FRAME`]. Entity ids are the same strings.
    pub fn frame_ids(&self) -> impl Iterator<Item = &str> {
        self.bodies
            .iter()
            .chain(&self.objects)
            .map(|item| item.id.as_str())
    }

    /// Frame `frame` of `frames` (already checked against this scene) as a full scene. The first
    /// frame of an episode first deletes every entity, so a room or objects of an earlier episode
    /// in the same file do not linger.
    pub(crate) fn scene_update(
        &self,
        frames: &EpisodeFrames,
        frame: usize,
        stamp_ns: u64,
    ) -> SceneUpdate {
        let stamp = timestamp(stamp_ns);
        let deletions = if frame == 0 {
            vec![SceneEntityDeletion {
                timestamp: Some(stamp),
                r#type: DeletionType::All.into(),
                id: String::new(),
            }]
        } else {
            Vec::new()
        };
        let mut entities = Vec::with_capacity(self.num_entities());
        entities.extend(
            self.statics
                .iter()
                .map(|(item, pose)| item.entity(pose, stamp)),
        );
        for (i, item) in self.objects.iter().enumerate() {
            let pose = object_pose(frames, frame, i);
            entities.push(item.entity(&pose, stamp));
        }
        for (i, item) in self.bodies.iter().enumerate() {
            let pose = body_pose(frames, frame, i);
            entities.push(item.entity(&pose, stamp));
        }
        SceneUpdate {
            deletions,
            entities,
        }
    }

    /// World → each body and object frame at frame `frame`, so a Foxglove camera can follow e.g.
    /// `body/pelvis`.
    pub(crate) fn frame_transforms(
        &self,
        frames: &EpisodeFrames,
        frame: usize,
        stamp_ns: u64,
    ) -> FrameTransforms {
        let stamp = timestamp(stamp_ns);
        let transform = |child: &str, pose: SimPose| FrameTransform {
            timestamp: Some(stamp),
            parent_frame_id: WORLD_FRAME.into(),
            child_frame_id: child.into(),
            translation: Some(vector3(pose.translation)),
            rotation: Some(quaternion(pose.rotation)),
        };
        let bodies = self
            .bodies
            .iter()
            .enumerate()
            .map(|(i, item)| transform(&item.id, body_pose(frames, frame, i)));
        let objects = self
            .objects
            .iter()
            .enumerate()
            .map(|(i, item)| transform(&item.id, object_pose(frames, frame, i)));
        FrameTransforms {
            transforms: bodies.chain(objects).collect(),
        }
    }
}

fn body_pose(frames: &EpisodeFrames, frame: usize, body: usize) -> SimPose {
    let index = frame * frames.num_bodies as usize + body;
    pose_at(&frames.body_positions, &frames.body_rotations, index)
}

fn object_pose(frames: &EpisodeFrames, frame: usize, object: usize) -> SimPose {
    let index = frame * frames.num_objects as usize + object;
    pose_at(&frames.object_positions, &frames.object_rotations, index)
}

/// Pose `index` of flattened position (xyz) and rotation (xyzw) arrays. Shapes were checked
/// before we get here; out-of-range or degenerate entries still give the identity rather than a
/// panic, and rotations are renormalised against f32 rounding on the wire.
fn pose_at(positions: &[f32], rotations: &[f32], index: usize) -> SimPose {
    let translation = positions
        .get(3 * index..3 * index + 3)
        .map_or(Vector::ZERO, |p| Vector::new(p[0], p[1], p[2]));
    let rotation = rotations
        .get(4 * index..4 * index + 4)
        .map(|q| Rotation::from_xyzw(q[0], q[1], q[2], q[3]))
        .filter(|q| q.length_squared() > 1e-12)
        .map_or(Rotation::IDENTITY, |q| q.normalize());
    SimPose::from_parts(translation, rotation)
}
