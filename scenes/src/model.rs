//! The benchmark's data model: the object catalogue, room types, and tasks, as they are stored in
//! the TOML files under `scenes/data/`. Coordinates: metres, z up, the room's floor centred on the
//! origin with walls at ±size/2; yaw in radians about +z.

use serde::{Deserialize, Serialize};
use std::fmt;

#[derive(Serialize, Deserialize, Clone, Copy, PartialEq, Eq, Hash, Debug, PartialOrd, Ord)]
#[serde(rename_all = "snake_case")]
pub enum RoomType {
    Warehouse,
    LivingRoom,
    Bedroom,
    Kitchen,
}

impl RoomType {
    pub const ALL: [RoomType; 4] = [
        RoomType::Warehouse,
        RoomType::LivingRoom,
        RoomType::Bedroom,
        RoomType::Kitchen,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            RoomType::Warehouse => "warehouse",
            RoomType::LivingRoom => "living_room",
            RoomType::Bedroom => "bedroom",
            RoomType::Kitchen => "kitchen",
        }
    }
}

impl fmt::Display for RoomType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[derive(Serialize, Deserialize, Clone, Copy, PartialEq, Eq, Hash, Debug, PartialOrd, Ord)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// 350 two-object tasks the teachers and the student train on.
    Train,
    /// 66 two-object tasks with layouts, object pairs and instructions that do not occur in train.
    Unseen,
    /// 3-, 4- and 5-object sequences for the extrapolation table.
    Extension,
}

impl Split {
    pub const ALL: [Split; 3] = [Split::Train, Split::Unseen, Split::Extension];

    pub fn as_str(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Unseen => "unseen",
            Split::Extension => "extension",
        }
    }

    pub fn file_name(self) -> String {
        format!("{}.toml", self.as_str())
    }

    pub fn parse(s: &str) -> Option<Split> {
        Split::ALL.into_iter().find(|x| x.as_str() == s)
    }
}

impl fmt::Display for Split {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[derive(Serialize, Deserialize, Clone, Copy, PartialEq, Eq, Debug)]
#[serde(rename_all = "snake_case")]
pub enum Shape {
    Box,
    Cylinder,
}

#[derive(Serialize, Deserialize, Clone, Copy, PartialEq, Eq, Debug)]
#[serde(rename_all = "snake_case")]
pub enum Placement {
    /// Back against a wall.
    Wall,
    /// Free-standing, anywhere in the room.
    Free,
}

/// One entry of the object catalogue.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ObjectType {
    pub name: String,
    /// Name used in instructions ("trash bin").
    pub display: String,
    pub category: String,
    pub movable: bool,
    pub shape: Shape,
    /// [length (x), width (y), height (z)] of the bounding box, metres. Cylinders: [d, d, h].
    pub size: [f64; 3],
    /// kg
    pub mass: f64,
    /// Movable only: may start on, or be placed on, a support surface.
    #[serde(default)]
    pub on_surface: bool,
    /// Static only: its top is a support surface.
    #[serde(default)]
    pub support: bool,
    /// Static only: how the generator places it.
    #[serde(default)]
    pub placement: Option<Placement>,
    pub rooms: Vec<RoomType>,
}

/// Size and clutter range of one room type.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RoomSpec {
    #[serde(rename = "type")]
    pub room_type: RoomType,
    /// [min, max] extent along x, metres.
    pub width: [f64; 2],
    /// [min, max] extent along y, metres.
    pub depth: [f64; 2],
    /// [min, max] number of static obstacles.
    pub obstacles: [u32; 2],
}

/// Where an object rests: on the floor or on the top of a static obstacle (by its id).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq, Eq, Hash)]
#[serde(try_from = "String", into = "String")]
pub enum Support {
    Floor,
    Surface(String),
}

impl TryFrom<String> for Support {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        match s.as_str() {
            "floor" => Ok(Support::Floor),
            "" => Err("empty support: expected \"floor\" or an obstacle id".into()),
            _ => Ok(Support::Surface(s)),
        }
    }
}

impl From<Support> for String {
    fn from(s: Support) -> String {
        match s {
            Support::Floor => "floor".into(),
            Support::Surface(id) => id,
        }
    }
}

#[derive(Serialize, Deserialize, Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[serde(rename_all = "snake_case")]
pub enum Wall {
    /// +y
    North,
    /// -y
    South,
    /// +x
    East,
    /// -x
    West,
}

impl Wall {
    pub const ALL: [Wall; 4] = [Wall::North, Wall::South, Wall::East, Wall::West];
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StartPose {
    /// Pelvis position on the floor plane.
    pub pos: [f64; 2],
    pub yaw: f64,
}

/// A static obstacle (furniture, fixture): an oriented box on the floor.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Obstacle {
    pub id: String,
    /// Catalogue name.
    pub kind: String,
    /// Centre of the footprint.
    pub pos: [f64; 2],
    pub yaw: f64,
    /// Copied from the catalogue so a task file is self-contained; the loader checks they agree.
    pub size: [f64; 3],
}

/// A movable target object at its initial pose.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MovableObject {
    pub id: String,
    pub kind: String,
    /// Centre of the bounding box (the object root).
    pub pos: [f64; 3],
    pub yaw: f64,
    pub size: [f64; 3],
    pub mass: f64,
    pub on: Support,
}

/// One (object, goal) pair of the ordered sequence, with its instruction.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PlacementStep {
    /// Id of the object to move.
    pub object: String,
    /// Goal position of the object root. Success: the root ends within 0.2 m of it.
    pub goal: [f64; 3],
    /// Yaw the footprint checks assume at the goal (success does not depend on it).
    pub goal_yaw: f64,
    pub on: Support,
    pub instruction: String,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Task {
    pub id: String,
    pub room: RoomType,
    /// [x extent, y extent] in metres; walls at ±size/2.
    pub room_size: [f64; 2],
    /// Centre of the region objects and goals are drawn from (shifted in the unseen split).
    pub centroid: [f64; 2],
    pub window_wall: Wall,
    pub start: StartPose,
    #[serde(rename = "obstacle")]
    pub obstacles: Vec<Obstacle>,
    #[serde(rename = "object")]
    pub objects: Vec<MovableObject>,
    /// The ordered (object, goal) pairs of the episode.
    #[serde(rename = "step")]
    pub sequence: Vec<PlacementStep>,
}

impl Task {
    /// The same room with only the `k`-th (object, goal) pair to do, id `<id>.p<k+1>`. The other
    /// objects stay where they start (they are clutter now). `None` if there is no such pair.
    pub fn single_pair(&self, k: usize) -> Option<Task> {
        let step = self.sequence.get(k)?.clone();
        Some(Task {
            id: format!("{}.p{}", self.id, k + 1),
            sequence: vec![step],
            ..self.clone()
        })
    }

    pub fn obstacle(&self, id: &str) -> Option<&Obstacle> {
        self.obstacles.iter().find(|o| o.id == id)
    }

    pub fn object(&self, id: &str) -> Option<&MovableObject> {
        self.objects.iter().find(|o| o.id == id)
    }

    pub fn object_index(&self, id: &str) -> Option<usize> {
        self.objects.iter().position(|o| o.id == id)
    }

    /// Height of the top of a support (0 for the floor), if the support exists.
    pub fn support_height(&self, on: &Support) -> Option<f64> {
        match on {
            Support::Floor => Some(0.0),
            Support::Surface(id) => self.obstacle(id).map(|o| o.size[2]),
        }
    }
}

/// File format version of the task files.
pub const TASK_FILE_SCHEMA: u32 = 1;

/// One split's task file (`scenes/data/<split>.toml`).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SplitFile {
    pub schema: u32,
    pub split: Split,
    #[serde(rename = "task")]
    pub tasks: Vec<Task>,
}
