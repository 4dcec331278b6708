//! The physics environment on rapier: the character from MJCF, rooms from the benchmark, control,
//! observations, rewards and reset-free cycles.

pub mod batch;
pub mod bench;
pub mod character;
pub mod env;
pub mod fidelity;
pub mod gait;
pub mod mjcf;
pub mod motion;
pub mod obs;
pub mod plan;
pub mod render;
pub mod room;
pub mod route;
pub mod task;
pub mod vla;
pub mod world;

pub use character::Character;
pub use mjcf::CharacterModel;
pub use world::{SimConfig, World};
