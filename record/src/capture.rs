//! Sampling a running [`TaskEnv`] into an [`EpisodeFrames`]: the actors (which send episodes to
//! the learner for recording) and `lhm record` (which writes them itself) share this.

use lhm_protos::{EpisodeFrames, EpisodeStats, Role, WireMessage};
use lhm_sim::env::TaskEnv;

/// Who produced an episode; copied into the [`EpisodeFrames`] header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EpisodeSource {
    /// Training run (non-empty).
    pub run_id: String,
    /// Actor name within the run (non-empty), e.g. `lhm-record` for a local recording.
    pub actor_id: String,
    /// Policy that acted; never `Role::Unspecified`.
    pub role: Role,
    /// `PolicyWeights.version` the policy ran with.
    pub policy_version: u64,
}

/// Body and object poses of one episode, one frame per control step.
///
/// ```ignore
/// let mut capture = EpisodeCapture::new(&env, source); // records the start pose
/// loop {
///     let step = env.step(&action);
///     capture.push(&env);
///     if step.done || step.truncated { break; }
/// }
/// let frames = capture.finish(stats);
/// ```
#[derive(Clone, Debug)]
pub struct EpisodeCapture {
    frames: EpisodeFrames,
}

impl EpisodeCapture {
    /// Starts capturing `env`'s episode and records its current state as frame 0.
    pub fn new(env: &TaskEnv, source: EpisodeSource) -> Self {
        let num_bodies = env.world.character.bodies.len();
        let num_objects = env.world.room.objects.len();
        let mut capture = Self {
            frames: EpisodeFrames {
                run_id: source.run_id,
                actor_id: source.actor_id,
                role: source.role.into(),
                policy_version: source.policy_version,
                task_id: env.task.id.clone(),
                frame_dt: 1.0 / env.world.config.control_hz,
                num_frames: 0,
                // Character and room sizes are tiny (tens), far below u32::MAX.
                num_bodies: num_bodies as u32,
                num_objects: num_objects as u32,
                ..EpisodeFrames::versioned()
            },
        };
        capture.push(env);
        capture
    }

    /// Records `env`'s current body and object poses as the next frame; call it once after each
    /// control step. Returns false, recording nothing, when the state is not worth drawing: the
    /// physics guard tripped, a pose is not finite, or `env` is not the environment this capture
    /// started on (other body or object count).
    pub fn push(&mut self, env: &TaskEnv) -> bool {
        let f = &mut self.frames;
        let bodies = env.world.body_states();
        let objects: Vec<_> = (0..f.num_objects as usize)
            .map_while(|i| env.world.object_pose(i))
            .collect();
        let finite = bodies
            .iter()
            .all(|b| b.pos.is_finite() && b.rot.is_finite())
            && objects.iter().all(|p| p.is_finite());
        if env.world.physics_invalid
            || !finite
            || bodies.len() != f.num_bodies as usize
            || objects.len() != f.num_objects as usize
            || env.world.room.objects.len() != f.num_objects as usize
        {
            return false;
        }
        for b in &bodies {
            f.body_positions.extend(b.pos.to_array());
            f.body_rotations.extend(b.rot.to_array());
        }
        for p in &objects {
            f.object_positions.extend(p.translation.to_array());
            f.object_rotations.extend(p.rotation.to_array());
        }
        f.num_frames += 1;
        true
    }

    /// Frames recorded so far.
    pub fn num_frames(&self) -> u32 {
        self.frames.num_frames
    }

    /// The finished episode with its `stats`. It passes `lhm.v1` checks when at least one frame
    /// was recorded and the source fields were filled in.
    pub fn finish(self, stats: EpisodeStats) -> EpisodeFrames {
        EpisodeFrames {
            stats: Some(stats),
            ..self.frames
        }
    }
}
