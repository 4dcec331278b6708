//! A CPU renderer: one ray per pixel against every collider, Lambert shading, a checkered
//! floor. Any camera works — third-person for people (walls cut away, like a dollhouse), or
//! head-mounted and egocentric for the VLA (the head itself left out).

use crate::world::World;
use rapier3d::prelude::*;
use std::io::Write;

#[derive(Clone, Copy, Debug)]
pub struct Camera {
    pub eye: Vector,
    pub target: Vector,
    /// Vertical field of view, degrees.
    pub fov_y: f32,
    pub width: u32,
    pub height: u32,
}

impl Camera {
    /// Behind and to the side of the character, looking at its pelvis.
    pub fn third_person(world: &World, width: u32, height: u32) -> Self {
        let root = world.body_pose(0);
        let yaw = crate::obs::heading_yaw(root.rotation);
        let back = Vector::new(-yaw.cos(), -yaw.sin(), 0.0);
        let side = Vector::new(-yaw.sin(), yaw.cos(), 0.0);
        let target = Vector::new(root.translation.x, root.translation.y, 0.7);
        Self {
            eye: target + back * 2.6 + side * 1.6 + Vector::new(0.0, 0.0, 1.4),
            target,
            fov_y: 55.0,
            width,
            height,
        }
    }

    /// At the eyes, looking where the head faces, slightly down.
    pub fn egocentric(world: &World, width: u32, height: u32) -> Self {
        let head = world.character.model.body_index("head").unwrap_or(0);
        let pose = world.body_pose(head);
        let eye = pose.translation + pose.rotation * Vector::new(0.08, 0.0, 0.17);
        let target = eye + pose.rotation * Vector::new(1.0, 0.0, -0.35);
        Self {
            eye,
            target,
            fov_y: 75.0,
            width,
            height,
        }
    }
}

pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

const SKY: [f32; 3] = [0.82, 0.88, 0.95];
const CHARACTER: [f32; 3] = [0.35, 0.55, 0.85];
const OBJECT: [f32; 3] = [0.90, 0.45, 0.15];
const OBSTACLE: [f32; 3] = [0.62, 0.48, 0.36];
const WALL: [f32; 3] = [0.85, 0.85, 0.82];

/// Renders the world from `camera`. `third_person` leaves the walls out so they never hide the
/// character; the egocentric view keeps them and leaves out the head.
pub fn render(world: &World, camera: &Camera, third_person: bool) -> Image {
    let s = &world.state;
    let head = world
        .character
        .model
        .body_index("head")
        .map(|i| world.character.bodies[i]);
    let walls = world.room.walls;
    // Every collider is tested directly (a few dozen), so rendering needs no broad-phase state
    // and works on a world that was just built or restored.
    type Shape<'a> = (
        Option<RigidBodyHandle>,
        &'a Collider,
        Pose,
        rapier3d::parry::bounding_volume::Aabb,
    );
    let shapes: Vec<Shape> = s
        .colliders
        .iter()
        .map(|(_, c)| {
            // From the parent body's pose, not the collider's cached one: that is only refreshed
            // by a physics step, and kinematic playback moves bodies without stepping.
            let pose = c
                .parent()
                .and_then(|p| s.bodies.get(p))
                .zip(c.position_wrt_parent())
                .map_or(*c.position(), |(b, local)| *b.position() * *local);
            (c.parent(), c, pose, c.shape().compute_aabb(&pose))
        })
        .filter(|(parent, _, _, _)| {
            if third_person {
                walls.is_none() || *parent != walls
            } else {
                *parent != head
            }
        })
        .collect();
    let forward = (camera.target - camera.eye).normalize();
    let right = forward.cross(Vector::Z).normalize();
    let up = right.cross(forward);
    let half_h = (camera.fov_y.to_radians() / 2.0).tan();
    let half_w = half_h * camera.width as f32 / camera.height as f32;
    let light = Vector::new(0.4, 0.3, 1.0).normalize();
    let character: Vec<RigidBodyHandle> = world.character.bodies.clone();
    let mut rgb = Vec::with_capacity((camera.width * camera.height * 3) as usize);
    for py in 0..camera.height {
        for px in 0..camera.width {
            let u = (2.0 * (px as f32 + 0.5) / camera.width as f32 - 1.0) * half_w;
            let v = (1.0 - 2.0 * (py as f32 + 0.5) / camera.height as f32) * half_h;
            let dir = (forward + right * u + up * v).normalize();
            let ray = Ray::new(camera.eye, dir);
            let mut nearest: Option<(
                Option<RigidBodyHandle>,
                rapier3d::parry::query::RayIntersection,
            )> = None;
            for (parent, collider, pose, aabb) in &shapes {
                let max = nearest.as_ref().map_or(100.0, |(_, h)| h.time_of_impact);
                if aabb.cast_local_ray(&ray, max, true).is_none() {
                    continue;
                }
                if let Some(hit) = collider
                    .shape()
                    .cast_ray_and_get_normal(pose, &ray, max, true)
                {
                    nearest = Some((*parent, hit));
                }
            }
            let colour = match nearest {
                None => SKY,
                Some((parent, hit)) => {
                    let point = camera.eye + dir * hit.time_of_impact;
                    let base = match parent {
                        Some(p) if character.contains(&p) => CHARACTER,
                        Some(p) if world.room.objects.contains(&p) => world
                            .room
                            .objects
                            .iter()
                            .position(|o| *o == p)
                            .and_then(|i| world.room.object_colours.get(i))
                            .copied()
                            .unwrap_or(OBJECT),
                        Some(p) if world.room.props.contains(&p) => OBJECT,
                        Some(p) if world.room.obstacles.contains(&p) => OBSTACLE,
                        Some(p) if Some(p) == walls => WALL,
                        _ => {
                            // The floor: a 0.5 m checkerboard.
                            let checker =
                                ((point.x / 0.5).floor() + (point.y / 0.5).floor()) as i64 % 2 == 0;
                            if checker {
                                [0.78, 0.76, 0.72]
                            } else {
                                [0.66, 0.64, 0.60]
                            }
                        }
                    };
                    let lambert = hit.normal.dot(light).max(0.0);
                    base.map(|c| c * (0.45 + 0.55 * lambert))
                }
            };
            rgb.extend(colour.map(|c| (c.clamp(0.0, 1.0) * 255.0) as u8));
        }
    }
    Image {
        width: camera.width,
        height: camera.height,
        rgb,
    }
}

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("writing the GIF: {0}")]
    Gif(#[from] gif::EncodingError),
    #[error("no frames to write")]
    Empty,
}

/// An animated GIF of `frames` (all the same size), `delay_cs` hundredths of a second apart.
pub fn write_gif(frames: &[Image], delay_cs: u16, out: impl Write) -> Result<(), RenderError> {
    let first = frames.first().ok_or(RenderError::Empty)?;
    let (w, h) = (first.width as u16, first.height as u16);
    let mut encoder = gif::Encoder::new(out, w, h, &[])?;
    encoder.set_repeat(gif::Repeat::Infinite)?;
    for f in frames {
        let mut frame = gif::Frame::from_rgb_speed(w, h, &f.rgb, 10);
        frame.delay = delay_cs;
        encoder.write_frame(&frame)?;
    }
    Ok(())
}
