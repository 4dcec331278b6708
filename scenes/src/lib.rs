//! The LHM benchmark of cluttered rooms (paper Sec. 4.1): a 79-type object catalogue (25 movable
//! targets), four room types, 350 train tasks, 66 unseen tasks and 3/4/5-object extension
//! sequences, each task with its obstacles, objects, ordered goals and instructions.
//!
//! The tasks are data (`scenes/data/*.toml`), produced by [`generate::generate`], checked by
//! [`validate`], summarised by [`stats`] and drawn by [`render`].

pub mod catalogue;
pub mod error;
pub mod generate;
pub mod geometry;
pub mod language;
pub mod load;
pub mod model;
pub mod raster;
pub mod render;
pub mod rng;
pub mod routes;
pub mod stats;
mod toml_util;
pub mod validate;

pub use catalogue::Catalogue;
pub use error::{FieldError, SceneError};
pub use load::Benchmark;
pub use model::*;
