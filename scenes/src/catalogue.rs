//! The object catalogue and room specifications (`scenes/data/catalogue.toml`).

use crate::error::SceneError;
use crate::model::{ObjectType, RoomSpec, RoomType};
use crate::toml_util::{deserialize_at, parse_table};
use serde::{Deserialize, Serialize};
use std::collections::HashSet;

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Catalogue {
    #[serde(rename = "object")]
    pub objects: Vec<ObjectType>,
    #[serde(rename = "room")]
    pub rooms: Vec<RoomSpec>,
}

impl Catalogue {
    /// Parses and checks a catalogue; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Self, SceneError> {
        let table = parse_table(text, file)?;
        let catalogue: Catalogue = deserialize_at(toml::Value::Table(table), file, None)?;
        catalogue.check(file)?;
        Ok(catalogue)
    }

    fn check(&self, file: &str) -> Result<(), SceneError> {
        let err = |field: String, msg: String| Err(SceneError::field(file, None, field, msg));
        let mut names = HashSet::new();
        for (i, o) in self.objects.iter().enumerate() {
            let at = |f: &str| format!("object[{i}].{f}");
            if o.name.is_empty() || !names.insert(o.name.as_str()) {
                return err(at("name"), format!("empty or duplicate name {:?}", o.name));
            }
            if o.size.iter().any(|s| !s.is_finite() || *s <= 0.0) {
                return err(at("size"), format!("{}: sizes must be positive", o.name));
            }
            if !o.mass.is_finite() || o.mass <= 0.0 {
                return err(at("mass"), format!("{}: mass must be positive", o.name));
            }
            if o.rooms.is_empty() {
                return err(at("rooms"), format!("{}: appears in no room type", o.name));
            }
            if o.movable && (o.support || o.placement.is_some()) {
                return err(
                    at("support"),
                    format!("{}: a movable object has no support/placement", o.name),
                );
            }
            if !o.movable && o.placement.is_none() {
                return err(
                    at("placement"),
                    format!("{}: static object needs a placement", o.name),
                );
            }
            if !o.movable && o.on_surface {
                return err(
                    at("on_surface"),
                    format!("{}: only movable objects", o.name),
                );
            }
        }
        for room in RoomType::ALL {
            let n = self.rooms.iter().filter(|r| r.room_type == room).count();
            if n != 1 {
                return err(
                    "room".into(),
                    format!("{room}: {n} specifications, expected 1"),
                );
            }
        }
        for (i, r) in self.rooms.iter().enumerate() {
            let ok = |v: [f64; 2]| v[0] > 0.0 && v[0] <= v[1] && v[1].is_finite();
            if !ok(r.width) || !ok(r.depth) {
                return err(format!("room[{i}].width"), "need 0 < min <= max".into());
            }
            if r.obstacles[0] > r.obstacles[1] {
                return err(format!("room[{i}].obstacles"), "need min <= max".into());
            }
        }
        Ok(())
    }

    pub fn get(&self, name: &str) -> Option<&ObjectType> {
        self.objects.iter().find(|o| o.name == name)
    }

    pub fn room(&self, room: RoomType) -> &RoomSpec {
        // `check` guarantees exactly one spec per room type.
        self.rooms
            .iter()
            .find(|r| r.room_type == room)
            .expect("catalogue checked: one spec per room type")
    }

    pub fn movable(&self) -> impl Iterator<Item = &ObjectType> {
        self.objects.iter().filter(|o| o.movable)
    }

    pub fn statics(&self) -> impl Iterator<Item = &ObjectType> {
        self.objects.iter().filter(|o| !o.movable)
    }
}
